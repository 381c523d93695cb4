#include "core/internal/level_errors.h"

#include <algorithm>
#include <cmath>
#include <numeric>

#include "core/internal/max_vertex_error.h"
#include "core/internal/simd_dispatch.h"
#include "core/internal/trace_forms.h"

namespace motionlod::core::internal {
namespace {

// Frame t's quadratic figures: the vertex parts summed over the active joint pairs, lane by
// lane (AddTraceForms), and the joint parts over the kept joints whose Delta can be
// nonzero (none of a baseline's).
void FrameQuadraticErrors(const PreparedData& d, const Eigen::Matrix<double, Eigen::Dynamic, 3>& frame,
                          const std::vector<size_t>& active_pairs,
                          const std::vector<int>& moving_kept, int t, LevelErrors& out) {
  Lanes4 p = {}, n = {};
  for (size_t q : active_pairs) AddPairTerms(d, frame, q, p, n);
  out.ep_vertex[t] = std::max(0.0, LaneSum(p));
  out.en_vertex[t] = std::max(0.0, LaneSum(n));
  Lanes4 joint_p = {}, joint_n = {};
  for (int j : moving_kept) {
    const double* block = frame.data() + 4 * j;
    AddTraceForms(block, block, frame.rows(), d.joint_cp[j], d.joint_cn[j], joint_p, joint_n);
  }
  out.ep_joint[t] = LaneSum(joint_p);
  out.en_joint[t] = LaneSum(joint_n);
  out.e[t] = d.alpha * (out.ep_vertex[t] + out.ep_joint[t]) +
             d.beta * (out.en_vertex[t] + out.en_joint[t]);
}

}  // namespace

std::vector<size_t> ActivePairs(const PreparedData& d, const DeltaView& delta) {
  std::vector<size_t> active;
  active.reserve(d.pairs.size());
  for (size_t q = 0; q < d.pairs.size(); ++q) {
    if (delta.Moves(d.pairs[q].first) && delta.Moves(d.pairs[q].second)) active.push_back(q);
  }
  return active;
}

void EvaluateErrors(const PreparedData& d, const DeltaView& delta, const std::vector<int>& kept,
                    Figures figures, LevelErrors& out, double decide_within,
                    const PieceRunner& run) {
  const bool quadratic = figures != Figures::kMaxVertexError;
  const bool maximum = figures != Figures::kQuadratic;
  const bool sampled = figures == Figures::kAll;
  const int n = d.n, frames = d.frames;
  // Only the joints whose Delta can be nonzero are read (all of an optimised level's, the
  // removed ones of a baseline); the others' blocks of a frame stay zero.
  std::vector<uint8_t> moving(n, 0);
  std::vector<int> moving_joints;
  moving_joints.reserve(n);
  for (int k = 0; k < n; ++k) {
    moving[k] = delta.Moves(k);
    if (moving[k]) moving_joints.push_back(k);
  }
  if (quadratic) {
    out.e.assign(frames, 0.0);
    out.ep_vertex.assign(frames, 0.0);
    out.ep_joint.assign(frames, 0.0);
    out.en_vertex.assign(frames, 0.0);
    out.en_joint.assign(frames, 0.0);
  }
  // The full skeleton (or a baseline that removes nothing): every figure is exactly 0.
  if (moving_joints.empty()) return;

  const auto quadratic_figures = [&] {
    RunWithSimd(d.simd, [&] {
      std::vector<int> moving_kept;
      moving_kept.reserve(kept.size());
      for (int j : kept) {
        if (moving[j]) moving_kept.push_back(j);
      }
      const std::vector<size_t> active_pairs = ActivePairs(d, delta);
      const ErrorSample& sample = d.sample;
      SampleSums sums;
      size_t next_sample = 0;
      SampleScratch scratch(sampled ? n : 0, sampled ? sample.vertices.size() : 0);
      SampleValues values(sampled ? sample.vertices.size() : 0);
      Eigen::Matrix<double, Eigen::Dynamic, 3> frame(4 * n, 3);
      frame.setZero();
      for (int t = 0; t < frames; ++t) {
        delta.Frame(t, moving_joints, frame);
        FrameQuadraticErrors(d, frame, active_pairs, moving_kept, t, out);
        if (sampled && next_sample < sample.frames.size() && sample.frames[next_sample] == t) {
          SampleFrameValues(sample, frame, next_sample++, nullptr, d.simd, scratch, values);
          AddSampleSums(sample, values, sums);
        }
      }
      FinishErrors(d, sampled ? &sums : nullptr, out);
    });
  };
  const auto maximum_figures = [&] {
    MaxSearchBounds bounds = MakeMaxSearchBounds(d, nullptr, moving);
    for (int t = 0; t < frames; ++t) FrameBounds(d, delta, t, bounds);
    MaxVertexError(d, delta, bounds, decide_within, MaxSearchStart{}, nullptr, out);
  };
  if (quadratic && maximum) {
    RunPieces(run, 2, [&](int piece) { piece == 0 ? maximum_figures() : quadratic_figures(); });
  } else if (quadratic) {
    quadratic_figures();
  } else {
    maximum_figures();
  }
}

LevelErrors WorstOverClips(std::vector<LevelErrors> per_clip, std::span<const MotionClip> clips) {
  LevelErrors out;
  for (size_t c = 0; c < per_clip.size(); ++c) {
    const LevelErrors& clip = per_clip[c];
    const int first = clips[c].first_frame;
    for (auto [all, part] : {std::pair{&out.e, &clip.e}, std::pair{&out.ep_vertex, &clip.ep_vertex},
                             std::pair{&out.ep_joint, &clip.ep_joint},
                             std::pair{&out.en_vertex, &clip.en_vertex},
                             std::pair{&out.en_joint, &clip.en_joint}}) {
      all->insert(all->end(), part->begin(), part->end());
    }
    if (c == 0 || clip.max_e > out.max_e) {
      out.max_e = clip.max_e;
      out.max_e_frame = first + clip.max_e_frame;
    }
    if (c == 0 || clip.max_vertex_error_pct > out.max_vertex_error_pct) {
      out.max_vertex_error_pct = clip.max_vertex_error_pct;
      out.max_vertex_frame = first + clip.max_vertex_frame;
      out.max_vertex_index = clip.max_vertex_index;
    }
    out.mean_e = std::max(out.mean_e, clip.mean_e);
    out.rms_vertex_error_pct = std::max(out.rms_vertex_error_pct, clip.rms_vertex_error_pct);
    out.mean_vertex_error_pct = std::max(out.mean_vertex_error_pct, clip.mean_vertex_error_pct);
    out.mean_normal_error_deg = std::max(out.mean_normal_error_deg, clip.mean_normal_error_deg);
    out.bone_length_drift_pct = std::max(out.bone_length_drift_pct, clip.bone_length_drift_pct);
    out.joint_rotation_drift_deg = std::max(out.joint_rotation_drift_deg, clip.joint_rotation_drift_deg);
  }
  out.per_clip = std::move(per_clip);
  return out;
}

void FinishErrors(const PreparedData& d, const SampleSums* sums, LevelErrors& out) {
  const int frames = d.frames;
  const double height = d.character->height();
  out.mean_e = std::accumulate(out.e.begin(), out.e.end(), 0.0) / frames;
  const auto max_it = std::max_element(out.e.begin(), out.e.end());
  out.max_e = *max_it;
  out.max_e_frame = static_cast<int>(max_it - out.e.begin());
  const double mean_sq = std::accumulate(out.ep_vertex.begin(), out.ep_vertex.end(), 0.0) / frames;
  out.rms_vertex_error_pct = 100.0 * std::sqrt(mean_sq) / height;
  if (sums == nullptr) return;
  // Ratio estimates: the sample's mean scaled by how far its mean square is from the
  // exact one over every vertex and frame (the quadratic forms). A strided sample that
  // over- or under-represents where a level's error sits (a hand, a face) gets the scale
  // right from the exact figure and keeps only the shape (mean over RMS) from the
  // sample; plain sample means were off by up to 2x on real levels.
  const double weight = d.sample.area * static_cast<double>(d.sample.frames.size());
  const auto ratio_estimate = [&](double sum, double sum_squared, const std::vector<double>& exact) {
    const double exact_mean_squared = std::accumulate(exact.begin(), exact.end(), 0.0) / frames;
    const double mean = sum / weight;
    return sum_squared > 0 ? mean * std::sqrt(exact_mean_squared / (sum_squared / weight)) : mean;
  };
  out.mean_vertex_error_pct =
      100.0 * ratio_estimate(sums->distance, sums->distance_squared, out.ep_vertex) / height;
  out.mean_normal_error_deg =
      ratio_estimate(sums->angle, sums->normal_squared, out.en_vertex) * 180.0 / M_PI;
}

}  // namespace motionlod::core::internal
