#include "proto/level_format.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "proto/aligned_bytes.h"
#include "proto/checksum.h"
#include "proto/level_format_internal.h"
#include "tests/proto/level_format_v1.h"
#include "tests/proto/level_format_v2.h"

namespace motionlod::proto {
namespace {

using ::testing::HasSubstr;

// ---------------------------------------------------------------------------------
// Fixtures.

// n = 6:   0 root ─┬─ 1 spine ── 2 head
//                  └─ 3 hip ──── 4 knee ── 5 foot
const std::vector<int32_t> kParents = {-1, 0, 1, 0, 3, 4};

// A finite value per (level, frame, slot, element), signs and magnitudes varied.
float SampleValue(size_t l, size_t t, size_t s, size_t k) {
  const float value = static_cast<float>(l * 1000 + t * 100 + s * 10 + k) * 0.125f;
  return (k % 3 == 1) ? -value : value;
}

LevelData MakeLevel(size_t l, std::vector<uint16_t> kept, uint32_t frames) {
  LevelData level;
  level.kept_joints = std::move(kept);
  level.joint_map = ComputeJointMap(kParents, level.kept_joints).value();
  const size_t m = level.kept_joints.size();
  for (size_t t = 0; t < frames; ++t) {
    for (size_t s = 0; s < m; ++s) {
      for (size_t k = 0; k < kMatrixFloats; ++k) level.matrices.push_back(SampleValue(l, t, s, k));
    }
  }
  return level;
}

// Three levels of the 6-joint skeleton: all joints, {root, spine, hip, knee}, root only.
LevelSetData MakeSample(uint32_t frames = 3) {
  LevelSetData data;
  data.variant_name = "walk_01 \xC3\xA9t\xC3\xA9";  // UTF-8
  data.algorithm_version = 7;
  data.frame_count = frames;
  data.fps = 29.97;
  for (size_t i = 0; i < data.source_hash.size(); ++i) {
    data.source_hash[i] = static_cast<uint8_t>(0xA0 + i);
  }
  data.settings_hash = 0x0123456789ABCDEFull;
  data.joint_names = {"root", "spine", "head", "hip", "knee", "foot"};
  data.parents = kParents;
  data.levels.push_back(MakeLevel(0, {0, 1, 2, 3, 4, 5}, frames));
  data.levels.push_back(MakeLevel(1, {0, 1, 3, 4}, frames));
  data.levels.push_back(MakeLevel(2, {0}, frames));
  data.levels[1].figures = {0.5f, 0.125f, 2.25f, 1e-3f, 200.0f};
  data.levels[2].figures = {4.0f, 1.5f, 12.0f, 0.25f, 25.0f};
  return data;
}

// A rotation about z by `angle` plus a translation.
void AppendRigid(std::vector<float>& out, float angle, float x, float y, float z) {
  const float c = std::cos(angle), s = std::sin(angle);
  const float matrix[12] = {c, -s, 0, x, s, c, 0, y, 0, 0, 1, z};
  out.insert(out.end(), matrix, matrix + 12);
}

LevelSetData MakeRigidSample(uint32_t frames = 2) {
  LevelSetData data = MakeSample(frames);
  data.flags = kLevelSetFlagRigid;
  for (size_t l = 0; l < data.levels.size(); ++l) {
    LevelData& level = data.levels[l];
    level.matrices.clear();
    for (size_t t = 0; t < frames; ++t) {
      for (size_t s = 0; s < level.kept_joints.size(); ++s) {
        AppendRigid(level.matrices, 0.3f * t + 0.7f * s, 1.0f * s, -2.0f * t, 0.5f);
      }
    }
  }
  return data;
}

// The sample as a character-wide level set: three clips over its six frames, the level
// set's fps the first clip's.
LevelSetData MakeClipSample() {
  LevelSetData data = MakeSample(6);
  data.clips = {{"walk", 0, 3, 29.97}, {"jump", 3, 2, 60.0}, {"idle \xC3\xA9", 5, 1, 24.0}};
  return data;
}

// Clip after clip, the level's stored frames at `stride` of every clip: frame t of the
// level set is SampleValue(l, t, ...), as in MakeLevel.
std::vector<float> StoredSampleMatrices(size_t l, size_t m, const std::vector<ClipInfo>& clips,
                                        uint32_t stride) {
  std::vector<float> matrices;
  for (const ClipInfo& clip : clips) {
    for (uint32_t i = 0; i < StoredFrameCount(clip.frame_count, stride); ++i) {
      const uint32_t t = clip.first_frame + std::min(i * stride, clip.frame_count - 1);
      for (size_t s = 0; s < m; ++s) {
        for (size_t k = 0; k < kMatrixFloats; ++k) matrices.push_back(SampleValue(l, t, s, k));
      }
    }
  }
  return matrices;
}

// The sample with what 3.0 adds: 18 frames in clips of 12, 5 and 1; level 0 every frame,
// level 1 every other one with a mesh of its own (5 of the character's 10 vertices, two
// triangles) and 2 influences a vertex, level 2 every third one with 1 influence on each
// of the character's vertices; a cost each.
LevelSetData MakeVersion3Sample() {
  LevelSetData data = MakeSample(18);
  data.clips = {{"walk", 0, 12, 29.97}, {"jump", 12, 5, 60.0}, {"idle", 17, 1, 24.0}};
  data.vertex_count = 10;
  const uint32_t strides[3] = {1, 2, 3};
  const float costs[3] = {1.0f, 0.375f, 0.0625f};
  for (size_t l = 0; l < 3; ++l) {
    LevelData& level = data.levels[l];
    level.frame_stride = strides[l];
    level.matrices = StoredSampleMatrices(l, level.kept_joints.size(), data.clips, strides[l]);
    level.cost = costs[l];
  }
  LevelData& meshed = data.levels[1];  // m = 4
  meshed.vertices = {1, 2, 4, 7, 9};
  meshed.triangles = {0, 1, 2, 2, 3, 4};
  meshed.influences_per_vertex = 2;
  meshed.influence_slots = {0, 1, 1, 2, 3, 0, 2, 3, 1, 1};
  meshed.influence_weights = {0.75f, 0.25f, 1.0f, 0.0f, 0.5f, 0.5f, 0.125f, 0.875f, 0.5f, 0.5f};
  LevelData& coarse = data.levels[2];  // m = 1: every vertex on the root
  coarse.influences_per_vertex = 1;
  coarse.influence_slots.assign(data.vertex_count, 0);
  coarse.influence_weights.assign(data.vertex_count, 1.0f);
  return data;
}

AlignedBytes Encode(const LevelSetData& data) {
  StatusOr<std::string> encoded = EncodeLevelSet(data);
  EXPECT_TRUE(encoded.ok()) << encoded.status().ToString();
  return AlignedBytes::CopyOf(encoded.ok() ? *encoded : std::string());
}

// Recomputes the trailer checksum after a test edited the bytes, so that the decoder
// gets past the checksum to the check under test.
void Reseal(AlignedBytes& bytes) {
  const uint64_t checksum = Xxh64(bytes.bytes().first(bytes.size() - 8));
  std::memcpy(bytes.data() + bytes.size() - 8, &checksum, sizeof checksum);
}

template <typename T>
void Poke(AlignedBytes& bytes, size_t offset, T value) {
  ASSERT_LE(offset + sizeof value, bytes.size());
  std::memcpy(bytes.data() + offset, &value, sizeof value);
}

size_t OffsetIn(const AlignedBytes& bytes, const void* p) {
  return static_cast<size_t>(static_cast<const std::byte*>(p) - bytes.data());
}

// Byte offsets of the sample's parts, found through a decoded view.
struct SampleOffsets {
  size_t parents;
  size_t names;  // the first name's length prefix
  size_t level1_kept;
  size_t level1_map;
  size_t level1_matrices;
  size_t level_table;
};

SampleOffsets OffsetsOf(const AlignedBytes& bytes) {
  const LevelSetView view = DecodeLevelSet(bytes.bytes()).value();
  SampleOffsets offsets;
  offsets.parents = OffsetIn(bytes, view.parents().data());
  offsets.names = OffsetIn(bytes, view.joint_name(0).data()) - 2;
  offsets.level1_kept = OffsetIn(bytes, view.level(1).kept_joints().data());
  offsets.level1_map = OffsetIn(bytes, view.level(1).joint_map().data());
  offsets.level1_matrices = OffsetIn(bytes, view.level(1).matrices().data());
  uint64_t table_offset;
  std::memcpy(&table_offset, bytes.data() + internal::kHeaderSize + 3 * 24 + 8, 8);
  offsets.level_table = static_cast<size_t>(table_offset);
  return offsets;
}

// The status of decoding `bytes` after `edit` and a reseal.
Status DecodeEdited(const AlignedBytes& original, const std::function<void(AlignedBytes&)>& edit) {
  AlignedBytes bytes = AlignedBytes::CopyOf(original.bytes());
  edit(bytes);
  Reseal(bytes);
  return DecodeLevelSet(bytes.bytes()).status();
}

void ExpectBitwiseEqual(std::span<const float> a, std::span<const float> b) {
  ASSERT_EQ(a.size(), b.size());
  EXPECT_EQ(std::memcmp(a.data(), b.data(), a.size_bytes()), 0);
}

// ---------------------------------------------------------------------------------
// Joint map.

TEST(ComputeJointMap, MapsRemovedJointsToTheSlotOfTheirNearestKeptAncestor) {
  // kept {0, 1, 3, 4}: slots 0, 1, 2, 3; head -> spine's slot, foot -> knee's slot.
  const std::vector<uint16_t> kept = {0, 1, 3, 4};
  EXPECT_EQ(ComputeJointMap(kParents, kept).value(), (std::vector<uint16_t>{0, 1, 1, 2, 3, 3}));
  const std::vector<uint16_t> root_and_foot = {0, 5};
  EXPECT_EQ(ComputeJointMap(kParents, root_and_foot).value(),
            (std::vector<uint16_t>{0, 0, 0, 0, 0, 1}));
}

TEST(ComputeJointMap, RejectsKeptListsWithoutRootOrOutOfOrder) {
  const std::vector<uint16_t> no_root = {1, 3};
  const std::vector<uint16_t> descending = {0, 3, 1};
  const std::vector<uint16_t> out_of_range = {0, 6};
  EXPECT_EQ(ComputeJointMap(kParents, no_root).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(ComputeJointMap(kParents, descending).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(ComputeJointMap(kParents, out_of_range).status().code(), StatusCode::kInvalidArgument);
}

// ---------------------------------------------------------------------------------
// Round trips.

TEST(LevelFormat, RoundTripReproducesEveryValue) {
  const LevelSetData data = MakeSample();
  const AlignedBytes bytes = Encode(data);
  StatusOr<LevelSetView> view = DecodeLevelSet(bytes.bytes());
  ASSERT_TRUE(view.ok()) << view.status().ToString();

  EXPECT_EQ(view->minor_version(), kLevelFormatMinorVersion);
  EXPECT_EQ(view->joint_count(), 6u);
  EXPECT_EQ(view->level_count(), 3u);
  EXPECT_EQ(view->frame_count(), 3u);
  EXPECT_EQ(view->fps(), 29.97);
  EXPECT_EQ(view->algorithm_version(), 7u);
  EXPECT_EQ(view->source_hash(), data.source_hash);
  EXPECT_EQ(view->settings_hash(), data.settings_hash);
  EXPECT_EQ(view->variant_name(), data.variant_name);
  EXPECT_FALSE(view->rigid());
  EXPECT_EQ(view->joint_name(4), "knee");
  EXPECT_EQ(view->parents()[5], 4);
  const LevelView& level = view->level(1);
  EXPECT_EQ(level.kept_count(), 4u);
  EXPECT_EQ(level.joint_map()[2], 1u);
  EXPECT_EQ(level.figures(), data.levels[1].figures);
  EXPECT_TRUE(std::isinf(view->level(0).figures().max_px_for_1px_error));
  for (uint32_t t = 0; t < 3; ++t) {
    for (uint32_t s = 0; s < 4; ++s) {
      for (size_t k = 0; k < kMatrixFloats; ++k) {
        EXPECT_EQ(level.matrix(t, s)[k], SampleValue(1, t, s, k));
      }
    }
  }
  EXPECT_EQ(ToLevelSetData(*view), data);
}

TEST(LevelFormat, DecodeViewsTheBufferWithoutCopying) {
  const AlignedBytes bytes = Encode(MakeSample());
  const LevelSetView view = DecodeLevelSet(bytes.bytes()).value();
  const auto inside = [&](const void* p) {
    return p >= static_cast<const void*>(bytes.data()) &&
           p < static_cast<const void*>(bytes.data() + bytes.size());
  };
  EXPECT_TRUE(inside(view.level(2).matrix(2, 0)));
  EXPECT_TRUE(inside(view.level(0).joint_map().data()));
  EXPECT_TRUE(inside(view.joint_name(5).data()));
  EXPECT_TRUE(inside(view.variant_name().data()));
  EXPECT_EQ(view.level(1).matrix(2, 3), view.level(1).frame(2).data() + 3 * kMatrixFloats);
  EXPECT_TRUE(IsLevelFormatAligned(view.level(1).matrices().data()));
}

TEST(LevelFormat, RoundTripKeepsFloatBitPatterns) {
  LevelSetData data = MakeSample(1);
  std::vector<float>& m = data.levels[2].matrices;  // one frame, one slot
  m = {-0.0f,
       std::numeric_limits<float>::denorm_min(),
       std::numeric_limits<float>::max(),
       -std::numeric_limits<float>::max(),
       std::numeric_limits<float>::min(),
       1.0f / 3.0f,
       0,
       0,
       0,
       0,
       0,
       0};
  const AlignedBytes bytes = Encode(data);
  const LevelSetView view = DecodeLevelSet(bytes.bytes()).value();
  ExpectBitwiseEqual(view.level(2).matrices(), m);
}

TEST(LevelFormat, RoundTripOfOneJointOneFrameOneLevel) {
  LevelSetData data;
  data.frame_count = 1;
  data.fps = 60;
  data.joint_names = {"j"};
  data.parents = {-1};
  data.levels.push_back(
      {.kept_joints = {0}, .joint_map = {0}, .matrices = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0}});
  const AlignedBytes bytes = Encode(data);
  StatusOr<LevelSetView> view = DecodeLevelSet(bytes.bytes());
  ASSERT_TRUE(view.ok()) << view.status().ToString();
  EXPECT_EQ(view->variant_name(), "");
  EXPECT_EQ(view->level(0).matrix(0, 0)[5], 1.0f);
  EXPECT_EQ(ToLevelSetData(*view), data);
}

TEST(LevelFormat, RoundTripOfRigidLevelSet) {
  const LevelSetData data = MakeRigidSample();
  const AlignedBytes bytes = Encode(data);
  StatusOr<LevelSetView> view = DecodeLevelSet(bytes.bytes());
  ASSERT_TRUE(view.ok()) << view.status().ToString();
  EXPECT_TRUE(view->rigid());
  EXPECT_EQ(ToLevelSetData(*view), data);
}

TEST(LevelFormat, ReencodingADecodedFileReproducesItByteForByte) {
  const AlignedBytes bytes = Encode(MakeSample());
  const LevelSetView view = DecodeLevelSet(bytes.bytes()).value();
  const std::string again = EncodeLevelSet(ToLevelSetData(view)).value();
  ASSERT_EQ(again.size(), bytes.size());
  EXPECT_EQ(std::memcmp(again.data(), bytes.data(), bytes.size()), 0);
}

TEST(LevelFormat, DecodesFromStringView) {
  const std::string encoded = EncodeLevelSet(MakeSample()).value();
  if (!IsLevelFormatAligned(encoded.data())) GTEST_SKIP() << "this allocator gives < 16";
  EXPECT_TRUE(DecodeLevelSet(std::string_view(encoded)).ok());
}

TEST(LevelFormat, EncodedSizeIsExactAndEveryPartIsAligned) {
  const LevelSetData data = MakeSample();
  const std::string encoded = EncodeLevelSet(data).value();
  EXPECT_EQ(EncodedLevelSetSize(data), encoded.size());
  EXPECT_EQ(encoded.size() % kLevelFormatAlignment, 0u);
}

TEST(LevelFormat, EncodingFromViewsWritesTheSameBytes) {
  const LevelSetData data = MakeSample();
  const std::string encoded = EncodeLevelSet(data).value();
  // Views of arrays the writer does not own, as a bake has them: each level's matrices in
  // one buffer of the whole set, the joint lists in other vectors.
  std::vector<float> all_matrices;
  std::vector<std::vector<uint16_t>> joint_lists;
  for (const LevelData& level : data.levels) {
    all_matrices.insert(all_matrices.end(), level.matrices.begin(), level.matrices.end());
    joint_lists.push_back(level.kept_joints);
    joint_lists.push_back(level.joint_map);
  }
  const std::vector<std::string> names = data.joint_names;
  const std::vector<int32_t> parents = data.parents;
  LevelSetRef ref = RefOf(data);
  ref.joint_names.assign(names.begin(), names.end());
  ref.parents = parents;
  size_t offset = 0;
  for (size_t l = 0; l < data.levels.size(); ++l) {
    const size_t count = data.levels[l].matrices.size();
    ref.levels[l] = {joint_lists[2 * l], joint_lists[2 * l + 1], data.levels[l].figures,
                     std::span<const float>(all_matrices).subspan(offset, count)};
    offset += count;
  }
  const std::string from_views = EncodeLevelSet(ref).value();
  ASSERT_EQ(from_views.size(), encoded.size());
  EXPECT_EQ(std::memcmp(from_views.data(), encoded.data(), encoded.size()), 0);
  // A view of a matrix that is not finite is rejected as the data would be.
  all_matrices[offset - 1] = std::numeric_limits<float>::quiet_NaN();
  EXPECT_EQ(EncodeLevelSet(ref).status().code(), StatusCode::kInvalidArgument);
}

TEST(LevelFormat, EncodeIntoCallerBufferWritesTheSameBytes) {
  const LevelSetData data = MakeSample();
  const std::string encoded = EncodeLevelSet(data).value();
  AlignedBytes out(EncodedLevelSetSize(data) + 5);
  // A used buffer: the padding and reserved fields must still come out zero.
  std::fill(out.mutable_bytes().begin(), out.mutable_bytes().end(), std::byte{0xAB});
  StatusOr<size_t> written = EncodeLevelSetInto(data, out.mutable_bytes());
  ASSERT_TRUE(written.ok()) << written.status().ToString();
  ASSERT_EQ(*written, encoded.size());
  EXPECT_EQ(std::memcmp(out.data(), encoded.data(), encoded.size()), 0);
  EXPECT_TRUE(DecodeLevelSet(out.bytes().first(*written)).ok());
}

TEST(LevelFormat, EncodeIntoRejectsTooSmallBufferAndWritesNothing) {
  const LevelSetData data = MakeSample();
  AlignedBytes out(EncodedLevelSetSize(data) - 1);
  StatusOr<size_t> written = EncodeLevelSetInto(data, out.mutable_bytes());
  EXPECT_EQ(written.status().code(), StatusCode::kInvalidArgument);
  for (std::byte b : out.bytes()) ASSERT_EQ(b, std::byte{0});
}

// ---------------------------------------------------------------------------------
// Extract one level (what the server streams).

TEST(ExtractLevel, ProducesAOneLevelFileOfTheSameFormat) {
  const LevelSetData data = MakeSample();
  const AlignedBytes bytes = Encode(data);
  const LevelSetView view = DecodeLevelSet(bytes.bytes()).value();
  for (uint32_t l = 0; l < view.level_count(); ++l) {
    StatusOr<std::string> extracted = ExtractLevel(view, l);
    ASSERT_TRUE(extracted.ok()) << extracted.status().ToString();
    const AlignedBytes one = AlignedBytes::CopyOf(*extracted);
    StatusOr<LevelSetView> single = DecodeLevelSet(one.bytes());
    ASSERT_TRUE(single.ok()) << single.status().ToString();
    LevelSetData expected = data;
    expected.levels = {data.levels[l]};
    EXPECT_EQ(ToLevelSetData(*single), expected) << "level " << l;
  }
}

TEST(ExtractLevel, OfAOneLevelFileIsThatFile) {
  const AlignedBytes bytes = Encode(MakeSample());
  const LevelSetView view = DecodeLevelSet(bytes.bytes()).value();
  const AlignedBytes one = AlignedBytes::CopyOf(ExtractLevel(view, 1).value());
  const std::string again = ExtractLevel(DecodeLevelSet(one.bytes()).value(), 0).value();
  ASSERT_EQ(again.size(), one.size());
  EXPECT_EQ(std::memcmp(again.data(), one.data(), one.size()), 0);
}

TEST(ExtractLevel, RejectsLevelOutOfRange) {
  const AlignedBytes bytes = Encode(MakeSample());
  const LevelSetView view = DecodeLevelSet(bytes.bytes()).value();
  EXPECT_EQ(ExtractLevel(view, 3).status().code(), StatusCode::kNotFound);
}

// ---------------------------------------------------------------------------------
// Encoder validity: each invalid field combination is rejected with a message naming it.

struct InvalidCase {
  const char* name;
  std::function<void(LevelSetData&)> edit;
  const char* message;
};

TEST(ValidateLevelSet, AcceptsTheSamples) {
  EXPECT_TRUE(ValidateLevelSet(MakeSample()).ok());
  EXPECT_TRUE(ValidateLevelSet(MakeRigidSample()).ok());
}

TEST(ValidateLevelSet, RejectsEachInvalidField) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  const InvalidCase cases[] = {
      {"no joint",
       [](LevelSetData& d) {
         d.joint_names.clear();
         d.parents.clear();
       },
       "no joint"},
      {"names count", [](LevelSetData& d) { d.joint_names.pop_back(); }, "5 joint names"},
      {"root parent", [](LevelSetData& d) { d.parents[0] = 3; }, "must be the root"},
      {"second root", [](LevelSetData& d) { d.parents[3] = -1; }, "topological"},
      {"parent after child", [](LevelSetData& d) { d.parents[2] = 4; }, "topological"},
      {"empty name", [](LevelSetData& d) { d.joint_names[2].clear(); }, "is empty"},
      {"duplicate name", [](LevelSetData& d) { d.joint_names[5] = "hip"; }, "\"hip\""},
      {"name not UTF-8", [](LevelSetData& d) { d.joint_names[1] = "sp\xFFine"; }, "UTF-8"},
      {"name with NUL", [](LevelSetData& d) { d.joint_names[1] = std::string("a\0b", 3); }, "NUL"},
      {"long name", [](LevelSetData& d) { d.joint_names[1] = std::string(70000, 'a'); },
       "at most 65535"},
      {"variant not UTF-8", [](LevelSetData& d) { d.variant_name = "\xC0\xAF"; }, "UTF-8"},
      {"no frame", [](LevelSetData& d) { d.frame_count = 0; }, "no frame"},
      {"fps zero", [](LevelSetData& d) { d.fps = 0; }, "fps"},
      {"fps NaN", [](LevelSetData& d) { d.fps = std::nan(""); }, "fps"},
      {"unknown flag", [](LevelSetData& d) { d.flags = 1u << 9; }, "unknown flag"},
      {"no level", [](LevelSetData& d) { d.levels.clear(); }, "no level"},
      {"level keeps nothing", [](LevelSetData& d) { d.levels[2].kept_joints.clear(); },
       "keeps no joint"},
      {"root removed", [](LevelSetData& d) { d.levels[1].kept_joints[0] = 2; }, "root"},
      {"kept not ascending",
       [](LevelSetData& d) { std::swap(d.levels[1].kept_joints[1], d.levels[1].kept_joints[2]); },
       "not strictly ascending"},
      {"kept duplicate", [](LevelSetData& d) { d.levels[1].kept_joints[2] = 1; },
       "not strictly ascending"},
      {"kept out of range", [](LevelSetData& d) { d.levels[1].kept_joints[3] = 6; },
       "out of range"},
      {"map too short", [](LevelSetData& d) { d.levels[1].joint_map.pop_back(); }, "5 entries"},
      {"map slot too large", [](LevelSetData& d) { d.levels[1].joint_map[5] = 4; }, "(m = 4)"},
      {"kept joint not on own slot", [](LevelSetData& d) { d.levels[0].joint_map[3] = 2; },
       "kept joint 3"},
      {"removed joint not on parent's slot", [](LevelSetData& d) { d.levels[1].joint_map[5] = 2; },
       "removed joint 5"},
      {"matrix count", [](LevelSetData& d) { d.levels[0].matrices.pop_back(); }, "T' x m x 12"},
      {"NaN matrix", [nan](LevelSetData& d) { d.levels[1].matrices[30] = nan; }, "not finite"},
      {"infinite matrix", [inf](LevelSetData& d) { d.levels[1].matrices[30] = inf; }, "not finite"},
      {"NaN figure", [nan](LevelSetData& d) { d.levels[1].figures.mean_E = nan; }, "mean_E"},
      {"negative figure", [](LevelSetData& d) { d.levels[1].figures.max_vertex_error_pct = -1; },
       "max_vertex_error_pct"},
      {"infinite error",
       [inf](LevelSetData& d) { d.levels[1].figures.mean_normal_error_deg = inf; },
       "mean_normal_error_deg"},
      {"NaN max px", [nan](LevelSetData& d) { d.levels[1].figures.max_px_for_1px_error = nan; },
       "max_px_for_1px_error"},
      {"rigid flag on scaled matrices", [](LevelSetData& d) { d.flags = kLevelSetFlagRigid; },
       "flagged rigid"},
  };
  for (const InvalidCase& c : cases) {
    LevelSetData data = MakeSample();
    c.edit(data);
    const Status status = ValidateLevelSet(data);
    EXPECT_EQ(status.code(), StatusCode::kInvalidArgument) << c.name;
    EXPECT_THAT(status.message(), HasSubstr(c.message)) << c.name;
    // Encoding checks the matrices' values beside the writing, and reports the same.
    EXPECT_EQ(EncodeLevelSet(data).status().code(), StatusCode::kInvalidArgument) << c.name;
    EXPECT_EQ(EncodeLevelSet(data).status().message(), status.message()) << c.name;
    EXPECT_EQ(EncodeLevelSet(RefOf(data)).status().message(), status.message()) << c.name;
  }
}

TEST(ValidateLevelSet, RejectsReflectionInRigidLevelSet) {
  LevelSetData data = MakeRigidSample();
  data.levels[0].matrices[0] = -data.levels[0].matrices[0];  // flip the first column
  data.levels[0].matrices[4] = -data.levels[0].matrices[4];
  data.levels[0].matrices[8] = -data.levels[0].matrices[8];
  EXPECT_THAT(ValidateLevelSet(data).message(), HasSubstr("flagged rigid"));
}

// The rigid check runs over all matrices before it locates a culprit: a reflection at
// every position of every level is the one named.
TEST(ValidateLevelSet, RejectsAReflectionWhereverItSitsInARigidLevelSet) {
  const LevelSetData sample = MakeRigidSample(3);
  ASSERT_TRUE(ValidateLevelSet(sample).ok());
  for (size_t l = 0; l < sample.levels.size(); ++l) {
    const size_t slots = sample.levels[l].kept_joints.size();
    const size_t count = sample.levels[l].matrices.size() / kMatrixFloats;
    for (size_t matrix = 0; matrix < count; ++matrix) {
      LevelSetData data = sample;
      float* k = data.levels[l].matrices.data() + matrix * kMatrixFloats;
      for (int row = 0; row < 3; ++row) k[4 * row] = -k[4 * row];
      const Status status = ValidateLevelSet(data);
      EXPECT_THAT(
          status.message(),
          HasSubstr("level " + std::to_string(l) + ": K'(frame " + std::to_string(matrix / slots) +
                    ", slot " + std::to_string(matrix % slots) + ") is not a rotation"))
          << l << " " << matrix;
    }
  }
}

// Unit columns that are not orthogonal: only the off-diagonal entries of A^T A show it.
// The last matrix of the last level, so that every other matrix is checked first.
TEST(ValidateLevelSet, RejectsShearInRigidLevelSet) {
  LevelSetData data = MakeRigidSample();
  std::vector<float>& matrices = data.levels.back().matrices;
  float* k = matrices.data() + matrices.size() - kMatrixFloats;
  const float c = std::cos(0.01f), s = std::sin(0.01f);  // column 1 tilted towards column 0
  for (int row = 0; row < 3; ++row) k[4 * row + 1] = c * k[4 * row + 1] + s * k[4 * row];
  const Status status = ValidateLevelSet(data);
  EXPECT_THAT(status.message(), HasSubstr("flagged rigid"));
  const size_t slots = data.levels.back().kept_joints.size();
  EXPECT_THAT(status.message(), HasSubstr("K'(frame 1, slot " + std::to_string(slots - 1) + ")"));
  // Tilted by 1e-4 rad instead (a dot product of 1e-4): within the tolerance.
  LevelSetData near = MakeRigidSample();
  std::vector<float>& near_matrices = near.levels.back().matrices;
  float* q = near_matrices.data() + near_matrices.size() - kMatrixFloats;
  const float c4 = std::cos(1e-4f), s4 = std::sin(1e-4f);
  for (int row = 0; row < 3; ++row) q[4 * row + 1] = c4 * q[4 * row + 1] + s4 * q[4 * row];
  EXPECT_TRUE(ValidateLevelSet(near).ok());
}

// Levels are checked as independent pieces (on the bake's threads): whatever order they
// run in, the problem reported is the first level's, as in a serial check.
TEST(ValidateLevelSet, ReportsTheFirstBadLevelWhateverOrderLevelsAreCheckedIn) {
  LevelSetData data = MakeSample();
  data.levels[1].matrices[3] = std::numeric_limits<float>::infinity();
  data.levels[2].matrices[5] = std::numeric_limits<float>::quiet_NaN();
  const PieceRunner backwards = [](int count, const std::function<void(int)>& piece) {
    for (int index = count - 1; index >= 0; --index) piece(index);
  };
  const Status serial = ValidateLevelSet(data);
  EXPECT_THAT(serial.message(), HasSubstr("level 1: K'(frame 0, slot 0) element 3"));
  EXPECT_EQ(ValidateLevelSet(data, backwards).message(), serial.message());
  EXPECT_EQ(EncodeLevelSet(data, backwards).status().message(), serial.message());
}

TEST(EncodeLevelSet, RejectsNanMatrix) {
  LevelSetData data = MakeSample();
  data.levels[0].matrices[7] = std::numeric_limits<float>::quiet_NaN();
  const StatusOr<std::string> encoded = EncodeLevelSet(data);
  EXPECT_EQ(encoded.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(encoded.status().message(), HasSubstr("frame 0, slot 0) element 7"));
}

TEST(EncodeLevelSet, RejectsInconsistentJointMap) {
  LevelSetData data = MakeSample();
  data.levels[1].joint_map[2] = 0;  // head removed, but not on its parent's (spine's) slot
  EXPECT_THAT(EncodeLevelSet(data).status().message(), HasSubstr("removed joint 2"));
}

// ---------------------------------------------------------------------------------
// Decoder rejections.

TEST(DecodeLevelSet, RejectsBadMagic) {
  AlignedBytes bytes = Encode(MakeSample());
  bytes.data()[0] = std::byte{'X'};
  Reseal(bytes);
  const Status status = DecodeLevelSet(bytes.bytes()).status();
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(status.message(), HasSubstr("magic"));
}

TEST(DecodeLevelSet, RefusesOtherMajorVersionsNamingTheVersionFoundAndTheOnesItReads) {
  internal::WriterOptions options;
  options.major_version = 4;
  options.minor_version = 1;
  const LevelSetData sample = MakeSample();
  const AlignedBytes bytes =
      AlignedBytes::CopyOf(internal::EncodeLevelSetWithOptions(RefOf(sample), options).value());
  const Status status = DecodeLevelSet(bytes.bytes()).status();
  EXPECT_EQ(status.code(), StatusCode::kUnsupported);
  EXPECT_THAT(status.message(), HasSubstr("version 4.1 is not supported"));
  EXPECT_THAT(status.message(), HasSubstr("reads versions 1.x, 2.x and 3.x"));

  for (const uint16_t major : {uint16_t{0}, uint16_t{5}, uint16_t{0xFFFF}}) {
    const Status other = DecodeEdited(
        bytes, [&](AlignedBytes& b) { Poke<uint16_t>(b, internal::kOffsetMajorVersion, major); });
    EXPECT_EQ(other.code(), StatusCode::kUnsupported) << major;
    EXPECT_THAT(other.message(), HasSubstr("version " + std::to_string(major) + ".1")) << major;
  }
  // Refused before the checksum is looked at: a reader of another major cannot know it.
  AlignedBytes unsealed = AlignedBytes::CopyOf(bytes.bytes());
  Poke<uint16_t>(unsealed, internal::kOffsetMajorVersion, 0);
  EXPECT_EQ(DecodeLevelSet(unsealed.bytes()).status().code(), StatusCode::kUnsupported);
}

TEST(DecodeLevelSet, RejectsTruncationAtEveryByteOffset) {
  for (const LevelSetData& data : {MakeSample(1), MakeVersion3Sample()}) {
    const AlignedBytes bytes = Encode(data);
    for (size_t size = 0; size < bytes.size(); ++size) {
      const Status status = DecodeLevelSet(bytes.bytes().first(size)).status();
      ASSERT_EQ(status.code(), StatusCode::kDataLoss) << "prefix of " << size << " bytes";
    }
  }
}

TEST(DecodeLevelSet, RejectsTrailingBytes) {
  const AlignedBytes original = Encode(MakeSample());
  AlignedBytes longer(original.size() + 16);
  std::memcpy(longer.data(), original.data(), original.size());
  EXPECT_EQ(DecodeLevelSet(longer.bytes()).status().code(), StatusCode::kDataLoss);
}

TEST(DecodeLevelSet, RejectsEveryFlippedBit) {
  for (const LevelSetData& data : {MakeSample(1), MakeVersion3Sample()}) {
    AlignedBytes bytes = Encode(data);
    for (size_t i = 0; i < bytes.size(); ++i) {
      for (const uint8_t bit : {0x01, 0x80}) {
        bytes.data()[i] ^= std::byte{bit};
        ASSERT_FALSE(DecodeLevelSet(bytes.bytes()).ok()) << "byte " << i << " bit " << int{bit};
        bytes.data()[i] ^= std::byte{bit};
      }
    }
    EXPECT_TRUE(DecodeLevelSet(bytes.bytes()).ok());
  }
}

TEST(DecodeLevelSet, ReportsChecksumMismatchAsDataLoss) {
  AlignedBytes bytes = Encode(MakeSample());
  bytes.data()[OffsetsOf(bytes).level1_matrices] ^= std::byte{0x10};
  const Status status = DecodeLevelSet(bytes.bytes()).status();
  EXPECT_EQ(status.code(), StatusCode::kDataLoss);
  EXPECT_THAT(status.message(), HasSubstr("checksum"));
}

TEST(DecodeLevelSet, WithoutChecksumNeverFailsOtherThanByStatusOnCorruptBytes) {
  // The fuzz target's configuration, on every single-byte corruption of small files (of
  // every version, one with several clips, one with strides, meshes and influences): each
  // decodes or fails cleanly (run under sanitizers to catch over-reads).
  LevelSetData clips = MakeClipSample();
  clips.levels.resize(1);
  LevelSetData version3 = MakeVersion3Sample();
  version3.levels.erase(version3.levels.begin());
  for (const std::string& file :
       {EncodeLevelSet(MakeSample(1)).value(), EncodeLevelSet(clips).value(),
        EncodeLevelSet(version3).value(), test_v2::EncodeVersion2(clips),
        test_v1::EncodeVersion1(MakeSample(1))}) {
    AlignedBytes bytes = AlignedBytes::CopyOf(file);
    const DecodeOptions no_checksum{.verify_checksum = false};
    ASSERT_TRUE(DecodeLevelSet(bytes.bytes(), no_checksum).ok());
    for (size_t i = 0; i < bytes.size(); ++i) {
      for (const uint8_t value : {0x00, 0x01, 0x7F, 0x80, 0xFF}) {
        const std::byte saved = bytes.data()[i];
        bytes.data()[i] = std::byte{value};
        StatusOr<LevelSetView> view = DecodeLevelSet(bytes.bytes(), no_checksum);
        if (view.ok()) {
          EXPECT_TRUE(EncodeLevelSet(ToLevelSetData(*view)).ok()) << "byte " << i;
          for (uint32_t c = 0; c < view->clip_count(); ++c) {
            EXPECT_TRUE(ExtractLevelClip(*view, 0, c).ok()) << "byte " << i << " clip " << c;
            const uint32_t frames = view->clip(c).frame_count;
            for (const LevelView& level : view->levels()) {
              const FrameBlend last = level.Blend(c, frames - 1, frames);
              EXPECT_LT(last.to, level.frame_count()) << "byte " << i << " clip " << c;
            }
          }
        }
        bytes.data()[i] = saved;
      }
    }
  }
}

TEST(DecodeLevelSet, RejectsInconsistentJointMap) {
  const AlignedBytes bytes = Encode(MakeSample());
  const SampleOffsets at = OffsetsOf(bytes);
  // Level 1 keeps {0, 1, 3, 4}: head (2) removed must share spine's slot 1.
  const Status removed =
      DecodeEdited(bytes, [&](AlignedBytes& b) { Poke<uint16_t>(b, at.level1_map + 2 * 2, 0); });
  EXPECT_EQ(removed.code(), StatusCode::kDataLoss);
  EXPECT_THAT(removed.message(), HasSubstr("removed joint 2 maps to slot 0"));
  const Status kept =
      DecodeEdited(bytes, [&](AlignedBytes& b) { Poke<uint16_t>(b, at.level1_map + 2 * 3, 3); });
  EXPECT_THAT(kept.message(), HasSubstr("kept joint 3 maps to slot 3"));
  const Status out_of_range =
      DecodeEdited(bytes, [&](AlignedBytes& b) { Poke<uint16_t>(b, at.level1_map + 2 * 5, 4); });
  EXPECT_THAT(out_of_range.message(), HasSubstr("joint 5 maps to slot 4 (m = 4)"));
}

TEST(DecodeLevelSet, RejectsKeptListNotAscending) {
  const AlignedBytes bytes = Encode(MakeSample());
  const SampleOffsets at = OffsetsOf(bytes);
  const Status status = DecodeEdited(bytes, [&](AlignedBytes& b) {
    Poke<uint16_t>(b, at.level1_kept + 2 * 1, 3);  // {0, 3, 3, 4}
  });
  EXPECT_EQ(status.code(), StatusCode::kDataLoss);
  EXPECT_THAT(status.message(), HasSubstr("not strictly ascending at slot 2"));
}

TEST(DecodeLevelSet, RejectsKeptListWithoutRoot) {
  const AlignedBytes bytes = Encode(MakeSample());
  const SampleOffsets at = OffsetsOf(bytes);
  const Status status = DecodeEdited(bytes, [&](AlignedBytes& b) {
    Poke<uint16_t>(b, at.level1_kept, 2);  // {2, 1, 3, 4}
  });
  EXPECT_THAT(status.message(), HasSubstr("does not keep the root"));
}

TEST(DecodeLevelSet, RejectsParentNotTopological) {
  const AlignedBytes bytes = Encode(MakeSample());
  const SampleOffsets at = OffsetsOf(bytes);
  const Status later = DecodeEdited(bytes, [&](AlignedBytes& b) {
    Poke<int32_t>(b, at.parents + 4 * 2, 4);  // head's parent after head
  });
  EXPECT_EQ(later.code(), StatusCode::kDataLoss);
  EXPECT_THAT(later.message(), HasSubstr("joint 2 has parent 4"));
  const Status self =
      DecodeEdited(bytes, [&](AlignedBytes& b) { Poke<int32_t>(b, at.parents + 4 * 3, 3); });
  EXPECT_THAT(self.message(), HasSubstr("joint 3 has parent 3"));
  const Status negative =
      DecodeEdited(bytes, [&](AlignedBytes& b) { Poke<int32_t>(b, at.parents + 4 * 5, -7); });
  EXPECT_THAT(negative.message(), HasSubstr("topological"));
}

TEST(DecodeLevelSet, RejectsNanMatrix) {
  const AlignedBytes bytes = Encode(MakeSample());
  const SampleOffsets at = OffsetsOf(bytes);
  const size_t element = (2 * 4 + 1) * kMatrixFloats + 11;  // frame 2, slot 1, element 11
  const Status status = DecodeEdited(bytes, [&](AlignedBytes& b) {
    Poke<float>(b, at.level1_matrices + 4 * element, std::numeric_limits<float>::quiet_NaN());
  });
  EXPECT_EQ(status.code(), StatusCode::kDataLoss);
  EXPECT_THAT(status.message(), HasSubstr("level 1: K'(frame 2, slot 1) element 11"));
}

TEST(DecodeLevelSet, RejectsInvalidJointName) {
  const AlignedBytes bytes = Encode(MakeSample());
  const SampleOffsets at = OffsetsOf(bytes);
  const Status utf8 = DecodeEdited(bytes, [&](AlignedBytes& b) {
    Poke<uint8_t>(b, at.names + 2, 0xFF);  // first byte of "root"
  });
  EXPECT_THAT(utf8.message(), HasSubstr("name of joint 0 is not valid UTF-8"));
  const Status duplicate = DecodeEdited(bytes, [&](AlignedBytes& b) {
    // Length-prefixed root(4) spine(5) head(4) hip(3) knee(4) foot(4): "knee" -> "foot".
    std::memcpy(b.data() + at.names + (2 + 4) + (2 + 5) + (2 + 4) + (2 + 3) + 2, "foot", 4);
  });
  EXPECT_THAT(duplicate.message(), HasSubstr("two joints are named \"foot\""));
  const Status overlong =
      DecodeEdited(bytes, [&](AlignedBytes& b) { Poke<uint16_t>(b, at.names, 0xFFFF); });
  EXPECT_THAT(overlong.message(), HasSubstr("ends inside the name of joint 0"));
}

TEST(DecodeLevelSet, RejectsNonRigidMatrixInRigidLevelSet) {
  const AlignedBytes bytes = Encode(MakeRigidSample());
  const SampleOffsets at = OffsetsOf(bytes);
  const Status status = DecodeEdited(bytes, [&](AlignedBytes& b) {
    Poke<float>(b, at.level1_matrices, 2.0f);  // scales the first column
  });
  EXPECT_THAT(status.message(), HasSubstr("flagged rigid"));
}

TEST(DecodeLevelSet, RejectsMisalignedBufferAndDecodesAnAlignedCopy) {
  const AlignedBytes bytes = Encode(MakeSample());
  AlignedBytes shifted(bytes.size() + 4);
  std::memcpy(shifted.data() + 4, bytes.data(), bytes.size());
  const std::span<const std::byte> misaligned = shifted.bytes().subspan(4);
  const Status status = DecodeLevelSet(misaligned).status();
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(status.message(), HasSubstr("multiple of 16"));

  const AlignedBytes copy = AlignedBytes::CopyOf(misaligned);
  EXPECT_TRUE(DecodeLevelSet(copy.bytes()).ok());
}

TEST(DecodeLevelSet, RejectsFrameCountWhoseMatrixSizeWouldOverflow) {
  // The clips no longer cover the frames: checked before any level's size.
  const AlignedBytes bytes = Encode(MakeSample());
  const auto huge_frame_count = [](AlignedBytes& b) {
    Poke<uint32_t>(b, internal::kOffsetFrameCount, 0xFFFFFFFFu);
  };
  const Status status = DecodeEdited(bytes, huge_frame_count);
  EXPECT_EQ(status.code(), StatusCode::kDataLoss);
  EXPECT_THAT(status.message(), HasSubstr("the clips cover frames [0, 3) of 4294967295"));
  // A 1.0 file's one clip is every frame: 0xFFFFFFFF x 6 x 48 wraps in 32 bits; in 64 it
  // does not match the section.
  const AlignedBytes v1 = AlignedBytes::CopyOf(test_v1::EncodeVersion1(MakeSample()));
  const Status v1_status = DecodeEdited(v1, huge_frame_count);
  EXPECT_EQ(v1_status.code(), StatusCode::kDataLoss);
  EXPECT_THAT(v1_status.message(),
              HasSubstr("level 0: the matrices section is 864 bytes; expected 1236950580960"));
  EXPECT_THAT(v1_status.message(), HasSubstr("T = 4294967295"));
}

TEST(DecodeLevelSet, RejectsSectionCountWhoseDirectoryWouldOverflow) {
  const AlignedBytes bytes = Encode(MakeSample());
  const Status status = DecodeEdited(bytes, [](AlignedBytes& b) {
    Poke<uint32_t>(b, internal::kOffsetSectionCount, 0xFFFFFFFFu);
  });
  EXPECT_EQ(status.code(), StatusCode::kDataLoss);
  EXPECT_THAT(status.message(), HasSubstr("section count"));
}

TEST(DecodeLevelSet, RejectsSectionSizeWhoseEndWouldOverflow) {
  const AlignedBytes bytes = Encode(MakeSample());
  const size_t names_entry = internal::kHeaderSize + 1 * internal::kDirectoryEntrySize;
  const Status status = DecodeEdited(
      bytes, [&](AlignedBytes& b) { Poke<uint64_t>(b, names_entry + 16, 0xFFFFFFFFFFFFFFF0ull); });
  EXPECT_EQ(status.code(), StatusCode::kDataLoss);
  EXPECT_THAT(status.message(), HasSubstr("runs past the end"));
  const Status offset = DecodeEdited(
      bytes, [&](AlignedBytes& b) { Poke<uint64_t>(b, names_entry + 8, 0xFFFFFFFFFFFFFFF0ull); });
  EXPECT_THAT(offset.message(), HasSubstr("section 1 starts at"));
}

TEST(DecodeLevelSet, RejectsKeptCountBeyondJointCount) {
  const AlignedBytes bytes = Encode(MakeSample());
  const SampleOffsets at = OffsetsOf(bytes);
  const Status status = DecodeEdited(bytes, [&](AlignedBytes& b) {
    Poke<uint32_t>(b, at.level_table + internal::kLevelRecordSize * 1, 0xFFFFFFFFu);
  });
  EXPECT_THAT(status.message(), HasSubstr("level 1 keeps 4294967295 joints of 6"));
}

TEST(DecodeLevelSet, RejectsHeaderAndRecordSizesThatWouldOverflow) {
  internal::WriterOptions later;
  later.minor_version = kLevelFormatMinorVersion + 1;
  const LevelSetData sample = MakeSample();
  const AlignedBytes bytes =
      AlignedBytes::CopyOf(internal::EncodeLevelSetWithOptions(RefOf(sample), later).value());
  ASSERT_TRUE(DecodeLevelSet(bytes.bytes()).ok());
  const Status header = DecodeEdited(
      bytes, [](AlignedBytes& b) { Poke<uint32_t>(b, internal::kOffsetHeaderSize, 0xFFFFFFF0u); });
  EXPECT_THAT(header.message(), HasSubstr("runs past the end"));
  const Status record = DecodeEdited(bytes, [](AlignedBytes& b) {
    Poke<uint32_t>(b, internal::kOffsetLevelRecordSize, 0xFFFFFFFCu);
  });
  EXPECT_THAT(record.message(), HasSubstr("level table"));
  const Status joints = DecodeEdited(
      bytes, [](AlignedBytes& b) { Poke<uint32_t>(b, internal::kOffsetJointCount, 0xFFFFFFFFu); });
  EXPECT_THAT(joints.message(), HasSubstr("joint count"));
  const Status file = DecodeEdited(bytes, [](AlignedBytes& b) {
    Poke<uint64_t>(b, internal::kOffsetFileSize, 0xFFFFFFFFFFFFFFF0ull);
  });
  EXPECT_THAT(file.message(), HasSubstr("truncated"));
}

TEST(DecodeLevelSet, RejectsNonZeroPadding) {
  const AlignedBytes bytes = Encode(MakeSample());
  const SampleOffsets at = OffsetsOf(bytes);
  // Level 1's kept list is 8 bytes: 8 bytes of padding follow it.
  const Status status =
      DecodeEdited(bytes, [&](AlignedBytes& b) { Poke<uint8_t>(b, at.level1_kept + 9, 1); });
  EXPECT_THAT(status.message(), HasSubstr("non-zero padding"));
}

TEST(DecodeLevelSet, RejectsReservedFieldsAndUnknownFlagsOfTheCurrentMinorVersion) {
  const AlignedBytes bytes = Encode(MakeSample());
  const SampleOffsets at = OffsetsOf(bytes);
  const Status reserved = DecodeEdited(bytes, [&](AlignedBytes& b) {
    Poke<uint32_t>(b, at.level_table + internal::kLevelRecordSize + internal::kRecordOffsetReserved,
                   1);
  });
  EXPECT_THAT(reserved.message(), HasSubstr("level 1: reserved record fields are not zero"));
  const Status flags = DecodeEdited(
      bytes, [](AlignedBytes& b) { Poke<uint32_t>(b, internal::kOffsetFlags, 1u << 5); });
  EXPECT_THAT(flags.message(), HasSubstr("unknown flag"));
}

TEST(DecodeLevelSet, RejectsUnknownSectionsOfTheCurrentMinorVersion) {
  internal::WriterOptions options;
  options.extra_sections.push_back({99, internal::kNoLevel, "future"});
  const LevelSetData sample = MakeSample();
  const AlignedBytes bytes =
      AlignedBytes::CopyOf(internal::EncodeLevelSetWithOptions(RefOf(sample), options).value());
  const Status status = DecodeLevelSet(bytes.bytes()).status();
  EXPECT_EQ(status.code(), StatusCode::kDataLoss);
  EXPECT_THAT(status.message(), HasSubstr("section count"));
}

// ---------------------------------------------------------------------------------
// Forward compatibility.

TEST(DecodeLevelSet, AcceptsLaterMinorVersionAndSkipsWhatItDoesNotKnow) {
  internal::WriterOptions later;
  later.minor_version = kLevelFormatMinorVersion + 3;
  later.header_size = internal::kHeaderSize + 32;
  later.level_record_size = internal::kLevelRecordSize + 12;
  later.clip_record_size = internal::kClipRecordSize + 8;
  later.extension_fill = 0xA5;
  later.extra_flags = 1u << 12;
  later.extra_sections.push_back({40, internal::kNoLevel, "a global section of the future"});
  later.extra_sections.push_back({41, 1, std::string(37, '\x5A')});
  const LevelSetData data = MakeClipSample();
  const AlignedBytes bytes =
      AlignedBytes::CopyOf(internal::EncodeLevelSetWithOptions(RefOf(data), later).value());

  StatusOr<LevelSetView> view = DecodeLevelSet(bytes.bytes());
  ASSERT_TRUE(view.ok()) << view.status().ToString();
  EXPECT_EQ(view->minor_version(), kLevelFormatMinorVersion + 3);
  EXPECT_EQ(view->clip(2).name, data.clips[2].name);
  EXPECT_EQ(view->clip(1).fps, 60.0);
  EXPECT_EQ(view->flags(), 1u << 12);
  EXPECT_EQ(ToLevelSetData(*view), data);  // unknown flags dropped

  // What the server streams from it is a file of the current version.
  const AlignedBytes one = AlignedBytes::CopyOf(ExtractLevel(*view, 2).value());
  StatusOr<LevelSetView> single = DecodeLevelSet(one.bytes());
  ASSERT_TRUE(single.ok()) << single.status().ToString();
  EXPECT_EQ(single->minor_version(), kLevelFormatMinorVersion);
  EXPECT_EQ(single->flags(), 0u);
  EXPECT_EQ(ToLevelSetData(*single).levels[0], data.levels[2]);
}

// ---------------------------------------------------------------------------------
// Clips (since version 2.0).

// Where the clip table starts: directory entry 4.
size_t ClipTableOffset(const AlignedBytes& bytes) {
  uint64_t offset;
  std::memcpy(&offset, bytes.data() + internal::kHeaderSize + 4 * internal::kDirectoryEntrySize + 8,
              8);
  return static_cast<size_t>(offset);
}

template <typename T>
T Peek(const AlignedBytes& bytes, size_t offset) {
  T value;
  std::memcpy(&value, bytes.data() + offset, sizeof value);
  return value;
}

TEST(Clips, RoundTripReproducesEveryClip) {
  const LevelSetData data = MakeClipSample();
  const AlignedBytes bytes = Encode(data);
  StatusOr<LevelSetView> view = DecodeLevelSet(bytes.bytes());
  ASSERT_TRUE(view.ok()) << view.status().ToString();
  EXPECT_EQ(view->major_version(), kLevelFormatMajorVersion);
  ASSERT_EQ(view->clip_count(), 3u);
  ASSERT_EQ(view->clips().size(), 3u);
  EXPECT_EQ(view->clip(0).name, "walk");
  EXPECT_EQ(view->clip(1).name, "jump");
  EXPECT_EQ(view->clip(2).name, "idle \xC3\xA9");
  EXPECT_EQ(view->clip(1).first_frame, 3u);
  EXPECT_EQ(view->clip(1).frame_count, 2u);
  EXPECT_EQ(view->clip(1).fps, 60.0);
  EXPECT_EQ(view->clip(2).first_frame, 5u);
  EXPECT_EQ(view->clip(2).fps, 24.0);
  EXPECT_EQ(view->fps(), view->clip(0).fps);
  EXPECT_EQ(view->FindClip("jump"), 1);
  EXPECT_EQ(view->FindClip("idle \xC3\xA9"), 2);
  EXPECT_EQ(view->FindClip("run"), -1);
  EXPECT_EQ(view->FindClip(""), -1);
  // The names are views into the buffer.
  const auto* name = reinterpret_cast<const std::byte*>(view->clip(2).name.data());
  EXPECT_TRUE(name >= bytes.data() && name < bytes.data() + bytes.size());
  EXPECT_EQ(ToLevelSetData(*view), data);
}

TEST(Clips, ReencodingADecodedFileReproducesItByteForByte) {
  const AlignedBytes bytes = Encode(MakeClipSample());
  const LevelSetView view = DecodeLevelSet(bytes.bytes()).value();
  const std::string again = EncodeLevelSet(ToLevelSetData(view)).value();
  ASSERT_EQ(again.size(), bytes.size());
  EXPECT_EQ(std::memcmp(again.data(), bytes.data(), bytes.size()), 0);
  EXPECT_EQ(EncodedLevelSetSize(MakeClipSample()), bytes.size());
}

TEST(Clips, WithoutClipsTheFileHoldsOneUnnamedClipOfEveryFrame) {
  const LevelSetData data = MakeSample();
  const AlignedBytes bytes = Encode(data);
  const LevelSetView view = DecodeLevelSet(bytes.bytes()).value();
  ASSERT_EQ(view.clip_count(), 1u);
  EXPECT_EQ(view.clip(0).name, "");
  EXPECT_EQ(view.clip(0).first_frame, 0u);
  EXPECT_EQ(view.clip(0).frame_count, data.frame_count);
  EXPECT_EQ(view.clip(0).fps, data.fps);
  EXPECT_EQ(view.FindClip(""), 0);
  EXPECT_EQ(Peek<uint32_t>(bytes, internal::kOffsetClipCount), 1u);
  // ... which reads back as no clips, and is also what that one clip, spelled out, writes.
  EXPECT_TRUE(ToLevelSetData(view).clips.empty());
  LevelSetData explicit_clip = data;
  explicit_clip.clips = {{"", 0, data.frame_count, data.fps}};
  const std::string spelled_out = EncodeLevelSet(explicit_clip).value();
  ASSERT_EQ(spelled_out.size(), bytes.size());
  EXPECT_EQ(std::memcmp(spelled_out.data(), bytes.data(), bytes.size()), 0);
}

TEST(Clips, OneNamedClipRoundTrips) {
  LevelSetData data = MakeSample();
  data.clips = {{"walk", 0, data.frame_count, data.fps}};
  const AlignedBytes bytes = Encode(data);
  const LevelSetView view = DecodeLevelSet(bytes.bytes()).value();
  EXPECT_EQ(view.clip(0).name, "walk");
  EXPECT_EQ(ToLevelSetData(view), data);
}

TEST(Clips, OneClipPerFrameIsAllowed) {
  LevelSetData data = MakeSample(4);
  for (uint32_t t = 0; t < 4; ++t) {
    data.clips.push_back({"pose " + std::to_string(t), t, 1, t == 0 ? data.fps : 10.0 + t});
  }
  const AlignedBytes bytes = Encode(data);
  EXPECT_EQ(ToLevelSetData(DecodeLevelSet(bytes.bytes()).value()), data);
}

// The clip table as docs/level-format.md lays it out, byte by byte.
TEST(Clips, TableLayoutIsAsDocumented) {
  const AlignedBytes bytes = Encode(MakeClipSample());
  EXPECT_EQ(Peek<uint16_t>(bytes, internal::kOffsetMajorVersion), 3);
  EXPECT_EQ(Peek<uint16_t>(bytes, internal::kOffsetMinorVersion), 0);
  EXPECT_EQ(Peek<uint32_t>(bytes, 100), 3u);   // clip_count
  EXPECT_EQ(Peek<uint32_t>(bytes, 104), 16u);  // clip_record_size
  EXPECT_EQ(Peek<uint32_t>(bytes, 108), 0u);   // vertex_count: no level has a mesh
  EXPECT_EQ(Peek<uint32_t>(bytes, internal::kOffsetSectionCount), 5u + 7u * 3u);
  EXPECT_EQ(Peek<double>(bytes, internal::kOffsetFps), 29.97);
  const size_t entry = internal::kHeaderSize + 4 * internal::kDirectoryEntrySize;
  EXPECT_EQ(Peek<uint32_t>(bytes, entry), 5u);  // kind: clip table
  EXPECT_EQ(Peek<uint32_t>(bytes, entry + 4), 0xFFFFFFFFu);
  const size_t names_bytes = (2 + 4) + (2 + 4) + (2 + 7);
  EXPECT_EQ(Peek<uint64_t>(bytes, entry + 16), 3 * 16 + names_bytes);
  EXPECT_EQ(Peek<uint32_t>(bytes, entry + 24), 16u);  // entry 5: level 0's kept joints
  EXPECT_EQ(Peek<uint32_t>(bytes, entry + 28), 0u);
  const size_t table = ClipTableOffset(bytes);
  EXPECT_EQ(table % 16, 0u);
  const uint32_t expected[3][2] = {{0, 3}, {3, 2}, {5, 1}};
  const double fps[3] = {29.97, 60.0, 24.0};
  for (size_t c = 0; c < 3; ++c) {
    EXPECT_EQ(Peek<uint32_t>(bytes, table + 16 * c), expected[c][0]) << c;
    EXPECT_EQ(Peek<uint32_t>(bytes, table + 16 * c + 4), expected[c][1]) << c;
    EXPECT_EQ(Peek<double>(bytes, table + 16 * c + 8), fps[c]) << c;
  }
  const std::string names(reinterpret_cast<const char*>(bytes.data() + table + 48), names_bytes);
  EXPECT_EQ(names, std::string("\x04\x00walk\x04\x00jump\x07\x00idle \xC3\xA9", names_bytes));
}

TEST(Clips, ExtractLevelKeepsEveryClip) {
  const LevelSetData data = MakeClipSample();
  const AlignedBytes bytes = Encode(data);
  const LevelSetView view = DecodeLevelSet(bytes.bytes()).value();
  const AlignedBytes one = AlignedBytes::CopyOf(ExtractLevel(view, 1).value());
  LevelSetData expected = data;
  expected.levels = {data.levels[1]};
  EXPECT_EQ(ToLevelSetData(DecodeLevelSet(one.bytes()).value()), expected);
}

TEST(ExtractLevelClip, HoldsTheMatricesOfTheClipsFramesOnly) {
  const LevelSetData data = MakeClipSample();
  const AlignedBytes bytes = Encode(data);
  const LevelSetView view = DecodeLevelSet(bytes.bytes()).value();
  for (uint32_t l = 0; l < view.level_count(); ++l) {
    for (uint32_t c = 0; c < view.clip_count(); ++c) {
      StatusOr<std::string> extracted = ExtractLevelClip(view, l, c);
      ASSERT_TRUE(extracted.ok()) << extracted.status().ToString();
      const AlignedBytes file = AlignedBytes::CopyOf(*extracted);
      StatusOr<LevelSetView> single = DecodeLevelSet(file.bytes());
      ASSERT_TRUE(single.ok()) << single.status().ToString();
      const ClipInfo& clip = data.clips[c];
      ASSERT_EQ(single->level_count(), 1u);
      ASSERT_EQ(single->clip_count(), 1u);
      EXPECT_EQ(single->clip(0).name, clip.name);
      EXPECT_EQ(single->clip(0).first_frame, 0u);
      EXPECT_EQ(single->clip(0).frame_count, clip.frame_count);
      EXPECT_EQ(single->clip(0).fps, clip.fps);
      EXPECT_EQ(single->frame_count(), clip.frame_count);
      EXPECT_EQ(single->fps(), clip.fps);
      EXPECT_EQ(single->variant_name(), data.variant_name);
      EXPECT_EQ(single->source_hash(), data.source_hash);
      const LevelView& level = single->level(0);
      EXPECT_EQ(level.figures(), data.levels[l].figures);
      EXPECT_TRUE(std::equal(level.kept_joints().begin(), level.kept_joints().end(),
                             data.levels[l].kept_joints.begin(), data.levels[l].kept_joints.end()));
      // Frame t of the file is frame first_frame + t of the level set.
      for (uint32_t t = 0; t < clip.frame_count; ++t) {
        for (uint32_t s = 0; s < level.kept_count(); ++s) {
          for (size_t k = 0; k < kMatrixFloats; ++k) {
            ASSERT_EQ(level.matrix(t, s)[k], SampleValue(l, clip.first_frame + t, s, k))
                << "level " << l << " clip " << c << " frame " << t;
          }
        }
      }
      // A one-clip file's clip is the file.
      const std::string again = ExtractLevelClip(*single, 0, 0).value();
      ASSERT_EQ(again.size(), file.size());
      EXPECT_EQ(std::memcmp(again.data(), file.data(), file.size()), 0);
    }
  }
}

TEST(ExtractLevelClip, OfTheSingleUnnamedClipIsExtractLevel) {
  const AlignedBytes bytes = Encode(MakeSample());
  const LevelSetView view = DecodeLevelSet(bytes.bytes()).value();
  EXPECT_EQ(ExtractLevelClip(view, 2, 0).value(), ExtractLevel(view, 2).value());
}

TEST(ExtractLevelClip, RejectsLevelOrClipOutOfRange) {
  const AlignedBytes bytes = Encode(MakeClipSample());
  const LevelSetView view = DecodeLevelSet(bytes.bytes()).value();
  const Status level = ExtractLevelClip(view, 3, 0).status();
  EXPECT_EQ(level.code(), StatusCode::kNotFound);
  EXPECT_THAT(level.message(), HasSubstr("level 3"));
  const Status clip = ExtractLevelClip(view, 0, 3).status();
  EXPECT_EQ(clip.code(), StatusCode::kNotFound);
  EXPECT_THAT(clip.message(), HasSubstr("clip 3"));
}

TEST(ValidateLevelSet, AcceptsTheClipSample) {
  EXPECT_TRUE(ValidateLevelSet(MakeClipSample()).ok());
}

TEST(ValidateLevelSet, RejectsEachInvalidClip) {
  const InvalidCase cases[] = {
      {"more clips than frames",
       [](LevelSetData& d) {
         d.clips.clear();
         for (uint32_t c = 0; c < 7; ++c) d.clips.push_back({std::to_string(c), c, 1, d.fps});
       },
       "7 clips for 6 frames"},
      {"gap", [](LevelSetData& d) { d.clips[1].first_frame = 4; },
       "clip 1 (\"jump\") starts at frame 4; clips must be contiguous and in frame order "
       "(expected frame 3)"},
      {"overlap", [](LevelSetData& d) { d.clips[1].first_frame = 2; },
       "clip 1 (\"jump\") starts at frame 2"},
      {"out of frame order", [](LevelSetData& d) { std::swap(d.clips[0], d.clips[1]); },
       "clip 0 (\"jump\") starts at frame 3"},
      {"no frame", [](LevelSetData& d) { d.clips[2].frame_count = 0; },
       "clip 2 (\"idle \xC3\xA9\") has no frame"},
      {"past the end", [](LevelSetData& d) { d.clips[2].frame_count = 2; },
       "clip 2 (\"idle \xC3\xA9\") ends at frame 7, past the 6 frames"},
      {"frame count that would wrap", [](LevelSetData& d) { d.clips[1].frame_count = 0xFFFFFFFFu; },
       "clip 1 (\"jump\") ends at frame 4294967298"},
      {"frames left uncovered", [](LevelSetData& d) { d.clips.pop_back(); },
       "the clips cover frames [0, 5) of 6"},
      {"fps zero", [](LevelSetData& d) { d.clips[1].fps = 0; }, "clip 1 (\"jump\"): fps is 0"},
      {"fps negative", [](LevelSetData& d) { d.clips[2].fps = -24; }, "clip 2"},
      {"fps NaN", [](LevelSetData& d) { d.clips[1].fps = std::nan(""); }, "clip 1 (\"jump\"): fps"},
      {"fps infinite",
       [](LevelSetData& d) { d.clips[1].fps = std::numeric_limits<double>::infinity(); },
       "clip 1 (\"jump\"): fps is inf"},
      {"level set fps not the first clip's", [](LevelSetData& d) { d.fps = 30; },
       "a level set's fps is its first clip's"},
      {"name not UTF-8", [](LevelSetData& d) { d.clips[1].name = "ju\xFFmp"; },
       "the name of clip 1 is not valid UTF-8"},
      {"name with NUL", [](LevelSetData& d) { d.clips[2].name = std::string("a\0b", 3); },
       "the name of clip 2 contains a NUL byte"},
      {"long name", [](LevelSetData& d) { d.clips[0].name = std::string(70000, 'a'); },
       "the name of clip 0 is 70000 bytes long"},
      {"unnamed among several", [](LevelSetData& d) { d.clips[1].name.clear(); },
       "the name of clip 1 is empty (only a level set's single clip may be unnamed)"},
      {"duplicate name", [](LevelSetData& d) { d.clips[2].name = "walk"; },
       "two clips are named \"walk\""},
  };
  for (const InvalidCase& c : cases) {
    LevelSetData data = MakeClipSample();
    c.edit(data);
    const Status status = ValidateLevelSet(data);
    EXPECT_EQ(status.code(), StatusCode::kInvalidArgument) << c.name;
    EXPECT_THAT(status.message(), HasSubstr(c.message)) << c.name;
    EXPECT_EQ(EncodeLevelSet(data).status().message(), status.message()) << c.name;
    EXPECT_EQ(EncodeLevelSet(RefOf(data)).status().message(), status.message()) << c.name;
  }
}

TEST(ValidateLevelSet, ChecksOneClipLikeSeveral) {
  LevelSetData data = MakeSample();
  data.clips = {{"", 0, data.frame_count - 1, data.fps}};
  EXPECT_THAT(ValidateLevelSet(data).message(), HasSubstr("the clips cover frames [0, 2) of 3"));
  data.clips = {{"", 0, data.frame_count, 25.0}};
  EXPECT_THAT(ValidateLevelSet(data).message(), HasSubstr("first clip's"));
}

TEST(DecodeLevelSet, RejectsInvalidClipTables) {
  const AlignedBytes bytes = Encode(MakeClipSample());
  const size_t table = ClipTableOffset(bytes);
  const size_t names = table + 3 * 16;
  struct Case {
    const char* name;
    std::function<void(AlignedBytes&)> edit;
    const char* message;
  };
  const Case cases[] = {
      {"gap", [&](AlignedBytes& b) { Poke<uint32_t>(b, table + 16 + 0, 4); },
       "clip 1 (\"jump\") starts at frame 4"},
      {"no frame", [&](AlignedBytes& b) { Poke<uint32_t>(b, table + 32 + 4, 0); }, "has no frame"},
      {"past the end", [&](AlignedBytes& b) { Poke<uint32_t>(b, table + 32 + 4, 2); },
       "ends at frame 7"},
      {"fps NaN",
       [&](AlignedBytes& b) {
         Poke<double>(b, table + 16 + 8, std::numeric_limits<double>::quiet_NaN());
       },
       "clip 1 (\"jump\"): fps"},
      {"header fps not the first clip's",
       [&](AlignedBytes& b) { Poke<double>(b, table + 8, 30.0); },
       "a level set's fps is its first clip's"},
      {"name not UTF-8", [&](AlignedBytes& b) { Poke<uint8_t>(b, names + 2, 0xFF); },
       "the name of clip 0 is not valid UTF-8"},
      {"name with NUL", [&](AlignedBytes& b) { Poke<uint8_t>(b, names + 6 + 2 + 1, 0); },
       "the name of clip 1 contains a NUL byte"},
      {"duplicate name", [&](AlignedBytes& b) { std::memcpy(b.data() + names + 6 + 2, "walk", 4); },
       "two clips are named \"walk\""},
      {"name past the table", [&](AlignedBytes& b) { Poke<uint16_t>(b, names + 12, 0xFFFF); },
       "the clip table ends inside the name of clip 2"},
      {"no clip", [](AlignedBytes& b) { Poke<uint32_t>(b, internal::kOffsetClipCount, 0); },
       "clip count 0 is out of [1, 6]"},
      {"more clips than frames",
       [](AlignedBytes& b) { Poke<uint32_t>(b, internal::kOffsetClipCount, 7); },
       "clip count 7 is out of [1, 6]"},
      {"huge clip count",
       [](AlignedBytes& b) { Poke<uint32_t>(b, internal::kOffsetClipCount, 0xFFFFFFFFu); },
       "clip count 4294967295"},
      {"clip record size of a later minor version",
       [](AlignedBytes& b) { Poke<uint32_t>(b, internal::kOffsetClipRecordSize, 24); },
       "clip record size 24 is invalid for version 3.0"},
      {"clip record size that would wrap",
       [](AlignedBytes& b) {
         Poke<uint16_t>(b, internal::kOffsetMinorVersion, 1);
         Poke<uint32_t>(b, internal::kOffsetClipRecordSize, 0xFFFFFFF8u);
       },
       "the clip table is"},
      {"clip table kind",
       [](AlignedBytes& b) {
         Poke<uint32_t>(b, internal::kHeaderSize + 4 * internal::kDirectoryEntrySize, 6);
       },
       "section 4 is of kind 6"},
  };
  for (const Case& c : cases) {
    const Status status = DecodeEdited(bytes, c.edit);
    EXPECT_EQ(status.code(), StatusCode::kDataLoss) << c.name;
    EXPECT_THAT(status.message(), HasSubstr(c.message)) << c.name;
  }
  // Fewer clips than the table holds: the names do not fill it.
  const Status fewer = DecodeEdited(
      bytes, [](AlignedBytes& b) { Poke<uint32_t>(b, internal::kOffsetClipCount, 2); });
  EXPECT_EQ(fewer.code(), StatusCode::kDataLoss);
}

// ---------------------------------------------------------------------------------
// Version 1.0 files (no clip table) still read, as one unnamed clip of every frame.

TEST(Version1, DecodesAsOneUnnamedClipOfEveryFrame) {
  const LevelSetData data = MakeSample();
  const AlignedBytes bytes = AlignedBytes::CopyOf(test_v1::EncodeVersion1(data));
  StatusOr<LevelSetView> view = DecodeLevelSet(bytes.bytes());
  ASSERT_TRUE(view.ok()) << view.status().ToString();
  EXPECT_EQ(view->major_version(), 1);
  EXPECT_EQ(view->minor_version(), 0);
  ASSERT_EQ(view->clip_count(), 1u);
  EXPECT_EQ(view->clip(0).name, "");
  EXPECT_EQ(view->clip(0).first_frame, 0u);
  EXPECT_EQ(view->clip(0).frame_count, 3u);
  EXPECT_EQ(view->clip(0).fps, 29.97);
  EXPECT_EQ(view->FindClip(""), 0);
  EXPECT_EQ(ToLevelSetData(*view), data);
  for (uint32_t t = 0; t < 3; ++t) {
    EXPECT_EQ(view->level(1).matrix(t, 3)[11], SampleValue(1, t, 3, 11));
  }
}

TEST(Version1, ReencodesAsTheCurrentVersionFileOfTheSameContent) {
  for (const LevelSetData& data : {MakeSample(), MakeRigidSample()}) {
    const AlignedBytes v1 = AlignedBytes::CopyOf(test_v1::EncodeVersion1(data));
    const LevelSetView view = DecodeLevelSet(v1.bytes()).value();
    const std::string again = EncodeLevelSet(ToLevelSetData(view)).value();
    const std::string current = EncodeLevelSet(data).value();
    ASSERT_EQ(again.size(), current.size());
    EXPECT_EQ(std::memcmp(again.data(), current.data(), current.size()), 0);
    // What the server streams from a 1.0 file is a file of the current version.
    const AlignedBytes one = AlignedBytes::CopyOf(ExtractLevel(view, 1).value());
    const LevelSetView single = DecodeLevelSet(one.bytes()).value();
    EXPECT_EQ(single.major_version(), kLevelFormatMajorVersion);
    EXPECT_EQ(ToLevelSetData(single).levels[0], data.levels[1]);
    EXPECT_EQ(ExtractLevelClip(view, 1, 0).value(), ExtractLevel(view, 1).value());
  }
}

TEST(Version1, KeepsItsOwnRules) {
  const LevelSetData data = MakeSample();
  // 1.0: offset 100 is reserved, and there are 4 + 3L sections.
  test_v1::Version1Options reserved;
  reserved.reserved = 3;
  Status status =
      DecodeLevelSet(AlignedBytes::CopyOf(test_v1::EncodeVersion1(data, reserved)).bytes())
          .status();
  EXPECT_EQ(status.code(), StatusCode::kDataLoss);
  EXPECT_THAT(status.message(), HasSubstr("reserved"));
  test_v1::Version1Options extra;
  extra.trailing_section = "a section 1.0 does not have";
  status =
      DecodeLevelSet(AlignedBytes::CopyOf(test_v1::EncodeVersion1(data, extra)).bytes()).status();
  EXPECT_THAT(status.message(), HasSubstr("section count 14 for 3 levels (expected 13)"));
  // A later 1.x minor version may fill them; this build skips what it does not know.
  test_v1::Version1Options later = extra;
  later.minor_version = 2;
  later.reserved = 3;
  const AlignedBytes later_bytes = AlignedBytes::CopyOf(test_v1::EncodeVersion1(data, later));
  StatusOr<LevelSetView> view = DecodeLevelSet(later_bytes.bytes());
  ASSERT_TRUE(view.ok()) << view.status().ToString();
  EXPECT_EQ(view->minor_version(), 2);
  EXPECT_EQ(ToLevelSetData(*view), data);
  // A 1.0 file's truncations are data loss too.
  const AlignedBytes v1 = AlignedBytes::CopyOf(test_v1::EncodeVersion1(MakeSample(1)));
  for (size_t size = 0; size < v1.size(); ++size) {
    ASSERT_EQ(DecodeLevelSet(v1.bytes().first(size)).status().code(), StatusCode::kDataLoss)
        << size;
  }
}

// ---------------------------------------------------------------------------------
// Version 2.0 files (levels of every frame, without mesh, influences or cost) still read.

TEST(Version2, DecodesWithEveryFrameStoredAndNothingOfVersion3) {
  const LevelSetData data = MakeClipSample();
  const AlignedBytes bytes = AlignedBytes::CopyOf(test_v2::EncodeVersion2(data));
  StatusOr<LevelSetView> view = DecodeLevelSet(bytes.bytes());
  ASSERT_TRUE(view.ok()) << view.status().ToString();
  EXPECT_EQ(view->major_version(), 2);
  EXPECT_EQ(view->minor_version(), 0);
  EXPECT_EQ(view->vertex_count(), 0u);
  ASSERT_EQ(view->clip_count(), 3u);
  EXPECT_EQ(view->clip(1).name, "jump");
  for (const LevelView& level : view->levels()) {
    EXPECT_EQ(level.frame_stride(), 1u);
    EXPECT_EQ(level.frame_count(), 6u);
    EXPECT_FALSE(level.has_own_mesh());
    EXPECT_TRUE(level.triangles().empty());
    EXPECT_EQ(level.influences_per_vertex(), 0u);
    EXPECT_TRUE(level.influence_slots().empty());
    EXPECT_TRUE(level.influence_weights().empty());
    EXPECT_EQ(level.cost(), 0.0f);
    EXPECT_EQ(level.clip_first_stored(2), 5u);
    const FrameBlend blend = level.Blend(1, 1, 2);
    EXPECT_EQ(blend.from, 4u);
    EXPECT_EQ(blend.to, 4u);
    EXPECT_EQ(blend.fraction, 0.0f);
  }
  EXPECT_EQ(view->level(1).matrix(4, 3)[11], SampleValue(1, 4, 3, 11));
  EXPECT_EQ(ToLevelSetData(*view), data);
}

TEST(Version2, ReencodesAsTheCurrentVersionFileOfTheSameContent) {
  for (const LevelSetData& data : {MakeClipSample(), MakeSample(), MakeRigidSample()}) {
    const AlignedBytes v2 = AlignedBytes::CopyOf(test_v2::EncodeVersion2(data));
    const LevelSetView view = DecodeLevelSet(v2.bytes()).value();
    const std::string again = EncodeLevelSet(ToLevelSetData(view)).value();
    const std::string current = EncodeLevelSet(data).value();
    ASSERT_EQ(again.size(), current.size());
    EXPECT_EQ(std::memcmp(again.data(), current.data(), current.size()), 0);
    const AlignedBytes one = AlignedBytes::CopyOf(ExtractLevelClip(view, 1, 0).value());
    const LevelSetView single = DecodeLevelSet(one.bytes()).value();
    EXPECT_EQ(single.major_version(), kLevelFormatMajorVersion);
    EXPECT_EQ(single.level(0).frame_count(), view.clip(0).frame_count);
  }
}

TEST(Version2, KeepsItsOwnRules) {
  const LevelSetData data = MakeClipSample();
  // 2.0: offset 108 is reserved, there are 5 + 3L sections and records of 32 bytes.
  test_v2::Version2Options reserved;
  reserved.reserved = 3;
  Status status =
      DecodeLevelSet(AlignedBytes::CopyOf(test_v2::EncodeVersion2(data, reserved)).bytes())
          .status();
  EXPECT_EQ(status.code(), StatusCode::kDataLoss);
  EXPECT_THAT(status.message(), HasSubstr("reserved header fields"));
  test_v2::Version2Options extra;
  extra.trailing_section = "a section 2.0 does not have";
  status =
      DecodeLevelSet(AlignedBytes::CopyOf(test_v2::EncodeVersion2(data, extra)).bytes()).status();
  EXPECT_THAT(status.message(), HasSubstr("section count 15 for 3 levels (expected 14)"));
  const AlignedBytes bytes = AlignedBytes::CopyOf(test_v2::EncodeVersion2(data));
  status = DecodeEdited(bytes, [](AlignedBytes& b) {
    Poke<uint32_t>(b, internal::kOffsetLevelRecordSize, internal::kLevelRecordSize);
  });
  EXPECT_THAT(status.message(), HasSubstr("level record size 48 is invalid for version 2.0"));
  // A later 2.x minor version may fill them; this build skips what it does not know.
  test_v2::Version2Options later = extra;
  later.minor_version = 1;
  later.reserved = 3;
  const AlignedBytes later_bytes = AlignedBytes::CopyOf(test_v2::EncodeVersion2(data, later));
  StatusOr<LevelSetView> view = DecodeLevelSet(later_bytes.bytes());
  ASSERT_TRUE(view.ok()) << view.status().ToString();
  EXPECT_EQ(view->minor_version(), 1);
  EXPECT_EQ(view->vertex_count(), 0u);  // offset 108 is not 2.x's vertex count
  EXPECT_EQ(ToLevelSetData(*view), data);
  for (size_t size = 0; size < bytes.size(); ++size) {
    ASSERT_EQ(DecodeLevelSet(bytes.bytes().first(size)).status().code(), StatusCode::kDataLoss)
        << size;
  }
}

// ---------------------------------------------------------------------------------
// Version 3.0: pose rate, the levels' own meshes and influences, cost.

TEST(Version3, RoundTripReproducesStridesMeshesInfluencesAndCosts) {
  const LevelSetData data = MakeVersion3Sample();
  ASSERT_TRUE(ValidateLevelSet(data).ok()) << ValidateLevelSet(data).ToString();
  const AlignedBytes bytes = Encode(data);
  StatusOr<LevelSetView> view = DecodeLevelSet(bytes.bytes());
  ASSERT_TRUE(view.ok()) << view.status().ToString();
  EXPECT_EQ(view->major_version(), 3);
  EXPECT_EQ(view->frame_count(), 18u);
  EXPECT_EQ(view->vertex_count(), 10u);
  // T' = 12 + 5 + 1 at stride 1; 7 + 3 + 1 at 2; 5 + 3 + 1 at 3.
  const uint32_t stored[3] = {18, 11, 9};
  const uint32_t second_clip[3] = {12, 7, 5};
  for (uint32_t l = 0; l < 3; ++l) {
    const LevelView& level = view->level(l);
    EXPECT_EQ(level.frame_stride(), l + 1);
    EXPECT_EQ(level.frame_count(), stored[l]);
    EXPECT_EQ(level.matrices().size(), stored[l] * level.kept_count() * kMatrixFloats);
    EXPECT_EQ(level.clip_first_stored(0), 0u);
    EXPECT_EQ(level.clip_first_stored(1), second_clip[l]);
    EXPECT_EQ(level.clip_first_stored(2), stored[l] - 1);
    EXPECT_EQ(level.cost(), data.levels[l].cost);
  }
  const LevelView& meshed = view->level(1);
  EXPECT_TRUE(meshed.has_own_mesh());
  EXPECT_THAT(meshed.vertices(), ::testing::ElementsAre(1, 2, 4, 7, 9));
  EXPECT_THAT(meshed.triangles(), ::testing::ElementsAre(0, 1, 2, 2, 3, 4));
  EXPECT_EQ(meshed.influences_per_vertex(), 2u);
  EXPECT_THAT(meshed.influence_slots(),
              ::testing::ElementsAreArray(data.levels[1].influence_slots));
  ExpectBitwiseEqual(meshed.influence_weights(), data.levels[1].influence_weights);
  // Stored frame 1 of clip "walk" at stride 2 is its frame 2.
  EXPECT_EQ(meshed.matrix(1, 3)[5], SampleValue(1, 2, 3, 5));
  const LevelView& coarse = view->level(2);
  EXPECT_FALSE(coarse.has_own_mesh());
  EXPECT_EQ(coarse.influence_slots().size(), 10u);
  EXPECT_FALSE(view->level(0).has_own_mesh());
  EXPECT_EQ(view->level(0).influences_per_vertex(), 0u);
  EXPECT_EQ(ToLevelSetData(*view), data);
}

TEST(Version3, ReencodingADecodedFileReproducesItByteForByte) {
  const LevelSetData data = MakeVersion3Sample();
  const AlignedBytes bytes = Encode(data);
  const LevelSetView view = DecodeLevelSet(bytes.bytes()).value();
  const std::string again = EncodeLevelSet(ToLevelSetData(view)).value();
  ASSERT_EQ(again.size(), bytes.size());
  EXPECT_EQ(std::memcmp(again.data(), bytes.data(), bytes.size()), 0);
  EXPECT_EQ(EncodedLevelSetSize(data), bytes.size());
  const std::string from_views = EncodeLevelSet(RefOf(data)).value();
  EXPECT_EQ(std::memcmp(from_views.data(), bytes.data(), bytes.size()), 0);
  AlignedBytes out(bytes.size());
  ASSERT_EQ(EncodeLevelSetInto(data, out.mutable_bytes()).value(), bytes.size());
  EXPECT_EQ(std::memcmp(out.data(), bytes.data(), bytes.size()), 0);
}

// The header, level records and per-level sections as docs/level-format.md lays them out.
TEST(Version3, LayoutIsAsDocumented) {
  const LevelSetData data = MakeVersion3Sample();
  const AlignedBytes bytes = Encode(data);
  EXPECT_EQ(Peek<uint16_t>(bytes, 8), 3);
  EXPECT_EQ(Peek<uint16_t>(bytes, 10), 0);
  EXPECT_EQ(Peek<uint32_t>(bytes, 96), 48u);   // level_record_size
  EXPECT_EQ(Peek<uint32_t>(bytes, 108), 10u);  // vertex_count
  EXPECT_EQ(Peek<uint32_t>(bytes, 44), 5u + 7u * 3u);
  const size_t table = OffsetsOf(bytes).level_table;
  const size_t record = table + 48;                    // level 1
  EXPECT_EQ(Peek<uint32_t>(bytes, record + 0), 4u);    // kept_count
  EXPECT_EQ(Peek<float>(bytes, record + 4), 0.5f);     // max_vertex_error_pct
  EXPECT_EQ(Peek<uint32_t>(bytes, record + 24), 2u);   // frame_stride
  EXPECT_EQ(Peek<uint32_t>(bytes, record + 28), 2u);   // influences_per_vertex
  EXPECT_EQ(Peek<uint32_t>(bytes, record + 32), 5u);   // vertex_count
  EXPECT_EQ(Peek<uint32_t>(bytes, record + 36), 2u);   // triangle_count
  EXPECT_EQ(Peek<float>(bytes, record + 40), 0.375f);  // cost
  EXPECT_EQ(Peek<uint32_t>(bytes, record + 44), 0u);   // reserved
  // Directory entries 5 + 7l .. 11 + 7l: kinds 16 to 22 of level l, sized as documented;
  // the empty ones are there too, packed like the others.
  const uint64_t sizes[3][7] = {{2 * 6, 2 * 6, 48 * 18 * 6, 0, 0, 0, 0},
                                {2 * 4, 2 * 6, 48 * 11 * 4, 4 * 5, 4 * 6, 2 * 10, 4 * 10},
                                {2 * 1, 2 * 6, 48 * 9 * 1, 0, 0, 2 * 10, 4 * 10}};
  for (uint32_t l = 0; l < 3; ++l) {
    for (uint32_t i = 0; i < 7; ++i) {
      const size_t entry = internal::kHeaderSize + (5 + 7 * l + i) * internal::kDirectoryEntrySize;
      const size_t previous = entry - internal::kDirectoryEntrySize;
      EXPECT_EQ(Peek<uint32_t>(bytes, entry), 16 + i) << l << " " << i;
      EXPECT_EQ(Peek<uint32_t>(bytes, entry + 4), l) << l << " " << i;
      EXPECT_EQ(Peek<uint64_t>(bytes, entry + 16), sizes[l][i]) << l << " " << i;
      const uint64_t end =
          Peek<uint64_t>(bytes, previous + 8) + Peek<uint64_t>(bytes, previous + 16);
      EXPECT_EQ(Peek<uint64_t>(bytes, entry + 8), (end + 15) / 16 * 16) << l << " " << i;
    }
  }
}

// A clip of 12 frames at stride 3 stores frames 0, 3, 6, 9 and 11.
TEST(Version3, BlendLocatesEachFrameBetweenTwoStoredOnes) {
  const AlignedBytes bytes = Encode(MakeVersion3Sample());
  const LevelSetView view = DecodeLevelSet(bytes.bytes()).value();
  const LevelView& level = view.level(2);
  struct Expected {
    uint32_t from, to;
    float fraction;
  };
  const Expected walk[12] = {{0, 0, 0},        {0, 1, 1 / 3.0f}, {0, 1, 2 / 3.0f}, {1, 1, 0},
                             {1, 2, 1 / 3.0f}, {1, 2, 2 / 3.0f}, {2, 2, 0},        {2, 3, 1 / 3.0f},
                             {2, 3, 2 / 3.0f}, {3, 3, 0},        {3, 4, 0.5f},     {4, 4, 0}};
  for (uint32_t t = 0; t < 12; ++t) {
    const FrameBlend blend = level.Blend(0, t, 12);
    EXPECT_EQ(blend.from, walk[t].from) << t;
    EXPECT_EQ(blend.to, walk[t].to) << t;
    EXPECT_FLOAT_EQ(blend.fraction, walk[t].fraction) << t;
  }
  // "jump", 5 frames from stored frame 5: frames 0, 3 and 4.
  const Expected jump[5] = {{5, 5, 0}, {5, 6, 1 / 3.0f}, {5, 6, 2 / 3.0f}, {6, 6, 0}, {7, 7, 0}};
  for (uint32_t t = 0; t < 5; ++t) {
    const FrameBlend blend = level.Blend(1, t, 5);
    EXPECT_EQ(blend.from, jump[t].from) << t;
    EXPECT_EQ(blend.to, jump[t].to) << t;
    EXPECT_FLOAT_EQ(blend.fraction, jump[t].fraction) << t;
  }
  const FrameBlend idle = level.Blend(2, 0, 1);
  EXPECT_EQ(idle.from, 8u);
  EXPECT_EQ(idle.to, 8u);
  EXPECT_EQ(idle.fraction, 0.0f);
  // At stride 1 every frame is stored.
  for (uint32_t t = 0; t < 5; ++t) {
    const FrameBlend blend = view.level(0).Blend(1, t, 5);
    EXPECT_EQ(blend.from, 12 + t);
    EXPECT_EQ(blend.to, 12 + t);
    EXPECT_EQ(blend.fraction, 0.0f);
  }
  // The sample's values are linear in the frame: a blend of the stored frames gives back
  // every frame of every clip at every stride.
  for (uint32_t l = 0; l < view.level_count(); ++l) {
    const LevelView& each = view.level(l);
    for (uint32_t c = 0; c < view.clip_count(); ++c) {
      const ClipView& clip = view.clip(c);
      for (uint32_t t = 0; t < clip.frame_count; ++t) {
        const FrameBlend blend = each.Blend(c, t, clip.frame_count);
        for (uint32_t s = 0; s < each.kept_count(); ++s) {
          for (size_t k = 0; k < kMatrixFloats; ++k) {
            const float value = (1 - blend.fraction) * each.matrix(blend.from, s)[k] +
                                blend.fraction * each.matrix(blend.to, s)[k];
            const float expected = SampleValue(l, clip.first_frame + t, s, k);
            ASSERT_NEAR(value, expected, 1e-5f * std::abs(expected))
                << "level " << l << " clip " << c << " frame " << t;
          }
        }
      }
    }
  }
}

TEST(Version3, ExtractLevelKeepsTheLevelsStrideMeshInfluencesAndCost) {
  const LevelSetData data = MakeVersion3Sample();
  const AlignedBytes bytes = Encode(data);
  const LevelSetView view = DecodeLevelSet(bytes.bytes()).value();
  for (uint32_t l = 0; l < view.level_count(); ++l) {
    const AlignedBytes one = AlignedBytes::CopyOf(ExtractLevel(view, l).value());
    StatusOr<LevelSetView> single = DecodeLevelSet(one.bytes());
    ASSERT_TRUE(single.ok()) << single.status().ToString();
    LevelSetData expected = data;
    expected.levels = {data.levels[l]};  // level 0 has no mesh: the vertex count stays
    EXPECT_EQ(ToLevelSetData(*single), expected) << "level " << l;
  }
}

TEST(Version3, ExtractLevelClipHoldsTheClipsStoredFramesOnly) {
  const LevelSetData data = MakeVersion3Sample();
  const AlignedBytes bytes = Encode(data);
  const LevelSetView view = DecodeLevelSet(bytes.bytes()).value();
  for (uint32_t l = 0; l < view.level_count(); ++l) {
    const LevelData& source = data.levels[l];
    for (uint32_t c = 0; c < view.clip_count(); ++c) {
      StatusOr<std::string> extracted = ExtractLevelClip(view, l, c);
      ASSERT_TRUE(extracted.ok()) << extracted.status().ToString();
      const AlignedBytes file = AlignedBytes::CopyOf(*extracted);
      StatusOr<LevelSetView> single = DecodeLevelSet(file.bytes());
      ASSERT_TRUE(single.ok()) << single.status().ToString();
      const ClipInfo& clip = data.clips[c];
      EXPECT_EQ(single->frame_count(), clip.frame_count);
      EXPECT_EQ(single->vertex_count(), data.vertex_count);
      ASSERT_EQ(single->clip_count(), 1u);
      EXPECT_EQ(single->clip(0).first_frame, 0u);
      LevelData expected = source;
      expected.matrices =
          StoredSampleMatrices(l, source.kept_joints.size(), {clip}, source.frame_stride);
      EXPECT_EQ(ToLevelSetData(*single).levels[0], expected) << "level " << l << " clip " << c;
      const LevelView& level = single->level(0);
      EXPECT_EQ(level.frame_count(), StoredFrameCount(clip.frame_count, source.frame_stride));
      EXPECT_EQ(level.clip_first_stored(0), 0u);
      // The one clip's blends are the set's, less the clip's first stored frame.
      for (uint32_t t = 0; t < clip.frame_count; ++t) {
        const FrameBlend in_set = view.level(l).Blend(c, t, clip.frame_count);
        const FrameBlend alone = level.Blend(0, t, clip.frame_count);
        const uint32_t first = view.level(l).clip_first_stored(c);
        EXPECT_EQ(alone.from + first, in_set.from);
        EXPECT_EQ(alone.to + first, in_set.to);
        EXPECT_EQ(alone.fraction, in_set.fraction);
      }
      const std::string again = ExtractLevelClip(*single, 0, 0).value();
      ASSERT_EQ(again.size(), file.size());
      EXPECT_EQ(std::memcmp(again.data(), file.data(), file.size()), 0);
    }
  }
}

TEST(ValidateLevelSet, RejectsEachInvalidVersion3Field) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  const InvalidCase cases[] = {
      {"stride 0", [](LevelSetData& d) { d.levels[1].frame_stride = 0; },
       "level 1: frame stride 0 is out of [1, 16]"},
      {"stride 17", [](LevelSetData& d) { d.levels[2].frame_stride = 17; },
       "level 2: frame stride 17 is out of [1, 16]"},
      {"matrices of another stride", [](LevelSetData& d) { d.levels[1].frame_stride = 3; },
       "level 1 has 528 matrix floats; T' x m x 12 = 432 (T' = 9 stored frames at frame "
       "stride 3)"},
      {"vertices not ascending", [](LevelSetData& d) { d.levels[1].vertices[2] = 2; },
       "level 1: its vertices are not strictly ascending at 2 (2 then 2)"},
      {"vertex out of range", [](LevelSetData& d) { d.levels[1].vertices[4] = 10; },
       "level 1: vertex 10 is out of range (vertex_count = 10)"},
      {"mesh without the character's vertex count",
       [](LevelSetData& d) {
         d.vertex_count = 0;
         d.levels[2].influences_per_vertex = 0;
         d.levels[2].influence_slots.clear();
         d.levels[2].influence_weights.clear();
       },
       "level 1 has a mesh of its own but the level set's vertex_count is 0"},
      {"vertices without triangles", [](LevelSetData& d) { d.levels[1].triangles.clear(); },
       "level 1 has 5 vertices of its own and 0 triangle indices (both or neither expected)"},
      {"triangles without vertices",
       [](LevelSetData& d) {
         d.levels[0].triangles = {0, 1, 2};
       },
       "level 0 has 0 vertices of its own and 3 triangle indices"},
      {"triangle indices not in threes", [](LevelSetData& d) { d.levels[1].triangles.pop_back(); },
       "level 1 has 5 triangle indices, not a multiple of 3"},
      {"triangle corner out of range", [](LevelSetData& d) { d.levels[1].triangles[4] = 5; },
       "level 1: triangle 1 corner 1 is vertex 5 of the level's 5"},
      {"influences per vertex 9", [](LevelSetData& d) { d.levels[1].influences_per_vertex = 9; },
       "level 1: influences_per_vertex 9 is out of [0, 8]"},
      {"influences of k 0", [](LevelSetData& d) { d.levels[0].influence_slots = {0}; },
       "level 0 has 1 influence slots and 0 weights but influences_per_vertex 0"},
      {"influence count", [](LevelSetData& d) { d.levels[1].influence_weights.pop_back(); },
       "level 1 has 10 influence slots and 9 weights; V x k = 10 (V = 5, k = 2)"},
      {"influences over the character's vertices",
       [](LevelSetData& d) { d.levels[2].influence_slots.pop_back(); },
       "level 2 has 9 influence slots and 10 weights; V x k = 10 (V = 10, k = 1)"},
      {"influences without vertices",
       [](LevelSetData& d) {
         d.vertex_count = 0;
         d.levels[1] = MakeLevel(1, {0, 1, 3, 4}, 18);
         d.levels[2].influence_slots.clear();
         d.levels[2].influence_weights.clear();
       },
       "level 2 has influences but no vertices (no mesh of its own and the level set's "
       "vertex_count is 0)"},
      {"influence slot out of range", [](LevelSetData& d) { d.levels[1].influence_slots[7] = 4; },
       "level 1: influence 1 of vertex 3 is on slot 4 (m = 4)"},
      {"NaN weight", [nan](LevelSetData& d) { d.levels[1].influence_weights[3] = nan; },
       "level 1: influence 1 of vertex 1 has weight nan"},
      {"negative weight",
       [](LevelSetData& d) {
         d.levels[1].influence_weights[2] = 1.5f;
         d.levels[1].influence_weights[3] = -0.5f;
       },
       "level 1: influence 1 of vertex 1 has weight -0.5 (finite and >= 0 expected)"},
      {"weights not summing to 1",
       [](LevelSetData& d) { d.levels[2].influence_weights[6] = 0.99f; },
       "level 2: the influence weights of vertex 6 sum to 0.99"},
      {"NaN cost", [nan](LevelSetData& d) { d.levels[1].cost = nan; }, "level 1: cost is nan"},
      {"negative cost", [](LevelSetData& d) { d.levels[0].cost = -1; },
       "level 0: cost is -1 (finite and >= 0 expected)"},
      {"infinite cost", [inf](LevelSetData& d) { d.levels[2].cost = inf; }, "level 2: cost is inf"},
  };
  for (const InvalidCase& c : cases) {
    LevelSetData data = MakeVersion3Sample();
    c.edit(data);
    const Status status = ValidateLevelSet(data);
    EXPECT_EQ(status.code(), StatusCode::kInvalidArgument) << c.name;
    EXPECT_THAT(status.message(), HasSubstr(c.message)) << c.name;
    EXPECT_EQ(EncodeLevelSet(data).status().message(), status.message()) << c.name;
    EXPECT_EQ(EncodeLevelSet(RefOf(data)).status().message(), status.message()) << c.name;
    AlignedBytes out(EncodedLevelSetSize(data) + 16);
    EXPECT_EQ(EncodeLevelSetInto(data, out.mutable_bytes()).status().message(), status.message())
        << c.name;
  }
}

TEST(ValidateLevelSet, AcceptsVersion3EdgeCases) {
  LevelSetData data = MakeVersion3Sample();
  data.levels[1].influence_weights[0] = 0.7505f;  // the weights of vertex 0 sum to 1.0005
  data.levels[0].frame_stride = kMaxFrameStride;
  data.levels[0].matrices =
      StoredSampleMatrices(0, data.levels[0].kept_joints.size(), data.clips, kMaxFrameStride);
  data.levels[2].cost = 0;
  data.vertex_count = 0xFFFFFFFFu;  // vertex ids are u32; influences cover p vertices
  data.levels[2].influences_per_vertex = 0;
  data.levels[2].influence_slots.clear();
  data.levels[2].influence_weights.clear();
  EXPECT_TRUE(ValidateLevelSet(data).ok()) << ValidateLevelSet(data).ToString();
  // A character's vertex count without any mesh or influences (a level extracted from a
  // set whose other levels have them) is kept as is.
  LevelSetData plain = MakeSample();
  plain.vertex_count = 7;
  const AlignedBytes bytes = Encode(plain);
  EXPECT_EQ(DecodeLevelSet(bytes.bytes()).value().vertex_count(), 7u);
}

TEST(DecodeLevelSet, RejectsInvalidVersion3Levels) {
  const AlignedBytes bytes = Encode(MakeVersion3Sample());
  const LevelSetView view = DecodeLevelSet(bytes.bytes()).value();
  const size_t record = OffsetsOf(bytes).level_table + internal::kLevelRecordSize;  // level 1
  const size_t vertices = OffsetIn(bytes, view.level(1).vertices().data());
  const size_t triangles = OffsetIn(bytes, view.level(1).triangles().data());
  const size_t slots = OffsetIn(bytes, view.level(1).influence_slots().data());
  const size_t weights = OffsetIn(bytes, view.level(2).influence_weights().data());
  struct Case {
    const char* name;
    std::function<void(AlignedBytes&)> edit;
    const char* message;
  };
  const Case cases[] = {
      {"stride 0", [&](AlignedBytes& b) { Poke<uint32_t>(b, record + 24, 0); },
       "level 1: frame stride 0 is out of [1, 16]"},
      {"stride 17", [&](AlignedBytes& b) { Poke<uint32_t>(b, record + 24, 17); },
       "level 1: frame stride 17"},
      {"another stride", [&](AlignedBytes& b) { Poke<uint32_t>(b, record + 24, 3); },
       "level 1: the matrices section is 2112 bytes; expected 1728 for m = 4, n = 6, T' = 9 "
       "(T = 18, frame stride 3)"},
      {"influences per vertex 9", [&](AlignedBytes& b) { Poke<uint32_t>(b, record + 28, 9); },
       "level 1: influences_per_vertex 9 is out of [0, 8]"},
      {"huge influences per vertex",
       [&](AlignedBytes& b) { Poke<uint32_t>(b, record + 28, 0xFFFFFFFFu); },
       "influences_per_vertex 4294967295"},
      {"influences per vertex 3", [&](AlignedBytes& b) { Poke<uint32_t>(b, record + 28, 3); },
       "level 1: the influence slots section is 20 bytes; expected 30"},
      {"vertex count", [&](AlignedBytes& b) { Poke<uint32_t>(b, record + 32, 4); },
       "level 1: the vertices section is 20 bytes; expected 16"},
      {"huge vertex count", [&](AlignedBytes& b) { Poke<uint32_t>(b, record + 32, 0xFFFFFFFFu); },
       "level 1: the vertices section is 20 bytes; expected 17179869180"},
      {"triangle count", [&](AlignedBytes& b) { Poke<uint32_t>(b, record + 36, 3); },
       "level 1: the triangles section is 24 bytes; expected 36"},
      {"character's vertex count",
       [](AlignedBytes& b) { Poke<uint32_t>(b, internal::kOffsetVertexCount, 9); },
       "level 2: the influence slots section is 20 bytes; expected 18"},
      {"cost NaN",
       [&](AlignedBytes& b) {
         Poke<float>(b, record + 40, std::numeric_limits<float>::quiet_NaN());
       },
       "level 1: cost is nan"},
      {"cost negative", [&](AlignedBytes& b) { Poke<float>(b, record + 40, -2.0f); },
       "level 1: cost is -2"},
      {"reserved", [&](AlignedBytes& b) { Poke<uint32_t>(b, record + 44, 1); },
       "level 1: reserved record fields are not zero"},
      {"vertices not ascending", [&](AlignedBytes& b) { Poke<uint32_t>(b, vertices + 4 * 3, 4); },
       "level 1: its vertices are not strictly ascending at 3 (4 then 4)"},
      {"vertex out of range", [&](AlignedBytes& b) { Poke<uint32_t>(b, vertices + 4 * 4, 10); },
       "level 1: vertex 10 is out of range (vertex_count = 10)"},
      {"triangle corner out of range",
       [&](AlignedBytes& b) { Poke<uint32_t>(b, triangles + 4 * 5, 0xFFFFFFFFu); },
       "level 1: triangle 1 corner 2 is vertex 4294967295 of the level's 5"},
      {"influence slot out of range", [&](AlignedBytes& b) { Poke<uint16_t>(b, slots + 2, 4); },
       "level 1: influence 1 of vertex 0 is on slot 4 (m = 4)"},
      {"weight infinite",
       [&](AlignedBytes& b) {
         Poke<float>(b, weights + 4 * 9, std::numeric_limits<float>::infinity());
       },
       "level 2: influence 0 of vertex 9 has weight inf"},
      {"weights not summing to 1", [&](AlignedBytes& b) { Poke<float>(b, weights, 0.5f); },
       "level 2: the influence weights of vertex 0 sum to 0.5 (1 expected, within 0.001)"},
  };
  for (const Case& c : cases) {
    const Status status = DecodeEdited(bytes, c.edit);
    EXPECT_EQ(status.code(), StatusCode::kDataLoss) << c.name;
    EXPECT_THAT(status.message(), HasSubstr(c.message)) << c.name;
  }
}

}  // namespace
}  // namespace motionlod::proto
