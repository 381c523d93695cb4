// The influence cap (core/influence_cap.h has the equations): the weight step from frame
// sums of matrix products, the matrix step from moments of the capped weights.
#include "core/influence_cap.h"

#include <Eigen/Cholesky>
#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <numeric>
#include <string>

#include "core/internal/influence_cap.h"

namespace motionlod::core {
namespace internal {

std::vector<std::vector<int>> KeptChildren(const ReducedSkeleton& level) {
  std::vector<std::vector<int>> children(static_cast<size_t>(level.kept_count()));
  for (int s = 1; s < level.kept_count(); ++s) children[level.parent_slots[s]].push_back(s);
  return children;
}

int CandidateSlots(const Character& character, const ReducedSkeleton& level,
                   std::span<const std::vector<int>> kept_children, int vertex,
                   std::span<int, kMaxCandidates> out) {
  const RawSkin& skin = character.skin();
  // The merged influences, largest first.
  std::array<std::pair<float, int>, kMaxCandidates> merged{};
  int merged_count = 0;
  for (uint32_t e = skin.influence_offsets[vertex]; e < skin.influence_offsets[vertex + 1]; ++e) {
    const int slot = level.joint_to_slot[skin.influence_joints[e]];
    const float weight = skin.influence_weights[e];
    int f = 0;
    while (f < merged_count && merged[f].second != slot) ++f;
    if (f < merged_count) {
      merged[f].first += weight;
    } else if (merged_count < kMaxCandidates) {
      merged[merged_count++] = {weight, slot};
    }
  }
  // Insertion sort: a handful of entries.
  for (int f = 1; f < merged_count; ++f) {
    for (int g = f; g > 0 && (merged[g].first > merged[g - 1].first ||
                              (merged[g].first == merged[g - 1].first &&
                               merged[g].second < merged[g - 1].second));
         --g) {
      std::swap(merged[g], merged[g - 1]);
    }
  }
  int count = 0;
  auto add = [&](int slot) {
    if (slot < 0 || count == kMaxCandidates) return;
    for (int c = 0; c < count; ++c) {
      if (out[c] == slot) return;
    }
    out[count++] = slot;
  };
  for (int f = 0; f < merged_count; ++f) add(merged[f].second);
  for (int f = 0; f < merged_count; ++f) add(level.parent_slots[merged[f].second]);
  for (int f = 0; f < merged_count; ++f) {
    for (int child : kept_children[merged[f].second]) add(child);
  }
  return count;
}

double SolveCappedSimplex(std::span<const double> g, std::span<const double> r, int c, int cap,
                          std::span<double> w) {
  // On a support S = {a_0 .. a_{q-1}}, w_{a_last} = 1 - sum of the others: an unconstrained
  // problem in q - 1 unknowns u, H u = h with H = Z^T G Z, h = Z^T (r - G e_last).
  double best = std::numeric_limits<double>::infinity();
  int best_mask = 0;
  std::array<double, kMaxCandidates> best_w{};
  double trace = 0;
  for (int a = 0; a < c; ++a) trace += g[a * c + a];
  const double ridge = 1e-12 * (trace / std::max(c, 1) + 1e-300);
  for (int mask = 1; mask < (1 << c); ++mask) {
    const int q = std::popcount(static_cast<unsigned>(mask));
    if (q > cap) continue;
    std::array<int, kMaxCandidates> support{};
    for (int a = 0, k = 0; a < c; ++a) {
      if (mask & (1 << a)) support[k++] = a;
    }
    const int last = support[q - 1];
    std::array<double, kMaxCandidates> x{};
    x[q - 1] = 1;
    if (q > 1) {
      const int u = q - 1;
      double h_matrix[kMaxCandidates][kMaxCandidates];
      double h_vector[kMaxCandidates];
      for (int a = 0; a < u; ++a) {
        const int sa = support[a];
        for (int b = 0; b <= a; ++b) {
          const int sb = support[b];
          h_matrix[a][b] =
              g[sa * c + sb] - g[sa * c + last] - g[last * c + sb] + g[last * c + last];
        }
        h_matrix[a][a] += ridge;
        h_vector[a] = r[sa] - r[last] - g[sa * c + last] + g[last * c + last];
      }
      // Cholesky of H (lower), in place.
      bool positive = true;
      for (int a = 0; a < u && positive; ++a) {
        for (int b = 0; b <= a; ++b) {
          double sum = h_matrix[a][b];
          for (int k = 0; k < b; ++k) sum -= h_matrix[a][k] * h_matrix[b][k];
          if (a == b) {
            if (!(sum > 0)) {
              positive = false;
              break;
            }
            h_matrix[a][a] = std::sqrt(sum);
          } else {
            h_matrix[a][b] = sum / h_matrix[b][b];
          }
        }
      }
      if (!positive) continue;
      for (int a = 0; a < u; ++a) {
        double sum = h_vector[a];
        for (int k = 0; k < a; ++k) sum -= h_matrix[a][k] * x[k];
        x[a] = sum / h_matrix[a][a];
      }
      for (int a = u - 1; a >= 0; --a) {
        double sum = x[a];
        for (int k = a + 1; k < u; ++k) sum -= h_matrix[k][a] * x[k];
        x[a] = sum / h_matrix[a][a];
      }
      double rest = 1;
      for (int a = 0; a < u; ++a) rest -= x[a];
      x[u] = rest;
    }
    bool feasible = true;
    for (int a = 0; a < q; ++a) feasible = feasible && x[a] >= 0;
    if (!feasible) continue;
    double objective = 0;
    for (int a = 0; a < q; ++a) {
      const int sa = support[a];
      double row = 0;
      for (int b = 0; b < q; ++b) row += g[sa * c + support[b]] * x[b];
      objective += x[a] * (row - 2 * r[sa]);
    }
    // A larger support must do measurably better to win (ties keep fewer influences).
    if (best_mask == 0 || objective < best - 1e-12 * std::abs(best)) {
      best = objective;
      best_mask = mask;
      best_w = x;
    }
  }
  std::fill(w.begin(), w.begin() + c, 0.0);
  for (int a = 0, k = 0; a < c; ++a) {
    if (best_mask & (1 << a)) w[a] = best_w[k++];
  }
  return best;
}

void WriteInfluenceRow(std::span<const int> slots, std::span<const double> weights, int vertex,
                       LevelInfluences& out) {
  const int k = out.per_vertex;
  std::array<int, kMaxCandidates> order{};
  const int c = static_cast<int>(slots.size());
  auto before = [&](int a, int b) {
    return weights[a] > weights[b] || (weights[a] == weights[b] && slots[a] < slots[b]);
  };
  for (int f = 0; f < c; ++f) {
    order[f] = f;
    for (int g = f; g > 0 && before(order[g], order[g - 1]); --g) std::swap(order[g], order[g - 1]);
  }
  double sum = 0;
  for (int e = 0; e < std::min(k, c); ++e) sum += std::max(weights[order[e]], 0.0);
  const size_t row = static_cast<size_t>(vertex) * k;
  for (int e = 0; e < k; ++e) {
    const bool used = e < c && weights[order[e]] > 0 && sum > 0;
    out.slots[row + e] = static_cast<uint16_t>(used ? slots[order[e]] : slots[order[0]]);
    out.weights[row + e] = used ? static_cast<float>(weights[order[e]] / sum) : 0.0f;
  }
}

}  // namespace internal

namespace {

// [v0; 1] and [n0; 0] of vertex i.
Eigen::Vector4d PointOf(const RawSkin& skin, int i) {
  return {skin.positions[i].x(), skin.positions[i].y(), skin.positions[i].z(), 1.0};
}
Eigen::Vector4d DirectionOf(const RawSkin& skin, int i) {
  return {skin.normals[i].x(), skin.normals[i].y(), skin.normals[i].z(), 0.0};
}

// The level's matrices stacked like PreparedMotion::original_matrices: 4m x 3T, block
// (4s, 3t) = K'_s(t)^T.
Eigen::MatrixXd StackTransposed(std::span<const RowMajorAffine34f> matrices, int m, int frames) {
  Eigen::MatrixXd stacked(4 * m, 3 * frames);
  for (int t = 0; t < frames; ++t) {
    for (int s = 0; s < m; ++s) {
      stacked.block<4, 3>(4 * s, 3 * t) =
          matrices[static_cast<size_t>(t) * m + s].cast<double>().transpose();
    }
  }
  return stacked;
}

Status CheckLevelMatrices(const char* job, const PreparedMotion* prepared,
                          const ReducedSkeleton* level,
                          std::span<const RowMajorAffine34f> matrices) {
  if (prepared == nullptr || level == nullptr) {
    return InvalidArgument(std::string(job) + ": no prepared motion or level");
  }
  const int n = prepared->character().joint_count();
  if (static_cast<int>(level->joint_to_slot.size()) != n || level->kept_count() < 1) {
    return InvalidArgument(std::string(job) + ": the level is of another skeleton");
  }
  const size_t expected = static_cast<size_t>(prepared->frame_count()) * level->kept_count();
  if (matrices.size() != expected) {
    return InvalidArgument(
        std::string(job) + ": " + std::to_string(matrices.size()) +
        " matrices, expected frames x kept joints = " + std::to_string(expected));
  }
  for (size_t e = 0; e < matrices.size(); ++e) {
    if (!matrices[e].allFinite()) {
      return InvalidArgument(std::string(job) + ": matrix " + std::to_string(e) + " is not finite");
    }
  }
  return Status::Ok();
}

Status CheckInfluences(const char* job, const LevelInfluences& influences, int vertices, int m) {
  const int k = influences.per_vertex;
  if (k < 1 || k > kMaxInfluencesPerVertex ||
      influences.slots.size() != static_cast<size_t>(vertices) * k ||
      influences.weights.size() != influences.slots.size()) {
    return InvalidArgument(std::string(job) + ": the influences are not " +
                           std::to_string(vertices) + " vertices of 1 to " +
                           std::to_string(kMaxInfluencesPerVertex));
  }
  for (size_t e = 0; e < influences.slots.size(); ++e) {
    if (influences.slots[e] >= m || !(influences.weights[e] >= 0) ||
        !std::isfinite(influences.weights[e])) {
      return InvalidArgument(std::string(job) + ": influence " + std::to_string(e) +
                             " has a slot out of range or a negative weight");
    }
  }
  return Status::Ok();
}

}  // namespace

double LevelInfluences::mean_used() const {
  if (weights.empty()) return 0;
  const auto used = std::count_if(weights.begin(), weights.end(), [](float w) { return w > 0; });
  return static_cast<double>(used) / vertex_count();
}

StatusOr<LevelInfluences> TruncateInfluences(const Character& character,
                                             const ReducedSkeleton& level, int cap) {
  if (cap < 1 || cap > kMaxInfluencesPerVertex) {
    return InvalidArgument("TruncateInfluences: the cap must be 1 to " +
                           std::to_string(kMaxInfluencesPerVertex));
  }
  const ReducedInfluences merged = ReduceInfluences(character.skin(), level);
  LevelInfluences out;
  out.per_vertex = cap;
  const int p = character.vertex_count();
  out.slots.resize(static_cast<size_t>(p) * cap);
  out.weights.resize(out.slots.size());
  std::vector<int> slots;
  std::vector<double> weights;
  for (int i = 0; i < p; ++i) {
    slots.assign(merged.slots.begin() + merged.offsets[i],
                 merged.slots.begin() + merged.offsets[i + 1]);
    weights.assign(merged.weights.begin() + merged.offsets[i],
                   merged.weights.begin() + merged.offsets[i + 1]);
    internal::WriteInfluenceRow(slots, weights, i, out);
  }
  return out;
}

Status InfluenceCapJob::Validate() const {
  if (Status status = CheckLevelMatrices("InfluenceCapJob", prepared, level, matrices);
      !status.ok()) {
    return status;
  }
  if (cap < 1 || cap > kMaxInfluencesPerVertex) {
    return InvalidArgument("InfluenceCapJob: the cap must be 1 to " +
                           std::to_string(kMaxInfluencesPerVertex));
  }
  if (!(normal_weight >= 0) || !std::isfinite(normal_weight)) {
    return InvalidArgument("InfluenceCapJob: the normal weight must be finite and >= 0");
  }
  return Status::Ok();
}

StatusOr<LevelInfluences> InfluenceCapJob::Run() const {
  if (Status status = Validate(); !status.ok()) return status;
  const Character& character = prepared->character();
  const RawSkin& skin = character.skin();
  const int m = level->kept_count(), frames = prepared->frame_count(), p = character.vertex_count();
  // Every frame sum at once: P = Kp Kp^T (4m x 4m), Q = Kp K^T (4m x 4n).
  const Eigen::MatrixXd kp = StackTransposed(matrices, m, frames);
  const Eigen::MatrixXd p_sums = kp * kp.transpose();
  const Eigen::MatrixXd q_sums = kp * prepared->original_matrices().transpose();
  const std::vector<std::vector<int>> children = internal::KeptChildren(*level);

  LevelInfluences out;
  out.per_vertex = cap;
  out.slots.resize(static_cast<size_t>(p) * cap);
  out.weights.resize(out.slots.size());
  std::array<int, kMaxCandidates> candidates{};
  std::array<double, kMaxCandidates * kMaxCandidates> g{};
  std::array<double, kMaxCandidates> r{}, w{};
  for (int i = 0; i < p; ++i) {
    const int c = internal::CandidateSlots(character, *level, children, i, candidates);
    const Eigen::Vector4d v = PointOf(skin, i), nv = DirectionOf(skin, i);
    auto form = [&](const Eigen::MatrixXd& sums, int row, int col) {
      const auto block = sums.block<4, 4>(4 * row, 4 * col);
      return v.dot(block * v) + normal_weight * nv.dot(block * nv);
    };
    for (int a = 0; a < c; ++a) {
      for (int b = 0; b <= a; ++b)
        g[a * c + b] = g[b * c + a] = form(p_sums, candidates[a], candidates[b]);
      double sum = 0;
      for (uint32_t e = skin.influence_offsets[i]; e < skin.influence_offsets[i + 1]; ++e) {
        sum += skin.influence_weights[e] * form(q_sums, candidates[a], skin.influence_joints[e]);
      }
      r[a] = sum;
    }
    internal::SolveCappedSimplex(std::span(g).first(c * c), std::span(r).first(c), c, cap, w);
    internal::WriteInfluenceRow(std::span(candidates).first(c), std::span(w).first(c), i, out);
  }
  return out;
}

Status InfluenceMatrixJob::Validate() const {
  if (Status status = CheckLevelMatrices("InfluenceMatrixJob", prepared, level, matrices);
      !status.ok()) {
    return status;
  }
  if (influences == nullptr) return InvalidArgument("InfluenceMatrixJob: no influences");
  if (Status status = CheckInfluences("InfluenceMatrixJob", *influences,
                                      prepared->character().vertex_count(), level->kept_count());
      !status.ok()) {
    return status;
  }
  if (!(normal_weight >= 0) || !std::isfinite(normal_weight) || !(regularization > 0) ||
      !std::isfinite(regularization)) {
    return InvalidArgument(
        "InfluenceMatrixJob: the normal weight must be >= 0 and the regularisation > 0");
  }
  return Status::Ok();
}

StatusOr<std::vector<RowMajorAffine34f>> InfluenceMatrixJob::Run() const {
  if (Status status = Validate(); !status.ok()) return status;
  const Character& character = prepared->character();
  const RawSkin& skin = character.skin();
  const int m = level->kept_count(), n = character.joint_count(), frames = prepared->frame_count();
  const int p = character.vertex_count(), k = influences->per_vertex;
  const std::vector<double>& areas = character.vertex_areas();
  const double total_area = std::accumulate(areas.begin(), areas.end(), 0.0);
  // G = sum_i a_i (W_i x vbar)(W_i x vbar)^T and C = sum_i a_i (W_i x vbar)(w_i x vbar)^T,
  // normals alike, accumulated block by block.
  Eigen::MatrixXd g = Eigen::MatrixXd::Zero(4 * m, 4 * m);
  Eigen::MatrixXd c = Eigen::MatrixXd::Zero(4 * m, 4 * n);
  for (int i = 0; i < p; ++i) {
    const double a = areas[i] / total_area;
    const Eigen::Vector4d v = PointOf(skin, i), nv = DirectionOf(skin, i);
    const Eigen::Matrix4d moment = a * (v * v.transpose() + normal_weight * nv * nv.transpose());
    for (int e = 0; e < k; ++e) {
      const float we = influences->weights[static_cast<size_t>(i) * k + e];
      if (we == 0) continue;
      const int s = influences->slots[static_cast<size_t>(i) * k + e];
      for (int f = 0; f < k; ++f) {
        const float wf = influences->weights[static_cast<size_t>(i) * k + f];
        if (wf != 0)
          g.block<4, 4>(4 * s, 4 * influences->slots[static_cast<size_t>(i) * k + f]) +=
              (we * wf) * moment;
      }
      for (uint32_t o = skin.influence_offsets[i]; o < skin.influence_offsets[i + 1]; ++o) {
        c.block<4, 4>(4 * s, 4 * skin.influence_joints[o]) +=
            (we * skin.influence_weights[o]) * moment;
      }
    }
  }
  // Tikhonov towards the given matrices, so that a kept joint no vertex follows keeps them.
  const double lambda = regularization * std::max(g.trace() / (4 * m), 1e-300);
  Eigen::MatrixXd rhs =
      c * prepared->original_matrices() + lambda * StackTransposed(matrices, m, frames);
  g.diagonal().array() += lambda;
  const Eigen::LLT<Eigen::MatrixXd> factor(g);
  if (factor.info() != Eigen::Success) {
    return InvalidArgument("InfluenceMatrixJob: the normal equations are not positive definite");
  }
  factor.solveInPlace(rhs);
  std::vector<RowMajorAffine34f> out(static_cast<size_t>(frames) * m);
  for (int t = 0; t < frames; ++t) {
    for (int s = 0; s < m; ++s) {
      out[static_cast<size_t>(t) * m + s] = rhs.block<4, 3>(4 * s, 3 * t).transpose().cast<float>();
    }
  }
  return out;
}

StatusOr<std::vector<double>> InfluenceObjective(const PreparedMotion& prepared,
                                                 const ReducedSkeleton& level,
                                                 std::span<const RowMajorAffine34f> matrices,
                                                 const LevelInfluences& influences,
                                                 double normal_weight) {
  if (Status status = CheckLevelMatrices("InfluenceObjective", &prepared, &level, matrices);
      !status.ok()) {
    return status;
  }
  const Character& character = prepared.character();
  const int p = character.vertex_count(), m = level.kept_count(), frames = prepared.frame_count();
  if (Status status = CheckInfluences("InfluenceObjective", influences, p, m); !status.ok())
    return status;
  const RawSkin& skin = character.skin();
  const Eigen::MatrixXd& kt = prepared.original_matrices();
  const int k = influences.per_vertex;
  std::vector<double> objective(static_cast<size_t>(p), 0.0);
  for (int t = 0; t < frames; ++t) {
    for (int i = 0; i < p; ++i) {
      const Eigen::Vector4d v = PointOf(skin, i), nv = DirectionOf(skin, i);
      Eigen::Vector3d original_v = Eigen::Vector3d::Zero(), original_n = Eigen::Vector3d::Zero();
      for (uint32_t e = skin.influence_offsets[i]; e < skin.influence_offsets[i + 1]; ++e) {
        const auto kj = kt.block<4, 3>(4 * skin.influence_joints[e], 3 * t);
        original_v += skin.influence_weights[e] * (kj.transpose() * v);
        original_n += skin.influence_weights[e] * (kj.transpose() * nv);
      }
      Eigen::Vector3d level_v = Eigen::Vector3d::Zero(), level_n = Eigen::Vector3d::Zero();
      for (int e = 0; e < k; ++e) {
        const size_t entry = static_cast<size_t>(i) * k + e;
        const Eigen::Matrix<double, 3, 4> ks =
            matrices[static_cast<size_t>(t) * m + influences.slots[entry]].cast<double>();
        level_v += influences.weights[entry] * (ks * v);
        level_n += influences.weights[entry] * (ks * nv);
      }
      objective[i] += (level_v - original_v).squaredNorm() +
                      normal_weight * (level_n - original_n).squaredNorm();
    }
  }
  return objective;
}

}  // namespace motionlod::core
