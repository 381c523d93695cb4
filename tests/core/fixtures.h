// Small hand-made characters and motions for core tests: shapes simple enough to check
// by hand, rich enough to exercise every code path.
#pragma once

#include <cmath>
#include <cstdlib>
#include <memory>

#include <Eigen/Geometry>

#include "core/character.h"
#include "core/motion.h"
#include "core/simd.h"

namespace motionlod::core::testing {

// The machine version the tests run (core/simd.h): MOTIONLOD_SIMD, as the programs read
// it, so that ctest runs the suites once per version.
inline SimdChoice TestSimd() {
  const char* setting = std::getenv("MOTIONLOD_SIMD");
  const auto choice = ParseSimdChoice(setting != nullptr ? setting : "");
  if (!choice.ok()) std::abort();
  return *choice;
}

inline Affine34d Translation(double x, double y, double z) {
  Affine34d m = IdentityAffine();
  m.col(3) << x, y, z;
  return m;
}

inline Affine34d RotationAbout(const Vec3d& axis, double angle, const Vec3d& pivot) {
  Affine34d m;
  const Eigen::Matrix3d r = Eigen::AngleAxisd(angle, axis.normalized()).toRotationMatrix();
  m.leftCols<3>() = r;
  m.col(3) = pivot - r * pivot;
  return m;
}

// A Y-shaped creature: root (0,0,0) -> spine (0,1,0) -> neck (0,2,0) -> head (0,2.5,0),
// with two arms spine -> arm_l (-0.5,1.6,0) -> hand_l (-1.2,1.6,0) and the mirror, each
// bone wrapped in a tube of `segments` sides whose rings blend between the bone's two
// joints.
inline RawCharacter MakeCreature(int segments = 8, int rings_per_bone = 4) {
  RawCharacter c;
  c.name = "creature";
  RawSkeleton& s = c.skeleton;
  const char* names[] = {"root", "spine", "neck", "head", "arm_l", "hand_l", "arm_r", "hand_r"};
  const int parents[] = {-1, 0, 1, 2, 1, 4, 1, 6};
  const Vec3d positions[] = {{0, 0, 0},      {0, 1, 0},       {0, 2, 0},     {0, 2.5, 0},
                             {-0.5, 1.6, 0}, {-1.2, 1.6, 0}, {0.5, 1.6, 0}, {1.2, 1.6, 0}};
  for (int j = 0; j < 8; ++j) {
    s.joint_names.push_back(names[j]);
    s.parents.push_back(parents[j]);
    s.bind_world.push_back(Translation(positions[j].x(), positions[j].y(), positions[j].z()));
  }
  RawSkin& k = c.skin;
  k.influence_offsets.push_back(0);
  for (int j = 1; j < 8; ++j) {
    const int parent = parents[j];
    const Vec3d a = positions[parent], b = positions[j];
    const Vec3d axis = (b - a).normalized();
    const Vec3d side = std::abs(axis.z()) < 0.9 ? axis.cross(Vec3d::UnitZ()).normalized()
                                                : axis.cross(Vec3d::UnitX()).normalized();
    const Vec3d up = axis.cross(side);
    const uint32_t first = static_cast<uint32_t>(k.positions.size());
    for (int ring = 0; ring <= rings_per_bone; ++ring) {
      const double u = static_cast<double>(ring) / rings_per_bone;
      const Vec3d center = a + u * (b - a);
      for (int q = 0; q < segments; ++q) {
        const double phi = 2 * M_PI * q / segments;
        const Vec3d normal = std::cos(phi) * side + std::sin(phi) * up;
        k.positions.push_back((center + 0.15 * normal).cast<float>());
        k.normals.push_back(normal.cast<float>());
        // Near the parent end the parent's own parent bone blends in.
        const float w_child = static_cast<float>(u);
        if (w_child <= 0) {
          k.influence_joints.push_back(parent);
          k.influence_weights.push_back(1.0f);
        } else if (w_child >= 1) {
          k.influence_joints.push_back(j);
          k.influence_weights.push_back(1.0f);
        } else {
          k.influence_joints.push_back(parent);
          k.influence_weights.push_back(1.0f - w_child);
          k.influence_joints.push_back(j);
          k.influence_weights.push_back(w_child);
        }
        k.influence_offsets.push_back(static_cast<uint32_t>(k.influence_joints.size()));
      }
    }
    for (int ring = 0; ring < rings_per_bone; ++ring) {
      for (int q = 0; q < segments; ++q) {
        const uint32_t a0 = first + ring * segments + q;
        const uint32_t a1 = first + ring * segments + (q + 1) % segments;
        const uint32_t b0 = a0 + segments, b1 = a1 + segments;
        k.triangles.push_back({a0, a1, b1});
        k.triangles.push_back({a0, b1, b0});
      }
    }
  }
  return c;
}

inline std::shared_ptr<const Character> BuildOrDie(RawCharacter raw) {
  auto built = BuildCharacter(std::move(raw));
  if (!built.ok()) std::abort();
  return *built;
}

// Local rotations that vary per joint and frame, composed down the hierarchy; the root
// also travels. `still` joints keep their bind pose.
inline Motion MakeWaveMotion(const Character& c, int frames, double amplitude = 0.6,
                             std::vector<int> still = {}) {
  Motion m;
  m.name = "wave";
  m.fps = 30;
  m.frame_count = frames;
  m.joint_count = c.joint_count();
  m.joint_world.resize(static_cast<size_t>(frames) * m.joint_count);
  const RawSkeleton& s = c.skeleton();
  for (int t = 0; t < frames; ++t) {
    for (int j = 0; j < m.joint_count; ++j) {
      const int parent = s.parents[j];
      const Affine34d bind_local =
          parent < 0 ? s.bind_world[j] : ComposeAffine(InverseAffine(s.bind_world[parent]), s.bind_world[j]);
      const bool is_still = std::find(still.begin(), still.end(), j) != still.end();
      const double angle = is_still ? 0.0 : amplitude * std::sin(0.2 * t + 1.3 * j);
      const Vec3d axis(std::sin(j), std::cos(0.7 * j), 0.5);
      Affine34d local = ComposeAffine(bind_local, RotationAbout(axis, angle, Vec3d::Zero()));
      if (parent < 0) local.col(3) += Vec3d(0.05 * t, 0.1 * std::sin(0.3 * t), 0);
      m.joint_world[static_cast<size_t>(t) * m.joint_count + j] =
          parent < 0 ? local : ComposeAffine(m.world(t, parent), local);
    }
  }
  return m;
}

}  // namespace motionlod::core::testing
