// Animation clips: the scene's channels bound to nodes, with times in seconds, and the
// sampler that turns a clip into per-frame joint world matrices. Internal to io.
#pragma once

#include <Eigen/Geometry>
#include <array>
#include <string>
#include <vector>

#include "base/pieces.h"
#include "base/status.h"
#include "core/motion.h"
#include "io/asset.h"
#include "io/scene.h"

namespace motionlod::io {

// A node's keys in clip time: seconds from the clip start.
struct Track : NodeKeys {
  int node = -1;
};

struct Clip {
  AnimationInfo info;
  std::vector<Track> tracks;  // at most one per node
};

// The rate a clip was keyed at. The median spacing of the distinct key times (ticks)
// gives ticks_per_second / spacing frames per second, snapped to a whole number (within
// 0.1%) or an NTSC rate (within 0.01%); the tick length is then adjusted so that keys
// fall exactly on frames (BVH frame times such as 0.0083333 s read as 120 fps). With
// fewer than two distinct times, or keys sparser than 10 per second (hand-set poses),
// the rate is `fallback_fps` (BuildClips: the most common rate of the file's other
// clips, else the tick rate when it is a plausible frame rate, else 30).
struct SourceRate {
  double fps = 0;
  double seconds_per_tick = 0;
};
SourceRate DeriveSourceRate(std::vector<double> key_ticks, double ticks_per_second,
                            double fallback_fps);

// T = floor(duration * fps + 1e-6) + 1.
int FrameCount(double duration_seconds, double fps);

// Converts the scene's animations into clips. A channel binds to the node of its name
// (preferring nodes flagged in `preferred_nodes`, see NodeNames). Unnamed animations
// with one channel and the same duration (COLLADA2GLTF writes one glTF animation per
// joint) merge into one clip. Clip names are made unique. Errors: InvalidArgument for
// a zero-length rotation key or a clip longer than a day (corrupted key times).
StatusOr<std::vector<Clip>> BuildClips(const Scene& scene, const std::vector<char>& preferred_nodes,
                                       std::vector<std::string>& warnings);

// Evaluates the world matrices of `joint_nodes` (scene node indices) under a clip.
// Holds scratch memory: one per thread.
class PoseSampler {
 public:
  PoseSampler(const std::vector<SceneNode>& nodes, const std::vector<int>& joint_nodes);
  // clip == nullptr: the rest pose. `joint_world` receives one matrix per joint node.
  void Evaluate(const Clip* clip, double seconds, core::Affine34d* joint_world);

 private:
  const std::vector<SceneNode>& nodes_;
  std::vector<int> joint_nodes_;
  std::vector<int> needed_;  // joint nodes and their ancestors, ascending (preorder)
  std::vector<core::Affine34d> world_;
  std::vector<int> track_of_node_;
  // Per track of the bound clip, the key spans last used (position, rotation, scale):
  // where Interpolate looks first.
  std::vector<std::array<size_t, 3>> key_cursors_;
  const Clip* bound_clip_ = nullptr;
};

// A sampled clip and the index in motion.joint_world of its first matrix that
// core::FirstNonInvertibleAffine rejects (joint_world.size() where there is none).
struct SampledClip {
  core::Motion motion;
  size_t first_non_invertible = 0;
};

// Samples `clip` at `fps` (> 0) into a Motion over `joint_nodes`, in pieces of
// contiguous frames on `run` (base/pieces.h), or in one on the calling thread when `run` is
// empty (each frame is sampled on its own: the result is the same). Each range of frames
// checks its matrices as it samples them, while they are in this core's cache (a serial
// check after the pieces was a tenth of a short clip's sampling on two threads).
SampledClip SampleClip(const Clip& clip, const std::vector<SceneNode>& nodes,
                       const std::vector<int>& joint_nodes, double fps, const PieceRunner& run);

}  // namespace motionlod::io
