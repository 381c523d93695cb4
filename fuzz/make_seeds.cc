// make_seeds OUT_DIR FILE...: seed inputs for the fuzzers whose inputs no data file is
// directly: OUT_DIR/asset_wire_fuzz/<name> holds the worker's reply for each FILE (as
// asset_wire_fuzz reads it: a kind byte, then the payload), and
// OUT_DIR/level_format_fuzz/<name>.mlod a two-level bake of it (a few frames).
// Run by scripts/fuzz.sh; exits 1 when a file cannot be read or baked.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include "io/asset.h"
#include "io/asset_wire.h"
#include "pipeline/bake.h"

namespace {

bool Write(const std::filesystem::path& path, const std::string& bytes) {
  std::filesystem::create_directories(path.parent_path());
  std::ofstream out(path, std::ios::binary);
  out << bytes;
  return static_cast<bool>(out);
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
