// Round 34 (docs/PERFORMANCE.md): the stages of an every-level bake of a subdivided
// character as the bench's replica runs it (round33-every-level-trace.cc), as medians over
// BAKES bakes (default 30): inputs, ranking and Create, the solves, the encoding, the whole.
// In a copy of the tree with bench/experiments/round34-pool-trace.patch applied
// (patch -p1), configured like build-bench into B:
//   g++ -O2 -std=c++20 -I. -I/usr/include/eigen3 -o /tmp/every_level_medians \
//     bench/experiments/round34-every-level-medians.cc bench/subdivide.cc $B/pipeline/libmotionlod_pipeline.a \
//     $B/io/libmotionlod_io.a $B/core/libmotionlod_core.a $B/proto/libmotionlod_proto.a \
//     $B/base/libmotionlod_base.a -lassimp -lspdlog -lfmt -lpthread
//   /tmp/every_level_medians ../shared/data/characters/Orc.gltf vpno+pd 2 16089 60
// Two builds side by side: bench/experiments/round34-every-level-ab.py.
#include <algorithm>
#include <cstdio>
#include <map>
#include <vector>
#include <string>
#include "base/allocator.h"
#include "base/parallel.h"
#include "bench/subdivide.h"
#include "core/character.h"
#include "core/rank_joints.h"
#include "core/solve_levels.h"
#include "io/asset.h"
#include "pipeline/bake.h"
#include "pipeline/report.h"
using namespace motionlod;
int main(int argc, char** argv) {
  KeepFreedBlocksForReuse();
  auto asset = *io::LoadAssetFile(argv[1]);
  auto variant = *core::ParseVariant(argv[2]);
  const int threads = std::atoi(argv[3]);
  core::RawCharacter raw = bench::SubdivideToVertexCount(asset->character(), std::atoi(argv[4]));
  std::vector<double> stages[5];
  const int bakes = argc > 5 ? std::atoi(argv[5]) : 30;
  for (int i = 0; i < bakes; ++i) {
    { std::lock_guard<std::mutex> lock(TraceMutex()); TraceEvents().clear(); }
    TaskPool pool(threads);
    TraceMark("inputs");
    std::optional<StatusOr<std::shared_ptr<const core::Character>>> built;
    std::optional<StatusOr<core::Motion>> sampled;
    pool.Run(2, [&](int task) {
      if (task == 0) built = core::BuildCharacter(raw, pool.Runner());
      else sampled = asset->SampleAnimation("", 0, &pool);
    });
    auto character = **built;
    auto motion = **sampled;
    TraceMark("rank+create");
    core::SolveSettings settings;
    settings.variant = variant;
    std::optional<StatusOr<core::JointRanking>> ranked;
    std::optional<StatusOr<std::shared_ptr<const core::PreparedMotion>>> created;
    pool.Run(2, [&](int task) {
      if (task == 0) ranked = core::RankJointsJob{character.get(), &motion, {}}.Run(pool.Runner());
      else created = core::PreparedMotion::Create(character, motion, settings, core::PreparedMotion::Workload::kEveryLevel, pool.Runner());
    });
    auto ranking = **ranked;
    auto prepared = **created;
    TraceMark("solve");
    std::vector<int> counts;
    for (int count = character->joint_count(); count >= ranking.locked_count; --count) counts.push_back(count);
    std::map<int, core::LevelResult> results;
    (void)pipeline::SolveLevels(prepared, ranking, counts, pool, results);
    TraceMark("encode");
    auto encoded = pipeline::EncodeSolvedLevels(*character, motion, settings, {}, counts, results, pool.Runner());
    TraceMark("end");
    {
      std::lock_guard<std::mutex> lock(TraceMutex());
      std::map<std::string, double> at;
      for (auto& e : TraceEvents()) if (e.label.rfind("MARK ", 0) == 0) at[e.label.substr(5)] = e.begin;
      stages[0].push_back(at["rank+create"] - at["inputs"]);
      stages[1].push_back(at["solve"] - at["rank+create"]);
      stages[2].push_back(at["encode"] - at["solve"]);
      stages[3].push_back(at["end"] - at["encode"]);
      stages[4].push_back(at["end"] - at["inputs"]);
    }
  }
  const char* names[5] = {"inputs", "rank+create", "solve", "encode", "total"};
  for (int k = 0; k < 5; ++k) {
    std::sort(stages[k].begin(), stages[k].end());
    std::printf("%s=%.1f ", names[k], stages[k][stages[k].size() / 2]);
  }
  std::printf("\n");
}
