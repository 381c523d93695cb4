#include "server/sqlite_store.h"

#include <sqlite3.h>

#include <set>
#include <type_traits>

namespace motionlod::server {
namespace {

// 1: the first schema. 2: bake_clips, the motions a bake bakes together (a version 1
// database gains it, each bake's one motion as its clip).
constexpr int kSchemaVersion = 2;

constexpr const char* kBakeClipsTable = R"sql(
CREATE TABLE bake_clips (
  bake_id TEXT NOT NULL REFERENCES bakes(id) ON DELETE CASCADE, idx INTEGER NOT NULL,
  motion_id TEXT NOT NULL REFERENCES motions(id) ON DELETE CASCADE,
  PRIMARY KEY (bake_id, idx));
CREATE INDEX bake_clips_motion ON bake_clips(motion_id);
)sql";

// A full disk, an I/O error or a read-only file is the file system's failure, which may
// pass (kUnavailable); anything else is ours (kInternal).
Status SqlError(sqlite3* db, const std::string& what) {
  const int primary = sqlite3_errcode(db) & 0xff;
  const bool transient = primary == SQLITE_FULL || primary == SQLITE_IOERR ||
                         primary == SQLITE_READONLY || primary == SQLITE_CANTOPEN ||
                         primary == SQLITE_BUSY;
  return Status(transient ? StatusCode::kUnavailable : StatusCode::kInternal,
                "database: " + what + ": " + sqlite3_errmsg(db));
}

// One prepared statement; binds by position (1-based), reads columns by index.
class Statement {
 public:
  Statement(sqlite3* db, const char* sql) : db_(db) {
    rc_ = sqlite3_prepare_v2(db, sql, -1, &stmt_, nullptr);
  }
  ~Statement() { sqlite3_finalize(stmt_); }
  Statement(const Statement&) = delete;
  Statement& operator=(const Statement&) = delete;

  bool ok() const { return rc_ == SQLITE_OK; }
  Statement& Bind(int index, const std::string& text) {
    if (ok())
      rc_ = sqlite3_bind_text(stmt_, index, text.data(), static_cast<int>(text.size()),
                              SQLITE_TRANSIENT);
    return *this;
  }
  Statement& Bind(int index, int64_t value) {
    if (ok()) rc_ = sqlite3_bind_int64(stmt_, index, value);
    return *this;
  }
  Statement& Bind(int index, int value) { return Bind(index, static_cast<int64_t>(value)); }
  Statement& Bind(int index, double value) {
    if (ok()) rc_ = sqlite3_bind_double(stmt_, index, value);
    return *this;
  }
  // SQLITE_ROW, SQLITE_DONE or an error code.
  int Step() {
    if (!ok()) return rc_;
    return sqlite3_step(stmt_);
  }
  Status Run(const char* what) {
    const int rc = Step();
    if (rc != SQLITE_DONE && rc != SQLITE_ROW) return SqlError(db_, what);
    return Status::Ok();
  }
  // Calls `row(*this)` on every row; `what` names the query in errors.
  template <typename Row>
  Status ForEachRow(const char* what, Row row) {
    while (true) {
      const int rc = Step();
      if (rc == SQLITE_DONE) return Status::Ok();
      if (rc != SQLITE_ROW) return SqlError(db_, what);
      row(*this);
    }
  }
  // Every row, each read by `read(*this)`.
  template <typename Read, typename Record = std::invoke_result_t<Read&, const Statement&>>
  StatusOr<std::vector<Record>> ReadAll(const char* what, Read read) {
    std::vector<Record> records;
    Status status = ForEachRow(what, [&](const Statement& row) { records.push_back(read(row)); });
    if (!status.ok()) return status;
    return records;
  }
  // The first row read by `read(*this)`, or none when there is no row.
  template <typename Read, typename Record = std::invoke_result_t<Read&, const Statement&>>
  StatusOr<std::optional<Record>> ReadOne(const char* what, Read read) {
    const int rc = Step();
    if (rc == SQLITE_ROW) return std::optional<Record>(read(*this));
    if (rc == SQLITE_DONE) return std::optional<Record>();
    return SqlError(db_, what);
  }
  std::string Text(int column) const {
    const auto* text = reinterpret_cast<const char*>(sqlite3_column_text(stmt_, column));
    return text == nullptr ? std::string() : std::string(text, sqlite3_column_bytes(stmt_, column));
  }
  int64_t Int(int column) const { return sqlite3_column_int64(stmt_, column); }
  double Double(int column) const { return sqlite3_column_double(stmt_, column); }

 private:
  sqlite3* db_;
  sqlite3_stmt* stmt_ = nullptr;
  int rc_ = SQLITE_OK;
};

Status Exec(sqlite3* db, const char* sql) {
  char* error = nullptr;
  if (sqlite3_exec(db, sql, nullptr, nullptr, &error) != SQLITE_OK) {
    Status status(StatusCode::kInternal, std::string("database: ") + (error ? error : "error"));
    sqlite3_free(error);
    return status;
  }
  return Status::Ok();
}

// BEGIN IMMEDIATE ... COMMIT, rolled back unless committed.
class Transaction {
 public:
  explicit Transaction(sqlite3* db) : db_(db) { status_ = Exec(db, "BEGIN IMMEDIATE"); }
  ~Transaction() {
    if (status_.ok() && !committed_) (void)Exec(db_, "ROLLBACK");
  }
  const Status& status() const { return status_; }
  Status Commit() {
    Status status = Exec(db_, "COMMIT");
    committed_ = status.ok();
    return status;
  }

 private:
  sqlite3* db_;
  Status status_;
  bool committed_ = false;
};

constexpr const char* kCharacterColumns =
    "id, name, files, joints, vertices, triangles, proxy_skin, warnings, created_ms, joint_names";
CharacterRecord ReadCharacter(const Statement& s) {
  CharacterRecord c;
  c.id = s.Text(0);
  c.name = s.Text(1);
  c.files = FilesFromJson(s.Text(2));
  c.joints = static_cast<int>(s.Int(3));
  c.vertices = static_cast<int>(s.Int(4));
  c.triangles = static_cast<int>(s.Int(5));
  c.proxy_skin = s.Int(6) != 0;
  c.warnings = ListFromJson(s.Text(7));
  c.created_ms = s.Int(8);
  c.joint_names = ListFromJson(s.Text(9));
  return c;
}

constexpr const char* kMotionColumns =
    "id, character_id, animation, source, source_id, files, duration_seconds, source_fps, "
    "frames, warnings, created_ms";
MotionRecord ReadMotion(const Statement& s) {
  MotionRecord m;
  m.id = s.Text(0);
  m.character_id = s.Text(1);
  m.animation = s.Text(2);
  m.source = s.Text(3);
  m.source_id = s.Text(4);
  m.files = FilesFromJson(s.Text(5));
  m.duration_seconds = s.Double(6);
  m.source_fps = s.Double(7);
  m.frames = static_cast<int>(s.Int(8));
  m.warnings = ListFromJson(s.Text(9));
  m.created_ms = s.Int(10);
  return m;
}

constexpr const char* kBakeColumns =
    "id, character_id, motion_id, request, created_ms, level_set, level_set_bytes, report, "
    "frames, fps";
BakeRecord ReadBake(const Statement& s) {
  BakeRecord b;
  b.id = s.Text(0);
  b.character_id = s.Text(1);
  b.motion_id = s.Text(2);
  b.request_json = s.Text(3);
  b.created_ms = s.Int(4);
  b.level_set = s.Text(5);
  b.level_set_bytes = s.Int(6);
  b.report_json = s.Text(7);
  b.frames = static_cast<int>(s.Int(8));
  b.fps = s.Double(9);
  return b;
}

constexpr const char* kJobColumns =
    "id, bake_id, state, progress, stage, error_code, error_detail, attempts, created_ms, "
    "started_ms, finished_ms";
JobRecord ReadJob(const Statement& s) {
  JobRecord j;
  j.id = s.Text(0);
  j.bake_id = s.Text(1);
  j.state = s.Text(2);
  j.progress = s.Double(3);
  j.stage = s.Text(4);
  j.error_code = s.Text(5);
  j.error_detail = s.Text(6);
  j.attempts = static_cast<int>(s.Int(7));
  j.created_ms = s.Int(8);
  j.started_ms = s.Int(9);
  j.finished_ms = s.Int(10);
  return j;
}

std::string Sql(const char* head, const char* columns, const char* tail) {
  return std::string(head) + columns + tail;
}

// The blobs rows of a bake name (level set and levels).
Status CollectBakeBlobs(sqlite3* db, const std::string& bake_id, std::set<std::string>& blobs) {
  Statement bake(db, "SELECT level_set FROM bakes WHERE id = ?");
  bake.Bind(1, bake_id);
  Status status = bake.ForEachRow("read bake", [&](const Statement& row) {
    if (!row.Text(0).empty()) blobs.insert(row.Text(0));
  });
  if (!status.ok()) return status;
  Statement levels(db, "SELECT hash FROM levels WHERE bake_id = ?");
  levels.Bind(1, bake_id);
  return levels.ForEachRow("read levels", [&](const Statement& row) { blobs.insert(row.Text(0)); });
}

}  // namespace

StatusOr<std::unique_ptr<SqliteStore>> SqliteStore::Open(const std::filesystem::path& file) {
  sqlite3* db = nullptr;
  const int rc =
      sqlite3_open_v2(file.c_str(), &db,
                      SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE | SQLITE_OPEN_FULLMUTEX, nullptr);
  if (rc != SQLITE_OK) {
    Status status(StatusCode::kInternal, "cannot open the database " + file.string() + ": " +
                                             (db ? sqlite3_errmsg(db) : "out of memory"));
    sqlite3_close(db);
    return status;
  }
  std::unique_ptr<SqliteStore> store(new SqliteStore(db));
  sqlite3_busy_timeout(db, 5000);
  for (const char* pragma :
       {"PRAGMA journal_mode=WAL", "PRAGMA synchronous=FULL", "PRAGMA foreign_keys=ON"}) {
    if (Status status = Exec(db, pragma); !status.ok()) return status;
  }
  if (Status status = store->Migrate(); !status.ok()) return status;
  return store;
}

SqliteStore::~SqliteStore() { sqlite3_close(db_); }

Status SqliteStore::Migrate() {
  std::lock_guard lock(mutex_);
  if (Status status =
          Exec(db_, "CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL)");
      !status.ok()) {
    return status;
  }
  Statement version(db_, "SELECT value FROM meta WHERE key = 'schema_version'");
  const int rc = version.Step();
  if (rc == SQLITE_ROW) {
    const std::string found = version.Text(0);
    if (found == std::to_string(kSchemaVersion)) return Status::Ok();
    if (found != "1") {
      return Status(StatusCode::kUnsupported, "the database has schema version " + found +
                                                  "; this build reads versions 1 and " +
                                                  std::to_string(kSchemaVersion));
    }
    Transaction transaction(db_);
    if (!transaction.status().ok()) return transaction.status();
    if (Status status = Exec(db_, kBakeClipsTable); !status.ok()) return status;
    if (Status status = Exec(db_,
                             "INSERT INTO bake_clips (bake_id, idx, motion_id) "
                             "SELECT id, 0, motion_id FROM bakes;"
                             "UPDATE meta SET value = '2' WHERE key = 'schema_version'");
        !status.ok()) {
      return status;
    }
    return transaction.Commit();
  }
  if (rc != SQLITE_DONE) return SqlError(db_, "read schema version");
  Transaction transaction(db_);
  if (!transaction.status().ok()) return transaction.status();
  static constexpr const char* kSchema = R"sql(
CREATE TABLE characters (
  id TEXT PRIMARY KEY, name TEXT NOT NULL, files TEXT NOT NULL, joints INTEGER NOT NULL,
  vertices INTEGER NOT NULL, triangles INTEGER NOT NULL, proxy_skin INTEGER NOT NULL,
  warnings TEXT NOT NULL, created_ms INTEGER NOT NULL, joint_names TEXT NOT NULL);
CREATE TABLE motions (
  id TEXT PRIMARY KEY,
  character_id TEXT NOT NULL REFERENCES characters(id) ON DELETE CASCADE,
  animation TEXT NOT NULL, source TEXT NOT NULL, source_id TEXT NOT NULL, files TEXT NOT NULL,
  duration_seconds REAL NOT NULL, source_fps REAL NOT NULL, frames INTEGER NOT NULL,
  warnings TEXT NOT NULL, created_ms INTEGER NOT NULL);
CREATE INDEX motions_character ON motions(character_id);
CREATE TABLE bakes (
  id TEXT PRIMARY KEY,
  character_id TEXT NOT NULL REFERENCES characters(id) ON DELETE CASCADE,
  motion_id TEXT NOT NULL REFERENCES motions(id) ON DELETE CASCADE,
  request TEXT NOT NULL, created_ms INTEGER NOT NULL, level_set TEXT NOT NULL DEFAULT '',
  level_set_bytes INTEGER NOT NULL DEFAULT 0, report TEXT NOT NULL DEFAULT '',
  frames INTEGER NOT NULL DEFAULT 0, fps REAL NOT NULL DEFAULT 0);
CREATE INDEX bakes_character ON bakes(character_id);
CREATE INDEX bakes_motion ON bakes(motion_id);
CREATE TABLE levels (
  bake_id TEXT NOT NULL REFERENCES bakes(id) ON DELETE CASCADE, idx INTEGER NOT NULL,
  joints INTEGER NOT NULL, hash TEXT NOT NULL, bytes INTEGER NOT NULL,
  PRIMARY KEY (bake_id, idx));
CREATE INDEX levels_hash ON levels(hash);
CREATE TABLE jobs (
  seq INTEGER PRIMARY KEY AUTOINCREMENT, id TEXT NOT NULL UNIQUE,
  bake_id TEXT NOT NULL REFERENCES bakes(id) ON DELETE CASCADE,
  state TEXT NOT NULL CHECK (state IN ('queued', 'running', 'succeeded', 'failed')),
  progress REAL NOT NULL DEFAULT 0, stage TEXT NOT NULL DEFAULT '',
  error_code TEXT NOT NULL DEFAULT '', error_detail TEXT NOT NULL DEFAULT '',
  attempts INTEGER NOT NULL DEFAULT 0, created_ms INTEGER NOT NULL,
  started_ms INTEGER NOT NULL DEFAULT 0, finished_ms INTEGER NOT NULL DEFAULT 0);
CREATE INDEX jobs_bake ON jobs(bake_id);
CREATE INDEX jobs_state ON jobs(state);
)sql";
  if (Status status = Exec(db_, kSchema); !status.ok()) return status;
  if (Status status = Exec(db_, kBakeClipsTable); !status.ok()) return status;
  Statement set(db_, "INSERT INTO meta (key, value) VALUES ('schema_version', ?)");
  set.Bind(1, std::to_string(kSchemaVersion));
  if (Status status = set.Run("write schema version"); !status.ok()) return status;
  return transaction.Commit();
}

StatusOr<bool> SqliteStore::InsertCharacter(const CharacterRecord& c,
                                      const std::vector<MotionRecord>& motions) {
  std::lock_guard lock(mutex_);
  Transaction transaction(db_);
  if (!transaction.status().ok()) return transaction.status();
  Statement insert(db_, Sql("INSERT OR IGNORE INTO characters (", kCharacterColumns,
                            ") VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?)")
                            .c_str());
  insert.Bind(1, c.id)
      .Bind(2, c.name)
      .Bind(3, FilesToJson(c.files))
      .Bind(4, c.joints)
      .Bind(5, c.vertices)
      .Bind(6, c.triangles)
      .Bind(7, c.proxy_skin ? 1 : 0)
      .Bind(8, ListToJson(c.warnings))
      .Bind(9, c.created_ms)
      .Bind(10, ListToJson(c.joint_names));
  if (Status status = insert.Run("insert character"); !status.ok()) return status;
  if (sqlite3_changes(db_) == 0) return false;
  for (const MotionRecord& m : motions) {
    Statement motion(db_, Sql("INSERT OR IGNORE INTO motions (", kMotionColumns,
                              ") VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)")
                              .c_str());
    motion.Bind(1, m.id)
        .Bind(2, m.character_id)
        .Bind(3, m.animation)
        .Bind(4, m.source)
        .Bind(5, m.source_id)
        .Bind(6, FilesToJson(m.files))
        .Bind(7, m.duration_seconds)
        .Bind(8, m.source_fps)
        .Bind(9, m.frames)
        .Bind(10, ListToJson(m.warnings))
        .Bind(11, m.created_ms);
    if (Status status = motion.Run("insert motion"); !status.ok()) return status;
  }
  if (Status status = transaction.Commit(); !status.ok()) return status;
  return true;
}

StatusOr<std::optional<CharacterRecord>> SqliteStore::GetCharacter(const std::string& id) {
  std::lock_guard lock(mutex_);
  Statement select(db_, Sql("SELECT ", kCharacterColumns, " FROM characters WHERE id = ?").c_str());
  select.Bind(1, id);
  return select.ReadOne("read character", ReadCharacter);
}

StatusOr<std::vector<CharacterRecord>> SqliteStore::ListCharacters() {
  std::lock_guard lock(mutex_);
  Statement select(
      db_, Sql("SELECT ", kCharacterColumns, " FROM characters ORDER BY created_ms, id").c_str());
  return select.ReadAll("list characters", ReadCharacter);
}

StatusOr<std::vector<std::string>> SqliteStore::DeleteCharacter(const std::string& id) {
  std::lock_guard lock(mutex_);
  Transaction transaction(db_);
  if (!transaction.status().ok()) return transaction.status();
  std::set<std::string> blobs;
  {
    Statement select(db_, "SELECT files FROM characters WHERE id = ?");
    select.Bind(1, id);
    const int rc = select.Step();
    if (rc == SQLITE_DONE) return NotFound("no character " + id);
    if (rc != SQLITE_ROW) return SqlError(db_, "read character");
    for (const FileRecord& f : FilesFromJson(select.Text(0))) blobs.insert(f.blob);
  }
  {
    Statement motions(db_, "SELECT files FROM motions WHERE character_id = ?");
    motions.Bind(1, id);
    Status status = motions.ForEachRow("read motions", [&](const Statement& row) {
      for (const FileRecord& f : FilesFromJson(row.Text(0))) blobs.insert(f.blob);
    });
    if (!status.ok()) return status;
  }
  {
    Statement bakes(db_, "SELECT id FROM bakes WHERE character_id = ?");
    bakes.Bind(1, id);
    auto bake_ids = bakes.ReadAll("read bakes", [](const Statement& row) { return row.Text(0); });
    if (!bake_ids.ok()) return bake_ids.status();
    for (const std::string& bake : *bake_ids) {
      if (Status status = CollectBakeBlobs(db_, bake, blobs); !status.ok()) return status;
    }
  }
  Statement remove(db_, "DELETE FROM characters WHERE id = ?");
  remove.Bind(1, id);
  if (Status status = remove.Run("delete character"); !status.ok()) return status;
  if (Status status = transaction.Commit(); !status.ok()) return status;
  return std::vector<std::string>(blobs.begin(), blobs.end());
}

Status SqliteStore::InsertMotions(const std::vector<MotionRecord>& motions) {
  std::lock_guard lock(mutex_);
  Transaction transaction(db_);
  if (!transaction.status().ok()) return transaction.status();
  for (const MotionRecord& m : motions) {
    Statement motion(db_, Sql("INSERT OR IGNORE INTO motions (", kMotionColumns,
                              ") VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)")
                              .c_str());
    motion.Bind(1, m.id)
        .Bind(2, m.character_id)
        .Bind(3, m.animation)
        .Bind(4, m.source)
        .Bind(5, m.source_id)
        .Bind(6, FilesToJson(m.files))
        .Bind(7, m.duration_seconds)
        .Bind(8, m.source_fps)
        .Bind(9, m.frames)
        .Bind(10, ListToJson(m.warnings))
        .Bind(11, m.created_ms);
    if (Status status = motion.Run("insert motion"); !status.ok()) return status;
  }
  return transaction.Commit();
}

StatusOr<std::optional<MotionRecord>> SqliteStore::GetMotion(const std::string& id) {
  std::lock_guard lock(mutex_);
  Statement select(db_, Sql("SELECT ", kMotionColumns, " FROM motions WHERE id = ?").c_str());
  select.Bind(1, id);
  return select.ReadOne("read motion", ReadMotion);
}

StatusOr<std::vector<MotionRecord>> SqliteStore::ListMotions(const std::string& character_id) {
  std::lock_guard lock(mutex_);
  Statement select(
      db_, Sql("SELECT ", kMotionColumns,
               " FROM motions WHERE character_id = ? ORDER BY source = 'file', created_ms, rowid")
               .c_str());
  select.Bind(1, character_id);
  return select.ReadAll("list motions", ReadMotion);
}

StatusOr<bool> SqliteStore::InsertBakeAndJob(const BakeRecord& bake, const JobRecord& job) {
  std::lock_guard lock(mutex_);
  Transaction transaction(db_);
  if (!transaction.status().ok()) return transaction.status();
  Statement insert(db_,
                   "INSERT OR IGNORE INTO bakes (id, character_id, motion_id, request, created_ms) "
                   "VALUES (?, ?, ?, ?, ?)");
  insert.Bind(1, bake.id)
      .Bind(2, bake.character_id)
      .Bind(3, bake.motion_id)
      .Bind(4, bake.request_json)
      .Bind(5, bake.created_ms);
  if (Status status = insert.Run("insert bake"); !status.ok()) return status;
  if (sqlite3_changes(db_) == 0) return false;
  for (size_t c = 0; c < bake.clip_motions.size(); ++c) {
    Statement clip(db_, "INSERT INTO bake_clips (bake_id, idx, motion_id) VALUES (?, ?, ?)");
    clip.Bind(1, bake.id).Bind(2, static_cast<int64_t>(c)).Bind(3, bake.clip_motions[c]);
    if (Status status = clip.Run("insert bake clip"); !status.ok()) return status;
  }
  Statement insert_job(db_,
                       "INSERT INTO jobs (id, bake_id, state, created_ms) VALUES (?, ?, ?, ?)");
  insert_job.Bind(1, job.id).Bind(2, job.bake_id).Bind(3, job.state).Bind(4, job.created_ms);
  if (Status status = insert_job.Run("insert job"); !status.ok()) return status;
  if (Status status = transaction.Commit(); !status.ok()) return status;
  return true;
}

Status SqliteStore::ReadClipMotions(BakeRecord& bake) {
  Statement select(db_, "SELECT motion_id FROM bake_clips WHERE bake_id = ? ORDER BY idx");
  select.Bind(1, bake.id);
  auto motions =
      select.ReadAll("read bake clips", [](const Statement& row) { return row.Text(0); });
  if (!motions.ok()) return motions.status();
  bake.clip_motions = std::move(*motions);
  return Status::Ok();
}

StatusOr<std::optional<BakeRecord>> SqliteStore::GetBake(const std::string& id) {
  std::lock_guard lock(mutex_);
  Statement select(db_, Sql("SELECT ", kBakeColumns, " FROM bakes WHERE id = ?").c_str());
  select.Bind(1, id);
  auto bake = select.ReadOne("read bake", ReadBake);
  if (!bake.ok() || !bake->has_value()) return bake;
  if (Status status = ReadClipMotions(**bake); !status.ok()) return status;
  return bake;
}

StatusOr<std::vector<BakeRecord>> SqliteStore::ListBakes(const std::string& character_id) {
  std::lock_guard lock(mutex_);
  Statement select(db_,
                   Sql("SELECT ", kBakeColumns,
                       " FROM bakes WHERE ?1 = '' OR character_id = ?1 ORDER BY created_ms, id")
                       .c_str());
  select.Bind(1, character_id);
  auto bakes = select.ReadAll("list bakes", [](const Statement& row) {
    BakeRecord record = ReadBake(row);
    record.report_json.clear();  // lists stay small
    return record;
  });
  if (!bakes.ok()) return bakes;
  for (BakeRecord& bake : *bakes) {
    if (Status status = ReadClipMotions(bake); !status.ok()) return status;
  }
  return bakes;
}

StatusOr<std::vector<LevelRecord>> SqliteStore::GetLevels(const std::string& bake_id) {
  std::lock_guard lock(mutex_);
  Statement select(db_,
                   "SELECT idx, joints, hash, bytes FROM levels WHERE bake_id = ? ORDER BY idx");
  select.Bind(1, bake_id);
  return select.ReadAll("read levels", [](const Statement& row) {
    return LevelRecord{static_cast<int>(row.Int(0)), static_cast<int>(row.Int(1)), row.Text(2),
                       row.Int(3)};
  });
}

StatusOr<std::vector<std::string>> SqliteStore::DeleteBake(const std::string& id) {
  std::lock_guard lock(mutex_);
  Transaction transaction(db_);
  if (!transaction.status().ok()) return transaction.status();
  std::set<std::string> blobs;
  if (Status status = CollectBakeBlobs(db_, id, blobs); !status.ok()) return status;
  Statement remove(db_, "DELETE FROM bakes WHERE id = ?");
  remove.Bind(1, id);
  if (Status status = remove.Run("delete bake"); !status.ok()) return status;
  if (sqlite3_changes(db_) == 0) return NotFound("no bake " + id);
  if (Status status = transaction.Commit(); !status.ok()) return status;
  return std::vector<std::string>(blobs.begin(), blobs.end());
}

Status SqliteStore::CompleteBake(const BakeRecord& bake, const std::vector<LevelRecord>& levels,
                                 JobRecord& job) {
  std::lock_guard lock(mutex_);
  Transaction transaction(db_);
  if (!transaction.status().ok()) return transaction.status();
  Statement update(
      db_,
      "UPDATE bakes SET level_set = ?, level_set_bytes = ?, report = ?, frames = ?, fps = ? "
      "WHERE id = ?");
  update.Bind(1, bake.level_set)
      .Bind(2, bake.level_set_bytes)
      .Bind(3, bake.report_json)
      .Bind(4, bake.frames)
      .Bind(5, bake.fps)
      .Bind(6, bake.id);
  if (Status status = update.Run("complete bake"); !status.ok()) return status;
  if (sqlite3_changes(db_) == 0) return NotFound("the bake was deleted");
  Statement clear(db_, "DELETE FROM levels WHERE bake_id = ?");
  clear.Bind(1, bake.id);
  if (Status status = clear.Run("clear levels"); !status.ok()) return status;
  for (const LevelRecord& level : levels) {
    Statement insert(
        db_, "INSERT INTO levels (bake_id, idx, joints, hash, bytes) VALUES (?, ?, ?, ?, ?)");
    insert.Bind(1, bake.id)
        .Bind(2, level.index)
        .Bind(3, level.joints)
        .Bind(4, level.hash)
        .Bind(5, level.bytes);
    if (Status status = insert.Run("insert level"); !status.ok()) return status;
  }
  Statement update_job(
      db_,
      "UPDATE jobs SET state = ?, progress = ?, stage = ?, error_code = ?, "
      "error_detail = ?, attempts = ?, started_ms = ?, finished_ms = ? WHERE id = ?");
  update_job.Bind(1, job.state)
      .Bind(2, job.progress)
      .Bind(3, job.stage)
      .Bind(4, job.error_code)
      .Bind(5, job.error_detail)
      .Bind(6, job.attempts)
      .Bind(7, job.started_ms)
      .Bind(8, job.finished_ms)
      .Bind(9, job.id);
  if (Status status = update_job.Run("finish job"); !status.ok()) return status;
  return transaction.Commit();
}

StatusOr<std::optional<JobRecord>> SqliteStore::GetJob(const std::string& id) {
  std::lock_guard lock(mutex_);
  Statement select(db_, Sql("SELECT ", kJobColumns, " FROM jobs WHERE id = ?").c_str());
  select.Bind(1, id);
  return select.ReadOne("read job", ReadJob);
}

StatusOr<bool> SqliteStore::UpdateJob(JobRecord& job) {
  std::lock_guard lock(mutex_);
  Statement update(db_,
                   "UPDATE jobs SET state = ?, progress = ?, stage = ?, error_code = ?, "
                   "error_detail = ?, attempts = ?, started_ms = ?, finished_ms = ? WHERE id = ?");
  update.Bind(1, job.state)
      .Bind(2, job.progress)
      .Bind(3, job.stage)
      .Bind(4, job.error_code)
      .Bind(5, job.error_detail)
      .Bind(6, job.attempts)
      .Bind(7, job.started_ms)
      .Bind(8, job.finished_ms)
      .Bind(9, job.id);
  if (Status status = update.Run("update job"); !status.ok()) return status;
  return sqlite3_changes(db_) > 0;
}

StatusOr<Store::UnfinishedJobs> SqliteStore::TakeUnfinishedJobs(int max_runs, int64_t now_ms) {
  std::lock_guard lock(mutex_);
  Transaction transaction(db_);
  if (!transaction.status().ok()) return transaction.status();
  const auto id_of = [](const Statement& row) { return row.Text(0); };
  Statement poisoned(db_,
                     "SELECT id FROM jobs WHERE state = 'running' AND attempts >= ? ORDER BY seq");
  poisoned.Bind(1, max_runs);
  auto failed = poisoned.ReadAll("list jobs that crashed the daemon", id_of);
  if (!failed.ok()) return failed.status();
  Statement fail(db_,
                 "UPDATE jobs SET state = 'failed', error_code = 'crashed', error_detail = ?, "
                 "finished_ms = ? WHERE state = 'running' AND attempts >= ?");
  fail.Bind(1, CrashedDetail(max_runs))
      .Bind(2, now_ms)
      .Bind(3, max_runs);
  if (Status status = fail.Run("fail jobs that crashed the daemon"); !status.ok()) return status;
  Statement reset(
      db_, "UPDATE jobs SET state = 'queued', progress = 0, stage = '' WHERE state = 'running'");
  if (Status status = reset.Run("requeue running jobs"); !status.ok()) return status;
  Statement select(db_, "SELECT id FROM jobs WHERE state = 'queued' ORDER BY seq");
  auto ids = select.ReadAll("list unfinished jobs", id_of);
  if (!ids.ok()) return ids.status();
  if (Status status = transaction.Commit(); !status.ok()) return status;
  return UnfinishedJobs{*std::move(ids), *std::move(failed)};
}

StatusOr<std::map<std::string, int64_t>> SqliteStore::CountJobsByState() {
  std::lock_guard lock(mutex_);
  Statement select(db_, "SELECT state, COUNT(*) FROM jobs GROUP BY state");
  std::map<std::string, int64_t> counts = {
      {"queued", 0}, {"running", 0}, {"succeeded", 0}, {"failed", 0}};
  Status status = select.ForEachRow(
      "count jobs", [&](const Statement& row) { counts[row.Text(0)] = row.Int(1); });
  if (!status.ok()) return status;
  return counts;
}

StatusOr<std::optional<int64_t>> SqliteStore::LevelBytes(const std::string& hash) {
  std::lock_guard lock(mutex_);
  Statement select(db_, "SELECT bytes FROM levels WHERE hash = ? LIMIT 1");
  select.Bind(1, hash);
  return select.ReadOne("read level", [](const Statement& row) { return row.Int(0); });
}

StatusOr<bool> SqliteStore::IsBlobReferenced(const std::string& hash) {
  std::lock_guard lock(mutex_);
  // Hashes are 64 hex digits, so a LIKE on the JSON file lists cannot match a prefix of
  // another hash by accident.
  Statement select(db_,
                   "SELECT EXISTS (SELECT 1 FROM levels WHERE hash = ?1) "
                   "OR EXISTS (SELECT 1 FROM bakes WHERE level_set = ?1) "
                   "OR EXISTS (SELECT 1 FROM characters WHERE files LIKE '%\"' || ?1 || '\"%') "
                   "OR EXISTS (SELECT 1 FROM motions WHERE files LIKE '%\"' || ?1 || '\"%')");
  select.Bind(1, hash);
  if (select.Step() != SQLITE_ROW) return SqlError(db_, "check blob references");
  return select.Int(0) != 0;
}

StatusOr<std::vector<std::string>> SqliteStore::ReferencedBlobs() {
  std::lock_guard lock(mutex_);
  std::set<std::string> blobs;
  {
    Statement select(
        db_, "SELECT hash FROM levels UNION SELECT level_set FROM bakes WHERE level_set != ''");
    Status status = select.ForEachRow("list level blobs",
                                      [&](const Statement& row) { blobs.insert(row.Text(0)); });
    if (!status.ok()) return status;
  }
  for (const char* sql : {"SELECT files FROM characters", "SELECT files FROM motions"}) {
    Statement select(db_, sql);
    Status status = select.ForEachRow("list file blobs", [&](const Statement& row) {
      for (const FileRecord& f : FilesFromJson(row.Text(0))) blobs.insert(f.blob);
    });
    if (!status.ok()) return status;
  }
  return std::vector<std::string>(blobs.begin(), blobs.end());
}

bool SqliteStore::Healthy() {
  std::lock_guard lock(mutex_);
  Statement select(db_, "SELECT 1");
  return select.Step() == SQLITE_ROW;
}

}  // namespace motionlod::server
