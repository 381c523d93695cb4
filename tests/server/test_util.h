// Helpers shared by the daemon tests: JSON replies, problem+json checks, uploads and
// job polling over real HTTP.
#pragma once

#include <gtest/gtest.h>
#include <httplib.h>

#include <chrono>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>

#include "tests/server/daemon.h"

namespace motionlod::server::testing {

using nlohmann::json;

// The CC0 sample the project ships, and its character id (the SHA-256 of its bytes).
inline constexpr const char* kSampleId =
    "11422afd50abf7e8c92ea107e2e0bc94abd38023d6d15f55ad580347efbfa29e";
inline std::string Sample() { return SourcePath("samples/Rig_Medium_MovementBasic.glb"); }

inline json Json(const httplib::Result& result) {
  if (!result) return json();
  return json::parse(result->body, nullptr, false);
}

// The reply is RFC 9457 problem+json with this status, a precise detail and the
// request id of its X-Request-Id header.
inline void ExpectProblem(const httplib::Result& result, int status,
                          const std::string& detail_part = "") {
  ASSERT_TRUE(result) << "no response";
  EXPECT_EQ(result->status, status) << result->body;
  EXPECT_EQ(result->get_header_value("Content-Type"), "application/problem+json");
  const json problem = json::parse(result->body, nullptr, false);
  ASSERT_TRUE(problem.is_object()) << result->body;
  EXPECT_EQ(problem.value("status", 0), status);
  EXPECT_EQ(problem.value("type", "").rfind("urn:motionlod:problem:", 0), 0u) << result->body;
  EXPECT_FALSE(problem.value("title", "").empty());
  EXPECT_FALSE(problem.value("detail", "").empty());
  EXPECT_TRUE(problem.contains("instance"));
  EXPECT_EQ(problem.value("request_id", ""), result->get_header_value("X-Request-Id"));
  EXPECT_EQ(result->get_header_value("X-Request-Id").size(), 16u);
  if (!detail_part.empty()) {
    EXPECT_NE(problem.value("detail", "").find(detail_part), std::string::npos) << result->body;
  }
}

inline httplib::Headers Auth(const std::string& key) {
  return key.empty() ? httplib::Headers{} : httplib::Headers{{"Authorization", "Bearer " + key}};
}

// POST /v1/characters with raw bytes, or a file's.
inline httplib::Result UploadBytes(httplib::Client& client, const std::string& name,
                                   const std::string& bytes, const std::string& key = "") {
  return client.Post(("/v1/characters?filename=" + name).c_str(), Auth(key), bytes,
                     "application/octet-stream");
}
inline httplib::Result UploadFile(httplib::Client& client, const std::string& path,
                                  const std::string& name, const std::string& key = "") {
  return UploadBytes(client, name, ReadFile(path), key);
}

inline httplib::Result SubmitBake(httplib::Client& client, const json& request,
                                  const std::string& key = "") {
  return client.Post("/v1/bakes", Auth(key), request.dump(), "application/json");
}

// Long-polls GET /v1/jobs/{id}?wait= until the job has finished; returns its last status.
// The default leaves room for the sanitizer build, where the sample's default ladder takes
// a minute or more.
inline json WaitForJob(httplib::Client& client, const std::string& id, double seconds = 300) {
  json status;
  uint64_t version = 0;
  const auto deadline = std::chrono::steady_clock::now() +
                        std::chrono::milliseconds(static_cast<int64_t>(seconds * 1000));
  while (std::chrono::steady_clock::now() < deadline) {
    auto result =
        client.Get(("/v1/jobs/" + id + "?wait=5&after=" + std::to_string(version)).c_str());
    if (!result || result->status != 200) {
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
      continue;
    }
    status = json::parse(result->body, nullptr, false);
    const std::string state = status.value("state", "");
    if (state == "succeeded" || state == "failed") return status;
    version = status.value("version", uint64_t{0});
  }
  return status;
}

}  // namespace motionlod::server::testing
