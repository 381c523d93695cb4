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

}  // namespace

BakeKey MakeBakeKey(const api::BakeRequest& resolved, const std::string& motion_source_id,
                    const std::string& animation, uint64_t settings_hash) {
  char fps[64];
  std::snprintf(fps, sizeof fps, "%.17g", resolved.fps);
  const std::string inputs = "motionlod-inputs/1\ncharacter " + resolved.character + "\nmotion " +
                             motion_source_id + "\nanimation " + std::to_string(animation.size()) +
                             ":" + animation + "\nfps " + fps + "\n";
  std::string key =
      "motionlod-bake/1\nalgorithm " + std::to_string(core::kAlgorithmVersion) + "\n" + inputs;
  key += "levels ";
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
                                          pipeline::ClipSource clip, int bake_threads,
                                          core::SimdChoice simd) {
  pipeline::BakeRequest request;
  request.clips = {std::move(clip)};
  request.fps = resolved.fps;
  request.levels = resolved.levels;
  request.all_levels = resolved.all_levels;
  request.locked_joints = resolved.locked_joints;
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

  // The motion: an id of this character, an animation name, or the first embedded one.
  const MotionRecord* motion = nullptr;
  if (request.motion.empty()) {
    for (const MotionRecord& m : *motions) {
      if (m.source == "character") {
        motion = &m;
        break;
      }
    }
    if (motion == nullptr) {
      return Error(
          ErrorKind::kUnprocessable,
          "the character has no animation of its own: upload one with POST /v1/motions?character=" +
              c.id + " and name it in 'motion'");
    }
  } else if (api::IsContentId(request.motion)) {
    for (const MotionRecord& m : *motions) {
      if (m.id == request.motion) motion = &m;
    }
    if (motion == nullptr) {
      auto other = context_.store->GetMotion(request.motion);
      if (other.ok() && other->has_value()) {
        return Error(ErrorKind::kUnprocessable,
                     "motion " + request.motion + " belongs to another character");
      }
      return Error(ErrorKind::kNotFound, "no motion " + request.motion);
    }
  } else {
    std::vector<const MotionRecord*> named;
    for (const MotionRecord& m : *motions) {
      if (m.animation == request.motion) named.push_back(&m);
    }
    // The character's own animation wins over a same-named one of a motion file.
    for (const MotionRecord* m : named) {
      if (m->source == "character") motion = m;
    }
    if (motion == nullptr && named.size() == 1) motion = named[0];
    if (motion == nullptr) {
      std::string available;
      for (const MotionRecord& m : *motions)
        available += (available.empty() ? "'" : ", '") + m.animation + "'";
      if (named.size() > 1) {
        return Error(ErrorKind::kUnprocessable,
                     "several motions are named '" + request.motion + "': give a motion id");
      }
      return Error(ErrorKind::kUnprocessable,
                   "the character has no animation named '" + request.motion + "'" +
                       (available.empty() ? "" : "; available: " + available));
    }
  }

  api::BakeRequest resolved = request;
  resolved.motion = motion->id;
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
  const pipeline::BakeRequest pipeline_request =
      MakePipelineRequest(resolved, {nullptr, motion->animation, ""}, context_.config.bake_threads,
                          context_.config.simd);
  if (Status status = pipeline_request.settings.Validate(); !status.ok()) {
    return Error(ErrorKind::kBadRequest, status.message());
  }
  const BakeKey key =
      MakeBakeKey(resolved, motion->source == "file" ? motion->source_id : "character",
                  motion->animation, pipeline_request.settings.Hash());
  const int64_t now = NowMs();
  BakeRecord bake;
  bake.id = key.id;
  bake.character_id = c.id;
  bake.motion_id = motion->id;
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
    auto status = jobs_.Get(key.id);
    if (!status.ok()) return status.error();
    return Created<api::JobStatus>{status.value(), false};
  }
  if (auto queued = jobs_.Enqueue(job); !queued.ok()) {
    (void)context_.store->DeleteBake(job.id);
    return queued.error();
  }
  spdlog::info("bake {} queued: character {}, animation '{}'", key.id, c.id, motion->animation);
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
  auto motion = context_.store->GetMotion(bake.motion_id);
  if (motion.ok() && motion->has_value()) info.animation = (*motion)->animation;
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
