// Round 26 (docs/PERFORMANCE.md): the level file's encoding and its parts, on one thread,
// for the level set of one bake (first argument: a character file; vp+pd, its default
// ladder). Medians of 2001 calls. Build against build-bench's libraries and run:
//   B=build-bench; g++ -O2 -std=c++20 -I. -I/usr/include/eigen3 -o /tmp/encode_timing \
//     bench/experiments/round26-encode-timing.cc $B/pipeline/libmotionlod_pipeline.a \
//     $B/io/libmotionlod_io.a $B/core/libmotionlod_core.a $B/proto/libmotionlod_proto.a \
//     $B/base/libmotionlod_base.a -lassimp -lspdlog -lfmt -lpthread
//   /tmp/encode_timing ../shared/data/characters/Fox.glb
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <string>
#include <vector>

#include "base/allocator.h"
#include "io/asset.h"
#include "pipeline/bake.h"
#include "proto/checksum.h"
#include "proto/level_format.h"

using namespace motionlod;
using Clock = std::chrono::steady_clock;

template <typename F>
double MedianMicroseconds(F f) {
  std::vector<double> times;
  for (int i = 0; i < 2001; ++i) {
    const auto t0 = Clock::now();
    f();
    times.push_back(std::chrono::duration<double, std::micro>(Clock::now() - t0).count());
  }
  std::sort(times.begin(), times.end());
  return times[1000];
}

int main(int argc, char** argv) {
  if (argc != 2) return 2;
  KeepFreedBlocksForReuse();
  auto asset = io::LoadAssetFile(argv[1]);
  if (!asset.ok()) return 2;
  pipeline::BakeRequest request;
  request.character = *asset;
  request.settings.variant = core::Variant::kVPPD;
  request.threads = 1;
  auto baked = pipeline::Bake(request);
  if (!baked.ok()) return 1;
  const proto::LevelSetData data = proto::ToLevelSetData(*proto::DecodeLevelSet(baked->level_set));
  size_t sink = 0;
  std::printf("level set %zu bytes\n", baked->level_set.size());
  std::printf("EncodeLevelSet %.1f us\n", MedianMicroseconds([&] { sink += proto::EncodeLevelSet(data)->size(); }));
  std::printf("ValidateLevelSet %.1f us\n", MedianMicroseconds([&] { sink += proto::ValidateLevelSet(data).ok(); }));
  std::printf("Xxh64 of the file %.1f us\n", MedianMicroseconds([&] { sink += proto::Xxh64(baked->level_set); }));
  return sink == 42;
}
