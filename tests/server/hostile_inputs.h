// Real hostile uploads shared by the import sandbox and daemon tests.
#pragma once

#include <string>

namespace motionlod::server::testing {

// A DirectX file whose mesh declares 200 million vertices: Assimp sizes its arrays from
// the count before reading them (2.4 GB; measured without a limit: 2.35 GB resident, 2 s).
inline constexpr const char* kHugeVertexCountX =
    "xof 0303txt 0032\n"
    "Frame Root {\n"
    " FrameTransformMatrix { 1.0,0.0,0.0,0.0,0.0,1.0,0.0,0.0,0.0,0.0,1.0,0.0,0.0,0.0,0.0,1.0;; }\n"
    " Mesh m {\n  200000000;\n  0.0;0.0;0.0;;\n  1;\n  3;0,0,0;;\n }\n"
    "}\n";

// 79 bytes of Valve SMD on which Assimp 5.2's SMD importer never returns (found by
// import_smd_fuzz on 2026-11-22, mutated from scripts/fuzz.sh's seed; the stack is in
// Assimp::BaseImporter::ReadFile). Only the worker's CPU and wall-clock limits end it.
inline constexpr const char* kHangingSmd =
    "version 1\nnodes\n0\xcd \"root\" -1\n1 \"ar\n1 0 1 0 0.5 0 0\nen:\ntriangles\nskin\n"
    "1 0 0end\n";

// A glTF whose only buffer has the URI `uri`.
inline std::string GltfWithBufferUri(const std::string& uri) {
  return R"({"asset":{"version":"2.0"},"buffers":[{"uri":")" + uri +
         R"(","byteLength":64}],"bufferViews":[{"buffer":0,"byteLength":64}],)"
         R"("accessors":[{"bufferView":0,"componentType":5126,"count":4,"type":"VEC3"}],)"
         R"("meshes":[{"primitives":[{"attributes":{"POSITION":0}}]}],"nodes":[{"mesh":0}],)"
         R"("scenes":[{"nodes":[0]}],"scene":0})";
}

}  // namespace motionlod::server::testing
