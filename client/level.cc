#include "client/level.h"

namespace motionlod::client {

Result<Level> Level::Decode(std::string bytes) {
  Level level;
  level.bytes_ = std::make_unique<std::string>(std::move(bytes));
  std::span<const std::byte> stored = std::as_bytes(std::span(*level.bytes_));
  if (!proto::IsLevelFormatAligned(stored.data())) {
    level.aligned_ = proto::AlignedBytes::CopyOf(stored);
    stored = level.aligned_.bytes();
  }
  auto view = proto::DecodeLevelSet(stored);
  if (!view.ok()) {
    return Error{ErrorKind::kDataLoss, 0, std::nullopt,
                 "not a valid level file: " + view.status().ToString()};
  }
  level.view_ = std::move(*view);
  return level;
}

}  // namespace motionlod::client
