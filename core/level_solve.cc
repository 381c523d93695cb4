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

StatusOr<LevelResult> PreparedMotion::SolveLevel(const ReducedSkeleton& level) const {
  auto result = SolveOptimized(level);
  if (!result.ok()) return result.status();
  auto baseline = BaselineErrors(level);
  if (!baseline.ok()) return baseline.status();
  result->baseline = *std::move(baseline);
  return result;
}

StatusOr<LevelResult> PreparedMotion::SolveOptimized(const ReducedSkeleton& level,
                                                     const PieceRunner& run) const {
  const internal::PreparedData& d = *data_;
  auto solution = internal::SolveVariant(d, level);
  if (!solution.ok()) return solution.status();
  const int m = level.kept_count();
  const MatrixXd& x = solution->Matrices(d);

  LevelResult result;
  result.skeleton = level;
  result.matrices.resize(static_cast<size_t>(d.frames) * m);
  // Row r of K'_s(t) is column 3t + r of x from row 4s: four contiguous doubles, converted
  // as one vector into the row-major matrix's row. (The pointers and the stride are local:
  // a store through a vector type that may alias anything would reload them after every
  // row.)
  static_assert(sizeof(RowMajorAffine34f) == 12 * sizeof(float));
  float* out = result.matrices.front().data();
  const double* columns = x.data();
  const Eigen::Index stride = x.rows();
  for (int t = 0; t < d.frames; ++t) {
    for (int s = 0; s < m; ++s) {
      for (int r = 0; r < 3; ++r) {
        *AsLanes4f(out + 4 * r) =
            __builtin_convertvector(*AsLanes4(columns + (3 * t + r) * stride + 4 * s), Lanes4f);
      }
      out += 12;
    }
  }
  internal::EvaluateErrors(d, solution->Delta(d, level), level.kept_joints, internal::Figures::kAll,
                           result.optimized, std::numeric_limits<double>::infinity(), run);
  internal::EvaluateSkeletonDrift(d, level, x, result.optimized);
  return result;
}

StatusOr<LevelErrors> PreparedMotion::BaselineErrors(const ReducedSkeleton& level,
                                                     const PieceRunner& run) const {
  const internal::PreparedData& d = *data_;
  if (Status status = internal::ValidateLevel(level, d.n); !status.ok()) return status;
  LevelErrors errors;
  internal::EvaluateErrors(d, internal::BaselineDelta(d, level), level.kept_joints,
                           internal::Figures::kAll, errors, std::numeric_limits<double>::infinity(),
                           run);
  return errors;
}

StatusOr<Eigen::MatrixXd> PreparedMotion::SolveLeastSquares(const ReducedSkeleton& level) const {
  auto system = internal::SolveNormalEquations(*data_, level);
  if (!system.ok()) return system.status();
  return std::move(system->x);
}

}  // namespace motionlod::core
