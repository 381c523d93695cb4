// How the layers that start no thread (core, io, proto) spread independent pieces of their
// work over a caller's threads.
#pragma once

#include <functional>

namespace motionlod {

// run(count, piece) calls piece(index) once for every index in [0, count), in any order and
// on any threads, and returns when all have run. A caller with threads passes its pool's
// (pipeline/task_pool.h: TaskPool::Runner); an empty runner runs the pieces in order on the
// calling thread. A function that takes one returns the same result for any runner.
using PieceRunner = std::function<void(int count, const std::function<void(int)>& piece)>;

inline void RunPieces(const PieceRunner& run, int count, const std::function<void(int)>& piece) {
  if (run) {
    run(count, piece);
  } else {
    for (int index = 0; index < count; ++index) piece(index);
  }
}

}  // namespace motionlod
