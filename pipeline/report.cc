#include "pipeline/report.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

#include "core/simd.h"
#include "proto/level_selection.h"

namespace motionlod::pipeline {
namespace {

using nlohmann::json;

double Mean(const std::vector<double>& values) {
  return values.empty() ? 0.0 : std::accumulate(values.begin(), values.end(), 0.0) / values.size();
}

// JSON has no infinity: an exact level's pixel limit is null.
json FiniteOrNull(double value) { return std::isfinite(value) ? json(value) : json(nullptr); }

json ErrorsJson(const core::LevelErrors& e) {
  return {{"mean_E", e.mean_e},
          {"max_E", e.max_e},
          {"max_E_frame", e.max_e_frame},
          {"mean_Ep_vertex", Mean(e.ep_vertex)},
          {"mean_Ep_joint", Mean(e.ep_joint)},
          {"mean_En_vertex", Mean(e.en_vertex)},
          {"mean_En_joint", Mean(e.en_joint)},
          {"max_vertex_error_pct", e.max_vertex_error_pct},
          {"max_vertex_frame", e.max_vertex_frame},
          {"max_vertex_index", e.max_vertex_index},
          {"rms_vertex_error_pct", e.rms_vertex_error_pct},
          {"mean_vertex_error_pct", e.mean_vertex_error_pct},
          {"mean_normal_error_deg", e.mean_normal_error_deg},
          {"bone_length_drift_pct", e.bone_length_drift_pct},
          {"joint_rotation_drift_deg", e.joint_rotation_drift_deg}};
}

}  // namespace

StatusOr<std::string> EncodeBakedLevels(const core::Character& character,
                                        const core::Motion& motion,
                                        const core::SolveSettings& settings,
                                        const std::array<uint8_t, 32>& source_hash,
                                        const std::vector<BakedLevel>& levels,
                                        const PieceRunner& run) {
  proto::LevelSetRef set;
  set.variant_name = core::VariantName(settings.variant);
  set.flags = core::IsRigid(settings.variant) ? proto::kLevelSetFlagRigid : 0;
  set.algorithm_version = core::kAlgorithmVersion;
  set.frame_count = static_cast<uint32_t>(motion.frame_count);
  const std::vector<core::MotionClip> clips = motion.Clips();
  set.fps = clips.front().fps;  // the format's header rate is the first clip's
  for (const core::MotionClip& clip : clips) {
    set.clips.push_back({clip.name, static_cast<uint32_t>(clip.first_frame),
                         static_cast<uint32_t>(clip.frame_count), clip.fps});
  }
  set.source_hash = source_hash;
  set.settings_hash = settings.Hash();
  const core::RawSkeleton& skeleton = character.skeleton();
  set.joint_names.assign(skeleton.joint_names.begin(), skeleton.joint_names.end());
  set.parents = skeleton.parents;
  // The integer lists in the file's types (joints, map, vertices, triangles a level); the
  // matrices, slots and weights in place.
  static_assert(sizeof(core::RowMajorAffine34f) == proto::kMatrixFloats * sizeof(float));
  std::vector<std::vector<uint16_t>> joint_lists(2 * levels.size());
  std::vector<std::vector<uint32_t>> mesh_lists(2 * levels.size());
  for (size_t l = 0; l < levels.size(); ++l) {
    const CostLevel& level = levels[l].level;
    std::vector<uint16_t>& kept = joint_lists[2 * l];
    std::vector<uint16_t>& map = joint_lists[2 * l + 1];
    kept.assign(level.skeleton.kept_joints.begin(), level.skeleton.kept_joints.end());
    map.assign(level.skeleton.joint_to_slot.begin(), level.skeleton.joint_to_slot.end());
    std::vector<uint32_t>& vertices = mesh_lists[2 * l];
    std::vector<uint32_t>& triangles = mesh_lists[2 * l + 1];
    if (level.mesh) {
      vertices = level.mesh->vertices;
      for (const auto& triangle : level.mesh->triangles)
        triangles.insert(triangles.end(), triangle.begin(), triangle.end());
    }
    if (level.mesh || level.influences.per_vertex > 0)
      set.vertex_count = static_cast<uint32_t>(character.vertex_count());
    proto::LevelFigures figures;
    figures.max_vertex_error_pct = static_cast<float>(level.deviation.max_pct);
    figures.mean_vertex_error_pct = static_cast<float>(level.deviation.mean_pct);
    if (levels[l].skeleton != nullptr) {
      figures.mean_normal_error_deg =
          static_cast<float>(levels[l].skeleton->optimized.mean_normal_error_deg);
      figures.mean_E = static_cast<float>(levels[l].skeleton->optimized.mean_e);
    }
    figures.max_px_for_1px_error =
        static_cast<float>(proto::MaxPixelHeightForBudget(level.deviation.max_pct / 100.0, 1.0));
    proto::LevelRef ref;
    ref.kept_joints = kept;
    ref.joint_map = map;
    ref.figures = figures;
    ref.frame_stride = static_cast<uint32_t>(level.frame_stride);
    const float* first =
        level.stored_matrices.empty() ? nullptr : level.stored_matrices.front().data();
    ref.matrices =
        std::span<const float>(first, level.stored_matrices.size() * proto::kMatrixFloats);
    ref.vertices = vertices;
    ref.triangles = triangles;
    ref.influences_per_vertex = static_cast<uint32_t>(level.influences.per_vertex);
    ref.influence_slots = level.influences.slots;
    ref.influence_weights = level.influences.weights;
    ref.cost = static_cast<float>(level.cost);
    set.levels.push_back(ref);
  }
  return proto::EncodeLevelSet(set, run);
}

json RankingTable(const core::Character& character, core::RankingMethod method,
                  const core::JointRanking& ranking, const core::JointRanking& paper) {
  std::vector<int> paper_rank(paper.removal_order.size());
  for (size_t r = 0; r < paper.removal_order.size(); ++r)
    paper_rank[paper.removal_order[r]] = static_cast<int>(r) + 1;
  const bool greedy = method == core::RankingMethod::kGreedy;
  json rows = json::array();
  for (size_t r = 0; r < ranking.removal_order.size(); ++r) {
    const int j = ranking.removal_order[r];
    rows.push_back(
        {{"rank", r + 1},
         {"joint", character.skeleton().joint_names[j]},
         {"index", j},
         {"removal_error_pct", greedy ? FiniteOrNull(ranking.priority[j]) : json(nullptr)},
         {"paper_rank", paper_rank[j]},
         {"hierarchical", paper.hierarchical[j]},
         {"rotational", paper.rotational[j]},
         {"priority", FiniteOrNull(paper.priority[j])},
         {"removable", std::isfinite(ranking.priority[j])}});
  }
  return rows;
}

json BuildReport(const ReportInputs& in) {
  const core::SolveSettings& settings = in.request.settings;
  json report;
  report["format"] = "motionlod-report";
  report["version"] = kReportVersion;
  report["algorithm_version"] = core::kAlgorithmVersion;
  report["character"] = {{"name", in.character.name()},
                         {"source", in.request.character_label},
                         {"joints", in.character.joint_count()},
                         {"vertices", in.character.vertex_count()},
                         {"triangles", in.character.skin().triangles.size()},
                         {"height", in.character.height()},
                         {"proxy_skin", in.request.character->has_proxy_skin()}};
  const std::vector<core::MotionClip> clips = in.motion.Clips();
  std::string names, sources;
  std::vector<std::string> seen_sources;
  double seconds = 0;
  json clip_table = json::array();
  for (size_t c = 0; c < clips.size(); ++c) {
    const core::MotionClip& clip = clips[c];
    // The file it came from: a motion file's label, else the character's.
    const ClipSource* from = c < in.request.clips.size() ? &in.request.clips[c] : nullptr;
    const std::string source = from && from->motion ? from->label : in.request.character_label;
    names += (names.empty() ? "" : ", ") + clip.name;
    if (std::find(seen_sources.begin(), seen_sources.end(), source) == seen_sources.end()) {
      seen_sources.push_back(source);
      sources += (sources.empty() ? "" : ", ") + source;
    }
    seconds += (clip.frame_count - 1) / clip.fps;
    clip_table.push_back({{"name", clip.name},
                          {"source", source},
                          {"first_frame", clip.first_frame},
                          {"frames", clip.frame_count},
                          {"fps", clip.fps},
                          {"seconds", (clip.frame_count - 1) / clip.fps}});
  }
  report["motion"] = {{"name", names},
                      {"source", sources},
                      {"frames", in.motion.frame_count},
                      {"fps", clips.front().fps},
                      {"seconds", seconds}};
  report["clips"] = std::move(clip_table);
  report["variant"] = core::VariantName(settings.variant);
  report["settings"] = {{"resolve_rigid_translation", settings.resolve_rigid_translation},
                        {"joint_weight", settings.joint_weight},
                        {"regularization", settings.regularization},
                        {"sample_frames", settings.sample_frames},
                        {"sample_vertices", settings.sample_vertices},
                        {"alpha", in.prepared.alpha()},
                        {"beta", in.prepared.beta()},
                        {"locked_joints", in.request.locked_joints},
                        {"settings_hash", std::to_string(settings.Hash())}};
  report["units"] = {
      {"E",
       "eq. (2): alpha Ep + beta En, alpha and beta normalise by the root-only skeleton's maximum"},
      {"vertex_error_pct",
       "percent of the character's height (longest side of the bind-pose bounding box)"},
      {"normal_error_deg", "degrees between the original and the level's blended normals"},
      {"max_px_for_1px_error",
       "pixels: tallest on-screen character height keeping the max vertex error within 1 px; null "
       "= exact"}};
  report["timing"] = {
      {"bake_seconds", in.bake_seconds},
      {"skinning_pass_seconds", in.skinning_pass_seconds},
      {"bake_over_skinning_pass",
       in.skinning_pass_seconds > 0 ? in.bake_seconds / in.skinning_pass_seconds : 0.0},
      {"threads", in.threads},
      {"simd", std::string(core::SimdVersionName(in.request.simd))}};
  json levels = json::array();
  for (const BakedLevel& baked : in.levels) {
    const CostLevel& cost_level = baked.level;
    const core::LevelResult& r = *baked.skeleton;
    json removed = json::array();
    std::vector<bool> kept(in.character.joint_count(), false);
    for (int j : r.skeleton.kept_joints) kept[j] = true;
    for (int j = 0; j < in.character.joint_count(); ++j) {
      if (!kept[j]) removed.push_back(in.character.skeleton().joint_names[j]);
    }
    const double max_px = proto::MaxPixelHeightForBudget(cost_level.deviation.max_pct / 100.0, 1.0);
    // The matrix stream: m matrices of 48 bytes per stored pose, the fastest clip's rate.
    double poses_per_second = 0;
    for (const core::MotionClip& clip : clips)
      poses_per_second = std::max(poses_per_second, clip.fps / cost_level.frame_stride);
    const int m = cost_level.skeleton.kept_count();
    json level = {{"joints", m},
                  {"removed", removed},
                  {"vertices", cost_level.vertex_count(in.character)},
                  {"triangles", cost_level.triangle_count(in.character)},
                  {"influences_per_vertex", cost_level.influences.per_vertex > 0
                                                ? json(cost_level.influences.per_vertex)
                                                : json(nullptr)},
                  {"mean_influences", cost_level.mean_influences},
                  {"frame_stride", cost_level.frame_stride},
                  {"poses_per_second", poses_per_second},
                  {"stream_bytes_per_second", poses_per_second * m * 48.0},
                  {"cost", cost_level.cost},
                  {"mean_E", r.optimized.mean_e},
                  {"baseline_mean_E", r.baseline.mean_e},
                  {"max_vertex_error_pct", cost_level.deviation.max_pct},
                  {"skeleton_max_vertex_error_pct", r.optimized.max_vertex_error_pct},
                  {"baseline_max_vertex_error_pct", r.baseline.max_vertex_error_pct},
                  {"mean_vertex_error_pct", cost_level.deviation.mean_pct},
                  {"baseline_mean_vertex_error_pct", r.baseline.mean_vertex_error_pct},
                  {"mean_normal_error_deg", r.optimized.mean_normal_error_deg},
                  {"baseline_mean_normal_error_deg", r.baseline.mean_normal_error_deg},
                  {"bone_length_drift_pct", r.optimized.bone_length_drift_pct},
                  {"joint_rotation_drift_deg", r.optimized.joint_rotation_drift_deg},
                  {"max_px_for_1px_error", FiniteOrNull(max_px)},
                  {"optimized", ErrorsJson(r.optimized)},
                  {"baseline", ErrorsJson(r.baseline)}};
    json per_clip = json::array();
    for (size_t c = 0; c < clips.size(); ++c) {
      const core::LevelErrors& clip = r.optimized.per_clip[c];
      const core::LevelErrors& base = r.baseline.per_clip[c];
      const core::LevelDeviation& deviation = cost_level.deviation.per_clip[c];
      per_clip.push_back({{"clip", clips[c].name},
                          {"source", core::LevelSourceName(r.sources[c])},
                          {"mean_E", clip.mean_e},
                          {"max_vertex_error_pct", deviation.max_pct},
                          {"skeleton_max_vertex_error_pct", clip.max_vertex_error_pct},
                          {"mean_vertex_error_pct", deviation.mean_pct},
                          {"mean_normal_error_deg", clip.mean_normal_error_deg},
                          {"bone_length_drift_pct", clip.bone_length_drift_pct},
                          {"joint_rotation_drift_deg", clip.joint_rotation_drift_deg},
                          {"baseline_mean_E", base.mean_e},
                          {"baseline_max_vertex_error_pct", base.max_vertex_error_pct},
                          {"baseline_mean_vertex_error_pct", base.mean_vertex_error_pct},
                          {"pose_fps", clips[c].fps / cost_level.frame_stride},
                          {"max_px_for_1px_error", FiniteOrNull(proto::MaxPixelHeightForBudget(
                                                       deviation.max_pct / 100.0, 1.0))}});
    }
    level["per_clip"] = std::move(per_clip);
    levels.push_back(std::move(level));
  }
  report["levels"] = std::move(levels);
  if (!in.curves.empty()) {
    json curves = json::object();
    for (const VariantCurve& curve : in.curves) {
      json points = json::array();
      for (const CurvePoint& p : curve.points) {
        points.push_back({{"joints", p.joints},
                          {"mean_E", p.mean_e},
                          {"baseline_mean_E", p.baseline_mean_e},
                          {"max_vertex_error_pct", p.max_vertex_error_pct}});
      }
      curves[core::VariantName(curve.variant)] = std::move(points);
    }
    report["variant_curves"] = std::move(curves);
  }
  report["ranking_method"] = core::RankingMethodName(in.request.ranking_method);
  report["ranking"] =
      RankingTable(in.character, in.request.ranking_method, in.ranking, in.paper_ranking);
  report["warnings"] = in.warnings;
  return report;
}

}  // namespace motionlod::pipeline
