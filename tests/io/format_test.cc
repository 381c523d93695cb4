#include "io/format.h"

#include <gtest/gtest.h>

#include <string>

namespace motionlod::io {
namespace {

const std::vector<std::string>& All() { return AllFormatExtensions(); }

std::string Glb(uint32_t version, uint32_t declared, size_t size) {
  std::string bytes = "glTF";
  for (uint32_t v : {version, declared}) {
    for (int i = 0; i < 4; ++i) bytes += static_cast<char>((v >> (8 * i)) & 255);
  }
  bytes.resize(size, ' ');
  return bytes;
}

TEST(DetectFormat, RecognisesEachFormatByContent) {
  EXPECT_EQ(*DetectFormat("a.glb", Glb(2, 64, 64), All()), Format::kGlb);
  EXPECT_EQ(*DetectFormat("a.gltf", " \n{\"asset\":{\"version\":\"2.0\"}}", All()), Format::kGltf);
  EXPECT_EQ(
      *DetectFormat("a.FBX", std::string("Kaydara FBX Binary  \0\x1a\0\xe8\x1c\0\0", 27), All()),
      Format::kFbx);
  EXPECT_EQ(*DetectFormat("a.fbx", "; FBX 7.4.0 project file\nFBXHeaderExtension:  {", All()),
            Format::kFbx);
  EXPECT_EQ(*DetectFormat("a.dae", "<?xml version=\"1.0\"?>\n<COLLADA xmlns=\"x\">", All()),
            Format::kCollada);
  EXPECT_EQ(*DetectFormat("a.bvh", "\xEF\xBB\xBFHIERARCHY\nROOT Hips", All()), Format::kBvh);
  EXPECT_EQ(*DetectFormat("a.x", "xof 0303txt 0032\n", All()), Format::kDirectX);
  EXPECT_EQ(*DetectFormat("a.smd", "// exported\nversion 1\nnodes\n", All()), Format::kSmd);
}

TEST(DetectFormat, GltfExtensionAcceptsBinaryContentAndViceVersa) {
  EXPECT_EQ(*DetectFormat("a.gltf", Glb(2, 64, 64), All()), Format::kGlb);
  EXPECT_EQ(*DetectFormat("a.glb", "{\"asset\":{}}", All()), Format::kGltf);
}

TEST(DetectFormat, RejectsExtensionsOutsideTheAllowedList) {
  const StatusOr<Format> obj = DetectFormat("a.obj", "v 0 0 0\n", All());
  ASSERT_FALSE(obj.ok());
  EXPECT_EQ(obj.status().code(), StatusCode::kUnsupported);
  EXPECT_NE(obj.status().message().find(".obj"), std::string::npos);
  EXPECT_EQ(DetectFormat("noextension", "HIERARCHY", All()).status().code(),
            StatusCode::kUnsupported);
  EXPECT_EQ(DetectFormat("a.bvh", "HIERARCHY", {"glb"}).status().code(), StatusCode::kUnsupported);
}

TEST(DetectFormat, RejectsNamesWithDirectories) {
  EXPECT_EQ(DetectFormat("../a.bvh", "HIERARCHY", All()).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(DetectFormat("/etc/a.bvh", "HIERARCHY", All()).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(DetectFormat("", "HIERARCHY", All()).status().code(), StatusCode::kInvalidArgument);
}

TEST(DetectFormat, RejectsEmptyBytes) {
  const StatusOr<Format> empty = DetectFormat("a.glb", "", All());
  EXPECT_EQ(empty.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(empty.status().message().find("empty"), std::string::npos);
}

TEST(DetectFormat, RejectsContentOfAnotherFormat) {
  EXPECT_EQ(DetectFormat("a.glb", "HIERARCHY\nROOT", All()).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(DetectFormat("a.bvh", "glTF....", All()).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(DetectFormat("a.dae", "{\"asset\":{}}", All()).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(DetectFormat("a.dae", "<?xml version=\"1.0\"?><svg/>", All()).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(DetectFormat("a.fbx", "hello", All()).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(DetectFormat("a.x", "xyz", All()).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(DetectFormat("a.gltf", "[1,2]", All()).status().code(), StatusCode::kInvalidArgument);
}

TEST(DetectFormat, ReportsTruncatedBinaryGltfHeaders) {
  EXPECT_EQ(DetectFormat("a.glb", "glTF\x02", All()).status().code(), StatusCode::kDataLoss);
  const StatusOr<Format> cut = DetectFormat("a.glb", Glb(2, 1000, 100), All());
  EXPECT_EQ(cut.status().code(), StatusCode::kDataLoss);
  EXPECT_NE(cut.status().message().find("1000"), std::string::npos);
  EXPECT_EQ(DetectFormat("a.glb", Glb(7, 64, 64), All()).status().code(), StatusCode::kUnsupported);
}

TEST(LowerExtension, LowerCasesTheLastSuffix) {
  EXPECT_EQ(LowerExtension("Model.GLB"), "glb");
  EXPECT_EQ(LowerExtension("a.b.Bvh"), "bvh");
  EXPECT_EQ(LowerExtension("a."), "");
  EXPECT_EQ(LowerExtension("a"), "");
}

}  // namespace
}  // namespace motionlod::io
