// One bake, or one skinning pass, of a file on one thread, for instruction counts under
// callgrind (docs/PERFORMANCE.md, "Where the time goes"): run with --instr-atstart=no,
// callgrind counts only the span between the client requests around Bake or the pass
// (not the import, nor the inputs of the pass), comparable across commits whatever the
// machine's load. Without valgrind's header the requests are no-ops.
//   motionlod_bench_bake_once FILE VARIANT [skin|all]
// "skin" runs the skinning pass instead; "all" bakes every level (all_levels) instead of
// the default ladder.
#include <cstdio>
#include <cstring>

#if __has_include(<valgrind/callgrind.h>)
#include <valgrind/callgrind.h>
#else
#define CALLGRIND_START_INSTRUMENTATION
#define CALLGRIND_STOP_INSTRUMENTATION
#endif

#include "io/asset.h"
#include "pipeline/allocator.h"
#include "pipeline/bake.h"

int main(int argc, char** argv) {
  using namespace motionlod;
  pipeline::KeepFreedBlocksForReuse();
  const bool skin = argc == 4 && std::strcmp(argv[3], "skin") == 0;
  const bool all_levels = argc == 4 && std::strcmp(argv[3], "all") == 0;
  if (argc < 3 || argc > 4 || (argc == 4 && !skin && !all_levels)) {
    std::fprintf(stderr, "usage: motionlod_bench_bake_once FILE VARIANT [skin|all]\n");
    return 2;
  }
  auto asset = io::LoadAssetFile(argv[1]);
  auto variant = core::ParseVariant(argv[2]);
  if (!asset.ok() || !variant.ok()) {
    std::fprintf(stderr, "bake_once: %s\n",
                 (!asset.ok() ? asset.status() : variant.status()).ToString().c_str());
    return 2;
  }
  pipeline::BakeRequest request;
  request.character = *std::move(asset);
  request.settings.variant = *variant;
  request.threads = 1;
  request.measure_skinning_pass = false;
  request.all_levels = all_levels;
  if (skin) {
    auto inputs = pipeline::PrepareInputs(request);
    if (!inputs.ok()) return 1;
    CALLGRIND_START_INSTRUMENTATION;
    const double seconds = pipeline::SkinningPassSeconds(*inputs->character, inputs->motion, 1);
    CALLGRIND_STOP_INSTRUMENTATION;
    return seconds < 0;
  }
  CALLGRIND_START_INSTRUMENTATION;
  const bool baked = pipeline::Bake(request).ok();
  CALLGRIND_STOP_INSTRUMENTATION;
  return baked ? 0 : 1;
}
