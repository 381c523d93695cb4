// Stored frames and their interpolation (core/pose_rate.h).
#include "core/pose_rate.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <string>

namespace motionlod::core {

int StoredFrameCount(int frame_count, int stride) {
  return frame_count <= 1 ? 1 : (frame_count - 2) / stride + 2;
}

StoredFrameBlend BlendOfFrame(int t, int frame_count, int stride) {
  if (t == frame_count - 1) return {StoredFrameCount(frame_count, stride) - 1, 0.0f};
  const int index = t / stride;
  if (t % stride == 0) return {index, 0.0f};
  // Between stored frame `index` (at index * stride) and the next: the next multiple of
  // the stride, or the clip's last frame where that comes first.
  const int from = index * stride, to = std::min(from + stride, frame_count - 1);
  return {index, static_cast<float>(t - from) / static_cast<float>(to - from)};
}

RowMajorAffine34f InterpolateMatrix(const RowMajorAffine34f& a, const RowMajorAffine34f& b,
                                    float fraction, bool rigid) {
  if (fraction == 0) return a;
  RowMajorAffine34f out;
  out.col(3) = (1 - fraction) * a.col(3) + fraction * b.col(3);
  if (rigid) {
    const Eigen::Quaternionf qa(Eigen::Matrix3f(a.leftCols<3>())),
        qb(Eigen::Matrix3f(b.leftCols<3>()));
    out.leftCols<3>() = qa.slerp(fraction, qb).toRotationMatrix();
  } else {
    out.leftCols<3>() = (1 - fraction) * a.leftCols<3>() + fraction * b.leftCols<3>();
  }
  return out;
}

StatusOr<std::vector<RowMajorAffine34f>> StoreAtStride(std::span<const RowMajorAffine34f> matrices,
                                                       int kept_count,
                                                       std::span<const MotionClip> clips,
                                                       int stride) {
  if (stride < 1 || stride > kMaxFrameStride) {
    return InvalidArgument("StoreAtStride: the frame stride must be 1 to " +
                           std::to_string(kMaxFrameStride));
  }
  size_t frames = 0;
  for (const MotionClip& clip : clips) frames += static_cast<size_t>(clip.frame_count);
  if (kept_count < 1 || matrices.size() != frames * kept_count) {
    return InvalidArgument("StoreAtStride: the matrices are not the clips' frames x kept joints");
  }
  std::vector<RowMajorAffine34f> stored;
  for (const MotionClip& clip : clips) {
    for (int k = 0; k < StoredFrameCount(clip.frame_count, stride); ++k) {
      const int t = clip.first_frame + std::min(k * stride, clip.frame_count - 1);
      const auto frame = matrices.subspan(static_cast<size_t>(t) * kept_count, kept_count);
      stored.insert(stored.end(), frame.begin(), frame.end());
    }
  }
  return stored;
}

void PlayFrame(std::span<const RowMajorAffine34f> stored, int kept_count,
               std::span<const MotionClip> clips, int stride, int t, bool rigid,
               std::span<RowMajorAffine34f> out) {
  size_t first_stored = 0;
  for (const MotionClip& clip : clips) {
    if (t < clip.first_frame + clip.frame_count) {
      const StoredFrameBlend blend = BlendOfFrame(t - clip.first_frame, clip.frame_count, stride);
      const size_t a = (first_stored + blend.index) * kept_count;
      for (int s = 0; s < kept_count; ++s) {
        out[s] = blend.fraction == 0 ? stored[a + s]
                                     : InterpolateMatrix(stored[a + s], stored[a + kept_count + s],
                                                         blend.fraction, rigid);
      }
      return;
    }
    first_stored += static_cast<size_t>(StoredFrameCount(clip.frame_count, stride));
  }
}

}  // namespace motionlod::core
