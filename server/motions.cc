#include "server/motions.h"

#include "io/retarget.h"
#include "io/sha256.h"
#include "server/uploads.h"

namespace motionlod::server {
namespace {

namespace api = proto::api;

std::string MotionId(const std::string& character_id, const std::string& source_id,
                     const std::string& animation) {
  return io::Sha256Hex("motionlod-motion/1\ncharacter " + character_id + "\nsource " + source_id +
                       "\nanimation " + std::to_string(animation.size()) + ":" + animation + "\n");
}

}  // namespace

MotionRecord MakeMotionRecord(const std::string& character_id, const std::string& source,
                              const std::string& source_id, const io::AnimationInfo& animation,
                              int64_t created_ms) {
  MotionRecord m;
  m.id = MotionId(character_id, source_id, animation.name);
  m.character_id = character_id;
  m.animation = animation.name;
  m.source = source;
  m.source_id = source_id;
  m.duration_seconds = animation.duration_seconds;
  m.source_fps = animation.source_fps;
  m.frames = animation.source_frame_count;
  m.created_ms = created_ms;
  return m;
}

api::MotionInfo ToMotionInfo(const MotionRecord& m) {
  api::MotionInfo info;
  info.id = m.id;
  info.character = m.character_id;
  info.animation = m.animation;
  info.source = m.source;
  if (m.source == "file") info.files = ToFileInfos(m.files);
  info.duration_seconds = m.duration_seconds;
  info.source_fps = m.source_fps;
  info.frames = m.frames;
  info.warnings = m.warnings;
  return info;
}

Result<Created<std::vector<api::MotionInfo>>> Motions::Upload(const std::string& character_id,
                                                              std::vector<io::SourceFile> files) {
  if (!api::IsContentId(character_id)) {
    return Error(ErrorKind::kBadRequest,
                 "?character= must be a character id (64 lower-case hex digits)");
  }
  auto character = FindRecord(*context_.store, &Store::GetCharacter, "character", character_id);
  if (!character.ok()) return character.error();
  if (Status status = ValidateUploadFiles(files); !status.ok())
    return Error(ErrorKind::kBadRequest, status.message());
  const std::string source_id = UploadId(files);
  ImportSlot slot(context_.imports, context_.config.max_concurrent_imports);
  if (!slot.acquired()) {
    return Error(ErrorKind::kUnavailable, "too many uploads are being imported; retry shortly", 2);
  }
  auto target = context_.LoadSource(character_id, character->files);
  if (!target.ok()) return Internal(target.status());
  auto asset = context_.Import(files);
  if (!asset.ok()) return ImportError(asset.status());
  if ((*asset)->animations().empty())
    return Error(ErrorKind::kUnprocessable, "the file has no animation");
  std::vector<MotionRecord> motions;
  std::string first_error;
  const int64_t now = NowMs();
  for (const io::AnimationInfo& a : (*asset)->animations()) {
    auto retargeted = io::RetargetAnimation(**asset, a.name, 0, (*target)->character());
    if (!retargeted.ok()) {
      if (first_error.empty())
        first_error = "animation '" + a.name + "': " + retargeted.status().message();
      continue;
    }
    MotionRecord m = MakeMotionRecord(character_id, "file", source_id, a, now);
    for (const std::string& joint : retargeted->unmatched_target_joints) {
      m.warnings.push_back("joint '" + joint +
                           "' has no match in the motion: it keeps its bind pose");
    }
    for (const std::string& joint : retargeted->unmatched_source_joints) {
      m.warnings.push_back("the motion's joint '" + joint + "' matches no joint of the character");
    }
    motions.push_back(std::move(m));
  }
  if (motions.empty()) {
    return Error(ErrorKind::kUnprocessable,
                 "no animation of the file retargets onto the character: " + first_error);
  }
  bool created = false;
  for (const MotionRecord& m : motions) {
    auto existing = context_.store->GetMotion(m.id);
    if (!existing.ok()) return Internal(existing.status());
    created = created || !existing->has_value();
  }
  std::vector<FileRecord> records;
  std::shared_lock blob_lock(context_.blobs_mutex);
  if (Status status = context_.StoreFiles(files, records); !status.ok()) return Internal(status);
  for (MotionRecord& m : motions) m.files = records;
  if (Status status = context_.store->InsertMotions(motions); !status.ok()) return Internal(status);
  context_.assets.Put(source_id, *asset);
  std::vector<api::MotionInfo> infos;
  for (const MotionRecord& m : motions) infos.push_back(ToMotionInfo(m));
  return Created<std::vector<api::MotionInfo>>{std::move(infos), created};
}

Result<api::MotionInfo> Motions::Get(const std::string& id) {
  auto motion = FindRecord(*context_.store, &Store::GetMotion, "motion", id);
  if (!motion.ok()) return motion.error();
  return ToMotionInfo(*motion);
}

Result<std::vector<api::MotionInfo>> Motions::List(const std::string& character_id) {
  if (!api::IsContentId(character_id))
    return Error(ErrorKind::kNotFound, "no character with that id");
  auto character = FindRecord(*context_.store, &Store::GetCharacter, "character", character_id);
  if (!character.ok()) return character.error();
  auto motions = context_.store->ListMotions(character_id);
  if (!motions.ok()) return Internal(motions.status());
  std::vector<api::MotionInfo> list;
  for (const MotionRecord& m : *motions) list.push_back(ToMotionInfo(m));
  return list;
}

}  // namespace motionlod::server
