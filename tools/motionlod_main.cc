// motionlod: the command-line bake tool.
//   motionlod info CHARACTER
//   motionlod rank CHARACTER [--motion M] [--animation NAME]... [--fps F] [--lock J,...] [--json]
//   motionlod bake CHARACTER [--motion M] [--animation NAME]...
//                  [--levels 30,20,10,5 | --all-levels | --heights 800,400,...]
//                  [--variant vpno+pd] [--fps F] [--lock J,...] [--threads N] [--curves] --out DIR
//   motionlod export CHARACTER [--motion M] [--animation NAME]... [--variant vpno+pd] [--fps F]
//                    [--lock J,...] [--joints N] [--level-set DIR/levels.mlod [--level I]]
//                    --out FILE.glb
//   motionlod plot REPORT.json -o FIG.svg
// Exit codes: 0 success, 2 bad input (usage, unreadable or invalid files, impossible
// requests), 1 failure to write the output.
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "core/greedy_ranking.h"
#include "core/solve_levels.h"
#include "io/asset.h"
#include "io/sha256.h"
#include "pipeline/allocator.h"
#include "pipeline/bake.h"
#include "pipeline/export.h"
#include "pipeline/report.h"
#include "tools/atomic_output.h"
#include "tools/plot_svg.h"

namespace motionlod::tools {
namespace {

constexpr int kExitOutput = 1;
constexpr int kExitBadInput = 2;

int Fail(const Status& status, int code = kExitBadInput) {
  std::cerr << "motionlod: error: " << status.message() << "\n";
  return code;
}

struct CommonOptions {
  std::string character;
  std::string motion;
  std::vector<std::string> animations;
  double fps = 0;
  std::vector<std::string> locked;
  std::string ranking = "greedy";
  int threads = 0;
  core::SimdChoice simd = core::SimdChoice::kWidest;  // from MOTIONLOD_SIMD
};

void AddCommon(CLI::App* app, CommonOptions& o) {
  app->add_option("CHARACTER", o.character, "character file (glTF/GLB, FBX, Collada, BVH, X, SMD)")
      ->required();
  app->add_option("--motion", o.motion, "separate motion file, retargeted onto the character by joint name");
  app->add_option("--animation", o.animations,
                  "a clip to bake, by animation name; repeat for several (default: every animation "
                  "of the motion source, all with one reduced skeleton per level)");
  app->add_option("--fps", o.fps, "sampling rate in frames per second (default: the source's)")
      ->check(CLI::Range(0.0, 1000.0));
  app->add_option("--lock", o.locked, "joints no level removes (sockets, IK targets)")->delimiter(',');
  app->add_option("--ranking", o.ranking,
                  "removal order: greedy (by the solved error) or paper (subtree length x rotation)")
      ->capture_default_str();
  app->add_option("--threads", o.threads, "worker threads (default: one per core)")->check(CLI::NonNegativeNumber);
}

StatusOr<std::shared_ptr<const io::Asset>> Load(const std::string& path) {
  auto asset = io::LoadAssetFile(path);
  if (!asset.ok()) {
    return Status(asset.status().code(), "'" + path + "': " + asset.status().message());
  }
  return asset;
}

std::string ReadFileOrEmpty(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream bytes;
  bytes << in.rdbuf();
  return bytes.str();
}

// SHA-256 over the input files' digests and the sampling choices.
std::array<uint8_t, 32> SourceHash(const CommonOptions& o) {
  std::string key = "character:" + io::Sha256Hex(ReadFileOrEmpty(o.character));
  if (!o.motion.empty()) key += ";motion:" + io::Sha256Hex(ReadFileOrEmpty(o.motion));
  for (const std::string& animation : o.animations) key += ";animation:" + animation;
  key += ";fps:" + std::to_string(o.fps);
  const std::string hex = io::Sha256Hex(key);
  std::array<uint8_t, 32> digest{};
  for (size_t q = 0; q < digest.size(); ++q) digest[q] = static_cast<uint8_t>(std::stoi(hex.substr(2 * q, 2), nullptr, 16));
  return digest;
}

StatusOr<pipeline::BakeRequest> MakeRequest(const CommonOptions& o) {
  pipeline::BakeRequest request;
  auto character = Load(o.character);
  if (!character.ok()) return character.status();
  request.character = *character;
  std::shared_ptr<const io::Asset> motion;
  const std::string label = std::filesystem::path(o.motion).filename().string();
  if (!o.motion.empty()) {
    auto loaded = Load(o.motion);
    if (!loaded.ok()) return loaded.status();
    motion = *loaded;
  }
  // No --animation: every animation of the motion file (or, without one, of the character).
  if (o.animations.empty() && motion) request.clips = pipeline::EveryClipOf(**character, motion, label);
  for (const std::string& animation : o.animations) request.clips.push_back({motion, animation, label});
  request.fps = o.fps;
  request.locked_joints = o.locked;
  auto ranking = core::ParseRankingMethod(o.ranking);
  if (!ranking.ok()) return ranking.status();
  request.ranking_method = *ranking;
  request.threads = o.threads;
  request.simd = o.simd;
  request.character_label = std::filesystem::path(o.character).filename().string();
  return request;
}

class ProgressBar {
 public:
  ProgressBar() : enabled_(::isatty(STDERR_FILENO) == 1) {}
  void Update(const pipeline::BakeProgress& p) {
    if (!enabled_) return;
    const int width = 30;
    const int filled = static_cast<int>(p.fraction * width + 0.5);
    std::fprintf(stderr, "\r[%s%s] %3d%% %-16s", std::string(filled, '#').c_str(),
                 std::string(width - filled, ' ').c_str(), static_cast<int>(p.fraction * 100 + 0.5),
                 p.stage);
    std::fflush(stderr);
  }
  ~ProgressBar() {
    if (enabled_) std::fprintf(stderr, "\r%60s\r", "");
  }

 private:
  bool enabled_;
};

int RunInfo(const std::string& path) {
  auto asset = Load(path);
  if (!asset.ok()) return Fail(asset.status());
  const core::RawCharacter& c = (*asset)->character();
  std::cout << "joints " << c.skeleton.parents.size() << ", vertices " << c.skin.positions.size()
            << ", triangles " << c.skin.triangles.size()
            << ((*asset)->has_proxy_skin() ? " (proxy skin)" : "") << "\n";
  for (const io::AnimationInfo& a : (*asset)->animations()) {
    std::printf("animation '%s': %.3f s, %d frames at %.3g fps\n", a.name.c_str(), a.duration_seconds,
                a.source_frame_count, a.source_fps);
  }
  for (const std::string& w : (*asset)->warnings()) std::cout << "warning: " << w << "\n";
  return 0;
}

int RunRank(const CommonOptions& o, bool as_json) {
  auto request = MakeRequest(o);
  if (!request.ok()) return Fail(request.status());
  auto inputs = pipeline::PrepareInputs(*request);
  if (!inputs.ok()) return Fail(inputs.status());
  auto paper = core::RankJointsJob{inputs->character.get(), &inputs->motion, o.locked, o.simd}.Run();
  if (!paper.ok()) return Fail(paper.status());
  core::JointRanking ranking = *paper;
  if (request->ranking_method == core::RankingMethod::kGreedy) {
    // Greedy by the default variant's error, as a bake with default settings removes them.
    auto prepared = core::PreparedMotion::Create(inputs->character, inputs->motion, request->settings, o.simd);
    if (!prepared.ok()) return Fail(prepared.status());
    auto greedy = core::GreedyRankingJob{prepared->get(), o.locked}.Run();
    if (!greedy.ok()) return Fail(greedy.status());
    ranking = *std::move(greedy);
  }
  const nlohmann::json table =
      pipeline::RankingTable(*inputs->character, request->ranking_method, ranking, *paper);
  if (as_json) {
    std::cout << table.dump(2) << "\n";
    return 0;
  }
  std::printf("%4s  %-28s %10s %6s %12s %12s %12s\n", "rank", "joint", "error%", "paper",
              "hierarchical", "rotational", "priority");
  for (const auto& row : table) {
    const auto text = [&](const nlohmann::json& value) {
      return value.is_null() ? std::string(!row["removable"].get<bool>() ? (row["index"] == 0 ? "root" : "locked") : "-")
                             : std::to_string(value.get<double>());
    };
    std::printf("%4d  %-28s %10s %6d %12.4f %12.4f %12s\n", row["rank"].get<int>(),
                row["joint"].get<std::string>().c_str(), text(row["removal_error_pct"]).c_str(),
                row["paper_rank"].get<int>(), row["hierarchical"].get<double>(),
                row["rotational"].get<double>(), text(row["priority"]).c_str());
  }
  return 0;
}

void PrintLevelTable(const nlohmann::json& report) {
  std::printf("%s: %d joints, %d vertices; %s: %d frames at %.4g fps; variant %s\n",
              report["character"]["source"].get<std::string>().c_str(),
              report["character"]["joints"].get<int>(), report["character"]["vertices"].get<int>(),
              report["motion"]["name"].get<std::string>().c_str(), report["motion"]["frames"].get<int>(),
              report["motion"]["fps"].get<double>(), report["variant"].get<std::string>().c_str());
  std::printf("%6s %6s %6s %5s %3s %6s %10s %10s %9s %9s %9s %9s %12s\n", "joints", "verts", "tris",
              "infl", "r", "cost", "mean_E", "base_E", "max_err%", "base_max%", "mean_err%", "normal°",
              "max_px@1px");
  for (const auto& level : report["levels"]) {
    const nlohmann::json& limit = level["max_px_for_1px_error"];
    const std::string px = limit.is_null() || limit.get<double>() >= 1e6
                               ? "any"
                               : std::to_string(static_cast<long>(limit.get<double>()));
    std::printf("%6d %6d %6d %5.2f %3d %6.3f %10.3g %10.3g %9.3f %9.3f %9.3f %9.2f %12s\n",
                level["joints"].get<int>(), level["vertices"].get<int>(), level["triangles"].get<int>(),
                level["mean_influences"].get<double>(), level["frame_stride"].get<int>(),
                level["cost"].get<double>(), level["mean_E"].get<double>(),
                level["baseline_mean_E"].get<double>(),
                level["max_vertex_error_pct"].get<double>(),
                level["baseline_max_vertex_error_pct"].get<double>(),
                level["mean_vertex_error_pct"].get<double>(), level["mean_normal_error_deg"].get<double>(),
                px.c_str());
  }
  std::printf("bake %.3f s, one skinning pass %.3f s (%d threads)\n",
              report["timing"]["bake_seconds"].get<double>(),
              report["timing"]["skinning_pass_seconds"].get<double>(), report["timing"]["threads"].get<int>());
}

// What `bake` asks for beyond the common options.
struct BakeOptions {
  std::vector<int> levels;
  bool all_levels = false;
  std::vector<double> heights_px;
  std::string variant = "vpno+pd";
  bool keep_pd_translation = false, curves = false;
  std::string out;
};

int RunBake(const CommonOptions& o, const BakeOptions& b) {
  auto parsed_variant = core::ParseVariant(b.variant);
  if (!parsed_variant.ok()) return Fail(parsed_variant.status());
  auto request = MakeRequest(o);
  if (!request.ok()) return Fail(request.status());
  request->levels = b.levels;
  request->all_levels = b.all_levels;
  request->ladder_heights_px = b.heights_px;
  request->settings.variant = *parsed_variant;
  request->settings.resolve_rigid_translation = !b.keep_pd_translation;
  request->variant_curves = b.curves;
  request->source_hash = SourceHash(o);
  for (const std::string& w : request->character->warnings()) std::cerr << "motionlod: warning: " << w << "\n";
  std::optional<pipeline::BakeOutput> output;
  {
    ProgressBar bar;
    auto baked = pipeline::Bake(*request, [&](const pipeline::BakeProgress& p) { bar.Update(p); });
    if (!baked.ok()) return Fail(baked.status());
    output = std::move(*baked);
  }
  for (const std::string& w : output->warnings) std::cerr << "motionlod: warning: " << w << "\n";
  if (Status status = WriteDirectoryAtomically(
          b.out, {{"levels.mlod", output->level_set}, {"report.json", output->report.dump(2) + "\n"}});
      !status.ok()) {
    return Fail(status, kExitOutput);
  }
  PrintLevelTable(output->report);
  std::printf("wrote %s/levels.mlod (%zu bytes) and %s/report.json\n", b.out.c_str(),
              output->level_set.size(), b.out.c_str());
  return 0;
}

// Exports the level keeping `joints` joints (0 = all of them), or level `level_index` of
// the level set (>= 0), as glTF: from the level set at `level_set_path` when given, else
// from a bake of that single level.
int RunExport(const CommonOptions& o, const std::string& variant, int joints, int level_index,
              const std::string& level_set_path, const std::string& out) {
  auto parsed_variant = core::ParseVariant(variant);
  if (!parsed_variant.ok()) return Fail(parsed_variant.status());
  auto request = MakeRequest(o);
  if (!request.ok()) return Fail(request.status());
  if (joints == 0) joints = static_cast<int>(request->character->character().skeleton.parents.size());
  // The first clip: the first one asked for, else the first of the file.
  std::string level_set, animation = o.animations.empty() ? std::string() : o.animations.front();
  if (!level_set_path.empty()) {
    std::ifstream in(level_set_path, std::ios::binary);
    if (!in) return Fail(InvalidArgument("cannot read '" + level_set_path + "'"));
    level_set = ReadFileOrEmpty(level_set_path);
  } else {
    request->levels = {joints};
    request->settings.variant = *parsed_variant;
    request->source_hash = SourceHash(o);
    ProgressBar bar;
    auto baked = pipeline::Bake(*request, [&](const pipeline::BakeProgress& p) { bar.Update(p); });
    if (!baked.ok()) return Fail(baked.status());
    level_set = std::move(baked->level_set);
    animation = baked->report["clips"][0]["name"].get<std::string>();
  }
  auto exported = pipeline::ExportLevelGltf(*request->character, level_set,
                                            {.index = level_index, .joints = joints}, animation);
  if (!exported.ok()) {
    return Fail(Status(exported.status().code(),
                       (level_set_path.empty() ? "" : "'" + level_set_path + "': ") +
                           exported.status().message()));
  }
  if (Status status = WriteFileAtomically(out, exported->glb); !status.ok()) return Fail(status, kExitOutput);
  const io::GltfExportStats& stats = exported->stats;
  std::printf("wrote %s (%zu bytes): %d joints, %d vertices, %d frames; max vertex deviation "
              "from the level %.3g%% of the height; %d vertices over %d influences (dropped weight "
              "up to %.3g)\n",
              out.c_str(), exported->glb.size(), stats.joints, stats.vertices, stats.frames,
              stats.max_vertex_deviation_pct, stats.truncated_vertices, io::kGltfMaxInfluences,
              stats.max_dropped_weight);
  return 0;
}

int RunPlot(const std::string& report_path, const std::string& out) {
  std::ifstream in(report_path);
  if (!in) return Fail(InvalidArgument("cannot read '" + report_path + "'"));
  const nlohmann::json report = nlohmann::json::parse(in, nullptr, /*allow_exceptions=*/false);
  if (report.is_discarded()) return Fail(InvalidArgument("'" + report_path + "' is not valid JSON"));
  auto svg = RenderErrorPlotSvg(report);
  if (!svg.ok()) return Fail(svg.status());
  if (Status status = WriteFileAtomically(out, *svg); !status.ok()) return Fail(status, kExitOutput);
  std::printf("wrote %s\n", out.c_str());
  return 0;
}

int Main(int argc, char** argv) {
  // The hot loops' machine version (core/simd.h): a misspelt "baseline" must not silently
  // bake another version.
  const char* simd_setting = std::getenv("MOTIONLOD_SIMD");
  auto simd = core::ParseSimdChoice(simd_setting != nullptr ? simd_setting : "");
  if (!simd.ok()) return Fail(InvalidArgument("MOTIONLOD_SIMD is " + simd.status().message()));
  CLI::App app{"motionlod: Motion LoD bake tool (Ahn, Oh, Wohn 2006)"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "motionlod 0.1.0");

  std::string info_path;
  CLI::App* info = app.add_subcommand("info", "list a file's joints, vertices and animations");
  info->add_option("FILE", info_path, "character or motion file")->required();

  CommonOptions rank_options;
  bool rank_json = false;
  CLI::App* rank = app.add_subcommand("rank", "print the joint removal priority table (fig. 2)");
  AddCommon(rank, rank_options);
  rank->add_flag("--json", rank_json, "print JSON");

  CommonOptions bake_options;
  BakeOptions bake_choices;
  CLI::App* bake = app.add_subcommand("bake", "bake a level set and its report");
  AddCommon(bake, bake_options);
  auto* levels_option = bake->add_option("--levels", bake_choices.levels,
                                         "kept joint counts, e.g. 30,20,10,5 (the skeleton alone)")
                            ->delimiter(',');
  auto* all_levels_option =
      bake->add_flag("--all-levels", bake_choices.all_levels, "every level from all joints down to the root")
          ->excludes(levels_option);
  bake->add_option("--heights", bake_choices.heights_px,
                   "on-screen heights in px, decreasing, the levels by cost are chosen for "
                   "(default 800,400,200,100,50,25,12)")
      ->delimiter(',')
      ->excludes(levels_option)
      ->excludes(all_levels_option);
  bake->add_option("--variant", bake_choices.variant, "vp, vpno, vp+pd or vpno+pd (rigid)")->capture_default_str();
  bake->add_flag("--keep-pd-translation", bake_choices.keep_pd_translation,
                 "rigid variants: keep the solved translation instead of re-solving it");
  bake->add_flag("--curves", bake_choices.curves, "also solve the four variants at every level for `plot`");
  bake->add_option("--out", bake_choices.out, "output directory (levels.mlod, report.json)")->required();

  CommonOptions export_options;
  std::string export_variant = "vpno+pd", level_set_path, glb_path;
  int export_joints = 0, export_level = -1;
  CLI::App* export_command =
      app.add_subcommand("export", "write one level as glTF 2.0 (.glb) with its animation");
  AddCommon(export_command, export_options);
  export_command->add_option("--variant", export_variant, "vp, vpno, vp+pd or vpno+pd (rigid)")
      ->capture_default_str();
  auto* joints_option =
      export_command->add_option("--joints", export_joints, "kept joints of the level (default: all)")
          ->check(CLI::PositiveNumber);
  auto* level_set_option = export_command->add_option(
      "--level-set", level_set_path, "export from this baked levels.mlod instead of baking the level");
  export_command
      ->add_option("--level", export_level,
                   "the level of --level-set to export, 0 the finest (its own mesh, influences "
                   "and pose rate)")
      ->check(CLI::NonNegativeNumber)
      ->needs(level_set_option)
      ->excludes(joints_option);
  export_command->add_option("--out", glb_path, ".glb file to write")->required();

  std::string report_path, svg_path;
  CLI::App* plot = app.add_subcommand("plot", "draw mean E(t) against kept joints (fig. 7) as SVG");
  plot->add_option("REPORT", report_path, "report.json of a bake")->required();
  plot->add_option("-o,--out", svg_path, "SVG file to write")->required();

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);
    return code == 0 ? 0 : kExitBadInput;
  }
  if (info->parsed()) return RunInfo(info_path);
  for (CommonOptions* options : {&rank_options, &bake_options, &export_options}) options->simd = *simd;
  if (rank->parsed()) return RunRank(rank_options, rank_json);
  if (bake->parsed()) {
    return RunBake(bake_options, bake_choices);
  }
  if (export_command->parsed()) {
    return RunExport(export_options, export_variant, export_joints, export_level, level_set_path,
                     glb_path);
  }
  return RunPlot(report_path, svg_path);
}

}  // namespace
}  // namespace motionlod::tools

int main(int argc, char** argv) {
  motionlod::pipeline::KeepFreedBlocksForReuse();
  return motionlod::tools::Main(argc, argv);
}
