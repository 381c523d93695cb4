#include "server/levels.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "io/sha256.h"
#include "pipeline/export.h"
#include "proto/aligned_bytes.h"
#include "proto/level_format.h"
#include "proto/level_selection.h"

namespace motionlod::server {
namespace {

namespace api = proto::api;
using nlohmann::json;

constexpr size_t kLevelTableEntries = 4096;

// "'a', 'b'": names for a message.
template <typename Names, typename NameOf>
std::string ListNames(const Names& items, NameOf name_of) {
  std::string list;
  for (const auto& item : items)
    list += (list.empty() ? "'" : ", '") + std::string(name_of(item)) + "'";
  return list;
}

std::string ClipNames(const std::vector<api::BakeClip>& clips) {
  return ListNames(clips, [](const api::BakeClip& clip) { return clip.animation; });
}

bool HasClip(const std::vector<api::BakeClip>& clips, const std::string& name) {
  return std::any_of(clips.begin(), clips.end(),
                     [&](const api::BakeClip& clip) { return clip.animation == name; });
}

ServiceError NoSuchClip(const std::string& what, const std::string& clip,
                        const std::string& names) {
  return Error(ErrorKind::kNotFound,
               what + " has no clip named '" + clip + "'; its clips: " + names);
}

}  // namespace

StatusOr<std::shared_ptr<const Levels::Table>> Levels::GetTable(const BakeRecord& bake) {
  {
    std::lock_guard lock(tables_mutex_);
    if (auto found = tables_.find(bake.id); found != tables_.end()) return found->second;
  }
  auto levels = context_.store->GetLevels(bake.id);
  if (!levels.ok()) return levels.status();
  const json report = json::parse(bake.report_json, nullptr, false);
  if (!report.is_object() || !report.contains("levels") || !report["levels"].is_array() ||
      report["levels"].size() != levels->size()) {
    return Status(StatusCode::kDataLoss,
                  "the stored report of bake " + bake.id + " does not match its levels");
  }
  auto table = std::make_shared<Table>();
  const size_t count = levels->size();
  for (size_t l = 0; l < count; ++l) {
    const json& level = report["levels"][l];
    const double pct = level.value("max_vertex_error_pct", 0.0);
    table->max_error_fraction.push_back(pct / 100.0);
    const double limit = proto::MaxPixelHeightForBudget(pct / 100.0, 1.0);
    api::LevelEntry entry;
    entry.index = static_cast<int>(l);
    entry.joints = (*levels)[l].joints;
    entry.vertices = level.value("vertices", 0);
    entry.triangles = level.value("triangles", 0);
    if (const auto k = level.find("influences_per_vertex");
        k != level.end() && k->is_number_integer()) {
      entry.influences_per_vertex = k->get<int>();
    }
    entry.mean_influences = level.value("mean_influences", 0.0);
    entry.frame_stride = level.value("frame_stride", 1);
    entry.stream_bytes_per_second = level.value("stream_bytes_per_second", 0.0);
    entry.cost = level.value("cost", 0.0);
    entry.max_vertex_error_pct = pct;
    entry.mean_vertex_error_pct = level.value("mean_vertex_error_pct", 0.0);
    entry.mean_normal_error_deg = level.value("mean_normal_error_deg", 0.0);
    entry.mean_e = level.value("mean_E", 0.0);
    if (std::isfinite(limit)) entry.max_px_for_1px_error = limit;
    entry.hash = (*levels)[l].hash;
    entry.bytes = static_cast<uint64_t>((*levels)[l].bytes);
    table->entries.push_back(std::move(entry));
  }
  // The clips: the report's clip table, with the motions of the bake in the same order.
  if (const auto clips = report.find("clips"); clips != report.end() && clips->is_array()) {
    for (size_t c = 0; c < clips->size(); ++c) {
      const json& clip = (*clips)[c];
      api::BakeClip entry;
      entry.motion = c < bake.clip_motions.size() ? bake.clip_motions[c] : std::string();
      entry.animation = clip.value("name", "");
      entry.frames = clip.value("frames", 0);
      entry.fps = clip.value("fps", 0.0);
      entry.first_frame = clip.value("first_frame", 0);
      table->clips.push_back(std::move(entry));
    }
  }
  // The heights Choose picks each level for at the default budget: one definition.
  const std::vector<proto::LevelRange> ranges = proto::LevelRanges(table->max_error_fraction, 1.0);
  for (size_t l = 0; l < count; ++l) {
    if (!ranges[l].chosen) continue;
    api::LevelEntry& entry = table->entries[l];
    entry.chosen = true;
    entry.px_min = ranges[l].px_min;
    if (std::isfinite(ranges[l].px_max)) entry.px_max = ranges[l].px_max;
  }
  std::lock_guard lock(tables_mutex_);
  if (tables_.size() >= kLevelTableEntries) tables_.clear();
  tables_[bake.id] = table;
  return std::shared_ptr<const Table>(table);
}

void Levels::ForgetTable(const std::string& bake_id) {
  std::lock_guard lock(tables_mutex_);
  tables_.erase(bake_id);
}

Result<std::shared_ptr<const Levels::Table>> Levels::TableOf(const std::string& bake_id) {
  {
    std::lock_guard lock(tables_mutex_);
    if (auto found = tables_.find(bake_id); found != tables_.end()) return found->second;
  }
  auto bake = BakeWithLevels(bake_id);
  if (!bake.ok()) return bake.error();
  auto table = GetTable(bake.value());
  if (!table.ok()) return Internal(table.status());
  return *table;
}

Result<api::LevelChoice> Levels::Choose(const std::string& bake_id, double px, double budget_px,
                                        const std::string& clip) {
  if (!api::IsContentId(bake_id)) return MalformedId("bake");
  if (!(px > 0) || !std::isfinite(px) || px > 1e6) {
    return Error(ErrorKind::kBadRequest,
                 "px (the character's on-screen height in pixels) must be in (0, 1e6]");
  }
  if (!(budget_px > 0) || !std::isfinite(budget_px) || budget_px > 1e4) {
    return Error(ErrorKind::kBadRequest,
                 "budget (the tolerated error in pixels) must be in (0, 1e4]");
  }
  auto found = TableOf(bake_id);
  if (!found.ok()) return found.error();
  const Table& table = **found;
  if (!clip.empty() && !HasClip(table.clips, clip))
    return NoSuchClip("bake " + bake_id, clip, ClipNames(table.clips));
  const int l = proto::SelectLevel(table.max_error_fraction, px, budget_px);
  const api::LevelEntry& entry = table.entries[static_cast<size_t>(l)];
  api::LevelChoice choice;
  choice.bake = bake_id;
  choice.clip = clip;
  choice.px = px;
  choice.budget_px = budget_px;
  choice.index = l;
  choice.joints = entry.joints;
  choice.max_vertex_error_pct = entry.max_vertex_error_pct;
  choice.error_px = px * entry.max_vertex_error_pct / 100.0;
  choice.within_budget = choice.error_px <= budget_px;
  choice.hash = entry.hash;
  choice.url =
      "/v1/levels/" + entry.hash + (clip.empty() ? "" : "?clip=" + api::EncodeQueryValue(clip));
  choice.bytes = entry.bytes;
  return choice;
}

Result<Levels::LevelFile> Levels::Get(const std::string& hash, const std::string& clip) {
  if (!api::IsContentId(hash))
    return Error(ErrorKind::kNotFound, "no level with that hash (hashes are 64 hex digits)");
  LevelFile file{nullptr, hash};
  if (!clip.empty()) {
    // The version after "motionlod-level-clip/" changes whenever the extraction writes
    // other bytes.
    file.key = io::Sha256Hex("motionlod-level-clip/1\nlevel " + hash + "\nclip " +
                             std::to_string(clip.size()) + ":" + clip + "\n");
  }
  LevelCache::Bytes whole = context_.cache.Get(hash);
  if (!whole) {
    auto size = context_.store->LevelBytes(hash);
    if (!size.ok()) return Internal(size.status());
    if (!size->has_value()) return Error(ErrorKind::kNotFound, "no level " + hash);
  }
  // A clip's file is served only while its level is (a deleted bake's levels leave the
  // cache and the store; the clips' files made from them cannot be listed to follow).
  if (!clip.empty() && (file.bytes = context_.cache.Get(file.key))) return file;
  if (!whole) {
    auto bytes = context_.blobs->Get(hash);
    if (!bytes.ok()) {
      if (bytes.status().code() == StatusCode::kNotFound)
        return Error(ErrorKind::kNotFound, "no level " + hash);
      return Internal(bytes.status());
    }
    whole = std::make_shared<const std::string>(std::move(*bytes));
    context_.cache.Put(hash, whole);
  }
  if (clip.empty()) {
    file.bytes = std::move(whole);
    return file;
  }
  const proto::AlignedBytes aligned = proto::AlignedBytes::CopyOf(*whole);
  auto view = proto::DecodeLevelSet(aligned.bytes());
  if (!view.ok()) return Internal(view.status());
  const int c = view->FindClip(clip);
  if (c < 0) {
    return NoSuchClip(
        "level " + hash, clip,
        ListNames(view->clips(), [](const proto::ClipView& one) { return one.name; }));
  }
  auto one_clip = proto::ExtractLevelClip(*view, 0, static_cast<uint32_t>(c));
  if (!one_clip.ok()) return Internal(one_clip.status());
  file.bytes = std::make_shared<const std::string>(std::move(*one_clip));
  context_.cache.Put(file.key, file.bytes);
  return file;
}

Result<BakeRecord> Levels::BakeWithLevels(const std::string& bake_id) {
  auto bake = FindRecord(*context_.store, &Store::GetBake, "bake", bake_id);
  if (!bake.ok()) return bake.error();
  if (bake->level_set.empty()) {
    auto job = jobs_.Get(bake_id);
    return Error(ErrorKind::kConflict, "bake " + bake_id + " has no levels yet (state: " +
                                           (job.ok() ? job->state : std::string("unknown")) +
                                           "); wait on /v1/jobs/" + bake_id);
  }
  return bake;
}

Result<Levels::GltfFile> Levels::GetGltf(const std::string& bake_id, const GltfPick& pick,
                                         const std::string& clip) {
  auto bake = BakeWithLevels(bake_id);
  if (!bake.ok()) return bake.error();
  auto levels = context_.store->GetLevels(bake_id);
  if (!levels.ok()) return Internal(levels.status());
  const LevelRecord* level = nullptr;
  std::string available;
  for (const LevelRecord& record : *levels) {
    const bool named = pick.hash.empty() ? record.joints == pick.joints : record.hash == pick.hash;
    if (level == nullptr && named) level = &record;
    available += (available.empty() ? "" : ", ") + std::to_string(record.joints);
  }
  if (level == nullptr && !pick.hash.empty()) {
    return Error(ErrorKind::kNotFound,
                 "bake " + bake_id + " has no level " + pick.hash + "; its level table lists them");
  }
  if (level == nullptr) {
    return Error(ErrorKind::kNotFound, "bake " + bake_id + " has no level with " +
                                           std::to_string(pick.joints) +
                                           " joints; its levels keep " + available);
  }
  auto table = GetTable(bake.value());
  if (!table.ok()) return Internal(table.status());
  const std::vector<api::BakeClip>& clips = (*table)->clips;
  if (!clip.empty() && !HasClip(clips, clip))
    return NoSuchClip("bake " + bake_id, clip, ClipNames(clips));
  const std::string animation = !clip.empty()   ? clip
                                : clips.empty() ? std::string()
                                                : clips.front().animation;
  GltfFile file;
  // The version after "motionlod-gltf/" changes whenever the exporter writes other bytes.
  file.key =
      io::Sha256Hex("motionlod-gltf/2\nlevel " + level->hash + "\ncharacter " + bake->character_id +
                    "\nanimation " + std::to_string(animation.size()) + ":" + animation + "\n");
  if ((file.glb = context_.cache.Get(file.key))) return file;
  auto one_level = Get(level->hash, "");
  if (!one_level.ok()) return one_level.error();
  auto character =
      FindRecord(*context_.store, &Store::GetCharacter, "character", bake->character_id);
  if (!character.ok()) return character.error();
  auto asset = context_.LoadSource(character->id, character->files);
  if (!asset.ok()) return Internal(asset.status());
  // A bound from above on the file, before it is built: the level's matrices become a
  // translation, rotation and scale per joint and frame (40 of its 48 bytes), and its mesh
  // is at most the character's (positions, normals, joints, weights: 48 bytes a vertex).
  const core::RawSkin& skin = (*asset)->character().skin;
  const int64_t bound = static_cast<int64_t>(one_level->bytes->size()) +
                        48 * static_cast<int64_t>(skin.positions.size()) +
                        12 * static_cast<int64_t>(skin.triangles.size());
  if (bound > context_.config.max_export_bytes) {
    return Error(ErrorKind::kUnprocessable,
                 "the glTF file of this level could reach " + std::to_string(bound >> 20) +
                     " MiB, more than max_export_bytes (" +
                     std::to_string(context_.config.max_export_bytes >> 20) +
                     " MiB); export it with the motionlod tool instead");
  }
  auto exported = pipeline::ExportLevelGltf(**asset, *one_level->bytes, {.index = 0}, animation);
  if (!exported.ok()) return Internal(exported.status());
  file.glb = std::make_shared<const std::string>(std::move(exported->glb));
  // Level files come first: one export may take at most an eighth of the cache.
  if (static_cast<int64_t>(file.glb->size()) <= context_.config.cache_bytes / 8) {
    context_.cache.Put(file.key, file.glb);
  }
  return file;
}

}  // namespace motionlod::server
