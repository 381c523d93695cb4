#include "io/format.h"

#include <algorithm>
#include <cctype>
#include <cstdint>
#include <cstring>

#include "io/text.h"

namespace motionlod::io {
namespace {

uint32_t ReadLittleEndian32(std::string_view bytes, size_t offset) {
  uint32_t value = 0;
  for (int b = 3; b >= 0; --b) {
    value = (value << 8) | static_cast<unsigned char>(bytes[offset + static_cast<size_t>(b)]);
  }
  return value;
}

// The text after a UTF-8 byte order mark and leading white space.
std::string_view SkipBomAndSpace(std::string_view text) {
  if (text.substr(0, 3) == "\xEF\xBB\xBF") text.remove_prefix(3);
  while (!text.empty() && std::isspace(static_cast<unsigned char>(text.front()))) {
    text.remove_prefix(1);
  }
  return text;
}

bool StartsWithNoCase(std::string_view text, std::string_view prefix) {
  if (text.size() < prefix.size()) return false;
  for (size_t i = 0; i < prefix.size(); ++i) {
    if (std::tolower(static_cast<unsigned char>(text[i])) !=
        std::tolower(static_cast<unsigned char>(prefix[i]))) {
      return false;
    }
  }
  return true;
}

std::string Quoted(std::string_view name) { return Quote(name); }

Status NotThatFormat(std::string_view name, Format format, std::string_view why) {
  return InvalidArgument(Quoted(name) + " does not look like a " + FormatName(format) + " file (" +
                         std::string(why) + ")");
}

StatusOr<Format> CheckGlb(std::string_view name, std::string_view bytes) {
  if (bytes.size() < 12) {
    return DataLoss(Quoted(name) +
                    " is truncated: a binary glTF header needs 12 bytes, the file has " +
                    std::to_string(bytes.size()));
  }
  const uint32_t version = ReadLittleEndian32(bytes, 4);
  if (version != 1 && version != 2) {
    return Unsupported(Quoted(name) + " is binary glTF version " + std::to_string(version) +
                       "; only versions 1 and 2 are supported");
  }
  const uint32_t declared = ReadLittleEndian32(bytes, 8);
  if (declared > bytes.size()) {
    return DataLoss(Quoted(name) + " is truncated: its header declares " +
                    std::to_string(declared) + " bytes but the file has " +
                    std::to_string(bytes.size()));
  }
  if (declared < 20) {
    return DataLoss(Quoted(name) + " is corrupted: its header declares a length of " +
                    std::to_string(declared) + " bytes, too short for any content");
  }
  return Format::kGlb;
}

StatusOr<Format> CheckGltfFamily(std::string_view name, std::string_view bytes) {
  if (bytes.substr(0, 4) == "glTF") return CheckGlb(name, bytes);
  const std::string_view text = SkipBomAndSpace(bytes);
  if (text.empty() || text.front() != '{') {
    return NotThatFormat(name, Format::kGltf, "neither the 'glTF' magic nor a JSON object");
  }
  if (text.find("\"asset\"") == std::string_view::npos) {
    return NotThatFormat(name, Format::kGltf, "the JSON has no \"asset\" member");
  }
  return Format::kGltf;
}

StatusOr<Format> CheckFbx(std::string_view name, std::string_view bytes) {
  static constexpr std::string_view kBinaryMagic("Kaydara FBX Binary  \0", 21);
  if (bytes.substr(0, kBinaryMagic.size()) == kBinaryMagic) {
    if (bytes.size() < 27) {
      return DataLoss(Quoted(name) + " is truncated inside the binary FBX header");
    }
    return Format::kFbx;
  }
  const std::string_view head = SkipBomAndSpace(bytes.substr(0, 1 << 16));
  if (head.find("FBXHeaderExtension") != std::string_view::npos ||
      StartsWithNoCase(head, "; FBX")) {
    return Format::kFbx;
  }
  return NotThatFormat(name, Format::kFbx, "no 'Kaydara FBX Binary' magic and no ASCII FBX header");
}

StatusOr<Format> CheckCollada(std::string_view name, std::string_view bytes) {
  const std::string_view head = SkipBomAndSpace(bytes.substr(0, 1 << 16));
  if (head.empty() || head.front() != '<') {
    return NotThatFormat(name, Format::kCollada, "not XML");
  }
  if (head.find("<COLLADA") == std::string_view::npos) {
    return NotThatFormat(name, Format::kCollada, "no <COLLADA> element near the start");
  }
  return Format::kCollada;
}

StatusOr<Format> CheckBvh(std::string_view name, std::string_view bytes) {
  if (!StartsWithNoCase(SkipBomAndSpace(bytes), "HIERARCHY")) {
    return NotThatFormat(name, Format::kBvh, "it does not start with HIERARCHY");
  }
  return Format::kBvh;
}

StatusOr<Format> CheckDirectX(std::string_view name, std::string_view bytes) {
  if (bytes.substr(0, 4) != "xof ") {
    return NotThatFormat(name, Format::kDirectX, "no 'xof ' magic");
  }
  if (bytes.size() < 16) return DataLoss(Quoted(name) + " is truncated inside the .x header");
  return Format::kDirectX;
}

StatusOr<Format> CheckSmd(std::string_view name, std::string_view bytes) {
  std::string_view text = SkipBomAndSpace(bytes);
  while (text.substr(0, 2) == "//" || text.substr(0, 1) == "#" || text.substr(0, 1) == ";") {
    const size_t end = text.find('\n');
    text = end == std::string_view::npos ? std::string_view() : SkipBomAndSpace(text.substr(end));
  }
  if (!StartsWithNoCase(text, "version")) {
    return NotThatFormat(name, Format::kSmd, "it does not start with 'version'");
  }
  return Format::kSmd;
}

}  // namespace

const std::vector<std::string>& AllFormatExtensions() {
  static const std::vector<std::string> kExtensions = {"glb", "gltf", "fbx", "dae",
                                                       "bvh", "x",    "smd"};
  return kExtensions;
}

const char* FormatName(Format format) {
  switch (format) {
    case Format::kGlb:
      return "binary glTF";
    case Format::kGltf:
      return "glTF";
    case Format::kFbx:
      return "FBX";
    case Format::kCollada:
      return "COLLADA";
    case Format::kBvh:
      return "BVH";
    case Format::kDirectX:
      return "DirectX .x";
    case Format::kSmd:
      return "Valve SMD";
  }
  return "unknown";
}

const char* AssimpExtension(Format format) {
  switch (format) {
    case Format::kGlb:
      return "glb";
    case Format::kGltf:
      return "gltf";
    case Format::kFbx:
      return "fbx";
    case Format::kCollada:
      return "dae";
    case Format::kBvh:
      return "bvh";
    case Format::kDirectX:
      return "x";
    case Format::kSmd:
      return "smd";
  }
  return "";
}

std::string LowerExtension(std::string_view name) {
  const size_t dot = name.rfind('.');
  if (dot == std::string_view::npos || dot + 1 == name.size()) return "";
  std::string extension(name.substr(dot + 1));
  for (char& c : extension) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return extension;
}

StatusOr<Format> DetectFormat(std::string_view name, std::string_view bytes,
                              const std::vector<std::string>& allowed) {
  if (name.empty() || name.find_first_of("/\\") != std::string_view::npos || name == "." ||
      name == ".." || name.find('\0') != std::string_view::npos) {
    return InvalidArgument("the file name " + Quoted(name) +
                           " must be a plain name without directories");
  }
  const std::string extension = LowerExtension(name);
  std::string accepted;
  for (const std::string& e : allowed) accepted += (accepted.empty() ? "." : ", .") + e;
  if (extension.empty() || std::find(allowed.begin(), allowed.end(), extension) == allowed.end()) {
    return Unsupported(Quoted(name) + " has " +
                       (extension.empty() ? std::string("no extension")
                                          : "the unsupported extension '." + extension + "'") +
                       "; accepted: " + accepted);
  }
  if (bytes.empty()) return InvalidArgument(Quoted(name) + " is empty");
  if (extension == "glb" || extension == "gltf") return CheckGltfFamily(name, bytes);
  if (extension == "fbx") return CheckFbx(name, bytes);
  if (extension == "dae") return CheckCollada(name, bytes);
  if (extension == "bvh") return CheckBvh(name, bytes);
  if (extension == "x") return CheckDirectX(name, bytes);
  if (extension == "smd") return CheckSmd(name, bytes);
  return Unsupported(Quoted(name) + ": no reader for the extension '." + extension +
                     "'; accepted: .glb, .gltf, .fbx, .dae, .bvh, .x, .smd");
}

}  // namespace motionlod::io
