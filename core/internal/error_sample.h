// The sample behind the sampled figures of LevelErrors (the mean vertex error and the
// mean normal angle): evenly spaced frames and vertices, SolveSettings::sample_frames and
// sample_vertices. The exact figures (E, the RMS and maximum vertex errors) never sample.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "core/character.h"
#include "core/simd.h"
#include "core/solve_levels.h"

namespace motionlod::core::internal {

// Delta_k(t) in float for the per-vertex blends, as a 4x4 with a zero last row: four
// aligned packets, so a blend and its transforms stay in registers.
using PaddedDelta = Eigen::Matrix4f;

struct ErrorSample {
  // The sampled vertices' skin, copied out contiguously: read in place, each of them would
  // touch its own cache lines of every skin array in every frame.
  struct Vertex {
    Vec3f position, normal;
    double area;
    uint32_t influence_end;  // its influences end here in `influences`
  };
  struct Influence {
    int32_t joint;
    float weight;
  };
  std::vector<int> frames;  // sampled frame q is frame frames[q]
  std::vector<Vertex> vertices;
  std::vector<Influence> influences;
  // The original blended normals of each sampled frame q as direction and inverse length,
  // in rows of |vertices| (x, y, z, 1/length: rows 4q to 4q+3).
  std::vector<double> normals;
  double area = 0;  // sum of the sampled vertices' areas

  uint32_t influence_begin(size_t v) const { return v == 0 ? 0 : vertices[v - 1].influence_end; }
};

// The sample of `frames` frames of a motion whose original matrices are kt (4n x 3T).
ErrorSample MakeErrorSample(const Character& character, const SolveSettings& settings,
                            const Eigen::MatrixXd& kt, int frames);

// Per sampled vertex of one sampled frame: |v - v'|^2, the normals' angle (radians) and
// |n - n'|^2, in rows of |vertices|.
struct SampleValues {
  std::vector<double> distance_squared, angle, normal_squared;
  explicit SampleValues(size_t count = 0)
      : distance_squared(count), angle(count), normal_squared(count) {}
};

// Area-weighted sums over the sample of |v - v'|, |v - v'|^2, the normals' angle and
// |n - n'|^2.
struct SampleSums {
  double distance = 0, distance_squared = 0, angle = 0, normal_squared = 0;
};

// Scratch of SampleFrameValues: n matrices, then rows of up to |vertices|.
struct SampleScratch {
  std::vector<PaddedDelta> frame_delta;
  std::vector<double> normals, normal_x, normal_y, normal_z, angle;
  explicit SampleScratch(size_t joints = 0, size_t count = 0)
      : frame_delta(joints, PaddedDelta::Zero()), normals(4 * count), normal_x(count),
        normal_y(count), normal_z(count), angle(count) {}
};

// The values of sampled frame q for the sampled vertices listed in `vertices` (nullptr:
// every one), written at their own index in `values`. frame: Delta_k^T stacked (4n x 3).
void SampleFrameValues(const ErrorSample& sample, const Eigen::Matrix<double, Eigen::Dynamic, 3>& frame,
                       size_t q, const std::vector<uint32_t>* vertices, SimdChoice simd,
                       SampleScratch& scratch, SampleValues& values);

void AddSampleSums(const ErrorSample& sample, const SampleValues& values, SampleSums& sums);

}  // namespace motionlod::core::internal
