// What the client tests bake in-process and draw: a bake's level set decoded in place, its
// report, and the character's mesh as the client's skinner takes it.
#pragma once

#include <gtest/gtest.h>

#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "client/skinner.h"
#include "core/character.h"
#include "io/asset.h"
#include "pipeline/bake.h"
#include "proto/level_format.h"

namespace motionlod::client::testing {

struct Baked {
  std::shared_ptr<const core::Character> character;
  proto::AlignedBytes bytes;
  proto::LevelSetView view;
  nlohmann::json report;
};

// `animation` of the file at `path` (one clip; "" the first) baked at `levels` (empty: the
// levels by cost) in `variant` on 2 threads; failures are test failures.
inline Baked BakeInProcess(const std::string& path, const std::string& animation,
                           std::vector<int> levels, core::Variant variant) {
  Baked baked;
  auto asset = io::LoadAssetFile(path);
  EXPECT_TRUE(asset.ok()) << asset.status().ToString();
  if (!asset.ok()) return baked;
  pipeline::BakeRequest request;
  request.character = *asset;
  request.clips = {{nullptr, animation, ""}};
  request.levels = std::move(levels);
  request.settings.variant = variant;
  request.threads = 2;
  request.measure_skinning_pass = false;
  auto inputs = pipeline::PrepareInputs(request);
  auto output = pipeline::Bake(request);
  EXPECT_TRUE(inputs.ok() && output.ok()) << (output.ok() ? "" : output.status().ToString());
  if (!inputs.ok() || !output.ok()) return baked;
  baked.character = inputs->character;
  baked.bytes = proto::AlignedBytes::CopyOf(output->level_set);
  baked.report = output->report;
  auto view = proto::DecodeLevelSet(baked.bytes.bytes());
  EXPECT_TRUE(view.ok()) << view.status().ToString();
  if (view.ok()) baked.view = std::move(*view);
  return baked;
}

inline SkinMesh MeshOf(const core::Character& character) {
  const core::RawSkin& skin = character.skin();
  const size_t p = skin.positions.size();
  return SkinMesh{{skin.positions.data()->data(), 3 * p},
                  {skin.normals.data()->data(), 3 * p},
                  skin.influence_offsets,
                  skin.influence_joints,
                  skin.influence_weights};
}

}  // namespace motionlod::client::testing
