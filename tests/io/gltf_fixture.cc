#include "gltf_fixture.h"

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <numbers>
#include <vector>

namespace motionlod::io::testing {
namespace {

class Buffer {
 public:
  // Appends values, 4-byte aligned; returns the offset.
  template <typename T>
  size_t Add(const std::vector<T>& values) {
    while (bytes_.size() % 4 != 0) bytes_.push_back('\0');
    const size_t offset = bytes_.size();
    const char* p = reinterpret_cast<const char*>(values.data());
    bytes_.append(p, p + values.size() * sizeof(T));
    return offset;
  }
  const std::string& bytes() const { return bytes_; }

 private:
  std::string bytes_;
};

std::string Base64(const std::string& bytes) {
  static const char kTable[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  size_t i = 0;
  for (; i + 2 < bytes.size(); i += 3) {
    const uint32_t v =
        (uint8_t(bytes[i]) << 16) | (uint8_t(bytes[i + 1]) << 8) | uint8_t(bytes[i + 2]);
    for (int s = 18; s >= 0; s -= 6) out += kTable[(v >> s) & 63];
  }
  if (i + 1 == bytes.size()) {
    const uint32_t v = uint8_t(bytes[i]) << 16;
    out += kTable[(v >> 18) & 63];
    out += kTable[(v >> 12) & 63];
    out += "==";
  } else if (i + 2 == bytes.size()) {
    const uint32_t v = (uint8_t(bytes[i]) << 16) | (uint8_t(bytes[i + 1]) << 8);
    out += kTable[(v >> 18) & 63];
    out += kTable[(v >> 12) & 63];
    out += kTable[(v >> 6) & 63];
    out += '=';
  }
  return out;
}

std::string View(size_t offset, size_t length) {
  return "{\"buffer\":0,\"byteOffset\":" + std::to_string(offset) +
         ",\"byteLength\":" + std::to_string(length) + "}";
}

}  // namespace

GltfFixture MakeSkinnedGltf(const GltfFixtureOptions& options) {
  Buffer b;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const size_t positions =
      b.Add(std::vector<float>{-0.5f, 0, 0, 0.5f, 0, 0, 0.5f, 2, 0, -0.5f, 2, 0});
  const size_t normals = b.Add(std::vector<float>{0, 0, 1, 0, 0, 1, 0, 0, 1, 0, 0, 1});
  const size_t joints = b.Add(std::vector<uint8_t>{0, 0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0});
  const size_t weights = b.Add(std::vector<float>{1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0});
  const size_t indices = b.Add(std::vector<uint16_t>{0, 1, 2, 0, 2, 3});
  const size_t ibm = b.Add(std::vector<float>{
      1,  0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0,
      0,  0, 1,  //
      1,  0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, options.nan_in_inverse_bind ? nan : 0.0f,
      -1, 0, 1});
  const size_t times = b.Add(std::vector<float>{0, 0.5f, 1});
  const float s45 = static_cast<float>(std::sin(std::numbers::pi / 8)),
              c45 = static_cast<float>(std::cos(std::numbers::pi / 8));
  const float s90 = static_cast<float>(std::sin(std::numbers::pi / 4)),
              c90 = static_cast<float>(std::cos(std::numbers::pi / 4));
  const size_t rotations = b.Add(std::vector<float>{0, 0, 0, 1, 0, 0, s45, c45, 0, 0, s90, c90});
  const size_t translations =
      b.Add(std::vector<float>{0, 0, 0, options.nan_in_animation ? nan : 1.0f, 0, 0, 2, 0, 0});
  GltfFixture fixture;
  fixture.buffer = b.bytes();
  const std::string uri = options.buffer_uri.empty()
                              ? "data:application/octet-stream;base64," + Base64(fixture.buffer)
                              : options.buffer_uri;

  std::string j = "{\"asset\":{\"version\":\"2.0\",\"generator\":\"motionlod test\"},";
  j += "\"scene\":0,\"scenes\":[{\"nodes\":[0,2]}],";
  j += "\"nodes\":[{\"name\":\"root\",\"children\":[1]},";
  j += "{\"name\":\"child\",\"translation\":[0,1,0]},";
  j += "{\"name\":\"body\",\"mesh\":0,\"skin\":0}],";
  j += "\"skins\":[{\"joints\":[0,1],\"inverseBindMatrices\":5}],";
  j +=
      "\"meshes\":[{\"name\":\"body\",\"primitives\":[{\"attributes\":{\"POSITION\":0,\"NORMAL\":1,"
      "\"JOINTS_0\":2,\"WEIGHTS_0\":3},\"indices\":4}]}],";
  j += "\"accessors\":[";
  j += "{\"bufferView\":0,\"componentType\":5126,\"count\":4,\"type\":\"VEC3\",\"min\":[-0.5,0,0],"
       "\"max\":[0.5,2,0]},";
  j += "{\"bufferView\":1,\"componentType\":5126,\"count\":4,\"type\":\"VEC3\"},";
  j += "{\"bufferView\":2,\"componentType\":5121,\"count\":4,\"type\":\"VEC4\"},";
  j += "{\"bufferView\":3,\"componentType\":5126,\"count\":4,\"type\":\"VEC4\"},";
  j += "{\"bufferView\":4,\"componentType\":5123,\"count\":6,\"type\":\"SCALAR\"},";
  j += "{\"bufferView\":5,\"componentType\":5126,\"count\":2,\"type\":\"MAT4\"},";
  j += "{\"bufferView\":6,\"componentType\":5126,\"count\":3,\"type\":\"SCALAR\",\"min\":[0],"
       "\"max\":[1]},";
  j += "{\"bufferView\":7,\"componentType\":5126,\"count\":3,\"type\":\"VEC4\"},";
  j += "{\"bufferView\":8,\"componentType\":5126,\"count\":3,\"type\":\"VEC3\"}],";
  j += "\"bufferViews\":[" + View(positions, 48) + "," + View(normals, 48) + "," +
       View(joints, 16) + "," + View(weights, 64) + "," + View(indices, 12) + "," + View(ibm, 128) +
       "," + View(times, 12) + "," + View(rotations, 48) + "," + View(translations, 36) + "],";
  if (options.with_animation) {
    j += "\"animations\":[{\"name\":\"Bend\",\"samplers\":[{\"input\":6,\"output\":7},{\"input\":6,"
         "\"output\":8}],"
         "\"channels\":[{\"sampler\":0,\"target\":{\"node\":1,\"path\":\"rotation\"}},"
         "{\"sampler\":1,\"target\":{\"node\":0,\"path\":\"translation\"}}]}],";
  }
  j += "\"buffers\":[{\"byteLength\":" + std::to_string(fixture.buffer.size());
  if (!options.glb_buffer) j += ",\"uri\":\"" + uri + "\"";
  j += "}]}";
  fixture.json = j;
  return fixture;
}

std::string MakeGlb(const std::string& json, const std::string& bin) {
  std::string padded_json = json;
  while (padded_json.size() % 4 != 0) padded_json += ' ';
  std::string padded_bin = bin;
  while (padded_bin.size() % 4 != 0) padded_bin += '\0';
  auto u32 = [](uint32_t v) {
    std::string s(4, '\0');
    for (int i = 0; i < 4; ++i) s[i] = static_cast<char>((v >> (8 * i)) & 255);
    return s;
  };
  const uint32_t total = static_cast<uint32_t>(12 + 8 + padded_json.size() + 8 + padded_bin.size());
  std::string glb = "glTF" + u32(2) + u32(total);
  glb += u32(static_cast<uint32_t>(padded_json.size())) + "JSON" + padded_json;
  glb += u32(static_cast<uint32_t>(padded_bin.size())) + std::string("BIN\0", 4) + padded_bin;
  return glb;
}

}  // namespace motionlod::io::testing
