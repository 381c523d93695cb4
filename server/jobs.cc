#include "server/jobs.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <thread>

#include "pipeline/task_pool.h"
#include "proto/level_format.h"
#include "server/bakes.h"

namespace motionlod::server {

namespace api = proto::api;

namespace {

// How often a wait on a job that runs on another daemon (or is not running) reads the
// store.
constexpr auto kStorePollInterval = std::chrono::milliseconds(100);

}  // namespace

Status Jobs::Start() {
  auto taken = context_.store->TakeUnfinishedJobs(context_.config.max_job_crashes, NowMs());
  if (!taken.ok()) return taken.status();
  for (const std::string& id : taken->failed) {
    spdlog::error("bake {} was running at the daemon's last {} stops: failed, not run again", id,
                  context_.config.max_job_crashes);
    ++context_.bake_metrics.failed;
  }
  const std::vector<std::string>& unfinished = taken->requeued;
  {
    std::lock_guard lock(board_mutex_);
    for (const std::string& id : unfinished) {
      auto job = context_.store->GetJob(id);
      if (!job.ok()) return job.status();
      if (job->has_value()) PutOnBoard(**job);
    }
  }
  const Config& config = context_.config;
  const int workers = config.threads > 0 ? config.threads : pipeline::ResolveThreads(0);
  auto queue = context_.make_queue(
      static_cast<size_t>(config.queue_capacity), workers,
      [this](const std::string& id) -> JobQueue::RunOutcome {
        bool interrupted = false;
        try {
          Run(id, interrupted);
          return interrupted ? JobQueue::RunOutcome::kInterrupted : JobQueue::RunOutcome::kFinished;
        } catch (const std::exception& error) {  // out of memory on a huge bake, ...
          spdlog::error("bake {} threw: {}", id, error.what());
          auto job = context_.store->GetJob(id);
          if (job.ok() && job->has_value()) {
            JobRecord record = **job;
            record.state = "failed";
            record.error_code = "internal";
            record.error_detail = "the bake ran out of resources or hit an internal error";
            record.finished_ms = NowMs();
            (void)context_.store->UpdateJob(record);
            Publish(record, /*erase=*/true);
          }
          ++context_.bake_metrics.failed;
          return JobQueue::RunOutcome::kFinished;
        }
      });
  if (!queue.ok()) return queue.status();
  queue_ = std::move(*queue);
  for (const std::string& id : unfinished) queue_->Push(id, /*force=*/true);
  if (!unfinished.empty()) spdlog::info("requeued {} unfinished jobs", unfinished.size());
  spdlog::info("{} bake workers, {} threads per bake, queue capacity {}", workers,
               config.bake_threads == 0 ? pipeline::ResolveThreads(0) : config.bake_threads,
               config.queue_capacity);
  return Status::Ok();
}

void Jobs::BeginDrain() {
  {
    std::lock_guard lock(board_mutex_);
    draining_ = true;
  }
  board_changed_.notify_all();
}

void Jobs::Shutdown() {
  if (!queue_ || stopping_.load()) return;
  BeginDrain();
  queue_->StopTaking();
  const auto deadline =
      std::chrono::steady_clock::now() +
      std::chrono::milliseconds(static_cast<int64_t>(context_.config.drain_seconds * 1000));
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

Result<Done> Jobs::Enqueue(const JobRecord& job) {
  const bool shared = context_.store->shared();
  if (!shared) {
    std::lock_guard lock(board_mutex_);
    PutOnBoard(job);
  }
  const JobQueue::PushResult pushed =
      queue_ ? queue_->Push(job.id) : JobQueue::PushResult::kStopped;
  if (pushed == JobQueue::PushResult::kQueued || pushed == JobQueue::PushResult::kAlreadyQueued)
    return Done{};
  if (!shared) {
    std::lock_guard lock(board_mutex_);
    board_.erase(job.id);
  }
  switch (pushed) {
    case JobQueue::PushResult::kStopped:
      return Error(ErrorKind::kUnavailable, "the daemon is shutting down", 5);
    case JobQueue::PushResult::kUnavailable:
      return Error(ErrorKind::kUnavailable, kStorageFaultDetail, 5);
    default:
      return Error(ErrorKind::kUnavailable,
                   "the bake queue is full (" + std::to_string(queue_->capacity()) +
                       " waiting); retry later",
                   5);
  }
}

void Jobs::Cancel(const std::string& id) {
  if (queue_) queue_->Remove(id);
  {
    std::lock_guard lock(board_mutex_);
    if (auto found = board_.find(id); found != board_.end()) {
      found->second.cancel->store(true);
      board_.erase(found);
    }
  }
  board_changed_.notify_all();
}

uint64_t Jobs::NextVersion(const JobRecord& record) {
  return context_.store->shared() ? record.version : next_version_++;
}

Jobs::LiveJob& Jobs::PutOnBoard(const JobRecord& record) {
  LiveJob& live = board_[record.id];
  live = LiveJob{};
  live.record = record;
  live.version = NextVersion(record);
  return live;
}

void Jobs::Publish(const JobRecord& record, bool erase) {
  {
    std::lock_guard lock(board_mutex_);
    if (erase) {
      board_.erase(record.id);
    } else {
      auto found = board_.find(record.id);
      if (found == board_.end()) return;  // deleted meanwhile
      found->second.record = record;
      found->second.version = NextVersion(record);
    }
  }
  board_changed_.notify_all();
}

api::JobStatus Jobs::ToStatus(const JobRecord& r, uint64_t version) const {
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

Result<api::JobStatus> Jobs::FromStore(const std::string& id) {
  auto job = FindRecord(*context_.store, &Store::GetJob, "job", id);
  if (!job.ok()) return job.error();
  return ToStatus(*job, job->version);
}

Result<api::JobStatus> Jobs::Get(const std::string& id) {
  if (!api::IsContentId(id)) return MalformedId("job");
  {
    std::lock_guard lock(board_mutex_);
    if (auto found = board_.find(id); found != board_.end()) {
      return ToStatus(found->second.record, found->second.version);
    }
  }
  return FromStore(id);
}

Result<api::JobStatus> Jobs::Wait(const std::string& id, uint64_t after_version, double seconds) {
  if (!api::IsContentId(id)) return MalformedId("job");
  const auto deadline =
      std::chrono::steady_clock::now() +
      std::chrono::milliseconds(static_cast<int64_t>(std::max(0.0, seconds) * 1000));
  std::unique_lock lock(board_mutex_);
  while (true) {
    const auto found = board_.find(id);
    if (found == board_.end()) {
      lock.unlock();
      return WaitInStore(id, after_version, deadline);
    }
    if (found->second.version > after_version || draining_ ||
        std::chrono::steady_clock::now() >= deadline) {
      return ToStatus(found->second.record, found->second.version);
    }
    board_changed_.wait_until(lock, deadline);
  }
}

Result<api::JobStatus> Jobs::WaitInStore(const std::string& id, uint64_t after_version,
                                         std::chrono::steady_clock::time_point deadline) {
  while (true) {
    auto status = FromStore(id);
    if (!status.ok() || status->version > after_version || status->state == "succeeded" ||
        status->state == "failed" || draining_ || std::chrono::steady_clock::now() >= deadline) {
      return status;
    }
    std::this_thread::sleep_for(kStorePollInterval);
    bool running_here = false;  // it may have started here meanwhile
    {
      std::lock_guard lock(board_mutex_);
      running_here = board_.count(id) > 0;
    }
    if (running_here) {
      const std::chrono::duration<double> left = deadline - std::chrono::steady_clock::now();
      return Wait(id, after_version, left.count());
    }
  }
}

void Jobs::Run(const std::string& id, bool& interrupted) {
  Store& store = *context_.store;
  std::shared_ptr<std::atomic<bool>> cancel;
  JobRecord job;
  {
    std::lock_guard lock(board_mutex_);
    if (const auto found = board_.find(id); found != board_.end()) {
      cancel = found->second.cancel;
      job = found->second.record;
    }
  }
  if (!cancel) {  // queued by another daemon on a shared store, or deleted while queued
    auto stored = store.GetJob(id);
    if (!stored.ok()) {  // the store is down: the queue keeps the job
      spdlog::error("job {}: {}", id, stored.status().message());
      interrupted = true;
      return;
    }
    if (!stored->has_value()) return;
    job = **stored;
    if (job.state == "succeeded" || job.state == "failed") return;  // delivered again
    std::lock_guard lock(board_mutex_);
    cancel = PutOnBoard(job).cancel;
  }
  if (cancel->load()) return;
  const auto fail = [&](const std::string& code, const std::string& detail) {
    job.state = "failed";
    job.error_code = code;
    job.error_detail = detail;
    job.finished_ms = NowMs();
    if (auto updated = store.UpdateJob(job); !updated.ok()) {
      spdlog::error("job {}: {}", id, updated.status().message());
      interrupted = store.shared();  // the failure is told by the next run
    }
    Publish(job, /*erase=*/true);
    ++context_.bake_metrics.failed;
    spdlog::warn("bake {} failed: {}: {}", id, code, detail);
  };
  // A storage fault is told without the server's paths (the log has them), as 'storage':
  // the same bake submitted again runs again. On a shared store it is Redis restarting,
  // most likely: the queue runs the job again (its runs count toward max_job_crashes).
  const auto fail_with = [&](const Status& status) {
    if (status.code() != StatusCode::kUnavailable) {
      return fail(StatusCodeName(status.code()), status.message());
    }
    spdlog::error("bake {}: {}", id, status.message());
    if (store.shared()) {
      interrupted = true;
      return Publish(job, true);
    }
    fail("storage", std::string(kStorageFaultDetail) + "; submit the same bake again to rerun it");
  };
  // Running already: the daemon that ran it died (a shared store's queue took the job
  // over from it).
  if (job.state == "running" && job.attempts >= context_.config.max_job_crashes)
    return fail("crashed", CrashedDetail(context_.config.max_job_crashes));
  auto bake = store.GetBake(id);
  if (!bake.ok()) return fail_with(bake.status());
  if (!bake->has_value()) return Publish(job, true);
  job.state = "running";
  job.attempts += 1;
  job.started_ms = NowMs();
  job.finished_ms = 0;
  job.progress = 0;
  job.stage = "import";
  job.error_code.clear();
  job.error_detail.clear();
  auto updated = store.UpdateJob(job);
  if (!updated.ok()) return fail_with(updated.status());
  if (!*updated) return Publish(job, true);
  Publish(job);
  spdlog::info("bake {} running (attempt {})", id, job.attempts);

  auto request = api::ParseBakeRequest((*bake)->request_json);
  if (!request.ok()) return fail("internal", "stored request: " + request.status().message());
  auto character = store.GetCharacter((*bake)->character_id);
  if (!character.ok()) return fail_with(character.status());
  if (!character->has_value()) return Publish(job, true);  // deleted meanwhile
  std::vector<pipeline::ClipSource> clips;
  std::vector<ClipIdentity> identities;
  std::map<std::string, std::shared_ptr<const io::Asset>> motion_files;  // by upload id
  for (const std::string& motion_id : (*bake)->clip_motions) {
    auto motion = store.GetMotion(motion_id);
    if (!motion.ok()) return fail_with(motion.status());
    if (!motion->has_value()) return Publish(job, true);  // deleted meanwhile
    const MotionRecord& m = **motion;
    pipeline::ClipSource clip{nullptr, m.animation, ""};
    if (m.source == "file") {
      std::shared_ptr<const io::Asset>& file = motion_files[m.source_id];
      if (!file) {
        auto motion_asset = context_.LoadSource(m.source_id, m.files);
        if (!motion_asset.ok()) return fail_with(motion_asset.status());
        file = *motion_asset;
      }
      clip.motion = file;
      clip.label = m.files.empty() ? "" : m.files[0].name;
    }
    clips.push_back(std::move(clip));
    identities.push_back(IdentityOf(m));
  }
  if (clips.empty()) return fail("internal", "the stored bake names no clip");
  pipeline::BakeRequest p = MakePipelineRequest(*request, std::move(clips),
                                                context_.config.bake_threads, context_.config.simd);
  p.max_joint_frames = context_.config.max_joint_frames;
  auto character_asset = context_.LoadSource((*character)->id, (*character)->files);
  if (!character_asset.ok()) return fail_with(character_asset.status());
  p.character = *character_asset;
  p.character_label = (*character)->name;
  p.source_hash = MakeBakeKey(*request, identities, p.settings.Hash()).source_hash;
  const auto start = std::chrono::steady_clock::now();
  auto last_publish = start - std::chrono::seconds(1);
  // Progress reaches this daemon's watchers every 50 ms; on a shared store it is written
  // there too, every 250 ms, for the other daemons' watchers.
  const auto publish_every = std::chrono::milliseconds(store.shared() ? 250 : 50);
  auto output = pipeline::Bake(
      p,
      [&](const pipeline::BakeProgress& progress) {
        job.progress = progress.fraction;
        job.stage = progress.stage;
        const auto now = std::chrono::steady_clock::now();
        if (now - last_publish >= publish_every || progress.fraction >= 1.0) {
          last_publish = now;
          if (store.shared()) (void)store.UpdateJob(job);
          Publish(job);
        }
      },
      cancel.get());
  if (cancel->load()) {
    if (stopping_) {
      job.state = "queued";
      job.progress = 0;
      job.stage = "";
      (void)store.UpdateJob(job);
      interrupted = true;
      ++context_.bake_metrics.interrupted;
      spdlog::info("bake {} interrupted by shutdown; it runs again (at the next start, or now "
                   "on another daemon of a shared store)",
                   id);
    }
    return Publish(job, true);
  }
  if (!output.ok()) return fail_with(output.status());
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  job.stage = "store";
  std::vector<std::string> written;
  if (Status status = FinishBake(**bake, std::move(*output), job, written); !status.ok()) {
    context_.CollectBlobs(written);  // what no row names (the bake was deleted meanwhile)
    if (status.code() == StatusCode::kNotFound) return Publish(job, true);
    return fail_with(status);
  }
  context_.bake_metrics.seconds.Observe(seconds);
  ++context_.bake_metrics.succeeded;
  Publish(job, true);
  spdlog::info("bake {} succeeded in {:.3f} s", id, seconds);
}

Status Jobs::FinishBake(const BakeRecord& bake_in, pipeline::BakeOutput output, JobRecord& job,
                        std::vector<std::string>& written) {
  std::shared_lock blob_lock(context_.blobs_mutex);
  const proto::AlignedBytes aligned = proto::AlignedBytes::CopyOf(output.level_set);
  auto view = proto::DecodeLevelSet(aligned.bytes());
  if (!view.ok())
    return Status(StatusCode::kInternal,
                  "the bake wrote an unreadable level set: " + view.status().message());
  std::vector<LevelRecord> levels;
  for (uint32_t l = 0; l < view->level_count(); ++l) {
    auto one = proto::ExtractLevel(*view, l);
    if (!one.ok()) return one.status();
    auto hash = context_.blobs->Put(*one);
    if (!hash.ok()) return hash.status();
    written.push_back(*hash);
    levels.push_back({static_cast<int>(l), static_cast<int>(view->level(l).kept_count()), *hash,
                      static_cast<int64_t>(one->size())});
    context_.cache.Put(*hash, std::make_shared<const std::string>(std::move(*one)));
  }
  auto level_set = context_.blobs->Put(output.level_set);
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
  if (Status status = context_.store->CompleteBake(bake, levels, job); !status.ok()) return status;
  return Status::Ok();
}

}  // namespace motionlod::server
