// The JSON wire contract of motionlodd (the HTTP daemon) and its thin client (client/): the
// bodies of /v1 requests and responses. proto/openapi.yaml describes the same shapes; the
// daemon serves it at /v1/openapi.yaml. No Eigen, no core: plain data, JSON conversion and
// the validation of what a client sends.
//
// Units: seconds, frames per second, pixels (on-screen character height) and percent of
// the character's height, as in docs/report.md. Ids are lower-case SHA-256 hex (64
// characters): content addresses of what they name.
#pragma once

#include <cstdint>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "base/status.h"

namespace motionlod::proto::api {

// ^[0-9a-f]{64}$: every id of the API (characters, motions, bakes, jobs, levels).
bool IsContentId(std::string_view text);

// The solver variants a bake accepts (core::VariantName spells the same).
inline constexpr std::string_view kVariantNames[] = {"vp", "vpno", "vp+pd", "vpno+pd"};
// The joint rankings a bake accepts (core::RankingMethodName spells the same).
inline constexpr std::string_view kRankingNames[] = {"greedy", "paper"};

// `text` percent-encoded for a URL's query value: every byte but A-Z a-z 0-9 - . _ ~
// as %XX (a clip's name in ?clip=).
std::string EncodeQueryValue(std::string_view text);

struct FileInfo {
  std::string name;    // plain file name as uploaded
  std::string sha256;  // content address of the bytes
  uint64_t size = 0;   // bytes
};

// An animation registered for a character: one embedded in the character's file, or one
// of a separately uploaded motion file, retargeted onto the character.
struct MotionInfo {
  std::string id;
  std::string character;
  std::string animation;        // the animation's name inside its file
  std::string source;           // "character" (embedded) or "file" (uploaded to /v1/motions)
  std::vector<FileInfo> files;  // the motion file's parts ("file" only)
  double duration_seconds = 0;
  double source_fps = 0;
  int frames = 0;                     // at source_fps
  std::vector<std::string> warnings;  // unmatched joints of a retargeted motion
};

struct CharacterInfo {
  std::string id;
  std::string name;  // the main file's name
  std::vector<FileInfo> files;
  int joints = 0;
  int vertices = 0;
  int triangles = 0;
  bool proxy_skin = false;               // no mesh in the file: capsules around the bones
  std::vector<std::string> joint_names;  // n, parents before children
  std::vector<MotionInfo> animations;    // embedded animations, registered as motions
  std::vector<std::string> warnings;     // what the importer fixed or ignored
  std::string created_at;                // RFC 3339, UTC
};

// POST /v1/bakes. Defaults match the `motionlod bake` tool.
struct BakeRequest {
  std::string character;  // character id
  // One clip: a motion id (of this character), or the name of one of its animations (its
  // own first, then those of its motion files).
  std::string motion;
  // The clips baked together, in this order, each as `motion` names one. Neither `motion`
  // nor `clips`: every motion of the character, in the order of its motion list. As
  // resolved by the daemon: the motion ids, `motion` empty.
  std::vector<std::string> clips;
  std::string ranking = "greedy";  // the joint ranking: greedy or paper
  std::vector<int> levels;         // kept joint counts; empty: the default ladder
  bool all_levels = false;         // every count from all joints down to the locked minimum
  std::string variant = "vpno+pd";
  double fps = 0;  // 0: the source's rate; else (0, 1000]
  std::vector<std::string> locked_joints;
  bool keep_pd_translation = false;  // rigid variants: keep the solved translation
};

// Strict parse of a bake request: unknown fields, wrong types, a malformed id, an unknown
// variant or ranking, fps outside [0, 1000], level counts below 1 or above 65535, more
// than 1024 levels, clips or locked joints, an empty clip, and levels together with
// all_levels or motion together with clips are kInvalidArgument with a message naming
// the field.
StatusOr<BakeRequest> ParseBakeRequest(std::string_view json_text);

struct JobError {
  std::string code;    // invalid_argument, not_found, unsupported, data_loss, internal
  std::string detail;  // the bake's message
};

// GET /v1/jobs/{id}. A bake has exactly one job, of the same id.
struct JobStatus {
  std::string id;
  std::string bake;
  std::string state;    // queued | running | succeeded | failed
  double progress = 0;  // 0..1
  std::string stage;    // the bake's current stage ("solve", ...)
  std::optional<JobError> error;
  int attempts = 0;      // runs started (a run interrupted by a crash or shutdown runs again)
  uint64_t version = 0;  // grows with every change seen by this daemon process
  std::string created_at, started_at, finished_at;  // RFC 3339, empty when not yet
};

// One level of a finished bake (finest first) with the pixel heights it serves.
struct LevelEntry {
  int index = 0;
  int joints = 0;
  // What the level draws and streams (report.json's level of the same index): its vertices
  // and triangles (the character's own where it has no mesh of its own), its own
  // influences per vertex (nullopt: the mesh's, merged through the joint map) and how many
  // it uses on average, its frame stride (poses stored: every stride-th frame), the matrix
  // stream's bytes per second and the modelled cost of a frame against full detail.
  int vertices = 0;
  int triangles = 0;
  std::optional<int> influences_per_vertex;
  double mean_influences = 0;
  int frame_stride = 1;
  double stream_bytes_per_second = 0;
  double cost = 0;
  double max_vertex_error_pct = 0;
  double mean_vertex_error_pct = 0;
  double mean_normal_error_deg = 0;
  double mean_e = 0;
  // Tallest on-screen height (px) within the 1 px budget; nullopt when the level is exact.
  std::optional<double> max_px_for_1px_error;
  // With the default 1 px budget proto::SelectLevel picks the level for the heights in
  // (px_min, px_max] (proto::LevelRanges): px_max nullopt for the level that serves every
  // larger height. `chosen` false: picked at no height (a coarser level is as accurate),
  // and both bounds are nullopt.
  bool chosen = false;
  std::optional<double> px_min;
  std::optional<double> px_max;
  std::string hash;  // /v1/levels/{hash}: the one-level file
  uint64_t bytes = 0;
};

// One clip of a bake: the frames [first_frame, first_frame + frames) of its level set.
// frames, fps and first_frame are 0 until the bake succeeded.
struct BakeClip {
  std::string motion;     // motion id
  std::string animation;  // the clip's name in the level set (?clip= of the level routes)
  int frames = 0;
  double fps = 0;
  int first_frame = 0;
};

// GET /v1/bakes/{id}.
struct BakeInfo {
  std::string id;
  std::string character;
  std::string motion;           // the first clip's motion id
  std::string animation;        // the first clip's animation
  std::vector<BakeClip> clips;  // in frame order
  std::string ranking;
  BakeRequest request;  // as resolved (clips as motion ids, lists sorted)
  std::string state;    // the job's state
  int frames = 0;       // every clip's
  double fps = 0;       // the first clip's
  std::string variant;
  std::string level_set;  // sha256 of the whole level set (empty until succeeded)
  uint64_t level_set_bytes = 0;
  std::vector<LevelEntry> levels;  // empty until succeeded
  std::string created_at;
};

// GET /v1/bakes/{id}/level?px=&budget=&clip= with Accept: application/json. The level
// is chosen by the figures over every clip; `clip` narrows the file to one clip.
struct LevelChoice {
  std::string bake;
  std::string clip;  // the clip asked for; empty: the file holds every clip
  double px = 0;
  double budget_px = 1;
  int index = 0;
  int joints = 0;
  double max_vertex_error_pct = 0;
  double error_px = 0;  // px * max_vertex_error_pct / 100: the worst deviation on screen
  bool within_budget = true;
  std::string hash;
  std::string url;     // /v1/levels/{hash}, with ?clip= when a clip was asked for
  uint64_t bytes = 0;  // the file of every clip
};

// RFC 9457 problem details (application/problem+json).
struct Problem {
  std::string type;  // urn:motionlod:problem:<slug>
  std::string title;
  int status = 500;
  std::string detail;
  std::string instance;    // the request path
  std::string request_id;  // also in the X-Request-Id response header
};

void to_json(nlohmann::json& j, const FileInfo& v);
void to_json(nlohmann::json& j, const MotionInfo& v);
void to_json(nlohmann::json& j, const CharacterInfo& v);
void to_json(nlohmann::json& j, const BakeRequest& v);
void to_json(nlohmann::json& j, const JobStatus& v);
void to_json(nlohmann::json& j, const LevelEntry& v);
void to_json(nlohmann::json& j, const BakeClip& v);
void to_json(nlohmann::json& j, const BakeInfo& v);
void to_json(nlohmann::json& j, const LevelChoice& v);
void to_json(nlohmann::json& j, const Problem& v);

// The reverse, for clients reading the daemon's replies. Absent or null optional fields
// keep their defaults; a required field missing or of the wrong type throws
// nlohmann::json::exception, which ParseReply turns into a Status.
void from_json(const nlohmann::json& j, FileInfo& v);
void from_json(const nlohmann::json& j, MotionInfo& v);
void from_json(const nlohmann::json& j, CharacterInfo& v);
void from_json(const nlohmann::json& j, BakeRequest& v);
void from_json(const nlohmann::json& j, JobStatus& v);
void from_json(const nlohmann::json& j, LevelEntry& v);
void from_json(const nlohmann::json& j, BakeClip& v);
void from_json(const nlohmann::json& j, BakeInfo& v);
void from_json(const nlohmann::json& j, LevelChoice& v);
void from_json(const nlohmann::json& j, Problem& v);

// One reply body as T (any of the DTOs above); kDataLoss naming the field when the body
// is not JSON or does not have T's shape. Never throws.
template <typename T>
StatusOr<T> ParseReply(std::string_view json_text) {
  const nlohmann::json body = nlohmann::json::parse(json_text, nullptr, /*allow_exceptions=*/false);
  if (body.is_discarded()) return DataLoss("the reply is not valid JSON");
  try {
    return body.get<T>();
  } catch (const nlohmann::json::exception& error) {
    return DataLoss(std::string("the reply does not have the expected shape: ") + error.what());
  }
}

}  // namespace motionlod::proto::api
