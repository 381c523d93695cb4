#include "core/character.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "core/internal/skin_clusters.h"
#include "tests/core/fixtures.h"

namespace motionlod::core {
namespace {

using testing::MakeCreature;

TEST(BuildCharacter, AcceptsTheCreatureAndDerivesAreasAndHeight) {
  auto built = BuildCharacter(MakeCreature());
  ASSERT_TRUE(built.ok()) << built.status().ToString();
  const Character& c = **built;
  EXPECT_EQ(c.joint_count(), 8);
  EXPECT_EQ(c.vertex_count(), 7 * 5 * 8);
  double total = 0;
  for (double a : c.vertex_areas()) total += a;
  // Each triangle's area is counted at its three corners.
  double triangles = 0;
  for (const auto& tri : c.skin().triangles) {
    const Vec3d a = c.skin().positions[tri[0]].cast<double>();
    const Vec3d b = c.skin().positions[tri[1]].cast<double>();
    const Vec3d d = c.skin().positions[tri[2]].cast<double>();
    triangles += 0.5 * (b - a).cross(d - a).norm();
  }
  EXPECT_NEAR(total, 3 * triangles, 1e-9);
  // Longest side of the bind bounding box: y from the root ring (0) to the head ring (2.5);
  // x only spans the hands' rings, -1.2 to 1.2.
  EXPECT_NEAR(c.height(), 2.5, 1e-6);
}

TEST(BuildCharacter, SubtreeLengthSumsDistancesToLeaves) {
  // Two bones along y, skin weighted 1.0 to each joint: the leaf's end site is the
  // farthest vertex it dominates.
  RawCharacter raw;
  raw.skeleton.joint_names = {"a", "b"};
  raw.skeleton.parents = {-1, 0};
  raw.skeleton.bind_world = {testing::Translation(0, 0, 0), testing::Translation(0, 1, 0)};
  raw.skin.positions = {Vec3f(0, 0, 0), Vec3f(0, 1, 0), Vec3f(0, 3, 0)};
  raw.skin.normals = {Vec3f(1, 0, 0), Vec3f(1, 0, 0), Vec3f(1, 0, 0)};
  raw.skin.influence_offsets = {0, 1, 2, 3};
  raw.skin.influence_joints = {0, 1, 1};
  raw.skin.influence_weights = {1, 1, 1};
  auto built = BuildCharacter(raw);
  ASSERT_TRUE(built.ok()) << built.status().ToString();
  // Leaf b ends at (0,3,0): h_b = 2, h_a = 3.
  EXPECT_DOUBLE_EQ((*built)->subtree_lengths()[1], 2.0);
  EXPECT_DOUBLE_EQ((*built)->subtree_lengths()[0], 3.0);
}

TEST(BuildCharacter, ChildlessJointWithSkinEndsAtItsFarthestVertex) {
  auto built = BuildCharacter(MakeCreature());
  ASSERT_TRUE(built.ok());
  const Character& c = **built;
  // head (0,2.5) dominates (weight > 0.5) the neck tube's rings at y = 2.375 and 2.5,
  // radius 0.15: the farthest, its end site, is a vertex of the ring at y = 2.375.
  EXPECT_NEAR(c.subtree_lengths()[3], std::hypot(0.125, 0.15), 1e-6);
  EXPECT_NEAR(c.subtree_lengths()[2], std::hypot(0.375, 0.15), 1e-6);
}

RawCharacter Valid() { return MakeCreature(4, 1); }

TEST(BuildCharacter, ClustersPartitionTheSkinAndBoundTheirVerticesAndWeights) {
  // More segments than one cluster holds, so groups split.
  auto built = BuildCharacter(MakeCreature(16, 6));
  ASSERT_TRUE(built.ok()) << built.status().ToString();
  const Character& c = **built;
  const RawSkin& skin = c.skin();
  const int n = c.joint_count();
  ASSERT_EQ(c.clusters().group_cluster_offsets.size(), static_cast<size_t>(n + 1));
  const auto& vertex_offsets = c.clusters().cluster_vertex_offsets;
  const size_t clusters = c.clusters().cluster_centers.size();
  ASSERT_EQ(vertex_offsets.size(), clusters + 1);
  ASSERT_EQ(c.clusters().cluster_influence_offsets.size(), clusters + 1);
  EXPECT_EQ(c.clusters().group_cluster_offsets.back(), clusters);
  EXPECT_GT(clusters, static_cast<size_t>(n));
  std::vector<int> seen(c.vertex_count(), 0);
  for (int group = 0; group < n; ++group) {
    for (uint32_t cluster = c.clusters().group_cluster_offsets[group]; cluster < c.clusters().group_cluster_offsets[group + 1];
         ++cluster) {
      const uint32_t size = vertex_offsets[cluster + 1] - vertex_offsets[cluster];
      EXPECT_GE(size, 1u);
      EXPECT_LE(size, static_cast<uint32_t>(internal::kMaxClusterVertices));
      // Each joint weighting a vertex of the cluster is listed with the range of its
      // weights: the smallest is 0 where a vertex of the cluster has no weight from it.
      std::vector<float> largest(n, 0.0f), smallest(n, 2.0f);
      std::vector<uint32_t> weighted(n, 0);
      for (uint32_t e = vertex_offsets[cluster]; e < vertex_offsets[cluster + 1]; ++e) {
        const uint32_t i = c.clusters().cluster_vertices[e];
        ++seen[i];
        const Vec3d offset = skin.positions[i].cast<double>() - c.clusters().cluster_centers[cluster];
        EXPECT_TRUE((offset.cwiseAbs().array() <= c.clusters().cluster_half_extents[cluster].array() + 1e-9).all());
        float dominant_weight = 0;
        int dominant = -1;
        for (uint32_t g = skin.influence_offsets[i]; g < skin.influence_offsets[i + 1]; ++g) {
          const int j = skin.influence_joints[g];
          largest[j] = std::max(largest[j], skin.influence_weights[g]);
          smallest[j] = std::min(smallest[j], skin.influence_weights[g]);
          ++weighted[j];
          if (skin.influence_weights[g] > dominant_weight) {
            dominant_weight = skin.influence_weights[g];
            dominant = skin.influence_joints[g];
          }
        }
        EXPECT_EQ(dominant, group) << "vertex " << i;
      }
      std::vector<float> listed_max(n, 0.0f), listed_min(n, 0.0f), expected_min(n, 0.0f);
      for (uint32_t q = c.clusters().cluster_influence_offsets[cluster]; q < c.clusters().cluster_influence_offsets[cluster + 1]; ++q) {
        listed_max[c.clusters().cluster_influences[q].joint] = c.clusters().cluster_influences[q].max_weight;
        listed_min[c.clusters().cluster_influences[q].joint] = c.clusters().cluster_influences[q].min_weight;
      }
      for (int j = 0; j < n; ++j) {
        if (weighted[j] == size) expected_min[j] = smallest[j];
      }
      EXPECT_EQ(listed_max, largest) << "cluster " << cluster;
      EXPECT_EQ(listed_min, expected_min) << "cluster " << cluster;
      // Its lane block: positions, then one row of weights per listed joint, padded.
      const uint32_t padded = internal::ClusterLaneRow(size);
      EXPECT_EQ(padded % internal::kClusterLanes, 0u);
      EXPECT_LT(padded - size, static_cast<uint32_t>(internal::kClusterLanes));
      const uint32_t listed =
          c.clusters().cluster_influence_offsets[cluster + 1] - c.clusters().cluster_influence_offsets[cluster];
      ASSERT_EQ(c.clusters().cluster_lane_offsets[cluster + 1] - c.clusters().cluster_lane_offsets[cluster],
                (3 + listed) * padded);
      const float* block = c.clusters().cluster_lanes.data() + c.clusters().cluster_lane_offsets[cluster];
      for (uint32_t v = 0; v < padded; ++v) {
        const bool real = v < size;
        const uint32_t i = real ? c.clusters().cluster_vertices[vertex_offsets[cluster] + v] : 0;
        for (int a = 0; a < 3; ++a)
          EXPECT_EQ(block[a * padded + v], real ? skin.positions[i][a] : 0.0f);
        for (uint32_t q = 0; q < listed; ++q) {
          const int joint =
              c.clusters().cluster_influences[c.clusters().cluster_influence_offsets[cluster] + q].joint;
          float weight = 0;
          for (uint32_t g = skin.influence_offsets[i]; real && g < skin.influence_offsets[i + 1];
               ++g) {
            if (skin.influence_joints[g] == joint) weight = skin.influence_weights[g];
          }
          EXPECT_EQ(block[(3 + q) * padded + v], weight) << "cluster " << cluster << " lane " << v;
        }
      }
    }
  }
  for (int i = 0; i < c.vertex_count(); ++i) EXPECT_EQ(seen[i], 1) << "vertex " << i;
  EXPECT_EQ(c.clusters().cluster_lanes.size(), c.clusters().cluster_lane_offsets.back());
}

// One joint weighting every vertex of `positions`, which need no triangles.
RawCharacter OneJointCloud(std::vector<Vec3f> positions) {
  RawCharacter raw;
  raw.skeleton.parents = {-1};
  raw.skeleton.joint_names = {"root"};
  raw.skeleton.bind_world = {IdentityAffine()};
  const size_t p = positions.size();
  raw.skin.positions = std::move(positions);
  raw.skin.normals.assign(p, Vec3f::UnitY());
  for (size_t i = 0; i <= p; ++i) raw.skin.influence_offsets.push_back(static_cast<uint32_t>(i));
  raw.skin.influence_joints.assign(p, 0);
  raw.skin.influence_weights.assign(p, 1.0f);
  return raw;
}

TEST(BuildCharacter, ClustersAreMedianSplitsEvenWhereCoordinatesRepeat) {
  // Median splits leave every cluster of a group larger than one cluster between half
  // and all of kMaxClusterVertices. Integer grids repeat each coordinate many times (the
  // split's equal keys), a single repeated point makes every key equal, and a shuffled
  // run along x shows whether the splits really are at the median.
  std::vector<Vec3f> grid, run, one_point;
  for (int x = 0; x < 48; ++x) {
    for (int z = 0; z < 40; ++z)
      grid.push_back(Vec3f(static_cast<float>(x % 7), 0.0f, static_cast<float>(z)));
  }
  for (int i = 0; i < 3000; ++i) {
    run.push_back(
        Vec3f(static_cast<float>(i * 1543 % 3000), 0.001f * static_cast<float>(i % 5), 0.0f));
  }
  one_point.assign(1000, Vec3f(1.0f, 2.0f, 3.0f));
  for (std::vector<Vec3f>* positions : {&grid, &run, &one_point}) {
    const size_t p = positions->size();
    auto built = BuildCharacter(OneJointCloud(*positions));
    ASSERT_TRUE(built.ok()) << built.status().ToString();
    const Character& c = **built;
    const auto& offsets = c.clusters().cluster_vertex_offsets;
    std::vector<int> seen(p, 0);
    for (size_t cluster = 0; cluster + 1 < offsets.size(); ++cluster) {
      const uint32_t size = offsets[cluster + 1] - offsets[cluster];
      EXPECT_GE(size, static_cast<uint32_t>(internal::kMaxClusterVertices / 2)) << "p " << p;
      EXPECT_LE(size, static_cast<uint32_t>(internal::kMaxClusterVertices)) << "p " << p;
      for (uint32_t e = offsets[cluster]; e < offsets[cluster + 1]; ++e) {
        const uint32_t i = c.clusters().cluster_vertices[e];
        ++seen[i];
        const Vec3d offset = c.skin().positions[i].cast<double>() - c.clusters().cluster_centers[cluster];
        EXPECT_TRUE(
            (offset.cwiseAbs().array() <= c.clusters().cluster_half_extents[cluster].array() + 1e-9).all());
      }
    }
    EXPECT_EQ(std::count(seen.begin(), seen.end(), 1), static_cast<std::ptrdiff_t>(p));
  }
  // Median splits along x cut the run into clusters of consecutive x, whose boxes do not
  // overlap: together they cover at most the run's length.
  const auto built = BuildCharacter(OneJointCloud(run));
  ASSERT_TRUE(built.ok());
  double covered = 0;
  for (const Vec3d& half : (*built)->clusters().cluster_half_extents) covered += 2 * half.x();
  EXPECT_LE(covered, 2999.0);
}

TEST(ValidateRawCharacter, RejectsEachInvalidField) {
  struct Case {
    const char* what;
    void (*mutate)(RawCharacter&);
    const char* expect;
  };
  const Case cases[] = {
      {"no joints", [](RawCharacter& c) { c.skeleton = {}; }, "no joints"},
      {"two roots", [](RawCharacter& c) { c.skeleton.parents[2] = -1; }, "parent"},
      {"parent after child", [](RawCharacter& c) { c.skeleton.parents[1] = 5; }, "parent"},
      {"duplicate name", [](RawCharacter& c) { c.skeleton.joint_names[2] = "spine"; }, "named"},
      {"nan bind", [](RawCharacter& c) { c.skeleton.bind_world[3](0, 3) = NAN; }, "non-finite"},
      {"singular bind", [](RawCharacter& c) { c.skeleton.bind_world[3].leftCols<3>().setZero(); }, "singular"},
      {"no vertices", [](RawCharacter& c) { c.skin = {}; }, "no vertices"},
      {"nan position", [](RawCharacter& c) { c.skin.positions[7].x() = NAN; }, "non-finite"},
      {"normal length", [](RawCharacter& c) { c.skin.normals[3] *= 2; }, "unit"},
      {"weights sum", [](RawCharacter& c) { c.skin.influence_weights[0] = 0.5f; }, "summing"},
      {"zero weight", [](RawCharacter& c) { c.skin.influence_weights[0] = 0.0f; }, "not positive"},
      {"bad joint", [](RawCharacter& c) { c.skin.influence_joints[0] = 99; }, "does not exist"},
      {"bad triangle", [](RawCharacter& c) { c.skin.triangles[0][1] = 100000; }, "triangle"},
      {"offsets", [](RawCharacter& c) { c.skin.influence_offsets.pop_back(); }, "influence_offsets"},
  };
  ASSERT_TRUE(ValidateRawCharacter(Valid()).ok());
  for (const Case& test : cases) {
    RawCharacter c = Valid();
    test.mutate(c);
    const Status status = ValidateRawCharacter(c);
    EXPECT_FALSE(status.ok()) << test.what;
    EXPECT_EQ(status.code(), StatusCode::kInvalidArgument) << test.what;
    EXPECT_NE(status.message().find(test.expect), std::string::npos)
        << test.what << ": " << status.message();
    EXPECT_FALSE(BuildCharacter(c).ok()) << test.what;
  }
}

TEST(ValidateMotion, RejectsShapeAndValueErrors) {
  const auto c = testing::BuildOrDie(MakeCreature());
  Motion m = testing::MakeWaveMotion(*c, 3);
  ASSERT_TRUE(ValidateMotion(m, *c).ok());
  Motion bad = m;
  bad.fps = 0;
  EXPECT_FALSE(ValidateMotion(bad, *c).ok());
  bad = m;
  bad.joint_world.pop_back();
  EXPECT_FALSE(ValidateMotion(bad, *c).ok());
  bad = m;
  bad.joint_world[5](1, 1) = INFINITY;
  EXPECT_NE(ValidateMotion(bad, *c).message().find("frame 0"), std::string::npos);
  bad = m;
  bad.joint_count = 7;
  EXPECT_FALSE(ValidateMotion(bad, *c).ok());
  // Each kind of bad matrix, first, inside and last, named by frame and joint: a
  // translation (no determinant sees it) and a rank-deficient rotation part.
  const int n = m.joint_count;
  for (const int q : {0, n + 2, static_cast<int>(m.joint_world.size()) - 1}) {
    const std::string where =
        "frame " + std::to_string(q / n) + ", joint '" + c->skeleton().joint_names[q % n] + "'";
    bad = m;
    bad.joint_world[q](2, 3) = NAN;
    EXPECT_EQ(ValidateMotion(bad, *c).message(), "non-finite joint matrix at " + where);
    bad = m;
    bad.joint_world[q].col(2) = bad.joint_world[q].col(1);
    EXPECT_EQ(ValidateMotion(bad, *c).message(), "singular joint matrix at " + where);
  }
}

TEST(FirstNonInvertibleAffine, FindsTheFirstRejectedMatrixWhereverItSits) {
  // Rotations with a translation, one per index: the check runs four matrices at a time
  // and pads the last one to three, so every count up to 9 and every position is tried.
  const auto valid = [](int i) {
    Affine34d m;
    m.leftCols<3>() = Eigen::AngleAxisd(0.3 * i, Vec3d(1, 2, 3).normalized()).toRotationMatrix();
    m.col(3) = Vec3d(i, -2.0 * i, 0.5);
    return m;
  };
  Affine34d singular = valid(1);
  singular.col(2) = 2 * singular.col(0);
  Affine34d nearly_singular = valid(2);
  nearly_singular.col(2) = 1e-13 * nearly_singular.col(2);
  Affine34d infinite = valid(3);
  infinite(0, 0) = INFINITY;
  Affine34d nan_translation = valid(4);
  nan_translation(1, 3) = NAN;
  const Affine34d zero = Affine34d::Zero();
  for (const Affine34d& bad : {singular, nearly_singular, infinite, nan_translation, zero}) {
    EXPECT_FALSE(IsInvertibleAffine(bad));
    for (size_t count = 1; count <= 9; ++count) {
      for (size_t at = 0; at < count; ++at) {
        std::vector<Affine34d> matrices;
        for (size_t i = 0; i < count; ++i) matrices.push_back(valid(static_cast<int>(i)));
        matrices[at] = bad;
        EXPECT_EQ(FirstNonInvertibleAffine(matrices), at) << count << " " << at;
        // A later rejected matrix does not hide the first.
        if (at + 1 < count) matrices[count - 1] = zero;
        EXPECT_EQ(FirstNonInvertibleAffine(matrices), at) << count << " " << at;
      }
    }
  }
  // Accepted whatever their scale or handedness: the bound scales as det does.
  Affine34d tiny = 1e-90 * valid(5);
  Affine34d huge = 1e90 * valid(6);
  Affine34d mirrored = valid(7);
  mirrored.col(0) = -mirrored.col(0);
  Affine34d sheared = valid(8);
  sheared.col(1) += 3 * sheared.col(0);
  const std::vector<Affine34d> accepted = {tiny, huge, mirrored, sheared, valid(9)};
  for (const Affine34d& m : accepted) EXPECT_TRUE(IsInvertibleAffine(m));
  EXPECT_EQ(FirstNonInvertibleAffine(accepted), accepted.size());
  EXPECT_EQ(FirstNonInvertibleAffine({}), 0u);
}

}  // namespace
}  // namespace motionlod::core
