// The daemon's service: characters, motions, bakes, jobs and levels, each a part of its
// own (server/characters.h, motions.h, bakes.h, jobs.h, levels.h) over the resources
// they share (server/service_context.h: the store, the blob directory, the importer, the
// caches). It knows nothing of HTTP: the parts take and return proto::api DTOs, and their
// errors are kinds (not found, too large, ...) that the HTTP layer maps to status codes.
//
// Ids (all ^[0-9a-f]{64}$, checked before any lookup):
//   character = SHA-256 of the uploaded bytes (one file), or of the sorted list of
//               "name NUL sha256" lines of its parts (several files);
//   motion    = SHA-256 of (character, source upload id, animation name);
//   bake = job = SHA-256 of the resolved request, the solver settings hash and
//               core::kAlgorithmVersion (BakeKey), so the same request is the same bake;
//   level     = SHA-256 of the one-level file (proto::ExtractLevel).
#pragma once

#include <memory>
#include <string>

#include "base/status.h"
#include "server/bakes.h"
#include "server/characters.h"
#include "server/config.h"
#include "server/jobs.h"
#include "server/levels.h"
#include "server/motions.h"
#include "server/service_context.h"

namespace motionlod::server {

// Owns the shared resources and the parts, and their lifecycle.
class Service {
 public:
  static StatusOr<std::unique_ptr<Service>> Open(const Config& config);
  ~Service();

  // Requeues the jobs a crash or a shutdown left unfinished and starts the workers.
  Status Start();
  // Stops taking jobs, lets running bakes finish for up to drain_seconds, then stops them
  // (they stay queued in the store and run again at the next start).
  void Shutdown();
  // Refuses new bakes and ends long-polls and event streams (before the HTTP server
  // stops, so that its connection threads are free to finish).
  void BeginDrain();
  bool draining() const { return jobs_.draining(); }

  Characters& characters() { return characters_; }
  Motions& motions() { return motions_; }
  Bakes& bakes() { return bakes_; }
  Jobs& jobs() { return jobs_; }
  Levels& levels() { return levels_; }

  // Ok when the daemon takes work: not draining, the queue started, the database
  // answering, the data directory writable with min_free_bytes free. Otherwise why not,
  // in words that name no server path.
  Status Ready();
  // Queue, jobs, bakes and cache metrics in Prometheus text.
  void RenderMetrics(std::string& out);

 private:
  explicit Service(const Config& config);

  // Declared before the parts, which hold references to it and to one another.
  ServiceContext context_;
  Jobs jobs_;
  Levels levels_;
  Bakes bakes_;
  Characters characters_;
  Motions motions_;
};

}  // namespace motionlod::server
