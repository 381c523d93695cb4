#include "server/uploads.h"

#include <algorithm>
#include <set>

#include "io/sha256.h"

namespace motionlod::server {
namespace {

Status ValidateFileName(const std::string& name) {
  if (name.empty())
    return InvalidArgument(
        "every file needs a name (?filename=, X-Filename or the part's filename)");
  if (name.size() > 255) return InvalidArgument("file names are limited to 255 bytes");
  if (name == "." || name == "..") return InvalidArgument("'" + name + "' is not a file name");
  for (unsigned char c : name) {
    if (c < 0x20 || c == 0x7f || c == '/' || c == '\\') {
      return InvalidArgument(
          "file names must be plain names: no directories or control characters");
    }
  }
  return Status::Ok();
}

}  // namespace

Status ValidateUploadFiles(const std::vector<io::SourceFile>& files) {
  if (files.empty()) return InvalidArgument("the upload holds no file");
  std::set<std::string> names;
  for (const io::SourceFile& f : files) {
    if (Status status = ValidateFileName(f.name); !status.ok()) return status;
    if (!names.insert(f.name).second)
      return InvalidArgument("two parts are named '" + f.name + "'");
  }
  return Status::Ok();
}

std::string UploadId(const std::vector<io::SourceFile>& files) {
  if (files.size() == 1) return io::Sha256Hex(files[0].bytes);
  std::vector<std::string> lines;
  for (const io::SourceFile& f : files)
    lines.push_back(f.name + '\0' + io::Sha256Hex(f.bytes) + "\n");
  std::sort(lines.begin(), lines.end());
  std::string text;
  for (const std::string& line : lines) text += line;
  return io::Sha256Hex(text);
}

ServiceError ImportError(const Status& status) {
  if (status.code() == StatusCode::kUnsupported)
    return Error(ErrorKind::kUnsupportedMedia, status.message());
  if (status.code() == StatusCode::kInternal) return Internal(status);
  return Error(ErrorKind::kUnprocessable, status.message());
}

std::vector<proto::api::FileInfo> ToFileInfos(const std::vector<FileRecord>& files) {
  std::vector<proto::api::FileInfo> infos;
  for (const FileRecord& f : files)
    infos.push_back({f.name, f.blob, static_cast<uint64_t>(f.size)});
  return infos;
}

}  // namespace motionlod::server
