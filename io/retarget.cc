#include "io/retarget.h"

#include <Eigen/SVD>
#include <algorithm>
#include <cctype>
#include <cmath>
#include <limits>
#include <map>

#include "core/motion.h"
#include "io/text.h"

namespace motionlod::io {
namespace {

using core::Affine34d;
using Eigen::Matrix3d;
using Eigen::Vector3d;

Matrix3d OrthogonalFactor(const Matrix3d& a) {
  Eigen::JacobiSVD<Matrix3d> svd(a, Eigen::ComputeFullU | Eigen::ComputeFullV);
  return svd.matrixU() * svd.matrixV().transpose();
}

double SkeletonHeight(const core::RawSkeleton& s) {
  Vector3d lo = Vector3d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (const Affine34d& m : s.bind_world) {
    lo = lo.cwiseMin(m.col(3));
    hi = hi.cwiseMax(m.col(3));
  }
  const double h = (hi - lo).maxCoeff();
  return h > 0 && std::isfinite(h) ? h : 1.0;
}

Status CheckSkeleton(const core::RawSkeleton& s, const char* which) {
  const size_t n = s.parents.size();
  const std::string w(which);
  if (n == 0) return InvalidArgument("the " + w + " skeleton has no joints");
  if (s.joint_names.size() != n || s.bind_world.size() != n) {
    return InvalidArgument("the " + w + " skeleton's arrays differ in length");
  }
  if (s.parents[0] != -1)
    return InvalidArgument("joint 0 of the " + w + " skeleton must be the root");
  for (size_t j = 0; j < n; ++j) {
    if (j > 0 && (s.parents[j] < 0 || s.parents[j] >= static_cast<int>(j))) {
      return InvalidArgument("joint '" + s.joint_names[j] + "' of the " + w +
                             " skeleton does not follow its parent");
    }
    if (!core::IsInvertibleAffine(s.bind_world[j])) {
      return InvalidArgument("joint '" + s.joint_names[j] + "' of the " + w +
                             " skeleton has a singular bind matrix");
    }
  }
  return Status::Ok();
}

std::string Lower(std::string_view text) {
  std::string out(text);
  for (char& c : out) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return out;
}

}  // namespace

std::string NormalizeJointName(std::string_view name) {
  const size_t cut = name.find_last_of(":|");
  if (cut != std::string_view::npos && cut + 1 < name.size()) name.remove_prefix(cut + 1);
  std::string lower = Lower(name);
  static const char* const kPrefixes[] = {"mixamorig_", "mixamorig", "bip001 ", "bip001_",
                                          "bip01 ",     "bip01_",    "def-",    "def_",
                                          "org-",       "armature_"};
  for (bool stripped = true; stripped;) {
    stripped = false;
    for (const char* prefix : kPrefixes) {
      const std::string_view p(prefix);
      if (lower.size() > p.size() && lower.compare(0, p.size(), p) == 0) {
        lower.erase(0, p.size());
        stripped = true;
      }
    }
  }
  std::string out;
  for (char c : lower) {
    if (c != ' ' && c != '_' && c != '-' && c != '.' && c != ':') out += c;
  }
  return out.empty() ? lower : out;
}

StatusOr<RetargetedMotion> RetargetMotion(const core::RawSkeleton& source,
                                          const core::Motion& source_motion,
                                          const core::RawSkeleton& target) {
  if (Status s = CheckSkeleton(source, "source"); !s.ok()) return s;
  if (Status s = CheckSkeleton(target, "target"); !s.ok()) return s;
  const int ns = static_cast<int>(source.parents.size());
  const int nt = static_cast<int>(target.parents.size());
  const int frames = source_motion.frame_count;
  if (source_motion.joint_count != ns || frames < 1 ||
      source_motion.joint_world.size() != static_cast<size_t>(frames) * ns) {
    return InvalidArgument("the source motion does not match the source skeleton");
  }

  // Matching: exact names, then unique normalised names; each source joint used once.
  std::vector<int> match(nt, -1);
  std::vector<char> taken(ns, 0);
  std::map<std::string, int> exact;
  for (int s = 0; s < ns; ++s) exact.emplace(source.joint_names[s], s);
  for (int j = 0; j < nt; ++j) {
    const auto it = exact.find(target.joint_names[j]);
    if (it != exact.end() && !taken[it->second]) {
      match[j] = it->second;
      taken[it->second] = 1;
    }
  }
  std::map<std::string, std::vector<int>> normalized;
  for (int s = 0; s < ns; ++s) {
    if (!taken[s]) normalized[NormalizeJointName(source.joint_names[s])].push_back(s);
  }
  std::map<std::string, int> target_key_count;
  for (int j = 0; j < nt; ++j) {
    if (match[j] < 0) ++target_key_count[NormalizeJointName(target.joint_names[j])];
  }
  for (int j = 0; j < nt; ++j) {
    if (match[j] >= 0) continue;
    const std::string key = NormalizeJointName(target.joint_names[j]);
    const auto it = normalized.find(key);
    if (it != normalized.end() && it->second.size() == 1 && target_key_count[key] == 1) {
      match[j] = it->second.front();
      taken[match[j]] = 1;
    }
  }
  RetargetedMotion result;
  int matched = 0;
  for (int j = 0; j < nt; ++j) {
    if (match[j] >= 0) {
      ++matched;
    } else {
      result.unmatched_target_joints.push_back(target.joint_names[j]);
    }
  }
  for (int s = 0; s < ns; ++s) {
    if (!taken[s]) result.unmatched_source_joints.push_back(source.joint_names[s]);
  }
  if (2 * matched < nt) {
    return InvalidArgument(
        "only " + std::to_string(matched) + " of the target's " + std::to_string(nt) +
        " joints match a source joint by name (at least half must); unmatched: " +
        QuotedList(result.unmatched_target_joints));
  }

  // anchor[j]: the nearest strict ancestor of target joint j that is matched.
  std::vector<int> anchor(nt, -1);
  for (int j = 1; j < nt; ++j) {
    const int q = target.parents[j];
    anchor[j] = match[q] >= 0 ? q : anchor[q];
  }
  const double h = SkeletonHeight(target) / SkeletonHeight(source);
  std::vector<Matrix3d> source_bind_rotation(ns);
  for (int s = 0; s < ns; ++s)
    source_bind_rotation[s] = OrthogonalFactor(source.bind_world[s].leftCols<3>());

  core::Motion& out = result.motion;
  out.name = source_motion.name;
  out.fps = source_motion.fps;
  out.frame_count = frames;
  out.joint_count = nt;
  out.joint_world.resize(static_cast<size_t>(frames) * nt);
  std::vector<Matrix3d> source_change(ns), target_change(nt);
  for (int t = 0; t < frames; ++t) {
    for (int s = 0; s < ns; ++s) {
      source_change[s] = OrthogonalFactor(source_motion.world(t, s).leftCols<3>()) *
                         source_bind_rotation[s].transpose();
    }
    Affine34d* world = &out.joint_world[static_cast<size_t>(t) * nt];
    for (int j = 0; j < nt; ++j) {
      const int q = target.parents[j];
      const Affine34d& bind = target.bind_world[j];
      const Matrix3d change = match[j] >= 0 ? source_change[match[j]]
                              : q >= 0      ? target_change[q]
                                            : Matrix3d::Identity();
      Vector3d position =
          q >= 0 ? Vector3d(world[q].col(3) +
                            target_change[q] * (bind.col(3) - target.bind_world[q].col(3)))
                 : Vector3d(bind.col(3));
      if (match[j] >= 0) {
        const int s = match[j];
        const int ps = source.parents[s];
        Vector3d delta = Vector3d::Zero();
        if (anchor[j] < 0) {
          delta = source_motion.world(t, s).col(3) - source.bind_world[s].col(3);
        } else if (ps >= 0 && ps == match[anchor[j]]) {
          delta = (source_motion.world(t, s).col(3) - source_motion.world(t, ps).col(3)) -
                  source_change[ps] * (source.bind_world[s].col(3) - source.bind_world[ps].col(3));
        }
        position += h * delta;
      }
      target_change[j] = change;
      world[j].leftCols<3>() = change * bind.leftCols<3>();
      world[j].col(3) = position;
    }
  }
  return result;
}

StatusOr<RetargetedMotion> RetargetAnimation(const Asset& source, std::string_view animation,
                                             double fps, const core::RawCharacter& target,
                                             const PieceRunner& run) {
  StatusOr<core::Motion> motion = source.SampleAnimation(animation, fps, run);
  if (!motion.ok()) return motion.status();
  return RetargetMotion(source.character().skeleton, *motion, target.skeleton);
}

}  // namespace motionlod::io
