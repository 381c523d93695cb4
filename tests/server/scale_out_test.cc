// Scale-out as docker/compose.yaml deploys it, as plain processes: a real redis-server
// (append-only file, fsync always), three real motionlodd on it (backend = "redis") with
// one shared blob directory, and a real nginx with deploy/nginx/motionlod.conf in front.
// Bakes are submitted round-robin, daemons and Redis are killed and restarted, and every
// accepted bake must complete exactly once with levels every daemon serves.
#include <gtest/gtest.h>
#include <signal.h>

#include <map>
#include <set>
#include <thread>

#include "io/sha256.h"
#include "server/redis_client.h"
#include "tests/server/nginx.h"
#include "tests/server/redis.h"
#include "tests/server/test_util.h"

namespace motionlod::server::testing {
namespace {

namespace fs = std::filesystem;

constexpr int kDaemons = 3;

const std::vector<std::string> kAnimations = {
    "Jump_Full_Long", "Jump_Full_Short", "Jump_Idle", "Jump_Land", "Jump_Start", "Running_A",
    "Running_B",      "T-Pose",          "Walking_A", "Walking_B", "Walking_C"};
const std::vector<std::vector<int>> kLadders = {{20, 10}, {16, 6}, {12, 4}, {23, 8}, {18}, {14}};

// A gauge of a daemon's /metrics; -1 when it cannot be read.
double Gauge(httplib::Client& client, const std::string& name) {
  auto metrics = client.Get("/metrics");
  if (!metrics || metrics->status != 200) return -1;
  const size_t at = metrics->body.find("\n" + name + " ");
  return at == std::string::npos ? -1 : std::atof(metrics->body.c_str() + at + name.size() + 2);
}

class ScaleOut : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!Redis::Installed() || !Nginx::Installed())
      GTEST_SKIP() << "redis-server or nginx is not installed (scripts/setup.sh installs both)";
    dir_ = TestDirectory();
    redis_ = std::make_unique<Redis>(dir_ / "redis");
    ASSERT_TRUE(redis_->Start()) << redis_->error;
    for (int d = 0; d < kDaemons; ++d) {
      daemons_.push_back(std::make_unique<Daemon>(dir_ / ("daemon" + std::to_string(d))));
      ASSERT_TRUE(StartDaemon(d)) << daemons_[d]->error;
    }
    std::vector<int> ports;
    for (const auto& daemon : daemons_) ports.push_back(daemon->port());
    nginx_ = std::make_unique<Nginx>(dir_ / "nginx");
    ASSERT_TRUE(nginx_->Start(ports)) << nginx_->error;
  }

  // Daemon `d` on the shared Redis and blob directory; one bake at a time each, and a
  // job silent for 5 s is taken over (60 s in production; less is at the mercy of a
  // loaded machine).
  bool StartDaemon(int d, const std::vector<std::string>& more = {}) {
    std::vector<std::string> args = {"--backend",
                                     "redis",
                                     "--redis-url",
                                     redis_->url(),
                                     "--blob-dir",
                                     (dir_ / "blobs").string(),
                                     "--threads",
                                     "1",
                                     "--bake-threads",
                                     "1",
                                     "--job-visibility-seconds",
                                     "5"};
    args.insert(args.end(), more.begin(), more.end());
    return daemons_[d]->Start(args);
  }

  void TearDown() override {
    nginx_.reset();
    daemons_.clear();
    redis_.reset();
    if (!HasFailure() && !dir_.empty()) fs::remove_all(dir_);
  }

  // Every daemon's log, for failure messages.
  std::string Logs() const {
    std::string logs;
    for (const auto& daemon : daemons_)
      logs += "--- " + daemon->dir().string() + "\n" + daemon->Log();
    return logs;
  }

  std::unique_ptr<httplib::Client> Client(int d) { return daemons_[d]->Client(); }

  // Once job `id` runs (its attempt stored) on the one daemon running a bake, SIGKILLs
  // that daemon; its index, or -1 when none ran it within 60 s.
  int KillTheDaemonRunning(const std::string& id) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    while (std::chrono::steady_clock::now() < deadline) {
      auto client = Client(0);
      auto job = client->Get(("/v1/jobs/" + id).c_str());
      if (job && Json(job).value("state", "") == "running") {
        for (int d = 0; d < kDaemons; ++d) {
          auto daemon = Client(d);
          if (Gauge(*daemon, "motionlodd_jobs_running") < 1) continue;
          EXPECT_EQ(daemons_[d]->Stop(SIGKILL), 128 + SIGKILL);
          return d;
        }
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    return -1;
  }
  std::unique_ptr<httplib::Client> Proxy() {
    auto client = std::make_unique<httplib::Client>("127.0.0.1", nginx_->port());
    client->set_read_timeout(60);
    return client;
  }

  std::string UploadSample() {
    auto client = Client(0);
    auto uploaded = UploadFile(*client, Sample(), "Rig_Medium_MovementBasic.glb");
    EXPECT_TRUE(uploaded && (uploaded->status == 201 || uploaded->status == 200));
    return uploaded ? Json(uploaded).value("id", "") : "";
  }

  // Submits the request to daemon `d` until it is accepted (202, or 200: known); the id.
  std::string Submit(int d, const json& request) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    while (std::chrono::steady_clock::now() < deadline) {
      auto client = Client(d);
      auto submitted = SubmitBake(*client, request);
      if (submitted && (submitted->status == 202 || submitted->status == 200))
        return Json(submitted).value("id", "");
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    ADD_FAILURE() << "daemon " << d << " did not accept " << request.dump();
    return "";
  }

  // The bake's levels, each fetched from every daemon and checked against its hash.
  void ExpectEveryDaemonServesTheLevels(const std::string& bake_id) {
    auto first = Client(0);
    auto bake = first->Get(("/v1/bakes/" + bake_id).c_str());
    ASSERT_TRUE(bake && bake->status == 200);
    const json levels = Json(bake)["levels"];
    ASSERT_FALSE(levels.empty());
    for (const json& level : levels) {
      const std::string url = level["url"];
      const std::string hash = url.substr(url.rfind('/') + 1);
      for (int d = 0; d < kDaemons; ++d) {
        auto client = Client(d);
        auto bytes = client->Get(url.c_str());
        ASSERT_TRUE(bytes && bytes->status == 200) << "daemon " << d << " " << url;
        EXPECT_EQ(io::Sha256Hex(bytes->body), hash) << "daemon " << d;
      }
    }
  }

  fs::path dir_;
  std::unique_ptr<Redis> redis_;
  std::vector<std::unique_ptr<Daemon>> daemons_;
  std::unique_ptr<Nginx> nginx_;
};

TEST_F(ScaleOut, SixtyBakesRoundRobinCompleteOnceEachAndEveryDaemonServesEveryLevel) {
  const std::string character = UploadSample();
  ASSERT_FALSE(character.empty());
  std::vector<json> requests;
  for (const std::vector<int>& ladder : kLadders) {
    for (const std::string& animation : kAnimations) {
      if (requests.size() < 60)
        requests.push_back(
            {{"character", character}, {"motion", animation}, {"levels", ladder}, {"fps", 30}});
    }
  }
  ASSERT_EQ(requests.size(), 60u);
  std::vector<std::string> ids;
  for (size_t r = 0; r < requests.size(); ++r)
    ids.push_back(Submit(static_cast<int>(r % kDaemons), requests[r]));
  ASSERT_EQ(std::set<std::string>(ids.begin(), ids.end()).size(), 60u);
  // Each watched on another daemon than the one that took it.
  for (size_t r = 0; r < ids.size(); ++r) {
    auto client = Client(static_cast<int>((r + 1) % kDaemons));
    const json status = WaitForJob(*client, ids[r], 120);
    EXPECT_EQ(status.value("state", ""), "succeeded") << status.dump();
    EXPECT_EQ(status.value("attempts", 0), 1) << status.dump();
  }
  // Sixty bakes ran, no one twice, and every daemon ran some.
  double baked = 0;
  for (int d = 0; d < kDaemons; ++d) {
    auto client = Client(d);
    const double by_daemon = Gauge(*client, "motionlodd_bakes_total{outcome=\"succeeded\"}");
    EXPECT_GT(by_daemon, 0) << "daemon " << d << " baked nothing";
    baked += by_daemon;
    EXPECT_EQ(Gauge(*client, "motionlodd_queue_depth"), 0);
  }
  EXPECT_EQ(baked, 60);
  for (const std::string& id : ids) ExpectEveryDaemonServesTheLevels(id);
  // The same bake submitted again anywhere is the finished one, not a new run.
  auto again = Client(2);
  auto resubmitted = SubmitBake(*again, requests[0]);
  ASSERT_TRUE(resubmitted);
  EXPECT_EQ(resubmitted->status, 200);
  EXPECT_EQ(Json(resubmitted).value("state", ""), "succeeded");

  // Through the proxy: a level from its cache after the first fetch, the same bytes.
  auto bake = Client(1)->Get(("/v1/bakes/" + ids[5]).c_str());
  ASSERT_TRUE(bake && bake->status == 200);
  const std::string url = Json(bake)["levels"][0]["url"];
  auto proxy = Proxy();
  auto miss = proxy->Get(url.c_str());
  auto hit = proxy->Get(url.c_str());
  ASSERT_TRUE(miss && hit);
  EXPECT_EQ(miss->status, 200);
  EXPECT_EQ(hit->get_header_value("X-Cache-Status"), "HIT");
  EXPECT_EQ(io::Sha256Hex(hit->body), url.substr(url.rfind('/') + 1));
}

TEST_F(ScaleOut, AKilledDaemonsJobIsTakenOverAndKillingAllThreeLosesNothing) {
  const std::string character = UploadSample();
  ASSERT_FALSE(character.empty());
  // The default ladder (levels chosen by cost): bakes of a second or more, long enough to
  // be killed in. The daemon running the first is killed; the others go to the rest.
  const auto slow = [&](size_t n) {
    return json{{"character", character}, {"motion", kAnimations[n]}};
  };
  std::vector<std::string> ids = {Submit(0, slow(0))};
  const int killed = KillTheDaemonRunning(ids[0]);
  ASSERT_GE(killed, 0);
  for (size_t n = 1; n < 6; ++n)
    ids.push_back(Submit((killed + 1 + static_cast<int>(n % 2)) % kDaemons, slow(n)));
  // Its bake is run by another daemon after the visibility timeout: two attempts.
  for (size_t i = 0; i < ids.size(); ++i) {
    auto client = Client((killed + 1) % kDaemons);
    const json status = WaitForJob(*client, ids[i], 180);
    EXPECT_EQ(status.value("state", ""), "succeeded") << status.dump();
    EXPECT_EQ(status.value("attempts", 0), i == 0 ? 2 : 1) << status.dump();
  }

  // More bakes (quick ones), then all three killed at once while some run and others wait.
  ASSERT_TRUE(StartDaemon(killed)) << daemons_[killed]->error;
  for (size_t n = 0; n < 30; ++n) {
    ids.push_back(
        Submit(static_cast<int>(n % kDaemons), {{"character", character},
                                                {"motion", kAnimations[n % kAnimations.size()]},
                                                {"levels", kLadders[n / kAnimations.size()]},
                                                {"fps", 30}}));
  }
  for (auto& daemon : daemons_) EXPECT_EQ(daemon->Stop(SIGKILL), 128 + SIGKILL);
  for (int d = 0; d < kDaemons; ++d) ASSERT_TRUE(StartDaemon(d)) << daemons_[d]->error;
  for (size_t i = 0; i < ids.size(); ++i) {
    auto client = Client(static_cast<int>(i % kDaemons));
    const json status = WaitForJob(*client, ids[i], 180);
    EXPECT_EQ(status.value("state", ""), "succeeded") << status.dump();
  }
  ExpectEveryDaemonServesTheLevels(ids[0]);
  ExpectEveryDaemonServesTheLevels(ids.back());

  // A job stored but never queued (its daemon died between the two, here made by hand
  // while every daemon is down) is queued again when the same bake is submitted again.
  const int runs_before = WaitForJob(*Client(0), ids[6], 5).value("attempts", 0);
  for (auto& daemon : daemons_) EXPECT_EQ(daemon->Stop(SIGKILL), 128 + SIGKILL);
  RedisPool redis(*ParseRedisUrl(redis_->url()), 2.0);
  ASSERT_TRUE(redis.Command({"HSET", "motionlod:job:" + ids[6], "state", "queued"}).ok());
  for (int d = 0; d < kDaemons; ++d) ASSERT_TRUE(StartDaemon(d)) << daemons_[d]->error;
  EXPECT_EQ(Submit(1, {{"character", character},
                       {"motion", kAnimations[0]},
                       {"levels", kLadders[0]},
                       {"fps", 30}}),
            ids[6]);
  const json rerun = WaitForJob(*Client(2), ids[6], 60);
  EXPECT_EQ(rerun.value("state", ""), "succeeded") << rerun.dump();
  EXPECT_EQ(rerun.value("attempts", 0), runs_before + 1) << rerun.dump();
}

// The poison-job cap holds across daemons: a bake whose daemon died max_job_crashes times
// is failed ('crashed') by the daemon that takes it over, not run again.
TEST_F(ScaleOut, AJobWhoseDaemonsDiedMaxJobCrashesTimesIsFailedNotRunAgain) {
  for (int d = 0; d < kDaemons; ++d) {
    EXPECT_EQ(daemons_[d]->Stop(SIGTERM), 0);
    ASSERT_TRUE(StartDaemon(d, {"--max-job-crashes", "1"})) << daemons_[d]->error;
  }
  const std::string character = UploadSample();
  ASSERT_FALSE(character.empty());
  const std::string id = Submit(0, {{"character", character}, {"motion", "Running_A"}});
  const int running_on = KillTheDaemonRunning(id);
  ASSERT_GE(running_on, 0);
  auto client = Client((running_on + 1) % kDaemons);
  const json status = WaitForJob(*client, id, 60);
  EXPECT_EQ(status.value("state", ""), "failed")
      << status.dump() << " killed " << running_on << "\n"
      << Logs();
  EXPECT_EQ(status["error"].value("code", ""), "crashed") << status.dump();
  EXPECT_EQ(status.value("attempts", 0), 1) << status.dump();
}

TEST_F(ScaleOut, ARedisRestartLosesNoJobWhileDaemonsAnswer503AndServeCachedLevels) {
  const std::string character = UploadSample();
  ASSERT_FALSE(character.empty());
  const auto request = [&](size_t n) {
    return json{{"character", character},
                {"motion", kAnimations[n % kAnimations.size()]},
                {"levels", kLadders[(n / kAnimations.size()) % kLadders.size()]},
                {"fps", 30}};
  };
  // One bake done and its first level fetched from every daemon (into their caches) and
  // through the proxy (into its cache).
  const std::string done = Submit(0, request(0));
  auto first = Client(0);
  ASSERT_EQ(WaitForJob(*first, done, 120).value("state", ""), "succeeded");
  auto bake = first->Get(("/v1/bakes/" + done).c_str());
  ASSERT_TRUE(bake && bake->status == 200);
  const std::string url = Json(bake)["levels"][0]["url"];
  for (int d = 0; d < kDaemons; ++d) ASSERT_EQ(Client(d)->Get(url.c_str())->status, 200);
  ASSERT_EQ(Proxy()->Get(url.c_str())->status, 200);

  // Bakes of the default ladder (a second or more each) and quick ones: Redis is killed
  // while some run and others wait.
  std::vector<std::string> ids;
  for (size_t n = 1; n < 7; ++n) {
    ids.push_back(Submit(static_cast<int>(n % kDaemons),
                         {{"character", character}, {"motion", kAnimations[n]}}));
  }
  for (size_t n = 1; n < 16; ++n) ids.push_back(Submit(static_cast<int>(n % kDaemons), request(n)));
  EXPECT_GT(Gauge(*first, "motionlodd_queue_depth"), 0);
  redis_->Kill();
  for (int d = 0; d < kDaemons; ++d) {
    auto client = Client(d);
    auto ready = client->Get("/readyz");
    ASSERT_TRUE(ready);
    EXPECT_EQ(ready->status, 503) << "daemon " << d;
    auto refused = SubmitBake(*client, request(40 + d));
    ExpectProblem(refused, 503, "");
    auto upload = UploadFile(*client, Sample(), "Rig_Medium_MovementBasic.glb");
    ExpectProblem(upload, 503, "");
    auto cached = client->Get(url.c_str());
    ASSERT_TRUE(cached);
    EXPECT_EQ(cached->status, 200) << "daemon " << d << " cannot serve a cached level";
  }
  auto through_proxy = Proxy()->Get(url.c_str());
  ASSERT_TRUE(through_proxy);
  EXPECT_EQ(through_proxy->status, 200);
  auto refused = SubmitBake(*Proxy(), request(50));
  ExpectProblem(refused, 503, "");

  ASSERT_TRUE(redis_->Start()) << redis_->error;
  for (int d = 0; d < kDaemons; ++d) {  // ready again by themselves
    auto client = Client(d);
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
    int status = 0;
    while (status != 200 && std::chrono::steady_clock::now() < deadline) {
      auto ready = client->Get("/readyz");
      status = ready ? ready->status : 0;
      if (status != 200) std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    EXPECT_EQ(status, 200) << "daemon " << d;
  }
  ids.push_back(Submit(1, request(60)));
  for (size_t i = 0; i < ids.size(); ++i) {
    auto client = Client(static_cast<int>(i % kDaemons));
    const json status = WaitForJob(*client, ids[i], 120);
    EXPECT_EQ(status.value("state", ""), "succeeded") << ids[i] << " " << status.dump();
  }
  ExpectEveryDaemonServesTheLevels(ids.back());
}

}  // namespace
}  // namespace motionlod::server::testing
