// The web viewer's built files (web/dist), read into memory once at start-up and served
// at "/". Only the files listed then are ever served, each under a path made from its
// own checked name, never from a request: an unknown path is a 404 of the router, and a
// traversal attempt ("..", "%2e%2e", "//") simply names no listed file.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "base/status.h"

namespace motionlod::server {

struct WebFile {
  std::string url_path;       // "/index.html", "/assets/index-3f9c1a2b.js"
  std::string content_type;   // from the extension; "text/html; charset=utf-8", ...
  std::string cache_control;  // immutable for assets/ (content-hashed names), else no-cache
  std::string etag;           // "\"<sha256 of the bytes>\""
  std::shared_ptr<const std::string> bytes;
};

struct WebAssets {
  std::string root;  // the directory read, as configured
  std::vector<WebFile> files;
  // The file "/" answers with: index.html, or nullptr when the root has none.
  const WebFile* index() const;
};

// What is read at most (the built viewer is about 1 MiB in a handful of files).
inline constexpr size_t kMaxWebFiles = 512;
inline constexpr size_t kMaxWebBytes = size_t{64} << 20;
inline constexpr int kMaxWebDepth = 3;  // directory levels below the root

// Reads the regular files of `root` and of its subdirectories down to kMaxWebDepth
// levels. Skipped (never served): symbolic links, hidden names (".x"), names with
// characters other than letters, digits, '.', '_', '-', and files whose extension has no
// known content type. NotFound when `root` is not a directory or has no index.html;
// InvalidArgument beyond the limits above or when a file cannot be read.
StatusOr<WebAssets> LoadWebAssets(const std::string& root);

// The Content-Type for a file name's extension, or "" when it is not one the viewer
// ships.
std::string WebContentType(const std::string& file_name);

}  // namespace motionlod::server
