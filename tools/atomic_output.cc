#include "tools/atomic_output.h"

#include <fcntl.h>
#include <stdio.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <system_error>

namespace motionlod::tools {
namespace fs = std::filesystem;
namespace {

// 'path', built piecewise: GCC 12 warns falsely (-Wrestrict) on "'" + string chains.
std::string Quote(const fs::path& path) {
  std::string quoted(1, '\'');
  quoted.append(path.string()).push_back('\'');
  return quoted;
}

Status Errno(const std::string& what, const fs::path& path) {
  return Status(StatusCode::kInvalidArgument, what + " " + Quote(path) + ": " + std::strerror(errno));
}

Status WriteAndSync(const fs::path& path, const std::string& contents) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) return Errno("cannot create", path);
  size_t written = 0;
  while (written < contents.size()) {
    const ssize_t n = ::write(fd, contents.data() + written, contents.size() - written);
    if (n < 0) {
      if (errno == EINTR) continue;
      const Status status = Errno("cannot write", path);
      ::close(fd);
      return status;
    }
    written += static_cast<size_t>(n);
  }
  if (::fsync(fd) != 0) {
    const Status status = Errno("cannot flush", path);
    ::close(fd);
    return status;
  }
  if (::close(fd) != 0) return Errno("cannot close", path);
  return Status::Ok();
}

void SyncDirectory(const fs::path& dir) {
  const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd >= 0) {
    ::fsync(fd);
    ::close(fd);
  }
}

fs::path Sibling(const fs::path& target, const char* tag) {
  fs::path parent = target.parent_path();
  if (parent.empty()) parent = ".";
  std::string name(".");
  name.append(target.filename().string()).append(".").append(tag).append(".");
  name.append(std::to_string(::getpid()));
  return parent / name;
}

}  // namespace

Status WriteFileAtomically(const fs::path& path, const std::string& contents) {
  if (const fs::path parent = path.parent_path(); !parent.empty()) {  // as `bake` makes its DIR
    std::error_code error;
    fs::create_directories(parent, error);
    if (error) return InvalidArgument("cannot create " + Quote(parent) + ": " + error.message());
  }
  const fs::path temp = Sibling(path, "partial");
  if (Status status = WriteAndSync(temp, contents); !status.ok()) {
    std::error_code ignored;
    fs::remove(temp, ignored);
    return status;
  }
  if (::rename(temp.c_str(), path.c_str()) != 0) {
    const Status status = Errno("cannot move into place", path);
    std::error_code ignored;
    fs::remove(temp, ignored);
    return status;
  }
  SyncDirectory(path.parent_path().empty() ? fs::path(".") : path.parent_path());
  return Status::Ok();
}

Status WriteDirectoryAtomically(const fs::path& dir,
                                const std::vector<std::pair<std::string, std::string>>& files) {
  if (dir.filename().empty()) return InvalidArgument("the output directory needs a name: " + Quote(dir));
  std::error_code error;
  if (fs::exists(dir, error) && !fs::is_directory(dir, error)) {
    return InvalidArgument(Quote(dir) + " exists and is not a directory");
  }
  const fs::path temp = Sibling(dir, "partial");
  fs::remove_all(temp, error);
  if (!fs::create_directories(temp, error)) {
    return InvalidArgument("cannot create " + Quote(temp) + ": " + error.message());
  }
  auto fail = [&](Status status) {
    std::error_code ignored;
    fs::remove_all(temp, ignored);
    return status;
  };
  for (const auto& [name, contents] : files) {
    if (name.empty() || name.find('/') != std::string::npos || name == "." || name == "..") {
      return fail(InvalidArgument("bad output file name " + Quote(name)));
    }
    if (Status status = WriteAndSync(temp / name, contents); !status.ok()) return fail(status);
  }
  SyncDirectory(temp);
  if (fs::exists(dir, error)) {
    // Swap in one step, then drop the previous output.
    if (::renameat2(AT_FDCWD, temp.c_str(), AT_FDCWD, dir.c_str(), RENAME_EXCHANGE) != 0) {
      return fail(Errno("cannot replace", dir));
    }
    fs::remove_all(temp, error);
  } else if (::rename(temp.c_str(), dir.c_str()) != 0) {
    return fail(Errno("cannot move into place", dir));
  }
  SyncDirectory(dir.parent_path().empty() ? fs::path(".") : dir.parent_path());
  return Status::Ok();
}

}  // namespace motionlod::tools
