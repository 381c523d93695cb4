// Round 33 (docs/PERFORMANCE.md): one probe of the search for the smallest useful level,
// MaxVertexErrorWithin on Bake's probe motion, timed alone (median of ITER calls, default
// 2000) for each count given; pin it with taskset, and run a second copy on the other CPU,
// to see whether the two CPUs share execution units. Build and run:
//   B=build-bench; g++ -O2 -std=c++20 -I. -I/usr/include/eigen3 -o /tmp/probe_timing \
//     bench/experiments/round33-probe-timing.cc $B/pipeline/libmotionlod_pipeline.a \
//     $B/io/libmotionlod_io.a $B/core/libmotionlod_core.a $B/proto/libmotionlod_proto.a \
//     $B/base/libmotionlod_base.a -lassimp -lspdlog -lfmt -lpthread
//   taskset -c 0 /tmp/probe_timing ../shared/data/characters/Fox.glb vp+pd 3 5
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <vector>
#include "base/allocator.h"
#include "io/asset.h"
#include "core/rank_joints.h"
#include "core/reduce_skeleton.h"
#include "core/solve_levels.h"
#include "pipeline/bake.h"
using namespace motionlod;
int main(int argc, char** argv) {
  KeepFreedBlocksForReuse();
  pipeline::BakeRequest request;
  request.character = *io::LoadAssetFile(argv[1]);
  request.settings.variant = *core::ParseVariant(argv[2]);
  request.threads = 1;
  auto inputs = *pipeline::PrepareInputs(request);
  auto ranking = *core::RankJointsJob{inputs.character.get(), &inputs.motion, {}}.Run();
  auto prepared = *core::PreparedMotion::Create(inputs.character, inputs.motion, request.settings,
                                                core::PreparedMotion::Workload::kSomeLevels);
  const int stride = (prepared->frame_count() + 63) / 64;
  auto probe = stride == 1 ? prepared : *prepared->EveryNthFrame(stride);
  std::printf("frames %d probe %d minimum %d\n", prepared->frame_count(), probe->frame_count(), ranking.locked_count);
  const int iters = getenv("ITER") ? atoi(getenv("ITER")) : 2000;
  for (int i = 3; i < argc; ++i) {
    const int count = atoi(argv[i]);
    auto level = *core::ReduceSkeletonToCount(probe->character(), ranking, count);
    std::vector<double> t;
    bool within = false;
    for (int k = 0; k < iters; ++k) {
      auto t0 = std::chrono::steady_clock::now();
      within = *probe->MaxVertexErrorWithin(level, 10.0);
      t.push_back(std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - t0).count());
    }
    std::nth_element(t.begin(), t.begin() + t.size() / 2, t.end());
    std::printf("count %d within %d median %.2f us\n", count, within, t[t.size() / 2]);
  }
}
