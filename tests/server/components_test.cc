// The daemon's parts on their own: level cache, job queue, store, blob store, router,
// framing guards, metrics, the HTTP server's stop, and the one-file rule for httplib.h.
#include <gtest/gtest.h>
#include <sqlite3.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <future>
#include <optional>
#include <regex>
#include <set>
#include <sstream>
#include <thread>

#include "io/sha256.h"
#include "server/directory_blob_store.h"
#include "server/http.h"
#include "server/http_server.h"
#include "server/memory_job_queue.h"
#include "server/level_cache.h"
#include "server/metrics.h"
#include "server/routes.h"
#include "server/service.h"
#include "server/sqlite_store.h"
#include "tests/server/daemon.h"

namespace motionlod::server {
namespace {

namespace fs = std::filesystem;

LevelCache::Bytes Bytes(size_t n) { return std::make_shared<const std::string>(n, 'x'); }

TEST(LevelCache, EvictsLeastRecentlyUsedBeyondTheByteBudget) {
  LevelCache cache(100);
  cache.Put("a", Bytes(40));
  cache.Put("b", Bytes(40));
  ASSERT_NE(cache.Get("a"), nullptr);  // a is now the most recent
  cache.Put("c", Bytes(40));           // 120 > 100: b goes
  EXPECT_EQ(cache.Get("b"), nullptr);
  EXPECT_NE(cache.Get("a"), nullptr);
  EXPECT_NE(cache.Get("c"), nullptr);
  const LevelCache::Stats stats = cache.stats();
  EXPECT_EQ(stats.bytes, 80);
  EXPECT_EQ(stats.entries, 2);
  EXPECT_EQ(stats.evictions, 1u);
  EXPECT_EQ(stats.hits, 3u);
  EXPECT_EQ(stats.misses, 1u);
}

TEST(LevelCache, KeepsNothingLargerThanTheBudgetAndSharesValuesPastEviction) {
  LevelCache cache(10);
  cache.Put("big", Bytes(11));
  EXPECT_EQ(cache.Get("big"), nullptr);
  cache.Put("a", Bytes(10));
  LevelCache::Bytes held = cache.Get("a");
  cache.Put("b", Bytes(10));
  EXPECT_EQ(cache.Get("a"), nullptr);
  EXPECT_EQ(held->size(), 10u);  // still valid for the response that holds it
}

TEST(JobQueue, RefusesBeyondCapacityExceptWhenForcedAndRunsInOrder) {
  std::mutex mutex;
  std::condition_variable cv;
  bool release = false;
  std::vector<std::string> ran;
  MemoryJobQueue queue(2, 1, [&](const std::string& id) {
    std::unique_lock lock(mutex);
    cv.wait(lock, [&] { return release; });
    ran.push_back(id);
    return JobQueue::RunOutcome::kFinished;
  });
  EXPECT_EQ(queue.Push("a"), JobQueue::PushResult::kQueued);
  while (queue.running() == 0) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  EXPECT_EQ(queue.Push("b"), JobQueue::PushResult::kQueued);
  EXPECT_EQ(queue.Push("b"), JobQueue::PushResult::kAlreadyQueued);
  EXPECT_EQ(queue.Push("c"), JobQueue::PushResult::kQueued);
  EXPECT_EQ(queue.Push("d"), JobQueue::PushResult::kFull);
  EXPECT_EQ(queue.Push("d", /*force=*/true), JobQueue::PushResult::kQueued);
  EXPECT_TRUE(queue.Remove("c"));
  EXPECT_EQ(queue.depth(), 2u);
  {
    std::lock_guard lock(mutex);
    release = true;
  }
  cv.notify_all();
  while (queue.depth() > 0 || queue.running() > 0)
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  queue.Stop();
  EXPECT_EQ(ran, (std::vector<std::string>{"a", "b", "d"}));
  EXPECT_EQ(queue.Push("e"), JobQueue::PushResult::kStopped);
}

TEST(BlobStore, WritesAtomicallyUnderTheHashAndDetectsCorruption) {
  const fs::path dir = testing::TestDirectory();
  auto store = DirectoryBlobStore::Open(dir / "blobs", /*shared=*/false);
  ASSERT_TRUE(store.ok());
  auto hash = (*store)->Put("hello");
  ASSERT_TRUE(hash.ok());
  EXPECT_EQ(*hash, io::Sha256Hex("hello"));
  const fs::path file = dir / "blobs" / "sha256" / hash->substr(0, 2) / hash->substr(2);
  EXPECT_TRUE(fs::exists(file));
  EXPECT_EQ(*(*store)->Get(*hash), "hello");
  EXPECT_EQ((*store)->List(), std::vector<std::string>{*hash});
  std::ofstream(file, std::ios::binary) << "hellO";
  EXPECT_EQ((*store)->Get(*hash).status().code(), StatusCode::kDataLoss);
  EXPECT_EQ((*store)->Get(std::string(64, 'a')).status().code(), StatusCode::kNotFound);
  EXPECT_EQ((*store)->Get("../../etc/passwd").status().code(), StatusCode::kInvalidArgument);
  // Temporary files a crash left are removed at the next open; in a shared directory only
  // those an hour old, since a younger one may be another daemon's write in progress.
  const fs::path stale = file.parent_path() / ".tmp-abc123";
  const fs::path fresh = file.parent_path() / ".tmp-def456";
  std::ofstream(stale) << "partial";
  std::ofstream(fresh) << "partial";
  fs::last_write_time(stale, fs::file_time_type::clock::now() - std::chrono::minutes(61));
  ASSERT_TRUE(DirectoryBlobStore::Open(dir / "blobs", /*shared=*/true).ok());
  EXPECT_FALSE(fs::exists(stale));
  EXPECT_TRUE(fs::exists(fresh));
  ASSERT_TRUE(DirectoryBlobStore::Open(dir / "blobs", /*shared=*/false).ok());
  EXPECT_FALSE(fs::exists(fresh));
  fs::remove_all(dir);
}

// A database of schema version 1 (before bakes had several clips), as that version wrote
// it: the migration gives each bake its one motion as its clip.
TEST(Store, MigratesAVersion1DatabaseGivingEachBakeItsMotionAsItsClip) {
  const fs::path dir = testing::TestDirectory();
  {
    sqlite3* db = nullptr;
    ASSERT_EQ(sqlite3_open((dir / "db").c_str(), &db), SQLITE_OK);
    const std::string version1 = R"sql(
CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE characters (
  id TEXT PRIMARY KEY, name TEXT NOT NULL, files TEXT NOT NULL, joints INTEGER NOT NULL,
  vertices INTEGER NOT NULL, triangles INTEGER NOT NULL, proxy_skin INTEGER NOT NULL,
  warnings TEXT NOT NULL, created_ms INTEGER NOT NULL, joint_names TEXT NOT NULL);
CREATE TABLE motions (
  id TEXT PRIMARY KEY,
  character_id TEXT NOT NULL REFERENCES characters(id) ON DELETE CASCADE,
  animation TEXT NOT NULL, source TEXT NOT NULL, source_id TEXT NOT NULL, files TEXT NOT NULL,
  duration_seconds REAL NOT NULL, source_fps REAL NOT NULL, frames INTEGER NOT NULL,
  warnings TEXT NOT NULL, created_ms INTEGER NOT NULL);
CREATE INDEX motions_character ON motions(character_id);
CREATE TABLE bakes (
  id TEXT PRIMARY KEY,
  character_id TEXT NOT NULL REFERENCES characters(id) ON DELETE CASCADE,
  motion_id TEXT NOT NULL REFERENCES motions(id) ON DELETE CASCADE,
  request TEXT NOT NULL, created_ms INTEGER NOT NULL, level_set TEXT NOT NULL DEFAULT '',
  level_set_bytes INTEGER NOT NULL DEFAULT 0, report TEXT NOT NULL DEFAULT '',
  frames INTEGER NOT NULL DEFAULT 0, fps REAL NOT NULL DEFAULT 0);
CREATE INDEX bakes_character ON bakes(character_id);
CREATE INDEX bakes_motion ON bakes(motion_id);
CREATE TABLE levels (
  bake_id TEXT NOT NULL REFERENCES bakes(id) ON DELETE CASCADE, idx INTEGER NOT NULL,
  joints INTEGER NOT NULL, hash TEXT NOT NULL, bytes INTEGER NOT NULL,
  PRIMARY KEY (bake_id, idx));
CREATE INDEX levels_hash ON levels(hash);
CREATE TABLE jobs (
  seq INTEGER PRIMARY KEY AUTOINCREMENT, id TEXT NOT NULL UNIQUE,
  bake_id TEXT NOT NULL REFERENCES bakes(id) ON DELETE CASCADE,
  state TEXT NOT NULL CHECK (state IN ('queued', 'running', 'succeeded', 'failed')),
  progress REAL NOT NULL DEFAULT 0, stage TEXT NOT NULL DEFAULT '',
  error_code TEXT NOT NULL DEFAULT '', error_detail TEXT NOT NULL DEFAULT '',
  attempts INTEGER NOT NULL DEFAULT 0, created_ms INTEGER NOT NULL,
  started_ms INTEGER NOT NULL DEFAULT 0, finished_ms INTEGER NOT NULL DEFAULT 0);
CREATE INDEX jobs_bake ON jobs(bake_id);
CREATE INDEX jobs_state ON jobs(state);
INSERT INTO meta VALUES ('schema_version', '1');
INSERT INTO characters VALUES ('c', 'c.glb', '[]', 2, 0, 0, 0, '[]', 1, '["root","hip"]');
INSERT INTO motions VALUES ('walk', 'c', 'walk', 'character', 'c', '[]', 1, 30, 31, '[]', 1);
INSERT INTO motions VALUES ('run', 'c', 'run', 'character', 'c', '[]', 1, 30, 31, '[]', 2);
INSERT INTO bakes (id, character_id, motion_id, request, created_ms) VALUES ('b1', 'c', 'walk', '{}', 1);
INSERT INTO bakes (id, character_id, motion_id, request, created_ms) VALUES ('b2', 'c', 'run', '{}', 2);
INSERT INTO jobs (id, bake_id, state, created_ms) VALUES ('b1', 'b1', 'succeeded', 1);
)sql";
    char* error = nullptr;
    EXPECT_EQ(sqlite3_exec(db, version1.c_str(), nullptr, nullptr, &error), SQLITE_OK) << error;
    sqlite3_free(error);
    sqlite3_close(db);
  }
  for (int open = 0; open < 2; ++open) {  // migrated, then read as it is
    auto store = SqliteStore::Open(dir / "db");
    ASSERT_TRUE(store.ok()) << store.status().message();
    auto b1 = (*store)->GetBake("b1");
    ASSERT_TRUE(b1.ok() && b1->has_value());
    EXPECT_EQ((*b1)->clip_motions, std::vector<std::string>{"walk"});
    auto listed = (*store)->ListBakes("c");
    ASSERT_TRUE(listed.ok());
    ASSERT_EQ(listed->size(), 2u);
    EXPECT_EQ((*listed)[1].clip_motions, std::vector<std::string>{"run"});
    EXPECT_EQ((**(*store)->GetJob("b1")).state, "succeeded");
  }
  // A later version than this build knows is refused, not misread.
  {
    sqlite3* db = nullptr;
    ASSERT_EQ(sqlite3_open((dir / "db").c_str(), &db), SQLITE_OK);
    EXPECT_EQ(sqlite3_exec(db, "UPDATE meta SET value = '3' WHERE key = 'schema_version'", nullptr,
                           nullptr, nullptr),
              SQLITE_OK);
    sqlite3_close(db);
  }
  auto refused = SqliteStore::Open(dir / "db");
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), StatusCode::kUnsupported);
  EXPECT_NE(refused.status().message().find("schema version 3"), std::string::npos);
}

// A job found running was running when the daemon died: it runs again, unless that was
// its max_runs-th run (a bake that kills the daemon must not do it at every start).
TEST(Store, KeepsJobsAcrossReopensAndRequeuesTheUnfinished) {
  const fs::path dir = testing::TestDirectory();
  {
    auto store = SqliteStore::Open(dir / "db");
    ASSERT_TRUE(store.ok()) << store.status().message();
    CharacterRecord c;
    c.id = std::string(64, 'c');
    c.name = "c.glb";
    c.files = {{"c.glb", std::string(64, 'f'), 3}};
    c.joints = 2;
    c.joint_names = {"root", "hip"};
    c.created_ms = 1;
    MotionRecord m;
    m.id = std::string(64, 'm');
    m.character_id = c.id;
    m.animation = "walk";
    m.source = "character";
    m.source_id = c.id;
    ASSERT_TRUE(*(*store)->InsertCharacter(c, {m}));
    EXPECT_FALSE(*(*store)->InsertCharacter(c, {m}));
    for (const char* id : {"1", "2", "3", "4"}) {
      BakeRecord b;
      b.id = std::string(64, id[0]);
      b.character_id = c.id;
      b.motion_id = m.id;
      b.clip_motions = {m.id};
      b.request_json = "{}";
      b.created_ms = 1;
      JobRecord j;
      j.id = b.id;
      j.bake_id = b.id;
      j.state = "queued";
      ASSERT_TRUE(*(*store)->InsertBakeAndJob(b, j));
      EXPECT_FALSE(*(*store)->InsertBakeAndJob(b, j));
    }
    JobRecord running = **(*store)->GetJob(std::string(64, '2'));
    running.state = "running";
    running.attempts = 1;
    ASSERT_TRUE(*(*store)->UpdateJob(running));
    JobRecord poison = **(*store)->GetJob(std::string(64, '4'));
    poison.state = "running";
    poison.attempts = 3;
    ASSERT_TRUE(*(*store)->UpdateJob(poison));
    JobRecord done = **(*store)->GetJob(std::string(64, '3'));
    done.state = "succeeded";
    ASSERT_TRUE(*(*store)->UpdateJob(done));
    EXPECT_EQ((**(*store)->GetCharacter(c.id)).joint_names,
              (std::vector<std::string>{"root", "hip"}));
  }
  auto store = SqliteStore::Open(dir / "db");
  ASSERT_TRUE(store.ok());
  auto unfinished = (*store)->TakeUnfinishedJobs(3, 1234);
  ASSERT_TRUE(unfinished.ok());
  EXPECT_EQ(unfinished->requeued,
            (std::vector<std::string>{std::string(64, '1'), std::string(64, '2')}));
  EXPECT_EQ(unfinished->failed, std::vector<std::string>{std::string(64, '4')});
  EXPECT_EQ((**(*store)->GetJob(std::string(64, '2'))).state, "queued");
  const JobRecord failed = **(*store)->GetJob(std::string(64, '4'));
  EXPECT_EQ(failed.state, "failed");
  EXPECT_EQ(failed.error_code, "crashed");
  EXPECT_NE(failed.error_detail.find("3 times"), std::string::npos) << failed.error_detail;
  EXPECT_EQ(failed.finished_ms, 1234);
  EXPECT_EQ((*store)->CountJobsByState()->at("queued"), 2);
  EXPECT_EQ((*store)->CountJobsByState()->at("failed"), 1);
  // Deleting the character deletes its bakes and jobs and names the blobs to collect.
  auto blobs = (*store)->DeleteCharacter(std::string(64, 'c'));
  ASSERT_TRUE(blobs.ok());
  EXPECT_EQ(*blobs, std::vector<std::string>{std::string(64, 'f')});
  EXPECT_FALSE((*store)->GetJob(std::string(64, '1'))->has_value());
  EXPECT_FALSE(*(*store)->IsBlobReferenced(std::string(64, 'f')));
  fs::remove_all(dir);
}

TEST(Router, MatchesTemplatesAndListsTheMethodsOfAPath) {
  http::Router router;
  router.Add("GET", "/v1/bakes/{id}", http::Access::kRead, nullptr);
  router.Add("DELETE", "/v1/bakes/{id}", http::Access::kWrite, nullptr);
  router.Add("GET", "/v1/bakes/{id}/level", http::Access::kRead, nullptr);
  const auto get = router.Find("GET", "/v1/bakes/abc");
  EXPECT_EQ(get.route, 0);
  EXPECT_EQ(get.params, std::vector<std::string>{"abc"});
  EXPECT_EQ(router.Find("HEAD", "/v1/bakes/abc").route, 0);
  EXPECT_EQ(router.Find("DELETE", "/v1/bakes/abc").route, 1);
  const auto put = router.Find("PUT", "/v1/bakes/abc");
  EXPECT_EQ(put.route, -1);
  EXPECT_EQ(put.allowed, (std::vector<std::string>{"GET", "HEAD", "DELETE"}));
  EXPECT_TRUE(router.Find("GET", "/v1/bakes/").allowed.empty());
  EXPECT_TRUE(router.Find("GET", "/v1/bakes/a/b").allowed.empty());
}

TEST(Dispatch, ChecksKeysAndTurnsExceptionsIntoAGeneric500) {
  http::Router router;
  router.Add("POST", "/w", http::Access::kWrite,
             [](http::Request&, http::Response& r) { r.status = 201; });
  router.Add("GET", "/boom", http::Access::kPublic,
             [](http::Request&, http::Response&) { throw std::runtime_error("secret detail"); });
  http::DispatchOptions options{{"wwwwwwwwwwwwwwww"}, {}};
  http::Request request;
  request.method = "POST";
  request.path = "/w";
  request.request_id = "0123456789abcdef";
  http::Response denied;
  http::Dispatch(router, options, request, denied);
  EXPECT_EQ(denied.status, 401);
  request.headers = {{"authorization", "Bearer wwwwwwwwwwwwwwww"}};
  http::Response allowed;
  http::Dispatch(router, options, request, allowed);
  EXPECT_EQ(allowed.status, 201);
  request.method = "GET";
  request.path = "/boom";
  http::Response boom;
  EXPECT_EQ(http::Dispatch(router, options, request, boom), -1);
  EXPECT_EQ(boom.status, 500);
  EXPECT_EQ(boom.content_type, "application/problem+json");
  EXPECT_EQ(boom.body.find("secret"), std::string::npos);
}

TEST(CheckFraming, RefusesAmbiguousOversizeAndUnexpectedBodies) {
  const http::FramingLimits limits{1000, 100};
  const auto check = [&](const std::string& method,
                         std::vector<std::pair<std::string, std::string>> headers) {
    http::Request request;
    request.method = method;
    request.path = "/v1/characters";
    request.headers = std::move(headers);
    http::Response response;
    return http::CheckFraming(request, limits, response) ? 0 : response.status;
  };
  EXPECT_EQ(check("POST", {{"content-length", "1000"}}), 0);
  EXPECT_EQ(check("POST", {{"content-length", "1001"}}), 413);
  EXPECT_EQ(check("POST", {{"content-length", "12abc"}}), 400);
  EXPECT_EQ(check("POST", {{"content-length", "5"}, {"transfer-encoding", "chunked"}}), 400);
  EXPECT_EQ(check("POST", {{"transfer-encoding", "gzip, chunked"}}), 501);
  EXPECT_EQ(check("POST", {{"transfer-encoding", "chunked"}}), 0);
  EXPECT_EQ(check("POST", {{"content-encoding", "compress"}}), 415);
  EXPECT_EQ(check("POST", {{"content-encoding", "gzip"}}), 0);
  EXPECT_EQ(check("POST", {{"transfer-encoding", "chunked"},
                           {"content-type", "multipart/form-data; boundary=x"}}),
            411);
  EXPECT_EQ(check("GET", {{"content-length", "0"}}), 0);
  EXPECT_EQ(check("GET", {{"content-length", "1"}}), 400);
  EXPECT_EQ(check("DELETE", {{"transfer-encoding", "chunked"}}), 400);
}

TEST(Metrics, RenderPrometheusTextWithCumulativeBuckets) {
  HttpMetrics metrics(std::vector<HttpMetrics::RouteLabel>{{"GET", "/v1/levels/{hash}"}});
  metrics.Record(0, 200, 0.0007);
  metrics.Record(0, 200, 0.02);
  metrics.Record(0, 404, 0.0001);
  metrics.Record(5, 400, 0.1);  // out of range: unmatched
  std::string text;
  metrics.Render(text);
  EXPECT_NE(text.find("motionlodd_http_requests_total{route=\"/v1/levels/"
                      "{hash}\",method=\"GET\",code=\"200\"} 2"),
            std::string::npos)
      << text;
  EXPECT_NE(text.find("code=\"404\"} 1"), std::string::npos);
  EXPECT_NE(text.find("route=\"unmatched\",method=\"\",code=\"400\"} 1"), std::string::npos);
  EXPECT_NE(text.find("le=\"0.001\"} 2"), std::string::npos) << text;
  EXPECT_NE(text.find("le=\"+Inf\"} 3"), std::string::npos);
}

TEST(Layering, OnlyHttpServerCcIncludesHttplibAndTheServerIncludesNoClientOrTool) {
  const std::regex httplib_include("#include [<\"]httplib\\.h[>\"]");
  const std::regex higher("#include \"(client|tools)/");
  std::vector<std::string> includers;
  for (const auto& entry : fs::directory_iterator(testing::SourcePath("server"))) {
    const std::string text = testing::ReadFile(entry.path().string());
    if (std::regex_search(text, httplib_include))
      includers.push_back(entry.path().filename().string());
    EXPECT_FALSE(std::regex_search(text, higher)) << entry.path();
  }
  EXPECT_EQ(includers, std::vector<std::string>{"http_server.cc"});
  // proto stays free of Eigen and core.
  const std::string api = testing::ReadFile(testing::SourcePath("proto/api.h")) +
                          testing::ReadFile(testing::SourcePath("proto/api.cc"));
  EXPECT_EQ(api.find("#include \"core/"), std::string::npos);
  EXPECT_EQ(api.find("#include <Eigen"), std::string::npos);
}

// A service in a test directory of its own and the daemon's router over it: set `config`,
// then Open().
struct RoutedService {
  RoutedService() : dir(testing::TestDirectory()) {
    config.data_dir = (dir / "data").string();
    config.import_worker = MOTIONLOD_IMPORT_WORKER;  // not next to this test binary
  }
  ~RoutedService() {
    router.reset();
    service.reset();
    if (!::testing::Test::HasFailure()) fs::remove_all(dir);  // kept to look into
  }
  Status Open() {
    auto opened = Service::Open(config);
    if (!opened.ok()) return opened.status();
    service = *std::move(opened);
    context = RouteContext{service.get(), &config, [](std::string&) {}, &streams, &uploads};
    router = MakeRouter(context);
    return Status::Ok();
  }

  fs::path dir;
  Config config;
  std::unique_ptr<Service> service;
  std::atomic<int> streams{0}, uploads{0};
  RouteContext context;
  std::optional<http::Router> router;
};

TEST(OpenApi, TheServedSpecDescribesExactlyTheRoutesTheDaemonHas) {
  RoutedService routed;
  const Status opened = routed.Open();
  ASSERT_TRUE(opened.ok()) << opened.message();
  const http::Router& router = *routed.router;
  // (method, path) pairs of the spec: "  /path:" then "    get:" lines under "paths:".
  const std::string yaml(OpenApiYaml());
  EXPECT_EQ(yaml, testing::ReadFile(testing::SourcePath("proto/openapi.yaml")));
  std::set<std::pair<std::string, std::string>> documented;
  std::istringstream lines(
      yaml.substr(yaml.find("\npaths:\n"), yaml.find("\ncomponents:\n") - yaml.find("\npaths:\n")));
  std::string line, path;
  const std::regex path_line("^  (/[^:]*):$"), method_line("^    (get|post|delete|put|patch):.*$");
  std::smatch match;
  while (std::getline(lines, line)) {
    if (std::regex_match(line, match, path_line)) path = match[1];
    if (std::regex_match(line, match, method_line)) {
      std::string method = match[1];
      std::transform(method.begin(), method.end(), method.begin(), ::toupper);
      documented.insert({method, path});
    }
  }
  std::set<std::pair<std::string, std::string>> served;
  for (const http::Route& route : router.routes()) served.insert({route.method, route.pattern});
  EXPECT_EQ(documented, served);
  EXPECT_GE(served.size(), 20u);
}

// The library's own stop() is lost when it comes before its listen loop has started: a
// daemon sent SIGTERM right after it printed "listening on" served on. Stop() before
// Run(), and Stop() while Run() is starting, must both end Run().
TEST(HttpServer, StopEndsRunWhetherItComesBeforeOrWhileRunStarts) {
  RoutedService routed;
  routed.config.port = 0;
  routed.config.http_threads = 2;
  const Status opened = routed.Open();
  ASSERT_TRUE(opened.ok()) << opened.message();
  HttpMetrics metrics(RouteLabels(*routed.router));
  for (int round = 0; round < 40; ++round) {
    HttpServer server(routed.config, *routed.router, metrics);
    ASSERT_TRUE(server.Bind().ok());
    const bool stop_before_run = round % 2 == 0;
    if (stop_before_run) server.Stop();
    std::promise<bool> ran;
    std::future<bool> result = ran.get_future();
    std::thread runner([&] { ran.set_value(server.Run()); });
    if (!stop_before_run) server.Stop();
    const bool ended = result.wait_for(std::chrono::seconds(10)) == std::future_status::ready;
    EXPECT_TRUE(ended) << "round " << round << ": Run() still serving after Stop()";
    // A lost stop leaves the loop running: stopping it again (it now runs) ends the test.
    while (result.wait_for(std::chrono::milliseconds(100)) != std::future_status::ready) server.Stop();
    runner.join();
    EXPECT_TRUE(result.get());
    if (!ended) break;
  }
}

}  // namespace
}  // namespace motionlod::server
