// What a hostile or careless client gets: keys, size limits (plain, chunked and
// compressed), malformed and hostile files, bad requests, header injection, a busy
// daemon. Every error is problem+json and the daemon keeps serving. hostile_http_test.cc
// holds what only a raw socket can send.
#include <gtest/gtest.h>
#include <signal.h>

#include "tests/server/raw_http.h"
#include "tests/server/test_util.h"

namespace motionlod::server::testing {
namespace {

constexpr const char* kWriteKey = "write-key-0123456789abcdef";
constexpr const char* kReadKey = "read-key-0123456789abcdef";

void ExpectServing(httplib::Client& client) {
  auto health = client.Get("/healthz");
  ASSERT_TRUE(health);
  EXPECT_EQ(health->status, 200);
}

TEST(DaemonSecurity, WritesNeedTheWriteKeyAndReadsAReadKeyWhenConfigured) {
  Daemon daemon(TestDirectory());
  ASSERT_TRUE(daemon.Start({}, {std::string("MOTIONLODD_WRITE_KEYS=") + kWriteKey,
                                std::string("MOTIONLODD_READ_KEYS=") + kReadKey}))
      << daemon.error;
  auto client = daemon.Client();
  auto anonymous = UploadFile(*client, Sample(), "rig.glb");
  ExpectProblem(anonymous, 401, "Authorization: Bearer");
  EXPECT_EQ(anonymous->get_header_value("WWW-Authenticate"), "Bearer realm=\"motionlodd\"");
  ExpectProblem(UploadFile(*client, Sample(), "rig.glb", "wrong-key-0123456789abcdef"), 401,
                "not valid");
  ExpectProblem(UploadFile(*client, Sample(), "rig.glb", kReadKey), 403);
  auto written = UploadFile(*client, Sample(), "rig.glb", kWriteKey);
  ASSERT_TRUE(written);
  EXPECT_EQ(written->status, 201) << written->body;

  const std::string path = std::string("/v1/characters/") + kSampleId;
  ExpectProblem(client->Get(path.c_str()), 401);
  EXPECT_EQ(client->Get(path.c_str(), Auth(kReadKey))->status, 200);
  EXPECT_EQ(client->Get(path.c_str(), Auth(kWriteKey))->status, 200);
  ExpectProblem(client->Delete(path.c_str(), Auth(kReadKey)), 403);
  ExpectProblem(client->Get("/metrics"), 401);
  // Probes and the API description stay public.
  EXPECT_EQ(client->Get("/healthz")->status, 200);
  EXPECT_EQ(client->Get("/readyz")->status, 200);
  EXPECT_EQ(client->Get("/v1/openapi.yaml")->status, 200);
}

// Read keys alone leave writes open: the daemon serves, and says so when it starts.
TEST(DaemonSecurity, ReadKeysWithoutWriteKeysAreNamedAtStart) {
  Daemon daemon(TestDirectory());
  ASSERT_TRUE(daemon.Start({}, {std::string("MOTIONLODD_READ_KEYS=") + kReadKey})) << daemon.error;
  EXPECT_NE(daemon.Log().find("read_keys are set but write_keys are not"), std::string::npos)
      << daemon.Log();
  auto client = daemon.Client();
  auto written = UploadFile(*client, Sample(), "rig.glb");
  ASSERT_TRUE(written);
  EXPECT_EQ(written->status, 201) << written->body;

  const std::filesystem::path second = daemon.dir() / "second";
  std::filesystem::create_directories(second);
  Daemon both(second);
  ASSERT_TRUE(both.Start({}, {std::string("MOTIONLODD_READ_KEYS=") + kReadKey,
                              std::string("MOTIONLODD_WRITE_KEYS=") + kWriteKey}))
      << both.error;
  EXPECT_EQ(both.Log().find("write_keys are not"), std::string::npos) << both.Log();
}

TEST(DaemonSecurity, OversizeBodiesAre413WhetherPlainChunkedOrCompressed) {
  Daemon daemon(TestDirectory());
  ASSERT_TRUE(daemon.Start({"--max-upload-bytes", "100000"})) << daemon.error;
  auto client = daemon.Client();
  const std::string big(300000, 'x');
  ExpectProblem(client->Post("/v1/characters?filename=big.glb", big, "application/octet-stream"),
                413, "100000");

  auto chunked_client = daemon.Client();
  size_t sent = 0;
  auto chunked = chunked_client->Post(
      "/v1/characters?filename=big.glb",
      [&](size_t, httplib::DataSink& sink) {
        if (sent >= big.size()) {
          sink.done();
          return true;
        }
        const size_t n = std::min<size_t>(16384, big.size() - sent);
        sent += n;
        return sink.write(big.data() + sent - n, n);
      },
      "application/octet-stream");
  ExpectProblem(chunked, 413, "decoded body");

  // 300 KB of zeros compress to a few hundred bytes: the limit applies to what they inflate to.
  const std::string bomb = Gzip(std::string(300000, '\0'));
  ASSERT_LT(bomb.size(), 100000u);
  auto compressed =
      daemon.Client()->Post("/v1/characters?filename=bomb.glb", {{"Content-Encoding", "gzip"}},
                            bomb, "application/octet-stream");
  ExpectProblem(compressed, 413, "decoded body");
  // An honest small compressed upload passes the limit (and then fails the import).
  auto small =
      daemon.Client()->Post("/v1/characters?filename=small.glb", {{"Content-Encoding", "gzip"}},
                            Gzip("not a model"), "application/octet-stream");
  ExpectProblem(small, 422);
  ExpectServing(*daemon.Client());
}

TEST(DaemonSecurity, MalformedAndHostileFilesGet4xxAndTheDaemonKeepsServing) {
  Daemon daemon(TestDirectory());
  ASSERT_TRUE(daemon.Start()) << daemon.error;
  auto client = daemon.Client();
  const std::string sample = ReadFile(Sample());
  struct Case {
    std::string name, bytes;
    int status;
  };
  const std::vector<Case> cases = {
      {"garbage.glb", std::string(4096, '\x7f'), 422},
      {"truncated.glb", sample.substr(0, sample.size() / 3), 422},
      {"empty.glb", "", 422},
      {"escape.gltf",
       R"({"asset":{"version":"2.0"},"buffers":[{"uri":"../../../../etc/passwd","byteLength":10}]})",
       422},
      {"absolute.gltf",
       R"({"asset":{"version":"2.0"},"buffers":[{"uri":"file:///etc/passwd","byteLength":10}]})",
       422},
      {"nan.gltf", R"({"asset":{"version":"2.0"},"nodes":[{"translation":[NaN,0,0]}]})", 422},
      {"deep.gltf", std::string(100000, '['), 422},
      {"program.exe", "MZ\x90\x00", 415},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    auto result = client->Post(("/v1/characters?filename=" + c.name).c_str(), c.bytes,
                               "application/octet-stream");
    ExpectProblem(result, c.status);
    ExpectServing(*client);
  }
  // File names are plain names.
  ExpectProblem(
      client->Post("/v1/characters?filename=../../rig.glb", sample, "application/octet-stream"),
      400);
  ExpectProblem(client->Post("/v1/characters", sample, "application/octet-stream"), 400,
                "filename");
  // The real file still imports afterwards.
  EXPECT_EQ(UploadFile(*client, Sample(), "rig.glb")->status, 201);
}

TEST(DaemonSecurity, BadRequestsAreProblemsWithPreciseDetails) {
  Daemon daemon(TestDirectory());
  ASSERT_TRUE(daemon.Start()) << daemon.error;
  auto client = daemon.Client();
  ASSERT_EQ(UploadFile(*client, Sample(), "rig.glb")->status, 201);
  ExpectProblem(client->Post("/v1/bakes", "{not json", "application/json"), 400, "JSON");
  ExpectProblem(client->Post("/v1/bakes", R"({"character":"abc"})", "application/json"), 400,
                "character");
  ExpectProblem(
      client->Post("/v1/bakes", std::string(R"({"character":")") + kSampleId + R"(","colour":1})",
                   "application/json"),
      400, "unknown field");
  ExpectProblem(
      client->Post("/v1/bakes",
                   std::string(R"({"character":")") + kSampleId + R"(","variant":"best"})",
                   "application/json"),
      400, "variant");
  ExpectProblem(client->Post("/v1/bakes", std::string(R"({"character":")") + kSampleId + R"("})",
                             "text/plain"),
                415);
  ExpectProblem(
      client->Post("/v1/characters?filename=a.glb", "a=b", "application/x-www-form-urlencoded"),
      415);
  ExpectProblem(SubmitBake(*client, {{"character", std::string(64, 'a')}}), 404);
  ExpectProblem(SubmitBake(*client, {{"character", kSampleId}, {"motion", "Moonwalk"}}), 422,
                "Walking_A");
  ExpectProblem(SubmitBake(*client, {{"character", kSampleId}, {"levels", {99}}}), 422);
  ExpectProblem(SubmitBake(*client, {{"character", kSampleId}, {"locked_joints", {"tail"}}}), 422,
                "tail");
  ExpectProblem(client->Get("/v1/bakes/not-an-id"), 404);
  ExpectProblem(client->Get("/v1/levels/..%2F..%2Fmotionlodd.db"), 404);
  ExpectProblem(client->Get("/v1/nothing-here"), 404);
  auto wrong_method = client->Delete("/v1/bakes");
  ExpectProblem(wrong_method, 405);
  EXPECT_NE(wrong_method->get_header_value("Allow").find("POST"), std::string::npos);
  ExpectProblem(client->Put("/v1/bakes", "{}", "application/json"), 400, "takes no body");
  ExpectProblem(
      client->Get((std::string("/v1/bakes/") + std::string(64, 'b') + "/level?px=abc").c_str()),
      400);
  ExpectProblem(
      client->Get((std::string("/v1/bakes/") + std::string(64, 'b') + "/level?px=100").c_str()),
      404);
  // A bake that has not run yet has no level: 409.
  ASSERT_TRUE(daemon.Stop(SIGKILL) != 0);
  ASSERT_TRUE(daemon.Start({"--threads", "1"})) << daemon.error;
  client = daemon.Client();
  auto slow = SubmitBake(
      *client,
      {{"character", kSampleId}, {"motion", "Jump_Full_Long"}, {"all_levels", true}, {"fps", 600}});
  auto queued = SubmitBake(*client, {{"character", kSampleId}, {"motion", "Walking_B"}});
  ASSERT_TRUE(slow && queued);
  ASSERT_EQ(queued->status, 202);
  ExpectProblem(
      client->Get(("/v1/bakes/" + Json(queued)["id"].get<std::string>() + "/level?px=100").c_str()),
      409);
}

TEST(DaemonSecurity, HeaderValuesAreNeverEchoedSoCrlfCannotSplitAResponse) {
  Daemon daemon(TestDirectory());
  ASSERT_TRUE(daemon.Start()) << daemon.error;
  auto client = daemon.Client();
  // The HTTP library percent-decodes header values: this one decodes to a line break.
  auto injected = client->Post("/v1/characters", {{"X-Filename", "rig.glb%0d%0aX-Injected: yes"}},
                               ReadFile(Sample()), "application/octet-stream");
  ASSERT_TRUE(injected);
  EXPECT_FALSE(injected->has_header("X-Injected"));
  ExpectProblem(injected, 400, "plain names");
  auto request_id = client->Get("/healthz", {{"X-Request-Id", "abc%0d%0aX-Injected: yes"}});
  ASSERT_TRUE(request_id);
  EXPECT_FALSE(request_id->has_header("X-Injected"));
  EXPECT_EQ(request_id->get_header_value("X-Request-Id").size(), 16u);
  auto path = client->Get("/v1/levels/x%0d%0aX-Injected:%20yes");
  ASSERT_TRUE(path);
  EXPECT_FALSE(path->has_header("X-Injected"));
  ExpectServing(*client);
}

TEST(DaemonSecurity, ABusyDaemonAnswers503WithRetryAfter) {
  Daemon daemon(TestDirectory());
  ASSERT_TRUE(daemon.Start({"--threads", "1", "--queue-capacity", "1", "--max-streams", "1"}))
      << daemon.error;
  auto client = daemon.Client();
  ASSERT_EQ(UploadFile(*client, Sample(), "rig.glb")->status, 201);
  std::vector<std::string> ids;
  int refused = 0;
  for (const char* motion : {"Jump_Full_Long", "Walking_A", "Walking_B", "Walking_C"}) {
    auto result = SubmitBake(
        *client,
        {{"character", kSampleId}, {"motion", motion}, {"all_levels", true}, {"fps", 800}});
    ASSERT_TRUE(result);
    if (result->status == 503) {
      ++refused;
      ExpectProblem(result, 503, "queue is full");
      EXPECT_FALSE(result->get_header_value("Retry-After").empty());
    } else {
      EXPECT_EQ(result->status, 202);
      ids.push_back(Json(result)["id"]);
    }
  }
  EXPECT_GE(refused, 1);
  // One stream slot: a long-poll holds it, a second waiter is refused.
  ASSERT_GE(ids.size(), 2u);
  auto holder = daemon.Client();
  std::thread poll([&] { holder->Get(("/v1/jobs/" + ids.back() + "?wait=3").c_str()); });
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  auto second = client->Get(("/v1/jobs/" + ids.back() + "/events").c_str());
  poll.join();
  if (second->status != 200) {  // the job may have finished before the second request
    ExpectProblem(second, 503, "streams");
    EXPECT_FALSE(second->get_header_value("Retry-After").empty());
  }
  // SIGTERM drains and exits 0 even with work queued.
  EXPECT_EQ(daemon.Stop(SIGTERM), 0) << daemon.Log();
}

}  // namespace
}  // namespace motionlod::server::testing
