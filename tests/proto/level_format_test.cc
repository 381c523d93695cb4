#include "proto/level_format.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "proto/aligned_bytes.h"
#include "proto/checksum.h"
#include "proto/level_format_internal.h"

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
  data.levels.push_back({{0}, {0}, {}, {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0}});
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
      {"matrix count", [](LevelSetData& d) { d.levels[0].matrices.pop_back(); }, "T x m x 12"},
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

TEST(DecodeLevelSet, RejectsUnknownMajorVersion) {
  internal::WriterOptions options;
  options.major_version = 2;
  const LevelSetData sample = MakeSample();
  const AlignedBytes bytes =
      AlignedBytes::CopyOf(internal::EncodeLevelSetWithOptions(RefOf(sample), options).value());
  const Status status = DecodeLevelSet(bytes.bytes()).status();
  EXPECT_EQ(status.code(), StatusCode::kUnsupported);
  EXPECT_THAT(status.message(), HasSubstr("version 2.0"));

  const Status zero = DecodeEdited(
      bytes, [](AlignedBytes& b) { Poke<uint16_t>(b, internal::kOffsetMajorVersion, 0); });
  EXPECT_EQ(zero.code(), StatusCode::kUnsupported);
}

TEST(DecodeLevelSet, RejectsTruncationAtEveryByteOffset) {
  const AlignedBytes bytes = Encode(MakeSample(1));
  for (size_t size = 0; size < bytes.size(); ++size) {
    const Status status = DecodeLevelSet(bytes.bytes().first(size)).status();
    ASSERT_EQ(status.code(), StatusCode::kDataLoss) << "prefix of " << size << " bytes";
  }
}

TEST(DecodeLevelSet, RejectsTrailingBytes) {
  const AlignedBytes original = Encode(MakeSample());
  AlignedBytes longer(original.size() + 16);
  std::memcpy(longer.data(), original.data(), original.size());
  EXPECT_EQ(DecodeLevelSet(longer.bytes()).status().code(), StatusCode::kDataLoss);
}

TEST(DecodeLevelSet, RejectsEveryFlippedBit) {
  const AlignedBytes original = Encode(MakeSample(1));
  AlignedBytes bytes = AlignedBytes::CopyOf(original.bytes());
  for (size_t i = 0; i < bytes.size(); ++i) {
    for (const uint8_t bit : {0x01, 0x80}) {
      bytes.data()[i] ^= std::byte{bit};
      ASSERT_FALSE(DecodeLevelSet(bytes.bytes()).ok()) << "byte " << i << " bit " << int{bit};
      bytes.data()[i] ^= std::byte{bit};
    }
  }
  EXPECT_TRUE(DecodeLevelSet(bytes.bytes()).ok());
}

TEST(DecodeLevelSet, ReportsChecksumMismatchAsDataLoss) {
  AlignedBytes bytes = Encode(MakeSample());
  bytes.data()[OffsetsOf(bytes).level1_matrices] ^= std::byte{0x10};
  const Status status = DecodeLevelSet(bytes.bytes()).status();
  EXPECT_EQ(status.code(), StatusCode::kDataLoss);
  EXPECT_THAT(status.message(), HasSubstr("checksum"));
}

TEST(DecodeLevelSet, WithoutChecksumNeverFailsOtherThanByStatusOnCorruptBytes) {
  // The fuzz target's configuration, on every single-byte corruption of a small file:
  // each decodes or fails cleanly (run under sanitizers to catch over-reads).
  const AlignedBytes original = Encode(MakeSample(1));
  AlignedBytes bytes = AlignedBytes::CopyOf(original.bytes());
  const DecodeOptions no_checksum{.verify_checksum = false};
  for (size_t i = 0; i < bytes.size(); ++i) {
    for (const uint8_t value : {0x00, 0x01, 0x7F, 0x80, 0xFF}) {
      const std::byte saved = bytes.data()[i];
      bytes.data()[i] = std::byte{value};
      StatusOr<LevelSetView> view = DecodeLevelSet(bytes.bytes(), no_checksum);
      if (view.ok()) {
        EXPECT_TRUE(EncodeLevelSet(ToLevelSetData(*view)).ok()) << "byte " << i;
      }
      bytes.data()[i] = saved;
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
  // 0xFFFFFFFF x 4 x 48 wraps in 32 bits; in 64 it does not match the section.
  const AlignedBytes bytes = Encode(MakeSample());
  const Status status = DecodeEdited(
      bytes, [](AlignedBytes& b) { Poke<uint32_t>(b, internal::kOffsetFrameCount, 0xFFFFFFFFu); });
  EXPECT_EQ(status.code(), StatusCode::kDataLoss);
  EXPECT_THAT(status.message(), HasSubstr("T = 4294967295"));
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
  const Status reserved = DecodeEdited(
      bytes, [](AlignedBytes& b) { Poke<uint32_t>(b, internal::kOffsetReserved0, 1); });
  EXPECT_THAT(reserved.message(), HasSubstr("reserved"));
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
  later.extension_fill = 0xA5;
  later.extra_flags = 1u << 12;
  later.extra_sections.push_back({40, internal::kNoLevel, "a global section of the future"});
  later.extra_sections.push_back({41, 1, std::string(37, '\x5A')});
  const LevelSetData data = MakeSample();
  const AlignedBytes bytes =
      AlignedBytes::CopyOf(internal::EncodeLevelSetWithOptions(RefOf(data), later).value());

  StatusOr<LevelSetView> view = DecodeLevelSet(bytes.bytes());
  ASSERT_TRUE(view.ok()) << view.status().ToString();
  EXPECT_EQ(view->minor_version(), kLevelFormatMinorVersion + 3);
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

}  // namespace
}  // namespace motionlod::proto
