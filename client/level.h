// A streamed level (the one-level file of docs/level-format.md) held in memory: the
// received or cached bytes and the validated view into them. Decoding is zero-copy: the
// matrices the skinner reads are the bytes that arrived. Move-only; moving keeps every
// span of the view valid (the bytes stay where they are).
#pragma once

#include <memory>
#include <string>

#include "client/error.h"
#include "proto/aligned_bytes.h"
#include "proto/level_format.h"

namespace motionlod::client {

class Level {
 public:
  // Validates `bytes` (checksum, structure, semantics) and views them in place; they are
  // copied once only when their storage is not 16-byte aligned. kDataLoss when invalid.
  static Result<Level> Decode(std::string bytes);

  const proto::LevelSetView& level_set() const { return view_; }  // L = 1 when streamed
  const proto::LevelView& level() const { return view_.level(0); }
  size_t byte_size() const { return view_.bytes().size(); }

 private:
  Level() = default;
  std::unique_ptr<std::string> bytes_;  // heap: its address survives moves of the Level
  proto::AlignedBytes aligned_;          // the copy, when bytes_ was misaligned
  proto::LevelSetView view_;
};

}  // namespace motionlod::client
