// A tiny skinned, animated glTF written by hand, for tests that need exact answers or
// hostile variations (external buffer URIs, NaN in the data, truncation).
//
// Joints: "root" (node 0, at the origin) and its child "child" (node 1, at (0, 1, 0)).
// Mesh "body" (node 2, skin 0): a quad from (-0.5, 0, 0) to (0.5, 2, 0), normals +z; the
// two vertices at y = 0 are weighted 1 to root, the two at y = 2 to child. Inverse bind
// matrices: identity and translate(0, -1, 0).
// Animation "Bend", keys at 0, 0.5 and 1 s (2 fps): child rotates about +z by 0, 45 and
// 90 degrees; root translates to (0,0,0), (1,0,0), (2,0,0).
#pragma once

#include <string>

namespace motionlod::io::testing {

struct GltfFixtureOptions {
  std::string buffer_uri;   // "" embeds the buffer as a base64 data URI
  bool glb_buffer = false;  // no uri at all: the buffer is a GLB's BIN chunk
  bool with_animation = true;
  bool nan_in_inverse_bind = false;
  bool nan_in_animation = false;
};

struct GltfFixture {
  std::string json;
  std::string buffer;  // the binary buffer (also embedded when buffer_uri is empty)
};

GltfFixture MakeSkinnedGltf(const GltfFixtureOptions& options = {});

// A GLB container around `json` and `bin` (the JSON's buffer 0 must have no uri).
std::string MakeGlb(const std::string& json, const std::string& bin);

}  // namespace motionlod::io::testing
