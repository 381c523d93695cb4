#include "server/service.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <set>
#include <thread>

#include "core/character.h"
#include "core/level_selection.h"
#include "core/solve_levels.h"
#include "io/retarget.h"
#include "io/sha256.h"
#include "pipeline/export.h"
#include "base/parallel.h"
#include "proto/level_format.h"

namespace motionlod::server {
namespace {

namespace api = proto::api;
using nlohmann::json;

constexpr size_t kAssetCacheEntries = 8;
constexpr size_t kLevelTableEntries = 4096;

int64_t NowMs() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

std::string Rfc3339(int64_t ms) {
  if (ms <= 0) return "";
  const std::time_t seconds = static_cast<std::time_t>(ms / 1000);
  std::tm utc{};
  gmtime_r(&seconds, &utc);
  char buffer[40];
  const size_t n = std::strftime(buffer, sizeof buffer, "%Y-%m-%dT%H:%M:%S", &utc);
  std::snprintf(buffer + n, sizeof buffer - n, ".%03dZ", static_cast<int>(ms % 1000));
  return buffer;
}

ServiceError Error(ErrorKind kind, std::string detail, int retry_after = 0) {
  return ServiceError{kind, std::move(detail), retry_after};
}

ServiceError Internal(const Status& status) {
  spdlog::error("internal error: {}", status.message());
  return Error(ErrorKind::kInternal, "internal error; see the daemon's log");
}

// The 404 for an id that cannot name anything (not 64 lower-case hex digits), answered
// before any lookup.
ServiceError MalformedId(const std::string& what) {
  return Error(ErrorKind::kNotFound, "no " + what + " with that id (ids are 64 hex digits)");
}

// The record that `get`, a Store getter, finds under `id` (a character, motion, bake or
// job): 404 for an id that is malformed or names nothing, 500 when the store fails.
template <typename Record>
Result<Record> FindRecord(Store& store,
                          StatusOr<std::optional<Record>> (Store::*get)(const std::string&),
                          const std::string& what, const std::string& id) {
  if (!api::IsContentId(id)) return MalformedId(what);
  auto record = (store.*get)(id);
  if (!record.ok()) return Internal(record.status());
  if (!record->has_value()) return Error(ErrorKind::kNotFound, "no " + what + " " + id);
  return std::move(**record);
}

// An importer or core failure on uploaded content.
ServiceError ImportError(const Status& status) {
  if (status.code() == StatusCode::kUnsupported)
    return Error(ErrorKind::kUnsupportedMedia, status.message());
  if (status.code() == StatusCode::kInternal) return Internal(status);
  return Error(ErrorKind::kUnprocessable, status.message());
}

Status ValidateFileName(const std::string& name) {
  if (name.empty())
    return InvalidArgument(
        "every file needs a name (?filename=, X-Filename or the part's filename)");
  if (name.size() > 255) return InvalidArgument("file names are limited to 255 bytes");
  if (name == "." || name == "..") return InvalidArgument("'" + name + "' is not a file name");
  for (unsigned char c : name) {
    if (c < 0x20 || c == 0x7f || c == '/' || c == '\\') {
      return InvalidArgument(
          "file names must be plain names: no directories or control characters");
    }
  }
  return Status::Ok();
}

// The files of one upload: at least one, each with a plain name, no two named alike.
Status ValidateUploadFiles(const std::vector<io::SourceFile>& files) {
  if (files.empty()) return InvalidArgument("the upload holds no file");
  std::set<std::string> names;
  for (const io::SourceFile& f : files) {
    if (Status status = ValidateFileName(f.name); !status.ok()) return status;
    if (!names.insert(f.name).second)
      return InvalidArgument("two parts are named '" + f.name + "'");
  }
  return Status::Ok();
}

std::array<uint8_t, 32> HexToBytes(const std::string& hex) {
  std::array<uint8_t, 32> bytes{};
  const auto nibble = [](char c) { return c <= '9' ? c - '0' : c - 'a' + 10; };
  for (size_t q = 0; q < bytes.size() && 2 * q + 1 < hex.size(); ++q) {
    bytes[q] = static_cast<uint8_t>(nibble(hex[2 * q]) * 16 + nibble(hex[2 * q + 1]));
  }
  return bytes;
}

std::string MotionId(const std::string& character_id, const std::string& source_id,
                     const std::string& animation) {
  return io::Sha256Hex("motionlod-motion/1\ncharacter " + character_id + "\nsource " + source_id +
                       "\nanimation " + std::to_string(animation.size()) + ":" + animation + "\n");
}

// The record of animation `animation` of the upload `source_id` as a motion of
// `character_id`; `source` is "character" (the character's own upload) or "file".
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

std::vector<api::FileInfo> ToFileInfos(const std::vector<FileRecord>& files) {
  std::vector<api::FileInfo> infos;
  for (const FileRecord& f : files)
    infos.push_back({f.name, f.blob, static_cast<uint64_t>(f.size)});
  return infos;
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

// Counts an in-flight import; refuses beyond the limit.
class ImportSlot {
 public:
  ImportSlot(std::atomic<int>& count, int limit) : count_(count) {
    acquired_ = count_.fetch_add(1) < limit;
    if (!acquired_) count_.fetch_sub(1);
  }
  ~ImportSlot() {
    if (acquired_) count_.fetch_sub(1);
  }
  bool acquired() const { return acquired_; }

 private:
  std::atomic<int>& count_;
  bool acquired_ = false;
};

}  // namespace

std::string UploadId(const std::vector<io::SourceFile>& files) {
  if (files.size() == 1) return io::Sha256Hex(files[0].bytes);
  std::vector<std::string> lines;
  for (const io::SourceFile& f : files)
    lines.push_back(f.name + '\0' + io::Sha256Hex(f.bytes) + "\n");
  std::sort(lines.begin(), lines.end());
  std::string text;
  for (const std::string& line : lines) text += line;
  return io::Sha256Hex(text);
}

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
                                          const std::string& animation, int bake_threads) {
  pipeline::BakeRequest request;
  request.animation = animation;
  request.fps = resolved.fps;
  request.levels = resolved.levels;
  request.all_levels = resolved.all_levels;
  request.locked_joints = resolved.locked_joints;
  auto variant = core::ParseVariant(resolved.variant);
  request.settings.variant = variant.ok() ? *variant : core::Variant::kVPNOPD;
  request.settings.resolve_rigid_translation = !resolved.keep_pd_translation;
  request.threads = bake_threads;
  return request;
}

Service::Service(const Config& config)
    : config_(config), cache_(config.cache_bytes), bake_seconds_(BakeBounds()) {}

Service::~Service() { Shutdown(); }

StatusOr<std::unique_ptr<Service>> Service::Open(const Config& config) {
  std::unique_ptr<Service> service(new Service(config));
  std::error_code error;
  std::filesystem::create_directories(config.data_dir, error);
  if (error) {
    return Status(StatusCode::kInternal,
                  "cannot create the data directory '" + config.data_dir + "': " + error.message());
  }
  ImportLimits limits;
  limits.memory_bytes = config.import_memory_bytes;
  limits.cpu_seconds = config.import_cpu_seconds;
  limits.wall_seconds = config.import_timeout_seconds;
  limits.output_bytes = config.import_output_bytes;
  auto importer = ImportSandbox::Create(config.import_isolation, config.import_worker, limits);
  if (!importer.ok()) return importer.status();
  service->importer_ = std::move(*importer);
  if (service->importer_->fallback_reason().empty()) {
    spdlog::info("imports run in a {} sandbox", IsolationName(service->importer_->isolation()));
  } else {
    spdlog::warn("imports run as plain processes with limits only: bubblewrap does not work ({})",
                 service->importer_->fallback_reason());
  }
  auto store = Store::Open(std::filesystem::path(config.data_dir) / "motionlodd.db");
  if (!store.ok()) return store.status();
  service->store_ = std::move(*store);
  auto blobs = BlobStore::Open(std::filesystem::path(config.data_dir) / "blobs");
  if (!blobs.ok()) return blobs.status();
  service->blobs_ = std::move(*blobs);
  // Blobs no row names (a crash between writing them and committing, or a delete that
  // stopped half way) are removed.
  auto referenced = service->store_->ReferencedBlobs();
  if (!referenced.ok()) return referenced.status();
  const std::set<std::string> keep(referenced->begin(), referenced->end());
  size_t removed = 0;
  for (const std::string& hash : service->blobs_->List()) {
    if (!keep.count(hash) && service->blobs_->Remove(hash).ok()) ++removed;
  }
  if (removed > 0) spdlog::info("removed {} unreferenced blobs", removed);
  return service;
}

Status Service::Start() {
  auto unfinished = store_->TakeUnfinishedJobs();
  if (!unfinished.ok()) return unfinished.status();
  {
    std::lock_guard lock(board_mutex_);
    for (const std::string& id : *unfinished) {
      auto job = store_->GetJob(id);
      if (!job.ok()) return job.status();
      if (!job->has_value()) continue;
      LiveJob live;
      live.record = **job;
      live.version = next_version_++;
      board_[id] = std::move(live);
    }
  }
  const int workers = config_.threads > 0 ? config_.threads : ResolveThreads(0);
  queue_ = std::make_unique<JobQueue>(
      static_cast<size_t>(config_.queue_capacity), workers, [this](const std::string& id) {
        try {
          RunJob(id);
        } catch (const std::exception& error) {  // out of memory on a huge bake, ...
          spdlog::error("bake {} threw: {}", id, error.what());
          auto job = store_->GetJob(id);
          if (job.ok() && job->has_value()) {
            JobRecord record = **job;
            record.state = "failed";
            record.error_code = "internal";
            record.error_detail = "the bake ran out of resources or hit an internal error";
            record.finished_ms = NowMs();
            (void)store_->UpdateJob(record);
            Publish(record, /*erase=*/true);
          }
          ++bakes_failed_;
        }
      });
  for (const std::string& id : *unfinished) queue_->Push(id, /*force=*/true);
  if (!unfinished->empty()) spdlog::info("requeued {} unfinished jobs", unfinished->size());
  spdlog::info("{} bake workers, {} threads per bake, queue capacity {}", workers,
               config_.bake_threads == 0 ? ResolveThreads(0) : config_.bake_threads,
               config_.queue_capacity);
  return Status::Ok();
}

void Service::BeginDrain() {
  {
    std::lock_guard lock(board_mutex_);
    draining_ = true;
  }
  board_changed_.notify_all();
}

void Service::Shutdown() {
  if (!queue_ || stopping_.load()) return;
  BeginDrain();
  queue_->StopTaking();
  const auto deadline =
      std::chrono::steady_clock::now() +
      std::chrono::milliseconds(static_cast<int64_t>(config_.drain_seconds * 1000));
  while (queue_->running() > 0 && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  {
    std::lock_guard lock(board_mutex_);
    stopping_ = true;
    for (auto& [id, live] : board_) live.cancel->store(true);
  }
  board_changed_.notify_all();
  queue_->Stop();
  spdlog::info("job queue stopped ({} jobs left queued for the next start)", queue_->depth());
}

void Service::Publish(const JobRecord& record, bool erase) {
  {
    std::lock_guard lock(board_mutex_);
    if (erase) {
      board_.erase(record.id);
    } else {
      auto found = board_.find(record.id);
      if (found == board_.end()) return;  // deleted meanwhile
      found->second.record = record;
      found->second.version = next_version_++;
    }
  }
  board_changed_.notify_all();
}

api::JobStatus Service::ToStatus(const JobRecord& r, uint64_t version) const {
  api::JobStatus status;
  status.id = r.id;
  status.bake = r.bake_id;
  status.state = r.state;
  status.progress = r.state == "succeeded" ? 1.0 : r.progress;
  status.stage = r.stage;
  if (!r.error_code.empty()) status.error = api::JobError{r.error_code, r.error_detail};
  status.attempts = r.attempts;
  status.version = version;
  status.created_at = Rfc3339(r.created_ms);
  status.started_at = Rfc3339(r.started_ms);
  status.finished_at = Rfc3339(r.finished_ms);
  return status;
}

Result<api::JobStatus> Service::JobFromStore(const std::string& id) {
  auto job = FindRecord(*store_, &Store::GetJob, "job", id);
  if (!job.ok()) return job.error();
  return ToStatus(*job, 0);
}

StatusOr<std::shared_ptr<const io::Asset>> Service::LoadSource(
    const std::string& source_id, const std::vector<FileRecord>& files) {
  {
    std::lock_guard lock(assets_mutex_);
    for (auto it = assets_.begin(); it != assets_.end(); ++it) {
      if (it->first == source_id) {
        assets_.splice(assets_.begin(), assets_, it);
        return assets_.front().second;
      }
    }
  }
  std::vector<io::SourceFile> sources;
  for (const FileRecord& f : files) {
    auto bytes = blobs_->Get(f.blob);
    if (!bytes.ok()) return bytes.status();
    sources.push_back({f.name, std::move(*bytes)});
  }
  auto asset = Import(sources);
  if (!asset.ok()) return asset.status();
  CacheAsset(source_id, *asset);
  return *asset;
}

StatusOr<std::shared_ptr<const io::Asset>> Service::Import(
    const std::vector<io::SourceFile>& files) {
  io::LoadOptions options;
  options.max_total_bytes = static_cast<size_t>(config_.max_upload_bytes);
  return importer_->Import(files, options);
}

void Service::CacheAsset(const std::string& source_id, std::shared_ptr<const io::Asset> asset) {
  std::lock_guard lock(assets_mutex_);
  assets_.remove_if([&](const auto& entry) { return entry.first == source_id; });
  assets_.emplace_front(source_id, std::move(asset));
  while (assets_.size() > kAssetCacheEntries) assets_.pop_back();
}

Status Service::StoreFiles(const std::vector<io::SourceFile>& files,
                           std::vector<FileRecord>& records) {
  for (const io::SourceFile& f : files) {
    auto hash = blobs_->Put(f.bytes);
    if (!hash.ok()) return hash.status();
    records.push_back({f.name, *hash, static_cast<int64_t>(f.bytes.size())});
  }
  return Status::Ok();
}

void Service::CollectBlobs(const std::vector<std::string>& blobs) {
  std::unique_lock lock(blobs_mutex_);
  for (const std::string& hash : blobs) {
    auto referenced = store_->IsBlobReferenced(hash);
    if (!referenced.ok() || *referenced) continue;
    cache_.Erase(hash);
    if (Status status = blobs_->Remove(hash); !status.ok())
      spdlog::warn("blob {}: {}", hash, status.message());
  }
}

// ---------------------------------------------------------------------------------------
// Characters and motions

Result<Created<api::CharacterInfo>> Service::UploadCharacter(std::vector<io::SourceFile> files) {
  if (Status status = ValidateUploadFiles(files); !status.ok())
    return Error(ErrorKind::kBadRequest, status.message());
  const std::string id = UploadId(files);
  auto existing = store_->GetCharacter(id);
  if (!existing.ok()) return Internal(existing.status());
  if (existing->has_value()) {
    auto character = GetCharacter(id);
    if (!character.ok()) return character.error();
    return Created<api::CharacterInfo>{character.value(), false};
  }
  ImportSlot slot(imports_, config_.max_concurrent_imports);
  if (!slot.acquired()) {
    return Error(ErrorKind::kUnavailable, "too many uploads are being imported; retry shortly", 2);
  }
  auto asset = Import(files);
  if (!asset.ok()) return ImportError(asset.status());
  const core::RawCharacter& raw = (*asset)->character();
  if (auto built = core::BuildCharacter(raw); !built.ok()) {
    return Error(ErrorKind::kUnprocessable,
                 "the character cannot be baked: " + built.status().message());
  }
  CharacterRecord record;
  record.id = id;
  record.name = files[0].name;
  std::shared_lock blob_lock(blobs_mutex_);
  if (Status status = StoreFiles(files, record.files); !status.ok()) return Internal(status);
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
  auto inserted = store_->InsertCharacter(record, motions);
  if (!inserted.ok()) return Internal(inserted.status());
  CacheAsset(id, *asset);
  spdlog::info("character {} '{}': {} joints, {} vertices, {} animations", id, record.name,
               record.joints, record.vertices, motions.size());
  auto character = GetCharacter(id);
  if (!character.ok()) return character.error();
  return Created<api::CharacterInfo>{character.value(), *inserted};
}

Result<api::CharacterInfo> Service::GetCharacter(const std::string& id) {
  auto record = FindRecord(*store_, &Store::GetCharacter, "character", id);
  if (!record.ok()) return record.error();
  auto motions = store_->ListMotions(id);
  if (!motions.ok()) return Internal(motions.status());
  return ToCharacterInfo(*record, *motions);
}

Result<std::vector<api::CharacterInfo>> Service::ListCharacters() {
  auto records = store_->ListCharacters();
  if (!records.ok()) return Internal(records.status());
  std::vector<api::CharacterInfo> list;
  for (const CharacterRecord& c : *records) {
    auto motions = store_->ListMotions(c.id);
    if (!motions.ok()) return Internal(motions.status());
    list.push_back(ToCharacterInfo(c, *motions));
  }
  return list;
}

Result<Done> Service::DeleteCharacter(const std::string& id) {
  if (!api::IsContentId(id)) return MalformedId("character");
  auto bakes = store_->ListBakes(id);
  if (!bakes.ok()) return Internal(bakes.status());
  auto blobs = store_->DeleteCharacter(id);
  if (!blobs.ok()) {
    if (blobs.status().code() == StatusCode::kNotFound)
      return Error(ErrorKind::kNotFound, "no character " + id);
    return Internal(blobs.status());
  }
  for (const BakeRecord& bake : *bakes) ForgetBake(bake.id);
  {
    std::lock_guard lock(assets_mutex_);
    assets_.remove_if([&](const auto& entry) { return entry.first == id; });
  }
  CollectBlobs(*blobs);
  spdlog::info("deleted character {} and {} bakes", id, bakes->size());
  return Done{};
}

Result<Created<std::vector<api::MotionInfo>>> Service::UploadMotion(
    const std::string& character_id, std::vector<io::SourceFile> files) {
  if (!api::IsContentId(character_id)) {
    return Error(ErrorKind::kBadRequest,
                 "?character= must be a character id (64 lower-case hex digits)");
  }
  auto character = FindRecord(*store_, &Store::GetCharacter, "character", character_id);
  if (!character.ok()) return character.error();
  if (Status status = ValidateUploadFiles(files); !status.ok())
    return Error(ErrorKind::kBadRequest, status.message());
  const std::string source_id = UploadId(files);
  ImportSlot slot(imports_, config_.max_concurrent_imports);
  if (!slot.acquired()) {
    return Error(ErrorKind::kUnavailable, "too many uploads are being imported; retry shortly", 2);
  }
  auto target = LoadSource(character_id, character->files);
  if (!target.ok()) return Internal(target.status());
  auto asset = Import(files);
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
    auto existing = store_->GetMotion(m.id);
    if (!existing.ok()) return Internal(existing.status());
    created = created || !existing->has_value();
  }
  std::vector<FileRecord> records;
  std::shared_lock blob_lock(blobs_mutex_);
  if (Status status = StoreFiles(files, records); !status.ok()) return Internal(status);
  for (MotionRecord& m : motions) m.files = records;
  if (Status status = store_->InsertMotions(motions); !status.ok()) return Internal(status);
  CacheAsset(source_id, *asset);
  std::vector<api::MotionInfo> infos;
  for (const MotionRecord& m : motions) infos.push_back(ToMotionInfo(m));
  return Created<std::vector<api::MotionInfo>>{std::move(infos), created};
}

Result<api::MotionInfo> Service::GetMotion(const std::string& id) {
  auto motion = FindRecord(*store_, &Store::GetMotion, "motion", id);
  if (!motion.ok()) return motion.error();
  return ToMotionInfo(*motion);
}

Result<std::vector<api::MotionInfo>> Service::ListMotions(const std::string& character_id) {
  if (!api::IsContentId(character_id))
    return Error(ErrorKind::kNotFound, "no character with that id");
  auto character = FindRecord(*store_, &Store::GetCharacter, "character", character_id);
  if (!character.ok()) return character.error();
  auto motions = store_->ListMotions(character_id);
  if (!motions.ok()) return Internal(motions.status());
  std::vector<api::MotionInfo> list;
  for (const MotionRecord& m : *motions) list.push_back(ToMotionInfo(m));
  return list;
}

// ---------------------------------------------------------------------------------------
// Bakes and jobs

Result<Created<api::JobStatus>> Service::SubmitBake(const api::BakeRequest& request) {
  if (draining_) return Error(ErrorKind::kUnavailable, "the daemon is shutting down", 5);
  auto character = FindRecord(*store_, &Store::GetCharacter, "character", request.character);
  if (!character.ok()) return character.error();
  const CharacterRecord& c = *character;
  auto motions = store_->ListMotions(c.id);
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
      auto other = store_->GetMotion(request.motion);
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
      MakePipelineRequest(resolved, motion->animation, config_.bake_threads);
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
  auto inserted = store_->InsertBakeAndJob(bake, job);
  if (!inserted.ok()) return Internal(inserted.status());
  if (!*inserted) {
    auto status = GetJob(key.id);
    if (!status.ok()) return status.error();
    return Created<api::JobStatus>{status.value(), false};
  }
  {
    std::lock_guard lock(board_mutex_);
    LiveJob live;
    live.record = job;
    live.version = next_version_++;
    board_[job.id] = std::move(live);
  }
  const JobQueue::PushResult pushed =
      queue_ ? queue_->Push(job.id) : JobQueue::PushResult::kStopped;
  if (pushed == JobQueue::PushResult::kFull || pushed == JobQueue::PushResult::kStopped) {
    {
      std::lock_guard lock(board_mutex_);
      board_.erase(job.id);
    }
    (void)store_->DeleteBake(job.id);
    if (pushed == JobQueue::PushResult::kStopped) {
      return Error(ErrorKind::kUnavailable, "the daemon is shutting down", 5);
    }
    return Error(
        ErrorKind::kUnavailable,
        "the bake queue is full (" + std::to_string(queue_->capacity()) + " waiting); retry later",
        5);
  }
  spdlog::info("bake {} queued: character {}, animation '{}'", key.id, c.id, motion->animation);
  auto status = GetJob(key.id);
  if (!status.ok()) return status.error();
  return Created<api::JobStatus>{status.value(), true};
}

Result<api::JobStatus> Service::GetJob(const std::string& id) {
  if (!api::IsContentId(id)) return MalformedId("job");
  {
    std::lock_guard lock(board_mutex_);
    if (auto found = board_.find(id); found != board_.end()) {
      return ToStatus(found->second.record, found->second.version);
    }
  }
  return JobFromStore(id);
}

Result<api::JobStatus> Service::WaitJob(const std::string& id, uint64_t after_version,
                                        double seconds) {
  if (!api::IsContentId(id)) return MalformedId("job");
  const auto deadline =
      std::chrono::steady_clock::now() +
      std::chrono::milliseconds(static_cast<int64_t>(std::max(0.0, seconds) * 1000));
  std::unique_lock lock(board_mutex_);
  while (true) {
    const auto found = board_.find(id);
    if (found == board_.end()) {
      lock.unlock();
      return JobFromStore(id);
    }
    if (found->second.version > after_version || draining_ ||
        std::chrono::steady_clock::now() >= deadline) {
      return ToStatus(found->second.record, found->second.version);
    }
    board_changed_.wait_until(lock, deadline);
  }
}

void Service::RunJob(const std::string& id) {
  std::shared_ptr<std::atomic<bool>> cancel;
  JobRecord job;
  {
    std::lock_guard lock(board_mutex_);
    const auto found = board_.find(id);
    if (found == board_.end()) return;  // deleted while queued
    cancel = found->second.cancel;
    job = found->second.record;
  }
  if (cancel->load()) return;
  const auto fail = [&](const std::string& code, const std::string& detail) {
    job.state = "failed";
    job.error_code = code;
    job.error_detail = detail;
    job.finished_ms = NowMs();
    if (auto updated = store_->UpdateJob(job); !updated.ok())
      spdlog::error("job {}: {}", id, updated.status().message());
    Publish(job, /*erase=*/true);
    ++bakes_failed_;
    spdlog::warn("bake {} failed: {}: {}", id, code, detail);
  };
  auto bake = store_->GetBake(id);
  if (!bake.ok()) return fail("internal", bake.status().message());
  if (!bake->has_value()) return Publish(job, true);
  job.state = "running";
  job.attempts += 1;
  job.started_ms = NowMs();
  job.finished_ms = 0;
  job.progress = 0;
  job.stage = "import";
  job.error_code.clear();
  job.error_detail.clear();
  if (auto updated = store_->UpdateJob(job); !updated.ok() || !*updated) return Publish(job, true);
  Publish(job);
  spdlog::info("bake {} running (attempt {})", id, job.attempts);

  auto request = api::ParseBakeRequest((*bake)->request_json);
  if (!request.ok()) return fail("internal", "stored request: " + request.status().message());
  auto character = store_->GetCharacter((*bake)->character_id);
  auto motion = store_->GetMotion((*bake)->motion_id);
  if (!character.ok() || !motion.ok() || !character->has_value() || !motion->has_value()) {
    return Publish(job, true);  // deleted meanwhile
  }
  const MotionRecord& m = **motion;
  pipeline::BakeRequest p = MakePipelineRequest(*request, m.animation, config_.bake_threads);
  auto character_asset = LoadSource((*character)->id, (*character)->files);
  if (!character_asset.ok())
    return fail(StatusCodeName(character_asset.status().code()),
                character_asset.status().message());
  p.character = *character_asset;
  p.character_label = (*character)->name;
  if (m.source == "file") {
    auto motion_asset = LoadSource(m.source_id, m.files);
    if (!motion_asset.ok())
      return fail(StatusCodeName(motion_asset.status().code()), motion_asset.status().message());
    p.motion = *motion_asset;
    p.motion_label = m.files.empty() ? "" : m.files[0].name;
  }
  p.source_hash = MakeBakeKey(*request, m.source == "file" ? m.source_id : "character", m.animation,
                              p.settings.Hash())
                      .source_hash;
  const auto start = std::chrono::steady_clock::now();
  auto last_publish = start - std::chrono::seconds(1);
  auto output = pipeline::Bake(
      p,
      [&](const pipeline::BakeProgress& progress) {
        job.progress = progress.fraction;
        job.stage = progress.stage;
        const auto now = std::chrono::steady_clock::now();
        if (now - last_publish >= std::chrono::milliseconds(50) || progress.fraction >= 1.0) {
          last_publish = now;
          Publish(job);
        }
      },
      cancel.get());
  if (cancel->load()) {
    if (stopping_) {
      job.state = "queued";
      job.progress = 0;
      job.stage = "";
      (void)store_->UpdateJob(job);
      ++bakes_interrupted_;
      spdlog::info("bake {} interrupted by shutdown; it runs again at the next start", id);
    }
    return Publish(job, true);
  }
  if (!output.ok()) return fail(StatusCodeName(output.status().code()), output.status().message());
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  job.stage = "store";
  std::vector<std::string> written;
  if (Status status = FinishBake(**bake, std::move(*output), job, written); !status.ok()) {
    CollectBlobs(written);  // what no row names (the bake was deleted meanwhile)
    if (status.code() == StatusCode::kNotFound) return Publish(job, true);
    return fail("internal", status.message());
  }
  bake_seconds_.Observe(seconds);
  ++bakes_succeeded_;
  Publish(job, true);
  spdlog::info("bake {} succeeded in {:.3f} s", id, seconds);
}

Status Service::FinishBake(const BakeRecord& bake_in, pipeline::BakeOutput output, JobRecord& job,
                           std::vector<std::string>& written) {
  std::shared_lock blob_lock(blobs_mutex_);
  const proto::AlignedBytes aligned = proto::AlignedBytes::CopyOf(output.level_set);
  auto view = proto::DecodeLevelSet(aligned.bytes());
  if (!view.ok())
    return Status(StatusCode::kInternal,
                  "the bake wrote an unreadable level set: " + view.status().message());
  std::vector<LevelRecord> levels;
  for (uint32_t l = 0; l < view->level_count(); ++l) {
    auto one = proto::ExtractLevel(*view, l);
    if (!one.ok()) return one.status();
    auto hash = blobs_->Put(*one);
    if (!hash.ok()) return hash.status();
    written.push_back(*hash);
    levels.push_back({static_cast<int>(l), static_cast<int>(view->level(l).kept_count()), *hash,
                      static_cast<int64_t>(one->size())});
    cache_.Put(*hash, std::make_shared<const std::string>(std::move(*one)));
  }
  auto level_set = blobs_->Put(output.level_set);
  if (!level_set.ok()) return level_set.status();
  written.push_back(*level_set);
  BakeRecord bake = bake_in;
  bake.level_set = *level_set;
  bake.level_set_bytes = static_cast<int64_t>(output.level_set.size());
  bake.report_json = output.report.dump();
  bake.frames = static_cast<int>(view->frame_count());
  bake.fps = view->fps();
  job.state = "succeeded";
  job.progress = 1;
  job.stage = "done";
  job.finished_ms = NowMs();
  if (Status status = store_->CompleteBake(bake, levels, job); !status.ok()) return status;
  return Status::Ok();
}

StatusOr<std::shared_ptr<const Service::LevelTable>> Service::GetLevelTable(
    const BakeRecord& bake) {
  {
    std::lock_guard lock(tables_mutex_);
    if (auto found = tables_.find(bake.id); found != tables_.end()) return found->second;
  }
  auto levels = store_->GetLevels(bake.id);
  if (!levels.ok()) return levels.status();
  const json report = json::parse(bake.report_json, nullptr, false);
  if (!report.is_object() || !report.contains("levels") || !report["levels"].is_array() ||
      report["levels"].size() != levels->size()) {
    return Status(StatusCode::kDataLoss,
                  "the stored report of bake " + bake.id + " does not match its levels");
  }
  auto table = std::make_shared<LevelTable>();
  const size_t count = levels->size();
  std::vector<double> limits(count);
  for (size_t l = 0; l < count; ++l) {
    const json& level = report["levels"][l];
    const double pct = level.value("max_vertex_error_pct", 0.0);
    table->max_error_fraction.push_back(pct / 100.0);
    limits[l] = core::MaxPixelHeightForBudget(pct / 100.0, 1.0);
    api::LevelEntry entry;
    entry.index = static_cast<int>(l);
    entry.joints = (*levels)[l].joints;
    entry.max_vertex_error_pct = pct;
    entry.mean_vertex_error_pct = level.value("mean_vertex_error_pct", 0.0);
    entry.mean_normal_error_deg = level.value("mean_normal_error_deg", 0.0);
    entry.mean_e = level.value("mean_E", 0.0);
    if (std::isfinite(limits[l])) entry.max_px_for_1px_error = limits[l];
    entry.hash = (*levels)[l].hash;
    entry.bytes = static_cast<uint64_t>((*levels)[l].bytes);
    table->entries.push_back(std::move(entry));
  }
  // core::SelectLevel picks the coarsest level l with err_l * px <= budget, the finest
  // when none: level l > 0 serves (max_{k>l} limit_k, limit_l], level 0 everything above
  // the coarser levels' limits.
  for (size_t l = 0; l < count; ++l) {
    double lower = 0;
    for (size_t k = l + 1; k < count; ++k) lower = std::max(lower, limits[k]);
    api::LevelEntry& entry = table->entries[l];
    entry.px_min = lower;
    if (l == 0) {
      entry.chosen = true;
    } else {
      entry.chosen = lower < limits[l];
      if (std::isfinite(limits[l])) entry.px_max = limits[l];
    }
  }
  std::lock_guard lock(tables_mutex_);
  if (tables_.size() >= kLevelTableEntries) tables_.clear();
  tables_[bake.id] = table;
  return std::shared_ptr<const LevelTable>(table);
}

Result<api::BakeInfo> Service::ToBakeInfo(const BakeRecord& bake) {
  api::BakeInfo info;
  info.id = bake.id;
  info.character = bake.character_id;
  info.motion = bake.motion_id;
  auto request = api::ParseBakeRequest(bake.request_json);
  if (request.ok()) info.request = *request;
  auto motion = store_->GetMotion(bake.motion_id);
  if (motion.ok() && motion->has_value()) info.animation = (*motion)->animation;
  info.variant = info.request.variant;
  auto job = GetJob(bake.id);
  info.state = job.ok() ? job->state : "unknown";
  info.created_at = Rfc3339(bake.created_ms);
  if (!bake.level_set.empty()) {
    info.frames = bake.frames;
    info.fps = bake.fps;
    info.level_set = bake.level_set;
    info.level_set_bytes = static_cast<uint64_t>(bake.level_set_bytes);
    auto table = GetLevelTable(bake);
    if (!table.ok()) return Internal(table.status());
    info.levels = (*table)->entries;
  }
  return info;
}

Result<api::BakeInfo> Service::GetBake(const std::string& id) {
  auto bake = FindRecord(*store_, &Store::GetBake, "bake", id);
  if (!bake.ok()) return bake.error();
  return ToBakeInfo(*bake);
}

Result<std::vector<api::BakeInfo>> Service::ListBakes(const std::string& character_id) {
  if (!character_id.empty() && !api::IsContentId(character_id)) {
    return Error(ErrorKind::kBadRequest,
                 "?character= must be a character id (64 lower-case hex digits)");
  }
  auto bakes = store_->ListBakes(character_id);
  if (!bakes.ok()) return Internal(bakes.status());
  std::vector<api::BakeInfo> list;
  for (const BakeRecord& bake : *bakes) {
    auto full = store_->GetBake(bake.id);
    if (!full.ok() || !full->has_value()) continue;
    auto info = ToBakeInfo(**full);
    if (info.ok()) list.push_back(std::move(info.value()));
  }
  return list;
}

Result<std::string> Service::GetReport(const std::string& bake_id) {
  auto bake = FindRecord(*store_, &Store::GetBake, "bake", bake_id);
  if (!bake.ok()) return bake.error();
  if (bake->report_json.empty()) {
    auto job = GetJob(bake_id);
    return Error(ErrorKind::kConflict, "bake " + bake_id + " has not succeeded (state: " +
                                           (job.ok() ? job->state : std::string("unknown")) + ")");
  }
  return std::move(bake->report_json);
}

Result<Done> Service::DeleteBake(const std::string& id) {
  if (!api::IsContentId(id)) return MalformedId("bake");
  auto blobs = store_->DeleteBake(id);
  if (!blobs.ok()) {
    if (blobs.status().code() == StatusCode::kNotFound)
      return Error(ErrorKind::kNotFound, "no bake " + id);
    return Internal(blobs.status());
  }
  ForgetBake(id);
  CollectBlobs(*blobs);
  spdlog::info("deleted bake {}", id);
  return Done{};
}

void Service::ForgetBake(const std::string& id) {
  if (queue_) queue_->Remove(id);
  {
    std::lock_guard lock(board_mutex_);
    if (auto found = board_.find(id); found != board_.end()) {
      found->second.cancel->store(true);
      board_.erase(found);
    }
  }
  board_changed_.notify_all();
  std::lock_guard lock(tables_mutex_);
  tables_.erase(id);
}

Result<api::LevelChoice> Service::ChooseLevel(const std::string& bake_id, double px,
                                              double budget_px) {
  if (!api::IsContentId(bake_id)) return MalformedId("bake");
  if (!(px > 0) || !std::isfinite(px) || px > 1e6) {
    return Error(ErrorKind::kBadRequest,
                 "px (the character's on-screen height in pixels) must be in (0, 1e6]");
  }
  if (!(budget_px > 0) || !std::isfinite(budget_px) || budget_px > 1e4) {
    return Error(ErrorKind::kBadRequest,
                 "budget (the tolerated error in pixels) must be in (0, 1e4]");
  }
  std::shared_ptr<const LevelTable> table;
  {
    std::lock_guard lock(tables_mutex_);
    if (auto found = tables_.find(bake_id); found != tables_.end()) table = found->second;
  }
  if (!table) {
    auto bake = BakeWithLevels(bake_id);
    if (!bake.ok()) return bake.error();
    auto loaded = GetLevelTable(bake.value());
    if (!loaded.ok()) return Internal(loaded.status());
    table = *loaded;
  }
  const int l = core::SelectLevel(table->max_error_fraction, px, budget_px);
  const api::LevelEntry& entry = table->entries[static_cast<size_t>(l)];
  api::LevelChoice choice;
  choice.bake = bake_id;
  choice.px = px;
  choice.budget_px = budget_px;
  choice.index = l;
  choice.joints = entry.joints;
  choice.max_vertex_error_pct = entry.max_vertex_error_pct;
  choice.error_px = px * entry.max_vertex_error_pct / 100.0;
  choice.within_budget = choice.error_px <= budget_px;
  choice.hash = entry.hash;
  choice.url = "/v1/levels/" + entry.hash;
  choice.bytes = entry.bytes;
  return choice;
}

Result<LevelCache::Bytes> Service::GetLevel(const std::string& hash) {
  if (!api::IsContentId(hash))
    return Error(ErrorKind::kNotFound, "no level with that hash (hashes are 64 hex digits)");
  if (LevelCache::Bytes bytes = cache_.Get(hash)) return bytes;
  auto size = store_->LevelBytes(hash);
  if (!size.ok()) return Internal(size.status());
  if (!size->has_value()) return Error(ErrorKind::kNotFound, "no level " + hash);
  auto bytes = blobs_->Get(hash);
  if (!bytes.ok()) {
    if (bytes.status().code() == StatusCode::kNotFound)
      return Error(ErrorKind::kNotFound, "no level " + hash);
    return Internal(bytes.status());
  }
  auto shared = std::make_shared<const std::string>(std::move(*bytes));
  cache_.Put(hash, shared);
  return LevelCache::Bytes(shared);
}

Result<BakeRecord> Service::BakeWithLevels(const std::string& bake_id) {
  auto bake = FindRecord(*store_, &Store::GetBake, "bake", bake_id);
  if (!bake.ok()) return bake.error();
  if (bake->level_set.empty()) {
    auto job = GetJob(bake_id);
    return Error(ErrorKind::kConflict, "bake " + bake_id + " has no levels yet (state: " +
                                           (job.ok() ? job->state : std::string("unknown")) +
                                           "); wait on /v1/jobs/" + bake_id);
  }
  return bake;
}

Result<Service::GltfFile> Service::GetLevelGltf(const std::string& bake_id, int joints) {
  auto bake = BakeWithLevels(bake_id);
  if (!bake.ok()) return bake.error();
  auto levels = store_->GetLevels(bake_id);
  if (!levels.ok()) return Internal(levels.status());
  const LevelRecord* level = nullptr;
  std::string available;
  for (const LevelRecord& record : *levels) {
    if (record.joints == joints) level = &record;
    available += (available.empty() ? "" : ", ") + std::to_string(record.joints);
  }
  if (level == nullptr) {
    return Error(ErrorKind::kNotFound, "bake " + bake_id + " has no level with " +
                                           std::to_string(joints) + " joints; its levels keep " +
                                           available);
  }
  auto motion = store_->GetMotion(bake->motion_id);
  if (!motion.ok()) return Internal(motion.status());
  const std::string animation = motion->has_value() ? (*motion)->animation : std::string();
  GltfFile file;
  // The version after "motionlod-gltf/" changes whenever the exporter writes other bytes.
  file.key = io::Sha256Hex("motionlod-gltf/1\nlevel " + level->hash + "\ncharacter " +
                           bake->character_id + "\nanimation " +
                           std::to_string(animation.size()) + ":" + animation + "\n");
  if ((file.glb = cache_.Get(file.key))) return file;
  auto one_level = GetLevel(level->hash);
  if (!one_level.ok()) return one_level.error();
  auto character = FindRecord(*store_, &Store::GetCharacter, "character", bake->character_id);
  if (!character.ok()) return character.error();
  auto asset = LoadSource(character->id, character->files);
  if (!asset.ok()) return Internal(asset.status());
  auto exported = pipeline::ExportLevelGltf(**asset, *one_level.value(), joints, animation);
  if (!exported.ok()) return Internal(exported.status());
  file.glb = std::make_shared<const std::string>(std::move(exported->glb));
  cache_.Put(file.key, file.glb);
  return file;
}

bool Service::Ready() { return !draining_ && queue_ != nullptr && store_->Healthy(); }

void Service::RenderMetrics(std::string& out) {
  const auto gauge = [&](const char* name, const char* help, const std::string& value) {
    out += std::string("# HELP ") + name + " " + help + "\n# TYPE " + name + " gauge\n" + name +
           " " + value + "\n";
  };
  gauge("motionlodd_queue_depth", "Bakes waiting in the queue.",
        std::to_string(queue_ ? queue_->depth() : 0));
  gauge("motionlodd_queue_capacity", "Queued bakes beyond which submissions get 503.",
        std::to_string(config_.queue_capacity));
  gauge("motionlodd_jobs_running", "Bakes running now.",
        std::to_string(queue_ ? queue_->running() : 0));
  if (auto counts = store_->CountJobsByState(); counts.ok()) {
    out += "# HELP motionlodd_jobs Jobs in the store by state.\n# TYPE motionlodd_jobs gauge\n";
    for (const auto& [state, count] : *counts) {
      out +=
          "motionlodd_jobs{state=\"" + EscapeLabel(state) + "\"} " + std::to_string(count) + "\n";
    }
  }
  out +=
      "# HELP motionlodd_bakes_total Bakes finished by this process, by outcome.\n"
      "# TYPE motionlodd_bakes_total counter\n";
  out += "motionlodd_bakes_total{outcome=\"succeeded\"} " +
         std::to_string(bakes_succeeded_.load()) + "\n";
  out +=
      "motionlodd_bakes_total{outcome=\"failed\"} " + std::to_string(bakes_failed_.load()) + "\n";
  out += "motionlodd_bakes_total{outcome=\"interrupted\"} " +
         std::to_string(bakes_interrupted_.load()) + "\n";
  out +=
      "# HELP motionlodd_bake_duration_seconds Wall time of successful bakes.\n"
      "# TYPE motionlodd_bake_duration_seconds histogram\n";
  bake_seconds_.Render(out, "motionlodd_bake_duration_seconds", "");
  const LevelCache::Stats cache = cache_.stats();
  out +=
      "# HELP motionlodd_level_cache_requests_total Level cache lookups by result.\n"
      "# TYPE motionlodd_level_cache_requests_total counter\n";
  out +=
      "motionlodd_level_cache_requests_total{result=\"hit\"} " + std::to_string(cache.hits) + "\n";
  out += "motionlodd_level_cache_requests_total{result=\"miss\"} " + std::to_string(cache.misses) +
         "\n";
  out +=
      "# HELP motionlodd_level_cache_evictions_total Levels evicted from the cache.\n"
      "# TYPE motionlodd_level_cache_evictions_total "
      "counter\nmotionlodd_level_cache_evictions_total " +
      std::to_string(cache.evictions) + "\n";
  gauge("motionlodd_level_cache_bytes", "Bytes held by the level cache.",
        std::to_string(cache.bytes));
  gauge("motionlodd_level_cache_entries", "Levels held by the level cache.",
        std::to_string(cache.entries));
  gauge("motionlodd_level_cache_capacity_bytes", "The level cache's byte budget.",
        std::to_string(cache.capacity));
  gauge("motionlodd_imports_in_progress", "Uploads being imported now.",
        std::to_string(imports_.load()));
}

}  // namespace motionlod::server
