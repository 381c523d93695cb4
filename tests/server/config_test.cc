// Config: defaults < TOML file < MOTIONLODD_* environment < flags, each validated.
#include "server/config.h"

#include <gtest/gtest.h>

#include <csignal>
#include <fstream>
#include <map>

#include "tests/server/daemon.h"

namespace motionlod::server {
namespace {

GetEnv Env(std::map<std::string, std::string> variables) {
  auto shared = std::make_shared<std::map<std::string, std::string>>(std::move(variables));
  return [shared](const char* name) -> const char* {
    const auto found = shared->find(name);
    return found == shared->end() ? nullptr : found->second.c_str();
  };
}

StatusOr<Options> Parse(std::vector<std::string> args, const GetEnv& env) {
  args.insert(args.begin(), "motionlodd");
  std::vector<const char*> argv;
  for (const std::string& a : args) argv.push_back(a.c_str());
  std::string out;
  return ParseCommandLine(static_cast<int>(argv.size()), argv.data(), env, &out);
}

TEST(Config, DefaultsAreValid) { EXPECT_TRUE(Config{}.Validate().ok()); }

TEST(Config, TheShippedConfigFileParsesAndDocumentsEveryOption) {
  const std::string path = testing::SourcePath("config/motionlodd.toml");
  Config config;
  const Status status = ApplyToml(testing::ReadFile(path), path, config);
  ASSERT_TRUE(status.ok()) << status.message();
  EXPECT_TRUE(config.Validate().ok());
  // Every option appears in the shipped file (as a key, possibly commented out).
  const std::string text = testing::ReadFile(path);
  for (const char* key : {"bind",
                          "port",
                          "http_threads",
                          "max_connections",
                          "web_root",
                          "data_dir",
                          "min_free_bytes",
                          "backend",
                          "redis_url",
                          "redis_prefix",
                          "blob_store",
                          "blob_dir",
                          "redis_max_blob_bytes",
                          "redis_timeout_seconds",
                          "job_visibility_seconds",
                          "threads",
                          "bake_threads",
                          "queue_capacity",
                          "drain_seconds",
                          "cache_bytes",
                          "max_upload_bytes",
                          "max_json_bytes",
                          "max_header_bytes",
                          "max_upload_parts",
                          "max_concurrent_uploads",
                          "max_concurrent_imports",
                          "max_joints",
                          "max_vertices",
                          "max_frames",
                          "max_joint_frames",
                          "max_export_bytes",
                          "max_streams",
                          "max_wait_seconds",
                          "max_stream_seconds",
                          "header_timeout_seconds",
                          "read_timeout_seconds",
                          "write_timeout_seconds",
                          "keep_alive_timeout_seconds",
                          "keep_alive_max_requests",
                          "upload_timeout_seconds",
                          "import_isolation",
                          "import_worker",
                          "import_memory_bytes",
                          "import_cpu_seconds",
                          "import_timeout_seconds",
                          "import_output_bytes",
                          "write_keys",
                          "read_keys",
                          "log_level",
                          "access_log"}) {
    EXPECT_NE(text.find(std::string(key) + " ="), std::string::npos) << key;
  }
}

TEST(Config, TomlSetsSectionedKeys) {
  Config config;
  ASSERT_TRUE(
      ApplyToml("[server]\nport = 9000\nbind = \"0.0.0.0\"\n[auth]\nwrite_keys = [\"k1\", \"k2\"]\n"
                "[log]\naccess_log = false\n",
                "test.toml", config)
          .ok());
  EXPECT_EQ(config.port, 9000);
  EXPECT_EQ(config.bind, "0.0.0.0");
  EXPECT_EQ(config.write_keys, (std::vector<std::string>{"k1", "k2"}));
  EXPECT_FALSE(config.access_log);
}

TEST(Config, TomlRejectsUnknownKeysWrongTypesAndSyntaxErrorsNamingThem) {
  Config config;
  Status unknown = ApplyToml("[server]\nprot = 1\n", "a.toml", config);
  EXPECT_NE(unknown.message().find("server.prot"), std::string::npos) << unknown.message();
  Status type = ApplyToml("[server]\nport = \"eighty\"\n", "a.toml", config);
  EXPECT_NE(type.message().find("server.port"), std::string::npos) << type.message();
  Status syntax = ApplyToml("[server\nport = 1\n", "a.toml", config);
  EXPECT_FALSE(syntax.ok());
  EXPECT_NE(syntax.message().find("a.toml:1"), std::string::npos) << syntax.message();
}

TEST(Config, FlagsOverrideEnvironmentWhichOverridesTheFile) {
  const std::string file =
      (std::filesystem::temp_directory_path() / "motionlodd_config_test.toml").string();
  std::ofstream(file) << "[server]\nport = 1111\nbind = \"10.0.0.1\"\n[jobs]\nthreads = "
                         "3\n[storage]\ndata_dir = \"/from/file\"\n";
  auto options = Parse({"--config", file, "--port", "3333"},
                       Env({{"MOTIONLODD_PORT", "2222"},
                            {"MOTIONLODD_THREADS", "5"},
                            {"MOTIONLODD_WRITE_KEYS", "aaaaaaaaaaaaaaaa, bbbbbbbbbbbbbbbb"}}));
  ASSERT_TRUE(options.ok()) << options.status().message();
  EXPECT_EQ(options->config.port, 3333);        // flag
  EXPECT_EQ(options->config.threads, 5);        // environment
  EXPECT_EQ(options->config.bind, "10.0.0.1");  // file
  EXPECT_EQ(options->config.data_dir, "/from/file");
  EXPECT_EQ(options->config.write_keys.size(), 2u);
  auto from_env_file = Parse({}, Env({{"MOTIONLODD_CONFIG", file}}));
  ASSERT_TRUE(from_env_file.ok());
  EXPECT_EQ(from_env_file->config.port, 1111);
  std::filesystem::remove(file);
}

TEST(Config, InvalidValuesAreRefusedWithTheOptionNamed) {
  auto port = Parse({"--port", "70000"}, Env({}));
  EXPECT_FALSE(port.ok());
  EXPECT_NE(port.status().message().find("port"), std::string::npos);
  auto text = Parse({"--threads", "many"}, Env({}));
  EXPECT_NE(text.status().message().find("--threads"), std::string::npos)
      << text.status().message();
  auto env = Parse({}, Env({{"MOTIONLODD_ACCESS_LOG", "maybe"}}));
  EXPECT_NE(env.status().message().find("MOTIONLODD_ACCESS_LOG"), std::string::npos);
  auto short_key = Parse({"--write-keys", "short"}, Env({}));
  EXPECT_NE(short_key.status().message().find("16"), std::string::npos);
  auto streams = Parse({"--max-streams", "64"}, Env({}));
  EXPECT_NE(streams.status().message().find("max_streams"), std::string::npos);
  // The backend, from the environment as from the file, and what it needs.
  const auto redis = Parse({}, Env({{"MOTIONLODD_BACKEND", "redis"},
                                    {"MOTIONLODD_REDIS_URL", "redis://cache:6380/1"}}));
  ASSERT_TRUE(redis.ok()) << redis.status().message();
  EXPECT_EQ(redis->config.backend, "redis");
  EXPECT_EQ(redis->config.redis_url, "redis://cache:6380/1");
  auto backend = Parse({"--backend", "postgres"}, Env({}));
  EXPECT_NE(backend.status().message().find("backend"), std::string::npos);
  auto url = Parse({"--backend", "redis", "--redis-url", "http://cache"}, Env({}));
  EXPECT_NE(url.status().message().find("redis_url"), std::string::npos);
  auto blobs = Parse({"--blob-store", "redis"}, Env({}));
  EXPECT_NE(blobs.status().message().find("needs backend"), std::string::npos);
  auto unknown = Parse({"--colour", "red"}, Env({}));
  EXPECT_FALSE(unknown.ok());
  auto missing = Parse({"--config", "/nonexistent/motionlodd.toml"}, Env({}));
  EXPECT_NE(missing.status().message().find("/nonexistent/motionlodd.toml"), std::string::npos);
}

// MOTIONLOD_SIMD picks the hot loops' machine version (core/simd.h): a misspelt value stops
// the daemon before it listens, naming the variable; "baseline" starts it, and its start-up
// line says which version runs.
TEST(Config, AnUnknownSimdSettingStopsTheDaemonAndTheVersionIsLogged) {
  {
    testing::Daemon daemon(testing::TestDirectory());
    EXPECT_FALSE(daemon.Start({}, {"MOTIONLOD_SIMD=sse2"}));
    EXPECT_NE(daemon.Log().find("MOTIONLOD_SIMD is 'sse2'"), std::string::npos) << daemon.Log();
  }
  testing::Daemon daemon(testing::TestDirectory());
  ASSERT_TRUE(daemon.Start({}, {"MOTIONLOD_SIMD=baseline"})) << daemon.error;
  EXPECT_NE(daemon.Log().find("baseline hot loops"), std::string::npos) << daemon.Log();
  EXPECT_EQ(daemon.Stop(SIGTERM), 0);
}

}  // namespace
}  // namespace motionlod::server
