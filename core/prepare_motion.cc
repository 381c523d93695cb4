// PreparedMotion::Create: what every level of one (character, motion, settings) shares,
// computed once (core/solve_levels.h): Kt, the joint pairs' moments, the normalisation
// alpha and beta, F^T = (Q Kt)^T for the right-hand sides, and the error sample.
#include <algorithm>
#include <numeric>
#include <string>

#include "core/internal/block_cholesky.h"
#include "core/internal/lanes.h"
#include "core/internal/level_errors.h"
#include "core/internal/rigid_projection.h"
#include "core/internal/prepared_data.h"
#include "core/internal/simd_dispatch.h"
#include "core/solve_levels.h"

namespace motionlod::core {

using Eigen::MatrixXd;

PreparedMotion::PreparedMotion(std::unique_ptr<const internal::PreparedData> data)
    : data_(std::move(data)) {}
PreparedMotion::~PreparedMotion() = default;
const Character& PreparedMotion::character() const { return *data_->character; }
const SolveSettings& PreparedMotion::settings() const { return data_->settings; }
int PreparedMotion::frame_count() const { return data_->frames; }
double PreparedMotion::alpha() const { return data_->alpha; }
double PreparedMotion::beta() const { return data_->beta; }
const MatrixXd& PreparedMotion::original_matrices() const { return data_->kt; }

StatusOr<std::shared_ptr<const PreparedMotion>> PreparedMotion::Create(
    std::shared_ptr<const Character> character, const Motion& motion, const SolveSettings& settings,
    SimdChoice simd, const PieceRunner& run) {
  if (!character) return InvalidArgument("PreparedMotion: no character");
  if (Status status = settings.Validate(); !status.ok()) return status;
  if (Status status = ValidateMotion(motion, *character, simd); !status.ok()) return status;

  auto data = std::make_unique<internal::PreparedData>();
  internal::PreparedData& d = *data;
  const Character& c = *character;
  const int n = c.joint_count();
  const int frames = motion.frame_count;
  d.character = character;
  d.settings = settings;
  d.simd = simd;
  d.n = n;
  d.frames = frames;

  // Kt: each skinning matrix K_k(t) = M_k(t) B_k^-1 (B_k the bind pose) written straight
  // into its block, row r of K as lanes: sum_i M(r, i) (row i of B^-1), plus M(r, 3) in the
  // translation's lane (one pass over the T x n matrices).
  std::vector<Lanes4> inverse_bind_rows(3 * static_cast<size_t>(n));
  for (int k = 0; k < n; ++k) {
    const Affine34d inverse = InverseAffine(c.skeleton().bind_world[k]);
    for (int i = 0; i < 3; ++i) {
      inverse_bind_rows[3 * k + i] =
          Lanes4{inverse(i, 0), inverse(i, 1), inverse(i, 2), inverse(i, 3)};
    }
  }
  d.kt.resize(4 * n, 3 * frames);
  RunWithSimd(simd, [&] {
    const Eigen::Index stride = d.kt.rows();
    for (int t = 0; t < frames; ++t) {
      double* frame = d.kt.data() + 3 * t * stride;
      for (int k = 0; k < n; ++k) {
        const double* m = motion.world(t, k).data();  // column-major 3x4
        const Lanes4* inverse_rows = &inverse_bind_rows[3 * k];
        for (int r = 0; r < 3; ++r) {
          Lanes4 row =
              m[r] * inverse_rows[0] + m[3 + r] * inverse_rows[1] + m[6 + r] * inverse_rows[2];
          row[3] += m[9 + r];
          *AsLanes4(frame + r * stride + 4 * k) = row;
        }
      }
    }
  });

  // The sample needs only Kt: it runs beside everything after it.
  RunPieces(run, 2, [&](int task) {
    if (task == 1) {
      d.sample = internal::MakeErrorSample(c, settings, d.kt, frames);
      return;
    }
    for (const Character::JointPairMoment& moment : c.joint_pair_moments()) {
      const double factor = moment.k == moment.l ? 1.0 : 2.0;
      d.pairs.emplace_back(moment.k, moment.l);
      d.pair_cp.push_back(factor * moment.position_moment);
      Eigen::Matrix4d cn = Eigen::Matrix4d::Zero();
      cn.topLeftCorner<3, 3>() = factor * moment.normal_moment;
      d.pair_cn.push_back(cn);
    }

    const std::vector<double>& lengths = c.subtree_lengths();
    const double total_length = std::accumulate(lengths.begin(), lengths.end(), 0.0);
    d.joint_cp.resize(n);
    d.joint_cn.resize(n);
    for (int j = 0; j < n; ++j) {
      const Affine34d& bind = c.skeleton().bind_world[j];
      Eigen::Vector4d point, axis;
      point << bind.col(3), 1.0;
      axis << bind.col(1).normalized(), 0.0;
      const double weight =
          total_length > 0 ? settings.joint_weight * lengths[j] / total_length : 0.0;
      d.joint_cp[j] = weight * point * point.transpose();
      d.joint_cn[j] = weight * axis * axis.transpose();
    }

    // Normalisation: the largest error of the root-only, unoptimised skeleton.
    {
      const internal::DeltaView root_delta{&d.kt, std::vector<int>(n, 0), &d.kt};
      d.alpha = d.beta = 1.0;
      LevelErrors root_only;
      internal::EvaluateErrors(d, root_delta, {0}, internal::Figures::kQuadratic, root_only);
      double max_ep = 0, max_en = 0;
      for (int t = 0; t < frames; ++t) {
        max_ep = std::max(max_ep, root_only.ep_vertex[t] + root_only.ep_joint[t]);
        max_en = std::max(max_en, root_only.en_vertex[t] + root_only.en_joint[t]);
      }
      // A motion that never leaves the root's rigid frame has nothing to normalise by.
      d.alpha =
          max_ep > 1e-20 * c.height() * c.height() ? 1.0 / max_ep : 1.0 / (c.height() * c.height());
      d.beta = max_en > 1e-20 ? 1.0 / max_en : 1.0;
    }
    d.beta_fit = FitsNormals(settings.variant) ? d.beta : 0.0;
    d.pair_fit.reserve(d.pairs.size());
    for (const Character::JointPairMoment& moment : c.joint_pair_moments()) {
      Eigen::Matrix4d q = d.alpha * moment.position_moment;
      q.topLeftCorner<3, 3>() += d.beta_fit * moment.normal_moment;
      d.pair_fit.push_back(q);
    }
    // F^T = Kt^T Q, one pair at a time: F_k += Q_kl Kt_l and F_l += Q_kl^T Kt_k, each a
    // product of 4 contiguous columns (a sparse-dense product would update one coefficient
    // at a time); in pieces of at most 16 frames (rows, a multiple of four so that their
    // rows fall in the same groups of four whatever the clip's length). Each piece
    // transposes its frames' columns of Kt and sums its rows of F^T in panels of its own,
    // then copies them into place: two pieces summing in place would share a cache line
    // in every column.
    const int f_frames = std::min(16, 4 * ((frames + 15) / 16));
    d.ft.resize(3 * frames, 4 * n);
    RunPieces(run, (frames + f_frames - 1) / f_frames, [&](int piece) {
      RunWithSimd(simd, [&] {
        const Eigen::Index first = 3 * piece * f_frames;
        const Eigen::Index rows = std::min<Eigen::Index>(3 * f_frames, d.ft.rows() - first);
        MatrixXd ktt(rows, 4 * n);
        MatrixXd ft = MatrixXd::Zero(rows, 4 * n);
        TransposeDoubles(d.kt.data() + first * d.kt.rows(), d.kt.rows(), d.kt.rows(), rows,
                         ktt.data(), rows);
        for (size_t q = 0; q < d.pairs.size(); ++q) {
          const auto [k, l] = d.pairs[q];
          AddPanelProduct<4>(ft.col(4 * k).data(), ktt.col(4 * l).data(), d.pair_fit[q],
                                       rows, rows);
          if (k != l) {
            AddPanelProduct<4>(ft.col(4 * l).data(), ktt.col(4 * k).data(),
                                         d.pair_fit[q].transpose(), rows, rows);
          }
        }
        d.ft.middleRows(first, rows) = ft;
      });
    });
  });
  d.joint_fit.resize(n);
  for (int j = 0; j < n; ++j) {
    d.joint_fit[j] = d.alpha * d.joint_cp[j] + d.beta_fit * d.joint_cn[j];
  }
  d.original_rotations = internal::AllRotations(d.kt, simd, internal::kRigidLevelRotation);
  d.clips = motion.Clips();
  if (d.clips.size() > 1) {
    for (const MotionClip& clip : d.clips) {
      std::vector<int> frames(clip.frame_count);
      std::iota(frames.begin(), frames.end(), clip.first_frame);
      auto part = internal::SelectFrames(d, frames);
      if (!part.ok()) return part.status();
      d.clip_parts.push_back(*std::move(part));
    }
  }
  return std::make_shared<const PreparedMotion>(std::move(data));
}

namespace internal {

StatusOr<std::shared_ptr<const PreparedMotion>> SelectFrames(const PreparedData& d,
                                                             std::span<const int> frames) {
  if (frames.empty()) return InvalidArgument("SelectFrames: no frames");
  for (size_t i = 0; i < frames.size(); ++i) {
    if (frames[i] < 0 || frames[i] >= d.frames || (i > 0 && frames[i] <= frames[i - 1])) {
      return InvalidArgument("SelectFrames: the frames must ascend within [0, " +
                             std::to_string(d.frames) + ")");
    }
  }
  auto data = std::make_unique<PreparedData>();
  PreparedData& e = *data;
  // What does not depend on the frames, as it is.
  e.character = d.character;
  e.settings = d.settings;
  e.simd = d.simd;
  e.n = d.n;
  e.pairs = d.pairs;
  e.pair_cp = d.pair_cp;
  e.pair_cn = d.pair_cn;
  e.pair_fit = d.pair_fit;
  e.joint_cp = d.joint_cp;
  e.joint_cn = d.joint_cn;
  e.joint_fit = d.joint_fit;
  e.alpha = d.alpha;
  e.beta = d.beta;
  e.beta_fit = d.beta_fit;
  // Each frame's columns of kt and rows of ft.
  const int count = static_cast<int>(frames.size());
  e.frames = count;
  e.kt.resize(d.kt.rows(), 3 * count);
  e.ft.resize(3 * count, d.ft.cols());
  // ft a column at a time: a frame's three rows of a column are contiguous.
  for (Eigen::Index col = 0; col < d.ft.cols(); ++col) {
    const double* source = d.ft.col(col).data();
    double* target = e.ft.col(col).data();
    for (int i = 0; i < count; ++i) {
      for (int r = 0; r < 3; ++r) target[3 * i + r] = source[3 * frames[i] + r];
    }
  }
  for (int i = 0; i < count; ++i) e.kt.middleCols<3>(3 * i) = d.kt.middleCols<3>(3 * frames[i]);
  e.sample = MakeErrorSample(*e.character, e.settings, e.kt, count);
  const MotionClip& first = d.clips.empty() ? MotionClip{} : d.clips.front();
  e.clips = {MotionClip{first.name, first.fps, 0, count}};
  return std::make_shared<const PreparedMotion>(std::move(data));
}

}  // namespace internal

}  // namespace motionlod::core
