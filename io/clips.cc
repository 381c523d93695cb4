#include "io/clips.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <map>
#include <set>
#include <utility>

#include "io/text.h"

namespace motionlod::io {
namespace {

constexpr double kMinScale = 1e-4;
constexpr double kMinSourceFps = 10;
constexpr double kMaxDurationSeconds = 24 * 3600;  // a day

// Rate snapping: a whole number within 0.1%, else an NTSC rate within 0.01%.
double SnapRate(double fps) {
  const double whole = std::round(fps);
  if (whole >= 1 && std::abs(fps - whole) <= 1e-3 * fps) return whole;
  for (double ntsc : {24000.0 / 1001.0, 30000.0 / 1001.0, 60000.0 / 1001.0}) {
    if (std::abs(fps - ntsc) <= 1e-4 * ntsc) return ntsc;
  }
  return fps;
}

inline Eigen::Vector3d Blend(const Eigen::Vector3d& a, const Eigen::Vector3d& b, double alpha) {
  return (1 - alpha) * a + alpha * b;
}
inline Eigen::Quaterniond Blend(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b,
                                double alpha) {
  return a.slerp(alpha, b).normalized();  // Eigen's slerp takes the shorter arc
}

// Blend weights this close to 0 or 1 are a sample on a key, off only by the rounding of
// the key times (DeriveSourceRate puts the keys of a clip sampled at its own rate on the
// frames): the key itself, which the blend would give to within 1e-9 of the step between
// the keys, without slerp's acos and three sines.
constexpr double kOnKey = 1e-9;

// Key times this close to a frame of the clip's rate (a fraction of a frame) are on that
// frame: off only by how the file wrote them (float seconds in glTF, a few decimals in
// COLLADA, a rate derived from their median spacing), which put every sample of
// Fox.glb, stormtrooper.dae or CesiumMan.glb at its own rate 1e-7 to 1e-3 of a frame past
// a key, blended (slerp's acos and three sines) a step that small towards the next key.
constexpr double kOnFrame = 1e-3;

// The keyed value at time t: the first or last key outside the keys, else the two
// surrounding keys blended (lerp for vectors, slerp for rotations). `cursor` is the index
// of the key before the previous call's time: sampling walks a clip forward, a key or
// less per frame, so the next span is found from it without a search.
template <typename T>
T Interpolate(const std::vector<double>& times, const std::vector<T>& values, double t,
              size_t& cursor) {
  if (t <= times.front()) return values.front();
  if (t >= times.back()) return values.back();
  size_t lo = cursor;
  if (!(lo + 1 < times.size() && times[lo] <= t)) lo = 0;
  for (int step = 0; step < 2 && times[lo + 1] <= t; ++step) ++lo;
  if (times[lo + 1] <= t) {
    const auto after = std::upper_bound(times.begin() + lo, times.end(), t);
    lo = static_cast<size_t>(after - times.begin()) - 1;
  }
  cursor = lo;
  const double span = times[lo + 1] - times[lo];
  const double alpha = span > 0 ? (t - times[lo]) / span : 0.0;
  if (alpha <= kOnKey) return values[lo];
  if (alpha >= 1 - kOnKey) return values[lo + 1];
  return Blend(values[lo], values[lo + 1], alpha);
}

// Sorts keys by time (stable) when a file lists them out of order.
template <typename T>
void SortKeys(std::vector<double>& times, std::vector<T>& values) {
  if (std::is_sorted(times.begin(), times.end())) return;
  std::vector<size_t> order(times.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(),
                   [&](size_t a, size_t b) { return times[a] < times[b]; });
  std::vector<double> t2;
  std::vector<T> v2;
  for (size_t i : order) {
    t2.push_back(times[i]);
    v2.push_back(values[i]);
  }
  times = std::move(t2);
  values = std::move(v2);
}

struct PendingClip {
  std::string name;
  double duration_ticks = 0;
  double ticks_per_second = 0;
  std::vector<const SceneChannel*> channels;
};

}  // namespace

SourceRate DeriveSourceRate(std::vector<double> key_ticks, double ticks_per_second,
                            double fallback_fps) {
  SourceRate rate;
  std::sort(key_ticks.begin(), key_ticks.end());
  std::vector<double> gaps;
  for (size_t k = 1; k < key_ticks.size(); ++k) {
    const double gap = key_ticks[k] - key_ticks[k - 1];
    const double tolerance = 1e-9 * std::max(1.0, std::abs(key_ticks[k]));
    if (gap > tolerance) gaps.push_back(gap);
  }
  if (gaps.empty() || !(ticks_per_second > 0)) {
    rate.fps = fallback_fps;
    rate.seconds_per_tick = ticks_per_second > 0 ? 1.0 / ticks_per_second
                            : fallback_fps > 0   ? 1.0 / fallback_fps
                                                 : 0.0;
    return rate;
  }
  std::nth_element(gaps.begin(), gaps.begin() + gaps.size() / 2, gaps.end());
  const double median_gap = gaps[gaps.size() / 2];
  const double raw = ticks_per_second / median_gap;
  if (raw < kMinSourceFps) {
    // Keys this sparse are hand-set poses, not a sampled clip: no rate to recover.
    rate.fps = fallback_fps;
    rate.seconds_per_tick = 1.0 / ticks_per_second;
    return rate;
  }
  rate.fps = SnapRate(raw);
  rate.seconds_per_tick = 1.0 / (rate.fps * median_gap);
  return rate;
}

int FrameCount(double duration_seconds, double fps) {
  const double frames = std::floor(duration_seconds * fps + 1e-6) + 1;
  if (!(frames < std::numeric_limits<int>::max())) return std::numeric_limits<int>::max();
  return frames < 1 ? 1 : static_cast<int>(frames);
}

StatusOr<std::vector<Clip>> BuildClips(const Scene& scene, const std::vector<char>& preferred_nodes,
                                       std::vector<std::string>& warnings) {
  // Group the split single-channel animations (same duration and rate, no name).
  std::vector<PendingClip> pending;
  std::map<std::pair<double, double>, size_t> split_group;
  std::map<std::pair<double, double>, int> split_count;
  for (const SceneAnimation& a : scene.animations) {
    if (a.name.empty() && a.channels.size() == 1)
      ++split_count[{a.duration_ticks, a.ticks_per_second}];
  }
  for (const SceneAnimation& a : scene.animations) {
    const std::pair<double, double> key(a.duration_ticks, a.ticks_per_second);
    if (a.name.empty() && a.channels.size() == 1 && split_count[key] > 1) {
      const auto it = split_group.find(key);
      if (it != split_group.end()) {
        pending[it->second].channels.push_back(&a.channels.front());
        continue;
      }
      split_group[key] = pending.size();
    }
    PendingClip p;
    p.name = a.name;
    p.duration_ticks = a.duration_ticks;
    p.ticks_per_second = a.ticks_per_second;
    for (const SceneChannel& c : a.channels) p.channels.push_back(&c);
    pending.push_back(std::move(p));
  }
  for (const auto& [key, count] : split_count) {
    if (count > 1) {
      warnings.push_back(
          std::to_string(count) +
          " unnamed single-channel animations of equal length were merged into one clip");
    }
  }

  const NodeNames names(scene.nodes);
  std::vector<Clip> clips;
  std::vector<std::vector<double>> all_key_ticks(pending.size());
  std::vector<double> starts(pending.size()), ends(pending.size()), tps(pending.size());
  for (size_t c = 0; c < pending.size(); ++c) {
    const PendingClip& p = pending[c];
    tps[c] = p.ticks_per_second;
    if (!(tps[c] > 0)) {
      // The formats' documented defaults: DirectX AnimTicksPerSecond 4800, else Assimp's 25.
      tps[c] = scene.format == Format::kDirectX ? 4800.0 : 25.0;
      warnings.push_back("animation " + Quote(p.name) + " gives no tick rate; assumed " +
                         std::to_string(static_cast<int>(tps[c])) + " ticks per second");
    }
    double first = std::numeric_limits<double>::infinity(), last = -first;
    for (const SceneChannel* ch : p.channels) {
      for (const std::vector<double>* times :
           {&ch->position_times, &ch->rotation_times, &ch->scaling_times}) {
        for (double t : *times) {
          first = std::min(first, t);
          last = std::max(last, t);
          all_key_ticks[c].push_back(t);
        }
      }
    }
    if (all_key_ticks[c].empty()) first = last = 0;
    starts[c] = std::min(0.0, first);
    ends[c] = std::max({p.duration_ticks, last, starts[c]});
  }

  // Rates: clips with a single pose borrow the most common rate of the others.
  std::vector<SourceRate> rates(pending.size());
  std::map<double, int> rate_votes;
  for (size_t c = 0; c < pending.size(); ++c) {
    rates[c] = DeriveSourceRate(all_key_ticks[c], tps[c], 0.0);
    if (rates[c].fps > 0) ++rate_votes[rates[c].fps];
  }
  double common = 0;
  int votes = 0;
  for (const auto& [fps, n] : rate_votes) {
    if (n > votes) {
      common = fps;
      votes = n;
    }
  }
  for (size_t c = 0; c < pending.size(); ++c) {
    if (rates[c].fps > 0) continue;
    double fallback = common;
    if (!(fallback > 0)) fallback = (tps[c] >= 1 && tps[c] <= 480) ? SnapRate(tps[c]) : 30.0;
    rates[c].fps = fallback;
    rates[c].seconds_per_tick = 1.0 / tps[c];
  }

  std::set<std::string> used_names;
  for (size_t c = 0; c < pending.size(); ++c) {
    const PendingClip& p = pending[c];
    Clip clip;
    const double spt = rates[c].seconds_per_tick;
    const double start = starts[c];
    std::string base = p.name.empty() ? "animation" : p.name;
    std::string name = base;
    for (int k = 1; used_names.count(name) != 0; ++k) name = base + "_" + std::to_string(k);
    if (!p.name.empty() && name != p.name) {
      warnings.push_back("two animations are named '" + p.name + "'; the later one is '" + name +
                         "'");
    }
    used_names.insert(name);
    clip.info.name = name;
    clip.info.source_fps = rates[c].fps;
    double duration = (ends[c] - start) * spt;
    const double frames = duration * rates[c].fps;
    if (std::abs(frames - std::round(frames)) < 1e-2) duration = std::round(frames) / rates[c].fps;
    if (!(duration <= kMaxDurationSeconds)) {
      return InvalidArgument("animation " + Quote(name) + " lasts " + std::to_string(duration) +
                             " s, more than " + std::to_string(kMaxDurationSeconds) +
                             " s (corrupted key times?)");
    }
    clip.info.duration_seconds = duration;
    clip.info.source_frame_count = FrameCount(duration, rates[c].fps);

    std::map<int, size_t> track_of_node;
    int clamped_nodes = 0;
    for (const SceneChannel* ch : p.channels) {
      const int node = names.Find(ch->node_name, &preferred_nodes);
      if (node < 0) {
        warnings.push_back("animation '" + name + "' animates '" + ch->node_name +
                           "', which is not a node of the file; ignored");
        continue;
      }
      Track track;
      track.node = node;
      const double fps = rates[c].fps;
      auto to_seconds = [&](const std::vector<double>& ticks) {
        std::vector<double> s(ticks.size());
        for (size_t k = 0; k < ticks.size(); ++k) {
          s[k] = (ticks[k] - start) * spt;
          // As SampleClip computes a frame's time, so that a sample on the frame is the key.
          const double frame = std::round(s[k] * fps);
          if (std::abs(s[k] * fps - frame) <= kOnFrame) s[k] = frame / fps;
        }
        return s;
      };
      track.position_times = to_seconds(ch->position_times);
      track.positions = ch->positions;
      track.rotation_times = to_seconds(ch->rotation_times);
      track.rotations = ch->rotations;
      track.scaling_times = to_seconds(ch->scaling_times);
      track.scalings = ch->scalings;
      for (Eigen::Quaterniond& q : track.rotations) {
        const double norm = q.norm();
        if (!(norm > 1e-12) || !std::isfinite(norm)) {
          return InvalidArgument("animation '" + name + "' has a zero-length rotation key for '" +
                                 ch->node_name + "'");
        }
        q.coeffs() /= norm;
      }
      // A scale key of exactly zero (a "spawn" clip growing from nothing) would make the
      // joint matrix singular; 1e-4 looks the same and stays invertible (in float too, for
      // chains of a few such joints).
      bool clamped = false;
      for (Eigen::Vector3d& scale : track.scalings) {
        for (int a = 0; a < 3; ++a) {
          if (std::abs(scale[a]) < kMinScale) {
            scale[a] = scale[a] < 0 ? -kMinScale : kMinScale;
            clamped = true;
          }
        }
      }
      clamped_nodes += clamped;
      SortKeys(track.position_times, track.positions);
      SortKeys(track.rotation_times, track.rotations);
      SortKeys(track.scaling_times, track.scalings);
      const auto existing = track_of_node.find(node);
      if (existing != track_of_node.end()) {
        warnings.push_back("animation '" + name + "' has two channels for '" + ch->node_name +
                           "'; the later one is used");
        clip.tracks[existing->second] = std::move(track);
      } else {
        track_of_node[node] = clip.tracks.size();
        clip.tracks.push_back(std::move(track));
      }
    }
    if (clamped_nodes > 0) {
      warnings.push_back("animation '" + name + "' scales " + std::to_string(clamped_nodes) +
                         " nodes to (nearly) zero; such scales were raised to 1e-4");
    }
    clips.push_back(std::move(clip));
  }
  return clips;
}

PoseSampler::PoseSampler(const std::vector<SceneNode>& nodes, const std::vector<int>& joint_nodes)
    : nodes_(nodes),
      joint_nodes_(joint_nodes),
      world_(nodes.size()),
      track_of_node_(nodes.size(), -1) {
  std::vector<char> needed(nodes.size(), 0);
  for (int j : joint_nodes) {
    for (int k = j; k >= 0 && !needed[k]; k = nodes[k].parent) needed[k] = 1;
  }
  for (size_t k = 0; k < nodes.size(); ++k) {
    if (needed[k]) needed_.push_back(static_cast<int>(k));
  }
}

void PoseSampler::Evaluate(const Clip* clip, double seconds, core::Affine34d* joint_world) {
  if (clip != bound_clip_) {
    std::fill(track_of_node_.begin(), track_of_node_.end(), -1);
    if (clip != nullptr) {
      for (size_t t = 0; t < clip->tracks.size(); ++t)
        track_of_node_[clip->tracks[t].node] = static_cast<int>(t);
      key_cursors_.assign(clip->tracks.size(), {0, 0, 0});
    }
    bound_clip_ = clip;
  }
  for (int k : needed_) {
    const SceneNode& node = nodes_[k];
    core::Affine34d local;
    const int t = track_of_node_[k];
    if (t < 0) {
      local = node.local;
    } else {
      const Track& track = clip->tracks[t];
      std::array<size_t, 3>& cursor = key_cursors_[t];
      const Eigen::Vector3d translation =
          track.positions.empty()
              ? node.translation
              : Interpolate(track.position_times, track.positions, seconds, cursor[0]);
      const Eigen::Quaterniond rotation =
          track.rotations.empty()
              ? node.rotation
              : Interpolate(track.rotation_times, track.rotations, seconds, cursor[1]);
      const Eigen::Vector3d scale =
          track.scalings.empty()
              ? node.scale
              : Interpolate(track.scaling_times, track.scalings, seconds, cursor[2]);
      local = ComposeTrs(translation, rotation, scale);
    }
    world_[k] = node.parent >= 0 ? core::ComposeAffine(world_[node.parent], local) : local;
  }
  for (size_t j = 0; j < joint_nodes_.size(); ++j) joint_world[j] = world_[joint_nodes_[j]];
}

SampledClip SampleClip(const Clip& clip, const std::vector<SceneNode>& nodes,
                       const std::vector<int>& joint_nodes, double fps, const PieceRunner& run) {
  SampledClip sampled;
  core::Motion& motion = sampled.motion;
  motion.name = clip.info.name;
  motion.fps = fps;
  motion.frame_count = FrameCount(clip.info.duration_seconds, fps);
  motion.joint_count = static_cast<int>(joint_nodes.size());
  motion.joint_world.resize(static_cast<size_t>(motion.frame_count) * joint_nodes.size());
  // Contiguous frame ranges, one sampler each. With a runner, short ranges: a thread that
  // comes late (from the character's build, beside this in a bake) still takes a share,
  // and a range's own setup (its sampler, its key cursors) is a small part of its frames.
  constexpr int kFramesPerRange = 16;
  const int ranges =
      run ? std::max(1, (motion.frame_count + kFramesPerRange - 1) / kFramesPerRange) : 1;
  // Per range, the index in joint_world of its first rejected matrix, or joint_world.size().
  std::vector<size_t> first_bad(ranges);
  const auto sample_range = [&](int w) {
    PoseSampler sampler(nodes, joint_nodes);
    const int begin = static_cast<int>(static_cast<int64_t>(motion.frame_count) * w / ranges);
    const int end = static_cast<int>(static_cast<int64_t>(motion.frame_count) * (w + 1) / ranges);
    for (int t = begin; t < end; ++t) {
      const double seconds = std::min(t / fps, clip.info.duration_seconds);
      sampler.Evaluate(&clip, seconds,
                       &motion.joint_world[static_cast<size_t>(t) * joint_nodes.size()]);
    }
    const std::span<const core::Affine34d> range(
        motion.joint_world.data() + static_cast<size_t>(begin) * joint_nodes.size(),
        static_cast<size_t>(end - begin) * joint_nodes.size());
    const size_t bad = core::FirstNonInvertibleAffine(range);
    first_bad[w] = bad < range.size() ? static_cast<size_t>(begin) * joint_nodes.size() + bad
                                      : motion.joint_world.size();
  };
  RunPieces(run, ranges, sample_range);
  sampled.first_non_invertible = *std::min_element(first_bad.begin(), first_bad.end());
  return sampled;
}

}  // namespace motionlod::io
