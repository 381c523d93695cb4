// Bad input never crashes or hangs the importer: it returns a Status that says why.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <random>

#include "core/character.h"
#include "core/motion.h"
#include "gltf_fixture.h"
#include "io/asset.h"
#include "test_util.h"

namespace motionlod::io {
namespace {

template <typename Edit>
testing::GltfFixtureOptions Options(Edit edit) {
  testing::GltfFixtureOptions options;
  edit(options);
  return options;
}

testing::GltfFixtureOptions Uri(const std::string& uri) {
  testing::GltfFixtureOptions options;
  options.buffer_uri = uri;
  return options;
}

// When a damaged file still imports, what comes out must be usable.
void ExpectUsableOrError(const StatusOr<std::shared_ptr<const Asset>>& asset) {
  if (!asset.ok()) {
    EXPECT_FALSE(asset.status().message().empty());
    return;
  }
  const auto character = core::BuildCharacter((*asset)->character());
  ASSERT_TRUE(character.ok()) << character.status().ToString();
  if ((*asset)->animations().empty()) return;
  const StatusOr<core::Motion> motion = (*asset)->SampleAnimation("", 10);
  if (motion.ok()) {
    EXPECT_TRUE(core::ValidateMotion(*motion, **character).ok());
  }
}

TEST(LoadAsset, EmptyFileIsAnError) {
  const auto asset = LoadAsset({{"empty.glb", ""}});
  ASSERT_EQ(asset.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(asset.status().message().find("empty"), std::string::npos);
}

TEST(LoadAsset, WrongOrMissingExtensionIsUnsupported) {
  EXPECT_EQ(LoadAsset({{"model.obj", "v 0 0 0\n"}}).status().code(), StatusCode::kUnsupported);
  EXPECT_EQ(LoadAsset({{"model.3ds", "MM"}}).status().code(), StatusCode::kUnsupported);
  EXPECT_EQ(LoadAsset({{"model", "HIERARCHY"}}).status().code(), StatusCode::kUnsupported);
}

TEST(LoadAsset, ContentOfAnotherFormatIsRejectedBeforeParsing) {
  const testing::GltfFixture fixture = testing::MakeSkinnedGltf();
  EXPECT_EQ(LoadAsset({{"fixture.bvh", fixture.json}}).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(LoadAsset({{"fixture.dae", fixture.json}}).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(LoadAsset({{"fixture.fbx", fixture.json}}).status().code(),
            StatusCode::kInvalidArgument);
}

TEST(LoadAsset, StaticMeshWithoutSkeletonIsAnError) {
  testing::GltfFixture fixture =
      testing::MakeSkinnedGltf(Options([](auto& o) { o.with_animation = false; }));
  // Drop the skin from the mesh node: a plain static quad.
  const std::string skin_ref = ",\"skin\":0";
  fixture.json.erase(fixture.json.find(skin_ref), skin_ref.size());
  const auto asset = LoadAsset({{"static.gltf", fixture.json}});
  ASSERT_EQ(asset.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(asset.status().message().find("no skeleton"), std::string::npos);
}

TEST(LoadAsset, NonFiniteNumbersAreRejected) {
  const auto bind = LoadAsset({{"nan.gltf", testing::MakeSkinnedGltf(Options([](auto& o) {
                                              o.nan_in_inverse_bind = true;
                                            })).json}});
  ASSERT_EQ(bind.status().code(), StatusCode::kInvalidArgument) << bind.status().ToString();
  EXPECT_NE(bind.status().message().find("non-finite"), std::string::npos);
  const auto keys = LoadAsset({{"nan.gltf", testing::MakeSkinnedGltf(Options([](auto& o) {
                                              o.nan_in_animation = true;
                                            })).json}});
  ASSERT_EQ(keys.status().code(), StatusCode::kInvalidArgument) << keys.status().ToString();
  EXPECT_NE(keys.status().message().find("non-finite"), std::string::npos);
}

TEST(LoadAsset, NanInBvhMotionIsRejected) {
  const std::string bvh =
      "HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 0\n  CHANNELS 6 Xposition Yposition Zposition "
      "Zrotation Xrotation Yrotation\n"
      "  JOINT Leg\n  {\n    OFFSET 0 -1 0\n    CHANNELS 3 Zrotation Xrotation Yrotation\n"
      "    End Site\n    {\n      OFFSET 0 -1 0\n    }\n  }\n}\nMOTION\nFrames: 2\nFrame Time: "
      "0.0333333\n"
      "0 0 0 0 0 0 0 0 0\n0 nan 0 0 0 0 0 0 0\n";
  const auto asset = LoadAsset({{"nan.bvh", bvh}});
  EXPECT_FALSE(asset.ok());
  const std::string good = bvh.substr(0, bvh.find("0 nan")) + "0 1 0 0 0 0 0 0 10\n";
  const auto fine = LoadAsset({{"fine.bvh", good}});
  ASSERT_TRUE(fine.ok()) << fine.status().ToString();
  EXPECT_EQ((*fine)->character().skeleton.parents.size(), 2u);
  EXPECT_TRUE((*fine)->has_proxy_skin());
  EXPECT_EQ((*fine)->animations()[0].source_frame_count, 2);
}

TEST(LoadAsset, UnknownGltfBufferIsNamedInTheError) {
  const auto asset =
      LoadAsset({{"fixture.gltf", testing::MakeSkinnedGltf(Uri("missing.bin")).json}});
  ASSERT_FALSE(asset.ok());
  EXPECT_NE(asset.status().message().find("missing.bin"), std::string::npos);
}

TEST(LoadAsset, HostileBufferUrisFailWithoutOpeningHostFiles) {
  // A real, valid buffer on disk: if any of these URIs reached the host file system the
  // import would succeed.
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / "motionlod_io_hostile";
  std::filesystem::create_directories(dir / "inner");
  const testing::GltfFixture plain = testing::MakeSkinnedGltf(Uri("x.bin"));
  std::ofstream(dir / "secret.bin", std::ios::binary) << plain.buffer;
  const std::string absolute = (dir / "secret.bin").string();
  for (const std::string& uri :
       {std::string("../../etc/passwd"), std::string("/etc/passwd"),
        std::string("file:///etc/passwd"), std::string("../secret.bin"), absolute,
        "file://" + absolute, std::string("inner/../../secret.bin"), std::string("..%2Fsecret.bin"),
        std::string("C:\\\\secret.bin")}) {
    SCOPED_TRACE(uri);
    const testing::GltfFixture fixture = testing::MakeSkinnedGltf(Uri(uri));
    const auto from_memory =
        LoadAsset({{"hostile.gltf", fixture.json}, {"secret.bin", plain.buffer}});
    EXPECT_FALSE(from_memory.ok());
    std::ofstream(dir / "inner" / "hostile.gltf", std::ios::binary) << fixture.json;
    const auto from_disk = LoadAssetFile(dir / "inner" / "hostile.gltf");
    EXPECT_FALSE(from_disk.ok());
  }
  // The same buffer named plainly is found, next to the file or among the given files.
  const testing::GltfFixture fine = testing::MakeSkinnedGltf(Uri("secret.bin"));
  std::ofstream(dir / "fine.gltf", std::ios::binary) << fine.json;
  EXPECT_TRUE(LoadAssetFile(dir / "fine.gltf").ok());
  EXPECT_TRUE(LoadAsset({{"fine.gltf", fine.json}, {"secret.bin", plain.buffer}}).ok());
  std::filesystem::remove_all(dir);
}

TEST(LoadAsset, FixtureTruncatedAnywhereFailsCleanly) {
  testing::GltfFixtureOptions options;
  options.glb_buffer = true;
  const testing::GltfFixture fixture = testing::MakeSkinnedGltf(options);
  const std::string glb = testing::MakeGlb(fixture.json, fixture.buffer);
  for (size_t size = 0; size < glb.size(); size += 7) {
    const auto asset = LoadAsset({{"cut.glb", glb.substr(0, size)}});
    EXPECT_FALSE(asset.ok()) << size;
  }
  for (size_t size = 0; size < fixture.json.size(); size += 13) {
    ExpectUsableOrError(LoadAsset({{"cut.gltf", testing::MakeSkinnedGltf().json.substr(0, size)}}));
  }
}

// Real files truncated at a few points: an error, never a crash.
TEST(LoadAsset, TruncatedManifestFilesFail) {
  MOTIONLOD_REQUIRE_DATA();
  for (const char* path : {"characters/CesiumMan.glb", "characters/Fox.glb", "characters/Orc.gltf",
                           "characters/stormtrooper.dae", "motions/cmu_131_01.bvh",
                           "motions/09_11_cmu.fbx", "characters/Superhero_Male_FullBody.gltf"}) {
    SCOPED_TRACE(path);
    const std::string bytes = testing::ReadBytes(testing::DataDir() / path);
    const std::string name = std::filesystem::path(path).filename().string();
    for (double fraction : {0.0005, 0.03, 0.5, 0.97}) {
      SCOPED_TRACE(fraction);
      const auto asset =
          LoadAsset({{name, bytes.substr(0, static_cast<size_t>(fraction * bytes.size()))}});
      EXPECT_FALSE(asset.ok());
    }
  }
}

// Random byte flips: an error or a usable asset, never a crash or hang.
TEST(LoadAsset, CorruptedManifestFilesFailOrStayUsable) {
  MOTIONLOD_REQUIRE_DATA();
  std::mt19937 random(1234);
  for (const char* path :
       {"characters/CesiumMan.glb", "characters/Fox.glb", "characters/RobotExpressive.glb",
        "motions/cmu_131_03.bvh", "motions/09_11_cmu.fbx", "characters/stormtrooper.dae"}) {
    SCOPED_TRACE(path);
    const std::string bytes = testing::ReadBytes(testing::DataDir() / path);
    const std::string name = std::filesystem::path(path).filename().string();
    for (int trial = 0; trial < 6; ++trial) {
      std::string damaged = bytes;
      const int flips = trial < 3 ? 1 : 64;
      for (int k = 0; k < flips; ++k) {
        // Headers and structure live near the start: bias half of the flips there.
        const size_t limit = (k % 2 == 0) ? std::min<size_t>(bytes.size(), 4096) : bytes.size();
        damaged[std::uniform_int_distribution<size_t>(0, limit - 1)(random)] ^=
            static_cast<char>(1 << std::uniform_int_distribution<int>(0, 7)(random));
      }
      SCOPED_TRACE(trial);
      ExpectUsableOrError(LoadAsset({{name, damaged}}));
    }
  }
}

}  // namespace
}  // namespace motionlod::io
