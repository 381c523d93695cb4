#include "core/solve_levels.h"

#include <cmath>
#include <limits>
#include <string>

#include "base/hash.h"
#include "core/internal/lanes.h"
#include "core/internal/level_errors.h"
#include "core/internal/level_solve.h"
#include "core/internal/normal_equations.h"
#include "core/internal/rigid_projection.h"
#include "core/internal/skeleton_drift.h"

namespace motionlod::core {

using Eigen::MatrixXd;

const char* VariantName(Variant variant) {
  switch (variant) {
    case Variant::kVP: return "vp";
    case Variant::kVPNO: return "vpno";
    case Variant::kVPPD: return "vp+pd";
    case Variant::kVPNOPD: return "vpno+pd";
  }
  return "?";
}

StatusOr<Variant> ParseVariant(std::string_view name) {
  for (Variant v : {Variant::kVP, Variant::kVPNO, Variant::kVPPD, Variant::kVPNOPD}) {
    if (name == VariantName(v)) return v;
  }
  return InvalidArgument("unknown variant '" + std::string(name) +
                         "'; expected vp, vpno, vp+pd or vpno+pd");
}

Status SolveSettings::Validate() const {
  if (!(joint_weight >= 0) || !std::isfinite(joint_weight)) {
    return InvalidArgument("joint_weight must be finite and >= 0");
  }
  if (!(regularization > 0) || !(regularization <= 1e-2)) {
    return InvalidArgument("regularization must be in (0, 0.01]");
  }
  if (sample_frames < 1 || sample_vertices < 1) {
    return InvalidArgument("sample_frames and sample_vertices must be positive");
  }
  return Status::Ok();
}

uint64_t SolveSettings::Hash() const {
  uint64_t h = Fnv1a64Value(kAlgorithmVersion, kFnv1a64Offset);
  h = Fnv1a64Value(static_cast<int>(variant), h);
  h = Fnv1a64Value(resolve_rigid_translation, h);
  h = Fnv1a64Value(joint_weight, h);
  h = Fnv1a64Value(regularization, h);
  h = Fnv1a64Value(sample_frames, h);
  return Fnv1a64Value(sample_vertices, h);
}

const char* LevelSourceName(LevelSource source) {
  switch (source) {
    case LevelSource::kSolved: return "solved";
    case LevelSource::kReparented: return "reparented";
    case LevelSource::kCoarserLevel: return "coarser level";
  }
  return "?";
}

namespace internal {

Status ValidateLevel(const ReducedSkeleton& level, int n) {
  const int m = level.kept_count();
  if (static_cast<int>(level.joint_to_slot.size()) != n || m < 1 || m > n ||
      level.kept_joints[0] != 0) {
    return InvalidArgument("SolveLevel: the reduced skeleton does not belong to this character");
  }
  for (int k = 0; k < n; ++k) {
    if (level.joint_to_slot[k] < 0 || level.joint_to_slot[k] >= m) {
      return InvalidArgument("SolveLevel: joint " + std::to_string(k) + " maps to no kept joint");
    }
  }
  for (int s = 0; s < m; ++s) {
    const int j = level.kept_joints[s];
    if (j < 0 || j >= n || level.joint_to_slot[j] != s) {
      return InvalidArgument("SolveLevel: kept joint " + std::to_string(s) + " is inconsistent");
    }
  }
  return Status::Ok();
}

DeltaView BaselineDelta(const PreparedData& d, const ReducedSkeleton& level) {
  DeltaView baseline{&d.kt, std::vector<int>(d.n), &d.kt};
  for (int k = 0; k < d.n; ++k) {
    baseline.solution_row[k] = 4 * level.kept_joints[level.joint_to_slot[k]];
  }
  return baseline;
}

DeltaView VariantSolution::Delta(const PreparedData& d, const ReducedSkeleton& level) const {
  DeltaView view{unchanged ? &d.kt : &x, std::vector<int>(d.n), &d.kt};
  for (int k = 0; k < d.n; ++k) view.solution_row[k] = unchanged ? 4 * k : 4 * level.joint_to_slot[k];
  return view;
}

StatusOr<VariantSolution> SolveVariant(const PreparedData& d, const ReducedSkeleton& level) {
  if (Status status = ValidateLevel(level, d.n); !status.ok()) return status;
  const int n = d.n;
  const int m = level.kept_count();
  // With every joint kept, the original matrices are the least-squares solution
  // (SolveNormalEquations), and original matrices that are rotations already (to within their
  // source's float precision) are the constrained minimiser too (no residual): they are
  // the level as they are, without the system (the right-hand sides alone are 3T x 4n),
  // and the rigid variants keep them bit for bit, as the fitted ones do, instead of
  // projecting them by a few 1e-6, re-solving them and measuring an error of 1e-13.
  if (m == n && (!IsRigid(d.settings.variant) || AllRotations(d.kt, d.simd))) {
    return VariantSolution{MatrixXd(), true};
  }
  auto system = SolveNormalEquations(d, level);
  if (!system.ok()) return system.status();
  if (IsRigid(d.settings.variant)) {
    if (Status status = ProjectOnRotations(d, level, *system); !status.ok()) return status;
  }
  return VariantSolution{std::move(system->x), false};
}

}  // namespace internal

namespace {

// Every figure of candidate matrices S for `level` on one clip's part of the prepared
// motion (core/internal/prepared_data.h). S is the level's own matrices `x` (4m x 3T,
// block (4s, 3t) = K'_s(t)^T, read at solution_row[k] = 4 phi(k)), or the original
// matrices where `x` is null (read at solution_row[k]; kept joints keep their own, so the
// skeleton does not drift).
LevelErrors PartFigures(const internal::PreparedData& part, const ReducedSkeleton& level,
                        const MatrixXd* x, const std::vector<int>& solution_row,
                        const PieceRunner& run) {
  LevelErrors errors;
  internal::EvaluateErrors(part, internal::DeltaView{x ? x : &part.kt, solution_row, &part.kt},
                           level.kept_joints, internal::Figures::kAll, errors,
                           std::numeric_limits<double>::infinity(), run);
  if (x != nullptr) internal::EvaluateSkeletonDrift(part, level, *x, errors);
  return errors;
}

// PartFigures clip by clip (`x` over every frame), combined as the worst clip's.
LevelErrors ClipFigures(const internal::PreparedData& d, const ReducedSkeleton& level,
                        const MatrixXd* x, const std::vector<int>& solution_row,
                        const PieceRunner& run) {
  const auto evaluate = [&](const internal::PreparedData& part, const MatrixXd* part_x) {
    return PartFigures(part, level, part_x, solution_row, run);
  };
  std::vector<LevelErrors> per_clip;
  if (d.clip_parts.empty()) {
    per_clip.push_back(evaluate(d, x));
  } else {
    for (size_t c = 0; c < d.clips.size(); ++c) {
      const MotionClip& clip = d.clips[c];
      MatrixXd part_x;
      if (x != nullptr) part_x = x->middleCols(3 * clip.first_frame, 3 * clip.frame_count);
      per_clip.push_back(evaluate(d.clip_parts[c]->data(), x != nullptr ? &part_x : nullptr));
    }
  }
  return internal::WorstOverClips(std::move(per_clip), d.clips);
}

// The rows of x (4 per matrix, 3T columns) as the level's T x m float matrices.
void StoreMatrices(const MatrixXd& x, int m, int frames, RowMajorAffine34f* out) {
  // Row r of K'_s(t) is column 3t + r of x from row 4s: four contiguous doubles, converted
  // as one vector into the row-major matrix's row. (The pointers and the stride are local:
  // a store through a vector type that may alias anything would reload them after every
  // row.)
  static_assert(sizeof(RowMajorAffine34f) == 12 * sizeof(float));
  float* target = out->data();
  const double* columns = x.data();
  const Eigen::Index stride = x.rows();
  for (int t = 0; t < frames; ++t) {
    for (int s = 0; s < m; ++s) {
      for (int r = 0; r < 3; ++r) {
        *AsLanes4f(target + 4 * r) =
            __builtin_convertvector(*AsLanes4(columns + (3 * t + r) * stride + 4 * s), Lanes4f);
      }
      target += 12;
    }
  }
}

}  // namespace

namespace internal {

bool ReparentingIsCandidate(const PreparedData& d) {
  // Original matrices with scale or shear are no candidate of a rigid level.
  return !IsRigid(d.settings.variant) || d.original_rotations;
}

bool NoWorseThan(const LevelErrors& candidate, const LevelErrors& reparented) {
  return candidate.max_vertex_error_pct <= reparented.max_vertex_error_pct &&
         candidate.mean_vertex_error_pct <= reparented.mean_vertex_error_pct;
}

}  // namespace internal

std::span<const MotionClip> PreparedMotion::clips() const { return data_->clips; }

StatusOr<LevelResult> PreparedMotion::SolveLevel(const ReducedSkeleton& level) const {
  auto result = SolveOptimized(level);
  if (!result.ok()) return result.status();
  auto baseline = BaselineErrors(level);
  if (!baseline.ok()) return baseline.status();
  result->baseline = *std::move(baseline);
  KeepNoWorseThanReparenting(*result);
  return result;
}

StatusOr<LevelResult> PreparedMotion::SolveOptimized(const ReducedSkeleton& level,
                                                     const PieceRunner& run) const {
  const internal::PreparedData& d = *data_;
  auto solution = internal::SolveVariant(d, level);
  if (!solution.ok()) return solution.status();
  const int m = level.kept_count();
  LevelResult result;
  result.skeleton = level;
  result.matrices.resize(static_cast<size_t>(d.frames) * m);
  StoreMatrices(solution->Matrices(d), m, d.frames, result.matrices.data());
  const internal::DeltaView delta = solution->Delta(d, level);
  result.optimized = ClipFigures(d, level, solution->unchanged ? nullptr : &solution->x,
                                 delta.solution_row, run);
  result.sources.assign(d.clips.size(), LevelSource::kSolved);
  return result;
}

StatusOr<LevelErrors> PreparedMotion::BaselineErrors(const ReducedSkeleton& level,
                                                     const PieceRunner& run) const {
  const internal::PreparedData& d = *data_;
  if (Status status = internal::ValidateLevel(level, d.n); !status.ok()) return status;
  return ClipFigures(d, level, nullptr, internal::BaselineDelta(d, level).solution_row, run);
}

void PreparedMotion::KeepNoWorseThanReparenting(LevelResult& result) const {
  const internal::PreparedData& d = *data_;
  if (!internal::ReparentingIsCandidate(d)) return;
  const int m = result.skeleton.kept_count();
  bool replaced = false;
  for (size_t c = 0; c < d.clips.size(); ++c) {
    if (internal::NoWorseThan(result.optimized.per_clip[c], result.baseline.per_clip[c])) continue;
    const MotionClip& clip = d.clips[c];
    for (int t = clip.first_frame; t < clip.first_frame + clip.frame_count; ++t) {
      for (int s = 0; s < m; ++s) {
        const int j = result.skeleton.kept_joints[s];
        result.matrices[static_cast<size_t>(t) * m + s] =
            d.kt.block<4, 3>(4 * j, 3 * t).transpose().cast<float>();
      }
    }
    result.optimized.per_clip[c] = result.baseline.per_clip[c];
    result.sources[c] = LevelSource::kReparented;
    replaced = true;
  }
  if (replaced) result.optimized = internal::WorstOverClips(std::move(result.optimized.per_clip), d.clips);
}

Status PreparedMotion::LiftCoarserLevel(const LevelResult& coarser, LevelResult& finer) const {
  const internal::PreparedData& d = *data_;
  const ReducedSkeleton& from = coarser.skeleton;
  const ReducedSkeleton& to = finer.skeleton;
  if (Status status = internal::ValidateLevel(from, d.n); !status.ok()) return status;
  if (Status status = internal::ValidateLevel(to, d.n); !status.ok()) return status;
  for (int j : from.kept_joints) {
    if (to.kept_joints[to.joint_to_slot[j]] != j) {
      return InvalidArgument("LiftCoarserLevel: the finer level removes joint '" +
                             d.character->skeleton().joint_names[j] + "', which the coarser keeps");
    }
  }
  const int m_from = from.kept_count(), m_to = to.kept_count();
  bool lifted = false;
  for (size_t c = 0; c < d.clips.size(); ++c) {
    if (finer.optimized.per_clip[c].max_vertex_error_pct <=
        coarser.optimized.per_clip[c].max_vertex_error_pct) {
      continue;
    }
    const MotionClip& clip = d.clips[c];
    const internal::PreparedData& part = d.clip_parts.empty() ? d : d.clip_parts[c]->data();
    // Each kept joint of the finer level takes the coarser level's matrix of its nearest
    // joint kept there, as the rows of a solution (4m x 3T of the clip).
    MatrixXd x(4 * m_to, 3 * clip.frame_count);
    for (int t = 0; t < clip.frame_count; ++t) {
      for (int s = 0; s < m_to; ++s) {
        x.block<4, 3>(4 * s, 3 * t) =
            coarser.matrices[static_cast<size_t>(clip.first_frame + t) * m_from +
                             from.joint_to_slot[to.kept_joints[s]]]
                .cast<double>()
                .transpose();
      }
    }
    std::vector<int> solution_row(d.n);
    for (int k = 0; k < d.n; ++k) solution_row[k] = 4 * to.joint_to_slot[k];
    LevelErrors figures = PartFigures(part, to, &x, solution_row, {});
    // Rigid levels keep their bones: a joint that rides on a coarser joint's matrix may
    // not stretch them.
    if (!internal::NoWorseThan(figures, finer.baseline.per_clip[c]) ||
        figures.max_vertex_error_pct >= finer.optimized.per_clip[c].max_vertex_error_pct ||
        (IsRigid(d.settings.variant) &&
         figures.bone_length_drift_pct > internal::kRigidBoneLengthDriftPct)) {
      continue;
    }
    for (int t = clip.first_frame; t < clip.first_frame + clip.frame_count; ++t) {
      for (int s = 0; s < m_to; ++s) {
        finer.matrices[static_cast<size_t>(t) * m_to + s] =
            coarser.matrices[static_cast<size_t>(t) * m_from + from.joint_to_slot[to.kept_joints[s]]];
      }
    }
    finer.optimized.per_clip[c] = std::move(figures);
    finer.sources[c] = LevelSource::kCoarserLevel;
    lifted = true;
  }
  if (lifted) finer.optimized = internal::WorstOverClips(std::move(finer.optimized.per_clip), d.clips);
  return Status::Ok();
}

StatusOr<Eigen::MatrixXd> PreparedMotion::SolveLeastSquares(const ReducedSkeleton& level) const {
  auto system = internal::SolveNormalEquations(*data_, level);
  if (!system.ok()) return system.status();
  return std::move(system->x);
}

}  // namespace motionlod::core
