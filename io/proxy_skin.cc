#include "io/proxy_skin.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <string>
#include <vector>

namespace motionlod::io {
namespace {

using core::Vec3d;

double SmoothStep(double x) {
  if (x <= 0) return 0;
  if (x >= 1) return 1;
  return x * x * (3 - 2 * x);
}

// One ring of a surface of revolution around the capsule axis.
struct ProfileRing {
  double axial;   // distance from the capsule start along the axis
  double radius;  // 0 for a pole
  double normal_axial;
  double normal_radial;
};

struct Capsule {
  Vec3d start;
  Vec3d axis;  // unit
  double length;
  double radius;
  int start_joint;  // blended in near the start, -1 for none
  int owner;
  int end_joint;  // blended in near the end, -1 for none
};

class Builder {
 public:
  Builder(const ProxySkinOptions& options, core::RawSkin& skin) : o_(options), skin_(skin) {
    skin_.influence_offsets.assign(1, 0);
  }

  void Add(const Capsule& c) {
    std::vector<ProfileRing> profile;
    profile.push_back({-c.radius, 0, -1, 0});
    const double half_pi = std::numbers::pi / 2;
    for (int k = o_.cap_rings; k >= 1; --k) {
      const double phi = half_pi * k / (o_.cap_rings + 1);  // from the equator
      profile.push_back(
          {-c.radius * std::sin(phi), c.radius * std::cos(phi), -std::sin(phi), std::cos(phi)});
    }
    for (int i = 0; i <= o_.rings; ++i)
      profile.push_back({c.length * i / o_.rings, c.radius, 0, 1});
    for (int k = 1; k <= o_.cap_rings; ++k) {
      const double phi = half_pi * k / (o_.cap_rings + 1);
      profile.push_back({c.length + c.radius * std::sin(phi), c.radius * std::cos(phi),
                         std::sin(phi), std::cos(phi)});
    }
    profile.push_back({c.length + c.radius, 0, 1, 0});

    // Any unit vector orthogonal to the axis.
    Vec3d helper = std::abs(c.axis.x()) < 0.9 ? Vec3d::UnitX() : Vec3d::UnitY();
    const Vec3d e1 = c.axis.cross(helper).normalized();
    const Vec3d e2 = c.axis.cross(e1);

    std::vector<std::vector<uint32_t>> ring_vertices;
    for (const ProfileRing& ring : profile) {
      const double s = c.length > 0 ? std::clamp(ring.axial / c.length, 0.0, 1.0) : 0.5;
      const int count = ring.radius == 0 ? 1 : o_.sides;
      std::vector<uint32_t> ids;
      for (int m = 0; m < count; ++m) {
        const double theta = 2 * std::numbers::pi * m / o_.sides;
        const Vec3d radial = std::cos(theta) * e1 + std::sin(theta) * e2;
        const Vec3d position = c.start + ring.axial * c.axis + ring.radius * radial;
        const Vec3d normal =
            (ring.normal_axial * c.axis + ring.normal_radial * radial).normalized();
        ids.push_back(AddVertex(position, normal, c, s));
      }
      ring_vertices.push_back(std::move(ids));
    }
    for (size_t r = 0; r + 1 < ring_vertices.size(); ++r) {
      const std::vector<uint32_t>& a = ring_vertices[r];
      const std::vector<uint32_t>& b = ring_vertices[r + 1];
      for (int m = 0; m < o_.sides; ++m) {
        const int m1 = (m + 1) % o_.sides;
        if (a.size() == 1) {
          AddTriangle(a[0], b[m], b[m1]);
        } else if (b.size() == 1) {
          AddTriangle(a[m], a[m1], b[0]);
        } else {
          AddTriangle(a[m], a[m1], b[m]);
          AddTriangle(a[m1], b[m1], b[m]);
        }
      }
    }
  }

 private:
  uint32_t AddVertex(const Vec3d& position, const Vec3d& normal, const Capsule& c, double s) {
    const double w_start = c.start_joint >= 0 ? 0.5 * SmoothStep(1 - s / o_.blend) : 0.0;
    const double w_end = c.end_joint >= 0 ? 0.5 * SmoothStep(1 - (1 - s) / o_.blend) : 0.0;
    const double w_owner = 1 - w_start - w_end;
    const uint32_t id = static_cast<uint32_t>(skin_.positions.size());
    skin_.positions.push_back(position.cast<float>());
    skin_.normals.push_back(normal.cast<float>().normalized());
    for (const auto& [joint, weight] :
         {std::pair{c.start_joint, w_start}, std::pair{c.owner, w_owner},
          std::pair{c.end_joint, w_end}}) {
      if (joint >= 0 && weight > 1e-6) {
        skin_.influence_joints.push_back(joint);
        skin_.influence_weights.push_back(static_cast<float>(weight));
      }
    }
    // Renormalise after dropping the tiny weights, in float.
    float sum = 0;
    for (size_t e = skin_.influence_offsets.back(); e < skin_.influence_weights.size(); ++e) {
      sum += skin_.influence_weights[e];
    }
    for (size_t e = skin_.influence_offsets.back(); e < skin_.influence_weights.size(); ++e) {
      skin_.influence_weights[e] /= sum;
    }
    skin_.influence_offsets.push_back(static_cast<uint32_t>(skin_.influence_joints.size()));
    return id;
  }

  // Winds the triangle so that it faces along the vertex normals.
  void AddTriangle(uint32_t a, uint32_t b, uint32_t c) {
    const Vec3d pa = skin_.positions[a].cast<double>(), pb = skin_.positions[b].cast<double>(),
                pc = skin_.positions[c].cast<double>();
    const Vec3d n = (skin_.normals[a] + skin_.normals[b] + skin_.normals[c]).cast<double>();
    if ((pb - pa).cross(pc - pa).dot(n) < 0) std::swap(b, c);
    skin_.triangles.push_back({a, b, c});
  }

  const ProxySkinOptions& o_;
  core::RawSkin& skin_;
};

Status ValidateSkeleton(const core::RawSkeleton& s) {
  const size_t n = s.parents.size();
  if (n == 0) return InvalidArgument("the skeleton has no joints");
  if (s.bind_world.size() != n)
    return InvalidArgument("the skeleton has " + std::to_string(n) + " parents but " +
                           std::to_string(s.bind_world.size()) + " bind matrices");
  if (s.parents[0] != -1) return InvalidArgument("joint 0 must be the root (parent -1)");
  for (size_t j = 1; j < n; ++j) {
    if (s.parents[j] < 0 || s.parents[j] >= static_cast<int>(j)) {
      return InvalidArgument("joint " + std::to_string(j) + " has parent " +
                             std::to_string(s.parents[j]) + "; joints must follow their parent");
    }
  }
  for (size_t j = 0; j < n; ++j) {
    if (!s.bind_world[j].allFinite()) {
      return InvalidArgument("joint " + std::to_string(j) + " has a non-finite bind matrix");
    }
  }
  return Status::Ok();
}

}  // namespace

Status ProxySkinOptions::Validate() const {
  if (sides < 3 || sides > 64) return InvalidArgument("proxy skin sides must be in [3, 64]");
  if (rings < 1 || rings > 64) return InvalidArgument("proxy skin rings must be in [1, 64]");
  if (cap_rings < 1 || cap_rings > 16)
    return InvalidArgument("proxy skin cap_rings must be in [1, 16]");
  if (!(radius_ratio > 0) || !(min_radius_ratio > 0) || !(max_radius_ratio >= min_radius_ratio) ||
      !std::isfinite(radius_ratio) || !std::isfinite(max_radius_ratio)) {
    return InvalidArgument("proxy skin radii must be positive with min <= max");
  }
  if (!(leaf_length_ratio > 0) || !std::isfinite(leaf_length_ratio)) {
    return InvalidArgument("proxy skin leaf_length_ratio must be positive");
  }
  if (!(blend > 0 && blend <= 0.5)) return InvalidArgument("proxy skin blend must be in (0, 0.5]");
  return Status::Ok();
}

StatusOr<core::RawSkin> MakeProxySkin(const core::RawSkeleton& skeleton,
                                      const ProxySkinOptions& options) {
  if (Status s = options.Validate(); !s.ok()) return s;
  if (Status s = ValidateSkeleton(skeleton); !s.ok()) return s;
  const int n = static_cast<int>(skeleton.parents.size());
  std::vector<Vec3d> position(n);
  Vec3d lo = Vec3d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (int j = 0; j < n; ++j) {
    position[j] = skeleton.bind_world[j].col(3);
    lo = lo.cwiseMin(position[j]);
    hi = hi.cwiseMax(position[j]);
  }
  double height = (hi - lo).maxCoeff();
  if (!(height > 0)) height = 1.0;
  const double tiny = 1e-6 * height;
  auto radius_for = [&](double length) {
    return std::clamp(options.radius_ratio * length, options.min_radius_ratio * height,
                      options.max_radius_ratio * height);
  };
  std::vector<int> child_count(n, 0);
  for (int j = 1; j < n; ++j) ++child_count[skeleton.parents[j]];

  core::RawSkin skin;
  Builder builder(options, skin);
  for (int j = 1; j < n; ++j) {
    const int p = skeleton.parents[j];
    const Vec3d d = position[j] - position[p];
    const double length = d.norm();
    if (length <= tiny) continue;
    builder.Add({position[p], d / length, length, radius_for(length), skeleton.parents[p], p, j});
  }
  for (int j = 0; j < n; ++j) {
    if (child_count[j] != 0 || j == 0) continue;
    // Continue the nearest non-degenerate bone above the leaf.
    Vec3d direction = Vec3d::Zero();
    for (int q = j; q > 0; q = skeleton.parents[q]) {
      direction = position[q] - position[skeleton.parents[q]];
      if (direction.norm() > tiny) break;
    }
    double bone = direction.norm();
    if (bone <= tiny) {
      direction = Vec3d::UnitY();
      bone = 0.1 * height;
    }
    const double length = options.leaf_length_ratio * bone;
    builder.Add({position[j], direction / direction.norm(), length, radius_for(length),
                 skeleton.parents[j], j, -1});
  }
  if (skin.positions.empty()) {
    // No bone has a length (a lone joint, or all joints at one point): a ball at the root.
    const double r = options.max_radius_ratio * height;
    builder.Add({position[0], Vec3d::UnitY(), 0.0, r > 0 ? r : 1.0, -1, 0, -1});
  }
  return skin;
}

}  // namespace motionlod::io
