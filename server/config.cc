#include "server/config.h"

#include <toml++/toml.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <fstream>
#include <sstream>
#include <variant>

#include "server/redis_client.h"

namespace motionlod::server {
namespace {

// One option: where it lives in the TOML file, its field, and its help line. Flags are
// --name-with-dashes, environment variables MOTIONLODD_NAME.
using Field = std::variant<std::string Config::*, int Config::*, int64_t Config::*,
                           double Config::*, bool Config::*, std::vector<std::string> Config::*>;
struct OptionSpec {
  const char* section;
  const char* name;
  Field field;
  const char* help;
};

const std::vector<OptionSpec>& Specs() {
  static const std::vector<OptionSpec> specs = {
      {"server", "bind", &Config::bind, "address to listen on (0.0.0.0: every interface)"},
      {"server", "port", &Config::port, "TCP port; 0 picks a free one"},
      {"server", "http_threads", &Config::http_threads, "requests served at once"},
      {"server", "max_connections", &Config::max_connections,
       "open connections, idle included (503 beyond)"},
      {"server", "web_root", &Config::web_root, "built web viewer served at / (empty: none)"},
      {"storage", "data_dir", &Config::data_dir, "database and content-addressed blobs"},
      {"storage", "min_free_bytes", &Config::min_free_bytes,
       "free space below which /readyz is 503"},
      {"storage", "backend", &Config::backend, "embedded (SQLite, one daemon) or redis (shared)"},
      {"storage", "redis_url", &Config::redis_url, "redis://[:password@]host[:port][/db]"},
      {"storage", "redis_prefix", &Config::redis_prefix, "prefix of every Redis key"},
      {"storage", "blob_store", &Config::blob_store, "blobs in a directory or in redis"},
      {"storage", "blob_dir", &Config::blob_dir, "blob directory (default: <data_dir>/blobs)"},
      {"storage", "redis_max_blob_bytes", &Config::redis_max_blob_bytes,
       "largest blob kept in Redis"},
      {"storage", "redis_timeout_seconds", &Config::redis_timeout_seconds,
       "Redis connect and reply timeout"},
      {"jobs", "job_visibility_seconds", &Config::job_visibility_seconds,
       "redis backend: silence after which another daemon takes a job"},
      {"jobs", "threads", &Config::threads, "bake workers (0: one per hardware thread)"},
      {"jobs", "bake_threads", &Config::bake_threads,
       "threads inside one bake (0: one per hardware thread)"},
      {"jobs", "queue_capacity", &Config::queue_capacity, "queued bakes before 503"},
      {"jobs", "drain_seconds", &Config::drain_seconds,
       "on SIGTERM, time running bakes get to finish"},
      {"jobs", "max_job_crashes", &Config::max_job_crashes,
       "daemon deaths during one bake before it is failed"},
      {"cache", "cache_bytes", &Config::cache_bytes, "memory for hot level files (LRU)"},
      {"limits", "max_upload_bytes", &Config::max_upload_bytes,
       "largest upload, decoded (413 beyond)"},
      {"limits", "max_json_bytes", &Config::max_json_bytes, "largest JSON request body"},
      {"limits", "max_header_bytes", &Config::max_header_bytes,
       "request line and headers (431 beyond)"},
      {"limits", "max_upload_parts", &Config::max_upload_parts, "multipart parts of one upload"},
      {"limits", "max_concurrent_uploads", &Config::max_concurrent_uploads,
       "upload bodies received at once"},
      {"limits", "max_concurrent_imports", &Config::max_concurrent_imports,
       "uploads imported at once"},
      {"limits", "max_joints", &Config::max_joints, "joints of one upload (422 beyond)"},
      {"limits", "max_vertices", &Config::max_vertices, "skin vertices of one upload"},
      {"limits", "max_frames", &Config::max_frames, "source frames of one upload's clips"},
      {"limits", "max_joint_frames", &Config::max_joint_frames,
       "joints times source frames of one upload"},
      {"limits", "max_export_bytes", &Config::max_export_bytes,
       "a level's glTF file (422 beyond)"},
      {"limits", "max_streams", &Config::max_streams, "open SSE streams and long-polls together"},
      {"limits", "max_wait_seconds", &Config::max_wait_seconds, "cap of ?wait= on job status"},
      {"limits", "max_stream_seconds", &Config::max_stream_seconds, "longest SSE stream"},
      {"timeouts", "header_timeout_seconds", &Config::header_timeout_seconds,
       "a request's line and headers (408 beyond)"},
      {"timeouts", "read_timeout_seconds", &Config::read_timeout_seconds, "one socket read"},
      {"timeouts", "write_timeout_seconds", &Config::write_timeout_seconds, "one socket write"},
      {"timeouts", "keep_alive_timeout_seconds", &Config::keep_alive_timeout_seconds,
       "idle keep-alive connection"},
      {"timeouts", "keep_alive_max_requests", &Config::keep_alive_max_requests,
       "requests per connection"},
      {"timeouts", "upload_timeout_seconds", &Config::upload_timeout_seconds,
       "one whole request body"},
      {"import", "import_isolation", &Config::import_isolation,
       "importer sandbox: auto, bwrap or process"},
      {"import", "import_worker", &Config::import_worker,
       "import worker executable (default: next to motionlodd)"},
      {"import", "import_memory_bytes", &Config::import_memory_bytes,
       "import worker address space (0: unlimited)"},
      {"import", "import_cpu_seconds", &Config::import_cpu_seconds, "import worker CPU time"},
      {"import", "import_timeout_seconds", &Config::import_timeout_seconds,
       "import worker wall-clock time"},
      {"import", "import_output_bytes", &Config::import_output_bytes, "import worker reply size"},
      {"auth", "write_keys", &Config::write_keys,
       "bearer keys for writes (comma-separated in env and flags)"},
      {"auth", "read_keys", &Config::read_keys,
       "bearer keys for reads (comma-separated in env and flags)"},
      {"log", "log_level", &Config::log_level, "trace, debug, info, warn, error, critical or off"},
      {"log", "access_log", &Config::access_log, "one info line per request"},
  };
  return specs;
}

std::string Trim(std::string_view text) {
  size_t begin = 0, end = text.size();
  while (begin < end && std::isspace(static_cast<unsigned char>(text[begin]))) ++begin;
  while (end > begin && std::isspace(static_cast<unsigned char>(text[end - 1]))) --end;
  return std::string(text.substr(begin, end - begin));
}

template <typename T>
bool ParseInteger(std::string_view text, T& out) {
  const std::string trimmed = Trim(text);
  const char* end = trimmed.data() + trimmed.size();
  auto [ptr, ec] = std::from_chars(trimmed.data(), end, out);
  return ec == std::errc() && ptr == end && !trimmed.empty();
}

// Parses the text form of an option (environment and flags) into its field.
Status SetFromText(const OptionSpec& spec, std::string_view text, std::string_view origin,
                   Config& config) {
  const auto bad = [&](const char* what) {
    return InvalidArgument(std::string(origin) + ": '" + std::string(text.substr(0, 64)) +
                           "' is not " + what);
  };
  return std::visit(
      [&](auto member) -> Status {
        using T = std::remove_reference_t<decltype(config.*member)>;
        T& field = config.*member;
        if constexpr (std::is_same_v<T, std::string>) {
          field = std::string(text);
        } else if constexpr (std::is_same_v<T, int> || std::is_same_v<T, int64_t>) {
          if (!ParseInteger(text, field)) return bad("an integer");
        } else if constexpr (std::is_same_v<T, double>) {
          const std::string trimmed = Trim(text);
          char* end = nullptr;
          const double value = std::strtod(trimmed.c_str(), &end);
          if (trimmed.empty() || end != trimmed.c_str() + trimmed.size()) return bad("a number");
          field = value;
        } else if constexpr (std::is_same_v<T, bool>) {
          std::string lower = Trim(text);
          std::transform(lower.begin(), lower.end(), lower.begin(),
                         [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
          if (lower == "1" || lower == "true" || lower == "yes" || lower == "on") {
            field = true;
          } else if (lower == "0" || lower == "false" || lower == "no" || lower == "off") {
            field = false;
          } else {
            return bad("a boolean (true/false)");
          }
        } else {
          field.clear();
          std::stringstream items{std::string(text)};
          std::string item;
          while (std::getline(items, item, ',')) {
            item = Trim(item);
            if (!item.empty()) field.push_back(item);
          }
        }
        return Status::Ok();
      },
      spec.field);
}

Status SetFromToml(const OptionSpec& spec, const toml::node& node, const std::string& key,
                   Config& config) {
  const auto bad = [&](const char* what) {
    return InvalidArgument("'" + key + "' must be " + what);
  };
  return std::visit(
      [&](auto member) -> Status {
        using T = std::remove_reference_t<decltype(config.*member)>;
        T& field = config.*member;
        if constexpr (std::is_same_v<T, std::string>) {
          if (!node.is_string()) return bad("a string");
          field = node.value<std::string>().value();
        } else if constexpr (std::is_same_v<T, int> || std::is_same_v<T, int64_t>) {
          if (!node.is_integer()) return bad("an integer");
          const int64_t value = node.value<int64_t>().value();
          if constexpr (std::is_same_v<T, int>) {
            if (value < INT32_MIN || value > INT32_MAX) return bad("a 32-bit integer");
          }
          field = static_cast<T>(value);
        } else if constexpr (std::is_same_v<T, double>) {
          if (!node.is_number()) return bad("a number");
          field = node.value<double>().value();
        } else if constexpr (std::is_same_v<T, bool>) {
          if (!node.is_boolean()) return bad("a boolean");
          field = node.value<bool>().value();
        } else {
          const toml::array* array = node.as_array();
          if (array == nullptr) return bad("an array of strings");
          field.clear();
          for (const toml::node& item : *array) {
            if (!item.is_string()) return bad("an array of strings");
            field.push_back(item.value<std::string>().value());
          }
        }
        return Status::Ok();
      },
      spec.field);
}

std::string Upper(std::string_view name) {
  std::string upper(name);
  std::transform(upper.begin(), upper.end(), upper.begin(),
                 [](unsigned char c) { return static_cast<char>(std::toupper(c)); });
  return upper;
}

std::string Dashed(std::string_view name) {
  std::string dashed(name);
  std::replace(dashed.begin(), dashed.end(), '_', '-');
  return dashed;
}

}  // namespace

Status Config::Validate() const {
  if (bind.empty()) return InvalidArgument("bind must not be empty");
  if (port < 0 || port > 65535) return InvalidArgument("port must be in [0, 65535]");
  if (http_threads < 4 || http_threads > 1024)
    return InvalidArgument("http_threads must be in [4, 1024]");
  if (max_connections < http_threads || max_connections > 1 << 20)
    return InvalidArgument("max_connections must be in [http_threads, 1048576]");
  if (data_dir.empty()) return InvalidArgument("data_dir must not be empty");
  if (min_free_bytes < 0) return InvalidArgument("min_free_bytes must be >= 0");
  if (backend != "embedded" && backend != "redis")
    return InvalidArgument("backend must be \"embedded\" or \"redis\"");
  if (blob_store != "directory" && blob_store != "redis")
    return InvalidArgument("blob_store must be \"directory\" or \"redis\"");
  if (backend == "redis") {
    if (Status status = ParseRedisUrl(redis_url).status(); !status.ok()) return status;
    if (redis_prefix.empty()) return InvalidArgument("redis_prefix must not be empty");
  } else if (blob_store == "redis") {
    return InvalidArgument("blob_store = \"redis\" needs backend = \"redis\"");
  }
  if (blob_store == "redis" && redis_max_blob_bytes < max_upload_bytes)
    return InvalidArgument("redis_max_blob_bytes must be at least max_upload_bytes");
  if (!(redis_timeout_seconds > 0 && redis_timeout_seconds <= 60))
    return InvalidArgument("redis_timeout_seconds must be in (0, 60]");
  if (!(job_visibility_seconds >= 1 && job_visibility_seconds <= 86400))
    return InvalidArgument("job_visibility_seconds must be in [1, 86400]");
  if (threads < 0 || threads > 256) return InvalidArgument("threads must be in [0, 256]");
  if (bake_threads < 0 || bake_threads > 256)
    return InvalidArgument("bake_threads must be in [0, 256]");
  if (queue_capacity < 1) return InvalidArgument("queue_capacity must be at least 1");
  if (max_job_crashes < 1) return InvalidArgument("max_job_crashes must be at least 1");
  if (!(drain_seconds >= 0)) return InvalidArgument("drain_seconds must be >= 0");
  if (cache_bytes < 0) return InvalidArgument("cache_bytes must be >= 0");
  if (max_upload_bytes < 1) return InvalidArgument("max_upload_bytes must be positive");
  if (max_json_bytes < 1) return InvalidArgument("max_json_bytes must be positive");
  // The HTTP library's own limit per header line is 8 KiB.
  if (max_header_bytes < 1024 || max_header_bytes > int64_t{1} << 20)
    return InvalidArgument("max_header_bytes must be in [1024, 1048576]");
  if (max_upload_parts < 1 || max_upload_parts > 1000)
    return InvalidArgument("max_upload_parts must be in [1, 1000]");
  if (max_concurrent_imports < 1)
    return InvalidArgument("max_concurrent_imports must be at least 1");
  if (max_joints < 2 || max_joints > 65535)
    return InvalidArgument("max_joints must be in [2, 65535]");
  if (max_vertices < 1 || max_frames < 1 || max_joint_frames < 1 || max_export_bytes < 1) {
    return InvalidArgument(
        "max_vertices, max_frames, max_joint_frames and max_export_bytes must be positive");
  }
  if (max_concurrent_uploads < 1)
    return InvalidArgument("max_concurrent_uploads must be at least 1");
  if (max_streams < 0 || max_streams >= http_threads) {
    return InvalidArgument(
        "max_streams must be in [0, http_threads): open streams must not take every connection "
        "thread");
  }
  if (!(max_wait_seconds >= 0) || max_wait_seconds > 3600)
    return InvalidArgument("max_wait_seconds must be in [0, 3600]");
  if (!(max_stream_seconds > 0)) return InvalidArgument("max_stream_seconds must be positive");
  for (int value : {read_timeout_seconds, write_timeout_seconds, keep_alive_timeout_seconds,
                    upload_timeout_seconds}) {
    if (value < 1) return InvalidArgument("timeouts must be at least 1 second");
  }
  if (!(header_timeout_seconds > 0 && header_timeout_seconds <= 3600))
    return InvalidArgument("header_timeout_seconds must be in (0, 3600]");
  if (keep_alive_max_requests < 1)
    return InvalidArgument("keep_alive_max_requests must be at least 1");
  if (import_isolation != "auto" && import_isolation != "bwrap" && import_isolation != "process")
    return InvalidArgument("import_isolation must be auto, bwrap or process");
  if (import_memory_bytes < 0) return InvalidArgument("import_memory_bytes must be >= 0");
  if (!(import_cpu_seconds >= 1 && import_cpu_seconds <= 86400))
    return InvalidArgument("import_cpu_seconds must be in [1, 86400]");
  if (!(import_timeout_seconds > 0 && import_timeout_seconds <= 86400))
    return InvalidArgument("import_timeout_seconds must be in (0, 86400]");
  if (import_output_bytes < 1) return InvalidArgument("import_output_bytes must be positive");
  for (const auto* keys : {&write_keys, &read_keys}) {
    for (const std::string& key : *keys) {
      if (key.size() < 16) return InvalidArgument("API keys must have at least 16 characters");
      for (char c : key) {
        if (c <= ' ' || c > '~')
          return InvalidArgument("API keys must be printable ASCII without spaces");
      }
    }
  }
  static const char* kLevels[] = {"trace", "debug", "info", "warn", "error", "critical", "off"};
  if (std::find(std::begin(kLevels), std::end(kLevels), log_level) == std::end(kLevels)) {
    return InvalidArgument(
        "log_level must be one of trace, debug, info, warn, error, critical, off");
  }
  return Status::Ok();
}

Status ApplyToml(std::string_view toml_text, std::string_view source_name, Config& config) {
  toml::table document;
  try {
    document = toml::parse(toml_text, source_name);
  } catch (const toml::parse_error& error) {
    std::ostringstream message;
    message << source_name << ":" << error.source().begin.line << ":" << error.source().begin.column
            << ": " << error.description();
    return InvalidArgument(message.str());
  }
  for (const auto& [section_key, section_node] : document) {
    const std::string section(section_key.str());
    const toml::table* table = section_node.as_table();
    const bool known_section = std::any_of(
        Specs().begin(), Specs().end(), [&](const OptionSpec& s) { return section == s.section; });
    if (table == nullptr || !known_section) {
      return InvalidArgument(std::string(source_name) + ": unknown section or top-level key '" +
                             section +
                             "' (sections: server, storage, jobs, cache, limits, "
                             "timeouts, import, auth, log)");
    }
    for (const auto& [key, node] : *table) {
      const std::string name(key.str());
      const auto spec = std::find_if(Specs().begin(), Specs().end(), [&](const OptionSpec& s) {
        return section == s.section && name == s.name;
      });
      if (spec == Specs().end()) {
        return InvalidArgument(std::string(source_name) + ": unknown key '" + section + "." + name +
                               "'");
      }
      if (Status status = SetFromToml(*spec, node, section + "." + name, config); !status.ok()) {
        return InvalidArgument(std::string(source_name) + ": " + status.message());
      }
    }
  }
  return Status::Ok();
}

Status ApplyEnvironment(const GetEnv& getenv, Config& config) {
  for (const OptionSpec& spec : Specs()) {
    const std::string variable = "MOTIONLODD_" + Upper(spec.name);
    const char* value = getenv(variable.c_str());
    if (value == nullptr) continue;
    if (Status status = SetFromText(spec, value, variable, config); !status.ok()) return status;
  }
  // The variable the bake tool reads too, for the same choice on a farm's every machine.
  if (const char* value = getenv("MOTIONLOD_SIMD")) {
    auto simd = core::ParseSimdChoice(value);
    if (!simd.ok()) return InvalidArgument("MOTIONLOD_SIMD is " + simd.status().message());
    config.simd = *simd;
  }
  return Status::Ok();
}

StatusOr<Options> ParseCommandLine(int argc, const char* const* argv, const GetEnv& getenv,
                                   std::string* out) {
  Options options;
  CLI::App app{"motionlodd: the Motion LoD bake and level-streaming daemon"};
  app.set_version_flag("--version", "motionlodd 0.1.0");
  app.add_option("--config", options.config_file,
                 "TOML config file (default: $MOTIONLODD_CONFIG; none: built-in defaults)");
  std::vector<std::string> flag_values(Specs().size());
  std::vector<CLI::Option*> flags;
  for (size_t k = 0; k < Specs().size(); ++k) {
    flags.push_back(
        app.add_option("--" + Dashed(Specs()[k].name), flag_values[k], Specs()[k].help));
  }
  app.add_option("--seed", options.seed_files,
                 "character file(s) to upload and bake at start (the main file first)")
      ->delimiter(',');
  app.add_option("--seed-animation", options.seed_animation,
                 "animation the seed bake uses (default: every animation of the character, "
                 "baked together)");
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp&) {
    if (out) *out = app.help();
    options.exit = true;
    return options;
  } catch (const CLI::CallForVersion&) {
    if (out) *out = "motionlodd 0.1.0\n";
    options.exit = true;
    return options;
  } catch (const CLI::ParseError& error) {
    return InvalidArgument(std::string("command line: ") + error.what() + " (see --help)");
  }
  if (options.config_file.empty()) {
    if (const char* path = getenv("MOTIONLODD_CONFIG")) options.config_file = path;
  }
  if (!options.config_file.empty()) {
    std::ifstream in(options.config_file, std::ios::binary);
    if (!in) return InvalidArgument("cannot read the config file '" + options.config_file + "'");
    std::ostringstream text;
    text << in.rdbuf();
    if (Status status = ApplyToml(text.str(), options.config_file, options.config); !status.ok()) {
      return status;
    }
  }
  if (Status status = ApplyEnvironment(getenv, options.config); !status.ok()) return status;
  for (size_t k = 0; k < Specs().size(); ++k) {
    if (flags[k]->count() == 0) continue;
    if (Status status =
            SetFromText(Specs()[k], flag_values[k], "--" + Dashed(Specs()[k].name), options.config);
        !status.ok()) {
      return status;
    }
  }
  if (Status status = options.config.Validate(); !status.ok()) return status;
  return options;
}

}  // namespace motionlod::server
