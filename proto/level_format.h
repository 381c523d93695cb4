// The Motion LoD level-set format: the bake tool writes a whole level set, the server
// streams single levels (the same format with one level), the thin client decodes
// without copying the frame data. The byte layout, versioning and validation rules are
// in docs/level-format.md; this header is the API.
//
// Letters (as in core/types.h): j joint of the original skeleton (n of them), l level
// (L), t frame (T), s slot of a kept joint within a level (m kept joints), c clip (C).
// A level set covers the clips (animations) of one character with one reduced skeleton
// per level: the frames of every clip, concatenated clip after clip, are the level's T
// frames, and the clip table says which frames are which clip.
// K'_s(t): the skinning matrix of kept joint s at frame t. It maps a bind-pose,
// model-space point to posed model space: p' = A p + b, stored as the top three rows of
// the 4x4 affine [A | b], row-major, float32:
//   { A00 A01 A02 b0  A10 A11 A12 b1  A20 A21 A22 b2 }.
//
// Writing: fill a LevelSetData (or a LevelSetRef of views of arrays the caller already
// has), EncodeLevelSet (validates, then writes).
// Reading: DecodeLevelSet checks everything (checksum, structure, semantics) and returns
// a LevelSetView whose spans point into the caller's buffer; the buffer must start on a
// 16-byte boundary (AlignedBytes::CopyOf otherwise) and outlive the view.
#pragma once

#include <array>
#include <bit>
#include <cassert>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "base/pieces.h"
#include "base/status.h"
#include "proto/aligned_bytes.h"

namespace motionlod::proto {

static_assert(std::endian::native == std::endian::little,
              "the level format is viewed in place: proto needs a little-endian host");
static_assert(std::numeric_limits<float>::is_iec559 && sizeof(float) == 4,
              "the level format stores IEEE-754 binary32 floats");

using ::motionlod::Status;
using ::motionlod::StatusOr;

// Format version written by this build. It reads every minor version of its major and
// of majors 2 (levels without their own mesh, influences or pose rate) and 1 (also one
// unnamed clip of every frame); another major version is refused (see
// docs/level-format.md, "Versioning").
inline constexpr uint16_t kLevelFormatMajorVersion = 3;
inline constexpr uint16_t kLevelFormatMinorVersion = 0;
// The oldest major version this build reads.
inline constexpr uint16_t kOldestReadableMajorVersion = 1;

// LevelSetData::flags bits.
// Every K'_s(t) is a rotation plus a translation (A orthonormal, det A = +1, checked
// to 1e-3): a client may transform normals by A instead of its inverse transpose.
inline constexpr uint32_t kLevelSetFlagRigid = 1u << 0;
inline constexpr uint32_t kKnownLevelSetFlags = kLevelSetFlagRigid;

inline constexpr uint32_t kMaxJointCount = 65535;  // joint indices and slots are u16
inline constexpr uint32_t kMaxLevelCount = 65535;
inline constexpr size_t kMaxNameBytes = 65535;  // joint, clip and variant names, UTF-8 bytes
inline constexpr size_t kMatrixFloats = 12;     // one 3x4 row-major K'_s(t)
inline constexpr uint32_t kMaxInfluencesPerVertex = 8;  // a level's own influences, k
inline constexpr uint32_t kMaxFrameStride = 16;         // a level's pose rate: fps / stride

// How many frames a clip of `frame_count` frames stores at frame stride `stride`: its
// frames 0, r, 2r, ... and its last (core/pose_rate.h computes the same).
inline uint32_t StoredFrameCount(uint32_t frame_count, uint32_t stride) {
  return frame_count <= 1 ? 1 : (frame_count - 2) / stride + 2;
}

// Quality figures of one level, as the bake measured them.
struct LevelFigures {
  float max_vertex_error_pct = 0;   // max over frames and vertices, % of character height
  float mean_vertex_error_pct = 0;  // mean over frames and vertices, % of character height
  float mean_normal_error_deg = 0;  // mean angle between reference and level normals, degrees
  float mean_E = 0;                 // mean over frames of the paper's objective E (core's units)
  // The largest on-screen character height, in pixels, at which this level's max
  // vertex error stays within one pixel (100 / max_vertex_error_pct); +inf when the
  // level is exact.
  float max_px_for_1px_error = std::numeric_limits<float>::infinity();

  bool operator==(const LevelFigures&) const = default;
};

// One level: m kept joints; since 3.0 also, optionally, its own mesh (a subset of the
// character's vertices with its own triangles), its own influences (k per vertex) and a
// pose rate (every `frame_stride`-th frame of each clip stored).
struct LevelData {
  // m original joint indices, strictly ascending; contains joint 0 (the root).
  std::vector<uint16_t> kept_joints;
  // n; joint_map[j] is the slot s (index into kept_joints) of the kept joint that drives
  // original joint j: its own slot when j is kept, else its nearest kept ancestor's
  // (ComputeJointMap builds it).
  std::vector<uint16_t> joint_map;
  LevelFigures figures = {};
  // Each clip stores its frames 0, r, 2r, ... and its last (StoredFrameCount), r =
  // frame_stride in [1, kMaxFrameStride]; a player interpolates the frames between two
  // stored ones (rigid sets: slerp of the rotation and lerp of the translation; otherwise
  // lerp of every entry). T' = sum over clips of StoredFrameCount(frames, r).
  uint32_t frame_stride = 1;
  // T' x m x 12: matrices[(t' * m + s) * 12 + k], K'_s of stored frame t', clip after
  // clip, as described above; finite.
  std::vector<float> matrices;
  // The level's own mesh: original vertex ids (strictly ascending, < the set's
  // vertex_count) and triangles over them (3 indices into `vertices` each). Both empty:
  // the character's whole mesh and triangles. Needs the set's vertex_count.
  std::vector<uint32_t> vertices = {};
  std::vector<uint32_t> triangles = {};
  // The level's own influences, k = influences_per_vertex in [1, kMaxInfluencesPerVertex]
  // per level vertex (its `vertices`, or the set's vertex_count), fixed width: entry
  // (i, e) at i * k + e; slots < m; weights finite, >= 0, each vertex's summing to 1
  // (within 1e-3). k = 0 (both empty): the client merges its own influences through the
  // joint map.
  uint32_t influences_per_vertex = 0;
  std::vector<uint16_t> influence_slots = {};
  std::vector<float> influence_weights = {};
  // What one frame of the level costs a skinner relative to full detail (vertices x
  // influences plus a term per joint: pipeline/cost_levels.h); finite, >= 0, 0 = not
  // measured (files before 3.0).
  float cost = 0;

  bool operator==(const LevelData&) const = default;
};

// One clip of a level set's frames: frames [first_frame, first_frame + frame_count) played
// at fps. A bake of several animations of one character concatenates their frames, clip
// after clip, in every level's matrices; frame t of the clip is frame first_frame + t of
// the level set.
struct ClipInfo {
  std::string name;  // UTF-8, no NUL; unique; empty only for a level set's single clip
  uint32_t first_frame = 0;
  uint32_t frame_count = 0;  // >= 1
  double fps = 30.0;         // finite, > 0; frame t of the clip is at time t / fps

  bool operator==(const ClipInfo&) const = default;
};

// Editable plain data of a level set (what the bake tool fills in).
struct LevelSetData {
  std::string variant_name;  // UTF-8, no NUL, may be empty
  uint32_t flags = 0;        // kLevelSetFlag* bits
  uint32_t algorithm_version = 0;
  uint32_t frame_count = 0;  // T >= 1, every clip's frames
  // The character's mesh vertex count p when levels carry their own mesh or influences
  // (then every level's vertex ids are < p); 0 when none does.
  uint32_t vertex_count = 0;
  // Finite, > 0; with `clips`, the first clip's (the header of a file holds the first
  // clip's fps, so that a reader of the header alone plays clip 0 right).
  double fps = 30.0;
  // SHA-256 of the bake inputs and the hash of the bake settings: opaque to proto,
  // carried so that a stored result can be checked against a cache key.
  std::array<uint8_t, 32> source_hash{};
  uint64_t settings_hash = 0;
  // n joints in topological order: parents[0] == -1 (the single root) and
  // 0 <= parents[j] < j for j > 0. Names: unique, non-empty UTF-8 without NUL.
  std::vector<std::string> joint_names;
  std::vector<int32_t> parents;
  std::vector<LevelData> levels;  // L >= 1, in the writer's order
  // In frame order, covering [0, frame_count) without gaps (at most frame_count clips).
  // Empty: one clip named "" of every frame at `fps`, which is what is written (every
  // 2.0 file has a clip table) and what a 1.0 file holds; ToLevelSetData gives back an
  // empty list for a file whose single clip is unnamed.
  std::vector<ClipInfo> clips;

  bool operator==(const LevelSetData&) const = default;
};

// A level set to write, by reference: LevelSetData's fields as views of the caller's
// arrays (a bake's solved matrices, say), which must outlive the call. Encoding from it
// copies each array once, straight into the file.
struct LevelRef {
  std::span<const uint16_t> kept_joints;
  std::span<const uint16_t> joint_map;
  LevelFigures figures = {};
  // Right after the figures, unlike in LevelData: a writer of 2.0 levels that initialises
  // {kept_joints, joint_map, figures, matrices} by position still means the same.
  std::span<const float> matrices;
  uint32_t frame_stride = 1;
  std::span<const uint32_t> vertices = {};
  std::span<const uint32_t> triangles = {};
  uint32_t influences_per_vertex = 0;
  std::span<const uint16_t> influence_slots = {};
  std::span<const float> influence_weights = {};
  float cost = 0;
};

// ClipInfo by reference.
struct ClipRef {
  std::string_view name;
  uint32_t first_frame = 0;
  uint32_t frame_count = 0;
  double fps = 30.0;
};

struct LevelSetRef {
  uint32_t flags = 0;
  uint32_t algorithm_version = 0;
  uint32_t frame_count = 0;
  uint32_t vertex_count = 0;
  double fps = 0;
  std::array<uint8_t, 32> source_hash{};
  uint64_t settings_hash = 0;
  std::string_view variant_name;
  std::vector<std::string_view> joint_names;
  std::span<const int32_t> parents;
  std::vector<LevelRef> levels;
  std::vector<ClipRef> clips;  // as LevelSetData::clips; empty: one unnamed clip
};

// `data` by reference: valid while `data` is alive and unchanged.
LevelSetRef RefOf(const LevelSetData& data);

// Checks every field combination of `data` against the rules of
// docs/level-format.md ("Validation"); the message names the first offending level,
// joint, slot or frame. kInvalidArgument when invalid. `run`: where the levels' checks
// run (base/pieces.h; the result is the same).
Status ValidateLevelSet(const LevelSetData& data, const PieceRunner& run = {});

// The joint map of a level: for each of the n joints, the slot of its nearest kept
// ancestor (itself when kept). kInvalidArgument when the parents are not topological
// or `kept_joints` is not strictly ascending, in range and containing the root.
StatusOr<std::vector<uint16_t>> ComputeJointMap(std::span<const int32_t> parents,
                                                std::span<const uint16_t> kept_joints);

// The exact number of bytes EncodeLevelSet writes for `data` when it is valid (a
// worst-case bound to size a caller-owned buffer). Does not validate.
size_t EncodedLevelSetSize(const LevelSetData& data);

// Validates `data` (on `run`, as ValidateLevelSet), then writes it. The string holds the
// whole file; decode it in place only where its storage is 16-byte aligned
// (AlignedBytes::CopyOf otherwise).
StatusOr<std::string> EncodeLevelSet(const LevelSetData& data, const PieceRunner& run = {});
// The same from views: the same checks, the same bytes.
StatusOr<std::string> EncodeLevelSet(const LevelSetRef& data, const PieceRunner& run = {});

// Validates `data`, then writes it into the first EncodedLevelSetSize(data) bytes of
// `out` (any alignment) and returns that size. kInvalidArgument when `out` is smaller;
// nothing is written on failure.
StatusOr<size_t> EncodeLevelSetInto(const LevelSetData& data, std::span<std::byte> out);

// One clip of a decoded level set; its name points into the decoded buffer.
struct ClipView {
  std::string_view name;
  uint32_t first_frame = 0;
  uint32_t frame_count = 0;
  double fps = 0;
};

// Where frame t of a clip lies among a level's stored frames: between stored frames
// `from` and `to` (indices of LevelView::frame), `fraction` of the way (0: frame `from`
// itself, and then `to` == `from`).
struct FrameBlend {
  uint32_t from = 0, to = 0;
  float fraction = 0;
};

// One level of a decoded level set; spans into the decoded buffer.
class LevelView {
 public:
  uint32_t kept_count() const { return static_cast<uint32_t>(kept_joints_.size()); }  // m
  // T': the stored frames of every clip at the level's frame stride (T at stride 1).
  uint32_t frame_count() const { return frame_count_; }
  uint32_t frame_stride() const { return frame_stride_; }                 // 1 in files before 3.0
  std::span<const uint16_t> kept_joints() const { return kept_joints_; }  // m, ascending
  std::span<const uint16_t> joint_map() const { return joint_map_; }      // n, slots < m
  const LevelFigures& figures() const { return figures_; }
  float cost() const { return cost_; }  // 0: not measured
  // The level's own mesh (both empty: the character's whole mesh and triangles).
  std::span<const uint32_t> vertices() const { return vertices_; }    // original ids, ascending
  std::span<const uint32_t> triangles() const { return triangles_; }  // 3 per triangle
  bool has_own_mesh() const { return !vertices_.empty(); }
  // The level's own influences: k per level vertex, fixed width; k = 0: none.
  uint32_t influences_per_vertex() const { return influences_per_vertex_; }
  std::span<const uint16_t> influence_slots() const { return influence_slots_; }
  std::span<const float> influence_weights() const { return influence_weights_; }
  // T' x m x 12 floats, stored-frame-major.
  std::span<const float> matrices() const { return matrices_; }
  // The first stored frame of clip c.
  uint32_t clip_first_stored(uint32_t c) const {
    assert(c < clip_first_stored_.size());
    return clip_first_stored_[c];
  }
  // Frame t (within the clip) of clip c of the set `clip_frame_count` long, at this
  // level's pose rate.
  FrameBlend Blend(uint32_t c, uint32_t t, uint32_t clip_frame_count) const;
  // The m x 12 floats of stored frame t.
  std::span<const float> frame(uint32_t t) const {
    assert(t < frame_count_);
    return matrices_.subspan(size_t{t} * kept_joints_.size() * kMatrixFloats,
                             kept_joints_.size() * kMatrixFloats);
  }
  // K'_s(t): 12 floats, 3x4 row-major.
  const float* matrix(uint32_t t, uint32_t s) const {
    assert(t < frame_count_ && s < kept_joints_.size());
    return matrices_.data() + (size_t{t} * kept_joints_.size() + s) * kMatrixFloats;
  }

 private:
  friend class LevelSetDecoder;
  uint32_t frame_count_ = 0;
  uint32_t frame_stride_ = 1;
  std::span<const uint16_t> kept_joints_;
  std::span<const uint16_t> joint_map_;
  LevelFigures figures_;
  float cost_ = 0;
  std::span<const float> matrices_;
  std::span<const uint32_t> vertices_;
  std::span<const uint32_t> triangles_;
  uint32_t influences_per_vertex_ = 0;
  std::span<const uint16_t> influence_slots_;
  std::span<const float> influence_weights_;
  std::vector<uint32_t> clip_first_stored_;  // per clip
};

// A decoded, fully validated level set. Holds O(n + L) bookkeeping of its own; every
// array and string points into the decoded buffer, which must outlive the view.
class LevelSetView {
 public:
  using ClipView = proto::ClipView;

  uint16_t major_version() const { return major_version_; }  // as written: 1, 2 or 3
  uint16_t minor_version() const { return minor_version_; }  // as written
  // As written: a file of a later minor version may carry bits this build ignores.
  uint32_t flags() const { return flags_; }
  bool rigid() const { return (flags_ & kLevelSetFlagRigid) != 0; }
  uint32_t algorithm_version() const { return algorithm_version_; }
  uint32_t joint_count() const { return static_cast<uint32_t>(parents_.size()); }  // n
  uint32_t level_count() const { return static_cast<uint32_t>(levels_.size()); }   // L
  uint32_t frame_count() const { return frame_count_; }                            // T
  uint32_t vertex_count() const { return vertex_count_; }  // p; 0 when no level has a mesh
  double fps() const { return fps_; }                      // the first clip's
  // The clips, in frame order, covering [0, T): at least one (a 1.0 file, or a file
  // written without clips: one clip named "" of every frame at fps()).
  std::span<const ClipView> clips() const { return clips_; }
  uint32_t clip_count() const { return static_cast<uint32_t>(clips_.size()); }
  const ClipView& clip(uint32_t c) const {
    assert(c < clips_.size());
    return clips_[c];
  }
  // The index of the clip named `name`, or -1.
  int FindClip(std::string_view name) const;
  const std::array<uint8_t, 32>& source_hash() const { return source_hash_; }
  uint64_t settings_hash() const { return settings_hash_; }
  std::string_view variant_name() const { return variant_name_; }
  std::span<const std::string_view> joint_names() const { return joint_names_; }
  std::string_view joint_name(uint32_t j) const {
    assert(j < joint_names_.size());
    return joint_names_[j];
  }
  std::span<const int32_t> parents() const { return parents_; }
  std::span<const LevelView> levels() const { return levels_; }
  const LevelView& level(uint32_t l) const {
    assert(l < levels_.size());
    return levels_[l];
  }
  // The whole decoded file.
  std::span<const std::byte> bytes() const { return bytes_; }

 private:
  friend class LevelSetDecoder;
  std::span<const std::byte> bytes_;
  uint16_t major_version_ = 0;
  uint16_t minor_version_ = 0;
  uint32_t flags_ = 0;
  uint32_t algorithm_version_ = 0;
  uint32_t frame_count_ = 0;
  uint32_t vertex_count_ = 0;
  double fps_ = 0;
  std::array<uint8_t, 32> source_hash_{};
  uint64_t settings_hash_ = 0;
  std::string_view variant_name_;
  std::vector<std::string_view> joint_names_;
  std::span<const int32_t> parents_;
  std::vector<LevelView> levels_;
  std::vector<ClipView> clips_;
};

struct DecodeOptions {
  // Off only where the structure itself is under test (a fuzz target, which cannot
  // forge checksums); every structural and semantic check still runs.
  bool verify_checksum = true;
};

// Decodes and validates a level-set file in place. Never reads outside `bytes`, never
// asserts on any content. Errors:
//   kInvalidArgument  `bytes` does not start on a 16-byte boundary, or is not a level
//                     set (magic mismatch);
//   kUnsupported      a major version other than 1, 2 and 3 (the message names the
//                     version found and the ones this build reads);
//   kDataLoss         truncated, corrupted (checksum) or malformed (any rule of
//                     docs/level-format.md, "Validation"); the message says which.
StatusOr<LevelSetView> DecodeLevelSet(std::span<const std::byte> bytes,
                                      const DecodeOptions& options = {});
StatusOr<LevelSetView> DecodeLevelSet(std::string_view bytes, const DecodeOptions& options = {});

// Level l of `view` as a one-level file of the current version (what the server
// streams): header, skeleton, clips and hashes unchanged, level_count 1. Flags this build
// does not know are dropped, and so are the unknown sections of a later minor version.
// kNotFound when l >= view.level_count().
StatusOr<std::string> ExtractLevel(const LevelSetView& view, uint32_t l);

// Level l of `view`, the stored frames of clip `clip` only, as a one-level, one-clip file
// of the current version: the clip keeps its name and fps and starts at frame 0; the
// file's frame_count and fps are the clip's; the level's frame stride, mesh, influences,
// cost and figures are kept as written (the figures are the bake's, over every clip), and
// so is the level set's vertex_count. kNotFound when l >= view.level_count() or
// clip >= view.clip_count().
StatusOr<std::string> ExtractLevelClip(const LevelSetView& view, uint32_t l, uint32_t clip);

// A copy of `view` as editable data (flags this build does not know dropped), so that
// EncodeLevelSet(ToLevelSetData(view)) reproduces a current-version file byte for byte
// (a 1.x or 2.x file comes out as the current-version one of the same content). A single
// unnamed clip comes back as empty `clips`.
LevelSetData ToLevelSetData(const LevelSetView& view);

}  // namespace motionlod::proto
