// The motionlod command as users run it: a real process, real files, exit codes.
#include <sys/wait.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "proto/level_format.h"
#include "tests/tools/gltf_validator.h"

namespace motionlod::tools {
namespace {

namespace fs = std::filesystem;

struct ProcessResult {
  int exit_code = -1;
  std::string output;  // stdout and stderr
};

// `environment`: assignments put before the command, e.g. "MOTIONLOD_SIMD=baseline".
ProcessResult Exec(const std::string& args, const std::string& environment = "") {
  const std::string command = environment + " " MOTIONLOD_TOOL " " + args + " 2>&1";
  ProcessResult run;
  FILE* pipe = ::popen(command.c_str(), "r");
  if (pipe == nullptr) return run;
  char buffer[4096];
  while (size_t n = std::fread(buffer, 1, sizeof buffer, pipe)) run.output.append(buffer, n);
  const int status = ::pclose(pipe);
  run.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return run;
}

std::string ReadAll(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

class Cli : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("motionlod_cli_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string Sample() const {
    return MOTIONLOD_SOURCE_DIR "/samples/Rig_Medium_MovementBasic.glb";
  }
  // The sample's Walking_A baked by cost for `heights` into `out`: the report's levels.
  nlohmann::json BakeForHeights(const fs::path& out, const std::string& heights) const {
    const ProcessResult bake = Exec("bake " + Sample() + " --threads 2 --animation Walking_A --heights " +
                                    heights + " --out " + out.string());
    EXPECT_EQ(bake.exit_code, 0) << bake.output;
    const nlohmann::json report = nlohmann::json::parse(ReadAll(out / "report.json"), nullptr, false);
    return report.is_object() ? report["levels"] : nlohmann::json::array();
  }
  fs::path dir_;
};

TEST_F(Cli, BakesTheSampleWithTheDefaultLadder) {
  const fs::path out = dir_ / "out";
  const ProcessResult run = Exec(Sample() + " --threads 2 --animation Walking_A --out " + out.string());
  ASSERT_EQ(run.exit_code, 2) << "a missing subcommand is a usage error: " << run.output;
  const ProcessResult bake = Exec("bake " + Sample() + " --threads 2 --animation Walking_A --out " + out.string());
  ASSERT_EQ(bake.exit_code, 0) << bake.output;
  EXPECT_NE(bake.output.find("max_px@1px"), std::string::npos) << bake.output;

  const nlohmann::json report = nlohmann::json::parse(ReadAll(out / "report.json"));
  EXPECT_EQ(report["character"]["joints"], 23);
  EXPECT_GT(report["character"]["vertices"].get<int>(), 6000);
  EXPECT_EQ(report["motion"]["fps"].get<double>(), 30.0);
  EXPECT_EQ(report["motion"]["frames"], 33);
  EXPECT_EQ(report["variant"], "vpno+pd");
  EXPECT_GT(report["timing"]["bake_seconds"].get<double>(), 0.0);
  EXPECT_GT(report["timing"]["skinning_pass_seconds"].get<double>(), 0.0);
  const auto& levels = report["levels"];
  ASSERT_GE(levels.size(), 4u);
  EXPECT_EQ(levels[0]["joints"], 23);
  EXPECT_TRUE(levels[0]["max_px_for_1px_error"].is_null() ||
              levels[0]["max_px_for_1px_error"].get<double>() > 1e4);
  for (size_t l = 1; l < levels.size(); ++l) {
    // Levels by cost: each cheaper than the one before, never keeping more joints.
    EXPECT_LE(levels[l]["joints"].get<int>(), levels[l - 1]["joints"].get<int>());
    EXPECT_LT(levels[l]["cost"].get<double>(), levels[l - 1]["cost"].get<double>());
    for (const char* field : {"removed", "vertices", "triangles", "mean_influences", "frame_stride",
                              "stream_bytes_per_second", "cost", "mean_E", "baseline_mean_E",
                              "max_vertex_error_pct", "baseline_max_vertex_error_pct",
                              "mean_vertex_error_pct", "mean_normal_error_deg", "max_px_for_1px_error"}) {
      EXPECT_TRUE(levels[l].contains(field)) << field;
    }
    EXPECT_EQ(levels[l]["removed"].size(), 23u - levels[l]["joints"].get<unsigned>());
  }
  const std::string bytes = ReadAll(out / "levels.mlod");
  const proto::AlignedBytes aligned = proto::AlignedBytes::CopyOf(bytes);
  auto view = proto::DecodeLevelSet(aligned.bytes());
  ASSERT_TRUE(view.ok()) << view.status().ToString();
  EXPECT_EQ(view->level_count(), levels.size());
  EXPECT_EQ(view->frame_count(), 33u);
  // Nothing but the two outputs, no temporary left behind.
  int entries = 0;
  for ([[maybe_unused]] const auto& e : fs::directory_iterator(dir_)) ++entries;
  EXPECT_EQ(entries, 1);

  const ProcessResult plot = Exec("plot " + (out / "report.json").string() + " -o " + (dir_ / "fig.svg").string());
  ASSERT_EQ(plot.exit_code, 0) << plot.output;
  const std::string svg = ReadAll(dir_ / "fig.svg");
  EXPECT_NE(svg.find("<polyline"), std::string::npos);
  EXPECT_NE(svg.find("vpno+pd"), std::string::npos);
}

// --heights: the levels by cost for the heights asked, each within 1 px at its height.
TEST_F(Cli, BakesTheLevelsForTheHeightsAsked) {
  const fs::path out = dir_ / "out";
  const nlohmann::json levels = BakeForHeights(out, "60,24");
  ASSERT_EQ(levels.size(), 3u) << "full detail, then one level per height";
  EXPECT_EQ(levels[0]["cost"].get<double>(), 1.0);
  const double heights[] = {60, 24};
  for (size_t l = 1; l < levels.size(); ++l) {
    EXPECT_LT(levels[l]["cost"].get<double>(), levels[l - 1]["cost"].get<double>());
    EXPECT_LE(levels[l]["max_vertex_error_pct"].get<double>(), 100.0 / heights[l - 1]);
    EXPECT_GE(levels[l]["max_px_for_1px_error"].get<double>(), heights[l - 1]);
  }
  EXPECT_LT(levels[2]["vertices"].get<int>(), levels[0]["vertices"].get<int>());
}

// Both machine versions of the hot loops (core/simd.h) bake the same levels: the figures
// agree to the rounding of fused multiply-adds. On a CPU without AVX2 and FMA both runs
// are the baseline version.
TEST_F(Cli, TheAvx2AndBaselineVersionsReportTheSameFigures) {
  nlohmann::json reports[2];
  for (int forced = 0; forced < 2; ++forced) {
    const fs::path out = dir_ / (forced ? "baseline" : "widest");
    const ProcessResult bake =
        Exec("bake " + Sample() + " --threads 2 --animation Walking_A --all-levels --out " + out.string(),
             forced ? "MOTIONLOD_SIMD=baseline" : "");
    ASSERT_EQ(bake.exit_code, 0) << bake.output;
    reports[forced] = nlohmann::json::parse(ReadAll(out / "report.json"));
  }
  const nlohmann::json& widest = reports[0];
  const nlohmann::json& baseline = reports[1];
  EXPECT_EQ(baseline["timing"]["simd"], "baseline");
  const std::string widest_name = widest["timing"]["simd"].get<std::string>();
  EXPECT_TRUE(widest_name == "avx2-fma" || widest_name == "baseline" || widest_name == "native")
      << widest_name;
  ASSERT_EQ(widest["levels"].size(), 23u);
  ASSERT_EQ(baseline["levels"].size(), 23u);
  for (size_t l = 0; l < 23; ++l) {
    const nlohmann::json& a = widest["levels"][l];
    const nlohmann::json& b = baseline["levels"][l];
    EXPECT_EQ(a["removed"], b["removed"]);
    for (const char* field : {"mean_E", "baseline_mean_E", "max_vertex_error_pct",
                              "baseline_max_vertex_error_pct", "mean_vertex_error_pct",
                              "mean_normal_error_deg"}) {
      const double x = a[field].get<double>(), y = b[field].get<double>();
      EXPECT_NEAR(x, y, 1e-5 * std::abs(x) + 1e-9) << field << " at " << a["joints"] << " joints";
    }
  }
}

TEST_F(Cli, AnUnknownSimdSettingIsAUsageError) {
  const fs::path out = dir_ / "out";
  const ProcessResult bake = Exec("bake " + Sample() + " --levels 23,9 --out " + out.string(),
                                  "MOTIONLOD_SIMD=avx512");
  EXPECT_EQ(bake.exit_code, 2) << bake.output;
  EXPECT_NE(bake.output.find("MOTIONLOD_SIMD is 'avx512'"), std::string::npos) << bake.output;
  EXPECT_FALSE(fs::exists(out));
}

TEST_F(Cli, RankPrintsTheRemovalOrderWithTheRootLast) {
  // The paper's order: by priority.
  const ProcessResult paper_run = Exec("rank " + Sample() + " --animation Running_A --ranking paper --json");
  ASSERT_EQ(paper_run.exit_code, 0) << paper_run.output;
  const nlohmann::json paper = nlohmann::json::parse(paper_run.output);
  ASSERT_EQ(paper.size(), 23u);
  EXPECT_EQ(paper.back()["index"], 0);
  EXPECT_FALSE(paper.back()["removable"].get<bool>());
  for (size_t r = 1; r + 1 < paper.size(); ++r) {
    EXPECT_LE(paper[r - 1]["priority"].get<double>(), paper[r]["priority"].get<double>());
    EXPECT_EQ(paper[r]["paper_rank"], r + 1);
    EXPECT_TRUE(paper[r]["removal_error_pct"].is_null());
  }
  // The default, greedy by error: every removable joint with the error its removal left,
  // the paper's rank beside it.
  const ProcessResult greedy_run = Exec("rank " + Sample() + " --animation Running_A --json");
  ASSERT_EQ(greedy_run.exit_code, 0) << greedy_run.output;
  const nlohmann::json greedy = nlohmann::json::parse(greedy_run.output);
  ASSERT_EQ(greedy.size(), 23u);
  EXPECT_EQ(greedy.back()["index"], 0);
  std::vector<int> paper_ranks;
  for (size_t r = 0; r + 1 < greedy.size(); ++r) {
    EXPECT_GE(greedy[r]["removal_error_pct"].get<double>(), 0.0);
    paper_ranks.push_back(greedy[r]["paper_rank"].get<int>());
  }
  std::sort(paper_ranks.begin(), paper_ranks.end());
  for (size_t r = 0; r < paper_ranks.size(); ++r) EXPECT_EQ(paper_ranks[r], static_cast<int>(r) + 1);
  EXPECT_NE(greedy, paper);
  const ProcessResult wrong = Exec("rank " + Sample() + " --ranking random");
  EXPECT_EQ(wrong.exit_code, 2);
  EXPECT_NE(wrong.output.find("expected greedy or paper"), std::string::npos) << wrong.output;
}

TEST_F(Cli, BadInputExitsWithTwoAndWritesNothing) {
  const fs::path truncated = dir_ / "truncated.glb";
  {
    const std::string bytes = ReadAll(Sample());
    std::ofstream(truncated, std::ios::binary) << bytes.substr(0, bytes.size() / 3);
  }
  const fs::path garbage = dir_ / "garbage.fbx";
  std::ofstream(garbage) << "this is not an FBX file";
  const fs::path out = dir_ / "out";
  struct Case {
    std::string args;
    std::string message;
  };
  const Case cases[] = {
      {"bake " + (dir_ / "missing.glb").string() + " --out " + out.string(), "missing.glb"},
      {"bake " + truncated.string() + " --out " + out.string(), "truncated.glb"},
      {"bake " + garbage.string() + " --out " + out.string(), "garbage.fbx"},
      {"bake " + Sample() + " --variant vpx --out " + out.string(), "unknown variant"},
      {"bake " + Sample() + " --levels 40 --out " + out.string(), "outside"},
      {"bake " + Sample() + " --animation Nope --out " + out.string(), "Nope"},
      {"bake " + Sample() + " --lock NoSuchJoint --out " + out.string(), "NoSuchJoint"},
      {"bake " + Sample() + " --fps -3 --out " + out.string(), "fps"},
      {"bake " + Sample() + " --threads 100000 --out " + out.string(), "threads must be in [0, 256]"},
      {"bake " + Sample() + " --heights 50,400 --out " + out.string(), "ladder heights must decrease"},
      {"bake " + Sample() + " --heights 0.5 --out " + out.string(), "ladder heights must decrease"},
      {"bake " + Sample() + " --heights 50 --levels 10 --out " + out.string(), "excludes"},
      {"bake " + Sample(), "--out"},
      {"plot " + truncated.string() + " -o " + (dir_ / "x.svg").string(), "not valid JSON"},
  };
  for (const Case& c : cases) {
    const ProcessResult run = Exec(c.args);
    EXPECT_EQ(run.exit_code, 2) << c.args << "\n" << run.output;
    EXPECT_NE(run.output.find(c.message), std::string::npos) << c.args << "\n" << run.output;
    EXPECT_FALSE(fs::exists(out)) << c.args;
  }
}

std::string DataFile(const std::string& relative) {
  return (fs::path(MOTIONLOD_SHARED_DATA) / relative).string();
}

// Joint nodes, skin joints and animation channels of an exported level.
void ExpectGltfLevel(const fs::path& glb, int joints, bool rigid) {
  const nlohmann::json gltf = testing::GlbJson(ReadAll(glb));
  ASSERT_TRUE(gltf.is_object()) << glb << " is no GLB";
  EXPECT_EQ(gltf["asset"]["version"], "2.0");
  EXPECT_EQ(gltf["nodes"].size(), static_cast<size_t>(joints) + 1)
      << "joint nodes and the mesh node";
  EXPECT_EQ(gltf["skins"][0]["joints"].size(), static_cast<size_t>(joints));
  EXPECT_EQ(gltf["animations"][0]["channels"].size(), static_cast<size_t>(joints) * (rigid ? 2 : 3))
      << "translation and rotation per joint, and scale when not rigid";
}

// `motionlod export` on real characters at several levels and variants: each file passes
// the Khronos validator with zero errors and holds the level's skeleton and channels.
TEST_F(Cli, ExportsLevelsThatTheGltfValidatorAccepts) {
  if (!fs::exists(DataFile("MANIFEST.md"))) GTEST_SKIP() << "no ../shared/data";
  struct Case {
    std::string args;
    int joints;
    bool rigid;
  };
  const Case cases[] = {
      {DataFile("characters/CesiumMan.glb") + " --joints 8", 8, true},
      {DataFile("characters/CesiumMan.glb"), 19, true},  // full detail: every joint
      {DataFile("characters/Fox.glb") + " --animation Walk --variant vp --joints 10", 10, false},
      {DataFile("characters/Orc.gltf") + " --animation Walk --variant vpno --joints 20", 20, false},
      {DataFile("characters/stormtrooper.dae") + " --variant vp+pd --joints 25", 25, true},
      {DataFile("characters/Knight.glb") + " --motion " +
           DataFile("characters/Rig_Medium_General.glb") + " --animation Idle_A --joints 12",
       12, true},
  };
  std::vector<fs::path> files;
  for (const Case& c : cases) {
    const fs::path glb = dir_ / ("level" + std::to_string(files.size()) + ".glb");
    const ProcessResult run = Exec("export " + c.args + " --threads 2 --out " + glb.string());
    ASSERT_EQ(run.exit_code, 0) << c.args << "\n" << run.output;
    EXPECT_NE(run.output.find("max vertex deviation"), std::string::npos) << run.output;
    ExpectGltfLevel(glb, c.joints, c.rigid);
    files.push_back(glb);
  }
  testing::ExpectValidGltf(files);
}

// From a baked level set: the level asked for, or exit 2 naming the levels there are.
TEST_F(Cli, ExportsALevelOfABakedLevelSet) {
  const fs::path out = dir_ / "out";
  const ProcessResult bake =
      Exec("bake " + Sample() + " --threads 2 --animation Walking_A --levels 23,9 --out " +
           out.string());
  ASSERT_EQ(bake.exit_code, 0) << bake.output;
  const fs::path glb = dir_ / "nine.glb";
  const std::string from = " --level-set " + (out / "levels.mlod").string();
  const ProcessResult run = Exec("export " + Sample() + from + " --joints 9 --out " + glb.string());
  ASSERT_EQ(run.exit_code, 0) << run.output;
  ExpectGltfLevel(glb, 9, true);
  testing::ExpectValidGltf({glb});

  const ProcessResult missing =
      Exec("export " + Sample() + from + " --joints 5 --out " + (dir_ / "five.glb").string());
  EXPECT_EQ(missing.exit_code, 2) << missing.output;
  EXPECT_NE(missing.output.find("the levels keep 23, 9"), std::string::npos) << missing.output;
  EXPECT_FALSE(fs::exists(dir_ / "five.glb"));
}

// Levels by cost carry their own mesh and influences: `--level I` exports them as they are
// (the level's vertices and triangles, its influences), into a directory made for it.
TEST_F(Cli, ExportsEachLevelByCostWithItsOwnMesh) {
  const fs::path out = dir_ / "out";
  const nlohmann::json levels = BakeForHeights(out, "60,24");
  ASSERT_EQ(levels.size(), 3u);
  const std::string from = " --level-set " + (out / "levels.mlod").string();
  std::vector<fs::path> files;
  for (size_t l = 0; l < levels.size(); ++l) {
    const fs::path glb = dir_ / "made" / "here" / ("level" + std::to_string(l) + ".glb");
    const ProcessResult run = Exec("export " + Sample() + from + " --level " + std::to_string(l) +
                                   " --out " + glb.string());
    ASSERT_EQ(run.exit_code, 0) << run.output;
    const int joints = levels[l]["joints"].get<int>();
    ExpectGltfLevel(glb, joints, true);
    const nlohmann::json gltf = testing::GlbJson(ReadAll(glb));
    const nlohmann::json& primitive = gltf["meshes"][0]["primitives"][0];
    const nlohmann::json& accessors = gltf["accessors"];
    EXPECT_EQ(accessors[primitive["attributes"]["POSITION"].get<int>()]["count"],
              levels[l]["vertices"]);
    EXPECT_EQ(accessors[primitive["attributes"]["JOINTS_0"].get<int>()]["count"],
              levels[l]["vertices"]);
    EXPECT_EQ(accessors[primitive["indices"].get<int>()]["count"].get<int>(),
              3 * levels[l]["triangles"].get<int>());
    EXPECT_NE(run.output.find(std::to_string(levels[l]["vertices"].get<int>()) + " vertices"),
              std::string::npos)
        << run.output;
    files.push_back(glb);
  }
  EXPECT_LT(levels[2]["vertices"].get<int>(), levels[0]["vertices"].get<int>());
  testing::ExpectValidGltf(files);

  const ProcessResult missing =
      Exec("export " + Sample() + from + " --level 3 --out " + (dir_ / "x.glb").string());
  EXPECT_EQ(missing.exit_code, 2) << missing.output;
  EXPECT_NE(missing.output.find("no level 3; the level set has 3"), std::string::npos)
      << missing.output;
  const ProcessResult both = Exec("export " + Sample() + from + " --level 1 --joints 9 --out " +
                                  (dir_ / "x.glb").string());
  EXPECT_EQ(both.exit_code, 2) << both.output;
  const ProcessResult no_set =
      Exec("export " + Sample() + " --level 1 --out " + (dir_ / "x.glb").string());
  EXPECT_EQ(no_set.exit_code, 2) << no_set.output;
  EXPECT_FALSE(fs::exists(dir_ / "x.glb"));
}

TEST_F(Cli, ExportBadInputExitsWithTwoAndWritesNothing) {
  const fs::path out = dir_ / "out";
  ASSERT_EQ(Exec("bake " + Sample() + " --threads 2 --levels 23 --out " + out.string()).exit_code,
            0);
  const fs::path glb = dir_ / "x.glb";
  const fs::path garbage = dir_ / "garbage.mlod";
  std::ofstream(garbage) << "not a level set";
  struct Case {
    std::string args;
    std::string message;
  };
  std::vector<Case> cases = {
      {(dir_ / "missing.glb").string(), "missing.glb"},
      {Sample() + " --joints 40", "outside"},
      {Sample() + " --joints 0", "--joints"},
      {Sample() + " --variant vpx", "unknown variant"},
      {Sample() + " --animation Nope", "Nope"},
      {Sample() + " --level-set " + (dir_ / "none.mlod").string(), "none.mlod"},
      {Sample() + " --level-set " + garbage.string(), "garbage.mlod"},
  };
  if (fs::exists(DataFile("MANIFEST.md"))) {
    // A level set of another character.
    cases.push_back({DataFile("characters/Fox.glb") + " --level-set " +
                         (out / "levels.mlod").string() + " --joints 23",
                     "another character"});
  }
  for (const Case& c : cases) {
    const ProcessResult run = Exec("export " + c.args + " --out " + glb.string());
    EXPECT_EQ(run.exit_code, 2) << c.args << "\n" << run.output;
    EXPECT_NE(run.output.find(c.message), std::string::npos) << c.args << "\n" << run.output;
    EXPECT_FALSE(fs::exists(glb)) << c.args;
  }
}

}  // namespace
}  // namespace motionlod::tools
