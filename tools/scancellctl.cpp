// scancellctl: the command-line client of scancelld's control socket (docs/daemon.md).
//   scancellctl [--socket PATH] [--json] submit --mesh FILE [--fit-mm L] [--spec FILE] [--settings FILE]
//                                          [--truth FILE] [--rough-vertices N] [--placement auto|as_given] [--watch]
//   scancellctl status [JOB] | list | watch JOB | pause JOB | resume JOB | abort JOB | continue JOB | reload
//   scancellctl export JOB --out DIR [--with-scans]
//   scancellctl calibrate sensor|turntable_axis|positioner [--watch]
// Exit codes: 0 success (watch: the job is done), 1 the daemon refused the request (export: or the copy failed), 2 usage, 3 cannot reach
// the daemon; watch: 10 stalled, 11 aborted, 12 faulted, 13 paused, 14 failed (a calibration on bad data),
// 15 awaiting the operator (turn the part over as the job says, then continue).
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <optional>
#include <string>
#include <vector>

#include "common/timing.hpp"
#include "daemon/job_limits.hpp"
#include "planner/core/rough_model_limits.hpp"

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

using nlohmann::json;

namespace {

class Connection {
 public:
  explicit Connection(const std::string& path) {
    fd_ = ::socket(AF_UNIX, SOCK_STREAM, 0);
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    if (fd_ < 0 || path.size() >= sizeof addr.sun_path) throw std::runtime_error(path + ": bad socket path");
    std::memcpy(addr.sun_path, path.c_str(), path.size() + 1);
    if (::connect(fd_, reinterpret_cast<sockaddr*>(&addr), sizeof addr) < 0)
      throw std::runtime_error(path + ": " + std::strerror(errno) + " (is scancelld running? --socket or SCANCELL_SOCKET)");
  }
  ~Connection() { ::close(fd_); }
  void send(const json& j) {
    const std::string s = j.dump() + "\n";
    for (std::size_t off = 0; off < s.size();) {
      const ssize_t n = ::send(fd_, s.data() + off, s.size() - off, MSG_NOSIGNAL);
      if (n <= 0) throw std::runtime_error(std::string("send: ") + std::strerror(errno));
      off += static_cast<std::size_t>(n);
    }
  }
  /// The next line as JSON; throws when the daemon hangs up.
  json receive() {
    while (true) {
      const auto nl = buf_.find('\n');
      if (nl != std::string::npos) {
        const std::string line = buf_.substr(0, nl);
        buf_.erase(0, nl + 1);
        return json::parse(line);
      }
      char chunk[4096];
      const ssize_t n = ::recv(fd_, chunk, sizeof chunk, 0);
      if (n <= 0) throw std::runtime_error("the daemon closed the connection");
      buf_.append(chunk, static_cast<std::size_t>(n));
    }
  }

 private:
  int fd_ = -1;
  std::string buf_;
};

std::string absolute(const std::string& p) { return p.empty() ? p : std::filesystem::absolute(p).lexically_normal().string(); }

int outcome_code(const std::string& state) {
  if (state == "done") return 0;
  if (state == "stalled") return 10;
  if (state == "aborted") return 11;
  if (state == "faulted") return 12;
  if (state == "paused") return 13;
  if (state == "failed") return 14;
  if (state == "awaiting_operator") return 15;
  return 1;
}

std::string bar(double fraction, int width) {
  const int full = static_cast<int>(std::lround(std::clamp(fraction, 0.0, 1.0) * width));
  return std::string(static_cast<std::size_t>(full), '#') + std::string(static_cast<std::size_t>(width - full), '.');
}

void print_result(const json& reply, double seconds) {
  const json r = reply.value("result", json::object());
  std::printf("\njob %lld: %s\n", static_cast<long long>(reply.value("job", 0)), reply.value("state", "?").c_str());
  if (!reply.value("cause", std::string()).empty()) std::printf("  %s\n", reply["cause"].get<std::string>().c_str());
  if (r.contains("kind")) {  // a calibration run
    if (r.contains("file")) std::printf("  %-34s %s\n", "result file", r["file"].get<std::string>().c_str());
    if (r.contains("values"))
      for (const auto& [name, v] : r["values"].items())
        std::printf("  %-34s %s ± %s (95 %%)\n", name.c_str(), v["value"].dump().c_str(), v["ci95"].dump().c_str());
    if (r.contains("changes"))
      for (const auto& c : r["changes"]) std::printf("  changed: %s\n", c.get<std::string>().c_str());
    if (r.contains("error")) std::printf("  %-34s %s\n", "error", r["error"].get<std::string>().c_str());
    return;
  }
  auto num = [&](const char* k) { return r.contains(k) ? r[k].get<double>() : std::nan(""); };
  if (r.value("state", std::string()) == "awaiting_operator") {  // between setups: what the operator is to do
    std::printf("  %-34s %d, measured %.4f of the rough model\n", "setup done", r.value("setup", 0), num("measured_coverage"));
    std::printf("  %-34s %s\n", "operator", r.value("instruction", std::string()).c_str());
    return;
  }
  std::printf("  %-34s %d\n", "views executed", r.value("views", 0));
  std::printf("  %-34s %d\n", "plan rounds", r.value("rounds", 0));
  if (r.contains("cell_time_s"))
    std::printf("  %-34s %.0f s (moves %.0f s, sweeps %.0f s)\n", "cell time at the cell's speeds", num("cell_time_s"), num("cell_move_s"),
                num("cell_scan_s"));
  std::printf("  %-34s %.4f\n", "estimated coverage (planner)", num("estimated_coverage"));
  std::printf("  %-34s %.4f\n", "measured coverage (rough model)", num("measured_coverage"));
  if (r.contains("rough_model")) {
    const json& q = r["rough_model"];
    std::printf("  %-34s Hausdorff %.2f mm; seen part %.3f mm mean, normals %.1f deg mean (ground truth)\n", "fused rough model",
                q.value("hausdorff_mm", NAN), q.value("seen_rough_to_fine_mean_mm", NAN), q.value("seen_normal_error_mean_rad", NAN) * 180.0 / M_PI);
  }
  if (r.contains("verified_coverage"))
    std::printf("  %-34s %.4f  (true positions, samples within 3 x the precision spec)\n", "verified coverage (rough model)", num("verified_coverage"));
  if (r.contains("sample_normal_error_rms_mm"))
    std::printf("  %-34s %.3f mm RMS across the surface (%.3f mm in 3-D), %.2f %% beyond 3 x the precision spec\n",
                "stored samples vs true hit points", num("sample_normal_error_rms_mm"), num("sample_error_rms_mm"), 100.0 * num("samples_off_spec"));
  if (r.contains("verified_mv"))
    std::printf("  %-34s %.4f  (against %s)\n", "verified m_v (ground truth)", num("verified_mv"), r["verified_against"].get<std::string>().c_str());
  std::printf("  %-34s %.1f mm2 in %d rows\n", "not measured, measurable", num("open_area_mm2"), r.value("open_rows", 0));
  std::printf("  %-34s %d rows\n", "unmeasurable in this cell", r.value("unmeasurable_rows", 0));
  if (r.contains("needs_attention_rows"))
    std::printf("  %-34s %.1f mm2 in %d rows (predicted measurable, never measured: retired)\n", "needs attention",
                num("needs_attention_area_mm2"), r.value("needs_attention_rows", 0));
  if (r.contains("round_gains")) {
    std::printf("  %-34s", "gain per round, predicted/realized");
    for (const auto& g : r["round_gains"])
      std::printf(" %d: %.0f/%.0f mm2%s", g.value("round", 0), g.value("predicted_gain_mm2", 0.0), g.value("realized_gain_mm2", 0.0),
                  g.value("under_20_percent", false) ? " (under 20 %)" : "");
    std::printf("\n");
  }
  if (seconds > 0.0) std::printf("  %-34s %.1f s\n", "watched for", seconds);
  if (r.contains("coverage_png")) std::printf("  %-34s %s\n", "coverage picture", r["coverage_png"].get<std::string>().c_str());
  if (r.contains("cloud"))
    std::printf("  %-34s %s (%zu samples)\n", "registered cloud", r["cloud"].get<std::string>().c_str(), r.value("cloud_points", std::size_t{0}));
  if (r.contains("model"))
    std::printf("  %-34s %s (%zu triangles, %zu open edges)\n", "surface model", r["model"].get<std::string>().c_str(),
                r.value("model_triangles", std::size_t{0}), r.value("model_open_edges", std::size_t{0}));
  if (r.contains("report"))
    std::printf("  %-34s %s (cloud %.4f mm RMS, model p95 %.4f mm from the reference)\n", "inspection report",
                r["report"].get<std::string>().c_str(), num("cloud_deviation_rms_mm"), num("model_deviation_p95_mm"));
  if (r.contains("placement"))
    std::printf("  %-34s %s\n", "placement", r["placement"].value("reason", std::string()).c_str());
  if (r.contains("next_setup"))
    std::printf("  %-34s %s%s%s\n", "next setup", r["next_setup"].value("reason", r["next_setup"].value("error", std::string())).c_str(),
                r["next_setup"].contains("picture") ? "; picture " : "", r["next_setup"].value("picture", std::string()).c_str());
  if (r.contains("setups"))
    for (const auto& st : r["setups"]) {
      std::printf("  %-34s %d views", ("setup " + std::to_string(st.value("setup", 0))).c_str(), st.value("views", 0));
      if (st.contains("measured_coverage_before")) std::printf(", from %.4f of the rough model measured", st.value("measured_coverage_before", 0.0));
      if (st.contains("verified_mv_at_end")) std::printf(", verified m_v %.4f at its end (ground truth)", st.value("verified_mv_at_end", 0.0));
      if (st.contains("resting_pose")) std::printf(", resting pose %d", st.value("resting_pose", 0));
      if (st.contains("alignment")) {
        const json& a = st["alignment"];
        std::printf(", aligned: residual %.3f mm, turned %.2f deg, shifted %.2f mm", a.value("rms_mm", NAN), a.value("turn_rad", NAN) * 180.0 / M_PI,
                    a.value("shift_mm", NAN));
        if (a.contains("sim_residual_mm"))
          std::printf(" (simulation: placement found to %.3f mm, %.3f deg)", a.value("sim_residual_mm", NAN), a.value("sim_residual_deg", NAN));
      }
      std::printf("\n");
    }
  if (r.contains("unmeasured_file")) std::printf("  %-34s %s\n", "unmeasured rows", r["unmeasured_file"].get<std::string>().c_str());
}

int watch(Connection& c, std::int64_t job, bool as_json) {
  const auto t0 = std::chrono::steady_clock::now();
  c.send({{"cmd", "watch"}, {"job", job}});
  const bool tty = ::isatty(STDOUT_FILENO) && !as_json;
  std::string last_line;
  while (true) {
    const json m = c.receive();
    if (m.contains("ok")) {  // the final reply: the job's outcome
      if (!m["ok"].get<bool>()) {
        std::cerr << "scancellctl: " << m.value("error", "refused") << "\n";
        return 1;
      }
      const double secs = scancell::seconds_since(t0);
      if (as_json) std::cout << m.dump() << std::endl;
      else print_result(m, secs);
      return outcome_code(m.value("state", ""));
    }
    if (as_json) {
      std::cout << m.dump() << std::endl;
      continue;
    }
    const int views = m.value("views", 0), view = m.value("view", 0);
    char line[256];
    std::snprintf(line, sizeof line, "[%s] round %d view %d/%d  measured %.3f  est %.3f  ETA %3.0f s  %-10s",
                  bar(m.value("measured_coverage", 0.0), 30).c_str(), m.value("round", 0), view, views,
                  m.value("measured_coverage", 0.0), m.value("estimated_coverage", 0.0), m.value("eta_s", 0.0),
                  m.value("state", "").c_str());
    if (tty) {
      std::printf("\r%s", line);
      std::fflush(stdout);
      const std::string ev = m.value("event", "");
      if (ev.find("stored") == std::string::npos && ev.find(": moving") == std::string::npos &&
          ev.find(": scanning") == std::string::npos && !ev.empty())
        std::printf("\n  %s\n", ev.c_str());
    } else {
      const std::string ev = m.value("event", "");
      if (ev.find(": moving") != std::string::npos || ev.find(": scanning") != std::string::npos) continue;
      std::printf("%s  %s\n", line, ev.c_str());
    }
  }
}

/// Every string in `v` (at `key`) naming an existing regular file by its absolute path.
void named_files(const json& v, const std::string& key, std::vector<std::pair<std::string, std::string>>& out) {
  if (v.is_object()) {
    for (auto it = v.begin(); it != v.end(); ++it) named_files(it.value(), key.empty() ? it.key() : key + "." + it.key(), out);
  } else if (v.is_array()) {
    for (std::size_t k = 0; k < v.size(); ++k) named_files(v[k], key + "[" + std::to_string(k) + "]", out);
  } else if (v.is_string()) {
    const std::string s = v.get<std::string>();
    std::error_code ec;
    if (!s.empty() && s[0] == '/' && std::filesystem::is_regular_file(s, ec)) out.emplace_back(key, s);
  }
}

void write_text(const std::filesystem::path& file, const std::string& text) {
  std::ofstream f(file, std::ios::binary | std::ios::trunc);
  if (!(f << text) || !f.flush()) throw std::filesystem::filesystem_error("cannot write", file, std::make_error_code(std::errc::io_error));
}

/// scancellctl export: a finished job's product, plans and events copied into `dir` (docs/daemon.md).
int export_job(Connection& c, std::int64_t job, const std::filesystem::path& dir, bool with_scans) {
  namespace fs = std::filesystem;
  c.send({{"cmd", "record"}, {"job", job}});
  json rec = c.receive();
  if (!rec.value("ok", false)) {
    std::cerr << "scancellctl: " << rec.value("error", "refused") << "\n";
    return 1;
  }
  const std::string state = rec.value("state", "");
  if (state != "done" && state != "stalled" && state != "aborted" && state != "failed") {
    std::cerr << "scancellctl: job " << job << " is " << state
              << ": its product is written when it ends (wait for it, or resume or abort it), then export it\n";
    return 1;
  }
  std::error_code ec;
  if (fs::exists(dir, ec) && !(fs::is_directory(dir, ec) && fs::is_empty(dir, ec))) {
    std::cerr << "scancellctl: " << dir.string() << " exists and is not an empty directory: export into a new one\n";
    return 1;
  }
  try {
    fs::create_directories(dir);
    std::vector<std::pair<std::string, std::string>> files;
    if (rec.contains("result")) named_files(rec["result"], "", files);
    json exported = json::object();
    for (const auto& [key, path] : files) {
      std::string name = fs::path(path).filename().string();
      if (fs::exists(dir / name)) name = key + "_" + name;
      fs::copy_file(path, dir / name);
      exported[key] = name;
    }
    std::size_t scans = 0;
    if (with_scans) {
      fs::create_directories(dir / "scans");
      for (auto& p : rec["plans"]) {
        const int round = p["round"].get<int>();
        for (auto& s : p["scans"]) {
          const std::string name = (round < 0 ? std::string("rough") : "round" + std::to_string(round)) + "_view" +
                                   std::to_string(s["view"].get<int>()) + ".ply";
          fs::copy_file(s["file"].get<std::string>(), dir / "scans" / name);
          s["exported"] = "scans/" + name;
          ++scans;
        }
      }
    }
    std::string events;
    for (const auto& e : rec["events"]) events += e.get<std::string>() + "\n";
    write_text(dir / "events.txt", events);
    write_text(dir / "plans.json", rec["plans"].dump(2) + "\n");
    rec.erase("ok");
    rec.erase("events");
    rec.erase("plans");
    rec["exported"] = exported;
    write_text(dir / "job.json", rec.dump(2) + "\n");
    std::cout << "job " << job << " (" << state << ") exported to " << dir.string() << ": " << files.size() << " files"
              << (with_scans ? ", " + std::to_string(scans) + " range images" : std::string()) << ", job.json, plans.json, events.txt\n";
    return 0;
  } catch (const fs::filesystem_error& e) {
    std::cerr << "scancellctl: export: " << e.what() << "\n";
    return 1;
  }
}

}  // namespace

namespace {

/// Every option of every subcommand: CLI11 writes into it, request() reads it.
struct Args {
  std::string socket, mesh, spec, settings, truth, placement, out_dir, kind;
  bool as_json = false, then_watch = false, with_scans = false;
  double fit_mm = 0.0;
  int rough_vertices = 0, setups = 0;
  std::vector<double> bbox;
  std::int64_t job = 0;
};

void add_submit(CLI::App& app, Args& a) {
  auto* submit = app.add_subcommand("submit", "queue a scan job on an object's rough model");
  auto* mesh_opt = submit->add_option("--mesh", a.mesh, "rough model of the object (OFF, PLY, OBJ, STL)")->check(CLI::ExistingFile);
  auto* bbox_opt = submit->add_option("--bbox-mm", a.bbox, "instead of a mesh: the object's size X Y Z (mm); the job starts with a rough scan")
                       ->expected(3)->delimiter(',');
  mesh_opt->excludes(bbox_opt);
  submit->add_option("--fit-mm", a.fit_mm, "scale so the longest side is this many mm (default: the mesh is in mm)")->check(CLI::PositiveNumber);
  submit->add_option("--spec", a.spec, "model specification (YAML; default: the daemon's)")->check(CLI::ExistingFile);
  submit->add_option("--settings", a.settings, "planner settings (YAML; default: the daemon's)")->check(CLI::ExistingFile);
  submit->add_option("--truth", a.truth, "simulation: the object actually on the table (default: the mesh)")->check(CLI::ExistingFile);
  submit->add_option("--rough-vertices", a.rough_vertices, "rough-model size (rows of the measurability matrix)")->check(CLI::Range(scancell::planner::kMinRoughVertices, scancell::planner::kMaxRoughVertices));
  submit->add_option("--placement", a.placement,
                     "how the object rests on the plate: auto (plan its stable resting poses, keep the best; the result says "
                     "how to place it) or as_given (default: the daemon's settings)")
      ->check(CLI::IsMember({"auto", "as_given"}));
  submit->add_option("--setups", a.setups,
                     "setups the job may use: after the first, with enough left unmeasured, it waits for the part to be "
                     "turned over as it says (then: scancellctl continue JOB) (default: the daemon's jobs.max_setups)")
      ->check(CLI::Range(1, scancell::daemon::kMaxSetups));
  submit->add_flag("--watch", a.then_watch, "then watch the job to its end");
}

/// status, list, watch, pause, resume, abort, continue, reload, export and calibrate.
void add_job_commands(CLI::App& app, Args& a) {
  auto* status = app.add_subcommand("status", "daemon status, or one job's");
  status->add_option("job", a.job, "job id");
  app.add_subcommand("list", "the latest jobs");
  auto* w = app.add_subcommand("watch", "live progress of a job; exits with its outcome");
  w->add_option("job", a.job, "job id")->required();
  const char* names[4] = {"pause", "resume", "abort", "continue"};
  const char* help[4] = {"pause at the next safe point", "continue a paused or faulted job (clears drive faults)", "end a job",
                         "confirm that the part was turned over as the job's next setup asks (a job awaiting the operator)"};
  for (int k = 0; k < 4; ++k) app.add_subcommand(names[k], help[k])->add_option("job", a.job, "job id")->required();
  app.add_subcommand("reload", "re-read the calibration (sensor and cell models)");
  auto* exp = app.add_subcommand("export", "copy a finished job's product (cloud, model, report, pictures), plans and events into a directory");
  exp->add_option("job", a.job, "job id")->required();
  exp->add_option("--out", a.out_dir, "a new or empty directory")->required();
  exp->add_flag("--with-scans", a.with_scans, "also the stored range images (scans/, what scancell fuse reads)");
  auto* calibrate = app.add_subcommand("calibrate", "run a calibration on the cell (its target must be on the table)");
  calibrate->add_option("kind", a.kind, "sensor | turntable_axis | positioner")->required()->check(CLI::IsMember({"sensor", "turntable_axis", "positioner"}));
  calibrate->add_flag("--watch", a.then_watch, "then watch the run to its end");
}

/// The control request for `cmd`, or nothing after saying why (a submit needs a mesh or a box).
std::optional<json> request(const std::string& cmd, const Args& a) {
  json req = {{"cmd", cmd}};
  if (cmd == "submit") {
    if (a.mesh.empty() == a.bbox.empty()) {
      std::cerr << "scancellctl: submit needs --mesh or --bbox-mm, one of them\n";
      return std::nullopt;
    }
    if (!a.mesh.empty()) req["mesh"] = absolute(a.mesh);
    if (!a.bbox.empty()) req["bbox_mm"] = a.bbox;
    if (a.fit_mm > 0.0) req["fit_mm"] = a.fit_mm;
    if (!a.spec.empty()) req["spec"] = absolute(a.spec);
    if (!a.settings.empty()) req["settings"] = absolute(a.settings);
    if (!a.truth.empty()) req["truth"] = absolute(a.truth);
    if (a.rough_vertices > 0) req["rough_vertices"] = a.rough_vertices;
    if (!a.placement.empty()) req["placement"] = a.placement;
    if (a.setups > 0) req["setups"] = a.setups;
  } else if (cmd == "calibrate") {
    req["kind"] = a.kind;
  } else if (cmd == "status") {
    if (a.job > 0) req["job"] = a.job;
  } else if (cmd != "list" && cmd != "reload") {
    req["job"] = a.job;
  }
  return req;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"scancellctl: control scancelld (submit, status, list, watch, pause, resume, abort, continue, reload, export)"};
  Args a;
  const char* env = std::getenv("SCANCELL_SOCKET");
  a.socket = env ? env : "/run/scancell/control.sock";
  app.add_option("--socket", a.socket, "control socket of scancelld (default $SCANCELL_SOCKET or /run/scancell/control.sock)");
  app.add_flag("--json", a.as_json, "print the daemon's replies as JSON lines");
  app.require_subcommand(1);
  add_submit(app, a);
  add_job_commands(app, a);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }

  try {
    Connection c(a.socket);
    const std::string cmd = app.get_subcommands().front()->get_name();
    if (cmd == "watch") return watch(c, a.job, a.as_json);
    if (cmd == "export") return export_job(c, a.job, a.out_dir, a.with_scans);
    const std::optional<json> req = request(cmd, a);
    if (!req) return 2;
    c.send(*req);
    const json reply = c.receive();
    if (!reply.value("ok", false)) {
      std::cerr << "scancellctl: " << reply.value("error", "refused") << "\n";
      return 1;
    }
    if (a.as_json || (cmd != "submit" && cmd != "calibrate")) std::cout << reply.dump(a.as_json ? -1 : 2) << std::endl;
    else std::cout << "job " << reply["job"] << " queued" << std::endl;
    if ((cmd == "submit" || cmd == "calibrate") && a.then_watch) return watch(c, reply["job"].get<std::int64_t>(), a.as_json);
    return 0;
  } catch (const std::runtime_error& e) {
    std::cerr << "scancellctl: " << e.what() << "\n";
    return 3;
  } catch (const json::exception& e) {
    std::cerr << "scancellctl: unreadable reply from the daemon: " << e.what() << "\n";
    return 1;
  }
}
