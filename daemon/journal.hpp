#pragma once
// The daemon's crash-safe journal (SQLite, WAL, synchronous=FULL): jobs, plans, views, scans, events. Each
// transition is committed before the action it starts; scan data go to files in the data directory (temp
// file, fsync, rename, fsync of the directory) and are referenced with their size and CRC-32 only once the
// file is durable. After a kill -9 at any moment, a reopened journal resumes every job at its first view
// without a stored scan: no stored scan is lost, none is repeated, no partial file is referenced.
#include <cstdint>
#include <filesystem>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

struct sqlite3;

namespace scancell::daemon {

/// `bytes` under `path` so that after a crash the file is either the old one or complete: written to
/// PATH.tmp, fsynced, renamed, the directory fsynced. JournalError naming the file otherwise.
void write_file_durably(const std::filesystem::path& path, const std::string& bytes);

/// A job's life. Every state and every allowed change is in `kJobTransitions` (journal.cpp), and
/// Journal::set_state refuses any other change; docs/daemon.md draws the same table.
enum class JobState {
  queued,          // waiting for the cell; resume and a restart come back here or to the active state it had
  rough_scanning,  // active: exploration views of a bounding-box job, fused into its rough model
  planning,        // active: the first plan (3M matrix and cover)
  executing,       // active: moving, sweeping, storing the views of the current round
  verifying,       // active: measured coverage of the rough model after a round
  replanning,      // active: a further round for the rows still open
  paused,          // stopped at a safe point by request; resume queues it again, abort ends it
  awaiting_operator,  // a setup is done and the operator is to turn the part over as journalled (issue 20);
                      // `continue` queues it again (the next setup), abort ends it
  done,            // final: the specification is met
  stalled,         // final: nothing more can be measured (named rows, rounds, gain), the rest reported
  aborted,         // final: by request
  faulted,         // a drive, scanner or input fault stopped it; resume (after the fault is cleared) queues it
  failed           // final: a calibration run that could not produce a result
};
const char* to_string(JobState s);
JobState job_state_from(const std::string& s);  // throws std::invalid_argument
bool finished(JobState s);                     // done, stalled, aborted, failed
bool active(JobState s);                       // rough_scanning, planning, executing, verifying, replanning
/// Whether a job may go from `from` to `to` (the table in journal.cpp).
bool transition_allowed(JobState from, JobState to);

struct JobRecord {
  std::int64_t id = 0;
  JobState state = JobState::queued;
  std::string mesh_path, request_json, cause;
  std::string result_json;  // the outcome summary once finished ("" before)
};

struct ViewRecord {
  std::int64_t plan = 0;
  int index = 0;
  std::string pose_json;
  bool stored = false;
};

struct ScanRecord {
  std::int64_t plan = 0;
  int view = 0;
  std::string file;  // relative to the data directory
  std::uint64_t bytes = 0;
  std::uint32_t crc32 = 0;
  std::string note;  // why the scan does not count (e.g. its registration failed); empty when it counts
};

/// Journal errors name the database file and the statement.
struct JournalError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

class Journal {
 public:
  /// How a journal is opened: by its owner (the daemon holding the data directory's lock), which removes the
  /// temp files a crash left behind; or to inspect it (`scancelld --check`, beside a running daemon), which
  /// leaves every file alone: a temp file may be a scan the daemon is writing right now.
  enum class Open { own, inspect };
  /// Opens (or creates) `dir`/journal.sqlite and `dir`/scans/.
  explicit Journal(const std::filesystem::path& dir, Open mode = Open::own);
  ~Journal();
  Journal(const Journal&) = delete;
  Journal& operator=(const Journal&) = delete;

  std::int64_t create_job(const std::string& mesh_path, const std::string& request_json);
  /// The state change and its event, in one transaction.
  void set_state(std::int64_t job, JobState state, const std::string& cause = "");
  JobRecord job(std::int64_t id);
  std::vector<JobRecord> unfinished_jobs();

  /// A plan round for a job with its views (pose JSON per view) and what the round needs to be resumed
  /// (`info`, JSON), in one transaction; returns the plan id.
  std::int64_t add_plan(std::int64_t job, int round, const std::vector<std::string>& view_poses,
                        const std::string& info = "{}");
  /// Plan ids of a job in round order (round -1: the rough scan, when the job made one).
  std::vector<std::int64_t> plans(std::int64_t job);
  std::vector<std::pair<std::int64_t, int>> plan_rounds(std::int64_t job);  // (plan id, round)
  std::string plan_info(std::int64_t plan);
  /// The job's outcome summary (JSON), kept with the job.
  void set_result(std::int64_t job, const std::string& result_json);
  std::vector<JobRecord> jobs(int limit = 100);  // newest first
  /// The latest plan of a job, if any.
  std::optional<std::int64_t> latest_plan(std::int64_t job);
  std::vector<ViewRecord> views(std::int64_t plan);
  std::optional<ViewRecord> first_unfinished_view(std::int64_t plan);

  /// Makes the scan durable (temp, fsync, rename, directory fsync), then records it and marks the view
  /// stored in one transaction. Refuses a view that already has a scan.
  ScanRecord store_scan(std::int64_t plan, int view, const std::string& data, const std::string& note = "");
  std::vector<ScanRecord> scans(std::int64_t plan);
  std::string read_scan(const ScanRecord& s);  // verifies size and CRC-32; JournalError if they do not match

  void event(std::int64_t job, const std::string& text);
  std::vector<std::string> events(std::int64_t job);

  /// Every referenced scan file present with its size and checksum, every stored view with exactly one scan.
  std::vector<std::string> check();
  const std::filesystem::path& data_dir() const { return dir_; }

 private:
  void exec(const std::string& sql);
  // One connection shared by the job runner and the control socket's clients: every public call holds this,
  // so a multi-statement transaction is never interleaved with another thread's.
  std::recursive_mutex mu_;
  std::filesystem::path dir_;
  sqlite3* db_ = nullptr;
};

}  // namespace scancell::daemon
