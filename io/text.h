// Small string helpers for Status messages. Internal to io.
#pragma once

#include <string>
#include <string_view>
#include <vector>

namespace motionlod::io {

// 'text' (single quotes around it).
inline std::string Quote(std::string_view text) {
  std::string out;
  out.reserve(text.size() + 2);
  out += '\'';
  out += text;
  out += '\'';
  return out;
}

// 'a', 'b', 'c'
template <typename Container>
std::string QuotedList(const Container& items) {
  std::string out;
  for (const auto& item : items) {
    if (!out.empty()) out += ", ";
    out += Quote(item);
  }
  return out;
}

}  // namespace motionlod::io
