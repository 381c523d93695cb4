#include "core/baseline_sequence.h"

#include <algorithm>
#include <tuple>
#include <vector>

#include "core/internal/error_sample.h"
#include "core/internal/level_errors.h"
#include "core/internal/max_vertex_error.h"
#include "core/internal/prepared_data.h"
#include "core/internal/simd_dispatch.h"
#include "core/internal/skin_clusters.h"
#include "core/internal/trace_forms.h"

namespace motionlod::core {

namespace {

// One clip's sequence, on its part of the prepared motion.
struct ClipSequence {
  const internal::PreparedData* d = nullptr;
  std::vector<int> solution_row;  // n: its baseline's DeltaView::solution_row
  // Every joint pair's PairTerms in every frame (T rows of |pairs|), for its Delta.
  std::vector<double> pair_p, pair_n;
  // Every sampled frame's SampleValues.
  std::vector<internal::SampleValues> sample_values;
  internal::MaxSearchStart maximum = {};  // its exact maximum
  LevelErrors last = {};
};

ClipSequence StartSequence(const internal::PreparedData& d) {
  ClipSequence st;
  st.d = &d;
  // Before the first level: the full skeleton, whose Delta is zero.
  st.solution_row.resize(d.n);
  for (int k = 0; k < d.n; ++k) st.solution_row[k] = 4 * k;
  st.pair_p.assign(static_cast<size_t>(d.frames) * d.pairs.size(), 0.0);
  st.pair_n.assign(static_cast<size_t>(d.frames) * d.pairs.size(), 0.0);
  // The sample's values with a zero Delta: zero. (EvaluateErrors measures angles of a few
  // 1e-17 rad where a normal is compared with itself, the same to rounding; computing them
  // here cost each sequence 90 k instructions.)
  st.sample_values.assign(d.sample.frames.size(), internal::SampleValues(d.sample.vertices.size()));
  for (std::vector<double>* part : {&st.last.e, &st.last.ep_vertex, &st.last.ep_joint, &st.last.en_vertex,
                                    &st.last.en_joint}) {
    part->assign(d.frames, 0.0);
  }
  return st;
}

// The next level's baseline figures on the clip's part (a validated level that keeps a
// subset of the last one's joints).
LevelErrors NextOf(ClipSequence& st, const ReducedSkeleton& level) {
  const internal::PreparedData& d = *st.d;
  const Character& c = *d.character;
  const int n = d.n;
  const internal::DeltaView delta = internal::BaselineDelta(d, level);
  // The joints whose Delta changes: those whose nearest kept joint does.
  std::vector<uint8_t> changed(n, 0);
  bool any_changed = false;
  for (int k = 0; k < n; ++k) {
    changed[k] = delta.solution_row[k] != st.solution_row[k];
    any_changed = any_changed || changed[k];
  }
  st.solution_row = delta.solution_row;
  if (!any_changed) return st.last;

  const auto weighted_by_changed = [&](const auto* begin, const auto* end) {
    return std::any_of(begin, end,
                       [&](const auto& influence) { return changed[influence.joint] != 0; });
  };
  std::vector<size_t> changed_pairs;
  for (size_t q = 0; q < d.pairs.size(); ++q) {
    if (changed[d.pairs[q].first] || changed[d.pairs[q].second]) changed_pairs.push_back(q);
  }
  const std::vector<size_t> active_pairs = internal::ActivePairs(d, delta);
  const internal::SkinClusters& clusters_of = c.clusters();
  std::vector<uint8_t> group_mask(n, 0);
  for (int j = 0; j < n; ++j) {
    group_mask[j] = weighted_by_changed(
        clusters_of.group_influences.data() + clusters_of.group_influence_offsets[j],
        clusters_of.group_influences.data() + clusters_of.group_influence_offsets[j + 1]);
  }
  const size_t clusters = clusters_of.cluster_centers.size();
  std::vector<uint8_t> cluster_mask(clusters, 0);
  for (size_t cluster = 0; cluster < clusters; ++cluster) {
    cluster_mask[cluster] = weighted_by_changed(
        clusters_of.cluster_influences.data() + clusters_of.cluster_influence_offsets[cluster],
        clusters_of.cluster_influences.data() + clusters_of.cluster_influence_offsets[cluster + 1]);
  }
  std::vector<uint32_t> changed_samples;
  for (size_t v = 0; v < d.sample.vertices.size(); ++v) {
    const uint32_t begin = d.sample.influence_begin(v);
    if (weighted_by_changed(d.sample.influences.data() + begin,
                            d.sample.influences.data() + d.sample.vertices[v].influence_end)) {
      changed_samples.push_back(static_cast<uint32_t>(v));
    }
  }
  // The vertices that no changed joint weights keep their errors, all at most the last
  // maximum: a search of the others from it finds the new one, unless the vertex that
  // attained it has changed (then every cluster is searched again). With no maximum yet
  // (none above the negligible), the unchanged vertices are all negligible.
  const RawSkin& skin = c.skin();
  const int last_vertex = st.maximum.vertex;
  bool restart = false;
  for (uint32_t g = skin.influence_offsets[last_vertex];
       st.maximum.best_squared > 0 && g < skin.influence_offsets[last_vertex + 1]; ++g) {
    restart = restart || changed[skin.influence_joints[g]];
  }

  LevelErrors out;
  out.e.assign(d.frames, 0.0);
  out.ep_vertex.assign(d.frames, 0.0);
  out.ep_joint.assign(d.frames, 0.0);  // kept joints keep their matrices: no joint error
  out.en_vertex.assign(d.frames, 0.0);
  out.en_joint.assign(d.frames, 0.0);
  std::vector<uint8_t> moving(n, 0);
  for (int k = 0; k < n; ++k) moving[k] = delta.Moves(k);
  internal::MaxSearchBounds bounds =
      internal::MakeMaxSearchBounds(d, restart ? nullptr : &group_mask, moving);
  internal::SampleScratch scratch(n, changed_samples.size());
  size_t next_sample = 0;
  const size_t pair_count = d.pairs.size();
  // Only the joints whose Delta the frame's copy serves: the changed pairs' and the
  // changed sampled vertices' (the bounds read theirs from the matrices).
  std::vector<uint8_t> read(n, 0);
  for (size_t q : changed_pairs) read[d.pairs[q].first] = read[d.pairs[q].second] = 1;
  for (uint32_t v : changed_samples) {
    for (uint32_t g = d.sample.influence_begin(v); g < d.sample.vertices[v].influence_end; ++g) {
      read[d.sample.influences[g].joint] = 1;
    }
  }
  std::vector<int> read_joints;
  for (int k = 0; k < n; ++k) {
    if (read[k]) read_joints.push_back(k);
  }
  Eigen::Matrix<double, Eigen::Dynamic, 3> frame =
      Eigen::Matrix<double, Eigen::Dynamic, 3>::Zero(4 * n, 3);
  for (int t = 0; t < d.frames; ++t) {
    delta.Frame(t, read_joints, frame);
    double* pair_p = st.pair_p.data() + static_cast<size_t>(t) * pair_count;
    double* pair_n = st.pair_n.data() + static_cast<size_t>(t) * pair_count;
    for (size_t q : changed_pairs)
      std::tie(pair_p[q], pair_n[q]) = internal::PairTerms(d, frame, q);
    // Summed in four lanes, as EvaluateErrors sums the joint pairs' terms (the same to
    // rounding): one chain of dependent additions would wait on its own latency. Four
    // terms per vector: a lane written on its own goes through memory.
    Lanes4 ep = {}, en = {};
    const size_t* active = active_pairs.data();
    const size_t whole = active_pairs.size() / 4 * 4;
    for (size_t e = 0; e < whole; e += 4) {
      ep += Lanes4{pair_p[active[e]], pair_p[active[e + 1]], pair_p[active[e + 2]],
                   pair_p[active[e + 3]]};
      en += Lanes4{pair_n[active[e]], pair_n[active[e + 1]], pair_n[active[e + 2]],
                   pair_n[active[e + 3]]};
    }
    Lanes4 ep_tail = {}, en_tail = {};
    for (size_t e = whole; e < active_pairs.size(); ++e) {
      ep_tail[e - whole] = pair_p[active[e]];
      en_tail[e - whole] = pair_n[active[e]];
    }
    ep += ep_tail;
    en += en_tail;
    out.ep_vertex[t] = std::max(0.0, internal::LaneSum(ep));
    out.en_vertex[t] = std::max(0.0, internal::LaneSum(en));
    out.e[t] = d.alpha * (out.ep_vertex[t] + out.ep_joint[t]) +
               d.beta * (out.en_vertex[t] + out.en_joint[t]);
    internal::FrameBounds(d, delta, t, bounds);
    if (next_sample < d.sample.frames.size() && d.sample.frames[next_sample] == t) {
      if (!changed_samples.empty()) {
        internal::SampleFrameValues(d.sample, frame, next_sample, &changed_samples, d.simd, scratch,
                                    st.sample_values[next_sample]);
      }
      ++next_sample;
    }
  }
  st.maximum = internal::MaxVertexError(d, delta, bounds, std::numeric_limits<double>::infinity(),
                                        restart ? internal::MaxSearchStart{} : st.maximum,
                                        restart ? nullptr : &cluster_mask, out);
  internal::SampleSums sums;
  for (const internal::SampleValues& values : st.sample_values)
    internal::AddSampleSums(d.sample, values, sums);
  internal::FinishErrors(d, &sums, out);
  st.last = out;
  return out;
}

}  // namespace

struct BaselineSequence::State {
  std::shared_ptr<const PreparedMotion> prepared;
  std::vector<ClipSequence> clips;
  std::vector<uint8_t> kept;  // n: the joints the last level kept
};

BaselineSequence::BaselineSequence(std::shared_ptr<const PreparedMotion> prepared)
    : state_(std::make_unique<State>()) {
  State& st = *state_;
  const internal::PreparedData& d = prepared->data();
  st.prepared = std::move(prepared);
  st.kept.assign(d.n, 1);
  if (d.clip_parts.empty()) {
    st.clips.push_back(StartSequence(d));
  } else {
    for (const auto& part : d.clip_parts) st.clips.push_back(StartSequence(part->data()));
  }
}

BaselineSequence::~BaselineSequence() = default;

StatusOr<LevelErrors> BaselineSequence::Next(const ReducedSkeleton& level) {
  State& st = *state_;
  const internal::PreparedData& d = st.prepared->data();
  if (Status status = internal::ValidateLevel(level, d.n); !status.ok()) return status;
  std::vector<uint8_t> kept(d.n, 0);
  for (int j : level.kept_joints) {
    if (!st.kept[j]) {
      return InvalidArgument("BaselineSequence: the level keeps joint '" +
                             d.character->skeleton().joint_names[j] +
                             "', which the level before it removed");
    }
    kept[j] = 1;
  }
  st.kept = std::move(kept);
  return RunWithSimd(d.simd, [&] {
    std::vector<LevelErrors> per_clip;
    for (ClipSequence& clip : st.clips) per_clip.push_back(NextOf(clip, level));
    return internal::WorstOverClips(std::move(per_clip), d.clips);
  });
}

}  // namespace motionlod::core
