#pragma once
// scancelld composed: the journal, the cell's hardware, the job loop, the control socket, LCM telemetry and
// systemd notifications. One job runs at a time (one cell); jobs left unfinished by a crash or a stop resume
// at their first unfinished view when the daemon starts.
#include <atomic>
#include <condition_variable>
#include <deque>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>

#include "daemon/cell_io.hpp"
#include "daemon/control.hpp"
#include "daemon/daemon_config.hpp"
#include "daemon/instance_lock.hpp"
#include "daemon/journal.hpp"
#include "daemon/notify.hpp"
#include "daemon/telemetry.hpp"

namespace scancell::daemon {

class Daemon {
 public:
  /// Opens the journal, LCM, the drives (enable, home if needed, park) and the control socket; throws with a
  /// message naming what failed.
  explicit Daemon(DaemonConfig config);
  ~Daemon();

  /// Runs until SIGTERM/SIGINT (stop at the next safe point, park, close); SIGHUP reloads the calibration.
  /// The caller blocks those signals in every thread before constructing the daemon.
  int run();

  /// The control socket's request handler (public for tests that skip the socket).
  nlohmann::json handle(const nlohmann::json& req, const std::function<bool(const nlohmann::json&)>& send);

 private:
  void job_loop();
  /// Stops the running job at its next safe point and joins the job thread (shutdown and destruction).
  void stop_job_thread();
  void report(const Progress& p);
  void publish_status();
  void publish_axes();
  nlohmann::json progress_json(const Progress& p) const;
  // The control commands (handle dispatches; docs/daemon.md lists them).
  nlohmann::json submit(const nlohmann::json& req);
  nlohmann::json status(const nlohmann::json& req);
  nlohmann::json record(const nlohmann::json& req);
  nlohmann::json watch(const nlohmann::json& req, const std::function<bool(const nlohmann::json&)>& send);
  nlohmann::json pause_or_abort(const nlohmann::json& req, const std::string& cmd);
  nlohmann::json resume(const nlohmann::json& req);
  /// awaiting_operator -> queued: the operator turned the part over as the job's next setup asked (issue 20).
  nlohmann::json continue_setup(const nlohmann::json& req);
  nlohmann::json reload();
  std::optional<std::int64_t> next_runnable();

  DaemonConfig config_;
  std::mutex config_mu_;  // models are copied per job; SIGHUP changes them for the next job
  std::unique_ptr<InstanceLock> data_lock_, socket_lock_;  // first taken, last released
  std::unique_ptr<Journal> journal_;
  std::unique_ptr<Telemetry> telemetry_;
  std::mutex telemetry_mu_;
  std::unique_ptr<CellIo> io_;
  ServiceNotifier notifier_;

  std::atomic<bool> running_{true};
  std::atomic<int> stop_{0};              // StopRequest for the job that is running
  std::atomic<std::int64_t> current_{0};  // the running job, 0 when idle
  std::mutex claim_mu_;
  std::atomic<int> shutting_down_{0};     // set first when stopping: a submit's mesh read stops at once                   // the job loop claiming a job vs. pause/abort requests
  std::mutex wake_mu_;
  std::condition_variable wake_;

  // Progress of every job as events for `watch`: a bounded log with sequence numbers.
  mutable std::mutex events_mu_;
  std::condition_variable events_cv_;
  std::deque<std::pair<std::uint64_t, Progress>> events_;
  std::uint64_t next_seq_ = 1;
  Progress last_;  // the latest progress of the running (or last run) job

  std::thread job_thread_;
  std::unique_ptr<ControlServer> control_;
};

}  // namespace scancell::daemon
