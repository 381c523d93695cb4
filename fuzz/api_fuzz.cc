// libFuzzer target for the JSON body parser of POST /v1/bakes (proto/api.h): any text
// must parse or fail with InvalidArgument, never crash or throw; what parses serialises
// back to JSON that parses to the same request.
#include <cstddef>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string_view>

#include "fuzz/check.h"
#include "proto/api.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace motionlod;
  using fuzz::Check;
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  (void)proto::api::IsContentId(text);
  const auto request = proto::api::ParseBakeRequest(text);
  if (!request.ok()) {
    Check(request.status().code() == StatusCode::kInvalidArgument);
    return 0;
  }
  const std::string again = nlohmann::json(*request).dump();
  const auto reparsed = proto::api::ParseBakeRequest(again);
  Check(reparsed.ok());
  Check(nlohmann::json(*reparsed).dump() == again);
  return 0;
}
