#include "core/internal/error_sample.h"

#include <algorithm>
#include <cmath>

#include "core/internal/chord_angle.h"
#include "core/internal/lanes.h"
#include "core/internal/simd_dispatch.h"

namespace motionlod::core::internal {
namespace {

std::vector<int> EvenlySpaced(int count, int available) {
  const int used = std::min(count, available);
  std::vector<int> out(used);
  for (int q = 0; q < used; ++q) {
    out[q] = used == 1 ? 0
                       : static_cast<int>(std::llround(static_cast<double>(q) * (available - 1) /
                                                       (used - 1)));
  }
  return out;
}

// The angle between each original normal n and n + dn (radians) from the chord of their
// directions, 2 asin(|u - w/|w|| / 2) with u = n/|n|, w = u + dn/|n| (chord_angle.h): up
// to 29 degrees, where level errors almost always are, by the series; past it the marker
// for FinishChordAngle, and NaN where n or n + dn is zero. Without a branch or a call the
// loop vectorises. normals: rows of count, u_x, u_y, u_z and 1/|n|.
void ChordAngles(size_t count, const double* normals, const double* dn_x, const double* dn_y,
                 const double* dn_z, double* __restrict angle) {
  const double* unit_x = normals;
  const double* unit_y = unit_x + count;
  const double* unit_z = unit_y + count;
  const double* inverse_length = unit_z + count;
  for (size_t v = 0; v < count; ++v) {
    const double wx = unit_x[v] + dn_x[v] * inverse_length[v];
    const double wy = unit_y[v] + dn_y[v] * inverse_length[v];
    const double wz = unit_z[v] + dn_z[v] * inverse_length[v];
    const double inverse_w = 1 / std::sqrt(wx * wx + wy * wy + wz * wz);
    const double cx = unit_x[v] - wx * inverse_w, cy = unit_y[v] - wy * inverse_w;
    const double cz = unit_z[v] - wz * inverse_w;
    angle[v] = ChordAngleOrMarker(0.5 * std::sqrt(cx * cx + cy * cy + cz * cz));
  }
}

}  // namespace

ErrorSample MakeErrorSample(const Character& character, const SolveSettings& settings,
                            const Eigen::MatrixXd& kt, int frames) {
  ErrorSample sample;
  const RawSkin& skin = character.skin();
  const int p = character.vertex_count();
  sample.frames = EvenlySpaced(settings.sample_frames, frames);
  // No more vertices per frame than keep the sample within 1% of the motion's
  // vertex-frames (64 at least): a short clip of a small mesh is not sampled more densely
  // than a long one.
  constexpr int64_t kMinSampleVertices = 64;
  const int64_t motion_budget =
      static_cast<int64_t>(p) * frames / (100 * static_cast<int64_t>(sample.frames.size()));
  const int64_t vertex_count =
      std::min<int64_t>(settings.sample_vertices, std::max(kMinSampleVertices, motion_budget));
  const int stride = static_cast<int>((p + vertex_count - 1) / vertex_count);
  for (int i = 0; i < p; i += stride) {
    for (uint32_t e = skin.influence_offsets[i]; e < skin.influence_offsets[i + 1]; ++e) {
      sample.influences.push_back({skin.influence_joints[e], skin.influence_weights[e]});
    }
    sample.vertices.push_back({skin.positions[i], skin.normals[i], character.vertex_areas()[i],
                               static_cast<uint32_t>(sample.influences.size())});
    sample.area += sample.vertices.back().area;
  }
  const size_t count = sample.vertices.size();
  sample.normals.resize(sample.frames.size() * 4 * count);
  for (size_t q = 0; q < sample.frames.size(); ++q) {
    const int t = sample.frames[q];
    uint32_t e = 0;
    for (size_t v = 0; v < count; ++v) {
      const ErrorSample::Vertex& vertex = sample.vertices[v];
      Vec3d normal = Vec3d::Zero();
      for (; e < vertex.influence_end; ++e) {
        const ErrorSample::Influence& influence = sample.influences[e];
        normal += influence.weight * (kt.block<3, 3>(4 * influence.joint, 3 * t).transpose() *
                                      vertex.normal.cast<double>());
      }
      const double length = normal.norm();
      const double inverse_length = length > 0 ? 1 / length : 0;
      double* rows = sample.normals.data() + 4 * q * count;
      for (int a = 0; a < 3; ++a) rows[a * count + v] = normal[a] * inverse_length;
      rows[3 * count + v] = inverse_length;
    }
  }
  return sample;
}

void SampleFrameValues(const ErrorSample& sample, const Eigen::Matrix<double, Eigen::Dynamic, 3>& frame,
                       size_t q, const std::vector<uint32_t>* vertices, SimdChoice simd,
                       SampleScratch& scratch, SampleValues& values) {
  RunWithSimd(simd, [&] {
    // Blends in float, as the maximum search: the rounding is relative to Delta itself.
    // Column a of Delta_k (a zero last row) is lane a of frame's three columns of joint k
    // and of zero, transposed as whole vectors.
    std::vector<PaddedDelta>& frame_delta = scratch.frame_delta;
    const double* columns = frame.data();
    const Eigen::Index stride = frame.rows();
    const Eigen::Index n = frame.rows() / 4;
    for (Eigen::Index k = 0; k < n; ++k) {
      const Lanes4 rows[4] = {*AsLanes4(columns + 4 * k), *AsLanes4(columns + stride + 4 * k),
                              *AsLanes4(columns + 2 * stride + 4 * k), Lanes4{}};
      Lanes4 delta_columns[4];
      Transpose4(rows, delta_columns);
      float* target = frame_delta[k].data();
      for (int a = 0; a < 4; ++a) {
        *AsLanes4f(target + 4 * a) = __builtin_convertvector(delta_columns[a], Lanes4f);
      }
    }
    const size_t all = sample.vertices.size();
    const size_t count = vertices ? vertices->size() : all;
    const double* normals = sample.normals.data() + 4 * q * all;
    // A subset's original normals are gathered into rows of its own length, as ChordAngles
    // reads them.
    if (vertices) {
      for (size_t e = 0; e < count; ++e) {
        for (int row = 0; row < 4; ++row)
          scratch.normals[row * count + e] = normals[row * all + (*vertices)[e]];
      }
      normals = scratch.normals.data();
    }
    for (size_t e = 0; e < count; ++e) {
      const size_t v = vertices ? (*vertices)[e] : e;
      const ErrorSample::Vertex& vertex = sample.vertices[v];
      PaddedDelta blended = PaddedDelta::Zero();
      for (uint32_t g = sample.influence_begin(v); g < vertex.influence_end; ++g) {
        blended.noalias() += sample.influences[g].weight * frame_delta[sample.influences[g].joint];
      }
      const Eigen::Vector4d d =
          (blended.leftCols<3>() * vertex.position + blended.col(3)).cast<double>();
      const Eigen::Vector4d dn = (blended.leftCols<3>() * vertex.normal).cast<double>();
      values.distance_squared[v] = d.squaredNorm();
      values.normal_squared[v] = dn.x() * dn.x() + dn.y() * dn.y() + dn.z() * dn.z();
      scratch.normal_x[e] = dn.x();
      scratch.normal_y[e] = dn.y();
      scratch.normal_z[e] = dn.z();
    }
    ChordAngles(count, normals, scratch.normal_x.data(), scratch.normal_y.data(),
                scratch.normal_z.data(), scratch.angle.data());
    for (size_t e = 0; e < count; ++e) {
      // No direction to compare (n or n + dn zero): no angle.
      const double angle = std::isnan(scratch.angle[e]) ? 0.0 : FinishChordAngle(scratch.angle[e]);
      values.angle[vertices ? (*vertices)[e] : e] = angle;
    }
  });
}

void AddSampleSums(const ErrorSample& sample, const SampleValues& values, SampleSums& sums) {
  for (size_t v = 0; v < sample.vertices.size(); ++v) {
    const double area = sample.vertices[v].area;
    sums.distance += area * std::sqrt(values.distance_squared[v]);
    sums.distance_squared += area * values.distance_squared[v];
    sums.angle += area * values.angle[v];
    sums.normal_squared += area * values.normal_squared[v];
  }
}

}  // namespace motionlod::core::internal
