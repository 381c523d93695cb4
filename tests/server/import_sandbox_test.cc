// The import sandbox (server/import_sandbox.h) with the real worker executable: results
// identical to importing in-process, the importer's errors unchanged, and each limit
// turning into a clear InvalidArgument instead of taking anything else down.
#include "server/import_sandbox.h"

#include <gtest/gtest.h>

#include "io/asset_wire.h"
#include "tests/server/daemon.h"
#include "tests/server/hostile_inputs.h"

namespace motionlod::server {
namespace {

using testing::ReadFile;
using testing::SharedDataPath;
using testing::SourcePath;

std::unique_ptr<ImportSandbox> MakeSandbox(const ImportLimits& limits = {},
                                           const std::string& mode = "auto") {
  auto sandbox = ImportSandbox::Create(mode, MOTIONLOD_IMPORT_WORKER, limits);
  EXPECT_TRUE(sandbox.ok()) << sandbox.status().ToString();
  return sandbox.ok() ? std::move(*sandbox) : nullptr;
}

std::vector<io::SourceFile> Files(const std::vector<std::string>& paths) {
  std::vector<io::SourceFile> files;
  for (const std::string& path : paths) {
    files.push_back({std::filesystem::path(path).filename().string(), ReadFile(path)});
  }
  return files;
}

void ExpectLimitError(const StatusOr<std::shared_ptr<const io::Asset>>& result,
                      const std::string& reason) {
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(result.status().message().find(reason), std::string::npos) << result.status().message();
}

TEST(ImportSandbox, ResultsAreIdenticalToTheInProcessImport) {
  const std::unique_ptr<ImportSandbox> sandbox = MakeSandbox();
  ASSERT_NE(sandbox, nullptr);
  std::vector<std::vector<std::string>> uploads = {
      {SourcePath("samples/Rig_Medium_MovementBasic.glb")}};
  if (!SharedDataPath("MANIFEST.md").empty()) {
    for (const char* file : {"characters/CesiumMan.glb", "characters/stormtrooper.dae",
                             "motions/07_01_cmu.fbx", "motions/cmu_131_01.bvh"}) {
      uploads.push_back({SharedDataPath(file)});
    }
    uploads.push_back({SharedDataPath("characters/Superhero_Male_FullBody.gltf"),
                       SharedDataPath("characters/Superhero_Male_FullBody.bin")});
  }
  for (const auto& paths : uploads) {
    const std::vector<io::SourceFile> files = Files(paths);
    const auto in_process = io::LoadAsset(files);
    ASSERT_TRUE(in_process.ok()) << paths[0] << ": " << in_process.status().ToString();
    const auto isolated = sandbox->Import(files, {});
    ASSERT_TRUE(isolated.ok()) << paths[0] << ": " << isolated.status().ToString();
    // The encoding covers every field of the asset, bit for bit.
    EXPECT_EQ(io::EncodeImportReply(*isolated), io::EncodeImportReply(*in_process)) << paths[0];
  }
}

TEST(ImportSandbox, TheImportersErrorsComeBackUnchanged) {
  const std::unique_ptr<ImportSandbox> sandbox = MakeSandbox();
  ASSERT_NE(sandbox, nullptr);
  const std::vector<std::vector<io::SourceFile>> bad = {
      {{"hero.glb", "this is no glTF"}},
      {{"hero.obj", "v 0 0 0\n"}},
      {{"clip.bvh", "HIERARCHY\nROOT Hips\n{\n OFFSET 0 0"}},
  };
  for (const auto& files : bad) {
    const auto in_process = io::LoadAsset(files);
    const auto isolated = sandbox->Import(files, {});
    ASSERT_FALSE(in_process.ok());
    ASSERT_FALSE(isolated.ok());
    EXPECT_EQ(isolated.status().code(), in_process.status().code()) << files[0].name;
    EXPECT_EQ(isolated.status().message(), in_process.status().message());
  }
}

// A glTF whose buffer names a host file: the importer refuses the reference, and the
// sandboxed worker could not have opened it anyway (no /etc in its file system).
TEST(ImportSandbox, ABufferUriNamingAHostFileIsNeverRead) {
  const std::unique_ptr<ImportSandbox> sandbox = MakeSandbox();
  ASSERT_NE(sandbox, nullptr);
  for (const char* uri : {"/etc/passwd", "../../../../../etc/passwd", "file:///etc/passwd"}) {
    const auto result = sandbox->Import({{"hostile.gltf", testing::GltfWithBufferUri(uri)}}, {});
    ASSERT_FALSE(result.ok()) << uri;
    EXPECT_EQ(result.status().code(), StatusCode::kInvalidArgument) << result.status().ToString();
    EXPECT_EQ(result.status().message().find("root:"), std::string::npos);
  }
}

TEST(ImportSandbox, AWorkerPastTheWallClockLimitIsKilled) {
  ImportLimits limits;
  limits.wall_seconds = 0.001;  // the probe at creation runs under the default limits
  const std::unique_ptr<ImportSandbox> sandbox = MakeSandbox(limits);
  ASSERT_NE(sandbox, nullptr);
  ExpectLimitError(sandbox->Import(Files({SourcePath("samples/Rig_Medium_MovementBasic.glb")}), {}),
                   "(the wall-clock limit)");
}

TEST(ImportSandbox, AResultOverTheOutputLimitIsRefused) {
  ImportLimits limits;
  limits.output_bytes = 64 << 10;  // the sample's reply is about a megabyte
  const std::unique_ptr<ImportSandbox> sandbox = MakeSandbox(limits);
  ASSERT_NE(sandbox, nullptr);
  ExpectLimitError(sandbox->Import(Files({SourcePath("samples/Rig_Medium_MovementBasic.glb")}), {}),
                   "(the output limit)");
}

TEST(ImportSandbox, AWorkerOverTheAddressSpaceLimitFailsCleanly) {
#if defined(__SANITIZE_ADDRESS__)
  GTEST_SKIP() << "AddressSanitizer builds apply no address space limit";
#endif
  ImportLimits limits;
  limits.memory_bytes = int64_t{1} << 30;
  const std::unique_ptr<ImportSandbox> sandbox = MakeSandbox(limits);
  ASSERT_NE(sandbox, nullptr);
  ExpectLimitError(sandbox->Import({{"huge.x", testing::kHugeVertexCountX}}, {}), "out of memory");
}

// Under bubblewrap the worker runs behind the seccomp filter: a real import still gives
// the in-process result, and a probe worker's attempts at the denied system calls fail
// with EPERM (clone3 with ENOSYS, for the C library to fall back to clone) while fork and
// the personality query go through. The same probe as a plain process, without the
// filter, may open a socket: the EPERMs are the filter's doing.
TEST(ImportSandbox, TheSeccompFilterDeniesWhatTheWorkerNeverNeeds) {
  const std::unique_ptr<ImportSandbox> sandbox = MakeSandbox();
  ASSERT_NE(sandbox, nullptr);
  if (sandbox->isolation() != Isolation::kBubblewrap) {
    GTEST_SKIP() << "bubblewrap does not work here: " << sandbox->fallback_reason();
  }
  const std::vector<io::SourceFile> sample =
      Files({SourcePath("samples/Rig_Medium_MovementBasic.glb")});
  const auto in_process = io::LoadAsset(sample);
  ASSERT_TRUE(in_process.ok()) << in_process.status().ToString();
  const auto isolated = sandbox->Import(sample, {});
  ASSERT_TRUE(isolated.ok()) << isolated.status().ToString();
  EXPECT_EQ(io::EncodeImportReply(*isolated), io::EncodeImportReply(*in_process));

  const auto attempts = [](const ImportSandbox& probe, const std::vector<std::string>& calls) {
    std::vector<io::SourceFile> files;
    for (const std::string& call : calls) files.push_back({call, ""});
    const auto result = probe.Import(files, {});
    EXPECT_FALSE(result.ok());
    return result.ok() ? std::string() : result.status().message();
  };
  auto filtered = ImportSandbox::Create("bwrap", MOTIONLOD_SYSCALL_PROBE_WORKER, {});
  ASSERT_TRUE(filtered.ok()) << filtered.status().ToString();
  EXPECT_EQ(
      attempts(**filtered, {"socket", "perf_event_open", "io_uring_setup", "unshare",
                            "clone_newuser", "personality", "clone3", "fork", "personality_query"}),
      "socket=EPERM perf_event_open=EPERM io_uring_setup=EPERM "
      "unshare=EPERM clone_newuser=EPERM personality=EPERM clone3=ENOSYS fork=ok "
      "personality_query=ok");
#if !defined(__SANITIZE_ADDRESS__)  // LeakSanitizer needs ptrace: sanitizer builds allow it
  EXPECT_EQ(attempts(**filtered, {"ptrace"}), "ptrace=EPERM");
#endif
}

TEST(ImportSandbox, APlainProcessWorkerInstallsTheSameFilter) {
  // Where bubblewrap cannot run (a container's default seccomp profile), the plain
  // process installs the filter itself, right before exec.
  auto process = ImportSandbox::Create("process", MOTIONLOD_SYSCALL_PROBE_WORKER, {});
  ASSERT_TRUE(process.ok()) << process.status().ToString();
  std::vector<io::SourceFile> calls;
  for (const char* call : {"socket", "perf_event_open", "unshare", "clone3", "fork"}) {
    calls.push_back({call, ""});
  }
  const auto result = (*process)->Import(calls, {});
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.status().message(),
            "socket=EPERM perf_event_open=EPERM unshare=EPERM clone3=ENOSYS fork=ok");
}

TEST(ImportSandbox, ModesAndWorkerPathAreChecked) {
  const std::unique_ptr<ImportSandbox> process = MakeSandbox({}, "process");
  ASSERT_NE(process, nullptr);
  EXPECT_EQ(process->isolation(), Isolation::kProcess);
  EXPECT_EQ(ImportSandbox::Create("docker", MOTIONLOD_IMPORT_WORKER, {}).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(ImportSandbox::Create("auto", "/nonexistent/worker", {}).status().code(),
            StatusCode::kUnsupported);
  // Where bubblewrap works, "auto" picks it (the daemon logs which one it got).
  const std::unique_ptr<ImportSandbox> automatic = MakeSandbox();
  ASSERT_NE(automatic, nullptr);
  EXPECT_EQ(automatic->isolation() == Isolation::kBubblewrap, automatic->fallback_reason().empty());
}

}  // namespace
}  // namespace motionlod::server
