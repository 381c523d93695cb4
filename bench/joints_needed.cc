// Joints needed: for every character and clip set of the data directory, the fewest joints
// whose level stays within 1 px (its maximum vertex error, every frame of every clip) on a
// character 25, 50, 100 and 200 px tall, for three removal orders:
//   reparent  plain reparenting (kept joints keep their original matrices) in its own
//             greedy order (GreedyRankingJob::reparented): what engines ship, at its best
//   paper     the paper's order (RankJointsJob) with the solve
//   greedy    the greedy order by the solved error (GreedyRankingJob) with the solve
// Every level is solved as a bake solves it (SolveLevelsJob, LiftCoarserLevels). Prints a
// table per case and the median ratios paper / reparent and greedy / reparent per height
// (docs/PERFORMANCE.md, "Joints needed").
//   motionlod_bench_joints_needed [VARIANT] [THREADS] [PROBE]   (vpno+pd, 2, the default probe)
// PROBE: the greedy order's probe frames per clip (0: every frame).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "core/baseline_sequence.h"
#include "core/greedy_ranking.h"
#include "io/asset.h"
#include "pipeline/bake.h"
#include "pipeline/task_pool.h"

namespace {

using namespace motionlod;
namespace fs = std::filesystem;

constexpr double kHeightsPx[] = {25, 50, 100, 200};
constexpr int kHeights = 4;

// The fewest kept joints among `max_error_pct` (count -> %) within 1 px at each height; 0
// where no level is.
std::vector<int> FewestWithinOnePixel(const std::map<int, double>& max_error_pct) {
  std::vector<int> fewest(kHeights, 0);
  for (int h = 0; h < kHeights; ++h) {
    const double bound_pct = 100.0 / kHeightsPx[h];
    for (const auto& [count, error] : max_error_pct) {
      if (error <= bound_pct) {
        fewest[h] = count;
        break;
      }
    }
  }
  return fewest;
}

double Median(std::vector<double> values) {
  if (values.empty()) return 0;
  std::sort(values.begin(), values.end());
  const size_t mid = values.size() / 2;
  return values.size() % 2 ? values[mid] : 0.5 * (values[mid - 1] + values[mid]);
}

void Check(const Status& status, const std::string& what) {
  if (status.ok()) return;
  std::fprintf(stderr, "joints_needed: %s: %s\n", what.c_str(), status.ToString().c_str());
  std::exit(1);
}

}  // namespace

int main(int argc, char** argv) {
  const auto variant = core::ParseVariant(argc > 1 ? argv[1] : "vpno+pd");
  Check(variant.status(), "variant");
  const int threads = argc > 2 ? std::atoi(argv[2]) : 2;
  const int probe = argc > 3 ? std::atoi(argv[3]) : core::GreedyRankingJob::kDefaultProbeFramesPerClip;
  const fs::path data = MOTIONLOD_BENCH_DATA;
  std::vector<fs::path> files;
  for (const char* folder : {"characters", "motions"}) {
    for (const auto& entry : fs::directory_iterator(data / folder)) {
      const std::string ext = entry.path().extension().string();
      if (ext == ".glb" || ext == ".gltf" || ext == ".dae" || ext == ".bvh" || ext == ".fbx") {
        files.push_back(entry.path());
      }
    }
  }
  std::sort(files.begin(), files.end());
  std::printf("variant %s, %d threads; fewest joints within 1 px at 25/50/100/200 px tall\n",
              core::VariantName(*variant), threads);
  std::printf("%-34s %6s %5s | %-15s | %-15s | %-15s | %-15s | %8s %8s\n", "character (clips)", "joints",
              "clips", "reparent", "paper", "greedy", "reparent+solve", "paper s", "greedy s");
  std::vector<std::vector<double>> paper_ratio(kHeights), greedy_ratio(kHeights), solved_ratio(kHeights);
  pipeline::TaskPool pool(threads);
  for (const fs::path& file : files) {
    auto asset = io::LoadAssetFile(file.string());
    Check(asset.status(), file.string());
    if ((*asset)->animations().empty()) continue;  // nothing to bake
    pipeline::BakeRequest request;
    request.character = *asset;
    request.settings.variant = *variant;
    request.threads = threads;
    auto inputs = pipeline::PrepareInputs(request);
    Check(inputs.status(), file.string());
    const core::Character& character = *inputs->character;
    const int n = character.joint_count();
    auto prepared = core::PreparedMotion::Create(inputs->character, inputs->motion, request.settings,
                                                 core::SimdChoice::kWidest, pool.Runner());
    Check(prepared.status(), "prepare");

    // Plain reparenting in its own greedy order: the baselines of its nested levels.
    auto reparent_order = core::GreedyRankingJob{prepared->get(), {}, 0, true}.Run(pool.Runner());
    Check(reparent_order.status(), "reparent order");
    std::map<int, double> reparent;
    {
      core::BaselineSequence sequence(*prepared);
      for (int count = n; count >= reparent_order->locked_count; --count) {
        auto errors = sequence.Next(*core::ReduceSkeletonToCount(character, *reparent_order, count));
        Check(errors.status(), "reparent levels");
        reparent[count] = errors->max_vertex_error_pct;
      }
    }
    // The solved orders, every level as a bake solves them.
    const auto solved_errors = [&](const core::JointRanking& ranking) {
      std::vector<int> counts;
      for (int count = n; count >= ranking.locked_count; --count) counts.push_back(count);
      auto levels = pipeline::SolveLevelsJob{*prepared, &ranking, counts}.Run(pool);
      Check(levels.status(), "solve");
      Check(pipeline::LiftCoarserLevels(**prepared, *levels), "lift");
      std::map<int, double> errors;
      for (const auto& [count, result] : *levels) errors[count] = result.optimized.max_vertex_error_pct;
      return errors;
    };
    using Clock = std::chrono::steady_clock;
    auto start = Clock::now();
    auto paper_order = core::RankJointsJob{&character, &inputs->motion, {}}.Run(pool.Runner());
    Check(paper_order.status(), "paper order");
    const std::map<int, double> paper = solved_errors(*paper_order);
    const double paper_seconds = std::chrono::duration<double>(Clock::now() - start).count();
    start = Clock::now();
    auto greedy_order = core::GreedyRankingJob{prepared->get(), {}, probe}.Run(pool.Runner());
    Check(greedy_order.status(), "greedy order");
    const std::map<int, double> greedy = solved_errors(*greedy_order);
    const double greedy_seconds = std::chrono::duration<double>(Clock::now() - start).count();

    const std::vector<int> r = FewestWithinOnePixel(reparent), p = FewestWithinOnePixel(paper),
                           g = FewestWithinOnePixel(greedy),
                           rs = FewestWithinOnePixel(solved_errors(*reparent_order));
    const auto row = [](const std::vector<int>& v) {
      char text[32];
      std::snprintf(text, sizeof text, "%3d %3d %3d %3d", v[0], v[1], v[2], v[3]);
      return std::string(text);
    };
    std::printf("%-34s %6d %5zu | %s | %s | %s | %s | %8.2f %8.2f\n", file.filename().string().c_str(), n,
                inputs->motion.Clips().size(), row(r).c_str(), row(p).c_str(), row(g).c_str(),
                row(rs).c_str(), paper_seconds, greedy_seconds);
    std::fflush(stdout);
    // No level within 1 px counts as infinitely many joints.
    const auto ratio = [](int a, int b) { return a == 0 ? HUGE_VAL : static_cast<double>(a) / b; };
    for (int h = 0; h < kHeights; ++h) {
      if (r[h] == 0) continue;  // not even reparenting's full skeleton is within 1 px
      paper_ratio[h].push_back(ratio(p[h], r[h]));
      greedy_ratio[h].push_back(ratio(g[h], r[h]));
      solved_ratio[h].push_back(ratio(rs[h], r[h]));
    }
  }
  std::printf("median ratio to reparent (cases where reparenting reaches 1 px):\n");
  for (int h = 0; h < kHeights; ++h) {
    std::printf("  %3.0f px: paper %.2f, greedy %.2f, reparent+solve %.2f (%zu cases)\n", kHeightsPx[h],
                Median(paper_ratio[h]), Median(greedy_ratio[h]), Median(solved_ratio[h]), greedy_ratio[h].size());
  }
  return 0;
}
