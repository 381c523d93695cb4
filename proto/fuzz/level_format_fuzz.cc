// libFuzzer target for the level-set decoder: any input must decode or fail with a
// Status, never crash, over-read or trip a sanitizer; what decodes must re-encode to
// the same bytes and extract (by level, and by level and clip) to files that decode again,
// and every frame of every clip must blend between stored frames of its own clip.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <span>

#include "proto/aligned_bytes.h"
#include "proto/level_format.h"

namespace {

void Check(bool condition) {
  if (!condition) std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace motionlod::proto;
  // The decoder requires a 16-byte aligned buffer; libFuzzer's is not guaranteed to be.
  const AlignedBytes bytes = AlignedBytes::CopyOf(std::as_bytes(std::span(data, size)));
  // Checksums cannot be forged by mutation: decode without, so the structural checks
  // are what is exercised. With the checksum, a mutated input must fail.
  const auto view = DecodeLevelSet(bytes.bytes(), DecodeOptions{.verify_checksum = false});
  (void)DecodeLevelSet(bytes.bytes());
  if (!view.ok()) return 0;

  float sum = 0;  // touch every viewed value
  for (const LevelView& level : view->levels()) {
    for (const float value : level.matrices()) sum += value;
    for (uint32_t j = 0; j < view->joint_count(); ++j)
      Check(level.joint_map()[j] < level.kept_count());
    Check(level.frame_stride() >= 1 && level.frame_stride() <= kMaxFrameStride);
    for (const uint32_t vertex : level.vertices()) Check(vertex < view->vertex_count());
    for (const uint32_t corner : level.triangles()) Check(corner < level.vertices().size());
    for (const uint16_t slot : level.influence_slots()) Check(slot < level.kept_count());
    for (const float weight : level.influence_weights()) sum += weight;
    Check(level.influence_slots().size() == level.influence_weights().size());
  }
  (void)sum;
  // The clips, one at least (a 1.x file: one unnamed clip), cover the frames in order.
  Check(view->clip_count() >= 1);
  uint64_t next_frame = 0;
  for (const ClipView& clip : view->clips()) {
    Check(clip.first_frame == next_frame && clip.frame_count >= 1);
    Check(clip.name.empty() || clip.name.size() <= kMaxNameBytes);
    Check(view->FindClip(clip.name) == static_cast<int>(&clip - view->clips().data()));
    next_frame += clip.frame_count;
  }
  Check(next_frame == view->frame_count());
  for (const LevelView& level : view->levels()) {
    for (uint32_t c = 0; c < view->clip_count(); ++c) {
      const uint32_t frames = view->clip(c).frame_count;
      const uint32_t first = level.clip_first_stored(c);
      const uint32_t end = first + StoredFrameCount(frames, level.frame_stride());
      Check(end <= level.frame_count());
      for (uint32_t t = 0; t < frames; ++t) {
        const FrameBlend blend = level.Blend(c, t, frames);
        Check(first <= blend.from && blend.from <= blend.to && blend.to < end);
        Check(blend.fraction >= 0 && blend.fraction < 1);
      }
    }
  }

  const auto reencoded = EncodeLevelSet(ToLevelSetData(*view));
  Check(reencoded.ok());
  if (view->major_version() == kLevelFormatMajorVersion &&
      view->minor_version() == kLevelFormatMinorVersion) {
    // A current-version file is canonical apart from its checksum field.
    Check(reencoded->size() == size);
    Check(
        std::equal(reencoded->begin(), reencoded->end() - 8, reinterpret_cast<const char*>(data)));
  }
  for (uint32_t l = 0; l < view->level_count(); ++l) {
    const auto extracted = ExtractLevel(*view, l);
    Check(extracted.ok());
    const AlignedBytes copy = AlignedBytes::CopyOf(*extracted);
    Check(DecodeLevelSet(copy.bytes()).ok());
    for (uint32_t c = 0; c < view->clip_count(); ++c) {
      const auto clip = ExtractLevelClip(*view, l, c);
      Check(clip.ok());
      const AlignedBytes clip_copy = AlignedBytes::CopyOf(*clip);
      const auto single = DecodeLevelSet(clip_copy.bytes());
      Check(single.ok() && single->clip_count() == 1 &&
            single->frame_count() == view->clip(c).frame_count &&
            single->level(0).frame_count() ==
                StoredFrameCount(view->clip(c).frame_count, view->level(l).frame_stride()));
    }
  }
  return 0;
}
