// motionlod-client: the thin client on the command line, against a running motionlodd.
//   motionlod-client [--server URL] [--api-key KEY] [--cache-dir DIR] [--json] COMMAND
//     upload FILE [FILE...] [--for CHARACTER]   a character (a .gltf with its .bin), or
//                                                with --for a motion file for it
//     bake CHARACTER [--motion M | --clip C... | --clips C,C] [--ranking greedy|paper]
//                    [--levels 17,12,6 | --all-levels] [--variant V] [--fps F]
//                    [--lock J,...] [--no-wait]
//     status JOB [--wait]
//     levels BAKE
//     fetch BAKE (--px PX [--budget B] | --level L) [--clip NAME] -o FILE
// Human-readable output on stdout, or one JSON document with --json; progress and errors
// on stderr. Exit codes: 0 success; 2 bad input (usage, a file that cannot be read, a
// request the daemon refused with 4xx); 1 anything else (daemon unreachable, 5xx, a bake
// that failed, an output that could not be written).
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>

#include "client/client.h"
#include "client/level_selector.h"

namespace motionlod::client {
namespace {

namespace api = proto::api;
using nlohmann::json;

constexpr int kExitFailure = 1;
constexpr int kExitBadInput = 2;

int Fail(const Error& error) {
  std::cerr << "motionlod-client: error: " << error.message << "\n";
  if (error.kind == ErrorKind::kConnection) {
    std::cerr << "  is motionlodd running and listening at that address? (--server or "
                 "MOTIONLOD_SERVER; --retries and --timeout set how long to try)\n";
  }
  if (error.problem && !error.problem->request_id.empty())
    std::cerr << "  (request id " << error.problem->request_id << ")\n";
  const bool bad_input = error.kind == ErrorKind::kInvalidArgument || error.client_error();
  return bad_input ? kExitBadInput : kExitFailure;
}

void PrintJson(const json& value) { std::cout << value.dump(2) << "\n"; }

// A progress bar on stderr: redrawn in place on a terminal, one line per stage otherwise.
class ProgressBar {
 public:
  ProgressBar() : terminal_(::isatty(STDERR_FILENO) == 1) {}
  ~ProgressBar() {
    if (drawn_ && terminal_) std::cerr << "\n";
  }
  void Show(const api::JobStatus& job) {
    const std::string label = job.state == "running" ? job.stage : job.state;
    if (!terminal_) {
      if (label != last_label_) std::cerr << "bake " << job.id.substr(0, 12) << ": " << label << "\n";
      last_label_ = label;
      return;
    }
    constexpr int kWidth = 30;
    const int filled = static_cast<int>(std::lround(std::clamp(job.progress, 0.0, 1.0) * kWidth));
    std::cerr << "\r[" << std::string(filled, '#') << std::string(kWidth - filled, '.') << "] "
              << std::lround(job.progress * 100) << "% " << label << "          " << std::flush;
    drawn_ = true;
  }

 private:
  bool terminal_;
  bool drawn_ = false;
  std::string last_label_;
};

// The bar ends (its line closed) before the caller prints anything else.
Result<api::BakeInfo> WaitWithProgressBar(Client& client, const std::string& job_id) {
  ProgressBar bar;
  return client.WaitForBake(job_id, [&bar](const api::JobStatus& status) { bar.Show(status); });
}

// "(px_min, px_max]" of a chosen level, in tenths of a pixel. Two levels whose errors
// differ in the fifth digit leave the finer one a sliver of heights that would print as
// an empty range such as (71.0, 71.0]: "only ~71.0" says what it is.
std::string PixelRange(double px_min, const std::optional<double>& px_max) {
  auto tenths = [](double value) {
    char buffer[32];
    std::snprintf(buffer, sizeof buffer, "%.1f", value);
    return std::string(buffer);
  };
  if (!px_max) return "(" + tenths(px_min) + ", inf]";
  if (tenths(px_min) == tenths(*px_max)) return "only ~" + tenths(*px_max);
  return "(" + tenths(px_min) + ", " + tenths(*px_max) + "]";
}

void PrintLevels(const api::BakeInfo& bake) {
  std::printf("bake %s: %s, %d frames at %g fps, variant %s, ranking %s\n", bake.id.c_str(),
              bake.state.c_str(), bake.frames, bake.fps, bake.variant.c_str(),
              bake.ranking.c_str());
  for (const api::BakeClip& clip : bake.clips) {
    if (bake.levels.empty()) {
      std::printf("  clip '%s' (motion %s)\n", clip.animation.c_str(), clip.motion.c_str());
    } else {
      std::printf("  clip '%s' (motion %s): frames %d-%d at %g fps\n", clip.animation.c_str(),
                  clip.motion.c_str(), clip.first_frame, clip.first_frame + clip.frames - 1,
                  clip.fps);
    }
  }
  if (bake.levels.empty()) return;
  std::printf("%5s %6s %6s %6s %5s %3s %6s %10s %10s %17s  %s\n", "level", "joints", "verts", "tris",
              "infl", "r", "cost", "max err %", "px (1 px)", "chosen for px", "hash");
  for (const api::LevelEntry& level : bake.levels) {
    const std::string limit =
        level.max_px_for_1px_error ? std::to_string(std::lround(*level.max_px_for_1px_error)) : "exact";
    // A level no height picks (a coarser level is as accurate) has no range.
    const std::string range =
        level.chosen && level.px_min ? PixelRange(*level.px_min, level.px_max) : "never";
    std::printf("%5d %6d %6d %6d %5.2f %3d %6.3f %10.3f %10s %17s  %s\n", level.index, level.joints,
                level.vertices, level.triangles, level.mean_influences, level.frame_stride, level.cost,
                level.max_vertex_error_pct, limit.c_str(), range.c_str(), level.hash.c_str());
  }
}

void PrintBake(const api::BakeInfo& bake, bool as_json) {
  if (as_json) {
    PrintJson(json(bake));
  } else {
    PrintLevels(bake);
  }
}

int RunUpload(Client& client, const std::vector<std::string>& paths, const std::string& for_character,
              bool as_json) {
  std::vector<UploadFile> files;
  for (const std::string& path : paths) {
    auto file = ReadUploadFile(path);
    if (!file.ok()) {
      std::cerr << "motionlod-client: error: " << file.error().message << "\n";
      return kExitBadInput;
    }
    files.push_back(std::move(*file));
  }
  if (!for_character.empty()) {
    auto motions = client.UploadMotion(for_character, files);
    if (!motions.ok()) return Fail(motions.error());
    if (as_json) {
      PrintJson(json{{"created", motions->created}, {"motions", motions->value}});
      return 0;
    }
    for (const api::MotionInfo& motion : motions->value) {
      std::printf("motion %s: '%s', %d frames at %g fps\n", motion.id.c_str(),
                  motion.animation.c_str(), motion.frames, motion.source_fps);
      for (const std::string& warning : motion.warnings) std::printf("  warning: %s\n", warning.c_str());
    }
    return 0;
  }
  auto character = client.UploadCharacter(files);
  if (!character.ok()) return Fail(character.error());
  const api::CharacterInfo& info = character->value;
  if (as_json) {
    json out = info;
    out["created"] = character->created;
    PrintJson(out);
    return 0;
  }
  std::printf("character %s%s: %s, %d joints, %d vertices\n", info.id.c_str(),
              character->created ? "" : " (already there)", info.name.c_str(), info.joints,
              info.vertices);
  for (const api::MotionInfo& animation : info.animations) {
    std::printf("  animation '%s' (motion %s), %d frames\n", animation.animation.c_str(),
                animation.id.c_str(), animation.frames);
  }
  return 0;
}

int RunBake(Client& client, const api::BakeRequest& request, bool wait, bool as_json) {
  auto job = client.SubmitBake(request);
  if (!job.ok()) return Fail(job.error());
  if (!wait) {
    if (as_json) {
      PrintJson(json(*job));
    } else {
      std::printf("job %s: %s\n", job->id.c_str(), job->state.c_str());
    }
    return 0;
  }
  Result<api::BakeInfo> bake = WaitWithProgressBar(client, job->id);
  if (!bake.ok()) return Fail(bake.error());
  PrintBake(*bake, as_json);
  return 0;
}

int RunStatus(Client& client, const std::string& job_id, bool wait, bool as_json) {
  auto job = client.GetJob(job_id);
  if (!job.ok()) return Fail(job.error());
  if (wait && job->state != "succeeded" && job->state != "failed") {
    Result<api::BakeInfo> bake = WaitWithProgressBar(client, job_id);
    if (!bake.ok() && bake.error().kind != ErrorKind::kJobFailed) return Fail(bake.error());
    job = client.GetJob(job_id);
    if (!job.ok()) return Fail(job.error());
  }
  if (as_json) {
    PrintJson(json(*job));
  } else {
    std::printf("job %s: %s, %.0f%% %s\n", job->id.c_str(), job->state.c_str(),
                job->progress * 100, job->stage.c_str());
    if (job->error) std::printf("  error (%s): %s\n", job->error->code.c_str(), job->error->detail.c_str());
  }
  return job->state == "failed" ? kExitFailure : 0;
}

int RunLevels(Client& client, const std::string& bake_id, bool as_json) {
  auto bake = client.GetBake(bake_id);
  if (!bake.ok()) return Fail(bake.error());
  PrintBake(*bake, as_json);
  return 0;
}

int RunFetch(Client& client, const std::string& bake_id, double px, double budget, int level_index,
             const std::string& clip, const std::string& out, bool as_json) {
  auto bake = client.GetBake(bake_id);
  if (!bake.ok()) return Fail(bake.error());
  if (bake->levels.empty()) {
    std::cerr << "motionlod-client: error: bake " << bake_id << " has no levels yet (state "
              << bake->state << ")\n";
    return kExitBadInput;
  }
  if (level_index < 0) {
    auto selector = LevelSelector::FromBake(*bake, SelectorSettings{budget, 0.0});
    if (!selector.ok()) return Fail(selector.error());
    level_index = selector->Choose(px, -1);
  } else if (level_index >= static_cast<int>(bake->levels.size())) {
    std::cerr << "motionlod-client: error: --level " << level_index << ": the bake has "
              << bake->levels.size() << " levels\n";
    return kExitBadInput;
  }
  if (!clip.empty() && std::none_of(bake->clips.begin(), bake->clips.end(),
                                    [&](const api::BakeClip& c) { return c.animation == clip; })) {
    std::string names;
    for (const api::BakeClip& c : bake->clips)
      names += (names.empty() ? "'" : ", '") + c.animation + "'";
    std::cerr << "motionlod-client: error: --clip " << clip << ": bake " << bake_id
              << " has no such clip; its clips: " << names << "\n";
    return kExitBadInput;
  }
  const api::LevelEntry& entry = bake->levels[static_cast<size_t>(level_index)];
  const int downloads_before = client.fetch_stats().downloads;
  auto level = client.FetchLevel(entry.hash, clip);
  if (!level.ok()) return Fail(level.error());
  const bool downloaded = client.fetch_stats().downloads > downloads_before;
  if (auto error = WriteFileAtomically(out, level->level_set().bytes())) return Fail(*error);
  if (as_json) {
    PrintJson(json{{"bake", bake_id},
                   {"clip", clip.empty() ? json(nullptr) : json(clip)},
                   {"index", level_index},
                   {"joints", level->level().kept_count()},
                   {"frames", level->level().frame_count()},
                   {"max_vertex_error_pct", entry.max_vertex_error_pct},
                   {"hash", entry.hash},
                   {"bytes", level->byte_size()},
                   {"downloaded", downloaded},
                   {"path", out}});
  } else {
    std::printf(
        "level %d%s (%u joints, %u frames, max error %.3f%%): %zu bytes %s, written to %s\n",
        level_index, clip.empty() ? "" : (", clip '" + clip + "'").c_str(),
        level->level().kept_count(), level->level().frame_count(), entry.max_vertex_error_pct,
        level->byte_size(), downloaded ? "downloaded" : "from the cache", out.c_str());
  }
  return 0;
}

int Main(int argc, char** argv) {
  CLI::App app{"motionlod-client: upload, bake and fetch Motion LoD levels from motionlodd"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "motionlod-client 0.1.0");
  ClientOptions options;
  bool as_json = false;
  std::string cache_dir;
  app.add_option("--server", options.base_url, "daemon URL, http://HOST:PORT")
      ->envname("MOTIONLOD_SERVER")
      ->capture_default_str();
  app.add_option("--api-key", options.api_key, "API key (better: MOTIONLOD_API_KEY)")
      ->envname("MOTIONLOD_API_KEY");
  app.add_option("--cache-dir", cache_dir, "level cache directory (default: none)")
      ->envname("MOTIONLOD_CACHE_DIR");
  app.add_option("--timeout", options.read_timeout_seconds, "seconds to wait for an answer")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--retries", options.retry.max_attempts, "tries on 503 or connection failure")
      ->check(CLI::Range(1, 100))
      ->capture_default_str();
  app.add_flag("--json", as_json, "print one JSON document on stdout");

  std::vector<std::string> upload_paths;
  std::string for_character;
  CLI::App* upload = app.add_subcommand("upload", "upload a character (or, with --for, a motion)");
  upload->add_option("FILE", upload_paths, "model file, then the files it references")->required();
  upload->add_option("--for", for_character, "character id: upload a motion file for it");

  api::BakeRequest bake_request;
  bool no_wait = false;
  CLI::App* bake = app.add_subcommand("bake", "bake a character's motion and wait for it");
  bake->add_option("CHARACTER", bake_request.character, "character id")->required();
  auto* motion_option = bake->add_option("--motion", bake_request.motion,
                                         "one clip: a motion id or an animation name");
  bake->add_option("--clip,--clips", bake_request.clips,
                   "clips baked together, in order: motion ids or animation names (repeat, or "
                   "a,b; default with no --motion: every motion of the character)")
      ->delimiter(',')
      ->excludes(motion_option);
  bake->add_option("--ranking", bake_request.ranking, "joint ranking: greedy or paper")
      ->check(CLI::IsMember({"greedy", "paper"}))
      ->capture_default_str();
  auto* levels = bake->add_option("--levels", bake_request.levels, "kept joint counts, e.g. 17,12,6")
                     ->delimiter(',');
  bake->add_flag("--all-levels", bake_request.all_levels, "every level down to the root")->excludes(levels);
  bake->add_option("--variant", bake_request.variant, "vp, vpno, vp+pd or vpno+pd (rigid)")
      ->capture_default_str();
  bake->add_option("--fps", bake_request.fps, "sampling rate (default: the source's)")
      ->check(CLI::Range(0.0, 1000.0));
  bake->add_option("--lock", bake_request.locked_joints, "joints no level removes")->delimiter(',');
  bake->add_flag("--keep-pd-translation", bake_request.keep_pd_translation,
                 "rigid variants: keep the solved translation");
  bake->add_flag("--no-wait", no_wait, "print the job and return at once");

  std::string job_id;
  bool status_wait = false;
  CLI::App* status = app.add_subcommand("status", "a job's state and progress");
  status->add_option("JOB", job_id, "job id (= bake id)")->required();
  status->add_flag("--wait", status_wait, "wait until it is finished, with a progress bar");

  std::string levels_bake;
  CLI::App* levels_command = app.add_subcommand("levels", "a bake's level table");
  levels_command->add_option("BAKE", levels_bake, "bake id")->required();

  std::string fetch_bake, fetch_out;
  double px = 0, budget = 1.0;
  int level_index = -1;
  CLI::App* fetch = app.add_subcommand("fetch", "download a level (through the cache)");
  fetch->add_option("BAKE", fetch_bake, "bake id")->required();
  auto* px_option = fetch->add_option("--px", px, "the character's on-screen height, pixels")
                        ->check(CLI::PositiveNumber);
  fetch->add_option("--budget", budget, "largest visible error, pixels")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  auto* level_option =
      fetch->add_option("--level", level_index, "a level index instead")->check(CLI::NonNegativeNumber);
  px_option->excludes(level_option);
  std::string fetch_clip;
  fetch->add_option("--clip", fetch_clip,
                    "only this clip's frames (an animation name of the bake)");
  fetch->add_option("-o,--out", fetch_out, "file to write the level to")->required();

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);
    return code == 0 ? 0 : kExitBadInput;
  }
  if (fetch->parsed() && px_option->count() == 0 && level_option->count() == 0) {
    std::cerr << "motionlod-client: error: fetch needs --px PIXELS or --level INDEX\n";
    return kExitBadInput;
  }
  options.cache_dir = cache_dir;
  options.on_retry = [&options](const RetryEvent& event) {
    std::cerr << "motionlod-client: try " << event.attempt << " of " << options.retry.max_attempts
              << " failed (" << event.reason << "); again in " << event.delay_seconds << " s\n";
  };
  auto client = Client::Create(options);
  if (!client.ok()) return Fail(client.error());
  if (upload->parsed()) return RunUpload(*client, upload_paths, for_character, as_json);
  if (bake->parsed()) return RunBake(*client, bake_request, !no_wait, as_json);
  if (status->parsed()) return RunStatus(*client, job_id, status_wait, as_json);
  if (levels_command->parsed()) return RunLevels(*client, levels_bake, as_json);
  return RunFetch(*client, fetch_bake, px, budget, level_index, fetch_clip, fetch_out, as_json);
}

}  // namespace
}  // namespace motionlod::client

int main(int argc, char** argv) { return motionlod::client::Main(argc, argv); }
