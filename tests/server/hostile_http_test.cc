// Hostile HTTP against the real daemon, over raw sockets where a client library would
// sanitise the request: oversized request lines and headers, chunked and gzip bodies past
// the limit, CRLF smuggled through percent-encoding, many overlapping ranges, slow
// clients, path-like and overlong ids, wrong content types, invalid JSON, wrong keys, a
// file whose content does not match its name, a bake naming a deleted character. Every
// answer is a 4xx problem (never a 5xx, never the text of an exception) and the daemon
// keeps serving. security_test.cc holds the cases a client library can send.
#include <gtest/gtest.h>
#include <signal.h>

#include "tests/server/raw_http.h"
#include "tests/server/test_util.h"

namespace motionlod::server::testing {
namespace {

// The reply is a problem+json of this status, with no header or body text that a C++
// exception would have put there.
void ExpectRawProblem(const RawReply& reply, int status, const std::string& detail_part = "") {
  EXPECT_EQ(reply.status, status) << reply.head << reply.body;
  EXPECT_EQ(RawConnection::Header(reply.head, "content-type"), "application/problem+json")
      << reply.head;
  const json problem = json::parse(reply.body, nullptr, false);
  ASSERT_TRUE(problem.is_object()) << reply.body;
  EXPECT_EQ(problem.value("status", 0), status);
  EXPECT_EQ(problem.value("request_id", ""), RawConnection::Header(reply.head, "x-request-id"));
  EXPECT_EQ(RawConnection::Header(reply.head, "x-content-type-options"), "nosniff") << reply.head;
  if (!detail_part.empty()) {
    EXPECT_NE(problem.value("detail", "").find(detail_part), std::string::npos) << reply.body;
  }
  EXPECT_EQ(RawConnection::Header(reply.head, "exception_what"), "") << reply.head;
  for (const char* leak : {"std::", "basic_string", "stoi", "stoll", "json.exception", "what()"}) {
    EXPECT_EQ(reply.body.find(leak), std::string::npos) << reply.body;
  }
}

// Sends `request` on a fresh connection and reads the one reply.
RawReply Exchange(int port, std::string_view request) {
  RawConnection connection(port);
  EXPECT_TRUE(connection.connected());
  connection.Send(request);
  return connection.Read();
}

void ExpectServing(const Daemon& daemon) {
  auto health = daemon.Client()->Get("/healthz");
  ASSERT_TRUE(health) << "the daemon stopped answering";
  EXPECT_EQ(health->status, 200);
}

class HostileHttp : public ::testing::Test {
 protected:
  void StartDaemon(const std::vector<std::string>& args = {},
                   const std::vector<std::string>& env = {}) {
    daemon_ = std::make_unique<Daemon>(TestDirectory());
    ASSERT_TRUE(daemon_->Start(args, env)) << daemon_->error;
    port_ = daemon_->port();
  }
  // Uploads the sample and bakes two levels of Walking_A; returns the bake id.
  std::string Bake() {
    auto client = daemon_->Client();
    auto uploaded = UploadFile(*client, Sample(), "rig.glb");
    EXPECT_TRUE(uploaded && (uploaded->status == 201 || uploaded->status == 200));
    auto submitted = SubmitBake(
        *client, {{"character", kSampleId}, {"motion", "Walking_A"}, {"levels", {17, 6}}});
    EXPECT_TRUE(submitted);
    const std::string id = Json(submitted).value("id", "");
    EXPECT_EQ(WaitForJob(*client, id).value("state", ""), "succeeded");
    return id;
  }
  std::unique_ptr<Daemon> daemon_;
  int port_ = 0;
};

TEST_F(HostileHttp, OversizedRequestLinesAndHeaderLinesAreRefused) {
  StartDaemon();
  const std::string long_path = "/v1/levels/" + std::string(20000, 'a');
  ExpectRawProblem(Exchange(port_, "GET " + long_path + " HTTP/1.1\r\nHost: x\r\n\r\n"), 414);
  ExpectRawProblem(Exchange(port_, "GET /healthz HTTP/1.1\r\nHost: x\r\nX-Big: " +
                                       std::string(20000, 'a') + "\r\n\r\n"),
                   400);
  // A request line that is not one, and one with a NUL in it.
  ExpectRawProblem(Exchange(port_, "GARBAGE\r\n\r\n"), 400);
  constexpr char kNul[] = "GET /healthz\0 HTTP/1.1\r\nHost: x\r\n\r\n";
  ExpectRawProblem(Exchange(port_, std::string(kNul, sizeof kNul - 1)), 400);
  ExpectServing(*daemon_);
}

TEST_F(HostileHttp, FramingTricksAreRefusedBeforeAnyBodyIsRead) {
  StartDaemon({"--max-upload-bytes", "100000"});
  const std::string bake =
      "POST /v1/bakes HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n";
  // Both framings at once (request smuggling), a coding other than chunked, lengths that
  // are no numbers.
  ExpectRawProblem(Exchange(port_, bake + "Content-Length: 4\r\nTransfer-Encoding: chunked\r\n\r\n"
                                          "0\r\n\r\n"),
                   400, "both");
  ExpectRawProblem(Exchange(port_, bake + "Transfer-Encoding: gzip, chunked\r\n\r\n0\r\n\r\n"),
                   501);
  ExpectRawProblem(Exchange(port_, bake + "Content-Length: -5\r\n\r\n"), 400, "Content-Length");
  ExpectRawProblem(Exchange(port_, bake + "Content-Length: 99999999999999999999999\r\n\r\n"), 400,
                   "Content-Length");
  // A chunk size past 64 bits.
  ExpectRawProblem(
      Exchange(port_,
               bake + "Transfer-Encoding: chunked\r\n\r\nffffffffffffffffffff\r\nabc\r\n0\r\n\r\n"),
      400);
  // A Content-Length far over the limit is refused at once, the connection closed.
  RawConnection huge(port_);
  huge.Send(
      "POST /v1/characters?filename=a.glb HTTP/1.1\r\nHost: x\r\n"
      "Content-Type: application/octet-stream\r\nContent-Length: 1000000000\r\n\r\n");
  const RawReply refused = huge.Read();
  ExpectRawProblem(refused, 413, "100000");
  EXPECT_TRUE(refused.closed || huge.ClosedByDaemon());
  ExpectServing(*daemon_);
}

TEST_F(HostileHttp, ChunkedAndGzipBodiesPastTheLimitAre413) {
  StartDaemon({"--max-upload-bytes", "100000", "--max-json-bytes", "4096"});
  const std::string upload =
      "POST /v1/characters?filename=bomb.glb HTTP/1.1\r\nHost: x\r\n"
      "Content-Type: application/octet-stream\r\n";
  // A gzip bomb, chunked: a few hundred bytes on the wire, 3 MB once inflated.
  const std::string bomb = Gzip(std::string(3000000, '\0'));
  ASSERT_LT(bomb.size(), 10000u);
  ExpectRawProblem(
      Exchange(port_, upload + "Content-Encoding: gzip\r\nTransfer-Encoding: chunked\r\n\r\n" +
                          Chunked(bomb, 512)),
      413, "decoded body");
  // Plain chunks past the limit, in many small chunks.
  ExpectRawProblem(Exchange(port_, upload + "Transfer-Encoding: chunked\r\n\r\n" +
                                       Chunked(std::string(150000, 'x'), 100)),
                   413, "decoded body");
  // A JSON body past max_json_bytes, gzip-compressed to fit.
  const std::string json_bomb = Gzip("{\"character\":\"" + std::string(100000, 'a') + "\"}");
  ExpectRawProblem(
      Exchange(port_,
               "POST /v1/bakes HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
               "Content-Encoding: gzip\r\nContent-Length: " +
                   std::to_string(json_bomb.size()) + "\r\n\r\n" + json_bomb),
      413);
  // gzip that is not gzip.
  ExpectRawProblem(Exchange(port_, upload + "Content-Encoding: gzip\r\nContent-Length: 12\r\n\r\n" +
                                       "not gzip at all"),
                   400);
  ExpectServing(*daemon_);
}

TEST_F(HostileHttp, PercentEncodedCrlfNeverSplitsAResponse) {
  StartDaemon();
  const std::string sample = ReadFile(Sample());
  for (const std::string& target :
       {std::string("/v1/characters?filename=rig.glb%0d%0aX-Injected:%20yes"),
        std::string("/v1/characters?filename=%0d%0a%0d%0aHTTP/1.1%20200%20OK")}) {
    SCOPED_TRACE(target);
    const RawReply reply =
        Exchange(port_, "POST " + target +
                            " HTTP/1.1\r\nHost: x\r\nContent-Type: application/octet-stream\r\n"
                            "Content-Length: " +
                            std::to_string(sample.size()) + "\r\n\r\n" + sample);
    ExpectRawProblem(reply, 400, "plain names");
    EXPECT_EQ(RawConnection::Header(reply.head, "x-injected"), "");
  }
  for (const std::string& target : {std::string("/v1/levels/%0d%0aX-Injected:%20yes"),
                                    std::string("/v1/bakes/x%0aX-Injected:%20yes/level?px=1"),
                                    std::string("/healthz?x=%0d%0aX-Injected:%20yes")}) {
    SCOPED_TRACE(target);
    const RawReply reply =
        Exchange(port_, "GET " + target +
                            " HTTP/1.1\r\nHost: x\r\nX-Request-Id: a%0d%0aX-Injected: yes\r\n\r\n");
    EXPECT_NE(reply.status, 0);
    EXPECT_LT(reply.status, 500);
    EXPECT_EQ(RawConnection::Header(reply.head, "x-injected"), "") << reply.head;
    EXPECT_EQ(RawConnection::Header(reply.head, "x-request-id").size(), 16u);
  }
  ExpectServing(*daemon_);
}

TEST_F(HostileHttp, ManyOverlappingRangesAreMergedOrIgnored) {
  StartDaemon();
  const std::string bake = Bake();
  auto choice = daemon_->Client()->Get(("/v1/bakes/" + bake + "/level?px=50").c_str(),
                                       {{"Accept", "application/json"}});
  ASSERT_TRUE(choice);
  const std::string url = Json(choice)["url"];
  const std::string whole = daemon_->Client()->Get(url.c_str())->body;
  ASSERT_GT(whole.size(), 1000u);
  const auto get = [&](const std::string& range) {
    return Exchange(port_, "GET " + url + " HTTP/1.1\r\nHost: x\r\nRange: " + range + "\r\n\r\n");
  };
  // Sixteen overlapping ranges merge into one.
  std::string overlapping = "bytes=0-99";
  for (int r = 1; r < 16; ++r) {
    overlapping += ',';
    overlapping += std::to_string(r * 50);
    overlapping += '-';
    overlapping += std::to_string(r * 50 + 99);
  }
  RawReply merged = get(overlapping);
  EXPECT_EQ(merged.status, 206);
  EXPECT_EQ(RawConnection::Header(merged.head, "content-range"),
            "bytes 0-849/" + std::to_string(whole.size()));
  EXPECT_EQ(merged.body, whole.substr(0, 850));
  // Hundreds of copies of one range, or of the whole file: the whole file, once.
  std::string many = "bytes=0-";
  for (int r = 0; r < 1500; ++r) many += ",0-";
  RawReply ignored = get(many);
  EXPECT_EQ(ignored.status, 200);
  EXPECT_EQ(ignored.body, whole);
  // A thousand leading zeros are still the number 0.
  RawReply zeros = get("bytes=" + std::string(1000, '0') + "-1");
  EXPECT_EQ(zeros.status, 206);
  EXPECT_EQ(zeros.body, whole.substr(0, 2));
  // Numbers past 64 bits, and no range starting inside the file.
  ExpectRawProblem(get("bytes=99999999999999999999999-"), 416);
  ExpectRawProblem(get("bytes=" + std::to_string(whole.size()) + "-"), 416);
  ExpectServing(*daemon_);
}

TEST_F(HostileHttp, SlowClientsAreCutOffAndDoNotHoldTheDaemon) {
  // Four connection threads, one second for headers and for each socket read, two
  // seconds for a body.
  StartDaemon({"--http-threads", "4", "--max-streams", "1", "--header-timeout-seconds", "1",
               "--read-timeout-seconds", "1", "--keep-alive-timeout-seconds", "1",
               "--upload-timeout-seconds", "2"});
  // Silent clients, one per connection thread: a half-sent request line, half-sent
  // headers, an idle keep-alive connection, an open connection that never says anything.
  std::vector<std::unique_ptr<RawConnection>> silent;
  for (const char* partial : {"GET /healthz HT", "GET /healthz HTTP/1.1\r\nHost: x\r\nX-Slow", "",
                              "GET /healthz HTTP/1.1\r\n"}) {
    silent.push_back(std::make_unique<RawConnection>(port_));
    silent.back()->Send(partial);
  }
  // Each is closed after its timeout, and a well-behaved client gets through meanwhile.
  ExpectServing(*daemon_);
  for (auto& connection : silent) EXPECT_TRUE(connection->ClosedByDaemon());

  // A body sent slower than upload_timeout_seconds allows: 408, the connection closed.
  RawConnection slow(port_);
  ASSERT_TRUE(
      slow.Send("POST /v1/characters?filename=slow.glb HTTP/1.1\r\nHost: x\r\n"
                "Content-Type: application/octet-stream\r\nContent-Length: 100000\r\n\r\n"));
  // Each piece comes within the read timeout; the whole body would take 250 s. Sending
  // stops at the answer: more data after the daemon's close would reset the connection.
  for (int piece = 0; piece < 20 && !slow.Answered() && slow.Send(std::string(200, 'x')); ++piece) {
    std::this_thread::sleep_for(std::chrono::milliseconds(500));
  }
  const RawReply timed_out = slow.Read();
  ExpectRawProblem(timed_out, 408, "upload_timeout_seconds");
  ExpectServing(*daemon_);
}

TEST_F(HostileHttp, AResetStreamClientFreesItsSlotWithinAboutASecond) {
  // One stream slot, one bake worker: a long bake runs, a second waits behind it, and
  // its event stream stays open as long as it waits.
  StartDaemon({"--max-streams", "1", "--threads", "1"});
  auto client = daemon_->Client();
  ASSERT_EQ(UploadFile(*client, Sample(), "rig.glb")->status, 201);
  std::vector<std::string> ids;
  for (const char* motion : {"Jump_Full_Long", "Walking_A"}) {
    auto submitted = SubmitBake(
        *client,
        {{"character", kSampleId}, {"motion", motion}, {"all_levels", true}, {"fps", 800}});
    ASSERT_TRUE(submitted);
    ASSERT_EQ(submitted->status, 202) << submitted->body;
    ids.push_back(Json(submitted)["id"]);
  }
  const std::string request =
      "GET /v1/jobs/" + ids.back() + "/events HTTP/1.1\r\nHost: x\r\n\r\n";
  auto stream = std::make_unique<RawConnection>(port_);
  ASSERT_TRUE(stream->Send(request));
  ASSERT_EQ(stream->ReadStatus(), 200);
  RawConnection refused(port_);
  refused.Send(request);
  EXPECT_EQ(refused.ReadStatus(), 503);  // the one slot is taken

  // The client resets its connection: the stream's next write (a comment each second
  // without news) fails and frees the slot.
  stream->Reset();
  const auto reset_at = std::chrono::steady_clock::now();
  int status = 0;
  while (status != 200 && std::chrono::steady_clock::now() - reset_at < std::chrono::seconds(10)) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    RawConnection next(port_);
    next.Send(request);
    status = next.ReadStatus();
  }
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - reset_at).count();
  std::printf("a reset stream client's slot was free again after %.2f s\n", seconds);
  EXPECT_EQ(status, 200);
  EXPECT_LT(seconds, 2.5);
}

TEST_F(HostileHttp, PathLikeAndOverlongIdsAreRefusedBeforeAnyLookup) {
  StartDaemon();
  auto client = daemon_->Client();
  const std::vector<std::string> ids = {
      "..%2F..%2Fmotionlodd.db",
      "%2e%2e%2f%2e%2e%2fetc%2fpasswd",
      "....%2F....%2F",
      "%00",
      "%2Fetc%2Fpasswd",
      std::string(64, 'A'),             // upper-case hex
      std::string(63, 'a'),             // one digit short
      std::string(65, 'a'),             // one digit long
      std::string(64, 'a') + "%00.db",  // a NUL after a valid id
      std::string(64, 'g'),             // not hex
      std::string(4000, 'a'),           // overlong, within the URI limit
      "~root",
      "%252e%252e%252f",  // double-encoded
  };
  for (const char* collection : {"characters", "bakes", "levels", "jobs", "motions"}) {
    for (const std::string& id : ids) {
      const std::string path = std::string("/v1/") + collection + "/" + id;
      SCOPED_TRACE(path.substr(0, 120));
      ExpectProblem(client->Get(path.c_str()), 404);
    }
  }
  for (const std::string& id : {std::string("..%2F..%2Fmotionlodd.db"), std::string(4000, 'a')}) {
    ExpectProblem(client->Delete(("/v1/characters/" + id).c_str()), 404);
    ExpectProblem(client->Delete(("/v1/bakes/" + id).c_str()), 404);
    ExpectProblem(client->Get(("/v1/bakes/" + id + "/level?px=100").c_str()), 404);
    ExpectProblem(client->Get(("/v1/jobs/" + id + "/events").c_str()), 404);
    ExpectProblem(SubmitBake(*client, {{"character", id}}), 400);
    ExpectProblem(client->Post(("/v1/motions?filename=walk.bvh&character=" + id).c_str(), "x",
                               "application/octet-stream"),
                  400, "character id");
  }
  ExpectServing(*daemon_);
}

TEST_F(HostileHttp, WrongContentTypesAre415) {
  StartDaemon();
  auto client = daemon_->Client();
  const std::string sample = ReadFile(Sample());
  const std::string bake = std::string(R"({"character":")") + kSampleId + R"("})";
  for (const char* type :
       {"text/plain", "application/xml", "application/jsonx", "application/x-www-form-urlencoded",
        "multipart/form-data; boundary=x"}) {
    SCOPED_TRACE(type);
    ExpectProblem(client->Post("/v1/bakes", bake, type), 415);
  }
  // No Content-Type at all.
  ExpectRawProblem(Exchange(port_, "POST /v1/bakes HTTP/1.1\r\nHost: x\r\nContent-Length: " +
                                       std::to_string(bake.size()) + "\r\n\r\n" + bake),
                   415);
  for (const char* type : {"multipart/mixed; boundary=x", "multipart/related; boundary=x",
                           "application/x-www-form-urlencoded"}) {
    SCOPED_TRACE(type);
    ExpectProblem(client->Post("/v1/characters?filename=rig.glb", sample, type), 415);
  }
  // multipart/form-data without a boundary, or with a body that is not multipart (small:
  // the connection closes on a body that could not be read, and a client still sending a
  // large one sees a reset).
  ExpectProblem(client->Post("/v1/characters", "hello", "multipart/form-data"), 400);
  ExpectProblem(client->Post("/v1/characters", "hello", "multipart/form-data; boundary=zz"), 400);
  // A well-formed multipart body where none is read (a wrong type, no route, no such
  // character): the body is dropped, the answer is the route's.
  const std::string form =
      "--zz\r\nContent-Disposition: form-data; name=\"file\"; filename=\"a.glb\"\r\n\r\n"
      "hello\r\n--zz--\r\n";
  ExpectProblem(client->Post("/v1/bakes", form, "multipart/form-data; boundary=zz"), 415);
  ExpectProblem(client->Post("/v1/nothing", form, "multipart/form-data; boundary=zz"), 404);
  ExpectProblem(client->Post((std::string("/v1/characters/") + kSampleId).c_str(), form,
                             "multipart/form-data; boundary=zz"),
                405);
  ExpectProblem(client->Post("/v1/motions", form, "multipart/form-data; boundary=zz"), 400,
                "character");
  // An unknown Content-Encoding: refused before the body is read, the connection closed.
  ExpectProblem(client->Post("/v1/characters?filename=rig.glb", {{"Content-Encoding", "zstd"}},
                             "(zstd)", "application/octet-stream"),
                415);
  ExpectServing(*daemon_);
}

TEST_F(HostileHttp, InvalidJsonIs400AndOversizedJsonIs413) {
  StartDaemon();
  auto client = daemon_->Client();
  const std::string id = kSampleId;
  const std::vector<std::string> bodies = {
      "",
      "null",
      "[]",
      "42",
      "\"character\"",
      "{",
      "{\"character\":",
      "{\"character\":\"" + id + "\",}",
      "{\"character\":\"" + id + "\"} trailing",
      std::string("{\"character\":\"") + id + "\",\"fps\":\"\xff\xfe\"}",
      std::string("{\"character\":\"") + '\0' + id + "\"}",
      "{\"character\":\"" + id + "\",\"fps\":1e999}",
      "{\"character\":\"" + id + "\",\"fps\":-30}",
      "{\"character\":\"" + id + "\",\"levels\":[1e300]}",
      "{\"character\":\"" + id + "\",\"levels\":\"17\"}",
      "{\"character\":\"" + id + "\",\"levels\":[" + std::string(20000, '[') + "]}",
      std::string(30000, '['),
      "{\"character\":[\"" + id + "\"]}",
  };
  for (const std::string& body : bodies) {
    SCOPED_TRACE(body.substr(0, 80));
    ExpectProblem(client->Post("/v1/bakes", body, "application/json"), 400);
  }
  ExpectProblem(client->Post("/v1/bakes", "{\"character\":\"" + std::string(70000, 'a') + "\"}",
                             "application/json"),
                413);
  ExpectServing(*daemon_);
}

TEST_F(HostileHttp, WrongOrMissingKeysAre401Or403) {
  const std::string write_key = "write-key-0123456789abcdef";
  const std::string read_key = "read-key-0123456789abcdef";
  StartDaemon({}, {"MOTIONLODD_WRITE_KEYS=" + write_key, "MOTIONLODD_READ_KEYS=" + read_key});
  auto client = daemon_->Client();
  const std::string sample = ReadFile(Sample());
  const auto upload = [&](const httplib::Headers& headers) {
    return client->Post("/v1/characters?filename=rig.glb", headers, sample,
                        "application/octet-stream");
  };
  for (const std::string& authorization :
       {std::string("Bearer"), std::string("Bearer "), std::string("Basic ") + write_key, write_key,
        "Bearer " + write_key.substr(0, write_key.size() - 1), "Bearer " + write_key + "x",
        "Bearer " + write_key + "%00", "Bearer " + std::string(5000, 'k'),
        "Bearer " + write_key + ", Bearer " + write_key}) {
    SCOPED_TRACE(authorization.substr(0, 60));
    ExpectProblem(upload({{"Authorization", authorization}}), 401);
  }
  // Two Authorization headers: the first counts.
  ExpectProblem(upload({{"Authorization", "Bearer wrong-key-0123456789abcdef"},
                        {"Authorization", "Bearer " + write_key}}),
                401);
  // A key in the query string or another header is no key.
  ExpectProblem(client->Post(("/v1/characters?filename=rig.glb&key=" + write_key).c_str(), sample,
                             "application/octet-stream"),
                401);
  ExpectProblem(upload({{"X-Api-Key", write_key}}), 401);
  ExpectProblem(upload({{"Authorization", "Bearer " + read_key}}), 403, "reads only");
  // The scheme is case-insensitive (RFC 9110); the key is not.
  EXPECT_EQ(upload({{"Authorization", "bearer " + write_key}})->status, 201);
  std::string upper = write_key;
  std::transform(upper.begin(), upper.end(), upper.begin(),
                 [](unsigned char c) { return static_cast<char>(std::toupper(c)); });
  ExpectProblem(client->Get("/v1/characters", {{"Authorization", "Bearer " + upper}}), 401);
  ExpectProblem(client->Get("/metrics", {{"Authorization", "Bearer"}}), 401);
  EXPECT_EQ(client->Get("/v1/characters", Auth(read_key))->status, 200);
  ExpectServing(*daemon_);
}

TEST_F(HostileHttp, AFileWhoseContentDoesNotMatchItsNameIs422) {
  StartDaemon();
  auto client = daemon_->Client();
  const std::string sample = ReadFile(Sample());
  const std::string bvh =
      "HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 0\n  CHANNELS 6 Xposition Yposition Zposition "
      "Zrotation Xrotation Yrotation\n  End Site\n  {\n    OFFSET 0 1 0\n  }\n}\nMOTION\n"
      "Frames: 2\nFrame Time: 0.033333\n0 0 0 0 0 0\n0 0 0 0 0 10\n";
  struct Case {
    std::string name, bytes;
  };
  for (const Case& c : {Case{"rig.bvh", sample}, Case{"rig.dae", sample}, Case{"rig.fbx", sample},
                        Case{"rig.gltf", sample}, Case{"walk.glb", bvh}, Case{"walk.dae", bvh}}) {
    SCOPED_TRACE(c.name);
    ExpectProblem(client->Post(("/v1/characters?filename=" + c.name).c_str(), c.bytes,
                               "application/octet-stream"),
                  422);
  }
  // Named right, the same bytes import.
  EXPECT_EQ(UploadFile(*client, Sample(), "rig.glb")->status, 201);
  ExpectServing(*daemon_);
}

TEST_F(HostileHttp, ABakeNamingADeletedCharacterIs404) {
  StartDaemon();
  auto client = daemon_->Client();
  const std::string bake = Bake();
  auto choice =
      client->Get(("/v1/bakes/" + bake + "/level?px=50").c_str(), {{"Accept", "application/json"}});
  ASSERT_TRUE(choice);
  ASSERT_EQ(client->Delete((std::string("/v1/characters/") + kSampleId).c_str())->status, 204);
  ExpectProblem(SubmitBake(*client, {{"character", kSampleId}, {"motion", "Walking_B"}}), 404);
  ExpectProblem(
      SubmitBake(*client, {{"character", kSampleId}, {"motion", "Walking_A"}, {"levels", {17, 6}}}),
      404);
  ExpectProblem(client->Get(("/v1/bakes/" + bake).c_str()), 404);
  ExpectProblem(client->Get(("/v1/bakes/" + bake + "/level?px=50").c_str()), 404);
  ExpectProblem(client->Get((std::string("/v1/characters/") + kSampleId).c_str()), 404);
  ExpectProblem(client->Delete((std::string("/v1/characters/") + kSampleId).c_str()), 404);
  ExpectProblem(
      client->Post((std::string("/v1/motions?filename=walk.bvh&character=") + kSampleId).c_str(),
                   "HIERARCHY", "application/octet-stream"),
      404);
  // Uploaded again, it bakes again.
  EXPECT_EQ(UploadFile(*client, Sample(), "rig.glb")->status, 201);
  auto again =
      SubmitBake(*client, {{"character", kSampleId}, {"motion", "Walking_A"}, {"levels", {17, 6}}});
  ASSERT_TRUE(again);
  EXPECT_EQ(WaitForJob(*client, Json(again)["id"]).value("state", ""), "succeeded");
}

TEST_F(HostileHttp, AccessLogLinesEscapeControlCharactersAndCarryTheRequestId) {
  StartDaemon();
  const RawReply reply =
      Exchange(port_, "GET /v1/levels/%1b%5b31mred%0d%0afake HTTP/1.1\r\nHost: x\r\n\r\n");
  ExpectRawProblem(reply, 404);
  const std::string id = RawConnection::Header(reply.head, "x-request-id");
  // SIGTERM flushes the per-thread access-log buffers.
  ASSERT_EQ(daemon_->Stop(SIGTERM), 0);
  const std::string log = daemon_->Log();
  const size_t line = log.find("[" + id + "] GET /v1/levels/\\x1b[31mred\\x0d\\x0afake 404 ");
  EXPECT_NE(line, std::string::npos) << log;
  EXPECT_EQ(log.find('\x1b'), std::string::npos);
}

}  // namespace
}  // namespace motionlod::server::testing
