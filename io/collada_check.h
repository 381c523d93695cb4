// A structural check of COLLADA skin data, run before Assimp sees the bytes: Assimp
// 5.2's COLLADA loader indexes vertex weights, joint names and inverse bind matrices
// without bounds checks, so a corrupted index crashes the process (found by the byte-flip
// tests). This check parses the XML itself and rejects any <accessor> that reaches past
// its array and any <vertex_weights> index past its sources. Internal to io; no Assimp.
#pragma once

#include <string_view>

#include "base/status.h"

namespace motionlod::io {

// Ok when every accessor fits its array and every skin's vertex_weights indices are in
// range; DataLoss naming the element otherwise (also for XML that is not well formed).
Status CheckColladaIndices(std::string_view xml);

}  // namespace motionlod::io
