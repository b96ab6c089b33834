#include "daemon/daemon.hpp"

#include <algorithm>
#include <cctype>
#include <csignal>
#include <iostream>
#include <limits>

#include <signal.h>

#include "calibration/results.hpp"
#include "daemon/calibration_job.hpp"
#include "common/errors.hpp"
#include "common/text_file.hpp"

namespace scancell::daemon {

using nlohmann::json;
namespace fs = std::filesystem;
using namespace std::chrono_literals;

namespace {

bool runnable(JobState s) {
  return s == JobState::queued || s == JobState::rough_scanning || s == JobState::planning || s == JobState::executing ||
         s == JobState::verifying || s == JobState::replanning;
}

bool ends_watch(JobState s) {
  return finished(s) || s == JobState::faulted || s == JobState::paused || s == JobState::awaiting_operator;
}

/// A file a client names: absolute, a regular file (a FIFO or device would block the thread that opens it),
/// and, when jobs.allowed_dirs is set, inside one of them after links are resolved. Nothing of the file's
/// content is quoted in a refusal.
std::string client_file(const json& req, const char* key, const std::vector<fs::path>& allowed) {
  if (!req.contains(key)) return "";
  const std::string p = req[key].get<std::string>();
  const std::string name = std::string("submit: '") + key + "'";
  if (p.empty() || p[0] != '/')
    throw std::invalid_argument(name + " must be an absolute path (the daemon's working directory is not yours), got '" + p + "'");
  const std::string kind = scancell::file_kind(p);
  if (kind == "missing") throw std::invalid_argument(name + ": no such file '" + p + "'");
  if (kind != "regular file") throw std::invalid_argument(name + ": '" + p + "' is a " + kind + ", not a regular file");
  if (allowed.empty()) return p;
  std::error_code ec;
  const fs::path real = fs::canonical(p, ec);
  if (ec) throw std::invalid_argument(name + ": cannot resolve '" + p + "'");
  for (const auto& dir : allowed) {
    const auto rel = real.lexically_relative(dir);
    if (!rel.empty() && *rel.begin() != "..") return real.string();
  }
  std::string dirs;
  for (const auto& d : allowed) dirs += (dirs.empty() ? "" : ", ") + d.string();
  throw std::invalid_argument(name + ": '" + p + "' is outside jobs.allowed_dirs (" + dirs + ")");
}

/// A refusal of a client-named YAML file without its content: quoted values become '…' and what follows
/// "got " is dropped, so no value of a file the client could not read itself comes back over the socket.
std::string without_content(const std::string& message) {
  std::string out;
  bool quoted = false;
  for (std::size_t k = 0; k < message.size(); ++k) {
    const char ch = message[k];
    // An opening quote follows a space or bracket (an apostrophe, as in "daemon's", follows a letter).
    if (ch == '\'' && (quoted || k == 0 || !std::isalnum(static_cast<unsigned char>(message[k - 1])))) {
      if (!quoted) out += "'…'";
      quoted = !quoted;
      continue;
    }
    if (!quoted) out += ch;
  }
  if (const auto g = out.find(", got "); g != std::string::npos) out.erase(g);
  return out;
}

}  // namespace

Daemon::Daemon(DaemonConfig config) : config_(std::move(config)) {
  // Before anything touches the journal, the drives or the socket: a second daemon must not.
  data_lock_ = std::make_unique<InstanceLock>(config_.data_dir / "scancelld.lock");
  socket_lock_ = std::make_unique<InstanceLock>(config_.socket_path.string() + ".lock");
  journal_ = std::make_unique<Journal>(config_.data_dir);
  fs::permissions(config_.data_dir, fs::perms::owner_all | fs::perms::group_read | fs::perms::group_exec);  // 0750
  telemetry_ = std::make_unique<Telemetry>(config_.lcm_url);
  io_ = open_cell_io(config_.models.cell, config_.drivers, config_.drivers_file.string());
  bring_up(*io_, config_.models.cell, config_.home_timeout);
  fs::create_directories(config_.socket_path.parent_path());
  control_ = std::make_unique<ControlServer>(
      config_.socket_path, [this](const json& r, const std::function<bool(const json&)>& send) { return handle(r, send); },
      config_.control);
  job_thread_ = std::thread([this] { job_loop(); });
}

void Daemon::stop_job_thread() {
  shutting_down_ = 1;  // first: a submit's mesh read stops at once
  running_ = false;
  stop_ = static_cast<int>(StopRequest::shutdown);
  wake_.notify_all();
  events_cv_.notify_all();
  if (job_thread_.joinable()) job_thread_.join();
}

Daemon::~Daemon() {
  stop_job_thread();
  control_.reset();
}

std::optional<std::int64_t> Daemon::next_runnable() {
  for (const auto& j : journal_->unfinished_jobs())
    if (runnable(j.state)) return j.id;
  return std::nullopt;
}

void Daemon::job_loop() {
  while (running_) {
    const auto id = next_runnable();
    bool hardware_ok = true;
    for (const auto& n : io_->positioner.names()) hardware_ok = hardware_ok && !io_->positioner.axis(n).state().faulted;
    hardware_ok = hardware_ok && !io_->positioner.estop_latched();
    if (!id || !hardware_ok) {
      std::unique_lock<std::mutex> lock(wake_mu_);
      wake_.wait_for(lock, 500ms);
      continue;
    }
    CellModels models;
    {
      std::lock_guard<std::mutex> lock(config_mu_);
      models = config_.models;
    }
    const std::uint64_t seed = config_.scanner_seed;
    const std::optional<SimTruth> truth = config_.truth;
    auto heads = [&models, seed, &truth, this](const planner::TriangleMesh& scene, std::size_t object_triangles,
                                               const planner::CellModel& placed) {
      if (config_.scanner_driver == "genicam")
        return make_genicam_head(models.sensor, config_.genicam, config_.trigger_chip, config_.trigger_offset);
      return make_sim_head(models.sensor, scene, object_triangles, seed, &placed, truth ? &*truth : nullptr,
                           config_.scanner_driver == "sim_gige" ? &config_.genicam : nullptr);
    };
    // Claim the job. Under claim_mu_ a pause or abort either finds current_ set (and raises stop_, which is
    // not cleared after this point) or has written its state to the journal first (and the re-read below
    // skips the job): the request is never lost (issue 16, suspected race 2). A stop request left from an
    // earlier job is cleared, a shutdown never: it may have come after running_ was checked (race 1).
    {
      std::lock_guard<std::mutex> claim(claim_mu_);
      int s = stop_.load();
      while (s != static_cast<int>(StopRequest::shutdown) && !stop_.compare_exchange_weak(s, 0)) {
      }
      if (!runnable(journal_->job(*id).state)) continue;
      current_ = *id;
    }
    notifier_.status("job " + std::to_string(*id) + " running");
    JobState end;
    const json request = json::parse(journal_->job(*id).request_json);
    if (request.contains("calibrate")) {
      const std::string kind = request["calibrate"].get<std::string>();
      end = run_calibration_job(*journal_, *id, kind, models, io_->positioner, heads, config_.jobs,
                                config_.data_dir / "calibration", stop_, [this](const Progress& p) { report(p); });
      if (end == JobState::done) {
        // The new values take effect for the jobs that follow.
        const json result = json::parse(journal_->job(*id).result_json);
        std::lock_guard<std::mutex> lock(config_mu_);
        calibration::apply_calibration(calibration::load_calibration(result["file"].get<std::string>()), config_.models.sensor,
                                       config_.models.cell);
        config_.calibration_applied.push_back(result["file"].get<std::string>());
      }
    } else {
      JobRunner runner(*journal_, models, io_->positioner, heads, config_.jobs, [this](const Progress& p) { report(p); });
      end = runner.run(*id, stop_);
    }
    current_ = 0;
    notifier_.status("idle (job " + std::to_string(*id) + " " + to_string(end) + ")");
    // Parked at the end, and before the operator reaches into the cell to turn the part over.
    if (running_ && (finished(end) || end == JobState::awaiting_operator)) {
      try {
        park(*io_, models.cell, config_.jobs.move_timeout);
      } catch (const std::exception& e) {
        journal_->event(*id, std::string("park after the job failed: ") + e.what());
      }
    }
    publish_status();
  }
}

json Daemon::progress_json(const Progress& p) const {
  return {{"job", p.job},          {"state", to_string(p.state)}, {"round", p.round},
          {"view", p.view},        {"views", p.views},            {"estimated_coverage", p.estimated},
          {"measured_coverage", p.measured}, {"eta_s", p.eta_s},   {"event", p.event}};
}

void Daemon::report(const Progress& p) {
  {
    std::lock_guard<std::mutex> lock(events_mu_);
    events_.emplace_back(next_seq_++, p);
    while (events_.size() > 4096) events_.pop_front();
    last_ = p;
  }
  events_cv_.notify_all();
  std::lock_guard<std::mutex> lock(telemetry_mu_);
  if (!p.event.empty()) telemetry_->progress(p.job, p.event);
  if (p.state == JobState::faulted && p.event.rfind("faulted", 0) == 0) {
    scancell::fault_t f{};
    f.job_id = p.job;
    f.axis = p.fault_axis;
    f.kind = p.fault_kind;
    f.text = p.event;
    telemetry_->fault(f);
  }
  if (p.state == JobState::executing && p.event.rfind("executing", 0) == 0) {
    // The round's plan as it will be executed.
    scancell::plan_t m{};
    m.job_id = p.job;
    m.round = p.round;
    if (const auto plan = journal_->latest_plan(p.job))
      for (const auto& v : journal_->views(*plan)) {
        const json pj = json::parse(v.pose_json);
        std::vector<double> t = pj.at("camera_to_object").get<std::vector<double>>();
        m.camera_to_object.push_back(t);
        m.scan_length_mm.push_back(pj.at("scan_length_mm").get<double>());
      }
    telemetry_->plan(m);
  }
  scancell::status_t s{};
  s.daemon_state = p.state == JobState::faulted ? "faulted" : "busy";
  s.job_id = p.job;
  s.job_state = to_string(p.state);
  s.view = p.view;
  s.views = p.views;
  s.estimated_coverage = p.estimated;
  s.measured_coverage = p.measured;
  telemetry_->status(s);
}

void Daemon::publish_status() {
  Progress p;
  {
    std::lock_guard<std::mutex> lock(events_mu_);
    p = last_;
  }
  scancell::status_t s{};
  const std::int64_t cur = current_;
  s.daemon_state = !running_ ? "stopping" : cur ? "busy" : io_->positioner.estop_latched() ? "faulted" : "idle";
  s.job_id = cur ? cur : 0;
  s.job_state = cur ? to_string(p.state) : "";
  s.view = cur ? p.view : 0;
  s.views = cur ? p.views : 0;
  s.estimated_coverage = cur ? p.estimated : 0.0;
  s.measured_coverage = cur ? p.measured : 0.0;
  std::lock_guard<std::mutex> lock(telemetry_mu_);
  telemetry_->status(s);
}

void Daemon::publish_axes() {
  scancell::axis_state_t m{};
  for (const auto& n : io_->positioner.names()) {
    drivers::AxisState st;
    try {
      st = io_->positioner.axis(n).state();
    } catch (const drivers::DriverError& e) {
      st.faulted = true;
      st.fault_code = 0xFFFF;
    }
    m.name.push_back(n);
    m.position.push_back(st.position);
    m.moving.push_back(st.moving);
    m.fault.push_back(static_cast<std::int16_t>(st.faulted ? (st.fault_code ? st.fault_code : 1) : 0));
  }
  std::lock_guard<std::mutex> lock(telemetry_mu_);
  telemetry_->axes(m);
}

namespace {

/// A control request's job, or a refusal naming the command and the id.
JobRecord job_of(Journal& journal, const json& req, const std::string& cmd) {
  const std::int64_t id = req["job"].get<std::int64_t>();
  try {
    return journal.job(id);
  } catch (const JournalError&) {
    throw std::invalid_argument(cmd + ": no job " + std::to_string(id));
  }
}

json job_json(const JobRecord& j) {
  json o = {{"job", j.id}, {"state", to_string(j.state)}, {"mesh", j.mesh_path}, {"cause", j.cause}};
  if (!j.result_json.empty()) o["result"] = json::parse(j.result_json);
  return o;
}

}  // namespace

json Daemon::handle(const json& req, const std::function<bool(const json&)>& send) {
  const std::string cmd = req["cmd"];
  if (cmd == "submit") return submit(req);
  if (cmd == "status") return status(req);
  if (cmd == "record") return record(req);
  if (cmd == "list") {
    json a = json::array();
    for (const auto& j : journal_->jobs(100)) a.push_back(job_json(j));
    return {{"jobs", a}};
  }
  if (cmd == "watch") return watch(req, send);
  if (cmd == "pause" || cmd == "abort") return pause_or_abort(req, cmd);
  if (cmd == "resume") return resume(req);
  if (cmd == "continue") return continue_setup(req);
  if (cmd == "calibrate") {
    const std::string kind = req["kind"].get<std::string>();
    check_calibration_kind(kind);
    const std::int64_t id = journal_->create_job("calibration:" + kind, json({{"calibrate", kind}}).dump());
    wake_.notify_all();
    return {{"job", id}, {"state", "queued"}, {"kind", kind}};
  }
  if (cmd == "reload") return reload();
  throw std::invalid_argument("unknown command '" + cmd + "'");
}

json Daemon::submit(const json& req) {
  JobRequest r;
  r.mesh = client_file(req, "mesh", config_.allowed_dirs);
  r.spec = client_file(req, "spec", config_.allowed_dirs);
  r.settings = client_file(req, "settings", config_.allowed_dirs);
  r.truth = client_file(req, "truth", config_.allowed_dirs);
  r.fit_mm = req.value("fit_mm", 0.0);
  if (req.contains("bbox_mm")) r.bbox_mm = Eigen::Vector3d(req["bbox_mm"][0].get<double>(), req["bbox_mm"][1].get<double>(), req["bbox_mm"][2].get<double>());
  if (r.bbox_mm && r.mesh.empty() && r.truth.empty() && config_.scanner_driver == "sim")
    throw std::invalid_argument("submit: a bounding-box job on the simulated scanner needs 'truth' (what stands on the table)");
  if (req.contains("rough_vertices")) {
    const auto n = req["rough_vertices"].get<std::int64_t>();
    r.rough_vertices = static_cast<std::size_t>(std::max<std::int64_t>(n, 0));  // validate_request checks the range
  }
  r.placement = req.value("placement", std::string());
  if (req.contains("setups")) {
    // An integer (control's schema), read wide so that no value wraps into the range validate_request checks.
    const auto n = req["setups"].get<std::int64_t>();
    r.setups = static_cast<int>(std::clamp<std::int64_t>(n, std::numeric_limits<int>::min(), std::numeric_limits<int>::max()));
  }
  try {
    validate_request(r, &shutting_down_);
  } catch (const scancell::MeshError& e) {
    throw std::invalid_argument(std::string("submit: mesh refused: ") + e.what());
  } catch (const scancell::ConfigError& e) {
    throw std::invalid_argument(std::string("submit: config refused: ") + without_content(e.what()));
  }
  const std::string what = r.bbox_mm ? "bbox:" + std::to_string(r.bbox_mm->x()) + "x" + std::to_string(r.bbox_mm->y()) + "x" +
                                            std::to_string(r.bbox_mm->z())
                                      : r.mesh;
  const std::int64_t id = journal_->create_job(what, r.to_json().dump());
  wake_.notify_all();
  return {{"job", id}, {"state", "queued"}};
}

json Daemon::status(const json& req) {
  if (req.contains("job")) {
    const JobRecord j = job_of(*journal_, req, "status");
    json o = job_json(j);
    std::lock_guard<std::mutex> lock(events_mu_);
    if (last_.job == j.id) o["progress"] = progress_json(last_);
    return o;
  }
  const std::int64_t cur = current_;
  json o = {{"daemon", cur ? "busy" : "idle"}, {"job", cur}};
  {
    std::lock_guard<std::mutex> lock(config_mu_);
    o["calibration"] = config_.calibration_applied;
  }
  std::lock_guard<std::mutex> lock(events_mu_);
  if (cur && last_.job == cur) o["progress"] = progress_json(last_);
  return o;
}

/// What a job did, from the journal: its events, and per plan round the views (axis targets, poses) and
/// the stored scans (absolute paths; a note where one does not count). scancellctl export copies it out.
json Daemon::record(const json& req) {
  const JobRecord j = job_of(*journal_, req, "record");
  json plans = json::array();
  for (const auto& [plan, round] : journal_->plan_rounds(j.id)) {
    json views = json::array(), scans = json::array();
    for (const auto& v : journal_->views(plan)) views.push_back(json::parse(v.pose_json));
    for (const auto& s : journal_->scans(plan))
      scans.push_back({{"view", s.view}, {"file", (journal_->data_dir() / s.file).string()}, {"bytes", s.bytes}, {"note", s.note}});
    plans.push_back({{"plan", plan}, {"round", round}, {"info", json::parse(journal_->plan_info(plan))}, {"views", views}, {"scans", scans}});
  }
  json o = job_json(j);
  o["request"] = json::parse(j.request_json);
  o["events"] = journal_->events(j.id);
  o["plans"] = plans;
  return o;
}

json Daemon::watch(const json& req, const std::function<bool(const json&)>& send) {
  const JobRecord j = job_of(*journal_, req, "watch");
  std::uint64_t seen = 0;
  {
    std::lock_guard<std::mutex> lock(events_mu_);
    seen = next_seq_ - 1;
    if (last_.job == j.id) send(progress_json(last_));
  }
  JobState state = j.state;
  while (running_ && !ends_watch(state)) {
    std::vector<Progress> fresh;
    {
      std::unique_lock<std::mutex> lock(events_mu_);
      events_cv_.wait_for(lock, 250ms, [&] { return !running_ || (!events_.empty() && events_.back().first > seen); });
      for (const auto& [seq, p] : events_)
        if (seq > seen) {
          seen = seq;
          if (p.job == j.id) fresh.push_back(p);
        }
    }
    for (const auto& p : fresh)
      if (!send(progress_json(p))) return {{"job", j.id}, {"state", to_string(state)}};
    state = journal_->job(j.id).state;
  }
  return job_json(journal_->job(j.id));
}

json Daemon::pause_or_abort(const json& req, const std::string& cmd) {
  std::lock_guard<std::mutex> claim(claim_mu_);  // see job_loop: the job is claimed, or not yet, not between
  const JobRecord j = job_of(*journal_, req, cmd);
  // The runner journals a job's end (aborted, paused, awaiting the operator, …) a moment before it lets go
  // of current_: a request in between goes by the journal. A raised stop_ would be a reply of "at the next
  // safe point" that nothing acts on (the next claim clears it), so an abort would be lost and a second
  // abort accepted (seen in daemon_cli with ctest -j3).
  if (current_ == j.id && (active(j.state) || j.state == JobState::queued)) {
    stop_ = static_cast<int>(cmd == "pause" ? StopRequest::pause : StopRequest::abort);
    return {{"job", j.id}, {"state", to_string(j.state)}, {"note", cmd + " at the next safe point (between moves or profiles)"}};
  }
  if (finished(j.state)) throw std::invalid_argument(cmd + ": job " + std::to_string(j.id) + " is already " + to_string(j.state));
  if (cmd == "pause" && j.state != JobState::queued)
    throw std::invalid_argument("pause: job " + std::to_string(j.id) + " is " + to_string(j.state) + ", not queued or running");
  journal_->set_state(j.id, cmd == "pause" ? JobState::paused : JobState::aborted, "by request");
  report({j.id, cmd == "pause" ? JobState::paused : JobState::aborted, 0, 0, 0, 0, 0, 0, std::string(cmd == "pause" ? "paused" : "aborted") + ": by request", "", ""});
  return {{"job", j.id}, {"state", cmd == "pause" ? "paused" : "aborted"}};
}

json Daemon::resume(const json& req) {
  const JobRecord j = job_of(*journal_, req, "resume");
  if (j.state != JobState::paused && j.state != JobState::faulted)
    throw std::invalid_argument("resume: job " + std::to_string(j.id) + " is " + to_string(j.state) + ", not paused or faulted");
  if (j.state == JobState::faulted) {
    if (current_ != 0) throw std::invalid_argument("resume: job " + std::to_string(current_.load()) + " is running; resume the faulted job after it");
    // The operator's resume is the authority to clear drive faults and the e-stop latch.
    if (io_->interlock) io_->interlock->reset();  // refused while the e-stop is still pressed
    else io_->positioner.reset_estop();
    bring_up(*io_, config_.models.cell, config_.home_timeout);
  }
  journal_->set_state(j.id, JobState::queued, "resumed");
  wake_.notify_all();
  return {{"job", j.id}, {"state", "queued"}};
}

json Daemon::continue_setup(const json& req) {
  const JobRecord j = job_of(*journal_, req, "continue");
  if (j.state != JobState::awaiting_operator)
    throw std::invalid_argument("continue: job " + std::to_string(j.id) + " is " + to_string(j.state) +
                                ", not awaiting the operator (continue confirms that the part was turned over as a setup asked)");
  journal_->set_state(j.id, JobState::queued, "continued: the operator turned the part over");
  report({j.id, JobState::queued, 0, 0, 0, 0, 0, 0, "queued: continued (the operator turned the part over)", "", ""});
  wake_.notify_all();
  return {{"job", j.id}, {"state", "queued"}};
}

json Daemon::reload() {
  std::lock_guard<std::mutex> lock(config_mu_);
  std::vector<std::string> changes;
  try {
    changes = reload_calibration(config_);
  } catch (const scancell::ConfigError& e) {
    throw std::invalid_argument(std::string("reload refused, the previous calibration stays in force: ") + e.what());
  }
  std::lock_guard<std::mutex> tl(telemetry_mu_);
  telemetry_->progress(0, changes.empty() ? "reload: no change" : "reload: " + std::to_string(changes.size()) + " changes");
  return {{"changes", changes}, {"applies_to", "jobs started from now on"}};
}

int Daemon::run() {
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGTERM);
  sigaddset(&set, SIGINT);
  sigaddset(&set, SIGHUP);
  notifier_.ready("scancelld ready: " + config_.socket_path.string());
  std::cerr << "scancelld: ready; control socket " << config_.socket_path << ", data " << config_.data_dir << ", LCM "
            << config_.lcm_url << std::endl;
  auto last_status = std::chrono::steady_clock::now() - 1h, last_axes = last_status, last_dog = last_status;
  const auto dog = notifier_.watchdog_period() / 2;
  while (true) {
    timespec ts{0, 50 * 1000 * 1000};
    const int sig = ::sigtimedwait(&set, nullptr, &ts);
    if (sig == SIGTERM || sig == SIGINT) break;
    if (sig == SIGHUP) {
      try {
        const json r = handle({{"cmd", "reload"}}, [](const json&) { return true; });
        std::cerr << "scancelld: SIGHUP reload: " << r["changes"].dump() << std::endl;
      } catch (const std::exception& e) {
        std::cerr << "scancelld: SIGHUP reload refused: " << e.what() << std::endl;
      }
    }
    const auto now = std::chrono::steady_clock::now();
    if (dog.count() > 0 && now - last_dog >= dog) {
      notifier_.watchdog();
      last_dog = now;
    }
    if (now - last_status >= 1s) {
      publish_status();
      last_status = now;
    }
    if (now - last_axes >= 200ms) {
      publish_axes();
      last_axes = now;
    }
  }
  std::cerr << "scancelld: stopping at the next safe point" << std::endl;
  notifier_.stopping("stopping: finishing the current move or profile, then parking");
  stop_job_thread();
  try {
    park(*io_, config_.models.cell, config_.jobs.move_timeout);
  } catch (const std::exception& e) {
    std::cerr << "scancelld: park failed: " << e.what() << std::endl;
  }
  control_.reset();
  journal_.reset();
  std::cerr << "scancelld: stopped" << std::endl;
  return 0;
}

}  // namespace scancell::daemon
