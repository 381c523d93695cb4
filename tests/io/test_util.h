// Helpers shared by the io tests: the third-party data set and skinning by hand.
#pragma once

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "base/pieces.h"
#include "core/character.h"
#include "core/motion.h"
#include "io/asset.h"

namespace motionlod::io::testing {

inline std::filesystem::path DataDir() { return std::filesystem::path(MOTIONLOD_SHARED_DATA); }

inline bool HaveData() { return std::filesystem::exists(DataDir() / "MANIFEST.md"); }

#define MOTIONLOD_REQUIRE_DATA()                                                    \
  do {                                                                              \
    if (!::motionlod::io::testing::HaveData()) GTEST_SKIP() << "no ../shared/data"; \
  } while (0)

inline std::string ReadBytes(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream buffer;
  buffer << in.rdbuf();
  return std::move(buffer).str();
}

// A PieceRunner on `threads` threads started for each call (io starts none of its own; the
// pipeline's pool is one such runner): thread w runs pieces w, w + threads, ..., so that
// pieces run at the same time and finish out of order.
inline PieceRunner ThreadRunner(int threads) {
  return [threads](int count, const std::function<void(int)>& piece) {
    std::vector<std::thread> workers;
    for (int w = 0; w < threads; ++w) {
      workers.emplace_back([&piece, count, threads, w] {
        for (int index = w; index < count; index += threads) piece(index);
      });
    }
    for (std::thread& worker : workers) worker.join();
  };
}

// Loads a data file (path relative to the data directory) once per test binary.
inline std::shared_ptr<const Asset> DataAsset(const std::string& relative) {
  static std::mutex mutex;
  static std::map<std::string, std::shared_ptr<const Asset>> cache;
  std::lock_guard<std::mutex> lock(mutex);
  auto it = cache.find(relative);
  if (it != cache.end()) return it->second;
  StatusOr<std::shared_ptr<const Asset>> asset = LoadAssetFile(DataDir() / relative);
  EXPECT_TRUE(asset.ok()) << relative << ": " << asset.status().ToString();
  std::shared_ptr<const Asset> result = asset.ok() ? *asset : nullptr;
  cache[relative] = result;
  return result;
}

// Linear blend skinning of the bind-pose skin with K_j = M_j(t) M0_j^-1.
inline std::vector<Eigen::Vector3d> SkinFrame(const core::RawCharacter& c, const core::Motion& m,
                                              int t) {
  const int n = static_cast<int>(c.skeleton.parents.size());
  std::vector<core::Affine34d> k(n);
  for (int j = 0; j < n; ++j) {
    k[j] = core::ComposeAffine(m.world(t, j), core::InverseAffine(c.skeleton.bind_world[j]));
  }
  std::vector<Eigen::Vector3d> out(c.skin.positions.size(), Eigen::Vector3d::Zero());
  for (size_t i = 0; i < out.size(); ++i) {
    const Eigen::Vector3d v = c.skin.positions[i].cast<double>();
    for (uint32_t e = c.skin.influence_offsets[i]; e < c.skin.influence_offsets[i + 1]; ++e) {
      out[i] +=
          c.skin.influence_weights[e] * core::TransformPoint(k[c.skin.influence_joints[e]], v);
    }
  }
  return out;
}

// Longest side of the bounding box.
inline double Extent(const std::vector<Eigen::Vector3d>& points) {
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e300), hi = -lo;
  for (const auto& p : points) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  return (hi - lo).maxCoeff();
}

inline std::vector<Eigen::Vector3d> BindPositions(const core::RawCharacter& c) {
  std::vector<Eigen::Vector3d> out;
  for (const auto& p : c.skin.positions) out.push_back(p.cast<double>());
  return out;
}

inline int JointIndex(const core::RawSkeleton& s, const std::string& name) {
  for (size_t j = 0; j < s.joint_names.size(); ++j) {
    if (s.joint_names[j] == name) return static_cast<int>(j);
  }
  return -1;
}

}  // namespace motionlod::io::testing
