#include "core/rank_joints.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

#include <Eigen/Core>

#include "core/internal/lanes.h"
#include "core/internal/simd_dispatch.h"
#include "core/internal/chord_angle.h"

namespace motionlod::core {
namespace {

// Rows of LocalTransforms' output: the rotation's unit quaternion, then the translation.
enum LocalRow { kW, kX, kY, kZ, kTx, kTy, kTz, kLocalRows };

// A joint's local transforms L(t) = M_parent(t)^-1 M(t) (M(t) alone for the root), frame
// by frame, into kLocalRows rows of `frames` (`rows`): their rotations as unit quaternions
// and their translations. The rotation is that of the 3x3 part with its columns normalised
// (local matrices may carry scale), converted as Eigen's Quaternion(Matrix3) converts it
// (Shepperd's method: from w where the trace is positive, else from the largest diagonal
// entry's axis), with selects instead of branches so that the frames' loop vectorises.
// world[t * stride] is M(t), parent[t * stride] M_parent(t); both are invertible
// (ValidateMotion). The matrices are first transposed into rows of `frames` in `scratch`
// (24 rows), the root's parent as the identity (whose adjugate, determinant and translation
// leave M as it is, exactly): read in place, a frame's matrices lie n matrices apart, and
// the loop ran one frame at a time.
void LocalTransforms(const Affine34d* world, const Affine34d* parent, size_t stride, int frames,
                     double* __restrict scratch, double* __restrict rows) {
  double* const m_rows = scratch;
  double* const p_rows = scratch + 12 * frames;
  // Three transposes of 4 rows each: one of 12 rows makes GCC 12 warn, wrongly, that its
  // loop over the rows past the last whole 4 overflows.
  const auto to_rows = [&](const Affine34d* matrices, double* out) {
    for (int block = 0; block < 3; ++block) {
      TransposeDoubles(matrices->data() + 4 * block, static_cast<long>(12 * stride), 4, frames,
                       out + 4 * block * frames, frames);
    }
  };
  to_rows(world, m_rows);
  if (parent != nullptr) {
    to_rows(parent, p_rows);
  } else {
    for (int e = 0; e < 12; ++e) {
      std::fill_n(p_rows + e * frames, frames, e % 4 == 0 && e < 9 ? 1.0 : 0.0);
    }
  }
  // Every row is `frames` long: no frame's writes reach another frame's reads or writes.
#pragma GCC ivdep
  for (int t = 0; t < frames; ++t) {
    // Column-major: m[3c + r] = M(r, c).
    const auto m = [&](int e) { return m_rows[e * frames + t]; };
    const auto p = [&](int e) { return p_rows[e * frames + t]; };
    double l[12];
    // M_parent^-1 = adj(P) / det(P), P its 3x3 part.
    const double c00 = p(4) * p(8) - p(7) * p(5), c01 = p(6) * p(5) - p(3) * p(8);
    const double c02 = p(3) * p(7) - p(6) * p(4), c10 = p(7) * p(2) - p(1) * p(8);
    const double c11 = p(0) * p(8) - p(6) * p(2), c12 = p(6) * p(1) - p(0) * p(7);
    const double c20 = p(1) * p(5) - p(4) * p(2), c21 = p(3) * p(2) - p(0) * p(5);
    const double c22 = p(0) * p(4) - p(3) * p(1);
    const double inverse_det = 1 / (p(0) * c00 + p(3) * c10 + p(6) * c20);
    for (int c = 0; c < 4; ++c) {
      // Column c of M, or for the translation M's minus the parent's.
      const double b0 = c < 3 ? m(3 * c) : m(9) - p(9);
      const double b1 = c < 3 ? m(3 * c + 1) : m(10) - p(10);
      const double b2 = c < 3 ? m(3 * c + 2) : m(11) - p(11);
      l[3 * c] = (c00 * b0 + c01 * b1 + c02 * b2) * inverse_det;
      l[3 * c + 1] = (c10 * b0 + c11 * b1 + c12 * b2) * inverse_det;
      l[3 * c + 2] = (c20 * b0 + c21 * b1 + c22 * b2) * inverse_det;
    }
    for (int c = 0; c < 3; ++c) {
      const double length = std::sqrt(l[3 * c] * l[3 * c] + l[3 * c + 1] * l[3 * c + 1] +
                                      l[3 * c + 2] * l[3 * c + 2]);
      const double inverse_length = length > 0 ? 1 / length : 1.0;
      for (int r = 0; r < 3; ++r) l[3 * c + r] *= inverse_length;
    }
    const double r00 = l[0], r10 = l[1], r20 = l[2], r01 = l[3], r11 = l[4], r21 = l[5];
    const double r02 = l[6], r12 = l[7], r22 = l[8];
    const bool from_w = r00 + r11 + r22 > 0;
    const bool from_y = !from_w && r11 > r00 && !(r22 > r11);
    const bool from_z = !from_w && r22 > std::max(r00, r11);
    const bool from_x = !from_w && !from_y && !from_z;
    const double d = from_w   ? r00 + r11 + r22 + 1
                     : from_x ? r00 - r11 - r22 + 1
                     : from_y ? r11 - r22 - r00 + 1
                              : r22 - r00 - r11 + 1;
    const double root = std::sqrt(d);
    const double half = 0.5 * root, f = 0.5 / root;
    const double a = (r21 - r12) * f, b = (r02 - r20) * f, c = (r10 - r01) * f;
    const double xy = (r10 + r01) * f, xz = (r20 + r02) * f, yz = (r21 + r12) * f;
    const double w = from_w ? half : from_x ? a : from_y ? b : c;
    const double x = from_w ? a : from_x ? half : from_y ? xy : xz;
    const double y = from_w ? b : from_x ? xy : from_y ? half : yz;
    const double z = from_w ? c : from_x ? xz : from_y ? yz : half;
    const double inverse_norm = 1 / std::sqrt(w * w + x * x + y * y + z * z);
    rows[kW * frames + t] = w * inverse_norm;
    rows[kX * frames + t] = x * inverse_norm;
    rows[kY * frames + t] = y * inverse_norm;
    rows[kZ * frames + t] = z * inverse_norm;
    rows[kTx * frames + t] = l[9];
    rows[kTy * frames + t] = l[10];
    rows[kTz * frames + t] = l[11];
  }
}

}  // namespace

const char* RankingMethodName(RankingMethod method) {
  return method == RankingMethod::kGreedy ? "greedy" : "paper";
}

StatusOr<RankingMethod> ParseRankingMethod(std::string_view name) {
  for (RankingMethod method : {RankingMethod::kGreedy, RankingMethod::kPaper}) {
    if (name == RankingMethodName(method)) return method;
  }
  return InvalidArgument("unknown ranking '" + std::string(name) + "'; expected greedy or paper");
}

Status RankJointsJob::Validate() const {
  if (character == nullptr || motion == nullptr) {
    return InvalidArgument("RankJointsJob needs a character and a motion");
  }
  if (Status status = ValidateMotion(*motion, *character, simd); !status.ok()) return status;
  std::string unknown;
  for (const std::string& name : locked_joints) {
    if (character->FindJoint(name) < 0) unknown += (unknown.empty() ? "'" : ", '") + name + "'";
  }
  if (!unknown.empty()) return NotFound("locked joints not in the skeleton: " + unknown);
  return Status::Ok();
}

StatusOr<JointRanking> RankJointsJob::Run(const PieceRunner& run) const {
  if (Status status = Validate(); !status.ok()) return status;
  const Character& c = *character;
  const RawSkeleton& s = c.skeleton();
  const int n = c.joint_count();
  const int frames = motion->frame_count;

  JointRanking ranking;
  ranking.hierarchical = c.subtree_lengths();
  ranking.rotational.assign(n, 0.0);
  ranking.priority.assign(n, 0.0);

  // Rotation angles are those between unit quaternions doubled, from their chords
  // (core/internal/chord_angle.h): 2 * 2 asin(|q - m| / 2), with m's sign the one nearer to q. The
  // frames' loops run in the widest vectors this CPU has, a few joints per piece.
  constexpr int kJointsPerPiece = 4;
  RunPieces(run, (n + kJointsPerPiece - 1) / kJointsPerPiece, [&](int piece) {
    RunWithSimd(simd, [&] {
      std::vector<double> local(static_cast<size_t>(kLocalRows) * frames);
      std::vector<double> scratch(24 * static_cast<size_t>(frames));
      std::vector<double> to_mean(frames), to_bind(frames), moved(frames);
      double* q[4] = {local.data() + kW * frames, local.data() + kX * frames,
                      local.data() + kY * frames, local.data() + kZ * frames};
      for (int j = piece * kJointsPerPiece; j < std::min(n, (piece + 1) * kJointsPerPiece); ++j) {
        const int parent = s.parents[j];
        double bind[kLocalRows];
        LocalTransforms(&s.bind_world[j], parent < 0 ? nullptr : &s.bind_world[parent], 0, 1,
                        scratch.data(), bind);
        LocalTransforms(&motion->joint_world[j],
                        parent < 0 ? nullptr : &motion->joint_world[parent], n, frames,
                        scratch.data(), local.data());
        // Signs aligned with the bind rotation, so that q and -q average together.
        for (int t = 0; t < frames; ++t) {
          const double dot =
              q[0][t] * bind[kW] + q[1][t] * bind[kX] + q[2][t] * bind[kY] + q[3][t] * bind[kZ];
          const double sign = dot < 0 ? -1.0 : 1.0;
          for (double* row : q) row[t] *= sign;
        }
        Eigen::Vector4d sum = Eigen::Vector4d::Zero();
        for (int t = 0; t < frames; ++t) {
          for (int a = 0; a < 4; ++a) sum[a] += q[a][t];
        }
        Eigen::Vector4d mean(bind[kW], bind[kX], bind[kY], bind[kZ]);
        if (sum.norm() > 0) mean = sum.normalized();
        for (int t = 0; t < frames; ++t) {
          const double dot =
              q[0][t] * mean[0] + q[1][t] * mean[1] + q[2][t] * mean[2] + q[3][t] * mean[3];
          const double sign = dot < 0 ? -1.0 : 1.0;
          double chord_mean = 0, chord_bind = 0;
          for (int a = 0; a < 4; ++a) {
            const double to_m = q[a][t] - sign * mean[a], to_b = q[a][t] - bind[a];
            chord_mean += to_m * to_m;
            chord_bind += to_b * to_b;
          }
          to_mean[t] = ChordAngleOrMarker(0.5 * std::sqrt(chord_mean));
          to_bind[t] = ChordAngleOrMarker(0.5 * std::sqrt(chord_bind));
          const double dx = local[kTx * frames + t] - bind[kTx];
          const double dy = local[kTy * frames + t] - bind[kTy];
          const double dz = local[kTz * frames + t] - bind[kTz];
          moved[t] = std::sqrt(dx * dx + dy * dy + dz * dz);
        }
        const double translation_scale = std::max(ranking.hierarchical[j], 0.01 * c.height());
        double variation = 0, offset = 0, translation = 0;
        for (int t = 0; t < frames; ++t) {
          variation += 2 * FinishChordAngle(to_mean[t]);
          offset += 2 * FinishChordAngle(to_bind[t]);
          translation += moved[t] / translation_scale;
        }
        ranking.rotational[j] = (variation + offset + translation) / frames;
        ranking.priority[j] = ranking.hierarchical[j] * ranking.rotational[j];
      }
    });
  });

  std::vector<int> depth(n, 0);
  for (int j = 1; j < n; ++j) depth[j] = depth[s.parents[j]] + 1;
  ranking.priority[0] = std::numeric_limits<double>::infinity();
  for (const std::string& name : locked_joints) {
    ranking.priority[c.FindJoint(name)] = std::numeric_limits<double>::infinity();
  }
  ranking.locked_count = static_cast<int>(
      std::count(ranking.priority.begin(), ranking.priority.end(),
                 std::numeric_limits<double>::infinity()));
  ranking.removal_order.resize(n);
  std::iota(ranking.removal_order.begin(), ranking.removal_order.end(), 0);
  std::stable_sort(ranking.removal_order.begin(), ranking.removal_order.end(), [&](int a, int b) {
    if (ranking.priority[a] != ranking.priority[b]) return ranking.priority[a] < ranking.priority[b];
    if (a == 0 || b == 0) return b == 0;
    if (depth[a] != depth[b]) return depth[a] > depth[b];
    return a > b;
  });
  return ranking;
}

}  // namespace motionlod::core
