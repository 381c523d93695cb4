// Retries: a daemon whose bake queue is full answers 503 with Retry-After, and the client
// waits and repeats until there is room; a daemon that is not there is retried, then
// reported; a 4xx is final at once.
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include "tests/client/fixture.h"

namespace motionlod::client::testing {
namespace {

namespace api = proto::api;

using ClientRetry = DaemonTest;

TEST_F(ClientRetry, FullBakeQueueAnswers503AndTheClientRetriesUntilThereIsRoom) {
  // One worker and room for one queued job: with one bake running and one waiting, the
  // daemon refuses the next with 503.
  StartDaemon({"--threads", "1", "--queue-capacity", "1", "--bake-threads", "1"});
  ClientOptions options = Options();
  options.retry = {.max_attempts = 200,
                   .initial_backoff_seconds = 0.05,
                   .backoff_multiplier = 1.5,
                   .max_backoff_seconds = 0.5};
  std::vector<RetryEvent> retries;
  options.on_retry = [&retries](const RetryEvent& event) { retries.push_back(event); };
  Client client = MakeClient(options);
  auto file = ReadUploadFile(SamplePath());
  ASSERT_TRUE(file.ok());
  auto character = client.UploadCharacter({*file});
  ASSERT_TRUE(character.ok()) << character.error().ToString();

  // Distinct requests (each its own bake), every level at 240 fps or just under: each
  // keeps the worker busy for tens of milliseconds, far longer than a submission takes, so
  // the queue of one is full from the third submission on, however fast the machine (a
  // single level, a few milliseconds, could finish before the next one is submitted).
  std::vector<std::string> jobs;
  for (int k = 0; k < 16 && (k < 5 || retries.empty()); ++k) {
    api::BakeRequest request = SampleBakeRequest(character->value.id);
    request.levels.clear();
    request.all_levels = true;
    request.fps = 240 - k;
    auto job = client.SubmitBake(request);
    ASSERT_TRUE(job.ok()) << "bake " << k << ": " << job.error().ToString();
    jobs.push_back(job->id);
  }
  ASSERT_FALSE(retries.empty()) << "a queue of one must have been full during " << jobs.size()
                                << " bakes";
  for (const RetryEvent& event : retries) {
    EXPECT_EQ(event.http_status, 503);
    EXPECT_NE(event.reason.find("503"), std::string::npos) << event.reason;
    EXPECT_LE(event.delay_seconds, 0.5) << "Retry-After is capped by the policy";
  }
  for (const std::string& job : jobs) {
    auto bake = client.WaitForBake(job, {}, 300);
    ASSERT_TRUE(bake.ok()) << bake.error().ToString();
    EXPECT_EQ(bake->state, "succeeded");
  }
}

TEST_F(ClientRetry, UnreachableDaemonIsRetriedThenReportedAsAConnectionError) {
  // A port that was just free: nothing listens there.
  const int probe = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  ASSERT_EQ(::bind(probe, reinterpret_cast<sockaddr*>(&address), sizeof address), 0);
  socklen_t length = sizeof address;
  ASSERT_EQ(::getsockname(probe, reinterpret_cast<sockaddr*>(&address), &length), 0);
  const int port = ntohs(address.sin_port);
  ::close(probe);

  ClientOptions options;
  options.base_url = "http://127.0.0.1:" + std::to_string(port);
  options.retry = {.max_attempts = 3, .initial_backoff_seconds = 0.01, .backoff_multiplier = 2,
                   .max_backoff_seconds = 0.05};
  std::vector<RetryEvent> retries;
  options.on_retry = [&retries](const RetryEvent& event) { retries.push_back(event); };
  auto client = Client::Create(options);
  ASSERT_TRUE(client.ok());
  auto job = client->GetJob(std::string(64, 'b'));
  ASSERT_FALSE(job.ok());
  EXPECT_EQ(job.error().kind, ErrorKind::kConnection);
  ASSERT_EQ(retries.size(), 2u) << "three tries, two waits";
  EXPECT_EQ(retries[0].http_status, 0);
  EXPECT_DOUBLE_EQ(retries[0].delay_seconds, 0.01);
  EXPECT_DOUBLE_EQ(retries[1].delay_seconds, 0.02);
}

TEST_F(ClientRetry, ClientErrorsAreNotRetried) {
  StartDaemon();
  ClientOptions options = Options();
  int retries = 0;
  options.on_retry = [&retries](const RetryEvent&) { ++retries; };
  Client client = MakeClient(options);
  auto missing = client.GetJob(std::string(64, 'c'));
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.error().http_status, 404);
  EXPECT_EQ(retries, 0);
}

}  // namespace
}  // namespace motionlod::client::testing
