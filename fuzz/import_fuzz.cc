// libFuzzer target for the importer as the import worker runs it (one per advertised
// format: MOTIONLOD_FUZZ_EXTENSION names the upload's extension): any bytes must import
// or fail with a Status. An imported asset must cross the worker's wire format and pass
// the daemon's validation unchanged, and its first animation must sample. Crashes inside
// Assimp itself cannot be fixed here: in the daemon the sandboxed worker turns them into
// a 422 (see docs/RELIABILITY.md).
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "fuzz/check.h"
#include "io/asset.h"
#include "io/asset_wire.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace motionlod;
  using fuzz::Check;
  std::vector<io::SourceFile> files = {{std::string("fuzz.") + MOTIONLOD_FUZZ_EXTENSION,
                                        std::string(reinterpret_cast<const char*>(data), size)}};
  const auto asset = io::LoadAsset(std::move(files));
  if (!asset.ok()) {
    Check(asset.status().code() != StatusCode::kOk);
    return 0;
  }
  const std::string reply = io::EncodeImportReply(*asset);
  const auto decoded = io::DecodeImportReply(reply);
  Check(decoded.ok());
  Check(io::EncodeImportReply(*decoded) == reply);
  if (!(*asset)->animations().empty()) {
    // A low rate keeps long clips cheap; the sampler's limits hold at any rate.
    (void)(*asset)->SampleAnimation((*asset)->animations().front().name, 5);
  }
  return 0;
}
