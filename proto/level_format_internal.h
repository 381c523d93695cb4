// Layout constants of the level format and a writer hook for tests: not the API.
// docs/level-format.md is the normative description; these constants mirror its tables.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "base/status.h"
#include "proto/level_format.h"

namespace motionlod::proto::internal {

inline constexpr char kMagic[8] = {'M', 'L', 'O', 'D', 'L', 'V', 'L', 'S'};
inline constexpr char kTrailerMagic[8] = {'M', 'L', 'O', 'D', '_', 'E', 'N', 'D'};

// File header (every version so far: 112 bytes); byte offsets of its fields.
inline constexpr uint32_t kHeaderSize = 112;
inline constexpr size_t kOffsetMagic = 0;              // char[8]
inline constexpr size_t kOffsetMajorVersion = 8;       // u16
inline constexpr size_t kOffsetMinorVersion = 10;      // u16
inline constexpr size_t kOffsetHeaderSize = 12;        // u32
inline constexpr size_t kOffsetFileSize = 16;          // u64
inline constexpr size_t kOffsetFlags = 24;             // u32
inline constexpr size_t kOffsetAlgorithmVersion = 28;  // u32
inline constexpr size_t kOffsetJointCount = 32;        // u32 n
inline constexpr size_t kOffsetLevelCount = 36;        // u32 L
inline constexpr size_t kOffsetFrameCount = 40;        // u32 T
inline constexpr size_t kOffsetSectionCount = 44;      // u32 S
inline constexpr size_t kOffsetFps = 48;               // f64
inline constexpr size_t kOffsetSettingsHash = 56;      // u64
inline constexpr size_t kOffsetSourceHash = 64;        // u8[32]
inline constexpr size_t kOffsetLevelRecordSize = 96;   // u32
inline constexpr size_t kOffsetClipCount = 100;        // u32 C (2.x, 3.x)
inline constexpr size_t kOffsetClipRecordSize = 104;   // u32 (2.x, 3.x)
inline constexpr size_t kOffsetVertexCount = 108;      // u32 p (3.x)
// Version 2.x: offset 108 is reserved, 0.
inline constexpr size_t kV2OffsetReserved = 108;  // u32, 0
// Version 1.x: offsets 100 (u32) and 104 (u64) are reserved, 0.
inline constexpr size_t kV1OffsetReserved0 = 100;  // u32, 0
inline constexpr size_t kV1OffsetReserved1 = 104;  // u64, 0

// Section directory entry: kind u32, level u32, offset u64, size u64.
inline constexpr uint32_t kDirectoryEntrySize = 24;
inline constexpr uint32_t kNoLevel = 0xFFFFFFFFu;  // `level` of a global section

// Level record (version 3.0: 48 bytes), one per level in the level table.
inline constexpr uint32_t kLevelRecordSize = 48;
inline constexpr size_t kRecordOffsetKeptCount = 0;             // u32 m
inline constexpr size_t kRecordOffsetFigures = 4;               // f32[5], LevelFigures order
inline constexpr size_t kRecordOffsetFrameStride = 24;          // u32 r, 1 .. 16
inline constexpr size_t kRecordOffsetInfluencesPerVertex = 28;  // u32 k, 0 .. 8
inline constexpr size_t kRecordOffsetVertexCount = 32;          // u32, the level's own vertices
inline constexpr size_t kRecordOffsetTriangleCount = 36;        // u32
inline constexpr size_t kRecordOffsetCost = 40;                 // f32
inline constexpr size_t kRecordOffsetReserved = 44;             // u32, 0
// Versions 1.x and 2.x: 32 bytes, the kept count and figures as above, then u32[2] 0.
inline constexpr uint32_t kV2LevelRecordSize = 32;
inline constexpr size_t kV2RecordOffsetReserved = 24;  // u32[2], 0

// Clip record (version 2.0: 16 bytes), C of them at the start of the clip table; the C
// length-prefixed names (u16 byte length, UTF-8 bytes) follow the last record.
inline constexpr uint32_t kClipRecordSize = 16;
inline constexpr size_t kClipOffsetFirstFrame = 0;  // u32
inline constexpr size_t kClipOffsetFrameCount = 4;  // u32
inline constexpr size_t kClipOffsetFps = 8;         // f64

// Trailer: char[8] kTrailerMagic, then u64 XXH64 (seed 0) of every preceding byte.
inline constexpr uint32_t kTrailerSize = 16;

enum class SectionKind : uint32_t {
  kVariantName = 1,        // global: UTF-8 bytes
  kJointNames = 2,         // global: n x (u16 byte length, UTF-8 bytes)
  kJointParents = 3,       // global: n x i32
  kLevelTable = 4,         // global: L x level record
  kClipTable = 5,          // global (2.x): C x clip record, then C x (u16 byte length, UTF-8)
  kKeptJoints = 16,        // per level: m x u16
  kJointMap = 17,          // per level: n x u16
  kMatrices = 18,          // per level: T' x m x 12 x f32 (T before 3.0)
  kVertices = 19,          // per level (3.x): u32[V_l], the level's own vertex ids
  kTriangles = 20,         // per level (3.x): u32[3 x triangle_count], indices into the vertices
  kInfluenceSlots = 21,    // per level (3.x): u16[V x k]
  kInfluenceWeights = 22,  // per level (3.x): f32[V x k]
};
inline constexpr uint32_t kGlobalSectionCount = 5;    // 2.x, 3.x: kinds 1 to 5, in kind order
inline constexpr uint32_t kV1GlobalSectionCount = 4;  // 1.x: kinds 1 to 4
inline constexpr uint32_t kSectionsPerLevel = 7;      // 3.x: kinds 16 to 22, in kind order
inline constexpr uint32_t kV2SectionsPerLevel = 3;    // 1.x, 2.x: kinds 16 to 18

// A section a writer of a later minor version might append.
struct ExtraSection {
  uint32_t kind = 0;
  uint32_t level = kNoLevel;
  std::string bytes;
};

// What a writer of another version could do differently; the defaults write exactly
// what EncodeLevelSet writes. For forward-compatibility and rejection tests only.
struct WriterOptions {
  uint16_t major_version = kLevelFormatMajorVersion;
  uint16_t minor_version = kLevelFormatMinorVersion;
  uint32_t header_size = kHeaderSize;             // multiple of 16, >= kHeaderSize
  uint32_t level_record_size = kLevelRecordSize;  // multiple of 4, >= kLevelRecordSize
  uint32_t clip_record_size = kClipRecordSize;    // multiple of 8, >= kClipRecordSize
  uint8_t extension_fill = 0;                // bytes past the known header, level and clip records
  uint32_t extra_flags = 0;                  // or-ed into the flags, unvalidated
  std::vector<ExtraSection> extra_sections;  // appended after the known sections
};

// Validates `data` (as ValidateLevelSet, on `run`) and writes it as `options` say.
StatusOr<std::string> EncodeLevelSetWithOptions(const LevelSetRef& data,
                                                const WriterOptions& options,
                                                const PieceRunner& run = {});

}  // namespace motionlod::proto::internal
