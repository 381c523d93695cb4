// Status: the error value of every motionlod library (no exceptions cross a
// library boundary). Bad *data* returns a Status; broken preconditions assert.
#pragma once

#include <string>
#include <utility>

#include "base/expected.h"

namespace motionlod {

enum class StatusCode {
  kOk = 0,
  kInvalidArgument,     // the caller's data or settings are unusable
  kNotFound,            // a named thing (joint, animation, file) does not exist
  kUnsupported,         // well-formed input that this build cannot handle
  kDataLoss,            // truncated or corrupted bytes
  kCancelled,           // the caller asked the work to stop
  kUnavailable,         // a resource failed for now (a full or unwritable disk): retry later
  kInternal,            // a bug: an invariant of ours did not hold
};

const char* StatusCodeName(StatusCode code);

class [[nodiscard]] Status {
 public:
  Status() = default;
  Status(StatusCode code, std::string message) : code_(code), message_(std::move(message)) {}

  static Status Ok() { return Status(); }
  bool ok() const { return code_ == StatusCode::kOk; }
  StatusCode code() const { return code_; }
  const std::string& message() const { return message_; }
  // "invalid_argument: <message>"
  std::string ToString() const;

 private:
  StatusCode code_ = StatusCode::kOk;
  std::string message_;
};

inline Status InvalidArgument(std::string message) {
  return Status(StatusCode::kInvalidArgument, std::move(message));
}
inline Status NotFound(std::string message) {
  return Status(StatusCode::kNotFound, std::move(message));
}
inline Status DataLoss(std::string message) {
  return Status(StatusCode::kDataLoss, std::move(message));
}
inline Status Unsupported(std::string message) {
  return Status(StatusCode::kUnsupported, std::move(message));
}

// A value or the Status that explains why there is none.
template <typename T>
class [[nodiscard]] StatusOr : public Expected<T, Status> {
 public:
  using Expected<T, Status>::Expected;

  // The error, or an OK status when there is a value (so that it forwards either).
  const Status& status() const {
    static const Status kOkStatus;
    return this->ok() ? kOkStatus : this->error();
  }
};

}  // namespace motionlod
