// motionlod-client as scripts run it: a real process against a real daemon, exit codes,
// --json on stdout, progress and errors on stderr.
#include <sys/wait.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <nlohmann/json.hpp>

#include "client/level.h"
#include "tests/client/fixture.h"

namespace motionlod::client::testing {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

struct CliRun {
  int exit_code = -1;
  std::string out;  // stdout
  std::string err;  // stderr
};

class ClientCli : public DaemonTest {
 protected:
  // motionlod-client ARGS with stdout captured and stderr in a file beside the daemon's.
  CliRun Cli(const std::string& args) {
    const fs::path err_file = daemon_->dir() / "cli.stderr";
    const std::string command =
        MOTIONLOD_CLIENT_CLI " " + args + " 2>" + err_file.string() + " </dev/null";
    CliRun run;
    FILE* pipe = ::popen(command.c_str(), "r");
    if (pipe == nullptr) return run;
    char buffer[4096];
    while (size_t n = std::fread(buffer, 1, sizeof buffer, pipe)) run.out.append(buffer, n);
    const int status = ::pclose(pipe);
    run.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    std::ifstream in(err_file);
    std::ostringstream text;
    text << in.rdbuf();
    run.err = text.str();
    return run;
  }
  std::string Server() const { return "--server " + BaseUrl(*daemon_) + " "; }
};

TEST_F(ClientCli, UploadBakeStatusLevelsAndFetchWithJson) {
  StartDaemon();
  const CliRun upload = Cli(Server() + "--json upload " + SamplePath());
  ASSERT_EQ(upload.exit_code, 0) << upload.err;
  const json character = json::parse(upload.out, nullptr, false);
  ASSERT_TRUE(character.is_object()) << upload.out;
  const std::string id = character.value("id", "");
  EXPECT_TRUE(proto::api::IsContentId(id));
  EXPECT_EQ(character.value("joints", 0), 23);
  EXPECT_TRUE(character.value("created", false));

  const CliRun bake = Cli(Server() + "--json bake " + id + " --motion Walking_A --levels 17,12,6");
  ASSERT_EQ(bake.exit_code, 0) << bake.err;
  const json info = json::parse(bake.out, nullptr, false);
  ASSERT_TRUE(info.is_object()) << bake.out;
  EXPECT_EQ(info.value("state", ""), "succeeded");
  ASSERT_EQ(info["levels"].size(), 3u);
  const std::string bake_id = info.value("id", "");
  EXPECT_NE(bake.err.find("bake " + bake_id.substr(0, 12)), std::string::npos)
      << "progress lines on stderr (not a terminal): " << bake.err;
  EXPECT_NE(bake.err.find("succeeded"), std::string::npos) << bake.err;

  const CliRun status = Cli(Server() + "--json status " + bake_id);
  ASSERT_EQ(status.exit_code, 0) << status.err;
  EXPECT_EQ(json::parse(status.out, nullptr, false).value("state", ""), "succeeded");

  const CliRun levels = Cli(Server() + "levels " + bake_id);
  ASSERT_EQ(levels.exit_code, 0) << levels.err;
  for (const json& level : info["levels"]) {
    EXPECT_NE(levels.out.find(level["hash"].get<std::string>()), std::string::npos) << levels.out;
  }

  const fs::path cache = daemon_->dir() / "cache";
  const fs::path out = daemon_->dir() / "level.mlod";
  const std::string fetch =
      Server() + "--json --cache-dir " + cache.string() + " fetch " + bake_id + " --px 120 -o " + out.string();
  const CliRun first = Cli(fetch);
  ASSERT_EQ(first.exit_code, 0) << first.err;
  const json fetched = json::parse(first.out, nullptr, false);
  EXPECT_TRUE(fetched.value("downloaded", false));
  const int index = fetched.value("index", -1);
  ASSERT_GE(index, 0);
  EXPECT_EQ(fetched.value("hash", ""), info["levels"][index]["hash"].get<std::string>());
  std::ifstream file(out, std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(file)), std::istreambuf_iterator<char>());
  auto level = Level::Decode(bytes);
  ASSERT_TRUE(level.ok()) << level.error().ToString();
  EXPECT_EQ(level->level().kept_count(), info["levels"][index]["joints"].get<uint32_t>());

  const CliRun second = Cli(fetch);
  ASSERT_EQ(second.exit_code, 0) << second.err;
  EXPECT_FALSE(json::parse(second.out, nullptr, false).value("downloaded", true))
      << "the cached level is revalidated, not downloaded again";
}

TEST_F(ClientCli, BakesSeveralClipsAndFetchesOneClipsLevel) {
  StartDaemon();
  const CliRun upload = Cli(Server() + "--json upload " + SamplePath());
  ASSERT_EQ(upload.exit_code, 0) << upload.err;
  const std::string id = json::parse(upload.out, nullptr, false).value("id", "");

  const CliRun bake = Cli(Server() + "--json bake " + id +
                          " --clip Walking_A --clip Running_A --ranking paper --levels 12,6");
  ASSERT_EQ(bake.exit_code, 0) << bake.err;
  const json info = json::parse(bake.out, nullptr, false);
  ASSERT_TRUE(info.is_object()) << bake.out;
  EXPECT_EQ(info.value("ranking", ""), "paper");
  ASSERT_EQ(info["clips"].size(), 2u);
  EXPECT_EQ(info["clips"][1]["animation"], "Running_A");
  const std::string bake_id = info.value("id", "");

  // --clips a,b names the same clips: the same request, but for the ranking.
  const CliRun greedy =
      Cli(Server() + "--json bake " + id + " --clips Walking_A,Running_A --levels 12,6 --no-wait");
  ASSERT_EQ(greedy.exit_code, 0) << greedy.err;
  EXPECT_NE(json::parse(greedy.out, nullptr, false).value("id", ""), bake_id);

  const CliRun levels = Cli(Server() + "levels " + bake_id);
  ASSERT_EQ(levels.exit_code, 0) << levels.err;
  EXPECT_NE(levels.out.find("ranking paper"), std::string::npos) << levels.out;
  EXPECT_NE(levels.out.find("clip 'Walking_A'"), std::string::npos) << levels.out;
  EXPECT_NE(levels.out.find("clip 'Running_A'"), std::string::npos) << levels.out;

  const fs::path cache = daemon_->dir() / "cache";
  const fs::path out = daemon_->dir() / "running.mlod";
  const std::string fetch = Server() + "--json --cache-dir " + cache.string() + " fetch " +
                            bake_id + " --px 120 --clip Running_A -o " + out.string();
  const CliRun first = Cli(fetch);
  ASSERT_EQ(first.exit_code, 0) << first.err;
  EXPECT_EQ(json::parse(first.out, nullptr, false).value("clip", ""), "Running_A");
  EXPECT_TRUE(json::parse(first.out, nullptr, false).value("downloaded", false));
  std::ifstream file(out, std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(file)), std::istreambuf_iterator<char>());
  auto level = Level::Decode(bytes);
  ASSERT_TRUE(level.ok()) << level.error().ToString();
  ASSERT_EQ(level->level_set().clip_count(), 1u);
  EXPECT_EQ(level->level_set().clip(0).name, "Running_A");
  EXPECT_EQ(level->level().frame_count(), info["clips"][1]["frames"].get<uint32_t>());
  const CliRun second = Cli(fetch);
  ASSERT_EQ(second.exit_code, 0) << second.err;
  EXPECT_FALSE(json::parse(second.out, nullptr, false).value("downloaded", true))
      << "from the cache";

  const CliRun unknown =
      Cli(Server() + "fetch " + bake_id + " --px 120 --clip Moonwalk -o " + out.string());
  EXPECT_EQ(unknown.exit_code, 2);
  EXPECT_NE(unknown.err.find("'Walking_A', 'Running_A'"), std::string::npos) << unknown.err;
  const CliRun both = Cli(Server() + "bake " + id + " --motion Walking_A --clip Running_A");
  EXPECT_EQ(both.exit_code, 2);
  const CliRun bad_ranking = Cli(Server() + "bake " + id + " --ranking best");
  EXPECT_EQ(bad_ranking.exit_code, 2);
}

TEST_F(ClientCli, BadInputExitsTwoAndFailuresExitOne) {
  StartDaemon();
  const CliRun malformed = Cli(Server() + "bake not-an-id");
  EXPECT_EQ(malformed.exit_code, 2);
  EXPECT_NE(malformed.err.find("character id must be 64 lower-case hex digits"), std::string::npos)
      << malformed.err;
  EXPECT_TRUE(malformed.out.empty());

  const CliRun unknown = Cli(Server() + "levels " + std::string(64, 'd'));
  EXPECT_EQ(unknown.exit_code, 2);
  EXPECT_NE(unknown.err.find("404"), std::string::npos) << unknown.err;
  EXPECT_NE(unknown.err.find("request id"), std::string::npos) << unknown.err;

  const CliRun missing_file = Cli(Server() + "upload " + (daemon_->dir() / "absent.glb").string());
  EXPECT_EQ(missing_file.exit_code, 2);
  EXPECT_NE(missing_file.err.find("cannot read"), std::string::npos) << missing_file.err;

  const CliRun no_px = Cli(Server() + "fetch " + std::string(64, 'e') + " -o x.mlod");
  EXPECT_EQ(no_px.exit_code, 2);
  EXPECT_NE(no_px.err.find("--px"), std::string::npos) << no_px.err;

  EXPECT_EQ(Cli(Server() + "frobnicate").exit_code, 2);
  EXPECT_EQ(Cli("--server ftp://nowhere levels " + std::string(64, 'f')).exit_code, 2);

  // Nothing listens on port 1: a connection failure after the (one) try.
  // No daemon there: the message names the address, says what failed and what to check;
  // each retry is announced.
  const CliRun unreachable = Cli("--server http://127.0.0.1:1 --retries 2 levels " + std::string(64, 'f'));
  EXPECT_EQ(unreachable.exit_code, 1);
  for (const char* part : {"http://127.0.0.1:1/v1/bakes/", "could not connect", "is motionlodd running",
                           "try 1 of 2 failed"}) {
    EXPECT_NE(unreachable.err.find(part), std::string::npos) << part << "\n" << unreachable.err;
  }
}

}  // namespace
}  // namespace motionlod::client::testing
