#include "daemon/journal.hpp"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <iterator>
#include <map>
#include <stdexcept>

#include <fcntl.h>
#include <sqlite3.h>
#include <unistd.h>
#include <zlib.h>

namespace scancell::daemon {
namespace {

const std::map<JobState, const char*> kNames = {
    {JobState::queued, "queued"},     {JobState::rough_scanning, "rough_scanning"}, {JobState::planning, "planning"}, {JobState::executing, "executing"},
    {JobState::verifying, "verifying"}, {JobState::replanning, "replanning"}, {JobState::paused, "paused"},
    {JobState::awaiting_operator, "awaiting_operator"}, {JobState::done, "done"},
    {JobState::stalled, "stalled"},   {JobState::aborted, "aborted"},   {JobState::faulted, "faulted"},
    {JobState::failed, "failed"}};

/// A prepared statement that finalises itself; errors name the database and the SQL.
class Stmt {
 public:
  Stmt(sqlite3* db, const std::string& sql) : db_(db), sql_(sql) {
    if (sqlite3_prepare_v2(db, sql.c_str(), -1, &s_, nullptr) != SQLITE_OK) fail("prepare");
  }
  ~Stmt() { sqlite3_finalize(s_); }
  Stmt& bind(int i, std::int64_t v) { return check(sqlite3_bind_int64(s_, i, v)); }
  Stmt& bind(int i, const std::string& v) { return check(sqlite3_bind_text(s_, i, v.c_str(), -1, SQLITE_TRANSIENT)); }
  bool step() {
    const int r = sqlite3_step(s_);
    if (r == SQLITE_ROW) return true;
    if (r == SQLITE_DONE) return false;
    fail("step");
  }
  std::int64_t i64(int c) { return sqlite3_column_int64(s_, c); }
  std::string text(int c) {
    const auto* t = sqlite3_column_text(s_, c);
    return t ? reinterpret_cast<const char*>(t) : "";
  }

 private:
  Stmt& check(int r) {
    if (r != SQLITE_OK) fail("bind");
    return *this;
  }
  [[noreturn]] void fail(const char* what) {
    throw JournalError(std::string(sqlite3_db_filename(db_, "main")) + ": " + what + " '" + sql_ + "': " + sqlite3_errmsg(db_));
  }
  sqlite3* db_;
  sqlite3_stmt* s_ = nullptr;
  std::string sql_;
};

/// BEGIN IMMEDIATE ... COMMIT, rolled back if not committed.
class Transaction {
 public:
  explicit Transaction(sqlite3* db) : db_(db) { run("BEGIN IMMEDIATE"); }
  ~Transaction() {
    if (!done_) sqlite3_exec(db_, "ROLLBACK", nullptr, nullptr, nullptr);
  }
  void commit() {
    run("COMMIT");
    done_ = true;
  }

 private:
  void run(const char* sql) {
    char* err = nullptr;
    if (sqlite3_exec(db_, sql, nullptr, nullptr, &err) != SQLITE_OK) {
      const std::string msg = err ? err : "?";
      sqlite3_free(err);
      throw JournalError(std::string("journal: ") + sql + ": " + msg);
    }
  }
  sqlite3* db_;
  bool done_ = false;
};

void fsync_path(const std::filesystem::path& p, bool directory) {
  const int fd = ::open(p.c_str(), directory ? O_RDONLY | O_DIRECTORY : O_RDONLY);
  if (fd < 0) throw JournalError(p.string() + ": open for fsync: " + std::strerror(errno));
  const int r = ::fsync(fd);
  ::close(fd);
  if (r != 0) throw JournalError(p.string() + ": fsync: " + std::strerror(errno));
}

std::uint32_t crc_of(const std::string& data) {
  return static_cast<std::uint32_t>(::crc32(0L, reinterpret_cast<const Bytef*>(data.data()), static_cast<uInt>(data.size())));
}

}  // namespace

void write_file_durably(const std::filesystem::path& path, const std::string& bytes) {
  const std::filesystem::path tmp = path.string() + ".tmp";
  {
    std::ofstream f(tmp, std::ios::binary | std::ios::trunc);
    if (!f) throw JournalError(tmp.string() + ": cannot open for writing");
    f.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    if (!f.flush()) throw JournalError(tmp.string() + ": write failed");
  }
  fsync_path(tmp, false);
  std::filesystem::rename(tmp, path);
  fsync_path(path.parent_path().empty() ? std::filesystem::path(".") : path.parent_path(), true);
}

const char* to_string(JobState s) { return kNames.at(s); }

JobState job_state_from(const std::string& s) {
  for (const auto& [k, v] : kNames)
    if (s == v) return k;
  throw std::invalid_argument("unknown job state '" + s + "'");
}

bool finished(JobState s) {
  return s == JobState::done || s == JobState::stalled || s == JobState::aborted || s == JobState::failed;
}

bool active(JobState s) {
  return s == JobState::rough_scanning || s == JobState::planning || s == JobState::executing || s == JobState::verifying ||
         s == JobState::replanning;
}

namespace {

// The job state machine, all of it (LinuxCNC estop_latch style: states and every transition in one place).
// An active state may go to any active state: the 3M loop goes round (executing, verifying, replanning,
// executing), and a daemon restarted after kill -9 resumes a job in the state it died in.
struct JobTransitions {
  JobState from;
  std::vector<JobState> to;
};
using S = JobState;
const std::vector<S> kActive = {S::rough_scanning, S::planning, S::executing, S::verifying, S::replanning};
std::vector<S> with_active(std::vector<S> more) {
  more.insert(more.end(), kActive.begin(), kActive.end());
  return more;
}
const std::vector<JobTransitions>& job_transitions() {
  static const std::vector<JobTransitions> t = {
      // queued: started (its first active state; a calibration run starts executing), or paused or aborted
      // while waiting, or faulted or failed on its input before anything moved.
      {S::queued, with_active({S::paused, S::aborted, S::faulted, S::failed})},
      // active: round and round, then an ending; paused at a safe point; faulted by hardware or input; a
      // setup ended with a next one to measure: the operator is to turn the part over (verifying or
      // replanning end a setup, as they end a job).
      {S::rough_scanning, with_active({S::paused, S::done, S::stalled, S::aborted, S::faulted, S::failed})},
      {S::planning, with_active({S::paused, S::done, S::stalled, S::aborted, S::faulted, S::failed})},
      {S::executing, with_active({S::paused, S::done, S::stalled, S::aborted, S::faulted, S::failed})},
      {S::verifying, with_active({S::paused, S::awaiting_operator, S::done, S::stalled, S::aborted, S::faulted, S::failed})},
      {S::replanning, with_active({S::paused, S::awaiting_operator, S::done, S::stalled, S::aborted, S::faulted, S::failed})},
      // paused and faulted: resume queues the job again; abort ends it.
      {S::paused, {S::queued, S::aborted}},
      {S::faulted, {S::queued, S::aborted}},
      // awaiting_operator: the operator's `continue` (the part turned over) queues the next setup; abort ends
      // the job with what the setups so far measured.
      {S::awaiting_operator, {S::queued, S::aborted}},
      // done, stalled, aborted, failed: final.
  };
  return t;
}

}  // namespace

bool transition_allowed(JobState from, JobState to) {
  for (const auto& t : job_transitions())
    if (t.from == from) return std::find(t.to.begin(), t.to.end(), to) != t.to.end();
  return false;
}

Journal::Journal(const std::filesystem::path& dir, Open mode) : dir_(dir) {
  std::filesystem::create_directories(dir_ / "scans");
  // A crash between writing a temp file and renaming it leaves it behind; it is referenced by nothing. Only
  // the owner removes them: `scancelld --check` beside a running daemon removed the scan it was writing, and
  // the job faulted renaming it (daemon_cli, 2026-11-29).
  if (mode == Open::own)
    for (const auto& e : std::filesystem::directory_iterator(dir_ / "scans"))
      if (e.path().extension() == ".tmp") std::filesystem::remove(e.path());
  const std::string file = (dir_ / "journal.sqlite").string();
  if (sqlite3_open(file.c_str(), &db_) != SQLITE_OK) {
    const std::string msg = db_ ? sqlite3_errmsg(db_) : "out of memory";
    sqlite3_close(db_);
    throw JournalError(file + ": open: " + msg);
  }
  sqlite3_busy_timeout(db_, 5000);
  exec("PRAGMA journal_mode=WAL");
  exec("PRAGMA synchronous=FULL");
  exec("PRAGMA foreign_keys=ON");
  exec(R"(CREATE TABLE IF NOT EXISTS jobs (id INTEGER PRIMARY KEY, state TEXT NOT NULL, mesh TEXT NOT NULL,
                                           request TEXT NOT NULL, cause TEXT NOT NULL DEFAULT '',
                                           result TEXT NOT NULL DEFAULT '',
                                           created REAL NOT NULL DEFAULT (julianday('now'))))");
  exec(R"(CREATE TABLE IF NOT EXISTS plans (id INTEGER PRIMARY KEY, job INTEGER NOT NULL REFERENCES jobs(id),
                                            round INTEGER NOT NULL, info TEXT NOT NULL DEFAULT '{}',
                                            UNIQUE(job, round)))");
  exec(R"(CREATE TABLE IF NOT EXISTS views (plan INTEGER NOT NULL REFERENCES plans(id), idx INTEGER NOT NULL,
                                            pose TEXT NOT NULL, stored INTEGER NOT NULL DEFAULT 0,
                                            PRIMARY KEY(plan, idx)))");
  exec(R"(CREATE TABLE IF NOT EXISTS scans (plan INTEGER NOT NULL, view INTEGER NOT NULL, file TEXT NOT NULL,
                                            bytes INTEGER NOT NULL, crc32 INTEGER NOT NULL,
                                            note TEXT NOT NULL DEFAULT '',
                                            PRIMARY KEY(plan, view), FOREIGN KEY(plan, view) REFERENCES views(plan, idx)))");
  exec(R"(CREATE TABLE IF NOT EXISTS events (id INTEGER PRIMARY KEY, job INTEGER NOT NULL, text TEXT NOT NULL,
                                             time REAL NOT NULL DEFAULT (julianday('now'))))");
}

Journal::~Journal() { sqlite3_close(db_); }

void Journal::exec(const std::string& sql) {
  char* err = nullptr;
  if (sqlite3_exec(db_, sql.c_str(), nullptr, nullptr, &err) != SQLITE_OK) {
    const std::string msg = err ? err : "?";
    sqlite3_free(err);
    throw JournalError((dir_ / "journal.sqlite").string() + ": '" + sql.substr(0, 60) + "': " + msg);
  }
}

std::int64_t Journal::create_job(const std::string& mesh, const std::string& request) {
  std::lock_guard<std::recursive_mutex> lock(mu_);
  Transaction t(db_);
  Stmt(db_, "INSERT INTO jobs(state, mesh, request) VALUES (?, ?, ?)").bind(1, std::string("queued")).bind(2, mesh).bind(3, request).step();
  const std::int64_t id = sqlite3_last_insert_rowid(db_);
  Stmt(db_, "INSERT INTO events(job, text) VALUES (?, 'queued')").bind(1, id).step();
  t.commit();
  return id;
}

void Journal::set_state(std::int64_t job, JobState state, const std::string& cause) {
  std::lock_guard<std::recursive_mutex> lock(mu_);
  Transaction t(db_);
  {
    Stmt s(db_, "SELECT state FROM jobs WHERE id = ?");
    s.bind(1, job);
    if (!s.step()) throw JournalError("journal: no job " + std::to_string(job));
    const JobState from = job_state_from(s.text(0));
    if (!transition_allowed(from, state))
      throw JournalError("journal: job " + std::to_string(job) + " cannot go from " + to_string(from) + " to " + to_string(state) +
                         " (the job state machine, daemon/journal.cpp)");
  }
  Stmt(db_, "UPDATE jobs SET state = ?, cause = ? WHERE id = ?").bind(1, std::string(to_string(state))).bind(2, cause).bind(3, job).step();
  if (sqlite3_changes(db_) != 1) throw JournalError("journal: no job " + std::to_string(job));
  Stmt(db_, "INSERT INTO events(job, text) VALUES (?, ?)").bind(1, job).bind(2, std::string(to_string(state)) + (cause.empty() ? "" : ": " + cause)).step();
  t.commit();
}

JobRecord Journal::job(std::int64_t id) {
  std::lock_guard<std::recursive_mutex> lock(mu_);
  Stmt s(db_, "SELECT id, state, mesh, request, cause, result FROM jobs WHERE id = ?");
  s.bind(1, id);
  if (!s.step()) throw JournalError("journal: no job " + std::to_string(id));
  return {s.i64(0), job_state_from(s.text(1)), s.text(2), s.text(3), s.text(4), s.text(5)};
}

std::vector<JobRecord> Journal::jobs(int limit) {
  std::lock_guard<std::recursive_mutex> lock(mu_);
  std::vector<JobRecord> out;
  Stmt s(db_, "SELECT id, state, mesh, request, cause, result FROM jobs ORDER BY id DESC LIMIT ?");
  s.bind(1, static_cast<std::int64_t>(limit));
  while (s.step()) out.push_back({s.i64(0), job_state_from(s.text(1)), s.text(2), s.text(3), s.text(4), s.text(5)});
  return out;
}

void Journal::set_result(std::int64_t job, const std::string& result) {
  std::lock_guard<std::recursive_mutex> lock(mu_);
  Stmt(db_, "UPDATE jobs SET result = ? WHERE id = ?").bind(1, result).bind(2, job).step();
  if (sqlite3_changes(db_) != 1) throw JournalError("journal: no job " + std::to_string(job));
}

std::vector<std::int64_t> Journal::plans(std::int64_t job) {
  std::lock_guard<std::recursive_mutex> lock(mu_);
  std::vector<std::int64_t> out;
  Stmt s(db_, "SELECT id FROM plans WHERE job = ? ORDER BY round");
  s.bind(1, job);
  while (s.step()) out.push_back(s.i64(0));
  return out;
}

std::vector<std::pair<std::int64_t, int>> Journal::plan_rounds(std::int64_t job) {
  std::lock_guard<std::recursive_mutex> lock(mu_);
  std::vector<std::pair<std::int64_t, int>> out;
  Stmt s(db_, "SELECT id, round FROM plans WHERE job = ? ORDER BY round");
  s.bind(1, job);
  while (s.step()) out.emplace_back(s.i64(0), static_cast<int>(s.i64(1)));
  return out;
}

std::string Journal::plan_info(std::int64_t plan) {
  std::lock_guard<std::recursive_mutex> lock(mu_);
  Stmt s(db_, "SELECT info FROM plans WHERE id = ?");
  s.bind(1, plan);
  if (!s.step()) throw JournalError("journal: no plan " + std::to_string(plan));
  return s.text(0);
}

std::vector<JobRecord> Journal::unfinished_jobs() {
  std::lock_guard<std::recursive_mutex> lock(mu_);
  std::vector<JobRecord> out;
  Stmt s(db_, "SELECT id, state, mesh, request, cause, result FROM jobs WHERE state NOT IN ('done', 'stalled', 'aborted', 'failed') ORDER BY id");
  while (s.step()) out.push_back({s.i64(0), job_state_from(s.text(1)), s.text(2), s.text(3), s.text(4), s.text(5)});
  return out;
}

std::int64_t Journal::add_plan(std::int64_t job, int round, const std::vector<std::string>& poses, const std::string& info) {
  std::lock_guard<std::recursive_mutex> lock(mu_);
  Transaction t(db_);
  Stmt(db_, "INSERT INTO plans(job, round, info) VALUES (?, ?, ?)").bind(1, job).bind(2, round).bind(3, info).step();
  const std::int64_t plan = sqlite3_last_insert_rowid(db_);
  for (std::size_t k = 0; k < poses.size(); ++k)
    Stmt(db_, "INSERT INTO views(plan, idx, pose) VALUES (?, ?, ?)").bind(1, plan).bind(2, static_cast<std::int64_t>(k)).bind(3, poses[k]).step();
  Stmt(db_, "INSERT INTO events(job, text) VALUES (?, ?)").bind(1, job).bind(2, "plan round " + std::to_string(round) + ": " + std::to_string(poses.size()) + " views").step();
  t.commit();
  return plan;
}

std::optional<std::int64_t> Journal::latest_plan(std::int64_t job) {
  std::lock_guard<std::recursive_mutex> lock(mu_);
  Stmt s(db_, "SELECT id FROM plans WHERE job = ? ORDER BY round DESC LIMIT 1");
  s.bind(1, job);
  if (!s.step()) return std::nullopt;
  return s.i64(0);
}

std::vector<ViewRecord> Journal::views(std::int64_t plan) {
  std::lock_guard<std::recursive_mutex> lock(mu_);
  std::vector<ViewRecord> out;
  Stmt s(db_, "SELECT plan, idx, pose, stored FROM views WHERE plan = ? ORDER BY idx");
  s.bind(1, plan);
  while (s.step()) out.push_back({s.i64(0), static_cast<int>(s.i64(1)), s.text(2), s.i64(3) != 0});
  return out;
}

std::optional<ViewRecord> Journal::first_unfinished_view(std::int64_t plan) {
  std::lock_guard<std::recursive_mutex> lock(mu_);
  Stmt s(db_, "SELECT plan, idx, pose, stored FROM views WHERE plan = ? AND stored = 0 ORDER BY idx LIMIT 1");
  s.bind(1, plan);
  if (!s.step()) return std::nullopt;
  return ViewRecord{s.i64(0), static_cast<int>(s.i64(1)), s.text(2), false};
}

ScanRecord Journal::store_scan(std::int64_t plan, int view, const std::string& data, const std::string& note) {
  std::lock_guard<std::recursive_mutex> lock(mu_);
  {
    Stmt s(db_, "SELECT stored FROM views WHERE plan = ? AND idx = ?");
    s.bind(1, plan).bind(2, static_cast<std::int64_t>(view));
    if (!s.step()) throw JournalError("journal: plan " + std::to_string(plan) + " has no view " + std::to_string(view));
    if (s.i64(0) != 0) throw JournalError("journal: plan " + std::to_string(plan) + " view " + std::to_string(view) + " already has its scan");
  }
  ScanRecord rec{plan, view, "scans/p" + std::to_string(plan) + "-v" + std::to_string(view) + ".bin", data.size(), crc_of(data), note};
  write_file_durably(dir_ / rec.file, data);
  // Only now, with the file durable under its final name, does the journal reference it.
  Transaction t(db_);
  Stmt(db_, "INSERT INTO scans(plan, view, file, bytes, crc32, note) VALUES (?, ?, ?, ?, ?, ?)")
      .bind(1, plan).bind(2, static_cast<std::int64_t>(view)).bind(3, rec.file)
      .bind(4, static_cast<std::int64_t>(rec.bytes)).bind(5, static_cast<std::int64_t>(rec.crc32)).bind(6, note).step();
  Stmt(db_, "UPDATE views SET stored = 1 WHERE plan = ? AND idx = ?").bind(1, plan).bind(2, static_cast<std::int64_t>(view)).step();
  t.commit();
  return rec;
}

std::vector<ScanRecord> Journal::scans(std::int64_t plan) {
  std::lock_guard<std::recursive_mutex> lock(mu_);
  std::vector<ScanRecord> out;
  Stmt s(db_, "SELECT plan, view, file, bytes, crc32, note FROM scans WHERE plan = ? ORDER BY view");
  s.bind(1, plan);
  while (s.step())
    out.push_back({s.i64(0), static_cast<int>(s.i64(1)), s.text(2), static_cast<std::uint64_t>(s.i64(3)),
                   static_cast<std::uint32_t>(s.i64(4)), s.text(5)});
  return out;
}

std::string Journal::read_scan(const ScanRecord& r) {
  std::lock_guard<std::recursive_mutex> lock(mu_);
  std::ifstream f(dir_ / r.file, std::ios::binary);
  if (!f) throw JournalError((dir_ / r.file).string() + ": missing");
  std::string data((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  if (data.size() != r.bytes) throw JournalError((dir_ / r.file).string() + ": " + std::to_string(data.size()) + " bytes, journal says " + std::to_string(r.bytes));
  if (crc_of(data) != r.crc32) throw JournalError((dir_ / r.file).string() + ": checksum mismatch");
  return data;
}

void Journal::event(std::int64_t job, const std::string& text) {
  std::lock_guard<std::recursive_mutex> lock(mu_);
  Stmt(db_, "INSERT INTO events(job, text) VALUES (?, ?)").bind(1, job).bind(2, text).step();
}

std::vector<std::string> Journal::events(std::int64_t job) {
  std::lock_guard<std::recursive_mutex> lock(mu_);
  std::vector<std::string> out;
  Stmt s(db_, "SELECT text FROM events WHERE job = ? ORDER BY id");
  s.bind(1, job);
  while (s.step()) out.push_back(s.text(0));
  return out;
}

std::vector<std::string> Journal::check() {
  std::lock_guard<std::recursive_mutex> lock(mu_);
  std::vector<std::string> problems;
  Stmt s(db_, "SELECT plan, view, file, bytes, crc32 FROM scans");
  while (s.step()) {
    const ScanRecord r{s.i64(0), static_cast<int>(s.i64(1)), s.text(2), static_cast<std::uint64_t>(s.i64(3)), static_cast<std::uint32_t>(s.i64(4)), ""};
    try {
      read_scan(r);
    } catch (const JournalError& e) {
      problems.push_back(e.what());
    }
  }
  Stmt v(db_, "SELECT v.plan, v.idx FROM views v LEFT JOIN scans s ON s.plan = v.plan AND s.view = v.idx "
              "WHERE v.stored = 1 AND s.file IS NULL");
  while (v.step()) problems.push_back("plan " + std::to_string(v.i64(0)) + " view " + std::to_string(v.i64(1)) + ": stored without a scan");
  return problems;
}

}  // namespace scancell::daemon
