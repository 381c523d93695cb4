// UTF-8 validation for the names carried by the wire contract.
#pragma once

#include <string_view>

namespace motionlod::proto {

// True when `text` is well-formed UTF-8 (RFC 3629): no overlong forms, no UTF-16
// surrogates (U+D800..U+DFFF), nothing above U+10FFFF, no truncated sequence.
bool IsValidUtf8(std::string_view text);

}  // namespace motionlod::proto
