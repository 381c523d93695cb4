// Crash and restart: the real daemon takes 50+ bakes of real characters while it is
// killed with SIGKILL twelve times, each while a bake runs and others wait, at a random
// moment (a seeded random: MOTIONLOD_CRASH_SEED, logged), and started again on the same
// data each time; the log shows the kills cut running bakes. At the end every accepted
// bake has completed exactly once, every stored blob's SHA-256 matches its name, no level
// ever served was partial or corrupt, and no temporary file is left behind.
#include <gtest/gtest.h>
#include <signal.h>

#include <atomic>
#include <cstdlib>
#include <map>
#include <random>
#include <set>
#include <thread>

#include "io/sha256.h"
#include "proto/aligned_bytes.h"
#include "proto/level_format.h"
#include "tests/server/test_util.h"

namespace motionlod::server::testing {
namespace {

namespace fs = std::filesystem;

constexpr int kKills = 12;
constexpr unsigned kDefaultSeed = 20261122;

struct Upload {
  std::string path;
  std::vector<std::string> animations;
  std::vector<std::vector<int>> ladders;  // kept joint counts of each bake
};

std::vector<Upload> Uploads() {
  std::vector<Upload> uploads = {
      {SourcePath("samples/Rig_Medium_MovementBasic.glb"),
       {"Jump_Full_Long", "Jump_Full_Short", "Jump_Idle", "Jump_Land", "Jump_Start", "Running_A",
        "Running_B", "T-Pose", "Walking_A", "Walking_B", "Walking_C"},
       {{20, 10}, {16, 6}, {12, 4}, {23, 8}, {18}}}};
  if (!SharedDataPath("MANIFEST.md").empty()) {
    uploads.push_back(
        {SharedDataPath("characters/Fox.glb"), {"Survey", "Walk", "Run"}, {{12, 6}, {20}}});
  }
  return uploads;
}

// A gauge of the daemon's /metrics; -1 when it cannot be read.
double Gauge(httplib::Client& client, const std::string& name) {
  auto metrics = client.Get("/metrics");
  if (!metrics || metrics->status != 200) return -1;
  const size_t at = metrics->body.find("\n" + name + " ");
  return at == std::string::npos ? -1 : std::atof(metrics->body.c_str() + at + name.size() + 2);
}

// Counts the lines of `text` holding `needle`.
int Count(const std::string& text, const std::string& needle) {
  int count = 0;
  for (size_t at = text.find(needle); at != std::string::npos; at = text.find(needle, at + 1))
    ++count;
  return count;
}

TEST(CrashRestart, BakesSurviveTwelveRandomSigkillsCompletingExactlyOnce) {
  const char* seed_text = std::getenv("MOTIONLOD_CRASH_SEED");
  const unsigned seed = seed_text != nullptr
                            ? static_cast<unsigned>(std::strtoul(seed_text, nullptr, 10))
                            : kDefaultSeed;
  std::mt19937 random(seed);
  std::cout << "MOTIONLOD_CRASH_SEED=" << seed << "\n";

  Daemon daemon(TestDirectory());
  // Twelve kills may land on one bake more than 3 times: that cap is for bakes that kill
  // the daemon themselves (components_test), not for these.
  const std::vector<std::string> args = {"--threads", "1", "--bake-threads", "1",
                                         "--max-job-crashes", "100"};
  ASSERT_TRUE(daemon.Start(args)) << daemon.error;
  auto client = daemon.Client();

  // Characters first (an upload is no bake; it is retried until it is stored).
  std::vector<json> requests;
  for (const Upload& upload : Uploads()) {
    auto uploaded = UploadFile(*client, upload.path, fs::path(upload.path).filename().string());
    ASSERT_TRUE(uploaded);
    ASSERT_TRUE(uploaded->status == 201 || uploaded->status == 200) << uploaded->body;
    const std::string character = Json(uploaded)["id"];
    for (const std::string& animation : upload.animations) {
      for (const std::vector<int>& levels : upload.ladders) {
        requests.push_back(
            {{"character", character}, {"motion", animation}, {"levels", levels}, {"fps", 30}});
      }
    }
  }
  ASSERT_GE(requests.size(), 50u);
  std::shuffle(requests.begin(), requests.end(), random);

  std::map<std::string, json> accepted;  // bake id -> request, once a 202 or 200 came back
  size_t next_request = 0;
  int levels_verified = 0;
  std::set<std::string> seen_succeeded;
  // Submits the next request; fetches and checks a level of a finished bake.
  const auto work_once = [&](httplib::Client& c) {
    if (next_request < requests.size()) {
      auto submitted = SubmitBake(c, requests[next_request]);
      if (submitted && (submitted->status == 202 || submitted->status == 200)) {
        accepted[Json(submitted)["id"]] = requests[next_request];
        ++next_request;
      }
    }
    if (accepted.empty()) return;
    auto it = accepted.begin();
    std::advance(it, std::uniform_int_distribution<size_t>(0, accepted.size() - 1)(random));
    auto bake = c.Get(("/v1/bakes/" + it->first).c_str());
    if (!bake || bake->status != 200) return;
    const json info = Json(bake);
    if (info.value("state", "") != "succeeded" || info["levels"].empty()) return;
    seen_succeeded.insert(it->first);
    const json& level =
        info["levels"][std::uniform_int_distribution<size_t>(0, info["levels"].size() - 1)(random)];
    auto fetched = c.Get(level["url"].get<std::string>().c_str());
    if (!fetched || fetched->status != 200) return;  // cut by the kill: nothing served
    // Served means whole: the bytes hash to their address and decode with their checksum.
    EXPECT_EQ(io::Sha256Hex(fetched->body), level["hash"].get<std::string>());
    const proto::AlignedBytes bytes = proto::AlignedBytes::CopyOf(fetched->body);
    EXPECT_TRUE(proto::DecodeLevelSet(bytes.bytes()).ok());
    ++levels_verified;
  };

  int kills_on_work = 0;  // kills that came while a bake ran and another waited
  for (int kill = 0; kill < kKills; ++kill) {
    const int delay_ms = std::uniform_int_distribution<int>(0, 300)(random);
    std::atomic<bool> killed{false};
    std::thread killer([&] {
      // Each kill lands while a bake runs and others wait (at a random moment of it):
      // the daemon's gauges say when, then the random delay.
      auto watcher = daemon.Client();
      const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
      while (std::chrono::steady_clock::now() < deadline) {
        if (Gauge(*watcher, "motionlodd_jobs_running") >= 1 &&
            Gauge(*watcher, "motionlodd_queue_depth") >= 1) {
          ++kills_on_work;
          break;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(delay_ms));
      EXPECT_EQ(daemon.Stop(SIGKILL), 128 + SIGKILL);
      killed = true;
    });
    while (!killed) work_once(*client);
    killer.join();
    ASSERT_TRUE(daemon.Start(args)) << daemon.error;
    client = daemon.Client();
  }

  // The last run: everything not yet accepted is submitted, then every bake finishes.
  while (next_request < requests.size()) work_once(*client);
  int reruns = 0;  // runs beyond the first: a kill cut the bake while it ran
  for (const auto& [id, request] : accepted) {
    const json finished = WaitForJob(*client, id, 300);
    ASSERT_EQ(finished.value("state", ""), "succeeded") << id << ": " << finished.dump();
    reruns += finished.value("attempts", 1) - 1;
  }
  // Every kill came while bakes ran and waited (a random 0-300 ms later), and kills cut
  // running bakes, which ran again.
  EXPECT_EQ(kills_on_work, kKills);
  EXPECT_GE(reruns, kKills / 3);
  auto listed = client->Get("/v1/bakes");
  ASSERT_TRUE(listed);
  ASSERT_EQ(listed->status, 200) << listed->body;
  std::multiset<std::string> listed_ids;
  const json list = Json(listed);
  for (const json& bake : list["bakes"]) listed_ids.insert(bake["id"].get<std::string>());
  for (const auto& [id, request] : accepted) {
    EXPECT_EQ(listed_ids.count(id), 1u) << "bake " << id << " listed once";
  }
  for (int k = 0; k < 20; ++k) work_once(*client);  // served levels after the last start too
  EXPECT_EQ(daemon.Stop(SIGTERM), 0);

  // Exactly once: no bake reached "succeeded" in two runs (the log of every run is kept).
  const std::string log = daemon.Log();
  for (const auto& [id, request] : accepted) {
    EXPECT_LE(Count(log, "bake " + id + " succeeded"), 1) << id;
  }

  // Every blob's content matches its address, and no temporary file is left.
  const fs::path data = daemon.dir() / "data";
  int blobs = 0;
  for (const auto& entry : fs::recursive_directory_iterator(data)) {
    const std::string name = entry.path().filename().string();
    EXPECT_EQ(name.find("tmp"), std::string::npos) << "left behind: " << entry.path();
    if (!entry.is_regular_file() || entry.path().parent_path().parent_path().filename() != "sha256")
      continue;
    const std::string hash = entry.path().parent_path().filename().string() + name;
    EXPECT_EQ(io::Sha256Hex(ReadFile(entry.path().string())), hash) << entry.path();
    ++blobs;
  }
  EXPECT_GE(blobs, static_cast<int>(accepted.size()));  // at least one level per bake
  EXPECT_EQ(accepted.size(), requests.size());
  EXPECT_GT(levels_verified, 0);
  // Log lines within a second of a SIGKILL may be lost (the log is flushed each second).
  std::cout << "bakes run again after a kill cut them " << reruns
            << ", runs that requeued interrupted jobs " << Count(log, "unfinished jobs")
            << ", runs that removed unreferenced blobs " << Count(log, "unreferenced blobs")
            << ", bake starts logged " << Count(log, " running (attempt") << "\n";
  std::cout << "kills " << kKills << ", bakes " << accepted.size() << " (" << seen_succeeded.size()
            << " seen finished), levels fetched and verified " << levels_verified
            << ", blobs verified " << blobs << "\n";
}

}  // namespace
}  // namespace motionlod::server::testing
