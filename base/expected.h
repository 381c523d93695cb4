// Expected<T, E>: a value, or the error of type E that explains why there is none. The one
// value-or-error template of motionlod: StatusOr<T> (base/status.h) is an Expected with a
// Status (adding status(), OK when there is a value), the client's Result<T>
// (client/error.h) one with a client::Error and the daemon service's Result<T>
// (server/service_context.h) one with a server::ServiceError.
#pragma once

#include <utility>
#include <variant>

namespace motionlod {

template <typename T, typename E>
class [[nodiscard]] Expected {
 public:
  // Implicit by design, so that a function returns its value or its error as it is.
  Expected(T value) : value_(std::in_place_index<0>, std::move(value)) {}  // NOLINT
  Expected(E error) : value_(std::in_place_index<1>, std::move(error)) {}  // NOLINT

  bool ok() const { return value_.index() == 0; }
  // Only when !ok() (std::bad_variant_access otherwise).
  const E& error() const { return std::get<1>(value_); }
  // Only when ok() (std::bad_variant_access otherwise).
  T& value() & { return std::get<0>(value_); }
  const T& value() const& { return std::get<0>(value_); }
  T&& value() && { return std::get<0>(std::move(value_)); }
  T* operator->() { return &value(); }
  const T* operator->() const { return &value(); }
  T& operator*() & { return value(); }
  const T& operator*() const& { return value(); }
  // `*std::move(e)` moves the value out (without this overload it bound to the const&
  // one and copied it: a level's matrices, errors and skeleton per call).
  T&& operator*() && { return std::move(*this).value(); }

 private:
  std::variant<T, E> value_;
};

}  // namespace motionlod
