// The /v1 API: each route parses its DTO (path, query, headers, body), calls the
// Service, and serialises the reply; service errors become problem+json here. The
// routes and their shapes are those of proto/openapi.yaml (served at /v1/openapi.yaml).
#pragma once

#include <atomic>
#include <functional>
#include <string>
#include <string_view>

#include "server/config.h"
#include "server/http.h"
#include "server/service.h"
#include "server/web_assets.h"

namespace motionlod::server {

struct RouteContext {
  Service* service = nullptr;
  const Config* config = nullptr;
  // Appends the HTTP request metrics (owned by the HTTP server).
  std::function<void(std::string&)> render_http_metrics;
  // SSE streams and long-polls open now (bounded by config->max_streams).
  std::atomic<int>* open_streams = nullptr;
  // Upload bodies being received now (bounded by config->max_concurrent_uploads).
  std::atomic<int>* open_uploads = nullptr;
  // The web viewer's files, served at "/"; nullptr: "/" says how to build them.
  const WebAssets* web = nullptr;
};

http::Router MakeRouter(const RouteContext& context);

// proto/openapi.yaml, embedded at build time.
std::string_view OpenApiYaml();

// The HTTP status for a service error kind.
int HttpStatus(ErrorKind kind);

}  // namespace motionlod::server
