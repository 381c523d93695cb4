// The ladder of levels by cost (pipeline/cost_levels.h: the cheapest within 1 px at 800 to
// 12 px tall), per skinned, animated character of the data: what each level keeps
// (joints, vertices, triangles, influences, pose stride, the simplified mesh's bind-pose
// error), the largest height at which its
// honest maximum error stays within 1 px, its modelled cost against full detail, and the
// time to build the ladder; then re-solved weights against truncated ones at caps 1, 2, 4.
//
//   motionlod_bench_cost_ladder [variant=vpno+pd] [threads=2] [file ...]
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <numeric>
#include <string>
#include <vector>

#include "core/greedy_ranking.h"
#include "core/influence_cap.h"
#include "core/reduce_skeleton.h"
#include "io/asset.h"
#include "pipeline/bake.h"
#include "pipeline/cost_levels.h"

namespace motionlod {
namespace {

namespace fs = std::filesystem;

void Check(const Status& status, const std::string& what) {
  if (!status.ok()) {
    std::fprintf(stderr, "cost_ladder: %s: %s\n", what.c_str(), status.ToString().c_str());
    std::exit(1);
  }
}

int Main(int argc, char** argv) {
  auto variant = core::ParseVariant(argc > 1 ? argv[1] : "vpno+pd");
  Check(variant.status(), "variant");
  const int threads = argc > 2 ? std::atoi(argv[2]) : 2;
  std::vector<fs::path> files;
  for (int a = 3; a < argc; ++a) files.emplace_back(argv[a]);
  if (files.empty()) {
    for (const auto& entry :
         fs::directory_iterator(fs::path(MOTIONLOD_BENCH_DATA) / "characters")) {
      const std::string ext = entry.path().extension().string();
      if (ext == ".glb" || ext == ".gltf" || ext == ".dae") files.push_back(entry.path());
    }
    std::sort(files.begin(), files.end());
  }
  pipeline::TaskPool pool(threads);
  std::printf("variant %s, %d threads; the cheapest level within 1 px at each height\n",
              core::VariantName(*variant), threads);
  std::printf("%-28s %7s | %6s %6s %6s %5s %3s %7s %7s %6s\n", "character", "max px", "joints",
              "verts", "tris", "infl", "r", "mesh%", "error%", "cost");
  for (const fs::path& file : files) {
    auto asset = io::LoadAssetFile(file.string());
    Check(asset.status(), file.string());
    if ((*asset)->animations().empty() || (*asset)->has_proxy_skin()) continue;
    pipeline::BakeRequest request;
    request.character = *asset;
    request.settings.variant = *variant;
    request.threads = threads;
    auto inputs = pipeline::PrepareInputs(request);
    Check(inputs.status(), file.string());
    auto prepared =
        core::PreparedMotion::Create(inputs->character, inputs->motion, request.settings,
                                     core::SimdChoice::kWidest, pool.Runner());
    Check(prepared.status(), "prepare");
    auto ranking = core::GreedyRankingJob{prepared->get()}.Run(pool.Runner());
    Check(ranking.status(), "ranking");
    const core::Character& character = *inputs->character;
    const auto start = std::chrono::steady_clock::now();
    pipeline::CostLadderJob job;
    job.prepared = *prepared;
    job.motion = &inputs->motion;
    job.ranking = &*ranking;
    auto ladder = job.Run(pool);
    Check(ladder.status(), "ladder");
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    for (const pipeline::CostLevel& level : *ladder) {
      const double px = level.deviation.max_pct > 0 ? 100.0 / level.deviation.max_pct : INFINITY;
      const double bind_pct = level.mesh ? 100.0 * level.mesh->bind_error / character.height() : 0.0;
      std::printf("%-28s %7.0f | %6d %6d %6d %5.2f %3d %7.3f %7.3f %6.3f\n", file.filename().c_str(), px,
                  level.skeleton.kept_count(), level.vertex_count(character),
                  level.triangle_count(character), level.mean_influences, level.frame_stride, bind_pct,
                  level.deviation.max_pct, level.cost);
    }
    std::printf("%-28s ladder in %.2f s\n", file.filename().c_str(), seconds);
    // Re-solved weights against truncated ones at every cap, on the full skeleton and on the
    // level of half its joints: the weight step's objective summed over vertices and frames.
    for (int kept : {character.joint_count(), (character.joint_count() + 1) / 2}) {
      auto level = core::ReduceSkeletonToCount(character, *ranking, kept);
      Check(level.status(), "level");
      auto solved = (*prepared)->SolveLevel(*level);
      Check(solved.status(), "solve");
      std::printf("%-28s %d joints, re-solved / truncated square error:", file.filename().c_str(), kept);
      for (int cap : {1, 2, 4}) {
        auto truncated = core::TruncateInfluences(character, *level, cap);
        auto resolved = core::InfluenceCapJob{prepared->get(), &*level, solved->matrices, cap, 0}.Run();
        Check(truncated.ok() ? resolved.status() : truncated.status(), "influences");
        auto before = core::InfluenceObjective(**prepared, *level, solved->matrices, *truncated, 0);
        auto after = core::InfluenceObjective(**prepared, *level, solved->matrices, *resolved, 0);
        Check(before.ok() ? after.status() : before.status(), "objective");
        const double sum_before = std::accumulate(before->begin(), before->end(), 0.0);
        const double sum_after = std::accumulate(after->begin(), after->end(), 0.0);
        std::printf(" cap %d %.3g", cap, sum_before > 0 ? sum_after / sum_before : 1.0);
      }
      std::printf("\n");
    }
    std::fflush(stdout);
  }
  return 0;
}

}  // namespace
}  // namespace motionlod

int main(int argc, char** argv) { return motionlod::Main(argc, argv); }
