// A real motionlodd for the client tests (tests/server/daemon.h) and a Client on it.
#pragma once

#include <gtest/gtest.h>

#include <optional>
#include <string>
#include <vector>

#include "client/client.h"
#include "tests/server/daemon.h"

namespace motionlod::client::testing {

using server::testing::Daemon;
using server::testing::SourcePath;
using server::testing::TestDirectory;

inline std::string SamplePath() { return SourcePath("samples/Rig_Medium_MovementBasic.glb"); }

// The sample's walk, three levels of its 23 joints: what most tests bake.
inline proto::api::BakeRequest SampleBakeRequest(const std::string& character_id) {
  proto::api::BakeRequest request;
  request.character = character_id;
  request.motion = "Walking_A";
  request.levels = {17, 12, 6};
  return request;
}

inline std::string BaseUrl(const Daemon& daemon) {
  return "http://127.0.0.1:" + std::to_string(daemon.port());
}

// A started daemon (with `args`) and a client of it.
class DaemonTest : public ::testing::Test {
 protected:
  void StartDaemon(const std::vector<std::string>& args = {}) {
    daemon_.emplace(TestDirectory());
    ASSERT_TRUE(daemon_->Start(args)) << daemon_->error;
  }
  ClientOptions Options() const {
    ClientOptions options;
    options.base_url = BaseUrl(*daemon_);
    options.read_timeout_seconds = 120;  // a loaded CI box
    return options;
  }
  Client MakeClient(const ClientOptions& options) {
    auto client = Client::Create(options);
    EXPECT_TRUE(client.ok()) << client.error().ToString();
    return std::move(*client);
  }
  // Uploads the sample and bakes SampleBakeRequest through `client`.
  proto::api::BakeInfo BakeSample(Client& client) {
    auto file = ReadUploadFile(SamplePath());
    EXPECT_TRUE(file.ok());
    auto character = client.UploadCharacter({*file});
    EXPECT_TRUE(character.ok()) << character.error().ToString();
    if (!character.ok()) return {};
    auto job = client.SubmitBake(SampleBakeRequest(character->value.id));
    EXPECT_TRUE(job.ok()) << job.error().ToString();
    if (!job.ok()) return {};
    auto bake = client.WaitForBake(job->id, {}, 300);
    EXPECT_TRUE(bake.ok()) << bake.error().ToString();
    return bake.ok() ? *bake : proto::api::BakeInfo{};
  }

  std::optional<Daemon> daemon_;
};

}  // namespace motionlod::client::testing
