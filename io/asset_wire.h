// The import worker's wire format: the daemon sends the uploaded files to a sandboxed
// worker process (server/import_worker) and gets back either the imported Asset or the
// importer's error. The reply comes from a process that parsed hostile bytes, so it is
// decoded as hostile too: every count is checked against the bytes left before anything
// is allocated, and the decoded asset is validated as a whole (core::ValidateRawCharacter,
// node and track indices in range, key times finite and sorted, unit rotations) before
// an Asset exists. A malformed reply is a DataLoss status, never a crash.
//
// A message is a 32-byte header and a payload, integers and IEEE-754 values little-endian:
//   0  magic "MLODWIRE"     8  u16 version (2)     10 u16 kind (MessageKind)
//   12 u32 reserved (0)     16 u64 payload bytes   24 u64 FNV-1a 64 of the payload
// Strings and arrays are a count (u32, bytes for a string) followed by the elements.
// The payload layouts are in asset_wire.cc next to the code that writes them.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "base/status.h"
#include "io/asset.h"

namespace motionlod::io {

inline constexpr uint16_t kAssetWireVersion = 2;
inline constexpr size_t kWireHeaderBytes = 32;

enum class MessageKind : uint16_t {
  kImportRequest = 1,  // daemon -> worker: LoadOptions and the files
  kAssetReply = 2,     // worker -> daemon: the imported asset
  kErrorReply = 3,     // worker -> daemon: the importer's Status
};

// Exit statuses of the import worker (server/import_worker) besides 0 (a reply was written).
inline constexpr int kWorkerExitBadRequest = 2;   // the request did not decode
inline constexpr int kWorkerExitOutOfMemory = 3;  // an allocation failed (address space limit)
inline constexpr int kWorkerExitWriteFailed = 4;  // the reply could not be written

struct ImportRequest {
  std::vector<SourceFile> files;  // files[0] is the main file
  LoadOptions options;
};

// Total size of the message whose header starts `bytes` (header included); DataLoss
// when fewer than kWireHeaderBytes are given or the magic, version or kind is wrong.
StatusOr<uint64_t> WireMessageBytes(std::string_view bytes);

std::string EncodeImportRequest(const std::vector<SourceFile>& files, const LoadOptions& options);
// DataLoss for a malformed message; InvalidArgument for options that do not validate.
StatusOr<ImportRequest> DecodeImportRequest(std::string_view message);

// An asset reply for an imported asset, an error reply for a failed import.
std::string EncodeImportReply(const StatusOr<std::shared_ptr<const Asset>>& result);
// The asset, or the importer's error as the worker reported it (InvalidArgument,
// NotFound, Unsupported or DataLoss). A reply that is cut off, fails its checksum, has
// the wrong kind, trailing bytes, another status code, or holds an asset that does not
// validate is DataLoss with a message starting "malformed import reply".
StatusOr<std::shared_ptr<const Asset>> DecodeImportReply(std::string_view message);

}  // namespace motionlod::io
