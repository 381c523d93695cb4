// What an Asset holds, shared by the importer (asset.cc) and the wire format of the
// import worker (asset_wire.cc), which rebuilds an Asset from a validated reply.
// Internal to io.
#pragma once

#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "io/asset.h"
#include "io/clips.h"
#include "io/rig.h"
#include "io/scene.h"

namespace motionlod::io {

struct Asset::Impl {
  Rig rig;
  std::vector<SceneNode> nodes;  // what SampleAnimation poses: parents, rest transforms
  std::vector<Clip> clips;
  std::vector<AnimationInfo> infos;  // clips[k].info, in order
  std::vector<std::string> warnings;
};

struct AssetFactory {
  static std::shared_ptr<const Asset> Make(std::unique_ptr<Asset::Impl> impl) {
    return std::shared_ptr<const Asset>(new Asset(std::move(impl)));
  }
  static const Asset::Impl& ImplOf(const Asset& asset) { return *asset.impl_; }
};

}  // namespace motionlod::io
