#include "server/redis_store.h"

#include <algorithm>
#include <cstdlib>
#include <nlohmann/json.hpp>

#include "proto/api.h"

namespace motionlod::server {
namespace {

using nlohmann::json;
using Fields = std::map<std::string, std::string>;

// Every script starts with these: P is the key prefix, ARGV[1].
constexpr const char* kPrelude = R"lua(
local P = ARGV[1]
local function hset(key, t)
  local a = {}
  for k, v in pairs(t) do a[#a + 1] = k; a[#a + 1] = v end
  redis.call('HSET', key, unpack(a))
end
local function ref(b)
  if b and b ~= '' then redis.call('HINCRBY', P .. 'blob-refs', b, 1) end
end
local named = {}
local function unref(b)
  if not b or b == '' then return end
  named[#named + 1] = b
  if redis.call('HINCRBY', P .. 'blob-refs', b, -1) <= 0 then
    redis.call('HDEL', P .. 'blob-refs', b)
    redis.call('HDEL', P .. 'level-bytes', b)
  end
end
local function count(state, delta)
  if state then redis.call('HINCRBY', P .. 'job-counts', state, delta) end
end
local function insert_motion(m)
  local key = P .. 'motion:' .. m.id
  if redis.call('EXISTS', key) == 1 then return end
  m.seq = tostring(redis.call('INCR', P .. 'seq'))
  hset(key, m)
  redis.call('ZADD', P .. 'character:' .. m.character_id .. ':motions', m.seq, m.id)
  for _, f in ipairs(cjson.decode(m.files)) do ref(f.blob) end
end
local function set_job(key, j)
  local old = redis.call('HGET', key, 'state')
  if not old then return 0 end
  hset(key, j)
  if old ~= j.state then count(old, -1); count(j.state, 1) end
  return redis.call('HINCRBY', key, 'version', 1)
end
local function unref_levels(key)
  local b = redis.call('HMGET', key, 'level_set', 'levels')
  unref(b[1])
  if b[2] then for _, l in ipairs(cjson.decode(b[2])) do unref(l[3]) end end
end
local function delete_bake(id)
  local key = P .. 'bake:' .. id
  local c = redis.call('HGET', key, 'character_id')
  if not c then return false end
  unref_levels(key)
  local job = P .. 'job:' .. id
  count(redis.call('HGET', job, 'state'), -1)
  redis.call('DEL', key, job)
  redis.call('ZREM', P .. 'bakes', id)
  redis.call('ZREM', P .. 'character:' .. c .. ':bakes', id)
  return true
end
)lua";

// ARGV[2]: {"c": character fields, "motions": [motion fields]}. 0: it existed.
constexpr const char* kInsertCharacter = R"lua(
local doc = cjson.decode(ARGV[2])
local c = doc.c
local key = P .. 'character:' .. c.id
if redis.call('EXISTS', key) == 1 then return 0 end
hset(key, c)
redis.call('ZADD', P .. 'characters', c.created_ms, c.id)
for _, f in ipairs(cjson.decode(c.files)) do ref(f.blob) end
for _, m in ipairs(doc.motions) do insert_motion(m) end
return 1
)lua";

// ARGV[2]: [motion fields].
constexpr const char* kInsertMotions = R"lua(
for _, m in ipairs(cjson.decode(ARGV[2])) do insert_motion(m) end
return 1
)lua";

// ARGV[2]: the character id. 0: none; else the blobs the deleted records named.
constexpr const char* kDeleteCharacter = R"lua(
local id = ARGV[2]
local key = P .. 'character:' .. id
local files = redis.call('HGET', key, 'files')
if not files then return 0 end
for _, f in ipairs(cjson.decode(files)) do unref(f.blob) end
for _, m in ipairs(redis.call('ZRANGE', key .. ':motions', 0, -1)) do
  local motion_files = redis.call('HGET', P .. 'motion:' .. m, 'files')
  if motion_files then for _, f in ipairs(cjson.decode(motion_files)) do unref(f.blob) end end
  redis.call('DEL', P .. 'motion:' .. m)
end
for _, b in ipairs(redis.call('ZRANGE', key .. ':bakes', 0, -1)) do delete_bake(b) end
redis.call('DEL', key, key .. ':motions', key .. ':bakes')
redis.call('ZREM', P .. 'characters', id)
return named
)lua";

// ARGV[2]: {"bake": bake fields, "job": job fields}. 0: the bake existed.
constexpr const char* kInsertBakeAndJob = R"lua(
local doc = cjson.decode(ARGV[2])
local b, j = doc.bake, doc.job
local key = P .. 'bake:' .. b.id
if redis.call('EXISTS', key) == 1 then return 0 end
hset(key, b)
redis.call('ZADD', P .. 'bakes', b.created_ms, b.id)
redis.call('ZADD', P .. 'character:' .. b.character_id .. ':bakes', b.created_ms, b.id)
j.version = '0'
hset(P .. 'job:' .. j.id, j)
count(j.state, 1)
return 1
)lua";

// ARGV[2]: the bake id. 0: none; else the blobs it named.
constexpr const char* kDeleteBake = R"lua(
if not delete_bake(ARGV[2]) then return 0 end
return named
)lua";

// ARGV[2]: {"bake": the finished bake's fields, levels included, "job": job fields}.
// -1: the bake is gone; else the job's new version (0: the job is gone).
constexpr const char* kCompleteBake = R"lua(
local doc = cjson.decode(ARGV[2])
local b = doc.bake
local key = P .. 'bake:' .. b.id
if redis.call('EXISTS', key) == 0 then return -1 end
unref_levels(key)
hset(key, b)
ref(b.level_set)
for _, l in ipairs(cjson.decode(b.levels)) do
  ref(l[3])
  redis.call('HSET', P .. 'level-bytes', l[3], tostring(l[4]))
end
return set_job(P .. 'job:' .. doc.job.id, doc.job)
)lua";

// ARGV[2]: job fields. The job's new version, 0 when it is gone.
constexpr const char* kUpdateJob = R"lua(
local j = cjson.decode(ARGV[2])
return set_job(P .. 'job:' .. j.id, j)
)lua";

std::string Script(const char* body) { return std::string(kPrelude) + body; }

std::string Number(double value) { return json(value).dump(); }

int64_t Int(const Fields& fields, const char* name) {
  const auto found = fields.find(name);
  return found == fields.end() ? 0 : std::strtoll(found->second.c_str(), nullptr, 10);
}
double Double(const Fields& fields, const char* name) {
  const auto found = fields.find(name);
  return found == fields.end() ? 0 : std::strtod(found->second.c_str(), nullptr);
}
std::string Text(const Fields& fields, const char* name) {
  const auto found = fields.find(name);
  return found == fields.end() ? std::string() : found->second;
}

json CharacterFields(const CharacterRecord& c) {
  return {{"id", c.id},
          {"name", c.name},
          {"files", FilesToJson(c.files)},
          {"joints", std::to_string(c.joints)},
          {"vertices", std::to_string(c.vertices)},
          {"triangles", std::to_string(c.triangles)},
          {"proxy_skin", c.proxy_skin ? "1" : "0"},
          {"warnings", ListToJson(c.warnings)},
          {"created_ms", std::to_string(c.created_ms)},
          {"joint_names", ListToJson(c.joint_names)}};
}
CharacterRecord ReadCharacter(const Fields& f) {
  CharacterRecord c;
  c.id = Text(f, "id");
  c.name = Text(f, "name");
  c.files = FilesFromJson(Text(f, "files"));
  c.joints = static_cast<int>(Int(f, "joints"));
  c.vertices = static_cast<int>(Int(f, "vertices"));
  c.triangles = static_cast<int>(Int(f, "triangles"));
  c.proxy_skin = Int(f, "proxy_skin") != 0;
  c.warnings = ListFromJson(Text(f, "warnings"));
  c.created_ms = Int(f, "created_ms");
  c.joint_names = ListFromJson(Text(f, "joint_names"));
  return c;
}

json MotionFields(const MotionRecord& m) {
  return {{"id", m.id},
          {"character_id", m.character_id},
          {"animation", m.animation},
          {"source", m.source},
          {"source_id", m.source_id},
          {"files", FilesToJson(m.files)},
          {"duration_seconds", Number(m.duration_seconds)},
          {"source_fps", Number(m.source_fps)},
          {"frames", std::to_string(m.frames)},
          {"warnings", ListToJson(m.warnings)},
          {"created_ms", std::to_string(m.created_ms)}};
}
MotionRecord ReadMotion(const Fields& f) {
  MotionRecord m;
  m.id = Text(f, "id");
  m.character_id = Text(f, "character_id");
  m.animation = Text(f, "animation");
  m.source = Text(f, "source");
  m.source_id = Text(f, "source_id");
  m.files = FilesFromJson(Text(f, "files"));
  m.duration_seconds = Double(f, "duration_seconds");
  m.source_fps = Double(f, "source_fps");
  m.frames = static_cast<int>(Int(f, "frames"));
  m.warnings = ListFromJson(Text(f, "warnings"));
  m.created_ms = Int(f, "created_ms");
  return m;
}

std::string LevelsToJson(const std::vector<LevelRecord>& levels) {
  json array = json::array();
  for (const LevelRecord& l : levels) array.push_back({l.index, l.joints, l.hash, l.bytes});
  return array.dump();
}

BakeRecord ReadBake(const Fields& f) {
  BakeRecord b;
  b.id = Text(f, "id");
  b.character_id = Text(f, "character_id");
  b.motion_id = Text(f, "motion_id");
  b.clip_motions = ListFromJson(Text(f, "clip_motions"));
  b.request_json = Text(f, "request");
  b.created_ms = Int(f, "created_ms");
  b.level_set = Text(f, "level_set");
  b.level_set_bytes = Int(f, "level_set_bytes");
  b.report_json = Text(f, "report");
  b.frames = static_cast<int>(Int(f, "frames"));
  b.fps = Double(f, "fps");
  return b;
}

json JobFields(const JobRecord& j) {
  return {{"id", j.id},
          {"bake_id", j.bake_id},
          {"state", j.state},
          {"progress", Number(j.progress)},
          {"stage", j.stage},
          {"error_code", j.error_code},
          {"error_detail", j.error_detail},
          {"attempts", std::to_string(j.attempts)},
          {"created_ms", std::to_string(j.created_ms)},
          {"started_ms", std::to_string(j.started_ms)},
          {"finished_ms", std::to_string(j.finished_ms)}};
}
JobRecord ReadJob(const Fields& f) {
  JobRecord j;
  j.id = Text(f, "id");
  j.bake_id = Text(f, "bake_id");
  j.state = Text(f, "state");
  j.progress = Double(f, "progress");
  j.stage = Text(f, "stage");
  j.error_code = Text(f, "error_code");
  j.error_detail = Text(f, "error_detail");
  j.attempts = static_cast<int>(Int(f, "attempts"));
  j.created_ms = Int(f, "created_ms");
  j.started_ms = Int(f, "started_ms");
  j.finished_ms = Int(f, "finished_ms");
  j.version = static_cast<uint64_t>(Int(f, "version"));
  return j;
}

// A script's list of blob names, or nullopt for its "not found" 0.
std::optional<std::vector<std::string>> NamedBlobs(const RedisReply& reply) {
  if (reply.type != RedisReply::Type::kArray) return std::nullopt;
  std::vector<std::string> blobs;
  for (const RedisReply& element : reply.elements) blobs.push_back(element.text);
  std::sort(blobs.begin(), blobs.end());
  blobs.erase(std::unique(blobs.begin(), blobs.end()), blobs.end());
  return blobs;
}

}  // namespace

StatusOr<std::map<std::string, std::string>> RedisStore::ReadHash(const std::string& key) {
  auto reply = redis_->Command({"HGETALL", key});
  if (!reply.ok()) return reply.status();
  Fields fields;
  for (size_t i = 0; i + 1 < reply->elements.size(); i += 2)
    fields[reply->elements[i].text] = reply->elements[i + 1].text;
  return fields;
}

StatusOr<std::vector<std::string>> RedisStore::ReadSortedSet(const std::string& key) {
  auto reply = redis_->Command({"ZRANGE", key, "0", "-1"});
  if (!reply.ok()) return reply.status();
  std::vector<std::string> members;
  for (const RedisReply& element : reply->elements) members.push_back(element.text);
  return members;
}

StatusOr<bool> RedisStore::InsertCharacter(const CharacterRecord& character,
                                           const std::vector<MotionRecord>& motions) {
  json doc = {{"c", CharacterFields(character)}, {"motions", json::array()}};
  for (const MotionRecord& m : motions) doc["motions"].push_back(MotionFields(m));
  auto reply = redis_->Eval(Script(kInsertCharacter), {prefix_, doc.dump()});
  if (!reply.ok()) return reply.status();
  return reply->integer == 1;
}

StatusOr<std::optional<CharacterRecord>> RedisStore::GetCharacter(const std::string& id) {
  auto fields = ReadHash(prefix_ + "character:" + id);
  if (!fields.ok()) return fields.status();
  if (fields->empty()) return std::optional<CharacterRecord>();
  return std::optional<CharacterRecord>(ReadCharacter(*fields));
}

StatusOr<std::vector<CharacterRecord>> RedisStore::ListCharacters() {
  auto ids = ReadSortedSet(prefix_ + "characters");
  if (!ids.ok()) return ids.status();
  std::vector<CharacterRecord> characters;
  for (const std::string& id : *ids) {
    auto character = GetCharacter(id);
    if (!character.ok()) return character.status();
    if (character->has_value()) characters.push_back(std::move(**character));
  }
  return characters;
}

StatusOr<std::vector<std::string>> RedisStore::DeleteCharacter(const std::string& id) {
  auto reply = redis_->Eval(Script(kDeleteCharacter), {prefix_, id});
  if (!reply.ok()) return reply.status();
  auto blobs = NamedBlobs(*reply);
  if (!blobs) return NotFound("no character " + id);
  return *std::move(blobs);
}

Status RedisStore::InsertMotions(const std::vector<MotionRecord>& motions) {
  json array = json::array();
  for (const MotionRecord& m : motions) array.push_back(MotionFields(m));
  auto reply = redis_->Eval(Script(kInsertMotions), {prefix_, array.dump()});
  return reply.ok() ? Status::Ok() : reply.status();
}

StatusOr<std::optional<MotionRecord>> RedisStore::GetMotion(const std::string& id) {
  auto fields = ReadHash(prefix_ + "motion:" + id);
  if (!fields.ok()) return fields.status();
  if (fields->empty()) return std::optional<MotionRecord>();
  return std::optional<MotionRecord>(ReadMotion(*fields));
}

StatusOr<std::vector<MotionRecord>> RedisStore::ListMotions(const std::string& character_id) {
  auto ids = ReadSortedSet(prefix_ + "character:" + character_id + ":motions");
  if (!ids.ok()) return ids.status();
  std::vector<MotionRecord> motions;
  for (const std::string& id : *ids) {
    auto motion = GetMotion(id);
    if (!motion.ok()) return motion.status();
    if (motion->has_value()) motions.push_back(std::move(**motion));
  }
  // The character's own animations first, each group by time, then insertion (the set's
  // order), as the SQLite store lists them.
  std::stable_sort(motions.begin(), motions.end(),
                   [](const MotionRecord& a, const MotionRecord& b) {
                     return std::make_pair(a.source == "file", a.created_ms) <
                            std::make_pair(b.source == "file", b.created_ms);
                   });
  return motions;
}

StatusOr<bool> RedisStore::InsertBakeAndJob(const BakeRecord& bake, const JobRecord& job) {
  const json bake_fields = {{"id", bake.id},
                            {"character_id", bake.character_id},
                            {"motion_id", bake.motion_id},
                            {"clip_motions", ListToJson(bake.clip_motions)},
                            {"request", bake.request_json},
                            {"created_ms", std::to_string(bake.created_ms)},
                            {"levels", "[]"}};
  const json doc = {{"bake", bake_fields}, {"job", JobFields(job)}};
  auto reply = redis_->Eval(Script(kInsertBakeAndJob), {prefix_, doc.dump()});
  if (!reply.ok()) return reply.status();
  return reply->integer == 1;
}

StatusOr<std::vector<BakeRecord>> RedisStore::ReadBakes(const std::vector<std::string>& ids,
                                                        bool reports) {
  std::vector<BakeRecord> bakes;
  for (const std::string& id : ids) {
    auto fields = ReadHash(prefix_ + "bake:" + id);
    if (!fields.ok()) return fields.status();
    if (fields->empty()) continue;
    bakes.push_back(ReadBake(*fields));
    if (!reports) bakes.back().report_json.clear();  // lists stay small
  }
  return bakes;
}

StatusOr<std::optional<BakeRecord>> RedisStore::GetBake(const std::string& id) {
  auto bakes = ReadBakes({id}, /*reports=*/true);
  if (!bakes.ok()) return bakes.status();
  if (bakes->empty()) return std::optional<BakeRecord>();
  return std::optional<BakeRecord>(std::move(bakes->front()));
}

StatusOr<std::vector<BakeRecord>> RedisStore::ListBakes(const std::string& character_id) {
  auto ids = ReadSortedSet(character_id.empty() ? prefix_ + "bakes"
                                                : prefix_ + "character:" + character_id + ":bakes");
  if (!ids.ok()) return ids.status();
  return ReadBakes(*ids, /*reports=*/false);
}

StatusOr<std::vector<LevelRecord>> RedisStore::GetLevels(const std::string& bake_id) {
  auto reply = redis_->Command({"HGET", prefix_ + "bake:" + bake_id, "levels"});
  if (!reply.ok()) return reply.status();
  std::vector<LevelRecord> levels;
  const json array = json::parse(reply->text, nullptr, false);
  if (!array.is_array()) return levels;
  for (const json& l : array) {
    if (!l.is_array() || l.size() != 4) continue;
    levels.push_back(
        {l[0].get<int>(), l[1].get<int>(), l[2].get<std::string>(), l[3].get<int64_t>()});
  }
  return levels;
}

StatusOr<std::vector<std::string>> RedisStore::DeleteBake(const std::string& id) {
  auto reply = redis_->Eval(Script(kDeleteBake), {prefix_, id});
  if (!reply.ok()) return reply.status();
  auto blobs = NamedBlobs(*reply);
  if (!blobs) return NotFound("no bake " + id);
  return *std::move(blobs);
}

Status RedisStore::CompleteBake(const BakeRecord& bake, const std::vector<LevelRecord>& levels,
                                JobRecord& job) {
  const json bake_fields = {{"id", bake.id},
                            {"level_set", bake.level_set},
                            {"level_set_bytes", std::to_string(bake.level_set_bytes)},
                            {"report", bake.report_json},
                            {"frames", std::to_string(bake.frames)},
                            {"fps", Number(bake.fps)},
                            {"levels", LevelsToJson(levels)}};
  const json doc = {{"bake", bake_fields}, {"job", JobFields(job)}};
  auto reply = redis_->Eval(Script(kCompleteBake), {prefix_, doc.dump()});
  if (!reply.ok()) return reply.status();
  if (reply->integer < 0) return NotFound("the bake was deleted");
  job.version = static_cast<uint64_t>(reply->integer);
  return Status::Ok();
}

StatusOr<std::optional<JobRecord>> RedisStore::GetJob(const std::string& id) {
  auto fields = ReadHash(prefix_ + "job:" + id);
  if (!fields.ok()) return fields.status();
  if (fields->empty()) return std::optional<JobRecord>();
  return std::optional<JobRecord>(ReadJob(*fields));
}

StatusOr<bool> RedisStore::UpdateJob(JobRecord& job) {
  auto reply = redis_->Eval(Script(kUpdateJob), {prefix_, JobFields(job).dump()});
  if (!reply.ok()) return reply.status();
  if (reply->integer == 0) return false;
  job.version = static_cast<uint64_t>(reply->integer);
  return true;
}

StatusOr<Store::UnfinishedJobs> RedisStore::TakeUnfinishedJobs(int, int64_t) {
  return UnfinishedJobs{};
}

StatusOr<std::map<std::string, int64_t>> RedisStore::CountJobsByState() {
  auto fields = ReadHash(prefix_ + "job-counts");
  if (!fields.ok()) return fields.status();
  std::map<std::string, int64_t> counts = {
      {"queued", 0}, {"running", 0}, {"succeeded", 0}, {"failed", 0}};
  for (const auto& [state, count] : *fields)
    counts[state] = std::strtoll(count.c_str(), nullptr, 10);
  return counts;
}

StatusOr<std::optional<int64_t>> RedisStore::LevelBytes(const std::string& hash) {
  auto reply = redis_->Command({"HGET", prefix_ + "level-bytes", hash});
  if (!reply.ok()) return reply.status();
  if (reply->nil()) return std::optional<int64_t>();
  return std::optional<int64_t>(std::strtoll(reply->text.c_str(), nullptr, 10));
}

StatusOr<bool> RedisStore::IsBlobReferenced(const std::string& hash) {
  auto reply = redis_->Command({"HGET", prefix_ + "blob-refs", hash});
  if (!reply.ok()) return reply.status();
  return !reply->nil() && std::strtoll(reply->text.c_str(), nullptr, 10) > 0;
}

StatusOr<std::vector<std::string>> RedisStore::ReferencedBlobs() {
  auto fields = ReadHash(prefix_ + "blob-refs");
  if (!fields.ok()) return fields.status();
  std::vector<std::string> blobs;
  for (const auto& [blob, count] : *fields) {
    if (std::strtoll(count.c_str(), nullptr, 10) > 0) blobs.push_back(blob);
  }
  return blobs;
}

bool RedisStore::Healthy() { return redis_->Command({"PING"}).ok(); }

Status RedisBlobStore::PutWithHash(std::string_view hash, std::string_view bytes) {
  if (!proto::api::IsContentId(hash)) return InvalidArgument("malformed blob id");
  if (static_cast<int64_t>(bytes.size()) > max_blob_bytes_) {
    return InvalidArgument("a blob of " + std::to_string(bytes.size()) +
                           " bytes is over redis_max_blob_bytes (" +
                           std::to_string(max_blob_bytes_) + "): use blob_store = \"directory\"");
  }
  auto reply = redis_->Command({"SET", KeyOf(hash), bytes, "NX"});
  return reply.ok() ? Status::Ok() : reply.status();
}

StatusOr<std::string> RedisBlobStore::Get(std::string_view hash) const {
  if (!proto::api::IsContentId(hash)) return InvalidArgument("malformed blob id");
  auto reply = redis_->Command({"GET", KeyOf(hash)});
  if (!reply.ok()) return reply.status();
  if (reply->nil()) return NotFound("blob " + std::string(hash) + " is not stored");
  if (io::Sha256Hex(reply->text) != hash)
    return DataLoss("blob " + std::string(hash) + " does not match its hash");
  return std::move(reply->text);
}

bool RedisBlobStore::Contains(std::string_view hash) const {
  if (!proto::api::IsContentId(hash)) return false;
  auto reply = redis_->Command({"EXISTS", KeyOf(hash)});
  return reply.ok() && reply->integer == 1;
}

Status RedisBlobStore::Remove(std::string_view hash) {
  if (!proto::api::IsContentId(hash)) return InvalidArgument("malformed blob id");
  auto reply = redis_->Command({"DEL", KeyOf(hash)});
  return reply.ok() ? Status::Ok() : reply.status();
}

Status RedisBlobStore::CheckWritable(int64_t) const {
  auto reply = redis_->Command({"PING"});
  if (!reply.ok()) return Status(StatusCode::kUnavailable, "Redis does not answer");
  return Status::Ok();
}

std::vector<std::string> RedisBlobStore::List() const {
  std::vector<std::string> hashes;
  const std::string pattern = prefix_ + "blob:*";
  std::string cursor = "0";
  do {
    auto reply = redis_->Command({"SCAN", cursor, "MATCH", pattern, "COUNT", "1000"});
    if (!reply.ok() || reply->elements.size() != 2) break;
    cursor = reply->elements[0].text;
    for (const RedisReply& key : reply->elements[1].elements)
      hashes.push_back(key.text.substr(prefix_.size() + 5));
  } while (cursor != "0");
  return hashes;
}

}  // namespace motionlod::server
