// motionlodd: the Motion LoD bake and level-streaming daemon. See docs/SERVER.md.
//   motionlodd [--config FILE] [--port N] [--data-dir DIR] [--bind ADDR] [--threads N] ...
// Prints "listening on http://HOST:PORT" on stdout once it accepts connections. SIGTERM
// and SIGINT drain: stop accepting, end streams, let running bakes finish for up to
// drain_seconds (the rest stay queued for the next start), exit 0.
// Exit codes: 0 after a drain, 1 when it cannot start (bind, data directory), 2 for a bad
// command line or config.
#include <pthread.h>
#include <signal.h>
#include <spdlog/sinks/base_sink.h>
#include <spdlog/spdlog.h>
#include <sys/resource.h>

#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <sstream>
#include <thread>

#include "core/simd.h"
#include "pipeline/allocator.h"
#include "server/config.h"
#include "server/http_server.h"
#include "server/routes.h"
#include "server/service.h"
#include "server/web_assets.h"

namespace motionlod::server {
namespace {

// stderr through a 64 KiB buffer, flushed every second and at every warning: an access
// line costs a formatted copy under a mutex, not a write(2) (spdlog's stderr sink
// flushes every line) nor a wake-up of a logging thread (its asynchronous logger).
class BufferedStderrSink : public spdlog::sinks::base_sink<std::mutex> {
 public:
  BufferedStderrSink() { std::setvbuf(stderr, nullptr, _IOFBF, size_t{1} << 16); }

 protected:
  void sink_it_(const spdlog::details::log_msg& message) override {
    spdlog::memory_buf_t formatted;
    formatter_->format(message, formatted);
    std::fwrite(formatted.data(), 1, formatted.size(), stderr);
  }
  void flush_() override { std::fflush(stderr); }
};

void SetUpLogging(const Config& config) {
  auto logger =
      std::make_shared<spdlog::logger>("motionlodd", std::make_shared<BufferedStderrSink>());
  logger->set_pattern("%Y-%m-%dT%H:%M:%S.%e %l %v");
  logger->set_level(spdlog::level::from_str(config.log_level));
  logger->flush_on(spdlog::level::warn);
  spdlog::set_default_logger(logger);
  spdlog::flush_every(std::chrono::seconds(1));
}

// --seed: upload the files, bake the character and print where its levels are.
void Seed(Service& service, const Options& options, const std::string& base_url) {
  std::vector<io::SourceFile> files;
  for (const std::string& path : options.seed_files) {
    std::ifstream in(path, std::ios::binary);
    if (!in) {
      spdlog::error("seed: cannot read '{}'", path);
      return;
    }
    std::ostringstream bytes;
    bytes << in.rdbuf();
    files.push_back({std::filesystem::path(path).filename().string(), bytes.str()});
  }
  auto character = service.characters().Upload(std::move(files));
  if (!character.ok()) {
    spdlog::error("seed: upload failed: {}", character.error().detail);
    return;
  }
  proto::api::BakeRequest request;
  request.character = character->value.id;
  request.motion = options.seed_animation;
  auto job = service.bakes().Submit(request);
  if (!job.ok()) {
    spdlog::error("seed: bake refused: {}", job.error().detail);
    return;
  }
  const std::string id = job->value.id;
  proto::api::JobStatus status = job->value;
  while (status.state != "succeeded" && status.state != "failed" && !service.draining()) {
    auto waited = service.jobs().Wait(id, status.version, 5.0);
    if (!waited.ok()) return;
    status = waited.value();
  }
  if (status.state != "succeeded") {
    spdlog::error("seed: bake {} {}", id, status.error ? status.error->detail : status.state);
    return;
  }
  std::printf("character %s: %s/v1/characters/%s\n", character->value.name.c_str(),
              base_url.c_str(), character->value.id.c_str());
  std::printf("bake (level table): %s/v1/bakes/%s\n", base_url.c_str(), id.c_str());
  if (auto bake = service.bakes().Get(id); bake.ok()) {
    for (const proto::api::LevelEntry& level : bake->levels) {
      std::string drawn = "never (a coarser level is as accurate)";
      if (level.chosen && level.px_min) {
        char range[96];
        if (level.px_max && *level.px_max - *level.px_min < 0.05) {
          // Two levels whose errors differ in the fifth digit have almost the same limit:
          // the finer one serves a range too narrow to print.
          std::snprintf(range, sizeof range,
                        "only within 0.05 px of %.1f px (a coarser level is almost as good)",
                        *level.px_min);
        } else if (level.px_max) {
          std::snprintf(range, sizeof range, "for heights above %.1f px up to %.1f px",
                        *level.px_min, *level.px_max);
        } else {
          std::snprintf(range, sizeof range, "for heights above %.1f px", *level.px_min);
        }
        drawn = range;
      }
      std::printf("  level %d: %2d joints, max error %.3f%% of the height, %s: %s/v1/levels/%s\n",
                  level.index, level.joints, level.max_vertex_error_pct, drawn.c_str(),
                  base_url.c_str(), level.hash.c_str());
    }
  }
  std::printf("level for a character 120 px tall: %s/v1/bakes/%s/level?px=120\n", base_url.c_str(),
              id.c_str());
  std::fflush(stdout);
}

// Each open connection is a file descriptor: the soft limit (often 1024) goes up to the
// hard one, and a hard limit below max_connections is named.
void RaiseDescriptorLimit(const Config& config) {
  rlimit files{};
  if (::getrlimit(RLIMIT_NOFILE, &files) != 0) return;
  if (files.rlim_cur < files.rlim_max) {
    files.rlim_cur = files.rlim_max;
    ::setrlimit(RLIMIT_NOFILE, &files);
  }
  // Descriptors beyond connections: the database, blobs, import workers, logs.
  constexpr rlim_t kOtherDescriptors = 256;
  const auto wanted = static_cast<rlim_t>(config.max_connections) + kOtherDescriptors;
  if (files.rlim_cur != RLIM_INFINITY && files.rlim_cur < wanted) {
    spdlog::warn("the open-file limit is {} but max_connections is {}: connections beyond about "
                 "{} wait in the listen queue (raise it with ulimit -n or LimitNOFILE=)",
                 files.rlim_cur, config.max_connections,
                 files.rlim_cur > kOtherDescriptors ? files.rlim_cur - kOtherDescriptors : 0);
  }
}

int Main(int argc, char** argv) {
  // Signals go to the thread that waits for them, never to a worker.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGTERM);
  sigaddset(&signals, SIGINT);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);
  ::signal(SIGPIPE, SIG_IGN);

  std::string text;
  auto options = ParseCommandLine(
      argc, argv, [](const char* name) { return std::getenv(name); }, &text);
  if (!options.ok()) {
    std::fprintf(stderr, "motionlodd: %s\n", options.status().message().c_str());
    return 2;
  }
  if (options->exit) {
    std::fputs(text.c_str(), stdout);
    return 0;
  }
  const Config& config = options->config;
  SetUpLogging(config);
  RaiseDescriptorLimit(config);

  auto service = Service::Open(config);
  if (!service.ok()) {
    spdlog::critical("cannot open the data directory: {}", service.status().message());
    spdlog::shutdown();
    return 1;
  }
  if (Status status = (*service)->Start(); !status.ok()) {
    spdlog::critical("cannot start the job queue: {}", status.message());
    spdlog::shutdown();
    return 1;
  }

  std::atomic<int> open_streams{0};
  std::atomic<int> open_uploads{0};
  std::unique_ptr<HttpMetrics> metrics;
  RouteContext context;
  context.service = service->get();
  context.config = &config;
  context.open_streams = &open_streams;
  context.open_uploads = &open_uploads;
  context.render_http_metrics = [&metrics](std::string& out) { metrics->Render(out); };
  auto web = LoadWebAssets(config.web_root);
  if (web.ok()) {
    context.web = &web.value();
    spdlog::info("web viewer: {} files from {}", web->files.size(), config.web_root);
  } else if (!config.web_root.empty()) {
    spdlog::warn("web viewer not served ({}); / says how to build it", web.status().message());
  }
  const http::Router router = MakeRouter(context);
  metrics = std::make_unique<HttpMetrics>(RouteLabels(router));
  HttpServer server(config, router, *metrics);
  auto port = server.Bind();
  if (!port.ok()) {
    spdlog::critical("{}", port.status().message());
    (*service)->Shutdown();
    spdlog::shutdown();
    return 1;
  }
  const std::string host =
      config.bind.find(':') != std::string::npos ? "[" + config.bind + "]" : config.bind;
  const std::string base_url = "http://" + host + ":" + std::to_string(*port);
  spdlog::info("listening on {} (data in {}, {} connection threads, {} hot loops)", base_url,
               config.data_dir, config.http_threads, core::SimdVersionName(config.simd));
  // Read keys alone protect reads, not writes: say so, it is rarely what was meant.
  if (!config.read_keys.empty() && config.write_keys.empty()) {
    spdlog::warn("read_keys are set but write_keys are not: anyone who reaches {} can upload, "
                 "bake and delete; set write_keys to protect writes",
                 base_url);
  }
  spdlog::default_logger()->flush();
  std::printf("listening on %s\n", base_url.c_str());
  if (context.web != nullptr) std::printf("web viewer: %s/\n", base_url.c_str());
  std::fflush(stdout);

  std::thread waiter([&] {
    int signal = 0;
    sigwait(&signals, &signal);
    spdlog::info("{}: draining", signal == SIGTERM ? "SIGTERM" : "SIGINT");
    (*service)->BeginDrain();
    server.Stop();
  });
  waiter.detach();
  std::thread seeder;
  if (!options->seed_files.empty()) {
    seeder = std::thread([&] { Seed(**service, *options, base_url); });
  }

  const bool served = server.Run();
  (*service)->BeginDrain();
  if (seeder.joinable()) seeder.join();
  (*service)->Shutdown();
  spdlog::info("stopped");
  spdlog::shutdown();
  return served ? 0 : 1;
}

}  // namespace
}  // namespace motionlod::server

int main(int argc, char** argv) {
  motionlod::pipeline::KeepFreedBlocksForReuse();
  return motionlod::server::Main(argc, argv);
}
