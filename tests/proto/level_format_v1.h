// A writer of version 1.x of the level format, written by hand from the 1.0 tables of
// docs/level-format.md ("Version 1.0") and sharing no code with proto/level_format.cc:
// the files a build of major version 1 wrote, for the tests that this build still reads
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

namespace motionlod::proto::test_v1 {

struct Version1Options {
  uint16_t minor_version = 0;
  uint32_t reserved = 0;             // the u32 at header offset 100 (0 in 1.0)
  std::string trailing_section;      // appended as a section of kind 40 when not empty
  uint32_t extra_section_count = 0;  // added to section_count (a malformed directory)
};

// `data` as a version 1.x file; `data.clips` is ignored (1.x has none). No validation.
inline std::string EncodeVersion1(const LevelSetData& data, const Version1Options& options = {}) {
  constexpr uint32_t kNoLevel = 0xFFFFFFFFu;
  const auto align16 = [](uint64_t x) { return (x + 15) & ~uint64_t{15}; };
  const auto bytes_of = [](const void* p, size_t size) {
    return std::string(static_cast<const char*>(p), size);
  };
  struct Part {
    uint32_t kind;
    uint32_t level;
    std::string bytes;
  };
  std::vector<Part> parts;
  parts.push_back({1, kNoLevel, data.variant_name});
  std::string names;
  for (const std::string& name : data.joint_names) {
    const auto length = static_cast<uint16_t>(name.size());
    names += bytes_of(&length, 2) + name;
  }
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
  put(8, uint16_t{1});
  put(10, options.minor_version);
  put(12, uint32_t{112});
  put(24, data.flags);
  put(28, data.algorithm_version);
  put(32, static_cast<uint32_t>(data.parents.size()));
  put(36, static_cast<uint32_t>(data.levels.size()));
  put(40, data.frame_count);
  put(44, static_cast<uint32_t>(parts.size() + options.extra_section_count));
  put(48, data.fps);
  put(56, data.settings_hash);
  std::memcpy(out.data() + 64, data.source_hash.data(), 32);
  put(96, uint32_t{32});
  put(100, options.reserved);
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

}  // namespace motionlod::proto::test_v1
