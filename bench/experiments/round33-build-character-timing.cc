// Round 32/33 (docs/PERFORMANCE.md): BuildCharacter of a subdivided real character, timed
// alone (medians of ITER builds, default 60): the RawCharacter copy, ValidateRawCharacter, and
// BuildCharacter on a pool of THREADS. Build against build-bench's libraries and run:
//   B=build-bench; g++ -O2 -std=c++20 -I. -I/usr/include/eigen3 -o /tmp/build_character_timing \
//     bench/experiments/round33-build-character-timing.cc bench/subdivide.cc $B/pipeline/libmotionlod_pipeline.a \
//     $B/io/libmotionlod_io.a $B/core/libmotionlod_core.a $B/proto/libmotionlod_proto.a \
//     $B/base/libmotionlod_base.a -lassimp -lspdlog -lfmt -lpthread
//   ITER=200 /tmp/build_character_timing ../shared/data/characters/Orc.gltf 2 16089
#include <chrono>
#include <cstdio>
#include <algorithm>
#include "base/allocator.h"
#include "base/parallel.h"
#include "bench/subdivide.h"
#include "core/character.h"
#include "io/asset.h"
using namespace motionlod;
int main(int argc, char** argv) {
  KeepFreedBlocksForReuse();
  auto asset = io::LoadAssetFile(argv[1]);
  const int threads = std::atoi(argv[2]);
  const int min_vertices = argc > 3 ? std::atoi(argv[3]) : 10000;
  core::RawCharacter raw = bench::SubdivideToVertexCount((*asset)->character(), min_vertices);
  std::vector<double> build, validate, copy;
  for (int i = 0; i < (getenv("ITER") ? atoi(getenv("ITER")) : 60); ++i) {
    auto t0 = std::chrono::steady_clock::now();
    core::RawCharacter r = raw;
    auto t1 = std::chrono::steady_clock::now();
    (void)core::ValidateRawCharacter(r);
    auto t2 = std::chrono::steady_clock::now();
    TaskPool pool(threads);
    if (getenv("WARM")) pool.Run(2, [](int) {});
    auto t3 = std::chrono::steady_clock::now();
    auto c = core::BuildCharacter(raw, pool.Runner());
    auto t4 = std::chrono::steady_clock::now();
    copy.push_back(std::chrono::duration<double, std::micro>(t1 - t0).count());
    validate.push_back(std::chrono::duration<double, std::micro>(t2 - t1).count());
    build.push_back(std::chrono::duration<double, std::micro>(t4 - t3).count());
  }
  auto med = [](std::vector<double> v) { std::sort(v.begin(), v.end()); return v[v.size() / 2]; };
  std::printf("copy %.1f validate %.1f build %.1f us\n", med(copy), med(validate), med(build));
}
