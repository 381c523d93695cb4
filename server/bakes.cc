#include "server/bakes.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cstdio>
#include <functional>

#include "core/solve_levels.h"
#include "io/sha256.h"

namespace motionlod::server {
namespace {

namespace api = proto::api;
using nlohmann::json;

std::array<uint8_t, 32> HexToBytes(const std::string& hex) {
  std::array<uint8_t, 32> bytes{};
  const auto nibble = [](char c) { return c <= '9' ? c - '0' : c - 'a' + 10; };
  for (size_t q = 0; q < bytes.size() && 2 * q + 1 < hex.size(); ++q) {
    bytes[q] = static_cast<uint8_t>(nibble(hex[2 * q]) * 16 + nibble(hex[2 * q + 1]));
  }
  return bytes;
}

// A motion of the character named as the API names one (a motion id, or an animation
// name: the character's own animation first, else the only motion file's one of that name).
// `field` names the request field in messages.
Result<const MotionRecord*> FindMotion(Store& store, const std::vector<MotionRecord>& motions,
                                       const std::string& name, const std::string& field) {
  if (api::IsContentId(name)) {
    for (const MotionRecord& m : motions) {
      if (m.id == name) return &m;
    }
    auto other = store.GetMotion(name);
    if (other.ok() && other->has_value()) {
      return Error(ErrorKind::kUnprocessable,
                   field + ": motion " + name + " belongs to another character");
    }
    return Error(ErrorKind::kNotFound, field + ": no motion " + name);
  }
  std::vector<const MotionRecord*> named;
  for (const MotionRecord& m : motions) {
    if (m.animation == name) named.push_back(&m);
  }
  // The character's own animation wins over a same-named one of a motion file.
  for (const MotionRecord* m : named) {
    if (m->source == "character") return m;
  }
  if (named.size() == 1) return named[0];
  if (named.size() > 1) {
    return Error(ErrorKind::kUnprocessable,
                 field + ": several motions are named '" + name + "': give a motion id");
  }
  std::string available;
  for (const MotionRecord& m : motions)
    available += (available.empty() ? "'" : ", '") + m.animation + "'";
  return Error(ErrorKind::kUnprocessable,
               field + ": the character has no animation named '" + name + "'" +
                   (available.empty() ? "" : "; available: " + available));
}

// The motions a request bakes, in order: `motion`, the `clips`, or every motion of the
// character. Each once, and no two of the same animation name (the levels' clips are
// addressed by name).
Result<std::vector<const MotionRecord*>> ResolveClips(Store& store,
                                                      const CharacterRecord& character,
                                                      const std::vector<MotionRecord>& motions,
                                                      const api::BakeRequest& request) {
  std::vector<const MotionRecord*> clips;
  if (!request.motion.empty()) {
    auto motion = FindMotion(store, motions, request.motion, "'motion'");
    if (!motion.ok()) return motion.error();
    clips.push_back(*motion);
  } else if (!request.clips.empty()) {
    for (size_t c = 0; c < request.clips.size(); ++c) {
      auto motion =
          FindMotion(store, motions, request.clips[c], "'clips'[" + std::to_string(c) + "]");
      if (!motion.ok()) return motion.error();
      clips.push_back(*motion);
    }
  } else {
    for (const MotionRecord& m : motions) clips.push_back(&m);
    if (clips.empty()) {
      return Error(ErrorKind::kUnprocessable,
                   "the character has no motion: upload one with POST /v1/motions?character=" +
                       character.id + " and name it in 'motion' or 'clips'");
    }
  }
  for (size_t c = 0; c < clips.size(); ++c) {
    for (size_t before = 0; before < c; ++before) {
      if (clips[before] == clips[c]) {
        return Error(ErrorKind::kUnprocessable, "motion " + clips[c]->id + " ('" +
                                                    clips[c]->animation +
                                                    "') is named twice in 'clips'");
      }
      if (clips[before]->animation == clips[c]->animation) {
        return Error(ErrorKind::kUnprocessable, "two clips are named '" + clips[c]->animation +
                                                    "' (motions " + clips[before]->id + " and " +
                                                    clips[c]->id +
                                                    "): a bake's clips need distinct animation "
                                                    "names; name the clips to bake in 'clips'");
      }
    }
  }
  return clips;
}

}  // namespace

ClipIdentity IdentityOf(const MotionRecord& motion) {
  return {motion.source == "file" ? motion.source_id : "character", motion.animation};
}

BakeKey MakeBakeKey(const api::BakeRequest& resolved, const std::vector<ClipIdentity>& clips,
                    uint64_t settings_hash) {
  char fps[64];
  std::snprintf(fps, sizeof fps, "%.17g", resolved.fps);
  std::string inputs = "motionlod-inputs/2\ncharacter " + resolved.character + "\nclips " +
                       std::to_string(clips.size()) + "\n";
  for (const ClipIdentity& clip : clips) {
    inputs += "clip " + clip.source + " " + std::to_string(clip.animation.size()) + ":" +
              clip.animation + "\n";
  }
  inputs += std::string("fps ") + fps + "\n";
  std::string key =
      "motionlod-bake/2\nalgorithm " + std::to_string(core::kAlgorithmVersion) + "\n" + inputs;
  key += "ranking " + resolved.ranking + "\nlevels ";
  if (resolved.all_levels) {
    key += "all";
  } else if (resolved.levels.empty()) {
    key += "default";
  } else {
    for (int level : resolved.levels) key += std::to_string(level) + ",";
  }
  key += "\nvariant " + resolved.variant + "\nkeep_pd_translation " +
         (resolved.keep_pd_translation ? "1" : "0") + "\nlocked ";
  for (const std::string& joint : resolved.locked_joints)
    key += std::to_string(joint.size()) + ":" + joint + ",";
  char settings[32];
  std::snprintf(settings, sizeof settings, "%016llx",
                static_cast<unsigned long long>(settings_hash));
  key += std::string("\nsettings ") + settings + "\n";
  return BakeKey{io::Sha256Hex(key), HexToBytes(io::Sha256Hex(inputs))};
}

pipeline::BakeRequest MakePipelineRequest(const api::BakeRequest& resolved,
                                          std::vector<pipeline::ClipSource> clips, int bake_threads,
                                          core::SimdChoice simd) {
  pipeline::BakeRequest request;
  request.clips = std::move(clips);
  request.fps = resolved.fps;
  request.levels = resolved.levels;
  request.all_levels = resolved.all_levels;
  request.locked_joints = resolved.locked_joints;
  auto ranking = core::ParseRankingMethod(resolved.ranking);
  request.ranking_method = ranking.ok() ? *ranking : core::RankingMethod::kGreedy;
  auto variant = core::ParseVariant(resolved.variant);
  request.settings.variant = variant.ok() ? *variant : core::Variant::kVPNOPD;
  request.settings.resolve_rigid_translation = !resolved.keep_pd_translation;
  request.threads = bake_threads;
  request.simd = simd;
  return request;
}

Result<Created<api::JobStatus>> Bakes::Submit(const api::BakeRequest& request) {
  if (jobs_.draining()) return Error(ErrorKind::kUnavailable, "the daemon is shutting down", 5);
  auto character =
      FindRecord(*context_.store, &Store::GetCharacter, "character", request.character);
  if (!character.ok()) return character.error();
  const CharacterRecord& c = *character;
  auto motions = context_.store->ListMotions(c.id);
  if (!motions.ok()) return Internal(motions.status());
  auto clips = ResolveClips(*context_.store, c, *motions, request);
  if (!clips.ok()) return clips.error();

  api::BakeRequest resolved = request;
  resolved.motion.clear();
  resolved.clips.clear();
  std::vector<ClipIdentity> identities;
  std::vector<pipeline::ClipSource> sources;
  for (const MotionRecord* motion : *clips) {
    resolved.clips.push_back(motion->id);
    identities.push_back(IdentityOf(*motion));
    sources.push_back({nullptr, motion->animation, ""});
  }
  std::sort(resolved.levels.begin(), resolved.levels.end(), std::greater<>());
  resolved.levels.erase(std::unique(resolved.levels.begin(), resolved.levels.end()),
                        resolved.levels.end());
  std::sort(resolved.locked_joints.begin(), resolved.locked_joints.end());
  resolved.locked_joints.erase(
      std::unique(resolved.locked_joints.begin(), resolved.locked_joints.end()),
      resolved.locked_joints.end());
  for (int level : resolved.levels) {
    if (level > c.joints) {
      return Error(ErrorKind::kUnprocessable, "level " + std::to_string(level) +
                                                  " keeps more joints than the character's " +
                                                  std::to_string(c.joints));
    }
  }
  for (const std::string& joint : resolved.locked_joints) {
    if (std::find(c.joint_names.begin(), c.joint_names.end(), joint) == c.joint_names.end()) {
      return Error(ErrorKind::kUnprocessable, "the character has no joint named '" + joint + "'");
    }
  }
  const pipeline::BakeRequest pipeline_request = MakePipelineRequest(
      resolved, std::move(sources), context_.config.bake_threads, context_.config.simd);
  if (Status status = pipeline_request.settings.Validate(); !status.ok()) {
    return Error(ErrorKind::kBadRequest, status.message());
  }
  const BakeKey key = MakeBakeKey(resolved, identities, pipeline_request.settings.Hash());
  const int64_t now = NowMs();
  BakeRecord bake;
  bake.id = key.id;
  bake.character_id = c.id;
  bake.motion_id = resolved.clips.front();
  bake.clip_motions = resolved.clips;
  bake.request_json = json(resolved).dump();
  bake.created_ms = now;
  JobRecord job;
  job.id = key.id;
  job.bake_id = key.id;
  job.state = "queued";
  job.created_ms = now;
  auto inserted = context_.store->InsertBakeAndJob(bake, job);
  if (!inserted.ok()) return Internal(inserted.status());
  if (!*inserted) {
    auto existing = context_.store->GetJob(key.id);
    if (!existing.ok()) return Internal(existing.status());
    // A bake that failed to store its result runs again when asked again.
    if (existing->has_value() && (*existing)->state == "failed" &&
        (*existing)->error_code == "storage") {
      JobRecord retry = job;  // queued now, its runs so far counted
      retry.attempts = (*existing)->attempts;
      auto updated = context_.store->UpdateJob(retry);
      if (!updated.ok()) return Internal(updated.status());
      if (auto queued = jobs_.Enqueue(retry); !queued.ok()) {
        (void)context_.store->UpdateJob(**existing);  // still failed: asked again later
        return queued.error();
      }
      spdlog::info("bake {} queued again after a storage fault", key.id);
      auto status = jobs_.Get(key.id);
      if (!status.ok()) return status.error();
      return Created<api::JobStatus>{status.value(), true};
    }
    // On a shared store a daemon may have died between storing the job and queueing it:
    // a queued job is queued again (the queue drops an id it holds).
    if (context_.store->shared() && existing->has_value() && (*existing)->state == "queued") {
      if (auto queued = jobs_.Enqueue(**existing); !queued.ok()) return queued.error();
    }
    auto status = jobs_.Get(key.id);
    if (!status.ok()) return status.error();
    return Created<api::JobStatus>{status.value(), false};
  }
  if (auto queued = jobs_.Enqueue(job); !queued.ok()) {
    (void)context_.store->DeleteBake(job.id);
    return queued.error();
  }
  std::string names;
  for (const MotionRecord* motion : *clips)
    names += (names.empty() ? "'" : ", '") + motion->animation + "'";
  spdlog::info("bake {} queued: character {}, clips {}", key.id, c.id, names);
  auto status = jobs_.Get(key.id);
  if (!status.ok()) return status.error();
  return Created<api::JobStatus>{status.value(), true};
}

Result<api::BakeInfo> Bakes::ToBakeInfo(const BakeRecord& bake) {
  api::BakeInfo info;
  info.id = bake.id;
  info.character = bake.character_id;
  info.motion = bake.motion_id;
  auto request = api::ParseBakeRequest(bake.request_json);
  if (request.ok()) info.request = *request;
  for (const std::string& motion_id : bake.clip_motions) {
    api::BakeClip clip;
    clip.motion = motion_id;
    auto motion = context_.store->GetMotion(motion_id);
    if (motion.ok() && motion->has_value()) clip.animation = (*motion)->animation;
    info.clips.push_back(std::move(clip));
  }
  if (!info.clips.empty()) info.animation = info.clips.front().animation;
  info.ranking = info.request.ranking;
  info.variant = info.request.variant;
  auto job = jobs_.Get(bake.id);
  info.state = job.ok() ? job->state : "unknown";
  info.created_at = Rfc3339(bake.created_ms);
  if (!bake.level_set.empty()) {
    info.frames = bake.frames;
    info.fps = bake.fps;
    info.level_set = bake.level_set;
    info.level_set_bytes = static_cast<uint64_t>(bake.level_set_bytes);
    auto table = levels_.GetTable(bake);
    if (!table.ok()) return Internal(table.status());
    info.levels = (*table)->entries;
    info.clips = (*table)->clips;
  }
  return info;
}

Result<api::BakeInfo> Bakes::Get(const std::string& id) {
  auto bake = FindRecord(*context_.store, &Store::GetBake, "bake", id);
  if (!bake.ok()) return bake.error();
  return ToBakeInfo(*bake);
}

Result<std::vector<api::BakeInfo>> Bakes::List(const std::string& character_id) {
  if (!character_id.empty() && !api::IsContentId(character_id)) {
    return Error(ErrorKind::kBadRequest,
                 "?character= must be a character id (64 lower-case hex digits)");
  }
  auto bakes = context_.store->ListBakes(character_id);
  if (!bakes.ok()) return Internal(bakes.status());
  std::vector<api::BakeInfo> list;
  for (const BakeRecord& bake : *bakes) {
    auto full = context_.store->GetBake(bake.id);
    if (!full.ok() || !full->has_value()) continue;
    auto info = ToBakeInfo(**full);
    if (info.ok()) list.push_back(std::move(info.value()));
  }
  return list;
}

Result<std::string> Bakes::GetReport(const std::string& bake_id) {
  auto bake = FindRecord(*context_.store, &Store::GetBake, "bake", bake_id);
  if (!bake.ok()) return bake.error();
  if (bake->report_json.empty()) {
    auto job = jobs_.Get(bake_id);
    return Error(ErrorKind::kConflict, "bake " + bake_id + " has not succeeded (state: " +
                                           (job.ok() ? job->state : std::string("unknown")) + ")");
  }
  return std::move(bake->report_json);
}

Result<Done> Bakes::Delete(const std::string& id) {
  if (!api::IsContentId(id)) return MalformedId("bake");
  auto blobs = context_.store->DeleteBake(id);
  if (!blobs.ok()) {
    if (blobs.status().code() == StatusCode::kNotFound)
      return Error(ErrorKind::kNotFound, "no bake " + id);
    return Internal(blobs.status());
  }
  Forget(id);
  context_.CollectBlobs(*blobs);
  spdlog::info("deleted bake {}", id);
  return Done{};
}

void Bakes::Forget(const std::string& id) {
  jobs_.Cancel(id);
  levels_.ForgetTable(id);
}

}  // namespace motionlod::server
