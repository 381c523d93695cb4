// The Redis backend's parts against a real redis-server: the Store contract both stores
// keep (run on SqliteStore too, so that the two cannot drift), the blob store's hash
// check and size cap, and the queue's deduplication, capacity, takeover of a dead
// consumer's job and requeue of an interrupted one.
#include <gtest/gtest.h>

#include <atomic>
#include <condition_variable>
#include <mutex>
#include <thread>

#include "server/redis_job_queue.h"
#include "server/redis_store.h"
#include "server/sqlite_store.h"
#include "tests/server/daemon.h"
#include "tests/server/redis.h"

namespace motionlod::server::testing {
namespace {

namespace fs = std::filesystem;

std::shared_ptr<RedisPool> Pool(const Redis& redis) {
  return std::make_shared<RedisPool>(*ParseRedisUrl(redis.url()), 2.0);
}

CharacterRecord Character(char id, char file) {
  CharacterRecord c;
  c.id = std::string(64, id);
  c.name = "c.glb";
  c.files = {{"c.glb", std::string(64, file), 3}};
  c.joints = 2;
  c.vertices = 10;
  c.joint_names = {"root", "hip"};
  c.warnings = {"a warning"};
  c.created_ms = 5;
  return c;
}

MotionRecord Motion(char id, const std::string& character, const std::string& animation,
                    const std::string& source, int64_t created_ms) {
  MotionRecord m;
  m.id = std::string(64, id);
  m.character_id = character;
  m.animation = animation;
  m.source = source;
  m.source_id = character;
  m.duration_seconds = 1.0 / 3;
  m.source_fps = 29.97;
  m.frames = 31;
  m.created_ms = created_ms;
  if (source == "file") m.files = {{"m.bvh", std::string(64, 'e'), 9}};
  return m;
}

class StoreContract : public ::testing::TestWithParam<const char*> {
 protected:
  void SetUp() override {
    dir_ = TestDirectory();
    if (std::string(GetParam()) == "sqlite") {
      auto store = SqliteStore::Open(dir_ / "db");
      ASSERT_TRUE(store.ok()) << store.status().message();
      store_ = std::move(*store);
      return;
    }
    if (!Redis::Installed()) GTEST_SKIP() << "redis-server is not installed";
    redis_ = std::make_unique<Redis>(dir_ / "redis");
    ASSERT_TRUE(redis_->Start()) << redis_->error;
    store_ = std::make_unique<RedisStore>(Pool(*redis_), "test:");
  }
  void TearDown() override {
    store_.reset();
    redis_.reset();
    if (!HasFailure()) fs::remove_all(dir_);
  }

  fs::path dir_;
  std::unique_ptr<Redis> redis_;
  std::unique_ptr<Store> store_;
};

TEST_P(StoreContract, KeepsRecordsTheirOrderTheirBlobsAndTheirJobs) {
  Store& store = *store_;
  const CharacterRecord c = Character('c', 'f');
  // Its own animations in file order, then a motion file's, whatever the ids' order.
  const std::vector<MotionRecord> own = {Motion('9', c.id, "walk", "character", 5),
                                         Motion('1', c.id, "run", "character", 5)};
  ASSERT_TRUE(*store.InsertCharacter(c, own));
  EXPECT_FALSE(*store.InsertCharacter(c, own));
  ASSERT_TRUE(store.InsertMotions({Motion('5', c.id, "clip", "file", 4)}).ok());
  const CharacterRecord read = **store.GetCharacter(c.id);
  EXPECT_EQ(read.files[0].blob, c.files[0].blob);
  EXPECT_EQ(read.joint_names, c.joint_names);
  EXPECT_EQ(read.warnings, c.warnings);
  EXPECT_EQ(read.vertices, 10);
  const std::vector<MotionRecord> motions = *store.ListMotions(c.id);
  std::vector<std::string> order;
  for (const MotionRecord& m : motions) order.push_back(m.animation);
  EXPECT_EQ(order, (std::vector<std::string>{"walk", "run", "clip"}));
  const MotionRecord motion = **store.GetMotion(std::string(64, '9'));
  EXPECT_EQ(motion.duration_seconds, 1.0 / 3);  // numbers round-trip exactly
  EXPECT_EQ(motion.source_fps, 29.97);
  EXPECT_EQ(store.ListCharacters()->size(), 1u);
  EXPECT_TRUE(*store.IsBlobReferenced(std::string(64, 'e')));

  BakeRecord bake;
  bake.id = std::string(64, 'b');
  bake.character_id = c.id;
  bake.motion_id = own[0].id;
  bake.clip_motions = {own[0].id, own[1].id};
  bake.request_json = R"({"levels":[4]})";
  bake.created_ms = 7;
  JobRecord job;
  job.id = bake.id;
  job.bake_id = bake.id;
  job.state = "queued";
  job.created_ms = 7;
  ASSERT_TRUE(*store.InsertBakeAndJob(bake, job));
  EXPECT_FALSE(*store.InsertBakeAndJob(bake, job));
  EXPECT_EQ((**store.GetBake(bake.id)).clip_motions, bake.clip_motions);
  EXPECT_EQ(store.CountJobsByState()->at("queued"), 1);
  job.state = "running";
  job.attempts = 1;
  ASSERT_TRUE(*store.UpdateJob(job));
  const uint64_t running_version = job.version;
  EXPECT_EQ(store.CountJobsByState()->at("queued"), 0);
  EXPECT_EQ(store.CountJobsByState()->at("running"), 1);

  const std::string level = std::string(64, 'a'), level_set = std::string(64, 'd');
  EXPECT_FALSE(store.LevelBytes(level)->has_value());
  bake.level_set = level_set;
  bake.level_set_bytes = 300;
  bake.report_json = R"({"levels":1})";
  bake.frames = 31;
  bake.fps = 30;
  job.state = "succeeded";
  job.progress = 1;
  ASSERT_TRUE(store.CompleteBake(bake, {{0, 4, level, 120}}, job).ok());
  if (store.shared()) {
    EXPECT_GT(job.version, running_version);  // every daemon sees news
  }
  EXPECT_EQ(**store.LevelBytes(level), 120);
  const std::vector<LevelRecord> levels = *store.GetLevels(bake.id);
  ASSERT_EQ(levels.size(), 1u);
  EXPECT_EQ(levels[0].joints, 4);
  EXPECT_EQ((**store.GetBake(bake.id)).report_json, bake.report_json);
  const std::vector<BakeRecord> listed = *store.ListBakes("");
  ASSERT_EQ(listed.size(), 1u);
  EXPECT_TRUE(listed[0].report_json.empty());  // lists stay small
  EXPECT_EQ(store.ListBakes(c.id)->size(), 1u);
  const JobRecord done = **store.GetJob(bake.id);
  EXPECT_EQ(done.state, "succeeded");
  EXPECT_EQ(done.attempts, 1);
  std::vector<std::string> referenced = *store.ReferencedBlobs();
  std::sort(referenced.begin(), referenced.end());
  EXPECT_EQ(referenced, (std::vector<std::string>{level, level_set, std::string(64, 'e'),
                                                  std::string(64, 'f')}));

  // Deleting the bake names its blobs and leaves the character's.
  EXPECT_EQ(*store.DeleteBake(bake.id), (std::vector<std::string>{level, level_set}));
  EXPECT_EQ(store.DeleteBake(bake.id).status().code(), StatusCode::kNotFound);
  EXPECT_FALSE(*store.IsBlobReferenced(level));
  EXPECT_FALSE(store.LevelBytes(level)->has_value());
  EXPECT_FALSE(store.GetJob(bake.id)->has_value());
  EXPECT_EQ(store.CountJobsByState()->at("succeeded"), 0);
  JobRecord gone = done;
  EXPECT_FALSE(*store.UpdateJob(gone));
  EXPECT_EQ(store.CompleteBake(bake, {}, gone).code(), StatusCode::kNotFound);

  ASSERT_TRUE(*store.InsertBakeAndJob(bake, job));
  EXPECT_EQ(*store.DeleteCharacter(c.id),
            (std::vector<std::string>{std::string(64, 'e'), std::string(64, 'f')}));
  EXPECT_EQ(store.DeleteCharacter(c.id).status().code(), StatusCode::kNotFound);
  EXPECT_FALSE(store.GetMotion(std::string(64, '5'))->has_value());
  EXPECT_FALSE(store.GetBake(bake.id)->has_value());
  EXPECT_TRUE(store.ReferencedBlobs()->empty());
  EXPECT_TRUE(store.ListCharacters()->empty());
  EXPECT_TRUE(store.Healthy());
}

INSTANTIATE_TEST_SUITE_P(BothStores, StoreContract, ::testing::Values("sqlite", "redis"));

TEST(RedisBlobs, AreCheckedAgainstTheirHashCappedInSizeAndUnavailableWithoutRedis) {
  if (!Redis::Installed()) GTEST_SKIP() << "redis-server is not installed";
  Redis redis(TestDirectory());
  ASSERT_TRUE(redis.Start()) << redis.error;
  auto pool = Pool(redis);
  RedisBlobStore blobs(pool, "test:", 8);
  auto hash = blobs.Put("hello");
  ASSERT_TRUE(hash.ok());
  EXPECT_EQ(*blobs.Get(*hash), "hello");
  EXPECT_TRUE(blobs.Contains(*hash));
  EXPECT_EQ(blobs.List(), std::vector<std::string>{*hash});
  EXPECT_EQ(blobs.Put("more than 8 bytes").status().code(), StatusCode::kInvalidArgument);
  ASSERT_TRUE(pool->Command({"SET", "test:blob:" + *hash, "hellO"}).ok());
  EXPECT_EQ(blobs.Get(*hash).status().code(), StatusCode::kDataLoss);
  EXPECT_EQ(blobs.Get(std::string(64, 'a')).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(blobs.Get("../x").status().code(), StatusCode::kInvalidArgument);
  ASSERT_TRUE(blobs.Remove(*hash).ok());
  EXPECT_FALSE(blobs.Contains(*hash));
  redis.Kill();
  EXPECT_EQ(blobs.Put("hello").status().code(), StatusCode::kUnavailable);
  EXPECT_EQ(blobs.CheckWritable(0).code(), StatusCode::kUnavailable);
  ASSERT_TRUE(redis.Start()) << redis.error;  // the pool connects again by itself
  EXPECT_TRUE(blobs.Put("hello").ok());
}

TEST(RedisUrl, ParsesHostsPortsDatabasesSocketsAndRefusesTheRest) {
  const RedisEndpoint full = *ParseRedisUrl("redis://:secret@cache.local:6380/2");
  EXPECT_EQ(full.host, "cache.local");
  EXPECT_EQ(full.port, 6380);
  EXPECT_EQ(full.password, "secret");
  EXPECT_EQ(full.db, 2);
  EXPECT_EQ(ParseRedisUrl("redis://redis")->port, 6379);
  const RedisEndpoint socket = *ParseRedisUrl("unix:///run/redis.sock?db=1");
  EXPECT_EQ(socket.socket_path, "/run/redis.sock");
  EXPECT_EQ(socket.db, 1);
  for (const char* bad :
       {"http://x", "redis://", "redis://h:0", "redis://h:99999", "redis://h/x", "unix://relative"})
    EXPECT_EQ(ParseRedisUrl(bad).status().code(), StatusCode::kInvalidArgument) << bad;
}

// A password and a database from the URL are sent when connecting; a wrong or missing
// password is refused with Redis's words.
TEST(RedisUrl, PasswordsAndDatabasesFromTheUrlAreUsed) {
  if (!Redis::Installed()) GTEST_SKIP() << "redis-server is not installed";
  Redis redis(TestDirectory(), "s3cret-pass");
  ASSERT_TRUE(redis.Start()) << redis.error;
  const std::string address = "127.0.0.1:" + std::to_string(redis.port());
  RedisPool db3(*ParseRedisUrl("redis://:s3cret-pass@" + address + "/3"), 2.0);
  ASSERT_TRUE(db3.Command({"SET", "where", "db3"}).ok());
  RedisPool db0(*ParseRedisUrl(redis.url()), 2.0);
  EXPECT_TRUE(db0.Command({"GET", "where"})->nil());
  EXPECT_EQ(db3.Command({"GET", "where"})->text, "db3");
  RedisPool wrong(*ParseRedisUrl("redis://:wrong@" + address), 2.0);
  const Status refused = wrong.Command({"PING"}).status();
  EXPECT_EQ(refused.code(), StatusCode::kInternal);
  EXPECT_NE(refused.message().find("WRONGPASS"), std::string::npos) << refused.message();
  EXPECT_FALSE(wrong.Command({"PING"}).ok());  // the connection was not kept
  RedisPool none(*ParseRedisUrl("redis://" + address), 2.0);
  EXPECT_NE(none.Command({"PING"}).status().message().find("NOAUTH"), std::string::npos);
}

// The queue on a stream where a consumer died holding a job: that job is taken over after
// the visibility timeout; ids are queued once and up to the capacity; an interrupted job
// is queued again at the end; nothing is left pending.
TEST(RedisQueue, TakesOverADeadConsumersJobDeduplicatesBoundsAndRequeuesInterruptedJobs) {
  if (!Redis::Installed()) GTEST_SKIP() << "redis-server is not installed";
  Redis redis(TestDirectory());
  ASSERT_TRUE(redis.Start()) << redis.error;
  auto pool = Pool(redis);
  const std::string stream = "q:jobs:stream";
  ASSERT_TRUE(pool->Command({"XGROUP", "CREATE", stream, "motionlodd", "0", "MKSTREAM"}).ok());
  ASSERT_TRUE(pool->Command({"XADD", stream, "*", "job", "dead"}).ok());
  ASSERT_TRUE(pool->Command({"XREADGROUP", "GROUP", "motionlodd", "gone:1:x", "COUNT", "1",
                             "STREAMS", stream, ">"})
                  .ok());
  std::mutex mutex;
  std::condition_variable changed;
  std::vector<std::string> ran;
  std::atomic<bool> hold_a{true};
  bool interrupted_b = false;
  const auto started = std::chrono::steady_clock::now();
  std::chrono::steady_clock::duration dead_taken{};
  auto queue = RedisJobQueue::Open(pool, "q:", 2, 1, 1.0, [&](const std::string& id) {
    {
      std::lock_guard lock(mutex);
      ran.push_back(id);
      if (id == "dead") dead_taken = std::chrono::steady_clock::now() - started;
    }
    changed.notify_all();
    while (id == "a" && hold_a.load()) std::this_thread::sleep_for(std::chrono::milliseconds(5));
    if (id == "b" && !interrupted_b) {
      interrupted_b = true;
      return JobQueue::RunOutcome::kInterrupted;
    }
    return JobQueue::RunOutcome::kFinished;
  });
  ASSERT_TRUE(queue.ok()) << queue.status().message();
  const auto wait_for = [&](size_t runs) {
    std::unique_lock lock(mutex);
    return changed.wait_for(lock, std::chrono::seconds(10), [&] { return ran.size() >= runs; });
  };
  ASSERT_TRUE(wait_for(1));
  EXPECT_GE(dead_taken, std::chrono::milliseconds(900));  // not before the timeout
  EXPECT_EQ((*queue)->Push("a"), JobQueue::PushResult::kQueued);
  ASSERT_TRUE(wait_for(2));
  EXPECT_EQ((*queue)->running(), 1u);
  EXPECT_EQ((*queue)->Push("b"), JobQueue::PushResult::kQueued);
  EXPECT_EQ((*queue)->Push("b"), JobQueue::PushResult::kAlreadyQueued);
  EXPECT_EQ((*queue)->Push("c"), JobQueue::PushResult::kQueued);
  EXPECT_EQ((*queue)->Push("d"), JobQueue::PushResult::kFull);
  EXPECT_EQ((*queue)->Push("d", /*force=*/true), JobQueue::PushResult::kQueued);
  EXPECT_EQ((*queue)->depth(), 3u);
  EXPECT_TRUE((*queue)->Remove("d"));  // its entry, when taken, names a job that is gone
  hold_a = false;
  ASSERT_TRUE(wait_for(6));
  {
    std::lock_guard lock(mutex);
    EXPECT_EQ(ran, (std::vector<std::string>{"dead", "a", "b", "c", "d", "b"}));
  }
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (((*queue)->running() > 0 || pool->Command({"XLEN", stream})->integer > 0) &&
         std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  EXPECT_EQ(pool->Command({"XLEN", stream})->integer, 0);
  EXPECT_EQ(pool->Command({"XPENDING", stream, "motionlodd"})->elements[0].integer, 0);
  EXPECT_EQ((*queue)->depth(), 0u);
  (*queue)->Stop();
  EXPECT_EQ((*queue)->Push("e"), JobQueue::PushResult::kStopped);
}

}  // namespace
}  // namespace motionlod::server::testing
