#include "server/redis_client.h"

#include <hiredis.h>

#include <charconv>
#include <cmath>
#include <optional>

namespace motionlod::server {
namespace {

// The most idle connections a pool keeps (more are closed when given back).
constexpr size_t kPoolIdle = 16;

timeval ToTimeval(double seconds) {
  timeval tv{};
  tv.tv_sec = static_cast<time_t>(seconds);
  tv.tv_usec = static_cast<suseconds_t>((seconds - std::floor(seconds)) * 1e6);
  return tv;
}

RedisReply Copy(const redisReply& reply) {
  RedisReply out;
  switch (reply.type) {
    case REDIS_REPLY_STRING:
      out.type = RedisReply::Type::kString;
      out.text.assign(reply.str, reply.len);
      break;
    case REDIS_REPLY_STATUS:
      out.type = RedisReply::Type::kStatus;
      out.text.assign(reply.str, reply.len);
      break;
    case REDIS_REPLY_INTEGER:
      out.type = RedisReply::Type::kInteger;
      out.integer = reply.integer;
      break;
    case REDIS_REPLY_ARRAY:
      out.type = RedisReply::Type::kArray;
      for (size_t i = 0; i < reply.elements; ++i) out.elements.push_back(Copy(*reply.element[i]));
      break;
    default:
      break;  // nil
  }
  return out;
}

std::optional<int> ParseInt(std::string_view text) {
  int value = 0;
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (error != std::errc() || end != text.data() + text.size()) return std::nullopt;
  return value;
}

}  // namespace

StatusOr<RedisEndpoint> ParseRedisUrl(std::string_view url) {
  RedisEndpoint endpoint;
  const auto bad = [&](const std::string& why) {
    return InvalidArgument("redis_url '" + std::string(url) + "': " + why +
                           " (redis://[:password@]host[:port][/db] or unix:///path[?db=N])");
  };
  if (url.rfind("unix://", 0) == 0) {
    std::string_view rest = url.substr(7);
    if (const size_t query = rest.find("?db="); query != std::string_view::npos) {
      const auto db = ParseInt(rest.substr(query + 4));
      if (!db || *db < 0) return bad("db must be a number");
      endpoint.db = *db;
      rest = rest.substr(0, query);
    }
    if (rest.empty() || rest[0] != '/') return bad("the socket path must be absolute");
    endpoint.socket_path = std::string(rest);
    return endpoint;
  }
  if (url.rfind("redis://", 0) != 0) return bad("unknown scheme");
  std::string_view rest = url.substr(8);
  if (const size_t at = rest.rfind('@'); at != std::string_view::npos) {
    std::string_view credentials = rest.substr(0, at);
    if (const size_t colon = credentials.find(':'); colon != std::string_view::npos)
      credentials = credentials.substr(colon + 1);
    endpoint.password = std::string(credentials);
    rest = rest.substr(at + 1);
  }
  if (const size_t slash = rest.find('/'); slash != std::string_view::npos) {
    const std::string_view db_text = rest.substr(slash + 1);
    if (!db_text.empty()) {
      const auto db = ParseInt(db_text);
      if (!db || *db < 0) return bad("db must be a number");
      endpoint.db = *db;
    }
    rest = rest.substr(0, slash);
  }
  if (const size_t colon = rest.rfind(':'); colon != std::string_view::npos) {
    const auto port = ParseInt(rest.substr(colon + 1));
    if (!port || *port < 1 || *port > 65535) return bad("the port must be 1 to 65535");
    endpoint.port = *port;
    rest = rest.substr(0, colon);
  }
  if (rest.empty()) return bad("no host");
  endpoint.host = std::string(rest);
  return endpoint;
}

RedisConnection::RedisConnection(RedisEndpoint endpoint, double timeout_seconds)
    : endpoint_(std::move(endpoint)), timeout_seconds_(timeout_seconds) {}

RedisConnection::~RedisConnection() { Drop(); }

void RedisConnection::Drop() {
  if (context_ != nullptr) redisFree(context_);
  context_ = nullptr;
}

Status RedisConnection::Connect() {
  const timeval timeout = ToTimeval(timeout_seconds_);
  context_ = endpoint_.socket_path.empty()
                 ? redisConnectWithTimeout(endpoint_.host.c_str(), endpoint_.port, timeout)
                 : redisConnectUnixWithTimeout(endpoint_.socket_path.c_str(), timeout);
  if (context_ == nullptr || context_->err != 0) {
    const std::string why = context_ == nullptr ? "out of memory" : context_->errstr;
    Drop();
    return Status(StatusCode::kUnavailable, "redis: cannot connect: " + why);
  }
  redisSetTimeout(context_, timeout);
  redisEnableKeepAlive(context_);
  // A connection that failed its AUTH or SELECT is not kept (the next command tries again).
  const auto setup = [&](const std::vector<std::string_view>& args) -> Status {
    auto reply = Command(args);
    if (reply.ok()) return Status::Ok();
    Drop();
    return reply.status();
  };
  if (!endpoint_.password.empty()) {
    if (Status status = setup({"AUTH", endpoint_.password}); !status.ok()) return status;
  }
  if (endpoint_.db != 0) {
    const std::string db = std::to_string(endpoint_.db);
    if (Status status = setup({"SELECT", db}); !status.ok()) return status;
  }
  return Status::Ok();
}

StatusOr<RedisReply> RedisConnection::Command(const std::vector<std::string_view>& args) {
  if (context_ == nullptr) {
    if (Status status = Connect(); !status.ok()) return status;
  }
  std::vector<const char*> argv;
  std::vector<size_t> lengths;
  for (std::string_view arg : args) {
    argv.push_back(arg.data());
    lengths.push_back(arg.size());
  }
  auto* reply = static_cast<redisReply*>(
      redisCommandArgv(context_, static_cast<int>(argv.size()), argv.data(), lengths.data()));
  if (reply == nullptr) {
    const std::string why = context_->errstr;
    Drop();
    return Status(StatusCode::kUnavailable, "redis: " + why);
  }
  Status error = Status::Ok();
  if (reply->type == REDIS_REPLY_ERROR) {
    const std::string text(reply->str, reply->len);
    // A Redis loading its append-only file, or a replica cut off, answers for a while.
    const bool passing = text.rfind("LOADING", 0) == 0 || text.rfind("MASTERDOWN", 0) == 0 ||
                         text.rfind("MISCONF", 0) == 0;
    error = Status(passing ? StatusCode::kUnavailable : StatusCode::kInternal, "redis: " + text);
  }
  RedisReply copy = error.ok() ? Copy(*reply) : RedisReply{};
  freeReplyObject(reply);
  if (!error.ok()) return error;
  return copy;
}

StatusOr<RedisReply> RedisPool::Command(const std::vector<std::string_view>& args) {
  std::unique_ptr<RedisConnection> connection;
  {
    std::lock_guard lock(mutex_);
    if (!idle_.empty()) {
      connection = std::move(idle_.back());
      idle_.pop_back();
    }
  }
  if (!connection) connection = std::make_unique<RedisConnection>(endpoint_, timeout_seconds_);
  auto reply = connection->Command(args);
  std::lock_guard lock(mutex_);
  if (idle_.size() < kPoolIdle) idle_.push_back(std::move(connection));
  return reply;
}

StatusOr<RedisReply> RedisPool::Eval(std::string_view script,
                                     const std::vector<std::string_view>& args) {
  std::vector<std::string_view> command = {"EVAL", script, "0"};
  command.insert(command.end(), args.begin(), args.end());
  return Command(command);
}

}  // namespace motionlod::server
