// What an upload of a character and an upload of a motion file go through alike: the
// files' names are checked, the upload gets its id, its import takes one of the slots of
// max_concurrent_imports, and an import failure becomes the error the client sees.
#pragma once

#include <atomic>
#include <string>
#include <vector>

#include "base/status.h"
#include "io/asset.h"
#include "proto/api.h"
#include "server/service_context.h"
#include "server/store.h"

namespace motionlod::server {

// The files of one upload: at least one, each with a plain name, no two named alike.
Status ValidateUploadFiles(const std::vector<io::SourceFile>& files);

// Id of an upload: SHA-256 of the one file, or of its parts' sorted (name, sha256) list.
std::string UploadId(const std::vector<io::SourceFile>& files);

// An importer or core failure on uploaded content.
ServiceError ImportError(const Status& status);

// The stored files of an upload as the API lists them.
std::vector<proto::api::FileInfo> ToFileInfos(const std::vector<FileRecord>& files);

// Counts an in-flight import; refuses beyond the limit.
class ImportSlot {
 public:
  ImportSlot(std::atomic<int>& count, int limit) : count_(count) {
    acquired_ = count_.fetch_add(1) < limit;
    if (!acquired_) count_.fetch_sub(1);
  }
  ~ImportSlot() {
    if (acquired_) count_.fetch_sub(1);
  }
  bool acquired() const { return acquired_; }

 private:
  std::atomic<int>& count_;
  bool acquired_ = false;
};

}  // namespace motionlod::server
