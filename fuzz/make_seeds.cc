// make_seeds OUT_DIR FILE...: seed inputs for the fuzzers whose inputs no data file is
// directly: OUT_DIR/asset_wire_fuzz/<name> holds the worker's reply for each FILE (as
// asset_wire_fuzz reads it: a kind byte, then the payload), and
// OUT_DIR/level_format_fuzz/<name>.mlod a two-level bake of it (a few frames); and, whatever
// the files, OUT_DIR/level_format_fuzz/clips.mlod (three clips), levels.mlod (three clips,
// levels with a frame stride, a mesh and influences of their own), v2_0.mlod and v1_0.mlod
// (version 2.0 and 1.0 files), which bakes of one clip by this version do not cover.
// Run by scripts/fuzz.sh; exits 1 when a file cannot be read or baked.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include "io/asset.h"
#include "io/asset_wire.h"
#include "pipeline/bake.h"
#include "proto/level_format.h"
#include "tests/proto/level_format_v1.h"
#include "tests/proto/level_format_v2.h"

namespace {

bool Write(const std::filesystem::path& path, const std::string& bytes) {
  std::filesystem::create_directories(path.parent_path());
  std::ofstream out(path, std::ios::binary);
  out << bytes;
  return static_cast<bool>(out);
}

// A small level set by hand: 3 joints (a chain), two levels, five frames in three clips.
motionlod::proto::LevelSetData SmallLevelSet() {
  using namespace motionlod::proto;
  LevelSetData data;
  data.variant_name = "vpno";
  data.frame_count = 5;
  data.fps = 30;
  data.joint_names = {"root", "spine", "head"};
  data.parents = {-1, 0, 1};
  for (const std::vector<uint16_t>& kept : {std::vector<uint16_t>{0, 1, 2}, {0, 2}}) {
    LevelData level;
    level.kept_joints = kept;
    level.joint_map = ComputeJointMap(data.parents, kept).value();
    for (uint32_t t = 0; t < data.frame_count; ++t) {
      for (size_t s = 0; s < kept.size(); ++s) {
        const float k[12] = {1, 0, 0, 0.1f * t, 0, 1, 0, float(s), 0, 0, 1, 0};
        level.matrices.insert(level.matrices.end(), k, k + 12);
      }
    }
    data.levels.push_back(std::move(level));
  }
  return data;
}

// SmallLevelSet in three clips with what version 3.0 adds: level 1 stores every other
// frame and has a mesh of its own (3 of the character's 4 vertices, one triangle) with 2
// influences a vertex; a third level, the root alone, every third frame with 1 influence
// on each of the character's vertices.
motionlod::proto::LevelSetData Version3LevelSet() {
  using namespace motionlod::proto;
  LevelSetData data = SmallLevelSet();
  data.clips = {{"walk", 0, 2, 30}, {"jump", 2, 2, 60}, {"idle", 4, 1, 24}};
  data.vertex_count = 4;
  data.levels.push_back(data.levels[1]);
  for (uint32_t l = 1; l < 3; ++l) {
    LevelData& level = data.levels[l];
    if (l == 2) {
      level.kept_joints = {0};
      level.joint_map = ComputeJointMap(data.parents, level.kept_joints).value();
    }
    level.frame_stride = l + 1;
    level.matrices.clear();
    for (const ClipInfo& clip : data.clips) {
      for (uint32_t i = 0; i < StoredFrameCount(clip.frame_count, level.frame_stride); ++i) {
        const uint32_t t =
            clip.first_frame + std::min(i * level.frame_stride, clip.frame_count - 1);
        for (size_t s = 0; s < level.kept_joints.size(); ++s) {
          const float k[12] = {1, 0, 0, 0.1f * t, 0, 1, 0, float(s), 0, 0, 1, 0};
          level.matrices.insert(level.matrices.end(), k, k + 12);
        }
      }
    }
    level.cost = 1.0f / float(l + 1);
  }
  data.levels[1].vertices = {0, 2, 3};
  data.levels[1].triangles = {0, 1, 2};
  data.levels[1].influences_per_vertex = 2;
  data.levels[1].influence_slots = {0, 1, 1, 0, 0, 1};
  data.levels[1].influence_weights = {0.5f, 0.5f, 1, 0, 0.25f, 0.75f};
  data.levels[2].influences_per_vertex = 1;
  data.levels[2].influence_slots.assign(data.vertex_count, 0);
  data.levels[2].influence_weights.assign(data.vertex_count, 1.0f);
  return data;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace motionlod;
  if (argc < 3) {
    std::fputs("usage: make_seeds OUT_DIR FILE...\n", stderr);
    return 2;
  }
  const std::filesystem::path out = argv[1];
  int status = 0;
  {
    proto::LevelSetData clips = SmallLevelSet();
    clips.clips = {{"walk", 0, 2, 30}, {"jump", 2, 2, 60}, {"idle", 4, 1, 24}};
    const auto encoded = proto::EncodeLevelSet(clips);
    if (!encoded.ok() || !Write(out / "level_format_fuzz" / "clips.mlod", *encoded)) status = 1;
    const auto levels = proto::EncodeLevelSet(Version3LevelSet());
    if (!levels.ok() || !Write(out / "level_format_fuzz" / "levels.mlod", *levels)) status = 1;
    const std::string v2 = proto::test_v2::EncodeVersion2(clips);
    if (!Write(out / "level_format_fuzz" / "v2_0.mlod", v2)) status = 1;
    const std::string v1 = proto::test_v1::EncodeVersion1(SmallLevelSet());
    if (!Write(out / "level_format_fuzz" / "v1_0.mlod", v1)) status = 1;
  }
  for (int a = 2; a < argc; ++a) {
    const std::string name = std::filesystem::path(argv[a]).filename().string();
    const auto asset = io::LoadAssetFile(argv[a]);
    if (!asset.ok()) {
      std::fprintf(stderr, "make_seeds: %s: %s\n", argv[a], asset.status().ToString().c_str());
      status = 1;
      continue;
    }
    // asset_wire_fuzz picks the kind as 1 + first byte % 3: 1 selects an asset reply.
    const std::string reply = io::EncodeImportReply(*asset);
    if (!Write(out / "asset_wire_fuzz" / name, "\x01" + reply.substr(io::kWireHeaderBytes)))
      status = 1;
    if ((*asset)->animations().empty()) continue;
    pipeline::BakeRequest request;
    request.character = *asset;
    request.fps = 2;
    const int joints = static_cast<int>((*asset)->character().skeleton.parents.size());
    request.levels = {joints, std::max(1, joints / 4)};
    request.threads = 1;
    const auto baked = pipeline::Bake(request);
    if (!baked.ok()) {
      std::fprintf(stderr, "make_seeds: bake of %s: %s\n", argv[a],
                   baked.status().ToString().c_str());
      status = 1;
      continue;
    }
    if (!Write(out / "level_format_fuzz" / (name + ".mlod"), baked->level_set)) status = 1;
  }
  return status;
}
