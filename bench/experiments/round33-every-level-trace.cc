// Round 33 (docs/PERFORMANCE.md): the pool's trace of an every-level bake of a subdivided
// character, as the bench's replica runs it; prints every event of the last of 30 bakes
// with its thread. In a copy of the tree with bench/experiments/round26-pool-trace.patch
// applied (patch -p1), configured like build-bench into B:
//   g++ -O2 -std=c++20 -I. -I/usr/include/eigen3 -o /tmp/every_level_trace \
//     bench/experiments/round33-every-level-trace.cc bench/subdivide.cc $B/pipeline/libmotionlod_pipeline.a \
//     $B/io/libmotionlod_io.a $B/core/libmotionlod_core.a $B/proto/libmotionlod_proto.a \
//     $B/base/libmotionlod_base.a -lassimp -lspdlog -lfmt -lpthread
//   /tmp/every_level_trace ../shared/data/characters/Orc.gltf vpno+pd 2 16089
// Per-stage idle time: the stages are between the MARK lines.
#include <algorithm>
#include <cstdio>
#include <map>
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
  for (int i = 0; i < 30; ++i) {
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
  }
  auto events = TraceEvents();
  double t0 = events.front().begin;
  for (auto& e : events) t0 = std::min(t0, e.begin);
  std::sort(events.begin(), events.end(), [](auto& a, auto& b) { return a.begin < b.begin; });
  for (auto& e : events) std::printf("%8.1f %8.1f %6.1f  T%d  %s [%d/%d]\n", e.begin - t0, e.end - t0, e.end - e.begin, e.thread, e.label.c_str(), e.index, e.count);
}
