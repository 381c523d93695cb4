// Round 35 (docs/PERFORMANCE.md): the clip's sampling alone, on no pool, a 1-thread pool
// and a 2-thread pool (the other thread otherwise idle): medians of 2000 samplings each,
// three rounds. Build in a copy of the tree, as a bench target:
//   cp bench/experiments/round35-sample-threads.cc bench/sample_threads.cc
//   printf 'add_executable(sample_threads sample_threads.cc)\ntarget_link_libraries(sample_threads PRIVATE motionlod_pipeline motionlod_io motionlod_core)\n' >> bench/CMakeLists.txt
//   cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release -DMOTIONLOD_BUILD_BENCH=ON
//   cmake --build build --target sample_threads && build/bench/sample_threads ../shared/data/characters/Fox.glb
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <thread>
#include <vector>
#include "base/allocator.h"
#include "base/parallel.h"
#include "io/asset.h"
using namespace motionlod;
template <typename F> double Median(F f) {
  std::vector<double> t;
  for (int i = 0; i < 2000; ++i) {
    auto s = std::chrono::steady_clock::now();
    f();
    t.push_back(std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - s).count());
  }
  std::sort(t.begin(), t.end());
  return t[t.size() / 2];
}
int main(int argc, char** argv) {
  KeepFreedBlocksForReuse();
  auto asset = io::LoadAssetFile(argv[1]);
  const io::Asset& a = **asset;
  TaskPool one(1);
  TaskPool two(2);
  for (int r = 0; r < 3; ++r) {
    std::printf("nopool %.1f  pool1 %.1f  pool2 %.1f\n",
                Median([&] { (void)a.SampleAnimation("", 0, nullptr); }),
                Median([&] { (void)a.SampleAnimation("", 0, &one); }),
                Median([&] { (void)a.SampleAnimation("", 0, &two); }));
  }
}
