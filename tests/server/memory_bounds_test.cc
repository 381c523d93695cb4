// The daemon's memory follows its configuration, not what an upload declares: the worst
// uploads of the hostile set (BVHs of 20,000 and 100,000 flat joints, which once took the
// daemon to 2.9 GB and held both import slots for minutes) are refused by the import
// worker in a moment, a normal upload meanwhile succeeds, the daemon's peak resident
// memory stays within a stated budget, and a level export past max_export_bytes is
// refused before it is built.
#include <gtest/gtest.h>

#include <fstream>
#include <thread>

#include "tests/fixtures/flat_bvh.h"
#include "tests/server/test_util.h"

namespace motionlod::server::testing {
namespace {

using Clock = std::chrono::steady_clock;
using motionlod::testing::FlatBvh;

// A line of /proc/PID/status in bytes ("VmHWM", "VmRSS"), -1 when absent.
int64_t StatusBytes(pid_t pid, const std::string& field) {
  std::ifstream status("/proc/" + std::to_string(pid) + "/status");
  std::string line;
  while (std::getline(status, line)) {
    if (line.rfind(field + ":", 0) == 0) return std::atoll(line.c_str() + field.size() + 1) * 1024;
  }
  return -1;
}

TEST(MemoryBounds, TheWorstUploadsAreRefusedQuicklyWithinTheMemoryBudget) {
  Daemon daemon(TestDirectory());
  ASSERT_TRUE(daemon.Start()) << daemon.error;
  const std::string wide = FlatBvh(20000, 2);
  const std::string wider = FlatBvh(100000, 2);
  ASSERT_GT(wider.size(), size_t{10} << 20);

  // Both import slots (max_concurrent_imports = 2) taken by the widest file at once,
  // then a normal upload: each hostile one is refused within seconds, naming the limit.
  const auto start = Clock::now();
  std::vector<std::thread> hostile;
  std::vector<int> statuses(2, 0);
  std::vector<std::string> details(2);
  for (int i = 0; i < 2; ++i) {
    hostile.emplace_back([&, i] {
      auto result = UploadBytes(*daemon.Client(), "wide" + std::to_string(i) + ".bvh", wider);
      if (!result) return;
      statuses[i] = result->status;
      details[i] = Json(result).value("detail", "");
    });
  }
  for (std::thread& thread : hostile) thread.join();
  for (int i = 0; i < 2; ++i) {
    EXPECT_EQ(statuses[i], 422);
    EXPECT_NE(details[i].find("declares 100000 joints, more than the limit of 1024 (max_joints)"),
              std::string::npos)
        << details[i];
  }
  auto client = daemon.Client();
  ExpectProblem(UploadBytes(*client, "wide.bvh", wide), 422, "(max_joints)");
  EXPECT_LT(Clock::now() - start, std::chrono::seconds(20));
  auto normal = UploadFile(*client, Sample(), "rig.glb");
  ASSERT_TRUE(normal);
  EXPECT_EQ(normal->status, 201) << normal->body;

  // Within every limit but one: 1000 joints of 4001 frames pass max_joints and
  // max_frames, not joints x frames (4 M).
  ExpectProblem(UploadBytes(*client, "long.bvh", FlatBvh(1000, 4001)), 422, "(max_joint_frames)");

  // The budget: 512 MiB for everything (the level cache is empty here). The 12 MB
  // bodies are held while received, no asset is ever built from them.
  const int64_t peak = StatusBytes(daemon.pid(), "VmHWM");
  std::printf("daemon peak resident memory: %.1f MiB\n", static_cast<double>(peak) / (1 << 20));
  EXPECT_GT(peak, 0);
  EXPECT_LT(peak, int64_t{512} << 20);
}

TEST(MemoryBounds, AnExportPastMaxExportBytesIsRefusedBeforeItIsBuilt) {
  Daemon daemon(TestDirectory());
  ASSERT_TRUE(daemon.Start({"--max-export-bytes", "100000"})) << daemon.error;
  auto client = daemon.Client();
  ASSERT_EQ(UploadFile(*client, Sample(), "rig.glb")->status, 201);
  auto submitted =
      SubmitBake(*client, {{"character", kSampleId}, {"motion", "Walking_A"}, {"levels", {17, 6}}});
  ASSERT_TRUE(submitted);
  const std::string id = Json(submitted)["id"];
  ASSERT_EQ(WaitForJob(*client, id).value("state", ""), "succeeded");
  ExpectProblem(client->Get(("/v1/bakes/" + id + "/levels/6.glb").c_str()), 422,
                "more than max_export_bytes");
}

}  // namespace
}  // namespace motionlod::server::testing
