#include "proto/api.h"

#include <algorithm>
#include <cmath>
#include <set>

namespace motionlod::proto::api {
namespace {

using nlohmann::json;

constexpr size_t kMaxListEntries = 1024;
constexpr size_t kMaxNameBytes = 65535;

json OptionalNumber(const std::optional<double>& value) {
  return value.has_value() && std::isfinite(*value) ? json(*value) : json(nullptr);
}

json OptionalText(const std::string& text) { return text.empty() ? json(nullptr) : json(text); }

// Readers of optional fields: absent and null keep the default.
template <typename T>
void ReadOptional(const json& j, const char* key, T& out) {
  if (const auto it = j.find(key); it != j.end() && !it->is_null()) it->get_to(out);
}

template <typename T>
void ReadOptional(const json& j, const char* key, std::optional<T>& out) {
  if (const auto it = j.find(key); it != j.end() && !it->is_null()) out = it->get<T>();
}

}  // namespace

bool IsContentId(std::string_view text) {
  return text.size() == 64 && std::all_of(text.begin(), text.end(), [](char c) {
           return (c >= '0' && c <= '9') || (c >= 'a' && c <= 'f');
         });
}

std::string EncodeQueryValue(std::string_view text) {
  static constexpr char kHex[] = "0123456789ABCDEF";
  std::string encoded;
  encoded.reserve(text.size());
  for (const char c : text) {
    const auto byte = static_cast<unsigned char>(c);
    if ((byte >= 'A' && byte <= 'Z') || (byte >= 'a' && byte <= 'z') ||
        (byte >= '0' && byte <= '9') || byte == '-' || byte == '.' || byte == '_' || byte == '~') {
      encoded += c;
    } else {
      encoded += '%';
      encoded += kHex[byte >> 4];
      encoded += kHex[byte & 15];
    }
  }
  return encoded;
}

StatusOr<BakeRequest> ParseBakeRequest(std::string_view json_text) {
  const json body = json::parse(json_text, nullptr, /*allow_exceptions=*/false);
  if (body.is_discarded()) return InvalidArgument("the body is not valid JSON");
  if (!body.is_object()) return InvalidArgument("the body must be a JSON object");
  static const std::set<std::string> kKnown = {
      "character",  "motion",  "clips", "ranking",       "levels",
      "all_levels", "variant", "fps",   "locked_joints", "keep_pd_translation"};
  for (const auto& [key, value] : body.items()) {
    if (!kKnown.count(key)) {
      return InvalidArgument("unknown field '" + key.substr(0, 64) +
                             "' (known: character, motion, clips, ranking, levels, all_levels, "
                             "variant, fps, locked_joints, keep_pd_translation)");
    }
  }
  BakeRequest request;
  const auto character = body.find("character");
  if (character == body.end() || !character->is_string()) {
    return InvalidArgument("'character' (a character id) is required and must be a string");
  }
  request.character = character->get<std::string>();
  if (!IsContentId(request.character)) {
    return InvalidArgument("'character' must be a character id: 64 lower-case hex digits");
  }
  if (const auto motion = body.find("motion"); motion != body.end() && !motion->is_null()) {
    if (!motion->is_string())
      return InvalidArgument("'motion' must be a string (a motion id or an animation name)");
    request.motion = motion->get<std::string>();
    if (request.motion.size() > kMaxNameBytes) return InvalidArgument("'motion' is too long");
  }
  if (const auto clips = body.find("clips"); clips != body.end() && !clips->is_null()) {
    if (!clips->is_array())
      return InvalidArgument("'clips' must be an array of motion ids or animation names");
    if (clips->size() > kMaxListEntries)
      return InvalidArgument("'clips' has more than 1024 entries");
    for (const json& clip : *clips) {
      if (!clip.is_string() || clip.get<std::string>().empty() ||
          clip.get<std::string>().size() > kMaxNameBytes) {
        return InvalidArgument(
            "'clips' entries must be motion ids or animation names (non-empty strings)");
      }
      request.clips.push_back(clip.get<std::string>());
    }
    if (request.clips.empty()) {
      return InvalidArgument(
          "'clips' is empty: name at least one clip, or leave it out to bake "
          "every motion of the character");
    }
  }
  if (!request.motion.empty() && !request.clips.empty()) {
    return InvalidArgument("give 'motion' (one clip) or 'clips' (several), not both");
  }
  if (const auto ranking = body.find("ranking"); ranking != body.end() && !ranking->is_null()) {
    if (!ranking->is_string())
      return InvalidArgument("'ranking' must be a string: greedy or paper");
    request.ranking = ranking->get<std::string>();
    if (std::find(std::begin(kRankingNames), std::end(kRankingNames), request.ranking) ==
        std::end(kRankingNames)) {
      return InvalidArgument("'ranking' must be greedy (the default) or paper, not '" +
                             request.ranking.substr(0, 64) + "'");
    }
  }
  if (const auto levels = body.find("levels"); levels != body.end() && !levels->is_null()) {
    if (!levels->is_array())
      return InvalidArgument("'levels' must be an array of kept joint counts");
    if (levels->size() > kMaxListEntries)
      return InvalidArgument("'levels' has more than 1024 entries");
    for (const json& level : *levels) {
      if (!level.is_number_integer()) return InvalidArgument("'levels' entries must be integers");
      const int64_t count = level.get<int64_t>();
      if (count < 1 || count > 65535)
        return InvalidArgument("'levels' entries must be in [1, 65535]");
      request.levels.push_back(static_cast<int>(count));
    }
  }
  if (const auto all = body.find("all_levels"); all != body.end() && !all->is_null()) {
    if (!all->is_boolean()) return InvalidArgument("'all_levels' must be a boolean");
    request.all_levels = all->get<bool>();
  }
  if (request.all_levels && !request.levels.empty()) {
    return InvalidArgument("give 'levels' or 'all_levels', not both");
  }
  if (const auto variant = body.find("variant"); variant != body.end() && !variant->is_null()) {
    if (!variant->is_string()) return InvalidArgument("'variant' must be a string");
    request.variant = variant->get<std::string>();
    if (std::find(std::begin(kVariantNames), std::end(kVariantNames), request.variant) ==
        std::end(kVariantNames)) {
      return InvalidArgument("'variant' must be one of vp, vpno, vp+pd, vpno+pd");
    }
  }
  if (const auto fps = body.find("fps"); fps != body.end() && !fps->is_null()) {
    if (!fps->is_number()) return InvalidArgument("'fps' must be a number");
    request.fps = fps->get<double>();
    if (!(request.fps >= 0 && request.fps <= 1000)) {
      return InvalidArgument("'fps' must be in [0, 1000] (0: the source's rate)");
    }
  }
  if (const auto locked = body.find("locked_joints"); locked != body.end() && !locked->is_null()) {
    if (!locked->is_array())
      return InvalidArgument("'locked_joints' must be an array of joint names");
    if (locked->size() > kMaxListEntries)
      return InvalidArgument("'locked_joints' has more than 1024 entries");
    for (const json& name : *locked) {
      if (!name.is_string() || name.get<std::string>().empty() ||
          name.get<std::string>().size() > kMaxNameBytes) {
        return InvalidArgument("'locked_joints' entries must be non-empty joint names");
      }
      request.locked_joints.push_back(name.get<std::string>());
    }
  }
  if (const auto keep = body.find("keep_pd_translation"); keep != body.end() && !keep->is_null()) {
    if (!keep->is_boolean()) return InvalidArgument("'keep_pd_translation' must be a boolean");
    request.keep_pd_translation = keep->get<bool>();
  }
  return request;
}

void to_json(json& j, const FileInfo& v) {
  j = json{{"name", v.name}, {"sha256", v.sha256}, {"size", v.size}};
}

void to_json(json& j, const MotionInfo& v) {
  j = json{{"id", v.id},
           {"character", v.character},
           {"animation", v.animation},
           {"source", v.source},
           {"duration_seconds", v.duration_seconds},
           {"source_fps", v.source_fps},
           {"frames", v.frames},
           {"warnings", v.warnings},
           {"url", "/v1/motions/" + v.id}};
  if (!v.files.empty()) j["files"] = v.files;
}

void to_json(json& j, const CharacterInfo& v) {
  j = json{{"id", v.id},
           {"name", v.name},
           {"files", v.files},
           {"joints", v.joints},
           {"vertices", v.vertices},
           {"triangles", v.triangles},
           {"proxy_skin", v.proxy_skin},
           {"joint_names", v.joint_names},
           {"animations", v.animations},
           {"warnings", v.warnings},
           {"created_at", v.created_at},
           {"url", "/v1/characters/" + v.id}};
}

void to_json(json& j, const BakeRequest& v) {
  j = json{{"character", v.character},
           {"motion", OptionalText(v.motion)},
           {"clips", v.clips.empty() ? json(nullptr) : json(v.clips)},
           {"ranking", v.ranking},
           {"levels", v.levels},
           {"all_levels", v.all_levels},
           {"variant", v.variant},
           {"fps", v.fps},
           {"locked_joints", v.locked_joints},
           {"keep_pd_translation", v.keep_pd_translation}};
}

void to_json(json& j, const JobStatus& v) {
  j = json{{"id", v.id},
           {"bake", v.bake},
           {"state", v.state},
           {"progress", v.progress},
           {"stage", v.stage},
           {"error", nullptr},
           {"attempts", v.attempts},
           {"version", v.version},
           {"created_at", v.created_at},
           {"started_at", OptionalText(v.started_at)},
           {"finished_at", OptionalText(v.finished_at)},
           {"url", "/v1/jobs/" + v.id},
           {"events_url", "/v1/jobs/" + v.id + "/events"},
           {"bake_url", "/v1/bakes/" + v.bake}};
  if (v.error) j["error"] = json{{"code", v.error->code}, {"detail", v.error->detail}};
}

void to_json(json& j, const LevelEntry& v) {
  j = json{{"index", v.index},
           {"joints", v.joints},
           {"vertices", v.vertices},
           {"triangles", v.triangles},
           {"influences_per_vertex",
            v.influences_per_vertex ? json(*v.influences_per_vertex) : json(nullptr)},
           {"mean_influences", v.mean_influences},
           {"frame_stride", v.frame_stride},
           {"stream_bytes_per_second", v.stream_bytes_per_second},
           {"cost", v.cost},
           {"max_vertex_error_pct", v.max_vertex_error_pct},
           {"mean_vertex_error_pct", v.mean_vertex_error_pct},
           {"mean_normal_error_deg", v.mean_normal_error_deg},
           {"mean_E", v.mean_e},
           {"max_px_for_1px_error", OptionalNumber(v.max_px_for_1px_error)},
           {"chosen", v.chosen},
           {"px_min", OptionalNumber(v.px_min)},
           {"px_max", OptionalNumber(v.px_max)},
           {"hash", v.hash},
           {"bytes", v.bytes},
           {"url", "/v1/levels/" + v.hash}};
}

void to_json(json& j, const BakeClip& v) {
  j = json{{"motion", v.motion},
           {"animation", v.animation},
           {"frames", v.frames},
           {"fps", v.fps},
           {"first_frame", v.first_frame}};
}

void to_json(json& j, const BakeInfo& v) {
  j = json{{"id", v.id},
           {"character", v.character},
           {"motion", v.motion},
           {"animation", v.animation},
           {"clips", v.clips},
           {"ranking", v.ranking},
           {"request", v.request},
           {"state", v.state},
           {"frames", v.frames},
           {"fps", v.fps},
           {"variant", v.variant},
           {"level_set", OptionalText(v.level_set)},
           {"level_set_bytes", v.level_set_bytes},
           {"levels", v.levels},
           {"created_at", v.created_at},
           {"url", "/v1/bakes/" + v.id},
           {"job_url", "/v1/jobs/" + v.id},
           {"report_url", "/v1/bakes/" + v.id + "/report"}};
}

void to_json(json& j, const LevelChoice& v) {
  j = json{{"bake", v.bake},
           {"clip", OptionalText(v.clip)},
           {"px", v.px},
           {"budget_px", v.budget_px},
           {"index", v.index},
           {"joints", v.joints},
           {"max_vertex_error_pct", v.max_vertex_error_pct},
           {"error_px", v.error_px},
           {"within_budget", v.within_budget},
           {"hash", v.hash},
           {"url", v.url},
           {"bytes", v.bytes}};
}

void to_json(json& j, const Problem& v) {
  j = json{{"type", v.type},     {"title", v.title},       {"status", v.status},
           {"detail", v.detail}, {"instance", v.instance}, {"request_id", v.request_id}};
}

void from_json(const json& j, FileInfo& v) {
  j.at("name").get_to(v.name);
  j.at("sha256").get_to(v.sha256);
  j.at("size").get_to(v.size);
}

void from_json(const json& j, MotionInfo& v) {
  j.at("id").get_to(v.id);
  j.at("character").get_to(v.character);
  j.at("animation").get_to(v.animation);
  j.at("source").get_to(v.source);
  ReadOptional(j, "files", v.files);
  ReadOptional(j, "duration_seconds", v.duration_seconds);
  ReadOptional(j, "source_fps", v.source_fps);
  ReadOptional(j, "frames", v.frames);
  ReadOptional(j, "warnings", v.warnings);
}

void from_json(const json& j, CharacterInfo& v) {
  j.at("id").get_to(v.id);
  j.at("name").get_to(v.name);
  ReadOptional(j, "files", v.files);
  j.at("joints").get_to(v.joints);
  ReadOptional(j, "vertices", v.vertices);
  ReadOptional(j, "triangles", v.triangles);
  ReadOptional(j, "proxy_skin", v.proxy_skin);
  ReadOptional(j, "joint_names", v.joint_names);
  ReadOptional(j, "animations", v.animations);
  ReadOptional(j, "warnings", v.warnings);
  ReadOptional(j, "created_at", v.created_at);
}

void from_json(const json& j, BakeRequest& v) {
  j.at("character").get_to(v.character);
  ReadOptional(j, "motion", v.motion);
  ReadOptional(j, "clips", v.clips);
  ReadOptional(j, "ranking", v.ranking);
  ReadOptional(j, "levels", v.levels);
  ReadOptional(j, "all_levels", v.all_levels);
  ReadOptional(j, "variant", v.variant);
  ReadOptional(j, "fps", v.fps);
  ReadOptional(j, "locked_joints", v.locked_joints);
  ReadOptional(j, "keep_pd_translation", v.keep_pd_translation);
}

void from_json(const json& j, JobStatus& v) {
  j.at("id").get_to(v.id);
  j.at("bake").get_to(v.bake);
  j.at("state").get_to(v.state);
  ReadOptional(j, "progress", v.progress);
  ReadOptional(j, "stage", v.stage);
  if (const auto error = j.find("error"); error != j.end() && !error->is_null()) {
    v.error =
        JobError{error->at("code").get<std::string>(), error->at("detail").get<std::string>()};
  }
  ReadOptional(j, "attempts", v.attempts);
  ReadOptional(j, "version", v.version);
  ReadOptional(j, "created_at", v.created_at);
  ReadOptional(j, "started_at", v.started_at);
  ReadOptional(j, "finished_at", v.finished_at);
}

void from_json(const json& j, LevelEntry& v) {
  j.at("index").get_to(v.index);
  j.at("joints").get_to(v.joints);
  ReadOptional(j, "vertices", v.vertices);
  ReadOptional(j, "triangles", v.triangles);
  ReadOptional(j, "influences_per_vertex", v.influences_per_vertex);
  ReadOptional(j, "mean_influences", v.mean_influences);
  ReadOptional(j, "frame_stride", v.frame_stride);
  ReadOptional(j, "stream_bytes_per_second", v.stream_bytes_per_second);
  ReadOptional(j, "cost", v.cost);
  j.at("max_vertex_error_pct").get_to(v.max_vertex_error_pct);
  ReadOptional(j, "mean_vertex_error_pct", v.mean_vertex_error_pct);
  ReadOptional(j, "mean_normal_error_deg", v.mean_normal_error_deg);
  ReadOptional(j, "mean_E", v.mean_e);
  ReadOptional(j, "max_px_for_1px_error", v.max_px_for_1px_error);
  ReadOptional(j, "chosen", v.chosen);
  ReadOptional(j, "px_min", v.px_min);
  ReadOptional(j, "px_max", v.px_max);
  j.at("hash").get_to(v.hash);
  ReadOptional(j, "bytes", v.bytes);
}

void from_json(const json& j, BakeClip& v) {
  j.at("motion").get_to(v.motion);
  j.at("animation").get_to(v.animation);
  ReadOptional(j, "frames", v.frames);
  ReadOptional(j, "fps", v.fps);
  ReadOptional(j, "first_frame", v.first_frame);
}

void from_json(const json& j, BakeInfo& v) {
  j.at("id").get_to(v.id);
  j.at("character").get_to(v.character);
  ReadOptional(j, "motion", v.motion);
  ReadOptional(j, "animation", v.animation);
  ReadOptional(j, "clips", v.clips);
  ReadOptional(j, "ranking", v.ranking);
  ReadOptional(j, "request", v.request);
  j.at("state").get_to(v.state);
  ReadOptional(j, "frames", v.frames);
  ReadOptional(j, "fps", v.fps);
  ReadOptional(j, "variant", v.variant);
  ReadOptional(j, "level_set", v.level_set);
  ReadOptional(j, "level_set_bytes", v.level_set_bytes);
  ReadOptional(j, "levels", v.levels);
  ReadOptional(j, "created_at", v.created_at);
}

void from_json(const json& j, LevelChoice& v) {
  j.at("bake").get_to(v.bake);
  ReadOptional(j, "clip", v.clip);
  j.at("px").get_to(v.px);
  ReadOptional(j, "budget_px", v.budget_px);
  j.at("index").get_to(v.index);
  j.at("joints").get_to(v.joints);
  ReadOptional(j, "max_vertex_error_pct", v.max_vertex_error_pct);
  ReadOptional(j, "error_px", v.error_px);
  ReadOptional(j, "within_budget", v.within_budget);
  j.at("hash").get_to(v.hash);
  ReadOptional(j, "url", v.url);
  ReadOptional(j, "bytes", v.bytes);
}

void from_json(const json& j, Problem& v) {
  ReadOptional(j, "type", v.type);
  ReadOptional(j, "title", v.title);
  ReadOptional(j, "status", v.status);
  ReadOptional(j, "detail", v.detail);
  ReadOptional(j, "instance", v.instance);
  ReadOptional(j, "request_id", v.request_id);
}

}  // namespace motionlod::proto::api
