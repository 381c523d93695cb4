// motionlodd's settings: defaults, then config/motionlodd.toml (or --config FILE), then
// MOTIONLODD_* environment variables, then command-line flags, each overriding the one
// before. Every option is documented in config/motionlodd.toml and docs/SERVER.md.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "base/status.h"
#include "core/simd.h"

namespace motionlod::server {

struct Config {
  // Network.
  std::string bind = "127.0.0.1";
  int port = 8080;  // 0: any free port (logged, and printed as "listening on http://HOST:PORT")
  int http_threads = 64;  // connection threads: requests served at once (server/connection_gate.h)
  int max_connections = 4096;  // open connections, idle or not (503 and closed beyond)
  // The built web viewer (web/dist, made by scripts/setup.sh), served at "/"; relative to
  // the working directory. Empty, or a directory without index.html: "/" says how to
  // build it, and the API is unaffected.
  std::string web_root = "web/dist";

  // Storage.
  std::string data_dir = "motionlodd-data";
  int64_t min_free_bytes = int64_t{64} << 20;  // free space below which /readyz says not ready
  // "embedded": SQLite in data_dir and a queue in memory (one daemon). "redis": metadata
  // and the job queue in Redis, shared by every daemon on it (server/redis_store.h).
  std::string backend = "embedded";
  std::string redis_url = "redis://127.0.0.1:6379";
  std::string redis_prefix = "motionlod:";  // every key's prefix (several deployments, one Redis)
  // Where blobs live: "directory" (blob_dir; shared by the daemons of a redis backend) or
  // "redis" (in Redis, each at most redis_max_blob_bytes).
  std::string blob_store = "directory";
  std::string blob_dir;  // "": <data_dir>/blobs
  int64_t redis_max_blob_bytes = int64_t{64} << 20;
  double redis_timeout_seconds = 5;  // connect and reply
  // A job whose daemon stopped answering for this long is run by another (redis backend).
  double job_visibility_seconds = 60;

  // Jobs.
  int threads = 0;            // bake workers draining the queue; 0: one per hardware thread
  int bake_threads = 1;       // threads inside one bake; 0: one per hardware thread
  int queue_capacity = 64;    // queued jobs beyond which POST /v1/bakes answers 503
  double drain_seconds = 10;  // on SIGTERM, how long running bakes may finish before
                              // they are stopped and left queued for the next start
  int max_job_crashes = 3;    // a bake running when the daemon dies on its this-many-th run
                              // is failed ('crashed') at the next start, not run again
  // The machine version of the bakes' hot loops (core/simd.h), from MOTIONLOD_SIMD.
  core::SimdChoice simd = core::SimdChoice::kWidest;

  // Memory.
  int64_t cache_bytes = int64_t{256} << 20;  // LRU cache of level files

  // Limits.
  int64_t max_upload_bytes = int64_t{64} << 20;  // decoded body of an upload (413 beyond)
  int64_t max_json_bytes = int64_t{64} << 10;    // body of a JSON request
  int64_t max_header_bytes = int64_t{32} << 10;  // request line and headers (431 beyond)
  int max_upload_parts = 32;                     // multipart parts of one upload
  int max_concurrent_uploads = 8;   // upload bodies being received at once (503 beyond):
                                    // bounds their memory to this x max_upload_bytes
  int max_concurrent_imports = 2;   // uploads imported at once (503 beyond)
  // What one character or motion may hold (422 beyond), checked by the import worker
  // before the daemon holds any of it: memory follows these, not what a file declares.
  int max_joints = 1024;
  int64_t max_vertices = 2000000;
  int64_t max_frames = 200000;          // source frames over every clip
  int64_t max_joint_frames = 4000000;   // joints x those frames
  int64_t max_export_bytes = int64_t{64} << 20;  // a level's glTF file, bounded before it is built
  int max_streams = 4;              // open SSE streams and long-polls together (503 beyond)
  double max_wait_seconds = 30;     // cap of ?wait= on GET /v1/jobs/{id}
  double max_stream_seconds = 300;  // an SSE stream ends after this (clients reconnect)

  // Timeouts (seconds).
  double header_timeout_seconds = 10;  // a request's line and headers, from its first byte
  int read_timeout_seconds = 10;   // one read on a connection
  int write_timeout_seconds = 10;  // one write on a connection
  int keep_alive_timeout_seconds = 5;
  int keep_alive_max_requests = 10000;
  int upload_timeout_seconds = 120;  // a whole request body

  // Import worker (server/import_sandbox.h): uploads are parsed in a separate process.
  std::string import_isolation = "auto";  // auto (bwrap, else process), bwrap or process
  std::string import_worker;              // "": motionlod-import-worker next to motionlodd
  int64_t import_memory_bytes = int64_t{4} << 30;   // its address space; 0: unlimited
  double import_cpu_seconds = 120;                  // its CPU time
  double import_timeout_seconds = 180;              // its wall-clock time
  int64_t import_output_bytes = int64_t{512} << 20;  // its reply

  // Keys (bearer tokens). With write_keys set, every write (POST, DELETE) needs one of
  // them; with read_keys set, every read needs one of read_keys or write_keys.
  std::vector<std::string> write_keys;
  std::vector<std::string> read_keys;

  // Logging.
  std::string log_level = "info";  // trace, debug, info, warn, error, critical, off
  bool access_log = true;          // one info line per request

  Status Validate() const;
};

// Applies a TOML document to `config` (only the keys it has). Unknown keys and wrong
// types are kInvalidArgument naming the key.
Status ApplyToml(std::string_view toml_text, std::string_view source_name, Config& config);

// Applies MOTIONLODD_<KEY> variables (upper-case option names: MOTIONLODD_PORT,
// MOTIONLODD_DATA_DIR, MOTIONLODD_WRITE_KEYS as a comma-separated list, ...).
using GetEnv = std::function<const char*(const char*)>;
Status ApplyEnvironment(const GetEnv& getenv, Config& config);

// What the command line asks for beyond the config.
struct Options {
  Config config;
  std::string config_file;  // empty: none
  // --seed FILE: upload this character at start, bake it (--seed-animation NAME, default
  // its first animation) and print the level URL when done; for the README's run command.
  std::vector<std::string> seed_files;
  std::string seed_animation;
  bool exit = false;  // --help or --version was printed
  int exit_code = 0;
};

// Parses flags (see --help), reading the config file they or MOTIONLODD_CONFIG name.
// `out` receives --help and --version text.
StatusOr<Options> ParseCommandLine(int argc, const char* const* argv, const GetEnv& getenv,
                                   std::string* out);

}  // namespace motionlod::server
