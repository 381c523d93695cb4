// Errors of the thin client, as values: every call returns Result<T>, a T or the Error
// that explains why there is none (no exception leaves the library). An error the daemon
// answered carries its RFC 9457 problem detail (proto::api::Problem) verbatim.
#pragma once

#include <optional>
#include <string>

#include "base/expected.h"
#include "proto/api.h"

namespace motionlod::client {

enum class ErrorKind {
  kConnection,       // no answer: refused, reset, timed out (after the retries)
  kHttp,             // the daemon answered 4xx or 5xx: http_status and problem
  kInvalidArgument,  // the caller's input, checked before anything was sent
  kDataLoss,         // a reply or a cached file that is not what it claims to be
  kIo,               // the local disk (the level cache, a file to upload)
  kJobFailed,        // the bake ran and failed: problem.detail is its message
};

const char* ErrorKindName(ErrorKind kind);

struct Error {
  ErrorKind kind = ErrorKind::kConnection;
  int http_status = 0;  // kHttp only
  // kHttp: the problem+json body (a synthesized one when the body was not problem+json);
  // kJobFailed: type urn:motionlod:problem:<job error code>, detail the bake's message.
  std::optional<proto::api::Problem> problem;
  std::string message;  // one line, for people: includes the problem's detail

  // 4xx: the request itself is wrong and repeating it will not help.
  bool client_error() const { return kind == ErrorKind::kHttp && http_status >= 400 && http_status < 500; }
  std::string ToString() const;  // "<kind>: <message>"
};

// A value or the Error that explains why there is none.
template <typename T>
using Result = Expected<T, Error>;

}  // namespace motionlod::client
