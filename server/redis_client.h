// Connections to Redis (hiredis) for the Redis backend (server/redis_store.h,
// server/redis_job_queue.h): a URL, one connection that reconnects by itself, and a small
// pool of them for threads that share one. A Redis that does not answer is kUnavailable
// (retry later), so that requests get 503 while it restarts and work again after.
#pragma once

#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <vector>

#include "base/status.h"

struct redisContext;

namespace motionlod::server {

// redis://[:password@]host[:port][/db] or unix:///path/to/socket[?db=N].
struct RedisEndpoint {
  std::string host;
  int port = 6379;
  std::string socket_path;  // set for unix://
  std::string password;
  int db = 0;
};
StatusOr<RedisEndpoint> ParseRedisUrl(std::string_view url);

// A reply, copied out of hiredis's.
struct RedisReply {
  enum class Type { kNil, kString, kInteger, kArray, kStatus };
  Type type = Type::kNil;
  std::string text;  // kString, kStatus
  int64_t integer = 0;
  std::vector<RedisReply> elements;
  bool nil() const { return type == Type::kNil; }
};

class RedisConnection {
 public:
  // Commands wait at most `timeout_seconds` for their reply (beyond a BLOCK they ask for).
  RedisConnection(RedisEndpoint endpoint, double timeout_seconds);
  ~RedisConnection();
  RedisConnection(const RedisConnection&) = delete;
  RedisConnection& operator=(const RedisConnection&) = delete;

  // One command. kUnavailable when Redis cannot be reached (the connection is made again
  // at the next command), kInternal for an error reply (a bug of ours or a misconfigured
  // server), with the reply's text.
  StatusOr<RedisReply> Command(const std::vector<std::string_view>& args);

 private:
  Status Connect();
  void Drop();

  const RedisEndpoint endpoint_;
  const double timeout_seconds_;
  redisContext* context_ = nullptr;
};

// Connections shared by threads: each command takes an idle one (or opens one), runs,
// and gives it back. Thread-safe.
class RedisPool {
 public:
  RedisPool(RedisEndpoint endpoint, double timeout_seconds)
      : endpoint_(std::move(endpoint)), timeout_seconds_(timeout_seconds) {}

  StatusOr<RedisReply> Command(const std::vector<std::string_view>& args);
  // EVAL of `script` with no keys and `args` as ARGV.
  StatusOr<RedisReply> Eval(std::string_view script, const std::vector<std::string_view>& args);

  const RedisEndpoint& endpoint() const { return endpoint_; }
  double timeout_seconds() const { return timeout_seconds_; }

 private:
  const RedisEndpoint endpoint_;
  const double timeout_seconds_;
  std::mutex mutex_;
  std::vector<std::unique_ptr<RedisConnection>> idle_;
};

}  // namespace motionlod::server
