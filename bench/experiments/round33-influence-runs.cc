// Round 33 (docs/PERFORMANCE.md): runs of consecutive vertices with the same influence list in a
// skin, as it is or subdivided to N+ vertices, and the joint pairs per vertex. Build and run:
//   B=build-bench; g++ -O2 -std=c++20 -I. -I/usr/include/eigen3 -o /tmp/influence_runs \
//     bench/experiments/round33-influence-runs.cc bench/subdivide.cc $B/pipeline/libmotionlod_pipeline.a \
//     $B/io/libmotionlod_io.a $B/core/libmotionlod_core.a $B/proto/libmotionlod_proto.a \
//     $B/base/libmotionlod_base.a -lassimp -lspdlog -lfmt -lpthread
//   /tmp/influence_runs ../shared/data/characters/Orc.gltf 10000
#include <cstdio>
#include <cstdlib>
#include "bench/subdivide.h"
#include "core/character.h"
#include "io/asset.h"
using namespace motionlod;
int main(int argc, char** argv) {
  auto asset = io::LoadAssetFile(argv[1]);
  core::RawCharacter raw = argc > 2 ? bench::SubdivideToVertexCount((*asset)->character(), atoi(argv[2])) : (*asset)->character();
  const auto& k = raw.skin;
  size_t p = k.positions.size(), runs = 0, pairs = 0;
  for (size_t i = 0; i < p; ++i) {
    uint32_t b = k.influence_offsets[i], e = k.influence_offsets[i + 1];
    pairs += (e - b) * (e - b + 1) / 2;
    bool same = i > 0 && (k.influence_offsets[i] - k.influence_offsets[i - 1]) == e - b;
    if (same) for (uint32_t f = 0; f < e - b; ++f) same = same && k.influence_joints[b + f] == k.influence_joints[k.influence_offsets[i - 1] + f];
    runs += !same;
  }
  std::printf("vertices %zu runs %zu (mean %.1f) pairs/vertex %.2f\n", p, runs, double(p) / runs, double(pairs) / p);
}
