// libFuzzer target for the daemon's side of the import worker protocol: whatever a
// compromised worker sends back must decode to a valid asset or fail with DataLoss,
// never crash, over-read or allocate without bound. The input is a payload; the target
// wraps it in a correct header and checksum (a hostile worker can compute those, and
// mutations could not), with the first byte choosing the message kind.
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>

#include "base/hash.h"
#include "core/character.h"
#include "fuzz/check.h"
#include "io/asset_wire.h"

namespace {

std::string Message(uint16_t kind, std::string_view payload) {
  std::string message(motionlod::io::kWireHeaderBytes, '\0');
  std::memcpy(message.data(), "MLODWIRE", 8);
  const uint16_t version = motionlod::io::kAssetWireVersion;
  const uint64_t size = payload.size(), checksum = motionlod::Fnv1a64(payload);
  std::memcpy(message.data() + 8, &version, 2);
  std::memcpy(message.data() + 10, &kind, 2);
  std::memcpy(message.data() + 16, &size, 8);
  std::memcpy(message.data() + 24, &checksum, 8);
  return message.append(payload);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace motionlod;
  using fuzz::Check;
  if (size == 0) return 0;
  const uint16_t kind = data[0] % 3 + 1;  // request, asset reply, error reply
  const std::string message =
      Message(kind, std::string_view(reinterpret_cast<const char*>(data) + 1, size - 1));
  if (kind == static_cast<uint16_t>(io::MessageKind::kImportRequest)) {
    const auto request = io::DecodeImportRequest(message);
    if (request.ok()) {
      // What decodes re-encodes to the same message.
      Check(io::EncodeImportRequest(request->files, request->options) == message);
    }
    return 0;
  }
  const auto reply = io::DecodeImportReply(message);
  if (!reply.ok()) {
    Check(reply.status().code() != StatusCode::kOk &&
          reply.status().code() != StatusCode::kInternal);
    return 0;
  }
  // An accepted asset is usable: it validates, re-encodes identically and samples.
  Check(core::ValidateRawCharacter((*reply)->character()).ok());
  Check(io::EncodeImportReply(*reply) == message);
  for (const io::AnimationInfo& info : (*reply)->animations()) {
    (void)(*reply)->SampleAnimation(info.name, 1);
  }
  return 0;
}
