// Level responses as an HTTP cache or CDN sees them: immutable, content-addressed,
// conditional (ETag, 304) and partial (Range: 206, 416), HEAD without a body.
#include <gtest/gtest.h>

#include "io/sha256.h"
#include "tests/server/test_util.h"

namespace motionlod::server::testing {
namespace {

class LevelResponses : public ::testing::Test {
 protected:
  void SetUp() override {
    daemon_ = std::make_unique<Daemon>(TestDirectory());
    ASSERT_TRUE(daemon_->Start()) << daemon_->error;
    client_ = daemon_->Client();
    ASSERT_EQ(
        UploadFile(*client_, SourcePath("samples/Rig_Medium_MovementBasic.glb"), "rig.glb")->status,
        201);
    auto submitted = SubmitBake(
        *client_, {{"character", kSampleId}, {"motion", "Walking_A"}, {"levels", {17, 6}}});
    ASSERT_TRUE(submitted);
    const std::string id = Json(submitted)["id"];
    ASSERT_EQ(WaitForJob(*client_, id).value("state", ""), "succeeded");
    auto choice = client_->Get(("/v1/bakes/" + id + "/level?px=50").c_str(),
                               {{"Accept", "application/json"}});
    ASSERT_TRUE(choice);
    url_ = Json(choice)["url"];
    hash_ = Json(choice)["hash"];
    auto whole = client_->Get(url_.c_str());
    ASSERT_TRUE(whole);
    ASSERT_EQ(whole->status, 200);
    bytes_ = whole->body;
  }
  std::unique_ptr<Daemon> daemon_;
  std::unique_ptr<httplib::Client> client_;
  std::string url_, hash_, bytes_;
};

TEST_F(LevelResponses, AreImmutableAndNamedByTheirSha256) {
  auto result = client_->Get(url_.c_str());
  ASSERT_TRUE(result);
  EXPECT_EQ(io::Sha256Hex(result->body), hash_);
  EXPECT_EQ(result->get_header_value("ETag"), "\"" + hash_ + "\"");
  EXPECT_EQ(result->get_header_value("Cache-Control"), "public, max-age=31536000, immutable");
  EXPECT_EQ(result->get_header_value("Accept-Ranges"), "bytes");
  EXPECT_EQ(result->get_header_value("Content-Length"), std::to_string(bytes_.size()));
  auto head = client_->Head(url_.c_str());
  ASSERT_TRUE(head);
  EXPECT_EQ(head->status, 200);
  EXPECT_TRUE(head->body.empty());
  EXPECT_EQ(head->get_header_value("Content-Length"), std::to_string(bytes_.size()));
}

TEST_F(LevelResponses, AnswerIfNoneMatchWith304) {
  for (const std::string& tag : {"\"" + hash_ + "\"", "W/\"" + hash_ + "\"",
                                 "\"other\", \"" + hash_ + "\"", std::string("*")}) {
    auto result = client_->Get(url_.c_str(), {{"If-None-Match", tag}});
    ASSERT_TRUE(result);
    EXPECT_EQ(result->status, 304) << tag;
    EXPECT_TRUE(result->body.empty());
    EXPECT_EQ(result->get_header_value("ETag"), "\"" + hash_ + "\"");
  }
  auto stale = client_->Get(url_.c_str(), {{"If-None-Match", "\"something-else\""}});
  ASSERT_TRUE(stale);
  EXPECT_EQ(stale->status, 200);
  EXPECT_TRUE(stale->body == bytes_);
}

TEST_F(LevelResponses, ServeOneByteRangeAs206) {
  const size_t size = bytes_.size();
  struct Case {
    std::string range;
    size_t first, last;
  };
  for (const Case& c : std::vector<Case>{{"bytes=0-111", 0, 111},
                                         {"bytes=112-", 112, size - 1},
                                         {"bytes=-16", size - 16, size - 1},
                                         {"bytes=100-999999999", 100, size - 1},
                                         // Overlapping and adjacent ranges are merged into one.
                                         {"bytes=0-9,5-20,21-30", 0, 30}}) {
    auto result = client_->Get(url_.c_str(), {{"Range", c.range}});
    ASSERT_TRUE(result);
    EXPECT_EQ(result->status, 206) << c.range;
    EXPECT_TRUE(result->body == bytes_.substr(c.first, c.last - c.first + 1)) << c.range;
    EXPECT_EQ(result->get_header_value("Content-Range"), "bytes " + std::to_string(c.first) + "-" +
                                                             std::to_string(c.last) + "/" +
                                                             std::to_string(size));
  }
}

TEST_F(LevelResponses, AnswerUnsatisfiableRangesWith416AndIgnoreOthers) {
  auto beyond =
      client_->Get(url_.c_str(), {{"Range", "bytes=" + std::to_string(bytes_.size()) + "-"}});
  ExpectProblem(beyond, 416);
  EXPECT_EQ(beyond->get_header_value("Content-Range"), "bytes */" + std::to_string(bytes_.size()));
  // cpp-httplib parses Range before any route runs and answers bad syntax with 416
  // itself; the daemon turns that into problem+json.
  ExpectProblem(client_->Get(url_.c_str(), {{"Range", "bytes=nine-"}}), 416);
  // Another unit (RFC 9110 says to ignore it; the connection gate drops it before the
  // library sees it), disjoint ranges, too many ranges and a stale If-Range: the whole
  // file.
  std::string many = "bytes=0-0";
  for (int r = 1; r < 40; ++r) {
    const std::string at = std::to_string(2 * r);
    many.append(",").append(at).append("-").append(at);
  }
  for (const httplib::Headers& headers :
       std::vector<httplib::Headers>{{{"Range", "items=0-9"}},
                                     {{"range", " Items=0-9"}},
                                     {{"Range", "bytes=0-9,100-109"}},
                                     {{"Range", many}},
                                     {{"Range", "bytes=0-9"}, {"If-Range", "\"stale\""}}}) {
    auto result = client_->Get(url_.c_str(), headers);
    ASSERT_TRUE(result);
    EXPECT_EQ(result->status, 200) << headers.begin()->second;
    EXPECT_TRUE(result->body == bytes_);
  }
  auto fresh =
      client_->Get(url_.c_str(), {{"Range", "bytes=0-9"}, {"If-Range", "\"" + hash_ + "\""}});
  ASSERT_TRUE(fresh);
  EXPECT_EQ(fresh->status, 206);
}

TEST_F(LevelResponses, UnknownOrMalformedHashesAre404WithoutTouchingTheDisk) {
  ExpectProblem(client_->Get((std::string("/v1/levels/") + std::string(64, '0')).c_str()), 404);
  ExpectProblem(client_->Get("/v1/levels/ABCDEF"), 404, "64 hex");
  // An uploaded file is a blob too, but not a level.
  ExpectProblem(client_->Get((std::string("/v1/levels/") + kSampleId).c_str()), 404);
}

}  // namespace
}  // namespace motionlod::server::testing
