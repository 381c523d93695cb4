// A heap byte buffer aligned for zero-copy decoding of the level format.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <new>
#include <span>
#include <string_view>

namespace motionlod::proto {

// Every section of the level format starts on a multiple of this many bytes, so its
// float and integer arrays can be viewed in place when the buffer itself starts on one.
inline constexpr size_t kLevelFormatAlignment = 16;

inline bool IsLevelFormatAligned(const void* data) {
  return reinterpret_cast<std::uintptr_t>(data) % kLevelFormatAlignment == 0;
}

// Owns `size()` bytes starting on a kLevelFormatAlignment boundary. The copy-to-aligned
// path for callers whose bytes arrive misaligned (a network buffer at an odd offset, a
// string whose allocator gives less than 16): `AlignedBytes::CopyOf(bytes)`, then decode
// `.bytes()`; the copy must outlive every view decoded from it. Move-only.
class AlignedBytes {
 public:
  AlignedBytes() = default;
  // `size` zero bytes.
  explicit AlignedBytes(size_t size)
      : data_(size == 0 ? nullptr
                        : static_cast<std::byte*>(
                              ::operator new[](size, std::align_val_t{kLevelFormatAlignment}))),
        size_(size) {
    if (size_ != 0) std::fill_n(data_.get(), size_, std::byte{0});
  }

  static AlignedBytes CopyOf(std::span<const std::byte> bytes) {
    AlignedBytes copy(bytes.size());
    if (!bytes.empty()) std::copy(bytes.begin(), bytes.end(), copy.data());
    return copy;
  }
  static AlignedBytes CopyOf(std::string_view bytes) {
    return CopyOf(std::as_bytes(std::span(bytes.data(), bytes.size())));
  }

  std::byte* data() { return data_.get(); }
  const std::byte* data() const { return data_.get(); }
  size_t size() const { return size_; }
  bool empty() const { return size_ == 0; }
  std::span<const std::byte> bytes() const { return {data_.get(), size_}; }
  std::span<std::byte> mutable_bytes() { return {data_.get(), size_}; }

 private:
  struct Free {
    void operator()(std::byte* p) const {
      ::operator delete[](p, std::align_val_t{kLevelFormatAlignment});
    }
  };
  std::unique_ptr<std::byte[], Free> data_;
  size_t size_ = 0;
};

}  // namespace motionlod::proto
