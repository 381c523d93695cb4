#include "server/web_assets.h"

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>

#include "io/sha256.h"

namespace motionlod::server {
namespace {

namespace fs = std::filesystem;

// A name the viewer's build writes: letters, digits, '.', '_', '-', not hidden.
bool IsPlainName(const std::string& name) {
  if (name.empty() || name.front() == '.') return false;
  return std::all_of(name.begin(), name.end(), [](unsigned char c) {
    return std::isalnum(c) || c == '.' || c == '_' || c == '-';
  });
}

StatusOr<std::string> ReadWhole(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream bytes;
  bytes << in.rdbuf();
  if (!in) return InvalidArgument("cannot read '" + path.string() + "'");
  return bytes.str();
}

}  // namespace

std::string WebContentType(const std::string& file_name) {
  static const std::pair<const char*, const char*> kTypes[] = {
      {"html", "text/html; charset=utf-8"},
      {"js", "text/javascript; charset=utf-8"},
      {"mjs", "text/javascript; charset=utf-8"},
      {"css", "text/css; charset=utf-8"},
      {"json", "application/json"},
      {"map", "application/json"},
      {"svg", "image/svg+xml"},
      {"png", "image/png"},
      {"jpg", "image/jpeg"},
      {"jpeg", "image/jpeg"},
      {"webp", "image/webp"},
      {"ico", "image/x-icon"},
      {"woff2", "font/woff2"},
      {"wasm", "application/wasm"},
      {"glb", "model/gltf-binary"},
      {"txt", "text/plain; charset=utf-8"},
  };
  const size_t dot = file_name.rfind('.');
  if (dot == std::string::npos) return "";
  std::string extension = file_name.substr(dot + 1);
  std::transform(extension.begin(), extension.end(), extension.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  for (const auto& [known, type] : kTypes) {
    if (extension == known) return type;
  }
  return "";
}

const WebFile* WebAssets::index() const {
  for (const WebFile& file : files) {
    if (file.url_path == "/index.html") return &file;
  }
  return nullptr;
}

StatusOr<WebAssets> LoadWebAssets(const std::string& root) {
  std::error_code error;
  if (root.empty() || !fs::is_directory(root, error)) {
    return NotFound("'" + root + "' is not a directory");
  }
  WebAssets assets;
  assets.root = root;
  size_t total_bytes = 0;
  fs::recursive_directory_iterator entry(root, fs::directory_options::none, error), end;
  if (error) return NotFound("cannot list '" + root + "': " + error.message());
  for (; entry != end; entry.increment(error)) {
    if (error) return InvalidArgument("cannot list '" + root + "': " + error.message());
    const std::string name = entry->path().filename().string();
    // Symbolic links are never followed: a link could lead out of the root.
    const bool plain = IsPlainName(name) && !entry->is_symlink(error);
    if (entry->is_directory(error)) {
      if (!plain || entry.depth() >= kMaxWebDepth) entry.disable_recursion_pending();
      continue;
    }
    if (!plain || !entry->is_regular_file(error)) continue;
    const std::string content_type = WebContentType(name);
    if (content_type.empty()) continue;
    if (assets.files.size() == kMaxWebFiles) {
      return InvalidArgument("'" + root + "' has more than " + std::to_string(kMaxWebFiles) +
                             " files to serve");
    }
    auto bytes = ReadWhole(entry->path());
    if (!bytes.ok()) return bytes.status();
    total_bytes += bytes->size();
    if (total_bytes > kMaxWebBytes) {
      return InvalidArgument("'" + root + "' holds more than " +
                             std::to_string(kMaxWebBytes >> 20) + " MiB to serve");
    }
    WebFile file;
    // generic_string: '/' separators; every component was checked by IsPlainName.
    file.url_path = "/" + fs::relative(entry->path(), root).generic_string();
    file.content_type = content_type;
    // Vite names what it writes under assets/ by a hash of the content.
    file.cache_control = file.url_path.rfind("/assets/", 0) == 0
                             ? "public, max-age=31536000, immutable"
                             : "no-cache";
    file.etag = "\"" + io::Sha256Hex(*bytes) + "\"";
    file.bytes = std::make_shared<const std::string>(std::move(bytes).value());
    assets.files.push_back(std::move(file));
  }
  std::sort(assets.files.begin(), assets.files.end(),
            [](const WebFile& a, const WebFile& b) { return a.url_path < b.url_path; });
  if (assets.index() == nullptr) return NotFound("'" + root + "' has no index.html");
  return assets;
}

}  // namespace motionlod::server
