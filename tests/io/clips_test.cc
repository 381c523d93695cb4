#include "io/clips.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <numbers>

#include "test_util.h"

namespace motionlod::io {
namespace {

using Eigen::Quaterniond;
using Eigen::Vector3d;

TEST(DeriveSourceRate, BvhFrameTimeReadsAsWholeRate) {
  // Frame Time .0083333 gives Assimp 120.0005 ticks per second, one key per tick.
  std::vector<double> ticks;
  for (int k = 0; k <= 993; ++k) ticks.push_back(k);
  const SourceRate rate = DeriveSourceRate(ticks, 1.0 / 0.0083333, 30);
  EXPECT_EQ(rate.fps, 120.0);
  EXPECT_DOUBLE_EQ(993 * rate.seconds_per_tick, 993.0 / 120.0);
}

TEST(DeriveSourceRate, GltfMillisecondTicksGiveTheKeySpacing) {
  std::vector<double> ticks;
  for (int k = 0; k <= 80; ++k) ticks.push_back(static_cast<float>(k * 1000.0 / 24.0));
  const SourceRate rate = DeriveSourceRate(ticks, 1000, 30);
  EXPECT_EQ(rate.fps, 24.0);
  EXPECT_NEAR(80 * 1000.0 / 24.0 * rate.seconds_per_tick, 80.0 / 24.0, 1e-6);
}

TEST(DeriveSourceRate, SparseChannelsDoNotHideTheFrameSpacing) {
  // Union of a dense channel (every 1/30 s) and a two-key channel.
  std::vector<double> ticks = {0, 1000};
  for (int k = 0; k <= 30; ++k) ticks.push_back(k * 1000.0 / 30.0);
  EXPECT_EQ(DeriveSourceRate(ticks, 1000, 24).fps, 30.0);
}

TEST(DeriveSourceRate, NtscRateIsKept) {
  std::vector<double> ticks;
  for (int k = 0; k < 100; ++k) ticks.push_back(k * 1001.0 / 30.0);
  EXPECT_NEAR(DeriveSourceRate(ticks, 1000, 24).fps, 30000.0 / 1001.0, 1e-9);
}

TEST(DeriveSourceRate, SingleKeyFallsBack) {
  EXPECT_EQ(DeriveSourceRate({0}, 1000, 24).fps, 24.0);
  EXPECT_EQ(DeriveSourceRate({}, 1000, 30).fps, 30.0);
}

TEST(DeriveSourceRate, SparsePosesHaveNoRate) {
  EXPECT_EQ(DeriveSourceRate({0, 500, 1000}, 1000, 30).fps, 30.0);
}

TEST(FrameCount, FloorsWithTolerance) {
  EXPECT_EQ(FrameCount(993.0 / 120.0, 120), 994);
  EXPECT_EQ(FrameCount(993.0 / 120.0, 30), 249);
  EXPECT_EQ(FrameCount(0, 30), 1);
  EXPECT_EQ(FrameCount(80.0 / 24.0, 24), 81);
  EXPECT_EQ(FrameCount(1e300, 1000), std::numeric_limits<int>::max());
}

// One node "n" (rest: translation (0, 0, 5)) animated by `animation`.
Scene OneNodeScene(SceneAnimation animation) {
  Scene scene;
  SceneNode node;
  node.name = "n";
  node.local = core::IdentityAffine();
  node.local.col(3) = Vector3d(0, 0, 5);
  DecomposeLocal(node);
  scene.nodes.push_back(node);
  scene.animations.push_back(std::move(animation));
  return scene;
}

SceneChannel Channel(const std::string& node) {
  SceneChannel c;
  c.node_name = node;
  return c;
}

TEST(PoseSampler, LerpsPositionsSlerpsRotationsAndClampsOutsideTheKeys) {
  SceneAnimation a;
  a.name = "move";
  a.ticks_per_second = 10;
  a.duration_ticks = 10;
  SceneChannel c = Channel("n");
  c.position_times = {0, 10};
  c.positions = {Vector3d(0, 0, 0), Vector3d(2, 4, 0)};
  c.rotation_times = {0, 10};
  c.rotations = {Quaterniond::Identity(),
                 Quaterniond(Eigen::AngleAxisd(std::numbers::pi / 2, Vector3d::UnitZ()))};
  a.channels.push_back(c);
  const Scene scene = OneNodeScene(a);
  std::vector<std::string> warnings;
  const StatusOr<std::vector<Clip>> clips = BuildClips(scene, {1}, warnings);
  ASSERT_TRUE(clips.ok()) << clips.status().ToString();
  const Clip& clip = clips->front();
  EXPECT_EQ(clip.info.name, "move");
  EXPECT_DOUBLE_EQ(clip.info.duration_seconds, 1.0);

  PoseSampler sampler(scene.nodes, {0});
  core::Affine34d world;
  sampler.Evaluate(&clip, 0.5, &world);
  EXPECT_TRUE(world.col(3).isApprox(Vector3d(1, 2, 0), 1e-12));
  const Eigen::Matrix3d expected =
      Eigen::AngleAxisd(std::numbers::pi / 4, Vector3d::UnitZ()).toRotationMatrix();
  EXPECT_TRUE(world.leftCols<3>().isApprox(expected, 1e-12));

  sampler.Evaluate(&clip, -1.0, &world);
  EXPECT_TRUE(world.col(3).isApprox(Vector3d(0, 0, 0), 1e-12));
  sampler.Evaluate(&clip, 7.0, &world);
  EXPECT_TRUE(world.col(3).isApprox(Vector3d(2, 4, 0), 1e-12));
}

TEST(PoseSampler, SlerpTakesTheShortArc) {
  SceneAnimation a;
  a.name = "turn";
  a.ticks_per_second = 1;
  a.duration_ticks = 1;
  SceneChannel c = Channel("n");
  c.rotation_times = {0, 1};
  const Quaterniond end(Eigen::AngleAxisd(0.2, Vector3d::UnitY()));
  c.rotations = {Quaterniond::Identity(), Quaterniond(-end.coeffs())};  // same rotation, far sign
  a.channels.push_back(c);
  const Scene scene = OneNodeScene(a);
  std::vector<std::string> warnings;
  const auto clips = BuildClips(scene, {1}, warnings);
  ASSERT_TRUE(clips.ok());
  PoseSampler sampler(scene.nodes, {0});
  core::Affine34d world;
  sampler.Evaluate(&clips->front(), 0.5, &world);
  EXPECT_TRUE(world.leftCols<3>().isApprox(
      Eigen::AngleAxisd(0.1, Vector3d::UnitY()).toRotationMatrix(), 1e-12));
}

TEST(PoseSampler, MissingChannelsKeepTheRestValues) {
  SceneAnimation a;
  a.name = "only_rotation";
  a.ticks_per_second = 1;
  a.duration_ticks = 1;
  SceneChannel c = Channel("n");
  c.rotation_times = {0};
  c.rotations = {Quaterniond(Eigen::AngleAxisd(1.0, Vector3d::UnitX()))};
  a.channels.push_back(c);
  const Scene scene = OneNodeScene(a);
  std::vector<std::string> warnings;
  const auto clips = BuildClips(scene, {1}, warnings);
  ASSERT_TRUE(clips.ok());
  PoseSampler sampler(scene.nodes, {0});
  core::Affine34d world;
  sampler.Evaluate(&clips->front(), 0.3, &world);
  EXPECT_TRUE(world.col(3).isApprox(Vector3d(0, 0, 5), 1e-12));  // rest translation
  sampler.Evaluate(nullptr, 0.3, &world);                        // rest pose
  EXPECT_TRUE(world.isApprox(scene.nodes[0].local, 1e-12));
}

// A clip of `keys` rotation and position keys at uneven times (ticks = seconds).
SceneAnimation UnevenKeys(int keys) {
  SceneAnimation a;
  a.name = "uneven";
  a.ticks_per_second = 1;
  SceneChannel c = Channel("n");
  double time = 0;
  for (int k = 0; k < keys; ++k) {
    c.rotation_times.push_back(time);
    c.rotations.push_back(
        Quaterniond(Eigen::AngleAxisd(0.3 * k, Vector3d(1, k % 3, 2).normalized())));
    c.position_times.push_back(time);
    c.positions.push_back(Vector3d(k, k * k, -k));
    time += 0.05 + 0.04 * (k % 4);
  }
  a.duration_ticks = c.rotation_times.back();
  a.channels.push_back(c);
  return a;
}

TEST(PoseSampler, AnyOrderOfTimesGivesTheSameMatrices) {
  // The sampler looks for each time's keys from the last ones it used: walking forward,
  // back, repeating a time or jumping must all find the same keys as a fresh sampler.
  const Scene scene = OneNodeScene(UnevenKeys(40));
  std::vector<std::string> warnings;
  const auto clips = BuildClips(scene, {1}, warnings);
  ASSERT_TRUE(clips.ok());
  const Clip& clip = clips->front();
  std::vector<double> times;
  for (int t = -2; t <= 300; ++t) times.push_back(t / 80.0);
  for (int t = 300; t >= 0; t -= 7) times.push_back(t / 80.0 + 1e-3);
  for (int t : {150, 3, 299, 3, 3, 200}) times.push_back(t / 80.0);
  PoseSampler walking(scene.nodes, {0});
  for (double seconds : times) {
    PoseSampler fresh(scene.nodes, {0});
    core::Affine34d walked, expected;
    walking.Evaluate(&clip, seconds, &walked);
    fresh.Evaluate(&clip, seconds, &expected);
    ASSERT_EQ(walked, expected) << "at " << seconds << " s";
  }
}

TEST(PoseSampler, ATimeWithinRoundingOfAKeyIsThatKey) {
  // Key times carry the rounding of the file's float ticks: a frame that lands a hair
  // off a key gets the key itself.
  const Scene scene = OneNodeScene(UnevenKeys(3));
  std::vector<std::string> warnings;
  const auto clips = BuildClips(scene, {1}, warnings);
  ASSERT_TRUE(clips.ok());
  const Track& track = clips->front().tracks.front();
  const Eigen::Matrix3d key = track.rotations[1].toRotationMatrix();
  PoseSampler sampler(scene.nodes, {0});
  core::Affine34d world;
  for (double offset : {-1e-12, 0.0, 1e-12}) {
    sampler.Evaluate(&clips->front(), track.rotation_times[1] + offset, &world);
    EXPECT_EQ(world.leftCols<3>(), key) << offset;
    EXPECT_EQ(world.col(3), track.positions[1]) << offset;
  }
  // Further off, the keys are blended.
  sampler.Evaluate(&clips->front(), track.rotation_times[1] + 1e-6, &world);
  EXPECT_GT((world.leftCols<3>() - key).norm(), 1e-8);
  EXPECT_LT((world.leftCols<3>() - key).norm(), 1e-5);
}

TEST(BuildClips, KeysAHairOffTheFramesOfTheirRateAreOnThem) {
  // Keys every 1/24 s written with the rounding of a file (float seconds, a few decimals):
  // up to 1e-3 of a frame off, they are on the frame, so that sampling the clip at its own
  // rate gives the keys themselves; a key 1e-2 of a frame off stays where it is.
  SceneAnimation a;
  a.name = "walk";
  a.ticks_per_second = 1;
  SceneChannel c = Channel("n");
  const std::vector<double> frame_offsets = {0, 1e-7, -2e-5, 4e-4, -9e-4, 1e-2, 0, 0};
  for (size_t k = 0; k < frame_offsets.size(); ++k) {
    c.rotation_times.push_back((k + frame_offsets[k]) / 24.0);
    c.rotations.push_back(Quaterniond(Eigen::AngleAxisd(0.2 * k, Vector3d::UnitY())));
  }
  a.duration_ticks = c.rotation_times.back();
  a.channels.push_back(c);
  const Scene scene = OneNodeScene(a);
  std::vector<std::string> warnings;
  const auto clips = BuildClips(scene, {1}, warnings);
  ASSERT_TRUE(clips.ok()) << clips.status().ToString();
  const Clip& clip = clips->front();
  ASSERT_EQ(clip.info.source_fps, 24.0);
  const Track& track = clip.tracks.front();
  PoseSampler sampler(scene.nodes, {0});
  for (int k = 0; k < 5; ++k) {
    EXPECT_EQ(track.rotation_times[k], k / 24.0) << k;
    core::Affine34d world;
    sampler.Evaluate(&clip, k / 24.0, &world);
    EXPECT_EQ(world.leftCols<3>(), c.rotations[k].toRotationMatrix()) << k;
  }
  EXPECT_DOUBLE_EQ(track.rotation_times[5], 5.01 / 24.0);
  // Frame 5 lies between keys 4 and 5, 99% of the way: a blend, not key 5.
  core::Affine34d world;
  sampler.Evaluate(&clip, 5 / 24.0, &world);
  const double angle = 0.2 * (4 + 1 / 1.01);
  EXPECT_TRUE(world.leftCols<3>().isApprox(
      Eigen::AngleAxisd(angle, Vector3d::UnitY()).toRotationMatrix(), 1e-12));
}

TEST(BuildClips, MergesUnnamedSingleChannelAnimationsOfEqualLength) {
  Scene scene;
  for (const char* name : {"a", "b", "c"}) {
    SceneNode node;
    node.name = name;
    node.parent = scene.nodes.empty() ? -1 : 0;
    scene.nodes.push_back(node);
  }
  for (const char* name : {"a", "b", "c"}) {
    SceneAnimation animation;
    animation.ticks_per_second = 1000;
    animation.duration_ticks = 2000;
    SceneChannel c = Channel(name);
    c.position_times = {0, 1000, 2000};
    c.positions = {Vector3d::Zero(), Vector3d::UnitX(), Vector3d::UnitY()};
    animation.channels.push_back(c);
    scene.animations.push_back(animation);
  }
  SceneAnimation other;  // a different length stays apart
  other.ticks_per_second = 1000;
  other.duration_ticks = 500;
  other.channels.push_back(Channel("a"));
  scene.animations.push_back(other);
  std::vector<std::string> warnings;
  const auto clips = BuildClips(scene, std::vector<char>(3, 0), warnings);
  ASSERT_TRUE(clips.ok());
  ASSERT_EQ(clips->size(), 2u);
  EXPECT_EQ((*clips)[0].tracks.size(), 3u);
  EXPECT_EQ((*clips)[0].info.name, "animation");
  EXPECT_EQ((*clips)[1].info.name, "animation_1");
  EXPECT_DOUBLE_EQ((*clips)[0].info.duration_seconds, 2.0);
  EXPECT_EQ((*clips)[0].info.source_fps, 30.0);  // one key per second: poses, no rate
  EXPECT_EQ((*clips)[0].info.source_frame_count, 61);
  EXPECT_FALSE(warnings.empty());
}

TEST(BuildClips, RejectsZeroLengthRotationKeys) {
  SceneAnimation a;
  a.name = "bad";
  a.ticks_per_second = 1;
  SceneChannel c = Channel("n");
  c.rotation_times = {0};
  c.rotations = {Quaterniond(0, 0, 0, 0)};
  a.channels.push_back(c);
  std::vector<std::string> warnings;
  const auto clips = BuildClips(OneNodeScene(a), {1}, warnings);
  EXPECT_EQ(clips.status().code(), StatusCode::kInvalidArgument);
}

TEST(BuildClips, RaisesZeroScalesSoMatricesStayInvertible) {
  SceneAnimation a;
  a.name = "spawn";
  a.ticks_per_second = 1;
  a.duration_ticks = 1;
  SceneChannel c = Channel("n");
  c.scaling_times = {0, 1};
  c.scalings = {Vector3d::Zero(), Vector3d::Ones()};
  a.channels.push_back(c);
  const Scene scene = OneNodeScene(a);
  std::vector<std::string> warnings;
  const auto clips = BuildClips(scene, {1}, warnings);
  ASSERT_TRUE(clips.ok());
  PoseSampler sampler(scene.nodes, {0});
  core::Affine34d world;
  sampler.Evaluate(&clips->front(), 0, &world);
  EXPECT_GT(std::abs(world.leftCols<3>().determinant()), 0);
  EXPECT_EQ(warnings.size(), 1u);
}

// Two joints, the second animated over 40 s with a zero scale keyed at 30 s and 35 s
// (a clip BuildClips would have raised: SampleClip checks what it samples whatever its
// source), sampled at 1 fps: the first singular matrix is frame 30's second joint, in a
// later range of frames than the first, on several threads.
TEST(SampleClip, FindsTheFirstSingularMatrixInAnyRangeOfFrames) {
  std::vector<SceneNode> nodes(2);
  for (SceneNode& node : nodes) {
    node.local = core::IdentityAffine();
    DecomposeLocal(node);
  }
  nodes[1].parent = 0;
  Clip clip;
  clip.info.name = "shrink";
  clip.info.duration_seconds = 40;
  Track& track = clip.tracks.emplace_back();
  track.node = 1;
  for (int second = 0; second <= 40; ++second) {
    track.scaling_times.push_back(second);
    track.scalings.push_back(second == 30 || second == 35 ? Vector3d::Zero() : Vector3d::Ones());
  }
  const SampledClip alone = SampleClip(clip, nodes, {0, 1}, 1, {});
  ASSERT_EQ(alone.motion.frame_count, 41);
  EXPECT_EQ(alone.first_non_invertible, 30u * 2 + 1);
  for (int threads : {1, 2, 3}) {
    const SampledClip sampled = SampleClip(clip, nodes, {0, 1}, 1, testing::ThreadRunner(threads));
    EXPECT_EQ(sampled.first_non_invertible, 30u * 2 + 1) << threads << " threads";
    for (size_t i = 0; i < alone.motion.joint_world.size(); ++i) {
      EXPECT_TRUE(sampled.motion.joint_world[i].isApprox(alone.motion.joint_world[i], 0))
          << "matrix " << i << ", " << threads << " threads";
    }
  }
  track.scalings[30] = track.scalings[35] = Vector3d::Ones();
  const SampledClip clean = SampleClip(clip, nodes, {0, 1}, 1, {});
  EXPECT_EQ(clean.first_non_invertible, clean.motion.joint_world.size());
}

TEST(BuildClips, IgnoresChannelsOfUnknownNodesWithAWarning) {
  SceneAnimation a;
  a.name = "ghost";
  a.ticks_per_second = 1;
  a.channels.push_back(Channel("nobody"));
  std::vector<std::string> warnings;
  const auto clips = BuildClips(OneNodeScene(a), {1}, warnings);
  ASSERT_TRUE(clips.ok());
  EXPECT_TRUE(clips->front().tracks.empty());
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_NE(warnings[0].find("nobody"), std::string::npos);
}

}  // namespace
}  // namespace motionlod::io
