#include "server/store.h"

#include <nlohmann/json.hpp>

namespace motionlod::server {

using nlohmann::json;

std::string FilesToJson(const std::vector<FileRecord>& files) {
  json array = json::array();
  for (const FileRecord& f : files)
    array.push_back({{"name", f.name}, {"blob", f.blob}, {"size", f.size}});
  return array.dump();
}

std::vector<FileRecord> FilesFromJson(const std::string& text) {
  std::vector<FileRecord> files;
  const json array = json::parse(text, nullptr, false);
  if (!array.is_array()) return files;
  for (const json& f : array) {
    if (!f.is_object()) continue;
    files.push_back({f.value("name", ""), f.value("blob", ""), f.value("size", int64_t{0})});
  }
  return files;
}

std::string ListToJson(const std::vector<std::string>& items) { return json(items).dump(); }

std::vector<std::string> ListFromJson(const std::string& text) {
  const json array = json::parse(text, nullptr, false);
  std::vector<std::string> items;
  if (!array.is_array()) return items;
  for (const json& item : array) {
    if (item.is_string()) items.push_back(item.get<std::string>());
  }
  return items;
}

std::string CrashedDetail(int max_runs) {
  return "the daemon stopped while running this bake " + std::to_string(max_runs) +
         " times (a crash, or the memory limit): it is not run again";
}

}  // namespace motionlod::server
