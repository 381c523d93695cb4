// The real daemon imports uploads in its sandboxed worker (server/import_sandbox.h): what
// an upload reports equals the in-process import, and hostile uploads (a buffer naming a
// host file, a mesh that allocates gigabytes, an import past the time limit) become 422
// problems naming the reason while the daemon goes on serving.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <fstream>

#include "io/asset.h"
#include "tests/server/hostile_inputs.h"
#include "tests/server/test_util.h"

namespace motionlod::server::testing {
namespace {

TEST(DaemonImport, UploadsAreImportedInTheSandboxWithTheInProcessResult) {
  Daemon daemon(TestDirectory());
  ASSERT_TRUE(daemon.Start()) << daemon.error;
  // The isolation in use is logged at start-up.
  const std::string log = daemon.Log();
  EXPECT_TRUE(log.find("imports run in a bwrap sandbox") != std::string::npos ||
              log.find("imports run as plain processes with limits only") != std::string::npos)
      << log;
  auto client = daemon.Client();
  std::vector<std::string> paths = {Sample()};
  if (!SharedDataPath("MANIFEST.md").empty()) {
    paths.push_back(SharedDataPath("characters/CesiumMan.glb"));
    paths.push_back(SharedDataPath("characters/stormtrooper.dae"));
  }
  for (const std::string& path : paths) {
    const std::string name = std::filesystem::path(path).filename().string();
    auto uploaded = UploadFile(*client, path, name);
    ASSERT_TRUE(uploaded);
    ASSERT_EQ(uploaded->status, 201) << uploaded->body;
    const json character = Json(uploaded);
    const auto asset = io::LoadAsset({{name, ReadFile(path)}});
    ASSERT_TRUE(asset.ok()) << asset.status().ToString();
    const core::RawCharacter& raw = (*asset)->character();
    EXPECT_EQ(character["joints"], raw.skeleton.parents.size()) << name;
    EXPECT_EQ(character["vertices"], raw.skin.positions.size());
    EXPECT_EQ(character["triangles"], raw.skin.triangles.size());
    EXPECT_EQ(character["joint_names"].get<std::vector<std::string>>(), raw.skeleton.joint_names);
    EXPECT_EQ(character["proxy_skin"], (*asset)->has_proxy_skin());
    EXPECT_EQ(character["warnings"].get<std::vector<std::string>>(), (*asset)->warnings());
    ASSERT_EQ(character["animations"].size(), (*asset)->animations().size());
    for (size_t k = 0; k < (*asset)->animations().size(); ++k) {
      const io::AnimationInfo& info = (*asset)->animations()[k];
      const json& motion = character["animations"][k];
      EXPECT_EQ(motion["animation"], info.name);
      EXPECT_EQ(motion["frames"], info.source_frame_count);
      EXPECT_EQ(motion["source_fps"].get<double>(), info.source_fps);
      EXPECT_EQ(motion["duration_seconds"].get<double>(), info.duration_seconds);
    }
  }
}

TEST(DaemonImport, HostileUploadsAre422NamingTheReasonAndTheDaemonCarriesOn) {
  Daemon daemon(TestDirectory());
  ASSERT_TRUE(daemon.Start({"--import-memory-bytes", "1073741824"})) << daemon.error;
  auto client = daemon.Client();

  auto passwd = UploadBytes(*client, "hostile.gltf", GltfWithBufferUri("/etc/passwd"));
  ExpectProblem(passwd, 422, "/etc/passwd");
  ASSERT_TRUE(passwd);
  EXPECT_EQ(passwd->body.find("root:"), std::string::npos);

#if !defined(__SANITIZE_ADDRESS__)  // AddressSanitizer builds apply no address space limit
  ExpectProblem(UploadBytes(*client, "huge.x", kHugeVertexCountX), 422,
                "the importer ran out of memory");
#endif

  // The daemon is the same process and serves every other request.
  EXPECT_TRUE(daemon.running());
  auto health = client->Get("/healthz");
  ASSERT_TRUE(health);
  EXPECT_EQ(health->status, 200);
  auto uploaded = UploadFile(*client, Sample(), "sample.glb");
  ASSERT_TRUE(uploaded);
  EXPECT_EQ(uploaded->status, 201) << uploaded->body;
  EXPECT_EQ(Json(uploaded)["joints"], 23);
}

TEST(DaemonImport, AnImportPastTheWallClockLimitIs422AndNothingIsStored) {
  Daemon daemon(TestDirectory());
  // Set low enough that a real file exceeds it (the start-up probe uses default limits).
  ASSERT_TRUE(daemon.Start({"--import-timeout-seconds", "0.001"})) << daemon.error;
  auto client = daemon.Client();
  ExpectProblem(UploadFile(*client, Sample(), "sample.glb"), 422,
                "took longer than 0.001 s (the wall-clock limit) and was stopped");
  auto list = client->Get("/v1/characters");
  ASSERT_TRUE(list);
  EXPECT_EQ(list->status, 200);
  EXPECT_TRUE(Json(list)["characters"].empty()) << list->body;  // nothing half-imported stored
}

TEST(DaemonImport, AnSmdThatHangsAssimpIs422AtTheCpuLimitAndTheDaemonCarriesOn) {
  Daemon daemon(TestDirectory());
  ASSERT_TRUE(daemon.Start({"--import-cpu-seconds", "2"})) << daemon.error;
  auto client = daemon.Client();
  ExpectProblem(UploadBytes(*client, "hang.smd", kHangingSmd), 422,
                "used more than 2 s of CPU time (the CPU limit) and was stopped");
  auto uploaded = UploadFile(*client, Sample(), "sample.glb");
  ASSERT_TRUE(uploaded);
  EXPECT_EQ(uploaded->status, 201) << uploaded->body;
}

// tests/data/assimp_x_bad_free.x (532 bytes, found by import_x_fuzz on 2026-11-22): a
// DirectX skin whose weights name vertex 4 of 3 makes Assimp 5.2 free a pointer it did
// not allocate when it destroys the scene (AddressSanitizer: "attempting free on address
// which was not malloc()-ed" in aiScene::~aiScene). It corrupts only the worker's heap.
TEST(DaemonImport, AnXFileThatCorruptsAssimpsHeapIs422AndTheDaemonCarriesOn) {
  Daemon daemon(TestDirectory());
  ASSERT_TRUE(daemon.Start()) << daemon.error;
  auto client = daemon.Client();
  ExpectProblem(UploadFile(*client, SourcePath("tests/data/assimp_x_bad_free.x"), "bad.x"), 422);
  auto uploaded = UploadFile(*client, Sample(), "sample.glb");
  ASSERT_TRUE(uploaded);
  EXPECT_EQ(uploaded->status, 201) << uploaded->body;
}

// Inputs import_glb_fuzz and import_fbx_fuzz found (2026-11-22): Assimp leaks memory on
// them (a glTF chunk buffer when an accessor's data is null; an FBX zlib stream), which in
// the daemon's one-shot worker costs nothing. Held as byte patches of the data files they
// were mutated from (the inputs are 0.4 and 0.5 MB); the daemon must answer what the
// in-process import answers.
struct BytePatch {
  size_t offset;
  unsigned char before, after;
};

TEST(DaemonImport, FuzzerFindingsInsideAssimpGetTheInProcessAnswer) {
  if (SharedDataPath("MANIFEST.md").empty()) GTEST_SKIP() << "shared data absent";
  struct Finding {
    const char* file;
    std::vector<BytePatch> patches;
  };
  const Finding findings[] = {
      {"characters/CesiumMan.glb",
       {{15910, 0x66, 0x62}, {187660, 0x7d, 0x79}, {209684, 0x03, 0xf7}, {432338, 0xf1, 0xd1}}},
      {"motions/07_01_cmu.fbx", {{332518, 0xe5, 0xb3}, {332520, 0xb3, 0xe5}}},
  };
  Daemon daemon(TestDirectory());
  ASSERT_TRUE(daemon.Start()) << daemon.error;
  auto client = daemon.Client();
  for (const Finding& finding : findings) {
    std::string bytes = ReadFile(SharedDataPath(finding.file));
    for (const BytePatch& patch : finding.patches) {
      ASSERT_EQ(static_cast<unsigned char>(bytes.at(patch.offset)), patch.before) << finding.file;
      bytes[patch.offset] = static_cast<char>(patch.after);
    }
    const std::string name = std::filesystem::path(finding.file).filename().string();
    const auto in_process = io::LoadAsset({{name, bytes}});
    auto uploaded = UploadBytes(*client, name, bytes);
    if (in_process.ok()) {
      ASSERT_TRUE(uploaded);
      EXPECT_EQ(uploaded->status, 201) << uploaded->body;
      EXPECT_EQ(Json(uploaded)["joints"], in_process.value()->character().skeleton.parents.size());
    } else {
      ExpectProblem(uploaded, 422, in_process.status().message());
    }
  }
  auto health = client->Get("/healthz");
  ASSERT_TRUE(health);
  EXPECT_EQ(health->status, 200);
}

// Kills and counts the processes whose command line names `worker` (a path no other test
// uses).
int KillProcessesNaming(const std::string& worker) {
  int found = 0;
  for (const auto& entry : std::filesystem::directory_iterator("/proc")) {
    const std::string name = entry.path().filename().string();
    if (name.find_first_not_of("0123456789") != std::string::npos) continue;
    std::ifstream cmdline(entry.path() / "cmdline");
    const std::string text((std::istreambuf_iterator<char>(cmdline)),
                           std::istreambuf_iterator<char>());
    if (text.find(worker) == std::string::npos) continue;
    kill(std::stoi(name), SIGKILL);
    ++found;
  }
  return found;
}

// bubblewrap clears the parent-death signal while it sets a sandbox up, so a daemon killed
// in those milliseconds left bubblewrap and its worker running for good. The guardian
// between them (server/import_sandbox.cc) takes bubblewrap along: kills at 40 moments of
// the start-up (its probe import) leave nothing behind. The daemons run their own copy of
// the worker, so only their sandboxes can match. Without the guardian one run of this
// test in three found a survivor: it can miss the bug, never invent it.
TEST(DaemonImport, ADaemonKilledWhileASandboxStartsLeavesNoProcessBehind) {
  const std::filesystem::path dir = TestDirectory();
  const std::string worker = (dir / "motionlod-import-worker").string();
  std::filesystem::copy_file(
      std::filesystem::path(MOTIONLODD).parent_path() / "motionlod-import-worker", worker);
  for (int k = 0; k < 40; ++k) {
    const std::string data = (dir / ("data" + std::to_string(k))).string();
    const pid_t pid = fork();
    if (pid == 0) {
      const int null = open("/dev/null", O_WRONLY);
      dup2(null, STDOUT_FILENO);
      dup2(null, STDERR_FILENO);
      execl(MOTIONLODD, MOTIONLODD, "--port", "0", "--data-dir", data.c_str(), "--import-worker",
            worker.c_str(), nullptr);
      _exit(127);
    }
    ASSERT_GT(pid, 0);
    std::this_thread::sleep_for(std::chrono::milliseconds(5 + 10 * k));
    kill(pid, SIGKILL);
    waitpid(pid, nullptr, 0);
  }
  std::this_thread::sleep_for(std::chrono::seconds(1));  // sandboxes still setting up
  EXPECT_EQ(KillProcessesNaming(worker), 0);
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace motionlod::server::testing
