// The import worker's wire format (io/asset_wire.h): what the worker sends back must
// rebuild exactly the asset the importer made, and a reply from a misbehaving worker
// (cut off, corrupted, hostile but correctly checksummed) must be refused with DataLoss.
#include "io/asset_wire.h"

#include <gtest/gtest.h>

#include <cstring>

#include "base/hash.h"
#include "test_util.h"

namespace motionlod::io {
namespace {

using testing::DataAsset;
using testing::DataDir;
using testing::ReadBytes;

// Rewrites the checksum so that a deliberate corruption reaches the decoder's checks.
std::string Rechecksummed(std::string message) {
  const uint64_t checksum = Fnv1a64(std::string_view(message).substr(kWireHeaderBytes));
  std::memcpy(message.data() + 24, &checksum, 8);
  return message;
}

void ExpectMalformed(const StatusOr<std::shared_ptr<const Asset>>& reply) {
  ASSERT_FALSE(reply.ok());
  EXPECT_EQ(reply.status().code(), StatusCode::kDataLoss);
  EXPECT_EQ(reply.status().message().rfind("malformed import reply", 0), 0u)
      << reply.status().message();
}

class AssetWireOnData : public ::testing::TestWithParam<const char*> {};

TEST_P(AssetWireOnData, ReplyRebuildsTheSameAsset) {
  MOTIONLOD_REQUIRE_DATA();
  const std::shared_ptr<const Asset> original = DataAsset(GetParam());
  ASSERT_NE(original, nullptr);
  const std::string reply = EncodeImportReply(original);
  const StatusOr<std::shared_ptr<const Asset>> decoded = DecodeImportReply(reply);
  ASSERT_TRUE(decoded.ok()) << decoded.status().ToString();
  // Every field travels bit for bit: re-encoding gives the same bytes.
  EXPECT_EQ(EncodeImportReply(*decoded), reply);

  const core::RawCharacter& a = original->character();
  const core::RawCharacter& b = (*decoded)->character();
  EXPECT_EQ(a.skeleton.joint_names, b.skeleton.joint_names);
  EXPECT_EQ(a.skin.positions.size(), b.skin.positions.size());
  EXPECT_EQ(a.skin.influence_weights, b.skin.influence_weights);
  EXPECT_EQ(original->has_proxy_skin(), (*decoded)->has_proxy_skin());
  EXPECT_EQ(original->warnings(), (*decoded)->warnings());
  ASSERT_EQ(original->animations().size(), (*decoded)->animations().size());
  for (size_t k = 0; k < original->animations().size(); ++k) {
    const AnimationInfo& info = original->animations()[k];
    EXPECT_EQ(info.name, (*decoded)->animations()[k].name);
    EXPECT_EQ(info.source_frame_count, (*decoded)->animations()[k].source_frame_count);
    // Sampling (what bakes use) gives identical matrices.
    const auto m1 = original->SampleAnimation(info.name, 30);
    const auto m2 = (*decoded)->SampleAnimation(info.name, 30);
    ASSERT_EQ(m1.ok(), m2.ok());
    if (!m1.ok()) continue;
    ASSERT_EQ(m1->joint_world.size(), m2->joint_world.size());
    for (size_t q = 0; q < m1->joint_world.size(); ++q)
      ASSERT_EQ(m1->joint_world[q], m2->joint_world[q]) << info.name << " matrix " << q;
  }
}

INSTANTIATE_TEST_SUITE_P(Data, AssetWireOnData,
                         ::testing::Values("characters/CesiumMan.glb", "characters/Orc.gltf",
                                           "characters/stormtrooper.dae", "characters/Knight.glb",
                                           "motions/cmu_131_01.bvh", "motions/07_01_cmu.fbx"));

TEST(AssetWire, RequestCarriesFilesAndOptions) {
  LoadOptions options;
  options.max_influences = 4;
  options.max_total_bytes = 12345;
  options.allowed_extensions = {"gltf", "bvh"};
  const std::vector<SourceFile> files = {{"a.gltf", std::string("{\0}", 3)}, {"a.bin", "xyz"}};
  const auto request = DecodeImportRequest(EncodeImportRequest(files, options));
  ASSERT_TRUE(request.ok()) << request.status().ToString();
  ASSERT_EQ(request->files.size(), 2u);
  EXPECT_EQ(request->files[0].name, "a.gltf");
  EXPECT_EQ(request->files[0].bytes, std::string("{\0}", 3));
  EXPECT_EQ(request->files[1].bytes, "xyz");
  EXPECT_EQ(request->options.max_influences, 4);
  EXPECT_EQ(request->options.max_total_bytes, 12345u);
  EXPECT_EQ(request->options.allowed_extensions, options.allowed_extensions);
}

TEST(AssetWire, ErrorReplyKeepsTheImportersStatus) {
  const auto reply = DecodeImportReply(
      EncodeImportReply(Status(StatusCode::kUnsupported, "'x.obj' is not allowed")));
  ASSERT_FALSE(reply.ok());
  EXPECT_EQ(reply.status().code(), StatusCode::kUnsupported);
  EXPECT_EQ(reply.status().message(), "'x.obj' is not allowed");
}

TEST(AssetWire, ErrorReplyWithAnotherStatusCodeIsMalformed) {
  // A worker may not make the daemon report an internal error (or success without asset).
  for (StatusCode code : {StatusCode::kOk, StatusCode::kInternal}) {
    ExpectMalformed(DecodeImportReply(EncodeImportReply(Status(code, "x"))));
  }
}

TEST(AssetWire, EveryTruncationAndBitFlipIsRefused) {
  MOTIONLOD_REQUIRE_DATA();
  const std::string reply = EncodeImportReply(DataAsset("characters/Fox.glb"));
  for (size_t size = 0; size < reply.size(); size += 1 + size / 8) {
    ExpectMalformed(DecodeImportReply(std::string_view(reply).substr(0, size)));
  }
  ExpectMalformed(DecodeImportReply(reply + "x"));
  for (size_t at = 0; at < reply.size(); at += 97) {
    std::string flipped = reply;
    flipped[at] = static_cast<char>(flipped[at] ^ 0x20);
    ExpectMalformed(DecodeImportReply(flipped));
  }
}

// A hostile worker can compute checksums: the content checks must hold on their own.
TEST(AssetWire, ChecksummedHostileContentIsRefused) {
  MOTIONLOD_REQUIRE_DATA();
  const std::string reply = EncodeImportReply(DataAsset("characters/Fox.glb"));
  // Payload: character name (u32 length + bytes), joint names (u32 count ...).
  uint32_t name_length = 0;
  std::memcpy(&name_length, reply.data() + kWireHeaderBytes, 4);
  const size_t joint_count_at = kWireHeaderBytes + 4 + name_length;

  std::string huge_count = reply;  // more joints than bytes left: refused before allocation
  const uint32_t huge = 0xffffffffu;
  std::memcpy(huge_count.data() + joint_count_at, &huge, 4);
  ExpectMalformed(DecodeImportReply(Rechecksummed(huge_count)));

  std::string huge_name = reply;  // a name longer than the message
  std::memcpy(huge_name.data() + kWireHeaderBytes, &huge, 4);
  ExpectMalformed(DecodeImportReply(Rechecksummed(huge_name)));

  // Every single-byte change that decodes must still be a valid asset; the rest refused.
  int accepted = 0, refused = 0;
  for (size_t at = kWireHeaderBytes; at < reply.size(); at += reply.size() / 300) {
    std::string changed = reply;
    changed[at] = static_cast<char>(0xff);
    const auto decoded = DecodeImportReply(Rechecksummed(changed));
    if (decoded.ok()) {
      ++accepted;
      EXPECT_TRUE(core::ValidateRawCharacter((*decoded)->character()).ok());
    } else {
      ++refused;
      EXPECT_EQ(decoded.status().code(), StatusCode::kDataLoss);
    }
  }
  EXPECT_GT(refused, 0);
  EXPECT_GE(accepted + refused, 290);
}

TEST(AssetWire, WrongKindAndVersionAreRefused) {
  const std::string request = EncodeImportRequest({}, LoadOptions{});
  ExpectMalformed(DecodeImportReply(request));  // a request is no reply
  std::string version = EncodeImportReply(Status(StatusCode::kDataLoss, "x"));
  version[8] = static_cast<char>(kAssetWireVersion + 1);
  ExpectMalformed(DecodeImportReply(version));
  EXPECT_EQ(DecodeImportRequest("MLODWIRE").status().code(), StatusCode::kDataLoss);
}

TEST(AssetWire, RealFileRoundTripsThroughTheRequest) {
  MOTIONLOD_REQUIRE_DATA();
  const std::string bytes = ReadBytes(DataDir() / "motions/cmu_131_03.bvh");
  const auto request = DecodeImportRequest(EncodeImportRequest({{"clip.bvh", bytes}}, {}));
  ASSERT_TRUE(request.ok());
  const auto asset = LoadAsset(request->files, request->options);
  ASSERT_TRUE(asset.ok()) << asset.status().ToString();
  EXPECT_EQ((*asset)->character().skeleton.parents.size(), 31u);  // MANIFEST: 31 joints
}

}  // namespace
}  // namespace motionlod::io
