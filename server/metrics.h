// Prometheus metrics, lock-free on the request path: counters and histograms are arrays
// of atomics indexed by route and status code, so recording a request is a few relaxed
// increments. Rendered in the text exposition format (version 0.0.4).
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace motionlod::server {

// Cumulative histogram with fixed upper bounds (seconds).
class Histogram {
 public:
  explicit Histogram(std::vector<double> bounds);
  void Observe(double seconds);
  // Appends the _bucket, _sum and _count lines; `labels` is "" or `key="value",...`.
  void Render(std::string& out, const std::string& name, const std::string& labels) const;
  uint64_t count() const { return count_.load(std::memory_order_relaxed); }

 private:
  std::vector<double> bounds_;
  std::unique_ptr<std::atomic<uint64_t>[]> buckets_;  // bounds_.size() + 1 (the last: +Inf)
  std::atomic<uint64_t> count_{0};
  std::atomic<uint64_t> sum_nanos_{0};
};

// Why the HTTP layer closed a connection without serving it (server/connection_gate.h).
enum class ConnectionRefusal { kHeaderTimeout, kHeaderTooLarge, kTooManyConnections };
inline constexpr int kConnectionRefusals = 3;

// Open connections and refusals, kept by the connection gate.
struct ConnectionCounters {
  std::atomic<int64_t> open{0};
  std::array<std::atomic<uint64_t>, kConnectionRefusals> refused{};
};

// Request counts by (route, method, code) and latency by (route, method), and the
// connection counters.
class HttpMetrics {
 public:
  struct RouteLabel {
    std::string method;
    std::string route;  // the route template, "/v1/levels/{hash}"
  };
  // Route indexes are those of `routes`; index routes.size() is "unmatched".
  explicit HttpMetrics(std::vector<RouteLabel> routes);
  void Record(int route, int status, double seconds);
  void Render(std::string& out) const;
  int unmatched() const { return static_cast<int>(routes_.size()) - 1; }
  ConnectionCounters connections;

 private:
  static constexpr int kCodes = 500;  // status 100..599
  struct PerRoute {
    std::array<std::atomic<uint64_t>, kCodes> by_code{};
    Histogram latency;
    PerRoute();
  };
  std::vector<RouteLabel> routes_;
  std::vector<std::unique_ptr<PerRoute>> per_route_;
};

// The bounds used for request latencies (0.5 ms .. 10 s) and bake durations (10 ms .. 1 h).
std::vector<double> LatencyBounds();
std::vector<double> BakeBounds();

// Escapes a label value (backslash, quote, newline).
std::string EscapeLabel(const std::string& value);

}  // namespace motionlod::server
