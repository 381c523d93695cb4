// The honest error of a level (core/level_deviation.h).
#include "core/level_deviation.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <string>

#include "core/pose_rate.h"

namespace motionlod::core {
namespace {

constexpr int kFramesPerPiece = 8;
// Float skinning resolves about 1e-7 of the height: a deviation under 1e-6 of it (1e-4 %)
// is the rounding of two blends of the same matrices in another order, reported as 0.
constexpr double kRoundingPct = 1e-4;

// sum_e weights[e] K_{joints[e]} [rest; 1] over `count` influences, in float as a skinner
// blends: the matrices first, then one transform.
template <typename Index>
Vec3f SkinPoint(const std::vector<RowMajorAffine34f>& palette, const Index* joints,
                const float* weights, int count, const Vec3f& rest) {
  RowMajorAffine34f blend = weights[0] * palette[joints[0]];
  for (int e = 1; e < count; ++e) blend += weights[e] * palette[joints[e]];
  return blend.leftCols<3>() * rest + blend.col(3);
}

struct Partial {  // one clip's figures over some of its frames
  double max = 0, weighted_sum = 0;
  int frames = 0, max_frame = 0, max_vertex = 0;
};

}  // namespace

Status LevelDeviationJob::Validate() const {
  if (prepared == nullptr || level == nullptr || influences == nullptr) {
    return InvalidArgument("LevelDeviationJob: no prepared motion, level or influences");
  }
  const Character& character = prepared->character();
  const int p = character.vertex_count(), m = level->kept_count();
  if (static_cast<int>(level->joint_to_slot.size()) != character.joint_count()) {
    return InvalidArgument("LevelDeviationJob: the level is of another skeleton");
  }
  const int level_vertices = mesh != nullptr ? static_cast<int>(mesh->vertices.size()) : p;
  if (mesh != nullptr) {
    if (mesh->correspondence.size() != static_cast<size_t>(p)) {
      return InvalidArgument(
          "LevelDeviationJob: the mesh's correspondence is not the character's vertices");
    }
    for (const SurfacePoint& point : mesh->correspondence) {
      for (uint32_t v : point.vertices) {
        if (v >= static_cast<uint32_t>(level_vertices)) {
          return InvalidArgument(
              "LevelDeviationJob: a surface point names a vertex the mesh does not have");
        }
      }
    }
  }
  const int k = influences->per_vertex;
  if (k < 1 || influences->slots.size() != static_cast<size_t>(level_vertices) * k ||
      influences->weights.size() != influences->slots.size()) {
    return InvalidArgument("LevelDeviationJob: the influences are not one row per level vertex");
  }
  for (uint16_t slot : influences->slots) {
    if (slot >= m)
      return InvalidArgument(
          "LevelDeviationJob: an influence names a slot the level does not keep");
  }
  if (frame_step < 1) return InvalidArgument("LevelDeviationJob: the frame step must be positive");
  if (frame_stride < 1 || frame_stride > kMaxFrameStride) {
    return InvalidArgument("LevelDeviationJob: the frame stride must be 1 to " +
                           std::to_string(kMaxFrameStride));
  }
  size_t stored = 0;
  for (const MotionClip& clip : prepared->clips())
    stored += StoredFrameCount(clip.frame_count, frame_stride);
  if (stored_matrices.size() != stored * m) {
    return InvalidArgument("LevelDeviationJob: " + std::to_string(stored_matrices.size()) +
                           " stored matrices, expected " + std::to_string(stored * m));
  }
  return Status::Ok();
}

StatusOr<LevelDeviation> LevelDeviationJob::Run(const PieceRunner& run) const {
  if (Status status = Validate(); !status.ok()) return status;
  const Character& character = prepared->character();
  const RawSkin& skin = character.skin();
  const int p = character.vertex_count(), n = character.joint_count(), m = level->kept_count();
  const int k = influences->per_vertex;
  const int frames = prepared->frame_count();
  const std::span<const MotionClip> clips = prepared->clips();
  const Eigen::MatrixXd& kt = prepared->original_matrices();
  const std::vector<double>& areas = character.vertex_areas();
  const double total_area = std::accumulate(areas.begin(), areas.end(), 0.0);
  const int level_vertices = mesh != nullptr ? static_cast<int>(mesh->vertices.size()) : p;
  auto original_id = [&](int v) {
    return mesh != nullptr ? static_cast<int>(mesh->vertices[v]) : v;
  };
  std::vector<int> clip_of(static_cast<size_t>(frames));
  for (size_t c = 0; c < clips.size(); ++c) {
    std::fill_n(clip_of.begin() + clips[c].first_frame, clips[c].frame_count, static_cast<int>(c));
  }

  const int pieces = (frames + kFramesPerPiece - 1) / kFramesPerPiece;
  std::vector<std::vector<Partial>> partials(static_cast<size_t>(pieces),
                                             std::vector<Partial>(clips.size()));
  RunPieces(run, pieces, [&](int piece) {
    std::vector<RowMajorAffine34f> played(static_cast<size_t>(m)),
        original_palette(static_cast<size_t>(n));
    std::vector<Vec3f> posed(static_cast<size_t>(level_vertices));
    for (int t = piece * kFramesPerPiece; t < std::min(frames, (piece + 1) * kFramesPerPiece);
         ++t) {
      if (t % frame_step != 0) continue;
      PlayFrame(stored_matrices, m, clips, frame_stride, t, rigid, played);
      for (int j = 0; j < n; ++j)
        original_palette[j] = kt.block<4, 3>(4 * j, 3 * t).transpose().cast<float>();
      for (int v = 0; v < level_vertices; ++v) {
        const size_t row = static_cast<size_t>(v) * k;
        posed[v] = SkinPoint(played, &influences->slots[row], &influences->weights[row], k,
                             skin.positions[original_id(v)]);
      }
      Partial& partial = partials[piece][clip_of[t]];
      ++partial.frames;
      for (int i = 0; i < p; ++i) {
        const uint32_t first = skin.influence_offsets[i];
        const Vec3d original =
            SkinPoint(original_palette, &skin.influence_joints[first],
                      &skin.influence_weights[first],
                      static_cast<int>(skin.influence_offsets[i + 1] - first), skin.positions[i])
                .cast<double>();
        Vec3d drawn;
        if (mesh != nullptr) {
          const SurfacePoint& point = mesh->correspondence[i];
          drawn = (point.weights[0] * posed[point.vertices[0]] +
                   point.weights[1] * posed[point.vertices[1]] +
                   point.weights[2] * posed[point.vertices[2]])
                      .cast<double>();
        } else {
          drawn = posed[i].cast<double>();
        }
        const double error = (drawn - original).norm();
        partial.weighted_sum += areas[i] * error;
        if (error > partial.max) {
          partial.max = error;
          partial.max_frame = t - clips[clip_of[t]].first_frame;
          partial.max_vertex = i;
        }
      }
    }
  });

  const double to_pct = 100.0 / character.height();
  LevelDeviation out;
  for (size_t c = 0; c < clips.size(); ++c) {
    Partial merged;
    for (const auto& piece : partials) {
      const Partial& part = piece[c];
      if (part.max > merged.max) {
        merged.max = part.max;
        merged.max_frame = part.max_frame;
        merged.max_vertex = part.max_vertex;
      }
      merged.weighted_sum += part.weighted_sum;
      merged.frames += part.frames;
    }
    LevelDeviation clip;
    clip.max_pct = merged.max * to_pct < kRoundingPct ? 0 : merged.max * to_pct;
    clip.mean_pct =
        merged.frames > 0 ? merged.weighted_sum / (total_area * merged.frames) * to_pct : 0;
    clip.max_frame = merged.max_frame;
    clip.max_vertex = merged.max_vertex;
    out.mean_pct = std::max(out.mean_pct, clip.mean_pct);
    if (c == 0 || clip.max_pct > out.max_pct) {
      out.max_pct = clip.max_pct;
      out.max_frame = clips[c].first_frame + clip.max_frame;
      out.max_vertex = clip.max_vertex;
    }
    out.per_clip.push_back(clip);
  }
  return out;
}

}  // namespace motionlod::core
