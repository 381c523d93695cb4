// The thin client's whole flow against a real motionlodd on loopback: upload, bake with
// progress, level table, levels fetched through the disk cache (304 on a hit), the
// problem+json detail of refused requests, and the client-side level choice with
// hysteresis on a camera sweep.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>

#include "client/level_selector.h"
#include "proto/level_selection.h"
#include "tests/client/fixture.h"

namespace motionlod::client::testing {
namespace {

namespace api = proto::api;
namespace fs = std::filesystem;

using ClientFlow = DaemonTest;

TEST_F(ClientFlow, UploadsBakesWithProgressAndFetchesEveryLevel) {
  StartDaemon();
  Client client = MakeClient(Options());
  auto file = ReadUploadFile(SamplePath());
  ASSERT_TRUE(file.ok()) << file.error().ToString();
  auto first = client.UploadCharacter({*file});
  ASSERT_TRUE(first.ok()) << first.error().ToString();
  EXPECT_TRUE(first->created);
  EXPECT_EQ(first->value.joints, 23);
  EXPECT_EQ(first->value.joint_names.size(), 23u);
  auto again = client.UploadCharacter({*file});
  ASSERT_TRUE(again.ok());
  EXPECT_FALSE(again->created) << "the same bytes are the same character";
  EXPECT_EQ(again->value.id, first->value.id);

  auto job = client.SubmitBake(SampleBakeRequest(first->value.id));
  ASSERT_TRUE(job.ok()) << job.error().ToString();
  std::vector<api::JobStatus> seen;
  auto bake = client.WaitForBake(job->id, [&](const api::JobStatus& s) { seen.push_back(s); }, 300);
  ASSERT_TRUE(bake.ok()) << bake.error().ToString();
  ASSERT_FALSE(seen.empty());
  for (size_t k = 1; k < seen.size(); ++k) {
    EXPECT_GE(seen[k].progress, seen[k - 1].progress) << "progress only grows";
  }
  EXPECT_EQ(seen.back().state, "succeeded");
  EXPECT_EQ(seen.back().progress, 1.0);
  EXPECT_EQ(bake->state, "succeeded");
  EXPECT_EQ(bake->id, job->id);
  ASSERT_EQ(bake->levels.size(), 3u);
  EXPECT_GT(bake->frames, 1);

  const int expected_joints[] = {17, 12, 6};
  for (size_t l = 0; l < bake->levels.size(); ++l) {
    const api::LevelEntry& entry = bake->levels[l];
    EXPECT_EQ(entry.joints, expected_joints[l]);
    auto level = client.FetchLevel(entry.hash);
    ASSERT_TRUE(level.ok()) << level.error().ToString();
    EXPECT_EQ(level->level_set().level_count(), 1u);
    EXPECT_EQ(level->level_set().joint_count(), 23u);
    EXPECT_EQ(level->level().kept_count(), static_cast<uint32_t>(entry.joints));
    EXPECT_EQ(level->level().frame_count(), static_cast<uint32_t>(bake->frames));
    EXPECT_EQ(level->byte_size(), entry.bytes);
    EXPECT_FLOAT_EQ(level->level().figures().max_vertex_error_pct,
                    static_cast<float>(entry.max_vertex_error_pct));
    EXPECT_TRUE(level->level_set().rigid()) << "vpno+pd levels are rigid";
  }
  EXPECT_EQ(client.fetch_stats().downloads, 3);
  EXPECT_EQ(client.fetch_stats().cache_writes, 0) << "no cache directory was given";

  // The local choice is the daemon's, for heights across the whole table.
  auto selector = LevelSelector::FromBake(*bake);
  ASSERT_TRUE(selector.ok()) << selector.error().ToString();
  for (double px : {5.0, 20.0, 40.0, 60.0, 90.0, 120.0, 200.0, 400.0, 1500.0}) {
    auto choice = client.ChooseLevel(bake->id, px);
    ASSERT_TRUE(choice.ok()) << choice.error().ToString();
    EXPECT_EQ(selector->Choose(px, -1), choice->index) << "at " << px << " px";
  }
}

TEST_F(ClientFlow, RefusalsCarryTheDaemonsProblemDetail) {
  StartDaemon();
  Client client = MakeClient(Options());
  const std::string unknown(64, 'a');
  auto missing = client.GetBake(unknown);
  ASSERT_FALSE(missing.ok());
  const Error& error = missing.error();
  EXPECT_EQ(error.kind, ErrorKind::kHttp);
  EXPECT_EQ(error.http_status, 404);
  EXPECT_TRUE(error.client_error());
  ASSERT_TRUE(error.problem.has_value());
  EXPECT_EQ(error.problem->status, 404);
  EXPECT_EQ(error.problem->type.rfind("urn:motionlod:problem:", 0), 0u);
  EXPECT_FALSE(error.problem->detail.empty());
  EXPECT_EQ(error.problem->request_id.size(), 16u);
  EXPECT_NE(error.message.find(error.problem->detail), std::string::npos);

  auto file = ReadUploadFile(SamplePath());
  ASSERT_TRUE(file.ok());
  auto character = client.UploadCharacter({*file});
  ASSERT_TRUE(character.ok());
  api::BakeRequest bad = SampleBakeRequest(character->value.id);
  bad.variant = "quadratic";
  auto refused = client.SubmitBake(bad);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().http_status, 400);
  EXPECT_NE(refused.error().problem->detail.find("variant"), std::string::npos)
      << refused.error().message;

  auto garbage = client.UploadCharacter({{"notes.glb", "this is not a model"}});
  ASSERT_FALSE(garbage.ok());
  EXPECT_EQ(garbage.error().http_status, 422) << garbage.error().message;

  // Malformed ids never reach the daemon.
  auto malformed = client.GetJob("../../etc/passwd");
  ASSERT_FALSE(malformed.ok());
  EXPECT_EQ(malformed.error().kind, ErrorKind::kInvalidArgument);
  ClientOptions foreign;
  foreign.base_url = "ftp://example";
  EXPECT_EQ(Client::Create(foreign).error().kind, ErrorKind::kInvalidArgument);
}

TEST_F(ClientFlow, CachedLevelIsRevalidatedWithoutASecondDownload) {
  StartDaemon();
  ClientOptions options = Options();
  options.cache_dir = daemon_->dir() / "client-cache";
  Client first = MakeClient(options);
  const api::BakeInfo bake = BakeSample(first);
  ASSERT_EQ(bake.levels.size(), 3u);
  const std::string hash = bake.levels[1].hash;

  auto downloaded = first.FetchLevel(hash);
  ASSERT_TRUE(downloaded.ok()) << downloaded.error().ToString();
  EXPECT_EQ(first.fetch_stats().downloads, 1);
  EXPECT_EQ(first.fetch_stats().cache_writes, 1);
  const fs::path cached = options.cache_dir / (hash + ".mlod");
  ASSERT_TRUE(fs::exists(cached));
  EXPECT_EQ(fs::file_size(cached), bake.levels[1].bytes);

  // Another client (another run of the game) on the same cache: 304, no body.
  Client second = MakeClient(options);
  auto revalidated = second.FetchLevel(hash);
  ASSERT_TRUE(revalidated.ok()) << revalidated.error().ToString();
  EXPECT_EQ(second.fetch_stats().downloads, 0);
  EXPECT_EQ(second.fetch_stats().revalidated, 1);
  ASSERT_EQ(revalidated->byte_size(), downloaded->byte_size());
  EXPECT_TRUE(std::equal(revalidated->level_set().bytes().begin(),
                         revalidated->level_set().bytes().end(),
                         downloaded->level_set().bytes().begin()));

  // A damaged cache file is never used: the checksum fails, the level comes again.
  {
    std::fstream damage(cached, std::ios::in | std::ios::out | std::ios::binary);
    damage.seekp(200);
    damage.put('\x7f');
  }
  Client third = MakeClient(options);
  auto repaired = third.FetchLevel(hash);
  ASSERT_TRUE(repaired.ok()) << repaired.error().ToString();
  EXPECT_EQ(third.fetch_stats().revalidated, 1);
  EXPECT_EQ(third.fetch_stats().downloads, 1);
  auto after = Client::Create(options);
  ASSERT_TRUE(after.ok());
  ASSERT_TRUE(after->FetchLevel(hash).ok());
  EXPECT_EQ(after->fetch_stats().downloads, 0) << "the cache holds the good file again";
}

// A camera flies away from the character and back with a jitter of +-3% in distance
// every frame (the worst case for flicker): without hysteresis the level flips at each
// threshold for as long as the jitter straddles it; with 10% hysteresis it changes once
// per threshold and direction, and never breaks the pixel budget.
TEST_F(ClientFlow, HysteresisStopsFlickerOnACameraSweepWithinTheBudget) {
  StartDaemon();
  Client client = MakeClient(Options());
  const api::BakeInfo bake = BakeSample(client);
  ASSERT_EQ(bake.levels.size(), 3u);
  auto steady = LevelSelector::FromBake(bake, {.budget_px = 1.0, .hysteresis = 0.1});
  auto plain = LevelSelector::FromBake(bake, {.budget_px = 1.0, .hysteresis = 0.0});
  ASSERT_TRUE(steady.ok() && plain.ok());

  constexpr int kFrames = 2000;
  int steady_level = -1, plain_level = -1, steady_switches = 0, plain_switches = 0;
  std::vector<int> levels_used;
  for (int f = 0; f < kFrames; ++f) {
    // Out from 1 to 1000 m and back (about 1100 to 2 px: beyond every threshold of the
    // table), log-spaced; jitter alternating every frame.
    const double u = f < kFrames / 2 ? f / (kFrames / 2.0) : 2.0 - f / (kFrames / 2.0);
    const double distance = std::exp(u * std::log(1000.0)) * (f % 2 == 0 ? 1.03 : 0.97);
    const double px = proto::PixelHeight({std::numbers::pi / 3, distance, 1.8, 1080});
    ASSERT_GT(px, 0);
    const int s = steady->Choose(px, steady_level);
    const int p = plain->Choose(px, plain_level);
    if (steady_level >= 0 && s != steady_level) ++steady_switches;
    if (plain_level >= 0 && p != plain_level) ++plain_switches;
    steady_level = s;
    plain_level = p;
    levels_used.push_back(s);
    const double error_px = bake.levels[static_cast<size_t>(s)].max_vertex_error_pct / 100 * px;
    EXPECT_TRUE(s == 0 || error_px <= 1.0) << "frame " << f << ": " << error_px << " px";
  }
  // Every level was used, once per threshold and direction.
  EXPECT_EQ(*std::max_element(levels_used.begin(), levels_used.end()), 2);
  EXPECT_EQ(*std::min_element(levels_used.begin(), levels_used.end()), 0);
  EXPECT_LE(steady_switches, 4);
  EXPECT_GE(steady_switches, 2);
  EXPECT_GT(plain_switches, 4 * steady_switches) << "the jitter straddles the thresholds";
}

TEST_F(ClientFlow, BakesClipsTogetherAndFetchesOneClipsFrames) {
  StartDaemon();
  ClientOptions options = Options();
  options.cache_dir = daemon_->dir() / "cache";
  Client client = MakeClient(options);
  auto file = ReadUploadFile(SamplePath());
  ASSERT_TRUE(file.ok());
  auto character = client.UploadCharacter({*file});
  ASSERT_TRUE(character.ok()) << character.error().ToString();
  api::BakeRequest request;
  request.character = character->value.id;
  request.clips = {"Walking_A", "Running_A"};
  request.levels = {12, 6};
  auto job = client.SubmitBake(request);
  ASSERT_TRUE(job.ok()) << job.error().ToString();
  auto bake = client.WaitForBake(job->id, {}, 300);
  ASSERT_TRUE(bake.ok()) << bake.error().ToString();
  ASSERT_EQ(bake->clips.size(), 2u);
  EXPECT_EQ(bake->ranking, "greedy");

  auto choice = client.ChooseLevel(bake->id, 100, 1.0, "Running_A");
  ASSERT_TRUE(choice.ok()) << choice.error().ToString();
  EXPECT_EQ(choice->clip, "Running_A");
  EXPECT_EQ(choice->url, "/v1/levels/" + choice->hash + "?clip=Running_A");
  auto whole = client.FetchLevel(choice->hash);
  ASSERT_TRUE(whole.ok()) << whole.error().ToString();
  EXPECT_EQ(whole->level_set().clip_count(), 2u);
  for (const api::BakeClip& clip : bake->clips) {
    auto level = client.FetchLevel(choice->hash, clip.animation);
    ASSERT_TRUE(level.ok()) << level.error().ToString();
    EXPECT_EQ(level->level().frame_count(), static_cast<uint32_t>(clip.frames));
    EXPECT_EQ(level->level_set().clip(0).name, clip.animation);
    EXPECT_TRUE(std::ranges::equal(level->level().kept_joints(), whole->level().kept_joints()));
  }
  const int downloads = client.fetch_stats().downloads;
  auto cached = client.FetchLevel(choice->hash, "Running_A");
  ASSERT_TRUE(cached.ok());
  EXPECT_EQ(client.fetch_stats().downloads, downloads);
  EXPECT_EQ(client.fetch_stats().cache_hits, 1);

  auto unknown = client.FetchLevel(choice->hash, "Moonwalk");
  ASSERT_FALSE(unknown.ok());
  EXPECT_EQ(unknown.error().http_status, 404);
  EXPECT_NE(unknown.error().message.find("'Walking_A', 'Running_A'"), std::string::npos)
      << unknown.error().message;
}

}  // namespace
}  // namespace motionlod::client::testing
