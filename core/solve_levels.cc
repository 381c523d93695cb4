#include "core/solve_levels.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <optional>
#include <tuple>

#include "base/hash.h"
#include "base/lanes.h"
#include "base/simd.h"
#include "core/block_cholesky.h"
#include "core/chord_angle.h"
#include "core/polar.h"

namespace motionlod::core {

using Eigen::MatrixXd;
// Delta_k(t) in float for the per-vertex blends, as a 4x4 with a zero last row: four
// aligned packets, so a blend and its transforms stay in registers (a 3x4 float matrix
// straddles packets, and the compiler spills it to extract its columns).
using PaddedDelta = Eigen::Matrix4f;

namespace {

// Adds tr(A^T Cp B) and tr(A^T Cn B), lane by lane, to p and n (each sums to its trace): A
// and B are 4x3 blocks of column-major matrices with `stride` rows (4 contiguous rows per
// column), Cp and Cn 4x4 (Cn a 3x3 padded with zeros, which leaves the translation rows
// out). As tr(A^T C B) = <C, A B^T>, the columns of A B^T are formed once for both forms:
// 19 multiply-adds of four lanes where C B took 30, summed as a tree so that p and n wait
// on one addition per call. Written with vector types rather than plain loops over the
// rows: GCC vectorised those with every load lane-reversed and every element of B
// broadcast by a shuffle, 20 shuffles per call on the one port Intel cores run them on.
inline void AddTraceForms(const double* a, const double* b, Eigen::Index stride,
                          const Eigen::Matrix4d& cp, const Eigen::Matrix4d& cn, Lanes4& p,
                          Lanes4& n) {
  const Lanes4 a0 = *AsLanes4(a), a1 = *AsLanes4(a + stride), a2 = *AsLanes4(a + 2 * stride);
  const double* b1 = b + stride;
  const double* b2 = b + 2 * stride;
  // Column r of A B^T.
  const Lanes4 outer0 = a0 * b[0] + a1 * b1[0] + a2 * b2[0];
  const Lanes4 outer1 = a0 * b[1] + a1 * b1[1] + a2 * b2[1];
  const Lanes4 outer2 = a0 * b[2] + a1 * b1[2] + a2 * b2[2];
  const Lanes4 outer3 = a0 * b[3] + a1 * b1[3] + a2 * b2[3];
  const UnalignedLanes4* cp_columns = AsLanes4(cp.data());
  const UnalignedLanes4* cn_columns = AsLanes4(cn.data());  // the last one is zero
  p += (cp_columns[0] * outer0 + cp_columns[1] * outer1) +
       (cp_columns[2] * outer2 + cp_columns[3] * outer3);
  n += (cn_columns[0] * outer0 + cn_columns[1] * outer1) + cn_columns[2] * outer2;
}

// The sum of AddTraceForms' four lanes.
inline double LaneSum(const Lanes4& lanes) { return (lanes[0] + lanes[1]) + (lanes[2] + lanes[3]); }

// The rotations' rows of a solution transposed: `from` is 4m x cols in 4x3 blocks (three
// rotation rows, then the translation's), and row 4b + a (a < 3) becomes column 3b + a of
// `to`, which has from.cols() rows. Four columns at a time, each block's four rows of them
// (four contiguous doubles) are transposed as whole vectors (Transpose4) and the
// translations' lane dropped: element by element, every element was a load and a store of
// its own, and reading a row of `from` touches one cache line per column. (Whole matrices
// go through TransposeDoubles.) Inline, so that a caller's AVX2 version (base/simd.h)
// runs it 256 bits wide.
inline void TransposeRotationRows(const MatrixXd& from, MatrixXd& to) {
  const Eigen::Index blocks = from.rows() / 4, cols = from.cols();
  const Eigen::Index from_stride = from.rows(), to_stride = to.rows();
  Eigen::Index col = 0;
  for (; col + 4 <= cols; col += 4) {
    for (Eigen::Index b = 0; b < blocks; ++b) {
      Lanes4 columns[4], rows[4];
      for (int f = 0; f < 4; ++f) {
        columns[f] = *AsLanes4(from.data() + (col + f) * from_stride + 4 * b);
      }
      Transpose4(columns, rows);
      for (int a = 0; a < 3; ++a) *AsLanes4(to.data() + (3 * b + a) * to_stride + col) = rows[a];
    }
  }
  for (; col < cols; ++col) {
    for (Eigen::Index b = 0; b < blocks; ++b) {
      for (int a = 0; a < 3; ++a) to(col, 3 * b + a) = from(4 * b + a, col);
    }
  }
}

// Row i of a panel of B^T (4 columns of kt.cols() rows each, one after the other) gains
// M times rows 4j to 4j + 3 of kt's column i, M symmetric: K_j^T M in the right-hand sides'
// transposed layout, read from Kt itself. Four columns at a time, each column's four rows
// (four contiguous doubles) transposed as whole vectors; the sums are PanelProduct's, in
// its order. Inline, so that a caller's AVX2 version (base/simd.h) runs it 256 bits wide.
inline void AddKtProduct(double* panel, const MatrixXd& kt, int j, const Eigen::Matrix4d& m) {
  const Eigen::Index rows = kt.cols(), stride = kt.rows();
  const double* source = kt.data() + 4 * j;
  double coefficient[4][4];
  for (int c = 0; c < 4; ++c) {
    for (int a = 0; a < 4; ++a) coefficient[c][a] = m(c, a);
  }
  Eigen::Index i = 0;
  for (; i + 4 <= rows; i += 4) {
    Lanes4 columns[4], q[4];  // q[a]: row 4j + a of the columns i to i + 3
    for (int f = 0; f < 4; ++f) columns[f] = *AsLanes4(source + (i + f) * stride);
    Transpose4(columns, q);
    for (int c = 0; c < 4; ++c) {
      Lanes4 sum = *AsLanes4(panel + c * rows + i);
      for (int a = 0; a < 4; ++a) sum += coefficient[c][a] * q[a];
      *AsLanes4(panel + c * rows + i) = sum;
    }
  }
  for (; i < rows; ++i) {
    const double* q = source + i * stride;
    for (int c = 0; c < 4; ++c) {
      double sum = panel[c * rows + i];
      for (int a = 0; a < 4; ++a) sum += coefficient[c][a] * q[a];
      panel[c * rows + i] = sum;
    }
  }
}

}  // namespace

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

struct PreparedMotion::Impl {
  std::shared_ptr<const Character> character;
  SolveSettings settings;
  int n = 0;
  int frames = 0;
  MatrixXd kt;                    // 4n x 3T: block (4k, 3t) = K_k(t)^T
  // The area-fraction weighted moments per pair of joints k <= l sharing vertices: for the
  // per-frame quadratic forms of the errors, with off-diagonal pairs doubled (they appear
  // twice in the trace sum), and Q_kl = alpha Cp_kl + beta_fit Cn_kl for the normal
  // equations, as they are.
  std::vector<std::pair<int, int>> pairs;
  std::vector<Eigen::Matrix4d> pair_cp;
  std::vector<Eigen::Matrix4d> pair_cn;  // 3x3, padded with a zero row and column (AddTraceForms)
  std::vector<Eigen::Matrix4d> pair_fit;
  // For the quadratic forms in the kept joints' space (see KeptForms; Workload::kEveryLevel
  // only, empty otherwise): with every frame's matrices shifted by the root's translation
  // r(t), Kr_k(t) = K_k(t) - [0 | r(t)], the products Fp = Cp Kr and Fn = Cn Kr (4n x 3T,
  // as kt; Fn's translation rows are zero) and the constants tr(Kr^T Cp Kr),
  // tr(Kr^T Cn Kr) per frame.
  MatrixXd fp_root, fn_root;
  std::vector<double> const_p, const_n;
  // The right-hand sides are assembled transposed (3T x 4m, see SolveSystem), from a
  // transposed copy of F: ft = (Q kt)^T, 3T x 4n.
  MatrixXd ft;
  // The joint terms' forms, Ep_joint(t) = sum_j tr(Delta_j^T Jp_j Delta_j) and the same
  // for En with Jn_j: Jp_j = omega b_j [p0_j;1][p0_j;1]^T, Jn_j = omega b_j [o0_j;0][o0_j;0]^T
  // (o0_j the bind y axis).
  std::vector<Eigen::Matrix4d> joint_cp, joint_cn;
  std::vector<Eigen::Matrix4d> joint_fit;        // J_j with alpha and beta_fit
  double alpha = 1, beta = 1, beta_fit = 1;
  // Sampled figures. The sampled vertices' skin is copied out contiguously: read in place,
  // each of them would touch its own cache lines of every skin array in every frame.
  struct SampleVertex {
    Vec3f position, normal;
    double area;
    uint32_t influence_end;  // its influences end here in sample_influences
  };
  std::vector<int> sample_frames;
  std::vector<SampleVertex> sample_vertices;
  struct SampleInfluence {
    int32_t joint;
    float weight;
  };
  std::vector<SampleInfluence> sample_influences;
  // The original blended normals of each sampled frame q as direction and inverse length,
  // in rows of |vertices| (x, y, z, 1/length: rows 4q to 4q+3), for the angles' loop.
  std::vector<double> sample_normals;
  double sample_area = 0;

  // Delta_k(t) = S_k(t) - K_k(t) for every original joint k, read from the matrices S it
  // compares with the originals instead of materialised: a long motion's 4n x 3T
  // difference does not fit the caches, and every figure would read it again.
  struct DeltaView {
    const MatrixXd* solution;       // rows of S, 3T columns (the solution, or kt itself)
    std::vector<int> solution_row;  // first row of S_k in *solution
    const MatrixXd* original;       // kt

    // Whether Delta_k can be nonzero in some frame.
    bool Moves(int k) const { return solution != original || solution_row[k] != 4 * k; }
    // Frame t's Delta_k^T stacked (4n x 3, block (4k, 0) = Delta_k(t)^T) for the listed
    // joints; the other blocks are left as they are.
    // Column by column as whole vectors: AddTraceForms reads each column back as one, and a
    // 32-byte read of two 16-byte stores (Eigen's packets here) waits for them to retire.
    // (The pointers and strides are local: a store through a vector type that may alias
    // anything would reload them from the matrices after every column.)
    void Frame(int t, const std::vector<int>& joints, Eigen::Matrix<double, Eigen::Dynamic, 3>& out) const {
      const double* s = solution->data() + 3 * t * solution->rows();
      const double* o = original->data() + 3 * t * original->rows();
      const Eigen::Index s_stride = solution->rows(), o_stride = original->rows();
      const int* s_row = solution_row.data();
      double* d = out.data();
      const Eigen::Index d_stride = out.rows();
      for (int k : joints) {
        const double* sk = s + s_row[k];
        const double* ok = o + 4 * k;
        double* dk = d + 4 * k;
        for (int col = 0; col < 3; ++col) {
          *AsLanes4(dk + col * d_stride) =
              *AsLanes4(sk + col * s_stride) - *AsLanes4(ok + col * o_stride);
        }
      }
    }
  };
  // The baseline's Delta_k = K_kept(phi(k)) - K_k of a validated level.
  DeltaView BaselineDelta(const ReducedSkeleton& level) const;
  // The per-frame bounds of the maximum search (see MaxVertexError), over a set of vertex
  // groups: the others' bounds stay 0, so the search never visits them.
  struct MaxSearchBounds {
    std::vector<int> groups;          // the groups bounded (nonempty ones)
    std::vector<int> joints;          // the joints that weight them (their Delta is read)
    std::vector<double> group_bound;  // n x T: bound of group j's vertices in frame t at jT + t
    std::vector<double> frame_bound;  // T
    // Scratch: the joints' box bounds U_k in the frames of the batch of kGroupBoundFrames
    // that FrameBounds is filling, joint k's at kGroupBoundFrames k.
    std::vector<double> joint_bound;
  };
  // Bounds of every nonempty group, or (group_mask) of the groups it flags, for T frames,
  // and of those only where a joint that `moving` flags weights them, from those joints
  // alone: the others' Delta is zero (a baseline's kept joints).
  MaxSearchBounds MakeMaxSearchBounds(const std::vector<uint8_t>* group_mask,
                                      const std::vector<uint8_t>& moving) const;
  // Where a maximum search starts: the largest |d_i(t)|^2 known (in float, as the search
  // compares them) and where it is.
  struct MaxSearchStart {
    float best_squared = 0;
    int frame = 0, vertex = 0;
  };

  enum class Figures {
    kQuadratic,       // E and its parts per frame, their means and maxima, the RMS error
    kMaxVertexError,  // the exact maximum vertex error and where it is
    kAll,             // both and the sampled figures: every field of LevelErrors
  };
  // The quadratic figures (with the sampled ones) and the maximum read the same Delta and
  // nothing of each other: with both asked for, they are two pieces on `run`, each one pass
  // over the frames (the maximum search then revisits the frames it needs), and the
  // figures do not depend on the runner. A finite `decide_within` (length) makes the
  // maximum search a decision: it stops at the first vertex past it and refines no bound
  // within it, so the maximum it reports is only on the right side of it.
  void EvaluateErrors(const DeltaView& delta, const std::vector<int>& kept, Figures figures,
                      LevelErrors& out,
                      double decide_within = std::numeric_limits<double>::infinity(),
                      const PieceRunner& run = {}) const;
  std::vector<size_t> ActivePairs(const DeltaView& delta) const;
  // Joint pair q's terms of the vertex parts of Ep and En in a frame (4n x 3, Delta_k^T
  // stacked): tr(Delta_k^T Cp_kl Delta_l) and tr(Delta_k^T Cn_kl Delta_l), doubled for k != l.
  // AddPairTerms adds them lane by lane to p and n (AddTraceForms).
  void AddPairTerms(const Eigen::Matrix<double, Eigen::Dynamic, 3>& frame, size_t q, Lanes4& p,
                    Lanes4& n) const {
    const auto [k, l] = pairs[q];
    AddTraceForms(frame.data() + 4 * k, frame.data() + 4 * l, frame.rows(), pair_cp[q], pair_cn[q],
                  p, n);
  }
  std::pair<double, double> PairTerms(const Eigen::Matrix<double, Eigen::Dynamic, 3>& frame,
                                      size_t q) const {
    Lanes4 p = {}, n = {};
    AddPairTerms(frame, q, p, n);
    return {LaneSum(p), LaneSum(n)};
  }
  // A level's quadratic forms in its kept joints' space. With Delta_k = X_s - K_k, s = phi(k),
  //   sum_kl tr(Delta_k^T C_kl Delta_l) = sum_su tr(X_s^T G_su X_u) - 2 sum_k tr(X_s^T F_k)
  //                                       + tr(K^T C K),   G_su = sum_{phi(k)=s, phi(l)=u} C_kl,
  // so a frame costs the slot pairs (fewer as joints go) and n 4x3 products instead of
  // every joint pair. Evaluated with the root's translation taken out of X and K (which
  // leaves Delta as it is), so that the constant is of the character's size and not of its
  // distance from the origin; a frame whose result is still below kKeptFormsPrecision of
  // that constant falls back to the joint pairs (the subtraction would lose digits).
  struct KeptForms {
    std::vector<std::pair<int, int>> slot_pairs;  // s <= u
    std::vector<Eigen::Matrix4d> slot_cp;         // pair factors folded in, as pair_cp
    std::vector<Eigen::Matrix4d> slot_cn;         // padded, as pair_cn
    const MatrixXd* solution = nullptr;           // X, 3T columns
    std::vector<int> slot_row;                    // X_s^T is the 4 rows from slot_row[s]
    std::vector<int> slot_of;                     // phi(k)
  };
  static constexpr double kKeptFormsPrecision = 1e-8;
  // The kept-space forms for a level's Delta (X_s the solution's slot s for an optimised
  // level, K of the kept joint for a baseline), or nothing where the joint pairs cost less
  // (levels that keep most joints, baselines that remove few).
  std::optional<KeptForms> MakeKeptForms(const DeltaView& delta, const std::vector<int>& kept,
                                         size_t active_pairs) const;
  // kept_frame: scratch for X(t), 4m x 3, where kept_forms is given. moving_kept: the kept
  // joints whose Delta can be nonzero, the only ones with joint terms (none of a baseline's).
  void FrameQuadraticErrors(const Eigen::Matrix<double, Eigen::Dynamic, 3>& frame,
                            const std::vector<size_t>& active_pairs, const KeptForms* kept_forms,
                            Eigen::Matrix<double, Eigen::Dynamic, 3>& kept_frame,
                            const std::vector<int>& kept, const std::vector<int>& moving_kept,
                            int t, LevelErrors& out) const;
  // Called for every frame, 0 to T - 1: the bounds are computed a batch of
  // kGroupBoundFrames frames at a time, when the batch's last frame (or frame T - 1) comes.
  static constexpr int kGroupBoundFrames = 4;
  void FrameBounds(const DeltaView& delta, int t, MaxSearchBounds& bounds) const;
  // The search starts from `start` (a value some vertex attains) and evaluates only the
  // clusters that cluster_mask flags (nullptr: every cluster).
  // Returns where it ended, the start of a later search.
  MaxSearchStart MaxVertexError(const DeltaView& delta, const MaxSearchBounds& bounds,
                                double decide_within, const MaxSearchStart& start,
                                const std::vector<uint8_t>* cluster_mask, LevelErrors& out) const;
  // Per sampled vertex of one sampled frame: |v - v'|^2, the normals' angle (radians) and
  // |n - n'|^2, in rows of |vertices|.
  struct SampleValues {
    std::vector<double> distance_squared, angle, normal_squared;
    explicit SampleValues(size_t count = 0) : distance_squared(count), angle(count), normal_squared(count) {}
  };
  // Area-weighted sums over the sample of |v - v'|, |v - v'|^2, the normals' angle and
  // |n - n'|^2.
  struct SampleSums {
    double distance = 0, distance_squared = 0, angle = 0, normal_squared = 0;
  };
  void AddSampleSums(const SampleValues& values, SampleSums& sums) const;
  // Scratch of SampleFrameValues: n matrices, then rows of up to |vertices|.
  struct SampleScratch {
    std::vector<PaddedDelta> frame_delta;
    std::vector<double> normals, normal_x, normal_y, normal_z, angle;
    explicit SampleScratch(size_t joints = 0, size_t count = 0)
        : frame_delta(joints, PaddedDelta::Zero()), normals(4 * count), normal_x(count),
          normal_y(count), normal_z(count), angle(count) {}
  };
  // The values of sampled frame q = sample_frames index for the sampled vertices listed in
  // `vertices` (nullptr: every one), written at their own index in `values`.
  void SampleFrameValues(const Eigen::Matrix<double, Eigen::Dynamic, 3>& frame, size_t q,
                         const std::vector<uint32_t>* vertices, SampleScratch& scratch,
                         SampleValues& values) const;
  // The figures that follow from the per-frame parts of E (e, mean_e, max_e, the RMS
  // error) and, where given, from the sample's sums.
  void FinishErrors(const SampleSums* sums, LevelErrors& out) const;
  // Fills the sample's fields (sample_frames to sample_area) from the character, the
  // settings and kt.
  void PrepareSample();
};

namespace {

std::vector<int> EvenlySpaced(int count, int available) {
  const int used = std::min(count, available);
  std::vector<int> out(used);
  for (int q = 0; q < used; ++q) {
    out[q] = used == 1 ? 0
                       : static_cast<int>(std::llround(static_cast<double>(q) * (available - 1) /
                                                       (used - 1)));
  }
  return out;
}

// The angle between each original normal n and n + dn (radians) from the chord of their
// directions, 2 asin(|u - w/|w|| / 2) with u = n/|n|, w = u + dn/|n| (core/chord_angle.h):
// up to 29 degrees, where level errors almost always are, by the series; past it the
// marker for FinishChordAngle, and NaN where n or n + dn is zero. Without a branch or a
// call the loop runs two vertices per instruction. normals: rows of count, u_x, u_y, u_z
// and 1/|n|.
void ChordAngles(size_t count, const double* normals, const double* dn_x, const double* dn_y,
                 const double* dn_z, double* __restrict angle) {
  const double* unit_x = normals;
  const double* unit_y = unit_x + count;
  const double* unit_z = unit_y + count;
  const double* inverse_length = unit_z + count;
  for (size_t v = 0; v < count; ++v) {
    const double wx = unit_x[v] + dn_x[v] * inverse_length[v];
    const double wy = unit_y[v] + dn_y[v] * inverse_length[v];
    const double wz = unit_z[v] + dn_z[v] * inverse_length[v];
    const double inverse_w = 1 / std::sqrt(wx * wx + wy * wy + wz * wz);
    const double cx = unit_x[v] - wx * inverse_w, cy = unit_y[v] - wy * inverse_w;
    const double cz = unit_z[v] - wz * inverse_w;
    angle[v] = ChordAngleOrMarker(0.5 * std::sqrt(cx * cx + cy * cy + cz * cz));
  }
}

}  // namespace

PreparedMotion::PreparedMotion(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
PreparedMotion::~PreparedMotion() = default;
const Character& PreparedMotion::character() const { return *impl_->character; }
const SolveSettings& PreparedMotion::settings() const { return impl_->settings; }
int PreparedMotion::frame_count() const { return impl_->frames; }
double PreparedMotion::alpha() const { return impl_->alpha; }
double PreparedMotion::beta() const { return impl_->beta; }
const MatrixXd& PreparedMotion::original_matrices() const { return impl_->kt; }

StatusOr<std::shared_ptr<const PreparedMotion>> PreparedMotion::Create(
    std::shared_ptr<const Character> character, const Motion& motion, const SolveSettings& settings,
    Workload workload, const PieceRunner& run) {
  if (!character) return InvalidArgument("PreparedMotion: no character");
  if (Status status = settings.Validate(); !status.ok()) return status;
  if (Status status = ValidateMotion(motion, *character); !status.ok()) return status;

  auto impl = std::make_unique<Impl>();
  Impl& d = *impl;
  const Character& c = *character;
  const int n = c.joint_count();
  const int frames = motion.frame_count;
  d.character = character;
  d.settings = settings;
  d.n = n;
  d.frames = frames;

  // Kt: each skinning matrix K_k(t) = M_k(t) B_k^-1 (B_k the bind pose) written straight
  // into its block, row r of K as lanes: sum_i M(r, i) (row i of B^-1), plus M(r, 3) in the
  // translation's lane. (Composed into a list of matrices first and copied into Kt, then
  // transposed into Kt^T by Eigen one element at a time, they cost a short clip's Create a
  // fifth of its time: three passes over T x n matrices, each slower on two threads, where
  // a thread writes lines the other one held.)
  std::vector<Lanes4> inverse_bind_rows(3 * static_cast<size_t>(n));
  for (int k = 0; k < n; ++k) {
    const Affine34d inverse = InverseAffine(c.skeleton().bind_world[k]);
    for (int i = 0; i < 3; ++i) {
      inverse_bind_rows[3 * k + i] =
          Lanes4{inverse(i, 0), inverse(i, 1), inverse(i, 2), inverse(i, 3)};
    }
  }
  d.kt.resize(4 * n, 3 * frames);
  RunWithWidestSimd([&] {
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

  // The sample needs only Kt: it runs beside everything after it, which is serial at
  // first (the pairs' moments, the normalisation), so that on two threads the one that
  // ranked the joints takes it instead of waiting for Create's first pieces, and a short
  // clip of a large mesh has it as its longest piece (Orc@16089v's 24 frames: 55 us, an F
  // piece 13 to 26). (Split in two, its vertices picked before the pieces, it kept
  // Create's thread longer.)
  RunPieces(run, 2, [&](int task) {
    if (task == 1) {
      d.PrepareSample();
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
      const Impl::DeltaView root_delta{&d.kt, std::vector<int>(n, 0), &d.kt};
      d.alpha = d.beta = 1.0;
      LevelErrors root_only;
      d.EvaluateErrors(root_delta, {0}, Impl::Figures::kQuadratic, root_only);
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
    // The per-frame work below runs in pieces of frames on `run`: at most 16 frames, and a
    // quarter of a clip of fewer than 64 frames (a 24-frame clip's pieces of 16 and 8
    // frames kept one of two threads waiting for a third of their time). The F pieces'
    // quarter is rounded up to a multiple of four frames, so that their rows fall in the
    // same groups of four rows (their vectors) whatever the clip's length.
    const int forms_frames = std::min(16, (frames + 3) / 4);
    const int f_frames = std::min(16, 4 * ((frames + 15) / 16));
    // The kept-space forms' products and constants (see KeptForms), frame by frame; after
    // the normalisation, whose root-only errors stay in the joint pairs' form so that alpha
    // and beta, and with them every solution, do not depend on the workload. Most of
    // Create's time: in pieces of frames (each frame's columns are its own), each in the
    // widest vectors this CPU has (base/simd.h).
    if (workload == Workload::kEveryLevel) {
      d.fp_root = MatrixXd::Zero(4 * n, 3 * frames);
      d.fn_root = MatrixXd::Zero(4 * n, 3 * frames);
      d.const_p.assign(frames, 0.0);
      d.const_n.assign(frames, 0.0);
      RunPieces(run, (frames + forms_frames - 1) / forms_frames, [&](int piece) {
        RunWithWidestSimd([&] {
          Eigen::Matrix<double, Eigen::Dynamic, 3> shifted(4 * n, 3);
          for (int t = piece * forms_frames; t < std::min(frames, (piece + 1) * forms_frames);
               ++t) {
            shifted = d.kt.middleCols<3>(3 * t);
            const Eigen::RowVector3d root = d.kt.block<1, 3>(3, 3 * t);
            for (int k = 0; k < n; ++k) shifted.row(4 * k + 3) -= root;
            auto fp = d.fp_root.middleCols<3>(3 * t);
            auto fn = d.fn_root.middleCols<3>(3 * t);
            for (size_t q = 0; q < d.pairs.size(); ++q) {
              const auto [k, l] = d.pairs[q];
              // The moments themselves: pair_cp and pair_cn have off-diagonal pairs doubled.
              const double single = k == l ? 1.0 : 0.5;
              const Eigen::Matrix4d cp = single * d.pair_cp[q];
              const Eigen::Matrix3d cn = single * d.pair_cn[q].topLeftCorner<3, 3>();
              fp.block<4, 3>(4 * k, 0).noalias() += cp * shifted.block<4, 3>(4 * l, 0);
              fn.block<3, 3>(4 * k, 0).noalias() += cn * shifted.block<3, 3>(4 * l, 0);
              if (k != l) {
                fp.block<4, 3>(4 * l, 0).noalias() += cp * shifted.block<4, 3>(4 * k, 0);
                fn.block<3, 3>(4 * l, 0).noalias() += cn * shifted.block<3, 3>(4 * k, 0);
              }
            }
            for (int k = 0; k < n; ++k) {
              d.const_p[t] +=
                  shifted.block<4, 3>(4 * k, 0).cwiseProduct(fp.block<4, 3>(4 * k, 0)).sum();
              d.const_n[t] +=
                  shifted.block<3, 3>(4 * k, 0).cwiseProduct(fn.block<3, 3>(4 * k, 0)).sum();
            }
          }
        });
      });
    }
    d.pair_fit.reserve(d.pairs.size());
    for (const Character::JointPairMoment& moment : c.joint_pair_moments()) {
      Eigen::Matrix4d q = d.alpha * moment.position_moment;
      q.topLeftCorner<3, 3>() += d.beta_fit * moment.normal_moment;
      d.pair_fit.push_back(q);
    }
    // F^T = Kt^T Q, one pair at a time: F_k += Q_kl Kt_l and F_l += Q_kl^T Kt_k, each a
    // product of 4 contiguous columns (a sparse-dense product would update one coefficient
    // at a time); in pieces of frames (rows), each in the widest vectors this CPU has. Each
    // piece transposes its frames' columns of Kt and sums its rows of F^T in panels of its
    // own, then copies F^T's into place: a column of F^T (3T rows) rarely ends on a cache
    // line, so two pieces share a line in every column, and summing in place had both
    // threads write those lines once per pair (Fox on an Intel Xeon, 2 threads: 23 to 34 us
    // for a piece beside another, 8 to 12 alone). A serial pass (the whole transpose, or
    // zeroing F^T up front) kept the other thread waiting. (Kt^T is not kept: the solves
    // read Kt, AddKtProduct; its copy cost the pieces more on two threads, where the lines
    // they write were last read by the other core, than the solves' transposes.)
    d.ft.resize(3 * frames, 4 * n);
    RunPieces(run, (frames + f_frames - 1) / f_frames, [&](int piece) {
      RunWithWidestSimd([&] {
        const Eigen::Index first = 3 * piece * f_frames;
        const Eigen::Index rows = std::min<Eigen::Index>(3 * f_frames, d.ft.rows() - first);
        MatrixXd ktt(rows, 4 * n);
        MatrixXd ft = MatrixXd::Zero(rows, 4 * n);
        TransposeDoubles(d.kt.data() + first * d.kt.rows(), d.kt.rows(), d.kt.rows(), rows,
                         ktt.data(), rows);
        for (size_t q = 0; q < d.pairs.size(); ++q) {
          const auto [k, l] = d.pairs[q];
          AddPanelProduct<4>(ft.col(4 * k).data(), ktt.col(4 * l).data(), d.pair_fit[q], rows,
                             rows);
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
  return std::shared_ptr<const PreparedMotion>(new PreparedMotion(std::move(impl)));
}

StatusOr<std::shared_ptr<const PreparedMotion>> PreparedMotion::EveryNthFrame(int stride) const {
  if (stride < 1) return InvalidArgument("EveryNthFrame: the stride must be at least 1");
  const Impl& d = *impl_;
  auto impl = std::make_unique<Impl>();
  Impl& e = *impl;
  // What does not depend on the frames, as it is.
  e.character = d.character;
  e.settings = d.settings;
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
  // Each frame's columns of kt (fp_root, fn_root) and rows of ft, and its constants.
  const int frames = 1 + (d.frames - 1) / stride;  // d.frames >= 1; no overflow
  e.frames = frames;
  const bool kept_forms = !d.const_p.empty();
  e.kt.resize(d.kt.rows(), 3 * frames);
  e.ft.resize(3 * frames, d.ft.cols());
  if (kept_forms) {
    e.fp_root.resize(d.fp_root.rows(), 3 * frames);
    e.fn_root.resize(d.fn_root.rows(), 3 * frames);
  }
  // ft a column at a time: a frame's three rows of a column are contiguous (row by row, as
  // Eigen copies middleRows, every element is a column's stride from the last).
  for (Eigen::Index col = 0; col < d.ft.cols(); ++col) {
    const double* source = d.ft.col(col).data();
    double* target = e.ft.col(col).data();
    for (int t = 0; t < frames; ++t) {
      for (int r = 0; r < 3; ++r) target[3 * t + r] = source[3 * t * stride + r];
    }
  }
  for (int t = 0; t < frames; ++t) {
    const int source = t * stride;
    e.kt.middleCols<3>(3 * t) = d.kt.middleCols<3>(3 * source);
    if (kept_forms) {
      e.fp_root.middleCols<3>(3 * t) = d.fp_root.middleCols<3>(3 * source);
      e.fn_root.middleCols<3>(3 * t) = d.fn_root.middleCols<3>(3 * source);
      e.const_p.push_back(d.const_p[source]);
      e.const_n.push_back(d.const_n[source]);
    }
  }
  e.PrepareSample();
  return std::shared_ptr<const PreparedMotion>(new PreparedMotion(std::move(impl)));
}

void PreparedMotion::Impl::PrepareSample() {
  // The sample for the per-vertex figures, with the original blended normals.
  const RawSkin& skin = character->skin();
  const int p = character->vertex_count();
  sample_frames = EvenlySpaced(settings.sample_frames, frames);
  constexpr int64_t kMinSampleVertices = 64;
  const int64_t motion_budget =
      static_cast<int64_t>(p) * frames / (100 * static_cast<int64_t>(sample_frames.size()));
  const int64_t vertex_count =
      std::min<int64_t>(settings.sample_vertices, std::max(kMinSampleVertices, motion_budget));
  const int stride = static_cast<int>((p + vertex_count - 1) / vertex_count);
  for (int i = 0; i < p; i += stride) {
    for (uint32_t e = skin.influence_offsets[i]; e < skin.influence_offsets[i + 1]; ++e) {
      sample_influences.push_back({skin.influence_joints[e], skin.influence_weights[e]});
    }
    sample_vertices.push_back({skin.positions[i], skin.normals[i], character->vertex_areas()[i],
                               static_cast<uint32_t>(sample_influences.size())});
    sample_area += sample_vertices.back().area;
  }
  const size_t sample_count = sample_vertices.size();
  sample_normals.resize(sample_frames.size() * 4 * sample_count);
  for (size_t q = 0; q < sample_frames.size(); ++q) {
    const int t = sample_frames[q];
    uint32_t e = 0;
    for (size_t v = 0; v < sample_vertices.size(); ++v) {
      const SampleVertex& sample = sample_vertices[v];
      Vec3d normal = Vec3d::Zero();
      for (; e < sample.influence_end; ++e) {
        const SampleInfluence& influence = sample_influences[e];
        normal += influence.weight * (kt.block<3, 3>(4 * influence.joint, 3 * t).transpose() *
                                      sample.normal.cast<double>());
      }
      const double length = normal.norm();
      const double inverse_length = length > 0 ? 1 / length : 0;
      double* rows = sample_normals.data() + 4 * q * sample_count;
      for (int a = 0; a < 3; ++a) rows[a * sample_count + v] = normal[a] * inverse_length;
      rows[3 * sample_count + v] = inverse_length;
    }
  }
}

std::vector<size_t> PreparedMotion::Impl::ActivePairs(const DeltaView& delta) const {
  // Pairs with a joint whose Delta is zero in every frame add nothing (every kept joint of
  // a baseline): skip them.
  std::vector<size_t> active;
  active.reserve(pairs.size());
  for (size_t q = 0; q < pairs.size(); ++q) {
    if (delta.Moves(pairs[q].first) && delta.Moves(pairs[q].second)) active.push_back(q);
  }
  return active;
}

void PreparedMotion::Impl::EvaluateErrors(const DeltaView& delta, const std::vector<int>& kept,
                                          Figures figures, LevelErrors& out, double decide_within,
                                          const PieceRunner& run) const {
  const bool quadratic = figures != Figures::kMaxVertexError;
  const bool maximum = figures != Figures::kQuadratic;
  const bool sampled = figures == Figures::kAll;
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
    RunWithWidestSimd([&] {
      std::vector<int> moving_kept;
      moving_kept.reserve(kept.size());
      for (int j : kept) {
        if (moving[j]) moving_kept.push_back(j);
      }
      const std::vector<size_t> active_pairs = ActivePairs(delta);
      const std::optional<KeptForms> kept_forms = MakeKeptForms(delta, kept, active_pairs.size());
      Eigen::Matrix<double, Eigen::Dynamic, 3> kept_frame(kept_forms ? 4 * kept.size() : 0, 3);
      SampleSums sums;
      size_t next_sample = 0;
      SampleScratch scratch(sampled ? n : 0, sampled ? sample_vertices.size() : 0);
      SampleValues values(sampled ? sample_vertices.size() : 0);
      Eigen::Matrix<double, Eigen::Dynamic, 3> frame(4 * n, 3);
      frame.setZero();
      for (int t = 0; t < frames; ++t) {
        delta.Frame(t, moving_joints, frame);
        FrameQuadraticErrors(frame, active_pairs, kept_forms ? &*kept_forms : nullptr, kept_frame,
                             kept, moving_kept, t, out);
        if (sampled && next_sample < sample_frames.size() && sample_frames[next_sample] == t) {
          SampleFrameValues(frame, next_sample++, nullptr, scratch, values);
          AddSampleSums(values, sums);
        }
      }
      FinishErrors(sampled ? &sums : nullptr, out);
    });
  };
  const auto maximum_figures = [&] {
    RunWithWidestSimd([&] {
      MaxSearchBounds bounds = MakeMaxSearchBounds(nullptr, moving);
      for (int t = 0; t < frames; ++t) FrameBounds(delta, t, bounds);
      MaxVertexError(delta, bounds, decide_within, MaxSearchStart{}, nullptr, out);
    });
  };
  if (quadratic && maximum) {
    RunPieces(run, 2, [&](int piece) { piece == 0 ? maximum_figures() : quadratic_figures(); });
  } else if (quadratic) {
    quadratic_figures();
  } else {
    maximum_figures();
  }
}

void PreparedMotion::Impl::FinishErrors(const SampleSums* sums, LevelErrors& out) const {
  out.mean_e = std::accumulate(out.e.begin(), out.e.end(), 0.0) / frames;
  const auto max_it = std::max_element(out.e.begin(), out.e.end());
  out.max_e = *max_it;
  out.max_e_frame = static_cast<int>(max_it - out.e.begin());
  const double mean_sq = std::accumulate(out.ep_vertex.begin(), out.ep_vertex.end(), 0.0) / frames;
  out.rms_vertex_error_pct = 100.0 * std::sqrt(mean_sq) / character->height();
  if (sums == nullptr) return;
  // Ratio estimates: the sample's mean scaled by how far its mean square is from the
  // exact one over every vertex and frame (the quadratic forms). A strided sample that
  // over- or under-represents where a level's error sits (a hand, a face) gets the scale
  // right from the exact figure and keeps only the shape (mean over RMS) from the
  // sample; plain sample means were off by up to 2x on real levels.
  const double weight = sample_area * static_cast<double>(sample_frames.size());
  const auto ratio_estimate = [&](double sum, double sum_squared, const std::vector<double>& exact) {
    const double exact_mean_squared = std::accumulate(exact.begin(), exact.end(), 0.0) / frames;
    const double mean = sum / weight;
    return sum_squared > 0 ? mean * std::sqrt(exact_mean_squared / (sum_squared / weight)) : mean;
  };
  out.mean_vertex_error_pct =
      100.0 * ratio_estimate(sums->distance, sums->distance_squared, out.ep_vertex) / character->height();
  out.mean_normal_error_deg =
      ratio_estimate(sums->angle, sums->normal_squared, out.en_vertex) * 180.0 / M_PI;
}

std::optional<PreparedMotion::Impl::KeptForms> PreparedMotion::Impl::MakeKeptForms(
    const DeltaView& delta, const std::vector<int>& kept, size_t active_pairs) const {
  const int m = static_cast<int>(kept.size());
  if (const_p.empty()) return std::nullopt;
  KeptForms forms;
  forms.solution = delta.solution;
  forms.slot_row.resize(m);
  forms.slot_of.resize(n);
  if (delta.solution != delta.original) {  // optimised: solution rows are slots
    for (int s = 0; s < m; ++s) forms.slot_row[s] = 4 * s;
    for (int k = 0; k < n; ++k) forms.slot_of[k] = delta.solution_row[k] / 4;
  } else {  // baseline: solution rows are the kept joints' own in K
    std::vector<int> slot_of_joint(n, -1);
    for (int s = 0; s < m; ++s) {
      forms.slot_row[s] = 4 * kept[s];
      slot_of_joint[kept[s]] = s;
    }
    for (int k = 0; k < n; ++k) {
      forms.slot_of[k] = slot_of_joint[delta.solution_row[k] / 4];
      if (forms.slot_of[k] < 0) return std::nullopt;
    }
  }
  std::vector<int> index(static_cast<size_t>(m) * m, -1);
  const size_t slot_pairs_at_most = std::min(pairs.size(), static_cast<size_t>(m) * (m + 1) / 2);
  forms.slot_pairs.reserve(slot_pairs_at_most);
  forms.slot_cp.reserve(slot_pairs_at_most);
  forms.slot_cn.reserve(slot_pairs_at_most);
  for (size_t q = 0; q < pairs.size(); ++q) {
    const int a = forms.slot_of[pairs[q].first], b = forms.slot_of[pairs[q].second];
    const int s = std::min(a, b), u = std::max(a, b);
    int& slot_pair = index[static_cast<size_t>(s) * m + u];
    if (slot_pair < 0) {
      slot_pair = static_cast<int>(forms.slot_pairs.size());
      forms.slot_pairs.emplace_back(s, u);
      forms.slot_cp.push_back(Eigen::Matrix4d::Zero());
      forms.slot_cn.push_back(Eigen::Matrix4d::Zero());
    }
    // A pair of distinct joints in one slot counts twice in the double sum, as pair_cp has
    // it; so does a pair across two slots (tr(X_s^T C X_u) = tr(X_u^T C X_s), C symmetric).
    forms.slot_cp[slot_pair] += pair_cp[q];
    forms.slot_cn[slot_pair] += pair_cn[q];
  }
  // A frame then costs the slot pairs and one 4x3 product per joint against the active
  // joint pairs: not worth it for the levels that keep most joints.
  if (4 * (forms.slot_pairs.size() + n / 2) > 3 * active_pairs) return std::nullopt;
  return forms;
}

void PreparedMotion::Impl::FrameQuadraticErrors(
    const Eigen::Matrix<double, Eigen::Dynamic, 3>& frame, const std::vector<size_t>& active_pairs,
    const KeptForms* kept_forms, Eigen::Matrix<double, Eigen::Dynamic, 3>& x,
    const std::vector<int>& kept, const std::vector<int>& moving_kept, int t,
    LevelErrors& out) const {
  // sum_kl tr(Delta_k^T C_kl Delta_l) over the joint pairs, lane by lane (AddTraceForms).
  const auto joint_pairs = [&](double& ep, double& en) {
    Lanes4 p = {}, n = {};
    for (size_t q : active_pairs) AddPairTerms(frame, q, p, n);
    ep = LaneSum(p);
    en = LaneSum(n);
  };
  double ep = 0, en = 0;
  if (kept_forms == nullptr) {
    joint_pairs(ep, en);
  } else {
    // X_s^T with the root's translation taken out: rows 4s..4s+3 of frame t's columns, each
    // column written whole (as DeltaView::Frame, for AddTraceForms' reads).
    const int m = static_cast<int>(kept.size());
    const MatrixXd& solution = *kept_forms->solution;
    const Eigen::Index x_stride = x.rows(), solution_stride = solution.rows();
    const double* solution_frame = solution.data() + 3 * t * solution_stride;
    const int* slot_row = kept_forms->slot_row.data();
    double* x_data = x.data();
    for (int col = 0; col < 3; ++col) {
      const Lanes4 root = {0, 0, 0, kt(3, 3 * t + col)};
      const double* solution_column = solution_frame + col * solution_stride;
      double* x_column = x_data + col * x_stride;
      for (int s = 0; s < m; ++s) {
        *AsLanes4(x_column + 4 * s) = *AsLanes4(solution_column + slot_row[s]) - root;
      }
    }
    // Summed lane by lane (AddTraceForms): the quadratic terms, then minus twice the linear ones.
    Lanes4 sum_p = {}, sum_n = {};
    for (size_t q = 0; q < kept_forms->slot_pairs.size(); ++q) {
      const auto [s, u] = kept_forms->slot_pairs[q];
      AddTraceForms(x.data() + 4 * s, x.data() + 4 * u, x.rows(), kept_forms->slot_cp[q],
                    kept_forms->slot_cn[q], sum_p, sum_n);
    }
    Lanes4 linear_p = {}, linear_n = {};
    const double* fp = fp_root.data() + 3 * t * fp_root.rows();
    const double* fn = fn_root.data() + 3 * t * fn_root.rows();
    for (int k = 0; k < n; ++k) {
      const double* xs = x.data() + 4 * kept_forms->slot_of[k];
      for (int col = 0; col < 3; ++col) {
        const Lanes4 xc = *AsLanes4(xs + col * x.rows());
        linear_p += xc * *AsLanes4(fp + col * fp_root.rows() + 4 * k);
        linear_n += xc * *AsLanes4(fn + col * fn_root.rows() + 4 * k);
      }
    }
    sum_p -= 2 * linear_p;
    sum_n -= 2 * linear_n;
    ep = LaneSum(sum_p) + const_p[t];
    en = LaneSum(sum_n) + const_n[t];
    if (ep < kKeptFormsPrecision * const_p[t] || en < kKeptFormsPrecision * const_n[t]) {
      joint_pairs(ep, en);
    }
  }
  out.ep_vertex[t] = std::max(0.0, ep);
  out.en_vertex[t] = std::max(0.0, en);
  Lanes4 joint_p = {}, joint_n = {};
  for (int j : moving_kept) {
    const double* block = frame.data() + 4 * j;
    AddTraceForms(block, block, frame.rows(), joint_cp[j], joint_cn[j], joint_p, joint_n);
  }
  out.ep_joint[t] = LaneSum(joint_p);
  out.en_joint[t] = LaneSum(joint_n);
  out.e[t] = alpha * (out.ep_vertex[t] + out.ep_joint[t]) + beta * (out.en_vertex[t] + out.en_joint[t]);
}

namespace {

// Delta_g in four frames, lane by lane (the maximum search bounds a batch of frames at
// once): entry 3a + i of m is Delta_g(i, a) (a = 3: the translation), then the column
// norms of its 3x3 part.
struct LaneDelta {
  static constexpr int kLanes = 4;
  double m[12][kLanes];
  double column_norms[3][kLanes];

  // Sets Delta_g of the four frames whose columns start at solution[f] and original[f]
  // (DeltaView: column c of Delta_g^T is row c of Delta_g, four contiguous doubles from
  // solution_offset and original_offset) and its column norms. Each row of the four frames
  // is transposed into lanes as whole vectors: element by element, this copy was a third
  // of the search.
  void Fill(const double* const solution[kLanes], const double* const original[kLanes],
            Eigen::Index solution_stride, Eigen::Index original_stride,
            Eigen::Index solution_offset, Eigen::Index original_offset) {
    for (int c = 0; c < 3; ++c) {
      Lanes4 row[kLanes], by_column[4];
      for (int f = 0; f < kLanes; ++f) {
        row[f] = *AsLanes4(solution[f] + c * solution_stride + solution_offset) -
                 *AsLanes4(original[f] + c * original_stride + original_offset);
      }
      Transpose4(row, by_column);
      for (int a = 0; a < 4; ++a) *AsLanes4(m[3 * a + c]) = by_column[a];
    }
    for (int a = 0; a < 3; ++a) {
      const Lanes4 x = *AsLanes4(m[3 * a]), y = *AsLanes4(m[3 * a + 1]);
      const Lanes4 z = *AsLanes4(m[3 * a + 2]);
      const Lanes4 squared = x * x + y * y + z * z;
      for (int f = 0; f < kLanes; ++f) column_norms[a][f] = std::sqrt(squared[f]);
    }
  }

  // The bounds of the maximum search (see MaxVertexError) for a box with center c and half
  // extents h: U_g = |Delta_g [c;1]| + sum_a |Delta_g(3x3) e_a| h_a in each lane.
  // (Vectors go out through references: returned by value, they would change the
  // baseline version's calling convention, which GCC warns of.)
  void BoxBounds(const Vec3d& center, const Vec3d& half, Lanes4& u) const {
    Lanes4 moved[3];
    for (int i = 0; i < 3; ++i) {
      moved[i] = *AsLanes4(m[i]) * center[0] + *AsLanes4(m[3 + i]) * center[1] +
                 *AsLanes4(m[6 + i]) * center[2] + *AsLanes4(m[9 + i]);
    }
    const Lanes4 squared = moved[0] * moved[0] + moved[1] * moved[1] + moved[2] * moved[2];
    Lanes4 length;
    for (int f = 0; f < kLanes; ++f) length[f] = std::sqrt(squared[f]);
    u = length + *AsLanes4(column_norms[0]) * half[0] + *AsLanes4(column_norms[1]) * half[1] +
        *AsLanes4(column_norms[2]) * half[2];
  }
};

// The largest sum_g w_g U_g, U_g = bound_of(g) >= 0, over weights w_g in their ranges
// [a_g, b_g] that sum to at most 1: a linear programme whose value, for every lambda >= 0,
// is at most
//   f(lambda) = sum_g a_g U_g + lambda (1 - sum_g a_g) + sum_g (b_g - a_g) max(0, U_g - lambda)
// (weak duality) and equals the smallest f at a breakpoint lambda in {0, U_g}. lambda = 0
// gives sum_g b_g U_g and lambda = max_g U_g, with every a_g 0, gives max_g U_g: this is
// never looser than the better of those two, and measured 2x tighter on the blended
// clusters of stormtrooper's every-level bakes (docs/PERFORMANCE.md, round 9), where
// the largest weights of a cluster in a blend region sum to well over 1.
// The breakpoints past lambda = 0 and max_g U_g cost a pass over the joints each: with
// kRefine they are tried where one of those two is above `threshold` (nothing to gain
// below it); without, the two alone (the per-frame group bounds, computed for every group).
// For four frames at once, one per lane (the maximum search's batches): bound_of(g, u)
// sets U_g of each, and `out` gets each frame's bound. Written with vector types: GCC left
// the plain loops over the four lanes scalar, and a bound stored one lane at a time and
// read back as a vector waited for the stores to retire.
template <bool kRefine, typename BoundOf>
void WeightedBound(const Character::InfluenceRange* begin, const Character::InfluenceRange* end,
                   double threshold, BoundOf&& bound_of, Lanes4& out) {
  // Weights sum to 1 within the validation's tolerance.
  constexpr double kWeightSum = 1.0 + 1e-3;
  constexpr int kMaxJoints = 8;
  const auto count = static_cast<int>(std::min<std::ptrdiff_t>(end - begin, kMaxJoints));
  Lanes4 u[kMaxJoints];  // the first `count` entries
  double span[kMaxJoints];
  Lanes4 floor = {}, largest = {}, widest = {};
  double budget = kWeightSum;
  for (const Character::InfluenceRange* q = begin; q != end; ++q) {
    Lanes4 bound;
    bound_of(q->joint, bound);
    floor += static_cast<double>(q->min_weight) * bound;
    largest = largest < bound ? bound : largest;
    widest += static_cast<double>(q->max_weight) * bound;
    budget -= q->min_weight;
    if (const auto index = q - begin; kRefine && index < kMaxJoints) {
      u[index] = bound;
      span[index] = q->max_weight - q->min_weight;
    }
  }
  budget = std::max(budget, 0.0);
  // lambda = 0 and lambda = max_g U_g hold for any number of joints; the other breakpoints
  // are tried for lists of up to kMaxJoints (a cluster's few joints).
  const Lanes4 at_largest = floor + largest * budget;
  out = at_largest < widest ? at_largest : widest;
  if (!kRefine || end - begin > kMaxJoints) return;
  const auto above = out > threshold;
  if (!(above[0] || above[1] || above[2] || above[3])) return;
  // f at the breakpoints lambda = U_b (lambda = 0 is `widest`), each over the lanes at once.
  for (int b = 0; b < count; ++b) {
    Lanes4 value = floor + u[b] * budget;
    for (int g = 0; g < count; ++g) {
      const Lanes4 past = u[g] - u[b];
      value += span[g] * (0.0 < past ? past : Lanes4{});
    }
    out = value < out ? value : out;
  }
}

constexpr int kVertexLanes = Character::kClusterLanes;

// |d_i|^2, d_i = sum_g w_ig Delta_g [v0_i; 1], of kVertexLanes vertices of a cluster in one
// frame, from its lane block (Character::cluster_lanes: rows of `padded` floats, read from
// the chunk's column on) and Delta_g of its influences' joints g (entry 3a + i, Delta_g(i,
// a), at delta[(12 g + 3a + i) * kDeltaLanes]: the maximum search's float lanes).
// Each blended entry of the 8 vertices is one vector (a 256-bit register in the AVX2
// version): a vertex at a time, the blends ran 128 bits wide through each vertex's own
// influence list, with a horizontal sum at the end. Written with vector types: from plain
// loops over the lanes GCC read the second and third coordinate rows one float at a time
// (it could not prove `padded + v` contiguous) and kept the blend in memory.
template <int kDeltaLanes>
inline float ChunkSquaredErrors(const float* rows, uint32_t padded,
                                const Character::InfluenceRange* influences,
                                uint32_t influence_count, const float* delta, float* squared) {
  static_assert(kVertexLanes == 8, "a chunk is one Lanes8f per row");
  const size_t row = padded;
  Lanes8f blended[12];  // entry 3a + i: the blended Delta(i, a)
  {
    const Lanes8f weight = *AsLanes8f(rows + 3 * row);
    const float* entries = delta + static_cast<size_t>(influences[0].joint) * 12 * kDeltaLanes;
#pragma GCC unroll 12
    for (int e = 0; e < 12; ++e) blended[e] = weight * entries[e * kDeltaLanes];
  }
  for (uint32_t g = 1; g < influence_count; ++g) {
    const Lanes8f weight = *AsLanes8f(rows + (3 + g) * row);
    const float* entries = delta + static_cast<size_t>(influences[g].joint) * 12 * kDeltaLanes;
#pragma GCC unroll 12
    for (int e = 0; e < 12; ++e) blended[e] += weight * entries[e * kDeltaLanes];
  }
  const Lanes8f x = *AsLanes8f(rows), y = *AsLanes8f(rows + row), z = *AsLanes8f(rows + 2 * row);
  Lanes8f length_squared = {};
#pragma GCC unroll 3
  for (int i = 0; i < 3; ++i) {
    const Lanes8f moved = blended[i] * x + blended[3 + i] * y + blended[6 + i] * z + blended[9 + i];
    length_squared += moved * moved;
  }
  float largest[kVertexLanes];
  for (int v = 0; v < kVertexLanes; ++v) {
    squared[v] = length_squared[v];
    largest[v] = length_squared[v];
  }
  for (int width = kVertexLanes / 2; width > 0; width /= 2) {
    for (int v = 0; v < width; ++v) largest[v] = std::max(largest[v], largest[v + width]);
  }
  return largest[0];
}

}  // namespace

PreparedMotion::Impl::MaxSearchBounds PreparedMotion::Impl::MakeMaxSearchBounds(
    const std::vector<uint8_t>* group_mask, const std::vector<uint8_t>& moving) const {
  const Character& c = *character;
  const auto& group_clusters = c.group_cluster_offsets();
  const auto& group_influence_offsets = c.group_influence_offsets();
  const auto& group_influences = c.group_influences();
  MaxSearchBounds bounds;
  bounds.groups.reserve(n);
  bounds.joints.reserve(n);
  std::vector<uint8_t> weights_a_group(n, 0);
  for (int j = 0; j < n; ++j) {
    if (group_clusters[j] == group_clusters[j + 1] || (group_mask != nullptr && !(*group_mask)[j])) continue;
    bool moved = false;
    for (uint32_t q = group_influence_offsets[j]; q < group_influence_offsets[j + 1]; ++q) {
      moved = moved || moving[group_influences[q].joint];
    }
    if (!moved) continue;
    bounds.groups.push_back(j);
    for (uint32_t q = group_influence_offsets[j]; q < group_influence_offsets[j + 1]; ++q) {
      weights_a_group[group_influences[q].joint] = 1;
    }
  }
  for (int k = 0; k < n; ++k) {
    if (weights_a_group[k] && moving[k]) bounds.joints.push_back(k);
  }
  bounds.group_bound.assign(static_cast<size_t>(frames) * n, 0.0);
  bounds.frame_bound.assign(frames, 0.0);
  bounds.joint_bound.assign(static_cast<size_t>(n) * kGroupBoundFrames, 0.0);
  return bounds;
}

void PreparedMotion::Impl::FrameBounds(const DeltaView& delta, int t, MaxSearchBounds& bounds) const {
  if (t % kGroupBoundFrames != kGroupBoundFrames - 1 && t != frames - 1) return;
  RunWithWidestSimd([&] {
    // Coarse bounds for every group from the joints' own boxes (one box bound per joint); a
    // visited group is refined with its own box.
    const Character& c = *character;
    const auto& group_influence_offsets = c.group_influence_offsets();
    const auto& group_influences = c.group_influences();
    static_assert(kGroupBoundFrames == 4, "a batch's bounds are one Lanes4");
    const int batch_first = t - t % kGroupBoundFrames, batch_frames = t - batch_first + 1;
    // Delta_k's rows read as DeltaView::Frame forms them, without a copy of the frames; a
    // batch past the last frame repeats its last frame in the lanes it lacks, unused.
    const Eigen::Index s_stride = delta.solution->rows(), o_stride = delta.original->rows();
    const double* s_frame[kGroupBoundFrames];
    const double* o_frame[kGroupBoundFrames];
    for (int f = 0; f < kGroupBoundFrames; ++f) {
      const int frame = batch_first + std::min(f, batch_frames - 1);
      s_frame[f] = delta.solution->data() + 3 * frame * s_stride;
      o_frame[f] = delta.original->data() + 3 * frame * o_stride;
    }
    const int* s_row = delta.solution_row.data();
    // U_k for each joint's own box in the batch's frames (LaneDelta::BoxBounds), one frame
    // per lane, stored as one vector. (Frame by frame with four joints in the lanes, each
    // frame's U_k and the column norms the search read were stored one double at a time.)
    static_assert(LaneDelta::kLanes == kGroupBoundFrames);
    LaneDelta lanes;
    for (int k : bounds.joints) {
      lanes.Fill(s_frame, o_frame, s_stride, o_stride, s_row[k], 4 * k);
      Lanes4 u;
      lanes.BoxBounds(c.joint_vertex_centers()[k], c.joint_vertex_half_extents()[k], u);
      *AsLanes4(bounds.joint_bound.data() + static_cast<size_t>(k) * kGroupBoundFrames) = u;
    }
    // The groups' bounds of the batch, one frame per lane: a frame at a time, the weighted
    // bound of each group was scalar, most of FrameBounds' time.
    Lanes4 batch_bound = {};  // each frame's largest group bound
    for (int j : bounds.groups) {
      Lanes4 group;
      WeightedBound<false>(
          group_influences.data() + group_influence_offsets[j],
          group_influences.data() + group_influence_offsets[j + 1],
          std::numeric_limits<double>::infinity(),
          [&](int g, Lanes4& u) {
            u = *AsLanes4(bounds.joint_bound.data() + static_cast<size_t>(g) * kGroupBoundFrames);
          },
          group);
      // A whole batch as one vector: a copy of batch_frames doubles was a call to memcpy.
      double* group_bound = bounds.group_bound.data() + static_cast<size_t>(j) * frames + batch_first;
      if (batch_frames == kGroupBoundFrames) {
        *AsLanes4(group_bound) = group;
      } else {
        for (int f = 0; f < batch_frames; ++f) group_bound[f] = group[f];
      }
      batch_bound = batch_bound < group ? group : batch_bound;
    }
    for (int f = 0; f < batch_frames; ++f) bounds.frame_bound[batch_first + f] = batch_bound[f];
  });
}

PreparedMotion::Impl::MaxSearchStart PreparedMotion::Impl::MaxVertexError(
    const DeltaView& delta, const MaxSearchBounds& bounds, double decide_within,
    const MaxSearchStart& start, const std::vector<uint8_t>* cluster_mask, LevelErrors& out) const {
  return RunWithWidestSimd([&]() -> MaxSearchStart {
    // Exact maximum of |d_i(t)|, d_i(t) = sum_g w_ig Delta_g(t) [v0_i; 1], over all vertices
    // and frames without evaluating most of them. For a box with center c and half extents
    // h in the bind pose, every vertex v in it has
    //   |Delta_g [v;1]| <= U_g(t) = |Delta_g [c;1]| + sum_a |Delta_g(3x3) e_a| h_a,
    // so a set of vertices whose joints g give them weights in [a_g, b_g] has, by the
    // triangle inequality, |d_i| <= max sum_g w_g U_g over weights in those ranges that
    // sum to 1 (WeightedBound: at most min(max_g U_g, sum_g b_g U_g), often much less).
    // Bounds nest: per frame and vertex group (dominant joint) from the joints' boxes
    // (FrameBounds), then from the group's box, then per cluster; frames and groups are
    // visited by decreasing bound and only clusters whose bound beats the best exact value
    // so far are evaluated.
    // Bounds below kNegligible of the height are not refined: a level that close to exact
    // reports its maximum to within 1e-4 % of the height (0.01 px on a 10000 px tall
    // character). That is the resolution of the streamed float matrices themselves (their
    // rounding moves a vertex by about 1e-7 of its distance from the origin), and it keeps
    // the rigid full level of a rig whose matrices are rotations only to float precision
    // (most glTF and FBX files) from visiting every vertex of every frame.
    constexpr double kNegligible = 1e-6;
    const Character& c = *character;
    const auto& group_clusters = c.group_cluster_offsets();
    const auto& group_influence_offsets = c.group_influence_offsets();
    const auto& group_influences = c.group_influences();
    const auto& cluster_vertex_offsets = c.cluster_vertex_offsets();
    const auto& cluster_vertices = c.cluster_vertices();
    const auto& cluster_influence_offsets = c.cluster_influence_offsets();
    const auto& cluster_influences = c.cluster_influences();

    std::vector<int> frame_order(frames);
    std::iota(frame_order.begin(), frame_order.end(), 0);
    std::sort(frame_order.begin(), frame_order.end(),
              [&](int a, int b) { return bounds.frame_bound[a] > bounds.frame_bound[b]; });

    float best_squared = start.best_squared;  // the float |d_i|^2 whose root is `best`
    double best = std::sqrt(static_cast<double>(best_squared));
    int best_frame = start.frame, best_vertex = start.vertex;
    // Nothing at or below `floor` is refined: negligible, or within the decision's bound.
    const double floor =
        std::max(kNegligible * c.height(), std::isfinite(decide_within) ? decide_within : 0.0);
    // Frames are searched in batches of kLanes, taken in that order: every bound is computed
    // for the whole batch at once, one frame per lane of a vector (the frames of a batch
    // have similar bounds, and most of them need the same groups and clusters bounded).
    constexpr int kLanes = LaneDelta::kLanes;
    static_assert(kLanes == 4, "a batch's Delta_k is transposed as Lanes4");
    std::vector<LaneDelta> lane_delta(n);
    // The exact evaluations blend in float (the skin's own precision): twice the throughput,
    // and the figure is a display quantity. Entry (12 k + 3a + i) kLanes + f: Delta_k(i, a)
    // of lane f's frame.
    std::vector<float> lane_delta_f(static_cast<size_t>(n) * 12 * kLanes);
    const double* solution = delta.solution->data();
    const double* original = delta.original->data();
    const Eigen::Index s_stride = delta.solution->rows(), o_stride = delta.original->rows();
    const int* s_row = delta.solution_row.data();
    std::vector<std::pair<double, int>> group_order;  // (largest lane bound, group)
    group_order.reserve(n);
    // The batch whose lanes joint k holds, -1 for the joints outside bounds.joints.
    std::vector<int> filled_in_batch(n, -1);
    for (int k : bounds.joints) filled_in_batch[k] = 0;
    int batch = 0;
    // The bounds of a group's or a cluster's vertices (entry `index` of a CSR list of
    // influences) from their box, per lane.
    const auto weighted_box_bounds = [&](const std::vector<Character::InfluenceRange>& influences,
                                         const std::vector<uint32_t>& offsets, size_t index,
                                         const Vec3d& center, const Vec3d& half, double* bound) {
      Lanes4 lanes;
      WeightedBound<true>(
          influences.data() + offsets[index], influences.data() + offsets[index + 1],
          std::max(best, floor), [&](int g, Lanes4& u) { lane_delta[g].BoxBounds(center, half, u); },
          lanes);
      *AsLanes4(bound) = lanes;
    };
    // A lambda, so that a decided search returns from every loop at once.
    const auto search = [&] {
      for (size_t first = 0; first < frame_order.size(); first += kLanes) {
        if (bounds.frame_bound[frame_order[first]] <= std::max(best, floor)) break;
        // A batch past the last frame repeats its first frame in the lanes it lacks, unused.
        int lane_frame[kLanes];
        bool lane_used[kLanes];
        for (int f = 0; f < kLanes; ++f) {
          lane_used[f] = first + f < frame_order.size();
          lane_frame[f] = frame_order[lane_used[f] ? first + f : first];
        }
        // Delta_k of the batch's frames in lanes (LaneDelta::Fill), for the joints that
        // weight the groups the batch refines (and so their clusters), each the first time
        // one needs it: all of them up front transposed joints that most batches never read.
        // A joint outside bounds.joints keeps the zero lanes it started with (its Delta is
        // zero).
        const double* s_frame[kLanes];
        const double* o_frame[kLanes];
        for (int f = 0; f < kLanes; ++f) {
          s_frame[f] = solution + 3 * lane_frame[f] * s_stride;
          o_frame[f] = original + 3 * lane_frame[f] * o_stride;
        }
        ++batch;
        const auto fill_lanes = [&](int j) {
          for (uint32_t q = group_influence_offsets[j]; q < group_influence_offsets[j + 1]; ++q) {
            const int k = group_influences[q].joint;
            if (filled_in_batch[k] == batch || filled_in_batch[k] < 0) continue;
            filled_in_batch[k] = batch;
            LaneDelta& lanes = lane_delta[k];
            lanes.Fill(s_frame, o_frame, s_stride, o_stride, s_row[k], 4 * k);
            float* lanes_f = lane_delta_f.data() + static_cast<size_t>(k) * 12 * kLanes;
            for (int e = 0; e < 12; ++e) {
              *AsLanes4f(lanes_f + e * kLanes) =
                  __builtin_convertvector(*AsLanes4(lanes.m[e]), Lanes4f);
            }
          }
        };
        const auto group_bound = [&](int f, int j) {
          return lane_used[f] ? bounds.group_bound[static_cast<size_t>(j) * frames + lane_frame[f]]
                              : 0.0;
        };
        // Only the groups that can beat the best so far in some lane, by decreasing bound.
        group_order.clear();
        for (int j : bounds.groups) {
          double largest = 0;
          for (int f = 0; f < kLanes; ++f) largest = std::max(largest, group_bound(f, j));
          if (largest > std::max(best, floor)) group_order.emplace_back(largest, j);
        }
        std::sort(group_order.begin(), group_order.end(),
                  [](const auto& a, const auto& b) { return a.first > b.first; });
        for (const auto& [largest, j] : group_order) {
          if (largest <= std::max(best, floor)) break;
          fill_lanes(j);
          bool open[kLanes];  // the lanes whose bound beats the best so far
          double refined[kLanes];
          weighted_box_bounds(group_influences, group_influence_offsets, j, c.group_centers()[j],
                              c.group_half_extents()[j], refined);
          bool any_open = false;
          for (int f = 0; f < kLanes; ++f) {
            open[f] =
                group_bound(f, j) > std::max(best, floor) && refined[f] > std::max(best, floor);
            any_open = any_open || open[f];
          }
          if (!any_open) continue;
          for (uint32_t cluster = group_clusters[j]; cluster < group_clusters[j + 1]; ++cluster) {
            if (cluster_mask != nullptr && !(*cluster_mask)[cluster]) continue;
            double cluster_bound[kLanes];
            weighted_box_bounds(cluster_influences, cluster_influence_offsets, cluster,
                                c.cluster_centers()[cluster], c.cluster_half_extents()[cluster],
                                cluster_bound);
            const uint32_t first_vertex = cluster_vertex_offsets[cluster];
            const uint32_t padded =
                Character::ClusterLaneRow(cluster_vertex_offsets[cluster + 1] - first_vertex);
            const float* block = c.cluster_lanes().data() + c.cluster_lane_offsets()[cluster];
            for (int f = 0; f < kLanes; ++f) {
              if (!open[f] || cluster_bound[f] <= std::max(best, floor)) continue;
              for (uint32_t chunk = 0; chunk < padded; chunk += kVertexLanes) {
                float squared[kVertexLanes];
                const float largest = ChunkSquaredErrors<kLanes>(
                    block + chunk, padded,
                    cluster_influences.data() + cluster_influence_offsets[cluster],
                    cluster_influence_offsets[cluster + 1] - cluster_influence_offsets[cluster],
                    lane_delta_f.data() + f, squared);
                if (!(largest > best_squared)) continue;
                // Compared squared (sqrt is monotonic): the square root, its conversion and a
                // compare with `best` in memory were a fifth of the search's time per vertex.
                for (int v = 0; v < kVertexLanes; ++v) {
                  if (squared[v] > best_squared) {
                    best_squared = squared[v];
                    best = std::sqrt(static_cast<double>(squared[v]));
                    best_frame = lane_frame[f];
                    best_vertex = static_cast<int>(cluster_vertices[first_vertex + chunk + v]);
                    if (best > decide_within) return;
                  }
                }
              }
            }
          }
        }
      }
    };
    search();
    out.max_vertex_error_pct = 100.0 * best / c.height();
    out.max_vertex_frame = best_frame;
    out.max_vertex_index = best_vertex;
    return MaxSearchStart{best_squared, best_frame, best_vertex};
  });
}

void PreparedMotion::Impl::SampleFrameValues(const Eigen::Matrix<double, Eigen::Dynamic, 3>& frame,
                                             size_t q, const std::vector<uint32_t>* vertices,
                                             SampleScratch& scratch, SampleValues& values) const {
  RunWithWidestSimd([&] {
    // Blends in float, as the maximum search: the rounding is relative to Delta itself.
    // Column a of Delta_k (a zero last row) is lane a of frame's three columns of joint k
    // and of zero: transposed as whole vectors and stored one column at a time (Eigen's
    // transposed cast stored one float at a time, and the blends read them back as vectors).
    std::vector<PaddedDelta>& frame_delta = scratch.frame_delta;
    const double* columns = frame.data();
    const Eigen::Index stride = frame.rows();
    for (int k = 0; k < n; ++k) {
      const Lanes4 rows[4] = {*AsLanes4(columns + 4 * k), *AsLanes4(columns + stride + 4 * k),
                              *AsLanes4(columns + 2 * stride + 4 * k), Lanes4{}};
      Lanes4 delta_columns[4];
      Transpose4(rows, delta_columns);
      float* target = frame_delta[k].data();
      for (int a = 0; a < 4; ++a) {
        *AsLanes4f(target + 4 * a) = __builtin_convertvector(delta_columns[a], Lanes4f);
      }
    }
    const size_t all = sample_vertices.size();
    const size_t count = vertices ? vertices->size() : all;
    const double* normals = sample_normals.data() + 4 * q * all;
    // A subset's original normals are gathered into rows of its own length, as ChordAngles
    // reads them.
    if (vertices) {
      for (size_t e = 0; e < count; ++e) {
        for (int row = 0; row < 4; ++row)
          scratch.normals[row * count + e] = normals[row * all + (*vertices)[e]];
      }
      normals = scratch.normals.data();
    }
    for (size_t e = 0; e < count; ++e) {
      const size_t v = vertices ? (*vertices)[e] : e;
      const SampleVertex& sample = sample_vertices[v];
      PaddedDelta blended = PaddedDelta::Zero();
      for (uint32_t g = v == 0 ? 0 : sample_vertices[v - 1].influence_end; g < sample.influence_end;
           ++g) {
        blended.noalias() += sample_influences[g].weight * frame_delta[sample_influences[g].joint];
      }
      const Eigen::Vector4d d =
          (blended.leftCols<3>() * sample.position + blended.col(3)).cast<double>();
      const Eigen::Vector4d dn = (blended.leftCols<3>() * sample.normal).cast<double>();
      values.distance_squared[v] = d.squaredNorm();
      values.normal_squared[v] = dn.x() * dn.x() + dn.y() * dn.y() + dn.z() * dn.z();
      scratch.normal_x[e] = dn.x();
      scratch.normal_y[e] = dn.y();
      scratch.normal_z[e] = dn.z();
    }
    ChordAngles(count, normals, scratch.normal_x.data(), scratch.normal_y.data(),
                scratch.normal_z.data(), scratch.angle.data());
    for (size_t e = 0; e < count; ++e) {
      // No direction to compare (n or n + dn zero): no angle.
      const double angle = std::isnan(scratch.angle[e]) ? 0.0 : FinishChordAngle(scratch.angle[e]);
      values.angle[vertices ? (*vertices)[e] : e] = angle;
    }
  });
}

void PreparedMotion::Impl::AddSampleSums(const SampleValues& values, SampleSums& sums) const {
  for (size_t v = 0; v < sample_vertices.size(); ++v) {
    const double area = sample_vertices[v].area;
    sums.distance += area * std::sqrt(values.distance_squared[v]);
    sums.distance_squared += area * values.distance_squared[v];
    sums.angle += area * values.angle[v];
    sums.normal_squared += area * values.normal_squared[v];
  }
}

namespace {

// The normal equations of one level: G (4m x 4m, lambda included, in 4x4 blocks), B
// (4m x 3T) and their solution X. B is kept transposed (3T x 4m: 4 contiguous columns of
// all frames per kept joint), the layout BlockCholesky::SolveTransposed works in.
struct LevelSystem {
  BlockSymmetric<4> g;
  MatrixXd bt, x;  // bt: moved into the solve (empty after it) unless nothing is removed
  // The rigid re-solve's right-hand sides (3T x m): B^T's translation columns, 4s + 3.
  MatrixXd translation_bt;
};

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

// Whether every 3x3 block of x (4m x 3T, one 4x3 block per kept joint and frame) is a
// rotation to within the precision of float source data, |R^T R - I|_F <= 1e-5 (the
// tolerance the rigid variants' stored matrices are held to). Composed through a
// skeleton's hierarchy, the float matrices of glTF, FBX and Collada files are orthonormal
// to 3e-6 to 8e-6 (2e-16 for BVH, whose rotations are built in double).
// Four joints of a frame at a time, one per lane: each column of their blocks (four
// contiguous doubles, the translation's last) is transposed into lanes (Transpose4), and
// the column products of R^T R and the determinant (the columns' triple product) are whole
// vectors; the last group repeats its last joint. (A matrix at a time through Eigen, this
// check was half of a rigid bake's full level.) Inline, so that a caller's AVX2 version
// (base/simd.h) runs it 256 bits wide.
inline bool AllRotations(const MatrixXd& x) {
  const Eigen::Index joints = x.rows() / 4, stride = x.rows();
  for (Eigen::Index t = 0; t < x.cols(); t += 3) {
    const double* frame = x.data() + t * stride;
    for (Eigen::Index first = 0; first < joints; first += 4) {
      Lanes4 column[3][4];  // column[c][i]: R(i, c) of the four joints
      for (int c = 0; c < 3; ++c) {
        Lanes4 blocks[4];
        for (Eigen::Index j = 0; j < 4; ++j) {
          blocks[j] = *AsLanes4(frame + c * stride + 4 * std::min(first + j, joints - 1));
        }
        Transpose4(blocks, column[c]);
      }
      Lanes4 gram[3][3];  // R^T R - I, its upper triangle
      for (int a = 0; a < 3; ++a) {
        for (int b = a; b < 3; ++b) {
          gram[a][b] = column[a][0] * column[b][0] + column[a][1] * column[b][1] +
                       column[a][2] * column[b][2] - (a == b ? 1.0 : 0.0);
        }
      }
      const Lanes4 error_squared =
          gram[0][0] * gram[0][0] + gram[1][1] * gram[1][1] + gram[2][2] * gram[2][2] +
          2 * (gram[0][1] * gram[0][1] + gram[0][2] * gram[0][2] + gram[1][2] * gram[1][2]);
      const Lanes4* c0 = column[0];
      const Lanes4* c1 = column[1];
      const Lanes4* c2 = column[2];
      const Lanes4 determinant = c0[0] * (c1[1] * c2[2] - c1[2] * c2[1]) -
                                 c0[1] * (c1[0] * c2[2] - c1[2] * c2[0]) +
                                 c0[2] * (c1[0] * c2[1] - c1[1] * c2[0]);
      const auto rotation = (error_squared <= 1e-10) & (determinant > 0);
      for (int j = 0; j < 4; ++j) {
        if (rotation[j] == 0) return false;
      }
    }
  }
  return true;
}

StatusOr<LevelSystem> SolveSystem(const PreparedMotion::Impl& d, const ReducedSkeleton& level) {
  if (Status status = ValidateLevel(level, d.n); !status.ok()) return status;
  const int n = d.n;
  const int m = level.kept_count();
  const int dim = 4 * m;
  const int cols = 3 * d.frames;
  const std::vector<int>& phi = level.joint_to_slot;
  LevelSystem system;

  // G = P Q P^T + S J S^T + lambda I.
  BlockSymmetric<4>& g = system.g;
  g = BlockSymmetric<4>(m, d.pairs.size());  // at most a block per joint pair
  for (size_t q = 0; q < d.pairs.size(); ++q) {
    const auto [k, l] = d.pairs[q];
    if (k == l) {
      g.AddDiagonal(phi[k], d.pair_fit[q]);
    } else {
      g.AddPair(phi[k], phi[l], d.pair_fit[q]);
    }
  }
  for (int s = 0; s < m; ++s) g.AddDiagonal(s, d.joint_fit[level.kept_joints[s]]);
  const double trace = g.Trace();
  const double lambda = d.settings.regularization * (trace > 0 ? trace / dim : 1.0);
  g.AddIdentity(lambda);

  // B^T = (P F + S (J + lambda I) Kt)^T, slot by slot: its 4 columns of all frames (one
  // contiguous panel) start as F of its kept joint, gain F of each joint merged into it
  // (ancestors come first: the same sums in the same order as from zero), then
  // (J + lambda I) Kt of its kept joint. Plain loops over whole panels, which the AVX2
  // version runs 256 bits wide; Eigen's column blocks kept 128-bit packets.
  MatrixXd& bt = system.bt;
  bt.resize(cols, dim);
  const Eigen::Index panel = 4 * static_cast<Eigen::Index>(cols);
  for (int s = 0; s < m; ++s) {
    std::copy_n(d.ft.col(4 * level.kept_joints[s]).data(), panel, bt.col(4 * s).data());
  }
  for (int k = 0; k < n; ++k) {
    if (level.kept_joints[phi[k]] == k) continue;
    double* __restrict target = bt.col(4 * phi[k]).data();
    const double* source = d.ft.col(4 * k).data();
    for (Eigen::Index i = 0; i < panel; ++i) target[i] += source[i];
  }
  for (int s = 0; s < m; ++s) {
    const int j = level.kept_joints[s];
    AddKtProduct(bt.col(4 * s).data(), d.kt, j,
                 d.joint_fit[j] + lambda * Eigen::Matrix4d::Identity());
  }

  if (IsRigid(d.settings.variant) && d.settings.resolve_rigid_translation) {
    system.translation_bt.resize(cols, m);
    for (int s = 0; s < m; ++s) system.translation_bt.col(s) = bt.col(4 * s + 3);
  }
  if (m == n) {
    // Nothing removed: the original matrices leave no residual and are what the
    // regulariser pulls towards, so they are the exact minimiser (SolveVariant skips the
    // system altogether where the level needs nothing else).
    system.x = d.kt;
    return system;
  }
  // G is block-sparse (kept joints that share vertices) and nearly a tree: its block
  // Cholesky factor solves the 3T right-hand sides in time nearly linear in m instead of
  // quadratic.
  auto factor = BlockCholesky<4>::Factor(g);
  if (!factor.ok()) return factor.status();
  system.x = factor->SolveTransposed(std::move(bt));
  return system;
}

}  // namespace

StatusOr<Eigen::MatrixXd> PreparedMotion::SolveLeastSquares(const ReducedSkeleton& level) const {
  auto system = SolveSystem(*impl_, level);
  if (!system.ok()) return system.status();
  return std::move(system->x);
}

namespace {

// A level's matrices in the variant: the least-squares solution, projected on rotations
// and with re-solved translations for the rigid variants (4m x 3T, as LevelSystem::x), and
// the view of its Delta_k = K'_phi(k) - K_k for the errors.
struct VariantSolution {
  MatrixXd x;  // empty where unchanged
  // The solution is the original matrices: nothing removed, nothing projected.
  bool unchanged = false;

  const MatrixXd& Matrices(const PreparedMotion::Impl& d) const { return unchanged ? d.kt : x; }

  // Reads x, so it lives as long as this.
  PreparedMotion::Impl::DeltaView Delta(const PreparedMotion::Impl& d, const ReducedSkeleton& level) const {
    PreparedMotion::Impl::DeltaView view{unchanged ? &d.kt : &x, std::vector<int>(d.n), &d.kt};
    for (int k = 0; k < d.n; ++k) view.solution_row[k] = unchanged ? 4 * k : 4 * level.joint_to_slot[k];
    return view;
  }
};

StatusOr<VariantSolution> SolveVariant(const PreparedMotion::Impl& d, const ReducedSkeleton& level) {
  return RunWithWidestSimd([&]() -> StatusOr<VariantSolution> {
    if (Status status = ValidateLevel(level, d.n); !status.ok()) return status;
    const int n = d.n;
    const int m = level.kept_count();
    // With every joint kept, the original matrices are the least-squares solution
    // (SolveSystem), and original matrices that are rotations already (to within their
    // source's float precision) are the constrained minimiser too (no residual): they are
    // the level as they are, without the system (the right-hand sides alone are 3T x 4n),
    // and the rigid variants keep them bit for bit, as the fitted ones do, instead of
    // projecting them by a few 1e-6, re-solving them and measuring an error of 1e-13.
    if (m == n && (!IsRigid(d.settings.variant) || AllRotations(d.kt))) {
      return VariantSolution{MatrixXd(), true};
    }
    auto system = SolveSystem(d, level);
    if (!system.ok()) return system.status();
    const int cols = 3 * d.frames;
    const BlockSymmetric<4>& g = system->g;
    MatrixXd& x = system->x;

    if (IsRigid(d.settings.variant)) {
      // x holds each K'^T: the polar factor of a transpose is the transpose of the factor.
      // Projected where they are, joint by joint: a batch of NearestRotations steps until
      // its slowest matrix converges, and a joint's matrices in consecutive frames converge
      // alike, where the joints of one frame did not (a fifth fewer steps on real rigs'
      // ladders, and a third to a seventh of the batches that need Newton's inverses).
      std::vector<double*> rotations(static_cast<size_t>(d.frames) * m);
      for (int s = 0; s < m; ++s) {
        for (int t = 0; t < d.frames; ++t)
          rotations[static_cast<size_t>(s) * d.frames + t] = x.data() + 3 * t * x.rows() + 4 * s;
      }
      NearestRotations(rotations, x.rows());
      if (d.settings.resolve_rigid_translation) {
        // x_T = G_TT^-1 (b_T - G_TN x_N): translations are rows 4s+3, the rest is fixed.
        // The right-hand sides transposed, as SolveTransposed takes them: b_T^T - x_N^T G_TN^T.
        // G_TT and G_TN keep G's block sparsity: G_TT is a block matrix of 1x1 blocks, and
        // each coefficient of G_TN subtracts one contiguous column of all frames.
        // x_N^T: the rotations' rows of x, transposed.
        MatrixXd x_nt(cols, 3 * m);
        TransposeRotationRows(x, x_nt);
        const Eigen::Index nt_stride = x_nt.rows();
        const double* nt_data = x_nt.data();
        BlockSymmetric<1> g_tt(m, g.lower().size());
        // Row s of G_TN as its couplings to the slots u of its blocks (G_su(3, 0..2): the
        // diagonal block first, then the others in G's order), so that each slot's
        // right-hand sides are summed in registers, eight frames' columns at a time, and
        // stored once (a pass over the blocks read and wrote every right-hand side once per
        // block).
        struct Coupling {
          int u;
          double g[3];
        };
        std::vector<int> coupling_offsets(m + 1, 0);
        for (const auto& block : g.lower()) {
          ++coupling_offsets[block.row + 1];
          ++coupling_offsets[block.col + 1];
        }
        for (int s = 0; s < m; ++s) coupling_offsets[s + 1] += coupling_offsets[s] + 1;
        std::vector<Coupling> couplings(coupling_offsets[m]);
        std::vector<int> filled(coupling_offsets.begin(), coupling_offsets.end() - 1);
        for (int s = 0; s < m; ++s) {
          const Eigen::Matrix4d& g_ss = g.diagonal(s);
          couplings[filled[s]++] = {s, {g_ss(3, 0), g_ss(3, 1), g_ss(3, 2)}};
          g_tt.AddDiagonal(s, g_ss.bottomRightCorner<1, 1>());
        }
        for (const auto& block : g.lower()) {  // G(row, col) and its transpose G(col, row)
          const Eigen::Matrix4d& v = block.value;
          g_tt.AddPair(block.row, block.col, v.bottomRightCorner<1, 1>());
          couplings[filled[block.row]++] = {block.col, {v(3, 0), v(3, 1), v(3, 2)}};
          couplings[filled[block.col]++] = {block.row, {v(0, 3), v(1, 3), v(2, 3)}};
        }
        // In place: each right-hand side is read before its own value is written.
        MatrixXd x_tt = std::move(system->translation_bt);
        for (int s = 0; s < m; ++s) {
          const Coupling* begin = couplings.data() + coupling_offsets[s];
          const Coupling* end = couplings.data() + coupling_offsets[s + 1];
          double* rhs = x_tt.col(s).data();
          int col = 0;
          for (; col + 8 <= cols; col += 8) {
            Lanes4 sum0 = *AsLanes4(rhs + col), sum1 = *AsLanes4(rhs + col + 4);
            for (const Coupling* c = begin; c != end; ++c) {
              const double* x0 = nt_data + 3 * c->u * nt_stride + col;
              const double* x1 = x0 + nt_stride;
              const double* x2 = x1 + nt_stride;
              sum0 -= c->g[0] * *AsLanes4(x0) + c->g[1] * *AsLanes4(x1) + c->g[2] * *AsLanes4(x2);
              sum1 -= c->g[0] * *AsLanes4(x0 + 4) + c->g[1] * *AsLanes4(x1 + 4) +
                      c->g[2] * *AsLanes4(x2 + 4);
            }
            *AsLanes4(rhs + col) = sum0;
            *AsLanes4(rhs + col + 4) = sum1;
          }
          for (; col < cols; ++col) {
            double sum = rhs[col];
            for (const Coupling* c = begin; c != end; ++c) {
              const double* x0 = nt_data + 3 * c->u * nt_stride + col;
              sum -= c->g[0] * x0[0] + c->g[1] * x0[nt_stride] + c->g[2] * x0[2 * nt_stride];
            }
            rhs[col] = sum;
          }
        }
        auto factor = BlockCholesky<1>::Factor(g_tt);
        if (!factor.ok()) return factor.status();
        const MatrixXd translations = factor->SolveTransposed(std::move(x_tt));
        for (int col = 0; col < cols; ++col) {
          for (int s = 0; s < m; ++s) x(4 * s + 3, col) = translations(s, col);
        }
      }
    }
    return VariantSolution{std::move(x), false};
  });
}

}  // namespace

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
  const Impl& d = *impl_;
  auto solution = SolveVariant(d, level);
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
  d.EvaluateErrors(solution->Delta(d, level), level.kept_joints, Impl::Figures::kAll, result.optimized,
                   std::numeric_limits<double>::infinity(), run);
  return result;
}

PreparedMotion::Impl::DeltaView PreparedMotion::Impl::BaselineDelta(const ReducedSkeleton& level) const {
  DeltaView baseline{&kt, std::vector<int>(n), &kt};
  for (int k = 0; k < n; ++k) baseline.solution_row[k] = 4 * level.kept_joints[level.joint_to_slot[k]];
  return baseline;
}

StatusOr<LevelErrors> PreparedMotion::BaselineErrors(const ReducedSkeleton& level,
                                                     const PieceRunner& run) const {
  const Impl& d = *impl_;
  if (Status status = ValidateLevel(level, d.n); !status.ok()) return status;
  LevelErrors errors;
  d.EvaluateErrors(d.BaselineDelta(level), level.kept_joints, Impl::Figures::kAll, errors,
                   std::numeric_limits<double>::infinity(), run);
  return errors;
}

struct BaselineSequence::State {
  std::shared_ptr<const PreparedMotion> prepared;
  std::vector<uint8_t> kept;      // n: the joints the last level kept
  std::vector<int> solution_row;  // n: its baseline's DeltaView::solution_row
  // Every joint pair's PairTerms in every frame (T rows of |pairs|), for its Delta.
  std::vector<double> pair_p, pair_n;
  // Every sampled frame's SampleValues.
  std::vector<PreparedMotion::Impl::SampleValues> sample_values;
  PreparedMotion::Impl::MaxSearchStart maximum;  // its exact maximum
  LevelErrors last;
};

BaselineSequence::BaselineSequence(std::shared_ptr<const PreparedMotion> prepared)
    : state_(std::make_unique<State>()) {
  State& st = *state_;
  const PreparedMotion::Impl& d = *prepared->impl_;
  st.prepared = std::move(prepared);
  // Before the first level: the full skeleton, whose Delta is zero.
  st.kept.assign(d.n, 1);
  st.solution_row.resize(d.n);
  for (int k = 0; k < d.n; ++k) st.solution_row[k] = 4 * k;
  st.pair_p.assign(static_cast<size_t>(d.frames) * d.pairs.size(), 0.0);
  st.pair_n.assign(static_cast<size_t>(d.frames) * d.pairs.size(), 0.0);
  // The sample's values with a zero Delta: zero. (EvaluateErrors measures angles of a few
  // 1e-17 rad where a normal is compared with itself, the same to rounding; computing them
  // here cost each sequence 90 k instructions.)
  st.sample_values.assign(d.sample_frames.size(), PreparedMotion::Impl::SampleValues(d.sample_vertices.size()));
  for (std::vector<double>* part : {&st.last.e, &st.last.ep_vertex, &st.last.ep_joint, &st.last.en_vertex,
                                    &st.last.en_joint}) {
    part->assign(d.frames, 0.0);
  }
}

BaselineSequence::~BaselineSequence() = default;

StatusOr<LevelErrors> BaselineSequence::Next(const ReducedSkeleton& level) {
  return RunWithWidestSimd([&]() -> StatusOr<LevelErrors> {
    State& st = *state_;
    const PreparedMotion::Impl& d = *st.prepared->impl_;
    const Character& c = *d.character;
    const int n = d.n;
    if (Status status = ValidateLevel(level, n); !status.ok()) return status;
    std::vector<uint8_t> kept(n, 0);
    for (int j : level.kept_joints) {
      if (!st.kept[j]) {
        return InvalidArgument("BaselineSequence: the level keeps joint '" +
                               c.skeleton().joint_names[j] +
                               "', which the level before it removed");
      }
      kept[j] = 1;
    }
    const PreparedMotion::Impl::DeltaView delta = d.BaselineDelta(level);
    // The joints whose Delta changes: those whose nearest kept joint does.
    std::vector<uint8_t> changed(n, 0);
    bool any_changed = false;
    for (int k = 0; k < n; ++k) {
      changed[k] = delta.solution_row[k] != st.solution_row[k];
      any_changed = any_changed || changed[k];
    }
    st.kept = std::move(kept);
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
    const std::vector<size_t> active_pairs = d.ActivePairs(delta);
    std::vector<uint8_t> group_mask(n, 0);
    for (int j = 0; j < n; ++j) {
      group_mask[j] =
          weighted_by_changed(c.group_influences().data() + c.group_influence_offsets()[j],
                              c.group_influences().data() + c.group_influence_offsets()[j + 1]);
    }
    const size_t clusters = c.cluster_centers().size();
    std::vector<uint8_t> cluster_mask(clusters, 0);
    for (size_t cluster = 0; cluster < clusters; ++cluster) {
      cluster_mask[cluster] = weighted_by_changed(
          c.cluster_influences().data() + c.cluster_influence_offsets()[cluster],
          c.cluster_influences().data() + c.cluster_influence_offsets()[cluster + 1]);
    }
    std::vector<uint32_t> changed_samples;
    for (size_t v = 0; v < d.sample_vertices.size(); ++v) {
      const uint32_t begin = v == 0 ? 0 : d.sample_vertices[v - 1].influence_end;
      if (weighted_by_changed(d.sample_influences.data() + begin,
                              d.sample_influences.data() + d.sample_vertices[v].influence_end)) {
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
    PreparedMotion::Impl::MaxSearchBounds bounds =
        d.MakeMaxSearchBounds(restart ? nullptr : &group_mask, moving);
    PreparedMotion::Impl::SampleScratch scratch(n, changed_samples.size());
    size_t next_sample = 0;
    const size_t pair_count = d.pairs.size();
    // Only the joints whose Delta the frame's copy serves: the changed pairs' and the
    // changed sampled vertices' (the bounds read theirs from the matrices).
    std::vector<uint8_t> read(n, 0);
    for (size_t q : changed_pairs) read[d.pairs[q].first] = read[d.pairs[q].second] = 1;
    for (uint32_t v : changed_samples) {
      for (uint32_t g = v == 0 ? 0 : d.sample_vertices[v - 1].influence_end;
           g < d.sample_vertices[v].influence_end; ++g) {
        read[d.sample_influences[g].joint] = 1;
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
      for (size_t q : changed_pairs) std::tie(pair_p[q], pair_n[q]) = d.PairTerms(frame, q);
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
      out.ep_vertex[t] = std::max(0.0, LaneSum(ep));
      out.en_vertex[t] = std::max(0.0, LaneSum(en));
      out.e[t] = d.alpha * (out.ep_vertex[t] + out.ep_joint[t]) +
                 d.beta * (out.en_vertex[t] + out.en_joint[t]);
      d.FrameBounds(delta, t, bounds);
      if (next_sample < d.sample_frames.size() && d.sample_frames[next_sample] == t) {
        if (!changed_samples.empty()) {
          d.SampleFrameValues(frame, next_sample, &changed_samples, scratch,
                              st.sample_values[next_sample]);
        }
        ++next_sample;
      }
    }
    st.maximum = d.MaxVertexError(delta, bounds, std::numeric_limits<double>::infinity(),
                                  restart ? PreparedMotion::Impl::MaxSearchStart{} : st.maximum,
                                  restart ? nullptr : &cluster_mask, out);
    PreparedMotion::Impl::SampleSums sums;
    for (const PreparedMotion::Impl::SampleValues& values : st.sample_values)
      d.AddSampleSums(values, sums);
    d.FinishErrors(&sums, out);
    st.last = out;
    return out;
  });
}

StatusOr<bool> PreparedMotion::MaxVertexErrorWithin(const ReducedSkeleton& level, double bound_pct) const {
  if (!(bound_pct > 0)) return InvalidArgument("MaxVertexErrorWithin: the bound must be positive");
  const Impl& d = *impl_;
  auto solution = SolveVariant(d, level);
  if (!solution.ok()) return solution.status();
  LevelErrors errors;
  const double bound = bound_pct / 100.0 * d.character->height();
  d.EvaluateErrors(solution->Delta(d, level), level.kept_joints, Impl::Figures::kMaxVertexError, errors,
                   bound);
  return errors.max_vertex_error_pct <= bound_pct;
}

}  // namespace motionlod::core
