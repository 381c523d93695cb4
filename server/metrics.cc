#include "server/metrics.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace motionlod::server {
namespace {

std::string FormatDouble(double value) {
  if (std::isinf(value)) return value > 0 ? "+Inf" : "-Inf";
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.9g", value);
  return buffer;
}

std::string Join(const std::string& labels, const std::string& extra) {
  if (labels.empty()) return extra;
  if (extra.empty()) return labels;
  return labels + "," + extra;
}

}  // namespace

std::vector<double> LatencyBounds() {
  return {0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1, 2.5, 5, 10};
}

std::vector<double> BakeBounds() {
  return {0.01, 0.05, 0.1, 0.25, 0.5, 1, 2.5, 5, 10, 30, 60, 300, 900, 3600};
}

std::string EscapeLabel(const std::string& value) {
  std::string out;
  for (char c : value) {
    if (c == '\\' || c == '"') {
      out += '\\';
      out += c;
    } else if (c == '\n') {
      out += "\\n";
    } else {
      out += c;
    }
  }
  return out;
}

Histogram::Histogram(std::vector<double> bounds)
    : bounds_(std::move(bounds)), buckets_(new std::atomic<uint64_t>[bounds_.size() + 1]) {
  for (size_t b = 0; b <= bounds_.size(); ++b) buckets_[b].store(0, std::memory_order_relaxed);
}

void Histogram::Observe(double seconds) {
  const size_t bucket = static_cast<size_t>(
      std::lower_bound(bounds_.begin(), bounds_.end(), seconds) - bounds_.begin());
  buckets_[bucket].fetch_add(1, std::memory_order_relaxed);
  count_.fetch_add(1, std::memory_order_relaxed);
  sum_nanos_.fetch_add(static_cast<uint64_t>(std::max(0.0, seconds) * 1e9),
                       std::memory_order_relaxed);
}

void Histogram::Render(std::string& out, const std::string& name, const std::string& labels) const {
  uint64_t cumulative = 0;
  for (size_t b = 0; b <= bounds_.size(); ++b) {
    cumulative += buckets_[b].load(std::memory_order_relaxed);
    const std::string le = b < bounds_.size() ? FormatDouble(bounds_[b]) : "+Inf";
    out += name + "_bucket{" + Join(labels, "le=\"" + le + "\"") + "} " +
           std::to_string(cumulative) + "\n";
  }
  const std::string braces = labels.empty() ? "" : "{" + labels + "}";
  out += name + "_sum" + braces + " " +
         FormatDouble(static_cast<double>(sum_nanos_.load(std::memory_order_relaxed)) * 1e-9) +
         "\n";
  out += name + "_count" + braces + " " + std::to_string(count_.load(std::memory_order_relaxed)) +
         "\n";
}

HttpMetrics::PerRoute::PerRoute() : latency(LatencyBounds()) {
  for (auto& counter : by_code) counter.store(0, std::memory_order_relaxed);
}

HttpMetrics::HttpMetrics(std::vector<RouteLabel> routes) : routes_(std::move(routes)) {
  routes_.push_back({"", "unmatched"});
  for (size_t r = 0; r < routes_.size(); ++r) per_route_.push_back(std::make_unique<PerRoute>());
}

void HttpMetrics::Record(int route, int status, double seconds) {
  if (route < 0 || route >= static_cast<int>(per_route_.size())) route = unmatched();
  PerRoute& r = *per_route_[route];
  if (status >= 100 && status < 100 + kCodes)
    r.by_code[status - 100].fetch_add(1, std::memory_order_relaxed);
  r.latency.Observe(seconds);
}

void HttpMetrics::Render(std::string& out) const {
  out += "# HELP motionlodd_http_requests_total HTTP requests by route, method and status code.\n";
  out += "# TYPE motionlodd_http_requests_total counter\n";
  for (size_t r = 0; r < routes_.size(); ++r) {
    for (int c = 0; c < kCodes; ++c) {
      const uint64_t count = per_route_[r]->by_code[c].load(std::memory_order_relaxed);
      if (count == 0) continue;
      out += "motionlodd_http_requests_total{route=\"" + EscapeLabel(routes_[r].route) +
             "\",method=\"" + EscapeLabel(routes_[r].method) + "\",code=\"" +
             std::to_string(c + 100) + "\"} " + std::to_string(count) + "\n";
    }
  }
  out +=
      "# HELP motionlodd_http_request_duration_seconds Time from the parsed request to the last "
      "byte written.\n";
  out += "# TYPE motionlodd_http_request_duration_seconds histogram\n";
  for (size_t r = 0; r < routes_.size(); ++r) {
    if (per_route_[r]->latency.count() == 0) continue;
    per_route_[r]->latency.Render(out, "motionlodd_http_request_duration_seconds",
                                  "route=\"" + EscapeLabel(routes_[r].route) + "\",method=\"" +
                                      EscapeLabel(routes_[r].method) + "\"");
  }
  out += "# HELP motionlodd_http_connections Open connections: idle, sending headers or served.\n";
  out += "# TYPE motionlodd_http_connections gauge\n";
  out += "motionlodd_http_connections " +
         std::to_string(connections.open.load(std::memory_order_relaxed)) + "\n";
  out += "# HELP motionlodd_http_connections_refused_total Connections closed unserved, by "
         "reason.\n";
  out += "# TYPE motionlodd_http_connections_refused_total counter\n";
  static constexpr const char* kReasons[kConnectionRefusals] = {
      "header_timeout", "header_too_large", "too_many_connections"};
  for (int reason = 0; reason < kConnectionRefusals; ++reason) {
    out += std::string("motionlodd_http_connections_refused_total{reason=\"") + kReasons[reason] +
           "\"} " + std::to_string(connections.refused[reason].load(std::memory_order_relaxed)) +
           "\n";
  }
}

}  // namespace motionlod::server
