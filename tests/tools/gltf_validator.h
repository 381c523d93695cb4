// The checks of tools/gltf-validate (npm, installed by scripts/setup.sh) run on exported
// .glb files: the Khronos glTF validator, and three.js' GLTFLoader posing the skin.
#pragma once

#include <gtest/gtest.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

namespace motionlod::testing {

struct GltfValidation {
  std::string file;
  int errors = -1, warnings = -1;
  std::vector<std::string> messages;  // every error and warning, "severity CODE at pointer: text"
};

inline std::filesystem::path GltfValidatorDir() {
  return std::filesystem::path(MOTIONLOD_SOURCE_DIR) / "tools" / "gltf-validate";
}

// Empty when the validator can run; else why not (and how to install it).
inline std::string GltfValidatorMissing() {
  if (std::system("node --version >/dev/null 2>&1") != 0) return "node is not installed";
  for (const char* package : {"gltf-validator", "three"}) {
    if (!std::filesystem::exists(GltfValidatorDir() / "node_modules" / package)) {
      return std::string("tools/gltf-validate/node_modules/") + package +
             " is missing: run scripts/setup.sh";
    }
  }
  return "";
}

// Runs `command` (stderr too) and returns its output.
inline std::string RunForOutput(const std::string& command) {
  std::string output;
  FILE* pipe = ::popen((command + " 2>&1").c_str(), "r");
  if (pipe == nullptr) {
    ADD_FAILURE() << "cannot run " << command;
    return output;
  }
  char buffer[4096];
  while (size_t n = std::fread(buffer, 1, sizeof buffer, pipe)) output.append(buffer, n);
  ::pclose(pipe);
  return output;
}

// three.js' GLTFLoader on `file`, its first animation at `seconds` (three_pose.mjs):
// {bones, tracks, unbound, positions: [x, y, z, ...] world-space skinned vertices}; null
// (and a test failure) when it fails.
inline nlohmann::json ThreePose(const std::filesystem::path& file, double seconds) {
  const std::string missing = GltfValidatorMissing();
  if (!missing.empty()) {
    ADD_FAILURE() << "three.js cannot run: " << missing;
    return nullptr;
  }
  const std::string output =
      RunForOutput("node '" + (GltfValidatorDir() / "three_pose.mjs").string() + "' '" +
                   file.string() + "' " + std::to_string(seconds));
  nlohmann::json pose = nlohmann::json::parse(output, nullptr, false);
  if (!pose.is_object() || !pose.contains("positions")) {
    ADD_FAILURE() << "three_pose.mjs: " << output.substr(0, 2000);
    return nullptr;
  }
  return pose;
}

// One result per file, in order; a failed run adds a test failure and returns fewer.
inline std::vector<GltfValidation> ValidateGltf(const std::vector<std::filesystem::path>& files) {
  std::string command = "node '" + (GltfValidatorDir() / "validate.js").string() + "'";
  for (const auto& file : files) command += " '" + file.string() + "'";
  std::vector<GltfValidation> results;
  const std::string output = RunForOutput(command);
  std::istringstream lines(output);
  std::string line;
  while (std::getline(lines, line)) {
    const nlohmann::json report = nlohmann::json::parse(line, nullptr, false);
    if (!report.is_object() || !report.contains("errors")) {
      ADD_FAILURE() << "unexpected validator output: " << line;
      continue;
    }
    GltfValidation v;
    v.file = report["file"].get<std::string>();
    v.errors = report["errors"].get<int>();
    v.warnings = report["warnings"].get<int>();
    v.messages = report["messages"].get<std::vector<std::string>>();
    results.push_back(std::move(v));
  }
  EXPECT_EQ(results.size(), files.size()) << output;
  return results;
}

// The JSON chunk of a .glb (GLB header: magic, version, length; then the JSON chunk's
// length and type); null when `glb` is no GLB.
inline nlohmann::json GlbJson(const std::string& glb) {
  if (glb.size() < 20 || glb.compare(0, 4, "glTF") != 0) return nullptr;
  uint32_t length = 0;
  std::memcpy(&length, glb.data() + 12, 4);
  if (glb.compare(16, 4, "JSON") != 0 || 20 + size_t{length} > glb.size()) return nullptr;
  return nlohmann::json::parse(glb.substr(20, length), nullptr, false);
}

// Validates `files`, expects zero errors in each, and prints the warnings.
inline void ExpectValidGltf(const std::vector<std::filesystem::path>& files) {
  const std::string missing = GltfValidatorMissing();
  ASSERT_TRUE(missing.empty()) << "the glTF validator cannot run: " << missing;
  for (const GltfValidation& v : ValidateGltf(files)) {
    std::string all;
    for (const std::string& m : v.messages) all += "  " + m + "\n";
    EXPECT_EQ(v.errors, 0) << v.file << ":\n" << all;
    std::printf("gltf-validator: %s: %d errors, %d warnings\n%s", v.file.c_str(), v.errors,
                v.warnings, all.c_str());
  }
}

}  // namespace motionlod::testing
