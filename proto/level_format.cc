#include "proto/level_format.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <optional>
#include <type_traits>
#include <utility>

#include "proto/checksum.h"
#include "proto/level_format_internal.h"
#include "proto/utf8.h"

namespace motionlod::proto {

using internal::ExtraSection;
using internal::kClipRecordSize;
using internal::kDirectoryEntrySize;
using internal::kGlobalSectionCount;
using internal::kHeaderSize;
using internal::kLevelRecordSize;
using internal::kNoLevel;
using internal::kSectionsPerLevel;
using internal::kTrailerSize;
using internal::SectionKind;
using internal::WriterOptions;

namespace {

// ---------------------------------------------------------------------------------
// Little helpers: messages, loads and stores at any alignment, overflow-safe sizes.

void Append(std::string& out, std::string_view text) { out.append(text); }
void Append(std::string& out, const char* text) { out.append(text); }
template <typename T>
requires std::is_arithmetic_v<T>
void Append(std::string& out, T value) {
  if constexpr (std::is_floating_point_v<T>) {
    char buffer[32];
    std::snprintf(buffer, sizeof buffer, "%.9g", static_cast<double>(value));
    out.append(buffer);
  } else {
    out.append(std::to_string(value));
  }
}
template <typename... Args>
std::string StrCat(const Args&... args) {
  std::string out;
  (Append(out, args), ...);
  return out;
}

template <typename T>
T Load(const std::byte* p) {
  T value;
  std::memcpy(&value, p, sizeof value);
  return value;
}
template <typename T>
void Store(std::byte* p, T value) {
  std::memcpy(p, &value, sizeof value);
}

constexpr uint64_t kAlignment = kLevelFormatAlignment;

// Rounds up to the alignment; callers guarantee x <= a multiple of 16 that fits.
constexpr uint64_t AlignUp(uint64_t x) { return (x + (kAlignment - 1)) & ~(kAlignment - 1); }

bool AllZero(std::span<const std::byte> bytes) {
  return std::all_of(bytes.begin(), bytes.end(), [](std::byte b) { return b == std::byte{0}; });
}

// A float whose exponent bits are all set is an infinity or a NaN.
bool IsFiniteBits(float value) {
  return (std::bit_cast<uint32_t>(value) & 0x7F800000u) != 0x7F800000u;
}

// ---------------------------------------------------------------------------------
// The content of a level set as spans, whether it comes from LevelSetData (encode),
// from a decoded buffer (validation after decode) or from a view (extract).

// The header and skeleton of `view`, without levels.
LevelSetRef HeaderRefOf(const LevelSetView& view) {
  LevelSetRef source;
  source.flags = view.flags() & kKnownLevelSetFlags;
  source.algorithm_version = view.algorithm_version();
  source.frame_count = view.frame_count();
  source.vertex_count = view.vertex_count();
  source.fps = view.fps();
  source.source_hash = view.source_hash();
  source.settings_hash = view.settings_hash();
  source.variant_name = view.variant_name();
  source.joint_names.assign(view.joint_names().begin(), view.joint_names().end());
  source.parents = view.parents();
  source.clips.reserve(view.clip_count());
  for (const ClipView& clip : view.clips()) {
    source.clips.push_back({clip.name, clip.first_frame, clip.frame_count, clip.fps});
  }
  return source;
}

// The clips a file of `source` holds: its own, or the one unnamed clip of every frame.
std::span<const ClipRef> ClipsToWrite(const LevelSetRef& source, ClipRef& single) {
  if (!source.clips.empty()) return source.clips;
  single = {std::string_view(""), 0, source.frame_count, source.fps};
  return {&single, 1};
}

LevelRef RefOf(const LevelView& level) {
  return {.kept_joints = level.kept_joints(),
          .joint_map = level.joint_map(),
          .figures = level.figures(),
          .matrices = level.matrices(),
          .frame_stride = level.frame_stride(),
          .vertices = level.vertices(),
          .triangles = level.triangles(),
          .influences_per_vertex = level.influences_per_vertex(),
          .influence_slots = level.influence_slots(),
          .influence_weights = level.influence_weights(),
          .cost = level.cost()};
}

// T', the stored frames of every clip, at each frame stride r (index r; 0 unused). Below
// 2^64 whatever the clips: fewer than 2^32 clips of fewer than 2^32 frames each.
using StoredFrames = std::array<uint64_t, kMaxFrameStride + 1>;
StoredFrames StoredFramesByStride(std::span<const ClipRef> clips) {
  StoredFrames stored{};
  for (uint32_t r = 1; r <= kMaxFrameStride; ++r) {
    for (const ClipRef& clip : clips) stored[r] += StoredFrameCount(clip.frame_count, r);
  }
  return stored;
}

// ---------------------------------------------------------------------------------
// Semantic validation, shared by the encoder (kInvalidArgument) and the decoder
// (kDataLoss): returns the first problem, or an empty string.

// What is wrong with a name, as the end of a sentence about it ("is empty"), or an empty
// string: the caller names the name only on failure (a joint's, built for every joint of
// every level set written or read, was most of the check of a small one).
std::string NameProblem(std::string_view name, bool allow_empty) {
  if (name.empty() && !allow_empty) return "is empty";
  if (name.size() > kMaxNameBytes) {
    return StrCat("is ", name.size(), " bytes long (at most ", kMaxNameBytes, ")");
  }
  if (!IsValidUtf8(name)) return "is not valid UTF-8";
  if (name.find('\0') != std::string_view::npos) return "contains a NUL byte";
  return {};
}

std::string CheckSkeleton(const LevelSetRef& source) {
  const size_t n = source.parents.size();
  if (n == 0) return "the skeleton has no joint";
  if (n > kMaxJointCount) {
    return StrCat("the skeleton has ", n, " joints (at most ", kMaxJointCount, ")");
  }
  if (source.joint_names.size() != n) {
    return StrCat(source.joint_names.size(), " joint names for ", n, " parents");
  }
  if (source.parents[0] != -1) {
    return StrCat("joint 0 has parent ", source.parents[0],
                  "; joint 0 must be the root (parent -1)");
  }
  for (size_t j = 1; j < n; ++j) {
    const int32_t parent = source.parents[j];
    if (parent < 0 || static_cast<size_t>(parent) >= j) {
      return StrCat("joint ", j, " has parent ", parent,
                    "; parents must be topological (0 <= parent < joint) with joint 0 the "
                    "single root");
    }
  }
  for (size_t j = 0; j < n; ++j) {
    const std::string problem = NameProblem(source.joint_names[j], /*allow_empty=*/false);
    if (!problem.empty()) return StrCat("the name of joint ", j, " ", problem);
  }
  std::vector<std::string_view> sorted = source.joint_names;
  std::sort(sorted.begin(), sorted.end());
  const auto duplicate = std::adjacent_find(sorted.begin(), sorted.end());
  if (duplicate != sorted.end()) {
    return StrCat("two joints are named \"", *duplicate, "\"");
  }
  return {};
}

// A clip named in a message once its name is known to be valid: `clip 2 ("run")`.
std::string ClipLabel(size_t c, std::string_view name) {
  return StrCat("clip ", c, " (\"", name, "\")");
}

// The clip table: in frame order, contiguous, covering every frame, each of at least one
// frame at a finite positive fps, uniquely named, the first at the level set's fps.
// Empty `clips` stand for one unnamed clip of every frame at the level set's fps.
std::string CheckClips(const LevelSetRef& source) {
  const std::span<const ClipRef> clips = source.clips;
  if (clips.empty()) return {};
  if (clips.size() > source.frame_count) {
    return StrCat("the level set has ", clips.size(), " clips for ", source.frame_count,
                  " frames (at most one clip per frame)");
  }
  uint64_t next_frame = 0;  // <= frame_count + 2^32: no wrap
  for (size_t c = 0; c < clips.size(); ++c) {
    const ClipRef& clip = clips[c];
    const bool single = clips.size() == 1;
    const std::string problem = NameProblem(clip.name, /*allow_empty=*/single);
    if (!problem.empty()) {
      return StrCat("the name of clip ", c, " ", problem,
                    clip.name.empty() ? " (only a level set's single clip may be unnamed)" : "");
    }
    if (clip.first_frame != next_frame) {
      return StrCat(ClipLabel(c, clip.name), " starts at frame ", clip.first_frame,
                    "; clips must be contiguous and in frame order (expected frame ", next_frame,
                    ")");
    }
    if (clip.frame_count == 0) return StrCat(ClipLabel(c, clip.name), " has no frame");
    if (!(std::isfinite(clip.fps) && clip.fps > 0)) {
      return StrCat(ClipLabel(c, clip.name), ": fps is ", clip.fps, " (finite and > 0 expected)");
    }
    next_frame += clip.frame_count;
    if (next_frame > source.frame_count) {
      return StrCat(ClipLabel(c, clip.name), " ends at frame ", next_frame, ", past the ",
                    source.frame_count, " frames of the level set");
    }
  }
  if (next_frame != source.frame_count) {
    return StrCat("the clips cover frames [0, ", next_frame, ") of ", source.frame_count,
                  "; they must cover every frame");
  }
  if (clips.size() > 1) {
    std::vector<std::string_view> sorted(clips.size());
    for (size_t c = 0; c < clips.size(); ++c) sorted[c] = clips[c].name;
    std::sort(sorted.begin(), sorted.end());
    const auto duplicate = std::adjacent_find(sorted.begin(), sorted.end());
    if (duplicate != sorted.end()) return StrCat("two clips are named \"", *duplicate, "\"");
  }
  if (clips[0].fps != source.fps) {
    return StrCat("fps is ", source.fps, " but ", ClipLabel(0, clips[0].name), " plays at ",
                  clips[0].fps, "; a level set's fps is its first clip's");
  }
  return {};
}

std::string CheckFigures(size_t l, const LevelFigures& f) {
  const std::pair<const char*, float> finite_figures[] = {
      {"max_vertex_error_pct", f.max_vertex_error_pct},
      {"mean_vertex_error_pct", f.mean_vertex_error_pct},
      {"mean_normal_error_deg", f.mean_normal_error_deg},
      {"mean_E", f.mean_E},
  };
  for (const auto& [name, value] : finite_figures) {
    if (!(std::isfinite(value) && value >= 0)) {
      return StrCat("level ", l, ": ", name, " is ", value, " (finite and >= 0 expected)");
    }
  }
  if (!(f.max_px_for_1px_error >= 0)) {  // +inf allowed, NaN not
    return StrCat("level ", l, ": max_px_for_1px_error is ", f.max_px_for_1px_error,
                  " (>= 0 or +inf expected)");
  }
  return {};
}

// The slots of `kept_joints` as ComputeJointMap and the map check both need them:
// problems with the kept list itself.
std::string CheckKeptJoints(size_t l, size_t n, std::span<const uint16_t> kept) {
  if (kept.empty()) return StrCat("level ", l, " keeps no joint");
  if (kept.size() > n) {
    return StrCat("level ", l, " keeps ", kept.size(), " joints of ", n);
  }
  if (kept[0] != 0) return StrCat("level ", l, " does not keep the root (joint 0)");
  for (size_t s = 1; s < kept.size(); ++s) {
    if (kept[s] <= kept[s - 1]) {
      return StrCat("level ", l, ": kept joints are not strictly ascending at slot ", s, " (",
                    kept[s - 1], " then ", kept[s], ")");
    }
  }
  if (kept.back() >= n) {
    return StrCat("level ", l, ": kept joint ", kept.back(), " is out of range (n = ", n, ")");
  }
  return {};
}

std::string CheckJointMap(size_t l, std::span<const int32_t> parents,
                          std::span<const uint16_t> kept, std::span<const uint16_t> map) {
  const size_t n = parents.size();
  const size_t m = kept.size();
  if (map.size() != n) {
    return StrCat("level ", l, ": the joint map has ", map.size(), " entries for ", n, " joints");
  }
  size_t next_slot = 0;  // kept is ascending: kept[next_slot] is the next kept joint
  for (size_t j = 0; j < n; ++j) {
    const uint16_t slot = map[j];
    if (slot >= m) {
      return StrCat("level ", l, ": joint ", j, " maps to slot ", slot, " (m = ", m, ")");
    }
    if (next_slot < m && kept[next_slot] == j) {
      if (slot != next_slot) {
        return StrCat("level ", l, ": kept joint ", j, " maps to slot ", slot,
                      " instead of its own slot ", next_slot);
      }
      ++next_slot;
    } else {
      // j > 0: the root is kept. Parents precede children, so map[parent] is already
      // known to be the slot of the parent's nearest kept ancestor.
      const auto parent = static_cast<size_t>(parents[j]);
      if (slot != map[parent]) {
        return StrCat("level ", l, ": removed joint ", j, " maps to slot ", slot,
                      " but its parent ", parent, " to slot ", map[parent],
                      " (a removed joint is driven by its nearest kept ancestor)");
      }
    }
  }
  return {};
}

// Whether the 3x3 part A of a stored matrix (three rows of four floats each: A's row, then
// the translation) is a rotation: columns orthonormal to 1e-3, det A > 0. Column a of A^T A
// and the terms of det A = r0 . (r1 x r2) are formed column by column, a = 0 to 2. Float
// is ample for the tolerance: the rounding of these sums is about 1e-7. Branch-free (an
// AND of comparisons, NaN failing all of them): a loop over matrices has no branch to
// mispredict.
inline bool IsRotation(const float* k) {
  constexpr float kTolerance = 1e-3f;
  const float* r0 = k;
  const float* r1 = k + 4;
  const float* r2 = k + 8;
  bool ok = true;
  float det = 0.0f;
  for (int a = 0; a < 3; ++a) {
    const int b = (a + 1) % 3;
    const int c = (a + 2) % 3;
    // (A^T A)(a, a) - 1 and (A^T A)(a, a + 1 mod 3).
    const float diagonal = r0[a] * r0[a] + r1[a] * r1[a] + r2[a] * r2[a] - 1.0f;
    const float off_diagonal = r0[a] * r0[b] + r1[a] * r1[b] + r2[a] * r2[b];
    ok &= (diagonal <= kTolerance) & (diagonal >= -kTolerance) & (off_diagonal <= kTolerance) &
          (off_diagonal >= -kTolerance);
    det += r0[a] * (r1[b] * r2[c] - r1[c] * r2[b]);
  }
  return ok & (det > 0.0f);
}

std::string CheckFrameStride(size_t l, uint32_t stride) {
  if (stride < 1 || stride > kMaxFrameStride) {
    return StrCat("level ", l, ": frame stride ", stride, " is out of [1, ", kMaxFrameStride, "]");
  }
  return {};
}

// `stored_frames`: T' at the level's stride, at most T (the clips were checked first).
std::string CheckMatrixCount(size_t l, uint64_t stored_frames, uint32_t stride, size_t m,
                             std::span<const float> matrices) {
  const uint64_t expected = stored_frames * m * kMatrixFloats;  // < 2^54
  if (matrices.size() != expected) {
    return StrCat("level ", l, " has ", matrices.size(), " matrix floats; T' x m x 12 = ", expected,
                  " (T' = ", stored_frames, " stored frames at frame stride ", stride, ")");
  }
  return {};
}

std::string CheckCost(size_t l, float cost) {
  if (!(std::isfinite(cost) && cost >= 0)) {
    return StrCat("level ", l, ": cost is ", cost, " (finite and >= 0 expected)");
  }
  return {};
}

// The level's own mesh: vertex ids strictly ascending below the character's vertex count,
// triangles (exactly when there are vertices) of three indices into them.
std::string CheckMesh(size_t l, uint32_t vertex_count, std::span<const uint32_t> vertices,
                      std::span<const uint32_t> triangles) {
  if (vertices.empty() != triangles.empty()) {
    return StrCat("level ", l, " has ", vertices.size(), " vertices of its own and ",
                  triangles.size(), " triangle indices (both or neither expected)");
  }
  if (vertices.empty()) return {};
  if (vertex_count == 0) {
    return StrCat("level ", l,
                  " has a mesh of its own but the level set's vertex_count is 0 (the "
                  "character's vertex count expected)");
  }
  for (size_t i = 1; i < vertices.size(); ++i) {
    if (vertices[i] <= vertices[i - 1]) {
      return StrCat("level ", l, ": its vertices are not strictly ascending at ", i, " (",
                    vertices[i - 1], " then ", vertices[i], ")");
    }
  }
  if (vertices.back() >= vertex_count) {
    return StrCat("level ", l, ": vertex ", vertices.back(),
                  " is out of range (vertex_count = ", vertex_count, ")");
  }
  if (triangles.size() % 3 != 0) {
    return StrCat("level ", l, " has ", triangles.size(), " triangle indices, not a multiple of 3");
  }
  for (size_t i = 0; i < triangles.size(); ++i) {
    if (triangles[i] >= vertices.size()) {
      return StrCat("level ", l, ": triangle ", i / 3, " corner ", i % 3, " is vertex ",
                    triangles[i], " of the level's ", vertices.size());
    }
  }
  return {};
}

std::string CheckInfluencesPerVertex(size_t l, uint32_t k) {
  if (k > kMaxInfluencesPerVertex) {
    return StrCat("level ", l, ": influences_per_vertex ", k, " is out of [0, ",
                  kMaxInfluencesPerVertex, "]");
  }
  return {};
}

// The level's own influences: k per vertex of its mesh (the character's without one),
// slots below m, weights finite, >= 0 and summing to 1 per vertex.
std::string CheckInfluences(size_t l, uint32_t vertex_count, const LevelRef& level) {
  const uint32_t k = level.influences_per_vertex;
  std::string problem = CheckInfluencesPerVertex(l, k);
  if (!problem.empty()) return problem;
  const std::span<const uint16_t> slots = level.influence_slots;
  const std::span<const float> weights = level.influence_weights;
  if (k == 0) {
    if (!slots.empty() || !weights.empty()) {
      return StrCat("level ", l, " has ", slots.size(), " influence slots and ", weights.size(),
                    " weights but influences_per_vertex 0");
    }
    return {};
  }
  const uint64_t vertices = level.vertices.empty() ? vertex_count : level.vertices.size();
  if (vertices == 0) {
    return StrCat("level ", l,
                  " has influences but no vertices (no mesh of its own and the level set's "
                  "vertex_count is 0)");
  }
  const uint64_t expected = vertices * k;  // < 2^36
  if (slots.size() != expected || weights.size() != expected) {
    return StrCat("level ", l, " has ", slots.size(), " influence slots and ", weights.size(),
                  " weights; V x k = ", expected, " (V = ", vertices, ", k = ", k, ")");
  }
  const size_t m = level.kept_joints.size();
  for (size_t i = 0; i < slots.size(); ++i) {
    if (slots[i] >= m) {
      return StrCat("level ", l, ": influence ", i % k, " of vertex ", i / k, " is on slot ",
                    slots[i], " (m = ", m, ")");
    }
  }
  constexpr double kWeightSumTolerance = 1e-3;
  for (uint64_t v = 0; v < vertices; ++v) {
    double sum = 0;
    for (uint32_t e = 0; e < k; ++e) {
      const float weight = weights[v * k + e];
      if (!(std::isfinite(weight) && weight >= 0)) {
        return StrCat("level ", l, ": influence ", e, " of vertex ", v, " has weight ", weight,
                      " (finite and >= 0 expected)");
      }
      sum += weight;
    }
    if (!(std::abs(sum - 1) <= kWeightSumTolerance)) {
      return StrCat("level ", l, ": the influence weights of vertex ", v, " sum to ", sum,
                    " (1 expected, within ", kWeightSumTolerance, ")");
    }
  }
  return {};
}

// The values of a level's matrices (m per frame, a count CheckMatrixCount accepted): finite,
// and rotations plus translations where the level set is rigid.
std::string CheckMatrixValues(size_t l, size_t m, bool rigid, std::span<const float> matrices) {
  // One branch-free pass, an OR of integer compares, which the compiler vectorises (a
  // running AND of bools did not); the culprit is located only on failure.
  uint32_t non_finite = 0;
  for (const float value : matrices) non_finite |= !IsFiniteBits(value);
  if (non_finite != 0) {
    for (size_t i = 0; i < matrices.size(); ++i) {
      if (!IsFiniteBits(matrices[i])) {
        const size_t matrix = i / kMatrixFloats;
        return StrCat("level ", l, ": K'(frame ", matrix / m, ", slot ", matrix % m, ") element ",
                      i % kMatrixFloats, " is not finite (", matrices[i], ")");
      }
    }
  }
  if (rigid) {
    // Branch-free over every matrix as above (a branch per matrix costs a rigid
    // every-level bake 3% of its time); the culprit is located only on failure.
    const size_t count = matrices.size() / kMatrixFloats;
    const float* k = matrices.data();
    uint32_t not_rotation = 0;
    for (size_t matrix = 0; matrix < count; ++matrix) {
      not_rotation |= !IsRotation(k + matrix * kMatrixFloats);
    }
    for (size_t matrix = 0; not_rotation != 0 && matrix < count; ++matrix) {
      if (!IsRotation(k + matrix * kMatrixFloats)) {
        return StrCat("level ", l, ": K'(frame ", matrix / m, ", slot ", matrix % m,
                      ") is not a rotation plus translation, but the level set is flagged "
                      "rigid");
      }
    }
  }
  return {};
}

// Whether CheckLevelSet checks the values of the levels' matrices (most of its work), or
// leaves them to CheckMatrixValues: writing a level set needs only the rest.
enum class MatrixValues { kChecked, kLeftOut };

// The frames and clips: what the sizes of the levels' matrices follow from, so the decoder
// checks them before it reads a level.
std::string CheckFrames(const LevelSetRef& source) {
  if (source.frame_count == 0) return "the level set has no frame";
  if (!(std::isfinite(source.fps) && source.fps > 0)) {
    return StrCat("fps is ", source.fps, " (finite and > 0 expected)");
  }
  return CheckClips(source);
}

// Everything but the flags and the frames (CheckFrames, which must have passed).
std::string CheckNamesAndLevels(const LevelSetRef& source, const PieceRunner& run,
                                MatrixValues matrix_values) {
  std::string problem = NameProblem(source.variant_name, /*allow_empty=*/true);
  if (!problem.empty()) return StrCat("the variant name ", problem);
  problem = CheckSkeleton(source);
  if (!problem.empty()) return problem;
  if (source.levels.empty()) return "the level set has no level";
  if (source.levels.size() > kMaxLevelCount) {
    return StrCat("the level set has ", source.levels.size(), " levels (at most ", kMaxLevelCount,
                  ")");
  }
  const bool rigid = (source.flags & kLevelSetFlagRigid) != 0;
  ClipRef single;
  const StoredFrames stored_frames = StoredFramesByStride(ClipsToWrite(source, single));
  // Levels are checked independently, each as a piece; the first level's problem is the
  // one reported, whatever order they ran in.
  std::vector<std::string> problems(source.levels.size());
  RunPieces(run, static_cast<int>(source.levels.size()), [&](int piece) {
    const auto l = static_cast<size_t>(piece);
    const LevelRef& level = source.levels[l];
    std::string& level_problem = problems[l];
    level_problem = CheckKeptJoints(l, source.parents.size(), level.kept_joints);
    if (level_problem.empty()) {
      level_problem = CheckJointMap(l, source.parents, level.kept_joints, level.joint_map);
    }
    if (level_problem.empty()) level_problem = CheckFigures(l, level.figures);
    if (level_problem.empty()) level_problem = CheckFrameStride(l, level.frame_stride);
    if (level_problem.empty()) {
      level_problem = CheckMatrixCount(l, stored_frames[level.frame_stride], level.frame_stride,
                                       level.kept_joints.size(), level.matrices);
    }
    if (level_problem.empty()) {
      level_problem = CheckMesh(l, source.vertex_count, level.vertices, level.triangles);
    }
    if (level_problem.empty()) level_problem = CheckInfluences(l, source.vertex_count, level);
    if (level_problem.empty()) level_problem = CheckCost(l, level.cost);
    if (level_problem.empty() && matrix_values == MatrixValues::kChecked) {
      level_problem = CheckMatrixValues(l, level.kept_joints.size(), rigid, level.matrices);
    }
  });
  for (std::string& level_problem : problems) {
    if (!level_problem.empty()) return std::move(level_problem);
  }
  return {};
}

std::string CheckLevelSet(const LevelSetRef& source, const PieceRunner& run = {},
                          MatrixValues matrix_values = MatrixValues::kChecked) {
  if ((source.flags & ~kKnownLevelSetFlags) != 0) {
    return StrCat("unknown flag bits ", source.flags & ~kKnownLevelSetFlags);
  }
  std::string problem = CheckFrames(source);
  if (!problem.empty()) return problem;
  return CheckNamesAndLevels(source, run, matrix_values);
}

// ---------------------------------------------------------------------------------
// Writing.

struct PlannedSection {
  uint32_t kind;
  uint32_t level;
  uint64_t offset;
  uint64_t size;
};

struct Layout {
  std::vector<PlannedSection> sections;
  uint64_t trailer_offset = 0;
  uint64_t file_size = 0;
};

uint64_t JointNamesBytes(const LevelSetRef& source) {
  uint64_t bytes = 0;
  for (std::string_view name : source.joint_names) bytes += 2 + uint64_t{name.size()};
  return bytes;
}

uint64_t ClipTableBytes(std::span<const ClipRef> clips, uint32_t clip_record_size) {
  uint64_t bytes = uint64_t{clip_record_size} * clips.size();
  for (const ClipRef& clip : clips) bytes += 2 + uint64_t{clip.name.size()};
  return bytes;
}

Layout PlanLayout(const LevelSetRef& source, const WriterOptions& options) {
  const uint64_t n = source.parents.size();
  Layout layout;
  auto add = [&](SectionKind kind, uint32_t level, uint64_t size) {
    layout.sections.push_back({static_cast<uint32_t>(kind), level, 0, size});
  };
  add(SectionKind::kVariantName, kNoLevel, source.variant_name.size());
  add(SectionKind::kJointNames, kNoLevel, JointNamesBytes(source));
  add(SectionKind::kJointParents, kNoLevel, 4 * n);
  add(SectionKind::kLevelTable, kNoLevel,
      uint64_t{options.level_record_size} * source.levels.size());
  ClipRef single;
  add(SectionKind::kClipTable, kNoLevel,
      ClipTableBytes(ClipsToWrite(source, single), options.clip_record_size));
  // The arrays' own sizes: those of a valid level set (EncodedLevelSetSize does not check).
  for (size_t l = 0; l < source.levels.size(); ++l) {
    const LevelRef& ref = source.levels[l];
    const auto level = static_cast<uint32_t>(l);
    add(SectionKind::kKeptJoints, level, ref.kept_joints.size_bytes());
    add(SectionKind::kJointMap, level, 2 * n);
    add(SectionKind::kMatrices, level, ref.matrices.size_bytes());
    add(SectionKind::kVertices, level, ref.vertices.size_bytes());
    add(SectionKind::kTriangles, level, ref.triangles.size_bytes());
    add(SectionKind::kInfluenceSlots, level, ref.influence_slots.size_bytes());
    add(SectionKind::kInfluenceWeights, level, ref.influence_weights.size_bytes());
  }
  for (const ExtraSection& extra : options.extra_sections) {
    layout.sections.push_back({extra.kind, extra.level, 0, extra.bytes.size()});
  }
  uint64_t cursor = AlignUp(uint64_t{options.header_size} +
                            uint64_t{kDirectoryEntrySize} * layout.sections.size());
  for (PlannedSection& section : layout.sections) {
    section.offset = cursor;
    cursor = AlignUp(cursor + section.size);
  }
  layout.trailer_offset = cursor;
  layout.file_size = cursor + kTrailerSize;
  return layout;
}

// Where WriteLevelSet puts the file: a std::string reserved to its size, or a caller's
// buffer. Put appends bytes, Fill a run of one byte value, data() is the file's start and
// size() how much of it is written.
class StringSink {
 public:
  explicit StringSink(std::string& out) : out_(out) {}
  void Put(const void* bytes, size_t size) { out_.append(static_cast<const char*>(bytes), size); }
  void Fill(size_t size, std::byte value) { out_.append(size, static_cast<char>(value)); }
  const std::byte* data() const { return reinterpret_cast<const std::byte*>(out_.data()); }
  uint64_t size() const { return out_.size(); }

 private:
  std::string& out_;
};

class BufferSink {
 public:
  explicit BufferSink(std::byte* out) : out_(out) {}
  void Put(const void* bytes, size_t size) {
    if (size != 0) std::memcpy(out_ + written_, bytes, size);
    written_ += size;
  }
  void Fill(size_t size, std::byte value) {
    std::fill_n(out_ + written_, size, value);
    written_ += size;
  }
  const std::byte* data() const { return out_; }
  uint64_t size() const { return written_; }

 private:
  std::byte* out_;
  size_t written_ = 0;
};

// Writes the planned file front to back into `sink`, every byte once: padding and
// reserved fields as they go (zeros), nothing filled first (a std::string's resize
// zero-filled what the writing then overwrote, a serial pass over a long clip's
// megabytes). The sink ends holding layout.file_size bytes.
template <typename Sink>
void WriteLevelSet(const LevelSetRef& source, const WriterOptions& options, const Layout& layout,
                   Sink& sink) {
  const auto put = [&](const void* bytes, size_t size) { sink.Put(bytes, size); };
  const auto fill = [&](uint64_t size, std::byte value) {
    sink.Fill(static_cast<size_t>(size), value);
  };
  const auto pad_to = [&](uint64_t offset) { fill(offset - sink.size(), std::byte{0}); };

  // Header.
  std::byte header[kHeaderSize] = {};
  std::memcpy(header + internal::kOffsetMagic, internal::kMagic, sizeof internal::kMagic);
  Store<uint16_t>(header + internal::kOffsetMajorVersion, options.major_version);
  Store<uint16_t>(header + internal::kOffsetMinorVersion, options.minor_version);
  Store<uint32_t>(header + internal::kOffsetHeaderSize, options.header_size);
  Store<uint64_t>(header + internal::kOffsetFileSize, layout.file_size);
  Store<uint32_t>(header + internal::kOffsetFlags, source.flags | options.extra_flags);
  Store<uint32_t>(header + internal::kOffsetAlgorithmVersion, source.algorithm_version);
  Store<uint32_t>(header + internal::kOffsetJointCount,
                  static_cast<uint32_t>(source.parents.size()));
  Store<uint32_t>(header + internal::kOffsetLevelCount,
                  static_cast<uint32_t>(source.levels.size()));
  Store<uint32_t>(header + internal::kOffsetFrameCount, source.frame_count);
  Store<uint32_t>(header + internal::kOffsetSectionCount,
                  static_cast<uint32_t>(layout.sections.size()));
  Store<double>(header + internal::kOffsetFps, source.fps);
  Store<uint64_t>(header + internal::kOffsetSettingsHash, source.settings_hash);
  std::memcpy(header + internal::kOffsetSourceHash, source.source_hash.data(),
              source.source_hash.size());
  Store<uint32_t>(header + internal::kOffsetLevelRecordSize, options.level_record_size);
  ClipRef single;
  const std::span<const ClipRef> clips = ClipsToWrite(source, single);
  Store<uint32_t>(header + internal::kOffsetClipCount, static_cast<uint32_t>(clips.size()));
  Store<uint32_t>(header + internal::kOffsetClipRecordSize, options.clip_record_size);
  Store<uint32_t>(header + internal::kOffsetVertexCount, source.vertex_count);
  put(header, sizeof header);
  fill(options.header_size - kHeaderSize, std::byte{options.extension_fill});

  // Directory.
  for (const PlannedSection& planned : layout.sections) {
    std::byte entry[kDirectoryEntrySize];
    Store<uint32_t>(entry + 0, planned.kind);
    Store<uint32_t>(entry + 4, planned.level);
    Store<uint64_t>(entry + 8, planned.offset);
    Store<uint64_t>(entry + 16, planned.size);
    put(entry, sizeof entry);
  }

  // Sections, in directory order, each at its planned offset.
  const PlannedSection* section = layout.sections.data();
  const auto begin_section = [&] { pad_to((section++)->offset); };
  const auto write_bytes = [&](const void* bytes, size_t size) {
    begin_section();
    put(bytes, size);
  };
  write_bytes(source.variant_name.data(), source.variant_name.size());
  begin_section();
  for (std::string_view name : source.joint_names) {
    const auto length = static_cast<uint16_t>(name.size());
    put(&length, sizeof length);
    put(name.data(), name.size());
  }
  write_bytes(source.parents.data(), source.parents.size_bytes());
  begin_section();
  for (const LevelRef& level : source.levels) {
    std::byte record[kLevelRecordSize] = {};
    Store<uint32_t>(record + internal::kRecordOffsetKeptCount,
                    static_cast<uint32_t>(level.kept_joints.size()));
    const float figures[5] = {level.figures.max_vertex_error_pct,
                              level.figures.mean_vertex_error_pct,
                              level.figures.mean_normal_error_deg, level.figures.mean_E,
                              level.figures.max_px_for_1px_error};
    std::memcpy(record + internal::kRecordOffsetFigures, figures, sizeof figures);
    Store<uint32_t>(record + internal::kRecordOffsetFrameStride, level.frame_stride);
    Store<uint32_t>(record + internal::kRecordOffsetInfluencesPerVertex,
                    level.influences_per_vertex);
    Store<uint32_t>(record + internal::kRecordOffsetVertexCount,
                    static_cast<uint32_t>(level.vertices.size()));
    Store<uint32_t>(record + internal::kRecordOffsetTriangleCount,
                    static_cast<uint32_t>(level.triangles.size() / 3));
    Store<float>(record + internal::kRecordOffsetCost, level.cost);
    put(record, sizeof record);
    fill(options.level_record_size - kLevelRecordSize, std::byte{options.extension_fill});
  }
  begin_section();
  for (const ClipRef& clip : clips) {
    std::byte record[kClipRecordSize] = {};
    Store<uint32_t>(record + internal::kClipOffsetFirstFrame, clip.first_frame);
    Store<uint32_t>(record + internal::kClipOffsetFrameCount, clip.frame_count);
    Store<double>(record + internal::kClipOffsetFps, clip.fps);
    put(record, sizeof record);
    fill(options.clip_record_size - kClipRecordSize, std::byte{options.extension_fill});
  }
  for (const ClipRef& clip : clips) {
    const auto length = static_cast<uint16_t>(clip.name.size());
    put(&length, sizeof length);
    put(clip.name.data(), clip.name.size());
  }
  for (const LevelRef& level : source.levels) {
    write_bytes(level.kept_joints.data(), level.kept_joints.size_bytes());
    write_bytes(level.joint_map.data(), level.joint_map.size_bytes());
    write_bytes(level.matrices.data(), level.matrices.size_bytes());
    write_bytes(level.vertices.data(), level.vertices.size_bytes());
    write_bytes(level.triangles.data(), level.triangles.size_bytes());
    write_bytes(level.influence_slots.data(), level.influence_slots.size_bytes());
    write_bytes(level.influence_weights.data(), level.influence_weights.size_bytes());
  }
  for (const ExtraSection& extra : options.extra_sections) {
    write_bytes(extra.bytes.data(), extra.bytes.size());
  }

  // Trailer.
  pad_to(layout.trailer_offset);
  put(internal::kTrailerMagic, sizeof internal::kTrailerMagic);
  std::byte checksum[8];
  Store<uint64_t>(checksum, Xxh64(std::span<const std::byte>(sink.data(), layout.file_size - 8)));
  put(checksum, sizeof checksum);
}

// Reads `count` names, each a u16 byte length then that many bytes, that must fill `bytes`
// exactly; the views point into `bytes`. A problem names `section` and the `item`.
std::string ReadNames(std::span<const std::byte> bytes, uint64_t count, const char* section,
                      const char* item, std::vector<std::string_view>& names) {
  names.reserve(count);  // count <= bytes.size() / 2, checked by the callers
  uint64_t at = 0;
  for (uint64_t i = 0; i < count; ++i) {
    if (bytes.size() - at < 2) {
      return StrCat(section, " ends inside the length of ", item, " ", i);
    }
    const auto length = Load<uint16_t>(bytes.data() + at);
    at += 2;
    if (bytes.size() - at < length) {
      return StrCat(section, " ends inside the name of ", item, " ", i);
    }
    names.emplace_back(reinterpret_cast<const char*>(bytes.data() + at), length);
    at += length;
  }
  if (at != bytes.size()) {
    return StrCat(section, " has ", bytes.size() - at, " bytes past the last name");
  }
  return {};
}

StatusOr<std::string> EncodeSource(const LevelSetRef& source, const WriterOptions& options) {
  const Layout layout = PlanLayout(source, options);
  std::string out;
  if (layout.file_size > out.max_size()) {
    return InvalidArgument(StrCat("the level set needs ", layout.file_size, " bytes"));
  }
  out.reserve(layout.file_size);
  StringSink sink(out);
  WriteLevelSet(source, options, layout, sink);
  return out;
}

}  // namespace

// -----------------------------------------------------------------------------------
// Decoding.

// Befriended by the views; checks a buffer and fills them in.
class LevelSetDecoder {
 public:
  static StatusOr<LevelSetView> Decode(std::span<const std::byte> bytes,
                                       const DecodeOptions& options);
};

StatusOr<LevelSetView> LevelSetDecoder::Decode(std::span<const std::byte> bytes,
                                               const DecodeOptions& options) {
  const std::byte* const data = bytes.data();
  const uint64_t size = bytes.size();
  auto malformed = [](std::string message) { return DataLoss(std::move(message)); };

  if (!IsLevelFormatAligned(data)) {
    return InvalidArgument(
        StrCat("the level set buffer starts at an address that is not a multiple of ",
               kLevelFormatAlignment, " bytes; decode an AlignedBytes::CopyOf it"));
  }
  if (size >= sizeof internal::kMagic &&
      std::memcmp(data, internal::kMagic, sizeof internal::kMagic) != 0) {
    return InvalidArgument("not a Motion LoD level set (bad magic)");
  }
  if (size < internal::kOffsetHeaderSize) {
    return malformed(StrCat("truncated: ", size, " bytes cannot hold the header"));
  }
  const auto major = Load<uint16_t>(data + internal::kOffsetMajorVersion);
  const auto minor = Load<uint16_t>(data + internal::kOffsetMinorVersion);
  static_assert(kOldestReadableMajorVersion == 1 && kLevelFormatMajorVersion == 3);
  if (major < kOldestReadableMajorVersion || major > kLevelFormatMajorVersion) {
    return Unsupported(StrCat("level format version ", major, ".", minor,
                              " is not supported (this build reads versions 1.x, 2.x and ",
                              kLevelFormatMajorVersion, ".x)"));
  }
  // 1.x has no clip table: one unnamed clip of every frame, at the header's fps. 1.x and
  // 2.x levels have a 32-byte record and three sections: every frame stored, no mesh or
  // influences of their own, no cost.
  const bool v1 = major == 1;
  const bool v3 = major == kLevelFormatMajorVersion;
  // A file of a later minor version may extend the header, the level and clip records,
  // set flag bits and fill reserved fields this build does not know, and append
  // sections; one of a minor version this build knows may not (1.0 and 2.0 are the last
  // of theirs).
  const bool from_later_minor = minor > (v3 ? kLevelFormatMinorVersion : 0);
  const uint32_t global_sections = v1 ? internal::kV1GlobalSectionCount : kGlobalSectionCount;
  const uint32_t sections_per_level = v3 ? kSectionsPerLevel : internal::kV2SectionsPerLevel;
  const uint32_t known_record_size = v3 ? kLevelRecordSize : internal::kV2LevelRecordSize;
  if (size < kHeaderSize + kTrailerSize) {
    return malformed(StrCat("truncated: ", size, " bytes cannot hold header and trailer"));
  }

  // Header.
  const auto header_size = Load<uint32_t>(data + internal::kOffsetHeaderSize);
  const auto file_size = Load<uint64_t>(data + internal::kOffsetFileSize);
  const auto flags = Load<uint32_t>(data + internal::kOffsetFlags);
  const auto joint_count = Load<uint32_t>(data + internal::kOffsetJointCount);
  const auto level_count = Load<uint32_t>(data + internal::kOffsetLevelCount);
  const auto frame_count = Load<uint32_t>(data + internal::kOffsetFrameCount);
  const auto section_count = Load<uint32_t>(data + internal::kOffsetSectionCount);
  const auto level_record_size = Load<uint32_t>(data + internal::kOffsetLevelRecordSize);
  if (file_size != size) {
    return malformed(StrCat("the header says the file is ", file_size, " bytes but there are ",
                            size, (file_size > size ? " (truncated)" : "")));
  }
  if (size % kAlignment != 0) {
    return malformed(StrCat("the file size ", size, " is not a multiple of ", kAlignment));
  }
  const uint64_t trailer_offset = size - kTrailerSize;
  if (std::memcmp(data + trailer_offset, internal::kTrailerMagic, sizeof internal::kTrailerMagic) !=
      0) {
    return malformed("the trailer magic is missing (truncated or corrupted)");
  }
  if (options.verify_checksum) {
    const auto stored = Load<uint64_t>(data + size - 8);
    const uint64_t computed = Xxh64(bytes.first(size - 8));
    if (stored != computed) return malformed("checksum mismatch: the file is corrupted");
  }
  if (header_size < kHeaderSize || header_size % kAlignment != 0 ||
      (!from_later_minor && header_size != kHeaderSize)) {
    return malformed(
        StrCat("header size ", header_size, " is invalid for version ", major, ".", minor));
  }
  if (header_size > trailer_offset) {
    return malformed(StrCat("header size ", header_size, " runs past the end of the file"));
  }
  if (level_record_size < known_record_size || level_record_size % 4 != 0 ||
      (!from_later_minor && level_record_size != known_record_size)) {
    return malformed(StrCat("level record size ", level_record_size, " is invalid for version ",
                            major, ".", minor));
  }
  const uint32_t clip_count = v1 ? 1 : Load<uint32_t>(data + internal::kOffsetClipCount);
  const uint32_t clip_record_size =
      v1 ? kClipRecordSize : Load<uint32_t>(data + internal::kOffsetClipRecordSize);
  if (clip_record_size < kClipRecordSize || clip_record_size % 8 != 0 ||
      (!from_later_minor && clip_record_size != kClipRecordSize)) {
    return malformed(StrCat("clip record size ", clip_record_size, " is invalid for version ",
                            major, ".", minor));
  }
  if (!from_later_minor) {
    if ((flags & ~kKnownLevelSetFlags) != 0) {
      return malformed(StrCat("unknown flag bits ", flags & ~kKnownLevelSetFlags));
    }
    // 3.x has none: offset 108 holds the vertex count.
    bool reserved_zero = true;
    if (v1) {
      reserved_zero = Load<uint32_t>(data + internal::kV1OffsetReserved0) == 0 &&
                      Load<uint64_t>(data + internal::kV1OffsetReserved1) == 0;
    } else if (!v3) {
      reserved_zero = Load<uint32_t>(data + internal::kV2OffsetReserved) == 0;
    }
    if (!reserved_zero) return malformed("reserved header fields are not zero");
  }
  if (joint_count == 0 || joint_count > kMaxJointCount) {
    return malformed(StrCat("joint count ", joint_count, " is out of [1, ", kMaxJointCount, "]"));
  }
  if (level_count == 0 || level_count > kMaxLevelCount) {
    return malformed(StrCat("level count ", level_count, " is out of [1, ", kMaxLevelCount, "]"));
  }
  if (frame_count == 0) return malformed("the frame count is 0");
  if (clip_count == 0 || clip_count > frame_count) {
    return malformed(StrCat("clip count ", clip_count, " is out of [1, ", frame_count,
                            "] (at most one clip per frame)"));
  }

  // Directory: the known sections in canonical order, then (later minor versions only)
  // sections this build skips. Every section starts on the first 16-byte boundary
  // after its predecessor, and every byte between is zero.
  const uint64_t known_sections = global_sections + uint64_t{sections_per_level} * level_count;
  if (section_count < known_sections || (!from_later_minor && section_count != known_sections)) {
    return malformed(StrCat("section count ", section_count, " for ", level_count,
                            " levels (expected ", known_sections, ")"));
  }
  const uint64_t directory_end = header_size + uint64_t{kDirectoryEntrySize} * section_count;
  if (directory_end > trailer_offset) {
    return malformed(StrCat("the directory of ", section_count, " sections runs past the end"));
  }
  struct Section {
    uint64_t offset;
    uint64_t size;
  };
  std::vector<Section> sections;  // the known ones; bounded by the file size above
  sections.reserve(known_sections);
  uint64_t cursor = AlignUp(directory_end);  // <= trailer_offset, a multiple of 16
  if (!AllZero(bytes.subspan(directory_end, cursor - directory_end))) {
    return malformed("non-zero padding after the directory");
  }
  for (uint64_t i = 0; i < section_count; ++i) {
    const std::byte* entry = data + header_size + i * kDirectoryEntrySize;
    const auto kind = Load<uint32_t>(entry + 0);
    const auto level = Load<uint32_t>(entry + 4);
    const auto offset = Load<uint64_t>(entry + 8);
    const auto section_size = Load<uint64_t>(entry + 16);
    if (offset != cursor) {
      return malformed(StrCat("section ", i, " starts at ", offset, " instead of ", cursor));
    }
    if (section_size > trailer_offset - offset) {
      return malformed(StrCat("section ", i, " of ", section_size, " bytes at ", offset,
                              " runs past the end of the file"));
    }
    const uint64_t end = offset + section_size;
    cursor = AlignUp(end);  // <= trailer_offset, which is a multiple of 16
    if (!AllZero(bytes.subspan(end, cursor - end))) {
      return malformed(StrCat("non-zero padding after section ", i));
    }
    if (i < known_sections) {
      SectionKind expected_kind;
      uint32_t expected_level = kNoLevel;
      if (i < global_sections) {
        expected_kind = static_cast<SectionKind>(i + 1);
      } else {
        const uint64_t k = i - global_sections;
        expected_kind = static_cast<SectionKind>(static_cast<uint32_t>(SectionKind::kKeptJoints) +
                                                 k % sections_per_level);
        expected_level = static_cast<uint32_t>(k / sections_per_level);
      }
      if (kind != static_cast<uint32_t>(expected_kind) || level != expected_level) {
        return malformed(
            StrCat("section ", i, " is of kind ", kind, " for level ",
                   static_cast<int64_t>(level == kNoLevel ? -1 : level), "; expected kind ",
                   static_cast<uint32_t>(expected_kind), " for level ",
                   static_cast<int64_t>(expected_level == kNoLevel ? -1 : expected_level)));
      }
      sections.push_back({offset, section_size});
    }
  }
  if (cursor != trailer_offset) {
    return malformed(StrCat(trailer_offset - cursor, " unclaimed bytes before the trailer"));
  }

  // Section contents. Sizes are checked before any array is read or allocated.
  const uint64_t n = joint_count;
  const Section& variant = sections[0];
  const Section& names = sections[1];
  const Section& parents = sections[2];
  const Section& table = sections[3];
  if (variant.size > kMaxNameBytes) {
    return malformed(
        StrCat("the variant name is ", variant.size, " bytes long (at most ", kMaxNameBytes, ")"));
  }
  if (parents.size != 4 * n) {
    return malformed(StrCat("the parents section is ", parents.size, " bytes for ", n, " joints"));
  }
  if (names.size < 2 * n) {
    return malformed(
        StrCat("the joint names section is ", names.size, " bytes for ", n, " joints"));
  }
  if (table.size != uint64_t{level_record_size} * level_count) {  // < 2^48
    return malformed(StrCat("the level table is ", table.size, " bytes for ", level_count,
                            " records of ", level_record_size));
  }

  LevelSetRef source;
  source.flags = flags;
  source.algorithm_version = Load<uint32_t>(data + internal::kOffsetAlgorithmVersion);
  source.frame_count = frame_count;
  source.fps = Load<double>(data + internal::kOffsetFps);
  std::memcpy(source.source_hash.data(), data + internal::kOffsetSourceHash,
              source.source_hash.size());
  source.settings_hash = Load<uint64_t>(data + internal::kOffsetSettingsHash);
  source.variant_name = {reinterpret_cast<const char*>(data + variant.offset), variant.size};
  std::string problem = ReadNames({data + names.offset, names.size}, n, "the joint names section",
                                  "joint", source.joint_names);
  if (!problem.empty()) return malformed(std::move(problem));
  if (!v1) {
    // The clip table: C records, then C length-prefixed names filling the rest exactly.
    // C <= T < 2^32 and the record size < 2^32: the product does not wrap.
    const Section& clip_table = sections[internal::kV1GlobalSectionCount];
    const uint64_t records_bytes = uint64_t{clip_count} * clip_record_size;
    if (clip_table.size < records_bytes + 2 * uint64_t{clip_count}) {
      return malformed(StrCat("the clip table is ", clip_table.size, " bytes for ", clip_count,
                              " clips (records of ", clip_record_size, " bytes, then names)"));
    }
    std::vector<std::string_view> clip_names;
    problem = ReadNames({data + clip_table.offset + records_bytes, clip_table.size - records_bytes},
                        clip_count, "the clip table", "clip", clip_names);
    if (!problem.empty()) return malformed(std::move(problem));
    source.clips.resize(clip_count);
    for (uint32_t c = 0; c < clip_count; ++c) {
      const std::byte* record = data + clip_table.offset + uint64_t{c} * clip_record_size;
      source.clips[c] = {clip_names[c], Load<uint32_t>(record + internal::kClipOffsetFirstFrame),
                         Load<uint32_t>(record + internal::kClipOffsetFrameCount),
                         Load<double>(record + internal::kClipOffsetFps)};
    }
  }
  // In place: the offset is a multiple of 16 and so is the buffer's address.
  source.parents = {reinterpret_cast<const int32_t*>(data + parents.offset), n};
  source.vertex_count = v3 ? Load<uint32_t>(data + internal::kOffsetVertexCount) : 0;
  // The clips before the levels: the levels' matrix sizes follow from their frame counts,
  // which once checked add up to T, so that T' <= T < 2^32.
  problem = CheckFrames(source);
  if (!problem.empty()) return malformed(std::move(problem));
  ClipRef single;
  const std::span<const ClipRef> clips = ClipsToWrite(source, single);
  const StoredFrames stored_frames = StoredFramesByStride(clips);

  source.levels.resize(level_count);
  for (uint32_t l = 0; l < level_count; ++l) {
    const std::byte* record = data + table.offset + uint64_t{l} * level_record_size;
    const auto m = Load<uint32_t>(record + internal::kRecordOffsetKeptCount);
    if (m == 0 || m > n) {
      return malformed(StrCat("level ", l, " keeps ", m, " joints of ", n));
    }
    LevelRef& level = source.levels[l];
    uint32_t level_vertices = 0;
    uint32_t triangle_count = 0;
    bool reserved_zero;
    if (v3) {
      level.frame_stride = Load<uint32_t>(record + internal::kRecordOffsetFrameStride);
      level.influences_per_vertex =
          Load<uint32_t>(record + internal::kRecordOffsetInfluencesPerVertex);
      level_vertices = Load<uint32_t>(record + internal::kRecordOffsetVertexCount);
      triangle_count = Load<uint32_t>(record + internal::kRecordOffsetTriangleCount);
      level.cost = Load<float>(record + internal::kRecordOffsetCost);
      reserved_zero = Load<uint32_t>(record + internal::kRecordOffsetReserved) == 0;
    } else {
      reserved_zero = Load<uint64_t>(record + internal::kV2RecordOffsetReserved) == 0;
    }
    if (!from_later_minor && !reserved_zero) {
      return malformed(StrCat("level ", l, ": reserved record fields are not zero"));
    }
    // The sizes below follow from these two.
    problem = CheckFrameStride(l, level.frame_stride);
    if (problem.empty()) problem = CheckInfluencesPerVertex(l, level.influences_per_vertex);
    if (!problem.empty()) return malformed(std::move(problem));
    const uint32_t k = level.influences_per_vertex;
    float figures[5];
    std::memcpy(figures, record + internal::kRecordOffsetFigures, sizeof figures);
    level.figures = {figures[0], figures[1], figures[2], figures[3], figures[4]};

    // Every count below 2^32, k <= 8, T' <= T: no product wraps.
    const uint64_t frames = stored_frames[level.frame_stride];
    const uint64_t influence_entries =
        uint64_t{k} * (level_vertices != 0 ? level_vertices : source.vertex_count);
    const uint64_t counts[kSectionsPerLevel] = {m,
                                                n,
                                                frames * m * kMatrixFloats,
                                                level_vertices,
                                                3 * uint64_t{triangle_count},
                                                influence_entries,
                                                influence_entries};
    constexpr uint64_t kElementBytes[kSectionsPerLevel] = {2, 2, 4, 4, 4, 2, 4};
    constexpr const char* kSectionNames[kSectionsPerLevel] = {
        "kept joints", "joint map",       "matrices",         "vertices",
        "triangles",   "influence slots", "influence weights"};
    const size_t first = global_sections + uint64_t{sections_per_level} * l;
    for (uint32_t i = 0; i < sections_per_level; ++i) {
      if (sections[first + i].size != counts[i] * kElementBytes[i]) {
        return malformed(StrCat(
            "level ", l, ": the ", kSectionNames[i], " section is ", sections[first + i].size,
            " bytes; expected ", counts[i] * kElementBytes[i], " for m = ", m, ", n = ", n,
            ", T' = ", frames, " (T = ", frame_count, ", frame stride ", level.frame_stride, "), ",
            level_vertices, " vertices, ", triangle_count, " triangles, k = ", k));
      }
    }
    // In place, as the parents; a 2.x level's sections past the matrices stay empty.
    const auto at = [&](uint32_t i) { return data + sections[first + i].offset; };
    level.kept_joints = {reinterpret_cast<const uint16_t*>(at(0)), counts[0]};
    level.joint_map = {reinterpret_cast<const uint16_t*>(at(1)), counts[1]};
    level.matrices = {reinterpret_cast<const float*>(at(2)), counts[2]};
    if (v3) {
      level.vertices = {reinterpret_cast<const uint32_t*>(at(3)), counts[3]};
      level.triangles = {reinterpret_cast<const uint32_t*>(at(4)), counts[4]};
      level.influence_slots = {reinterpret_cast<const uint16_t*>(at(5)), counts[5]};
      level.influence_weights = {reinterpret_cast<const float*>(at(6)), counts[6]};
    }
  }

  problem = CheckNamesAndLevels(source, {}, MatrixValues::kChecked);
  if (!problem.empty()) return malformed(std::move(problem));

  LevelSetView view;
  view.bytes_ = bytes;
  view.major_version_ = major;
  view.minor_version_ = minor;
  view.flags_ = flags;
  view.algorithm_version_ = source.algorithm_version;
  view.frame_count_ = frame_count;
  view.vertex_count_ = source.vertex_count;
  view.fps_ = source.fps;
  view.source_hash_ = source.source_hash;
  view.settings_hash_ = source.settings_hash;
  view.variant_name_ = source.variant_name;
  view.joint_names_ = std::move(source.joint_names);
  view.parents_ = source.parents;
  view.levels_.resize(level_count);
  for (uint32_t l = 0; l < level_count; ++l) {
    const LevelRef& ref = source.levels[l];
    LevelView& level = view.levels_[l];
    level.frame_count_ = static_cast<uint32_t>(stored_frames[ref.frame_stride]);
    level.frame_stride_ = ref.frame_stride;
    level.kept_joints_ = ref.kept_joints;
    level.joint_map_ = ref.joint_map;
    level.figures_ = ref.figures;
    level.cost_ = ref.cost;
    level.matrices_ = ref.matrices;
    level.vertices_ = ref.vertices;
    level.triangles_ = ref.triangles;
    level.influences_per_vertex_ = ref.influences_per_vertex;
    level.influence_slots_ = ref.influence_slots;
    level.influence_weights_ = ref.influence_weights;
    // O(C) a level, which the file's size bounds: each clip stores a frame of m matrices.
    level.clip_first_stored_.resize(clips.size());
    uint32_t first_stored = 0;
    for (size_t c = 0; c < clips.size(); ++c) {
      level.clip_first_stored_[c] = first_stored;
      first_stored += StoredFrameCount(clips[c].frame_count, ref.frame_stride);
    }
  }
  view.clips_.reserve(clips.size());
  for (const ClipRef& clip : clips) {
    view.clips_.push_back({clip.name, clip.first_frame, clip.frame_count, clip.fps});
  }
  return view;
}

// -----------------------------------------------------------------------------------
// Public entry points.

LevelSetRef RefOf(const LevelSetData& data) {
  LevelSetRef source;
  source.flags = data.flags;
  source.algorithm_version = data.algorithm_version;
  source.frame_count = data.frame_count;
  source.vertex_count = data.vertex_count;
  source.fps = data.fps;
  source.source_hash = data.source_hash;
  source.settings_hash = data.settings_hash;
  source.variant_name = data.variant_name;
  source.joint_names.assign(data.joint_names.begin(), data.joint_names.end());
  source.parents = data.parents;
  source.levels.reserve(data.levels.size());
  for (const LevelData& level : data.levels) {
    source.levels.push_back({.kept_joints = level.kept_joints,
                             .joint_map = level.joint_map,
                             .figures = level.figures,
                             .matrices = level.matrices,
                             .frame_stride = level.frame_stride,
                             .vertices = level.vertices,
                             .triangles = level.triangles,
                             .influences_per_vertex = level.influences_per_vertex,
                             .influence_slots = level.influence_slots,
                             .influence_weights = level.influence_weights,
                             .cost = level.cost});
  }
  source.clips.reserve(data.clips.size());
  for (const ClipInfo& clip : data.clips) {
    source.clips.push_back({clip.name, clip.first_frame, clip.frame_count, clip.fps});
  }
  return source;
}

FrameBlend LevelView::Blend(uint32_t c, uint32_t t, uint32_t clip_frame_count) const {
  assert(c < clip_first_stored_.size() && t < clip_frame_count);
  const uint32_t first = clip_first_stored_[c];
  const uint32_t r = frame_stride_;
  if (t == clip_frame_count - 1) {
    const uint32_t last = first + StoredFrameCount(clip_frame_count, r) - 1;
    return {last, last, 0.0f};
  }
  // Between stored frame k (frame k r) and the next: frame k r + r, or the clip's last
  // where that comes first.
  const uint32_t k = t / r;
  const uint32_t from_frame = k * r;
  if (t == from_frame) return {first + k, first + k, 0.0f};
  const uint32_t to_frame = std::min(from_frame + r, clip_frame_count - 1);
  return {first + k, first + k + 1,
          static_cast<float>(t - from_frame) / static_cast<float>(to_frame - from_frame)};
}

int LevelSetView::FindClip(std::string_view name) const {
  for (size_t c = 0; c < clips_.size(); ++c) {
    if (clips_[c].name == name) return static_cast<int>(c);
  }
  return -1;
}

Status ValidateLevelSet(const LevelSetData& data, const PieceRunner& run) {
  std::string problem = CheckLevelSet(RefOf(data), run);
  if (!problem.empty()) return InvalidArgument(std::move(problem));
  return Status::Ok();
}

StatusOr<std::vector<uint16_t>> ComputeJointMap(std::span<const int32_t> parents,
                                                std::span<const uint16_t> kept_joints) {
  const size_t n = parents.size();
  if (n == 0 || n > kMaxJointCount) return InvalidArgument(StrCat("invalid joint count ", n));
  if (parents[0] != -1) return InvalidArgument("joint 0 must be the root (parent -1)");
  for (size_t j = 1; j < n; ++j) {
    if (parents[j] < 0 || static_cast<size_t>(parents[j]) >= j) {
      return InvalidArgument(
          StrCat("joint ", j, " has parent ", parents[j], "; parents must be topological"));
    }
  }
  std::string problem = CheckKeptJoints(0, n, kept_joints);
  if (!problem.empty()) return InvalidArgument(std::move(problem));
  std::vector<uint16_t> map(n);
  size_t next_slot = 0;
  for (size_t j = 0; j < n; ++j) {
    if (next_slot < kept_joints.size() && kept_joints[next_slot] == j) {
      map[j] = static_cast<uint16_t>(next_slot++);
    } else {
      map[j] = map[static_cast<size_t>(parents[j])];
    }
  }
  return map;
}

size_t EncodedLevelSetSize(const LevelSetData& data) {
  return static_cast<size_t>(PlanLayout(RefOf(data), WriterOptions{}).file_size);
}

StatusOr<std::string> EncodeLevelSet(const LevelSetData& data, const PieceRunner& run) {
  return internal::EncodeLevelSetWithOptions(RefOf(data), WriterOptions{}, run);
}

StatusOr<std::string> EncodeLevelSet(const LevelSetRef& data, const PieceRunner& run) {
  return internal::EncodeLevelSetWithOptions(data, WriterOptions{}, run);
}

StatusOr<size_t> EncodeLevelSetInto(const LevelSetData& data, std::span<std::byte> out) {
  Status status = ValidateLevelSet(data);
  if (!status.ok()) return status;
  const LevelSetRef source = RefOf(data);
  const WriterOptions options;
  const Layout layout = PlanLayout(source, options);
  if (out.size() < layout.file_size) {
    return InvalidArgument(
        StrCat("the output holds ", out.size(), " bytes; the level set needs ", layout.file_size));
  }
  BufferSink sink(out.data());
  WriteLevelSet(source, options, layout, sink);
  return static_cast<size_t>(layout.file_size);
}

StatusOr<LevelSetView> DecodeLevelSet(std::span<const std::byte> bytes,
                                      const DecodeOptions& options) {
  return LevelSetDecoder::Decode(bytes, options);
}

StatusOr<LevelSetView> DecodeLevelSet(std::string_view bytes, const DecodeOptions& options) {
  return LevelSetDecoder::Decode(std::as_bytes(std::span(bytes.data(), bytes.size())), options);
}

StatusOr<std::string> ExtractLevel(const LevelSetView& view, uint32_t l) {
  if (l >= view.level_count()) {
    return NotFound(StrCat("level ", l, " of a level set of ", view.level_count()));
  }
  // The view was validated when decoded: write without checking again.
  LevelSetRef source = HeaderRefOf(view);
  source.levels.push_back(RefOf(view.level(l)));
  return EncodeSource(source, WriterOptions{});
}

StatusOr<std::string> ExtractLevelClip(const LevelSetView& view, uint32_t l, uint32_t clip) {
  if (l >= view.level_count()) {
    return NotFound(StrCat("level ", l, " of a level set of ", view.level_count()));
  }
  if (clip >= view.clip_count()) {
    return NotFound(StrCat("clip ", clip, " of a level set of ", view.clip_count()));
  }
  // Validated when decoded: a clip's frames lie within the level set's, and one clip of
  // at least one frame at a finite positive fps is a valid clip table.
  const ClipView& kept = view.clip(clip);
  LevelSetRef source = HeaderRefOf(view);
  source.frame_count = kept.frame_count;
  source.fps = kept.fps;
  source.clips = {{kept.name, 0, kept.frame_count, kept.fps}};
  // The clip's stored frames at the level's stride.
  const LevelView& chosen = view.level(l);
  LevelRef level = RefOf(chosen);
  const size_t frame_floats = level.kept_joints.size() * kMatrixFloats;
  level.matrices =
      level.matrices.subspan(chosen.clip_first_stored(clip) * frame_floats,
                             StoredFrameCount(kept.frame_count, level.frame_stride) * frame_floats);
  source.levels.push_back(level);
  return EncodeSource(source, WriterOptions{});
}

LevelSetData ToLevelSetData(const LevelSetView& view) {
  LevelSetData data;
  data.variant_name = std::string(view.variant_name());
  data.flags = view.flags() & kKnownLevelSetFlags;
  data.algorithm_version = view.algorithm_version();
  data.frame_count = view.frame_count();
  data.vertex_count = view.vertex_count();
  data.fps = view.fps();
  data.source_hash = view.source_hash();
  data.settings_hash = view.settings_hash();
  data.joint_names.assign(view.joint_names().begin(), view.joint_names().end());
  data.parents.assign(view.parents().begin(), view.parents().end());
  data.levels.reserve(view.level_count());
  for (const LevelView& level : view.levels()) {
    LevelData& copy = data.levels.emplace_back();
    copy.kept_joints.assign(level.kept_joints().begin(), level.kept_joints().end());
    copy.joint_map.assign(level.joint_map().begin(), level.joint_map().end());
    copy.figures = level.figures();
    copy.frame_stride = level.frame_stride();
    copy.matrices.assign(level.matrices().begin(), level.matrices().end());
    copy.vertices.assign(level.vertices().begin(), level.vertices().end());
    copy.triangles.assign(level.triangles().begin(), level.triangles().end());
    copy.influences_per_vertex = level.influences_per_vertex();
    copy.influence_slots.assign(level.influence_slots().begin(), level.influence_slots().end());
    copy.influence_weights.assign(level.influence_weights().begin(),
                                  level.influence_weights().end());
    copy.cost = level.cost();
  }
  // A single unnamed clip is what empty `clips` write.
  if (!(view.clip_count() == 1 && view.clip(0).name.empty())) {
    data.clips.reserve(view.clip_count());
    for (const ClipView& clip : view.clips()) {
      data.clips.push_back({std::string(clip.name), clip.first_frame, clip.frame_count, clip.fps});
    }
  }
  return data;
}

namespace internal {

StatusOr<std::string> EncodeLevelSetWithOptions(const LevelSetRef& source,
                                                const WriterOptions& options,
                                                const PieceRunner& run) {
  // (On this thread: without the values, a level's check is too short to hand to another.)
  std::string problem = CheckLevelSet(source, {}, MatrixValues::kLeftOut);
  if (!problem.empty()) return InvalidArgument(std::move(problem));
  // The matrices' values are checked beside the writing and its checksum, which need only
  // what was checked above (a level set that then fails is dropped): on two threads the
  // checks no longer come before the file's one serial pass. Piece 0 is the writing, the
  // others a level's values each.
  const bool rigid = (source.flags & kLevelSetFlagRigid) != 0;
  std::optional<StatusOr<std::string>> encoded;
  std::vector<std::string> problems(source.levels.size());
  RunPieces(run, 1 + static_cast<int>(source.levels.size()), [&](int piece) {
    if (piece == 0) {
      encoded = EncodeSource(source, options);
      return;
    }
    const LevelRef& level = source.levels[piece - 1];
    problems[piece - 1] =
        CheckMatrixValues(piece - 1, level.kept_joints.size(), rigid, level.matrices);
  });
  for (std::string& level_problem : problems) {
    if (!level_problem.empty()) return InvalidArgument(std::move(level_problem));
  }
  return std::move(*encoded);
}

}  // namespace internal

}  // namespace motionlod::proto
