#include "server/characters.h"

#include <spdlog/spdlog.h>

#include "core/character.h"
#include "server/motions.h"
#include "server/uploads.h"

namespace motionlod::server {
namespace {

namespace api = proto::api;

api::CharacterInfo ToCharacterInfo(const CharacterRecord& c,
                                   const std::vector<MotionRecord>& motions) {
  api::CharacterInfo info;
  info.id = c.id;
  info.name = c.name;
  info.files = ToFileInfos(c.files);
  info.joints = c.joints;
  info.vertices = c.vertices;
  info.triangles = c.triangles;
  info.proxy_skin = c.proxy_skin;
  info.joint_names = c.joint_names;
  for (const MotionRecord& m : motions) {
    if (m.source == "character") info.animations.push_back(ToMotionInfo(m));
  }
  info.warnings = c.warnings;
  info.created_at = Rfc3339(c.created_ms);
  return info;
}

}  // namespace

Result<Created<api::CharacterInfo>> Characters::Upload(std::vector<io::SourceFile> files) {
  if (Status status = ValidateUploadFiles(files); !status.ok())
    return Error(ErrorKind::kBadRequest, status.message());
  const std::string id = UploadId(files);
  auto existing = context_.store->GetCharacter(id);
  if (!existing.ok()) return Internal(existing.status());
  if (existing->has_value()) {
    auto character = Get(id);
    if (!character.ok()) return character.error();
    return Created<api::CharacterInfo>{character.value(), false};
  }
  ImportSlot slot(context_.imports, context_.config.max_concurrent_imports);
  if (!slot.acquired()) {
    return Error(ErrorKind::kUnavailable, "too many uploads are being imported; retry shortly", 2);
  }
  auto asset = context_.Import(files);
  if (!asset.ok()) return ImportError(asset.status());
  const core::RawCharacter& raw = (*asset)->character();
  if (auto built = core::BuildCharacter(raw); !built.ok()) {
    return Error(ErrorKind::kUnprocessable,
                 "the character cannot be baked: " + built.status().message());
  }
  CharacterRecord record;
  record.id = id;
  record.name = files[0].name;
  std::shared_lock blob_lock(context_.blobs_mutex);
  if (Status status = context_.StoreFiles(files, record.files); !status.ok())
    return Internal(status);
  record.joints = static_cast<int>(raw.skeleton.parents.size());
  record.vertices = static_cast<int>(raw.skin.positions.size());
  record.triangles = static_cast<int>(raw.skin.triangles.size());
  record.proxy_skin = (*asset)->has_proxy_skin();
  record.joint_names = raw.skeleton.joint_names;
  record.warnings = (*asset)->warnings();
  record.created_ms = NowMs();
  std::vector<MotionRecord> motions;
  for (const io::AnimationInfo& a : (*asset)->animations())
    motions.push_back(MakeMotionRecord(id, "character", id, a, record.created_ms));
  auto inserted = context_.store->InsertCharacter(record, motions);
  if (!inserted.ok()) return Internal(inserted.status());
  context_.assets.Put(id, *asset);
  spdlog::info("character {} '{}': {} joints, {} vertices, {} animations", id, record.name,
               record.joints, record.vertices, motions.size());
  auto character = Get(id);
  if (!character.ok()) return character.error();
  return Created<api::CharacterInfo>{character.value(), *inserted};
}

Result<api::CharacterInfo> Characters::Get(const std::string& id) {
  auto record = FindRecord(*context_.store, &Store::GetCharacter, "character", id);
  if (!record.ok()) return record.error();
  auto motions = context_.store->ListMotions(id);
  if (!motions.ok()) return Internal(motions.status());
  return ToCharacterInfo(*record, *motions);
}

Result<std::vector<api::CharacterInfo>> Characters::List() {
  auto records = context_.store->ListCharacters();
  if (!records.ok()) return Internal(records.status());
  std::vector<api::CharacterInfo> list;
  for (const CharacterRecord& c : *records) {
    auto motions = context_.store->ListMotions(c.id);
    if (!motions.ok()) return Internal(motions.status());
    list.push_back(ToCharacterInfo(c, *motions));
  }
  return list;
}

Result<Done> Characters::Delete(const std::string& id) {
  if (!api::IsContentId(id)) return MalformedId("character");
  auto bakes = context_.store->ListBakes(id);
  if (!bakes.ok()) return Internal(bakes.status());
  auto blobs = context_.store->DeleteCharacter(id);
  if (!blobs.ok()) {
    if (blobs.status().code() == StatusCode::kNotFound)
      return Error(ErrorKind::kNotFound, "no character " + id);
    return Internal(blobs.status());
  }
  for (const BakeRecord& bake : *bakes) bakes_.Forget(bake.id);
  context_.assets.Erase(id);
  context_.CollectBlobs(*blobs);
  spdlog::info("deleted character {} and {} bakes", id, bakes->size());
  return Done{};
}

}  // namespace motionlod::server
