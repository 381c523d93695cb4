// A writer of version 2.x of the level format, written by hand from the 2.0 tables of
// docs/level-format.md ("Version 2.0") and sharing no code with proto/level_format.cc:
// the files a build of major version 2 wrote, for the tests that this build still reads
// them (tests/proto/level_format_test.cc) and for a fuzz seed (fuzz/make_seeds.cc).
// Header-only; needs motionlod_proto (XXH64).
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <span>
#include <string>
#include <vector>

#include "proto/checksum.h"
#include "proto/level_format.h"

namespace motionlod::proto::test_v2 {

struct Version2Options {
  uint16_t minor_version = 0;
  uint32_t reserved = 0;         // the u32 at header offset 108 (0 in 2.0)
  std::string trailing_section;  // appended as a section of kind 40 when not empty
};

// `data` as a version 2.x file: every level's frames, kept joints, joint map and figures
// (a 2.0 level has no stride, mesh, influences or cost; those fields are ignored, and so
// is `data.vertex_count`). Empty `data.clips`: one unnamed clip of every frame. No
// validation.
inline std::string EncodeVersion2(const LevelSetData& data, const Version2Options& options = {}) {
  constexpr uint32_t kNoLevel = 0xFFFFFFFFu;
  const auto align16 = [](uint64_t x) { return (x + 15) & ~uint64_t{15}; };
  const auto bytes_of = [](const void* p, size_t size) {
    return std::string(static_cast<const char*>(p), size);
  };
  const auto length_prefixed = [&](const std::string& name) {
    const auto length = static_cast<uint16_t>(name.size());
    return bytes_of(&length, 2) + name;
  };
  struct Part {
    uint32_t kind;
    uint32_t level;
    std::string bytes;
  };
  std::vector<Part> parts;
  parts.push_back({1, kNoLevel, data.variant_name});
  std::string names;
  for (const std::string& name : data.joint_names) names += length_prefixed(name);
  parts.push_back({2, kNoLevel, names});
  parts.push_back({3, kNoLevel, bytes_of(data.parents.data(), 4 * data.parents.size())});
  std::string table;
  for (const LevelData& level : data.levels) {
    char record[32] = {};  // u32 m, f32[5] figures, u32[2] reserved
    const auto m = static_cast<uint32_t>(level.kept_joints.size());
    const float figures[5] = {level.figures.max_vertex_error_pct,
                              level.figures.mean_vertex_error_pct,
                              level.figures.mean_normal_error_deg, level.figures.mean_E,
                              level.figures.max_px_for_1px_error};
    std::memcpy(record, &m, 4);
    std::memcpy(record + 4, figures, sizeof figures);
    table += bytes_of(record, sizeof record);
  }
  parts.push_back({4, kNoLevel, table});
  std::vector<ClipInfo> clips = data.clips;
  if (clips.empty()) clips.push_back({"", 0, data.frame_count, data.fps});
  std::string clip_table;
  for (const ClipInfo& clip : clips) {
    char record[16];  // u32 first_frame, u32 frame_count, f64 fps
    std::memcpy(record, &clip.first_frame, 4);
    std::memcpy(record + 4, &clip.frame_count, 4);
    std::memcpy(record + 8, &clip.fps, 8);
    clip_table += bytes_of(record, sizeof record);
  }
  for (const ClipInfo& clip : clips) clip_table += length_prefixed(clip.name);
  parts.push_back({5, kNoLevel, clip_table});
  for (size_t l = 0; l < data.levels.size(); ++l) {
    const LevelData& level = data.levels[l];
    const auto index = static_cast<uint32_t>(l);
    parts.push_back({16, index, bytes_of(level.kept_joints.data(), 2 * level.kept_joints.size())});
    parts.push_back({17, index, bytes_of(level.joint_map.data(), 2 * level.joint_map.size())});
    parts.push_back({18, index, bytes_of(level.matrices.data(), 4 * level.matrices.size())});
  }
  if (!options.trailing_section.empty()) parts.push_back({40, kNoLevel, options.trailing_section});

  std::string out(112, '\0');
  const auto put = [&](size_t at, const auto& value) {
    std::memcpy(out.data() + at, &value, sizeof value);
  };
  std::memcpy(out.data(), "MLODLVLS", 8);
  put(8, uint16_t{2});
  put(10, options.minor_version);
  put(12, uint32_t{112});
  put(24, data.flags);
  put(28, data.algorithm_version);
  put(32, static_cast<uint32_t>(data.parents.size()));
  put(36, static_cast<uint32_t>(data.levels.size()));
  put(40, data.frame_count);
  put(44, static_cast<uint32_t>(parts.size()));
  put(48, data.fps);
  put(56, data.settings_hash);
  std::memcpy(out.data() + 64, data.source_hash.data(), 32);
  put(96, uint32_t{32});
  put(100, static_cast<uint32_t>(clips.size()));
  put(104, uint32_t{16});
  put(108, options.reserved);
  uint64_t cursor = align16(112 + 24 * parts.size());
  for (const Part& part : parts) {
    char entry[24];
    const uint64_t size = part.bytes.size();
    std::memcpy(entry, &part.kind, 4);
    std::memcpy(entry + 4, &part.level, 4);
    std::memcpy(entry + 8, &cursor, 8);
    std::memcpy(entry + 16, &size, 8);
    out += bytes_of(entry, sizeof entry);
    cursor = align16(cursor + size);
  }
  for (const Part& part : parts) {
    out.resize(align16(out.size()), '\0');
    out += part.bytes;
  }
  out.resize(align16(out.size()), '\0');
  out += "MLOD_END";
  put(16, uint64_t{out.size() + 8});
  const uint64_t checksum = Xxh64(std::as_bytes(std::span(out.data(), out.size())));
  out += bytes_of(&checksum, 8);
  return out;
}

}  // namespace motionlod::proto::test_v2
