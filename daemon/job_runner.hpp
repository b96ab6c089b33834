#pragma once
// The 3M loop of one job on the cell (thesis table 3.1): plan from the rough model, execute each view (move,
// scan, store), update the measured coverage on the rough model from the acquired samples, verify, replan
// for what is still unmeasured, until the spec is met (done) or a replan adds nothing (stalled).
//
// Every transition is journalled before the action it starts, so a job resumes after a crash, a SIGTERM or a
// fault at its first view without a stored scan: the rough model is rebuilt from the same mesh and options
// (deterministic), the measured coverage from the stored scans. The runner knows nothing of sockets or LCM:
// it reports through a callback and is stopped through a flag (the daemon composes the pieces).
#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "daemon/job_request.hpp"
#include "daemon/job_product.hpp"
#include "daemon/journal.hpp"
#include "daemon/phase_trace.hpp"
#include "drivers/axis.hpp"
#include "drivers/gpio.hpp"
#include "daemon/scan_heads.hpp"
#include "planner/kinematics/cell.hpp"
#include "planner/config.hpp"
#include "planner/reconstruction/measured_coverage.hpp"
#include "planner/plan.hpp"
#include "planner/reconstruction/registration.hpp"
#include "planner/reconstruction/rough_scan.hpp"
#include "planner/reconstruction/setup_alignment.hpp"

namespace scancell::daemon {

struct JobSettings {
  int max_rounds = 4;                              // plan rounds before a job that still lacks rows stalls
  /// The closed loop's evidence (issue 15): a row a round's views were predicted to measure and did not is
  /// down-weighted for the next plan (failed once) and, after `retire_after_failures` such rounds, retired:
  /// reported as needing attention, never chased again. A replan takes no view that gains (weighted so)
  /// under `min_gain_per_view_mm2`, and one whose predicted gain per view is under it is not executed: the
  /// job stops there.
  int retire_after_failures = 3;
  double failed_row_weight = 0.25;
  double min_gain_per_view_mm2 = 5.0;
  /// A replan predicts each open row by up to this many samples of its unfilled footprint cells, not by its
  /// vertex (planner/core/footprint.hpp): a view is credited with the row only when it is predicted to fill
  /// what the row lacks. 0: by the vertex, as the first round does.
  int footprint_samples = 8;
  /// Issue 20: a job that ends (done or stalled) with at least this much of the rough model unmeasured plans
  /// a second setup: the stable resting pose that lets the cell measure most of the rest, named in the
  /// result with a picture (next_setup.png). 0: never.
  double next_setup_min_area_mm2 = 100.0;
  /// Setups a job may use unless its request says (issue 20): with 2 or more, a setup that ends with the
  /// next-setup advice above waits for the operator (awaiting_operator) instead of ending the job.
  int max_setups = 1;
  /// Simulation: how far off the simulated operator puts the part down in a further setup, drawn uniformly
  /// per job and setup within ± these: a shift on the plate (mm) and a turn about the table axis (rad).
  double sim_placement_error_mm = 0.0;
  double sim_placement_error_rad = 0.0;
  /// Exploration views of a further setup (aligned to the model so far): turntable steps × elevations.
  planner::ExplorationOptions setup_exploration = [] {
    planner::ExplorationOptions o;
    o.table_steps = 6;
    o.tilts_rad = {0.75, 0.35};
    return o;
  }();
  planner::SetupAlignmentOptions setup_alignment;
  planner::CoverageOptions coverage;               // when a rough-model row counts as measured
  std::chrono::milliseconds move_timeout{60000};   // one positioning move
  double scan_speed_mm_s = 0.0;                    // sweep speed; 0: the cell's scan_speed_mm_s
  std::chrono::microseconds trigger_width{0};      // scanner trigger pulse width
  /// scanner.trigger_source: drive_compare — the sweep drive's position-compare output triggers the scanner
  /// (armed before each sweep, start + k·pitch), and each profile's pose is its compare position; daemon —
  /// the daemon polls the sweep axis and pulses the trigger line itself (software compare).
  bool drive_compare = false;
  /// Passes after a view's sweep for the rows it left without a profile (daemon/acquire): 0 keeps the holes.
  int fill_sweeps = 2;
  /// cloud.ply: one sample per cube of this side (mm); 0 keeps every spec-compliant sample. The model is
  /// fused from all of them either way.
  double cloud_spacing_mm = 0.0;
  int planner_threads = 0;
  bool register_views = true;                      // ICP each executed view against the model before counting it
  planner::IcpOptions icp = [] {
    planner::IcpOptions o;
    o.partial = true;  // a face-on view registers in what its shape fixes; the rest stays as positioned
    // The pose error bound (max_distance_mm) at the lever: 2.9°, 58× the demo cell's σ_a and 6× issue 9's
    // 0.5°. A view turned farther is a patch that does not fix its pose, refused rather than counted.
    o.max_turn_rad = o.max_distance_mm / o.lever_mm;
    return o;
  }();
  std::filesystem::path jobs_dir;                  // per-job outputs (coverage picture, unmeasured rows)
  planner::ExplorationOptions rough_scan;          // jobs that start from a bounding box
  /// How far off the registration target may be, mm: a submitted mesh is taken as the object (0); a fused
  /// rough model is off by a fraction of its voxel. Corrections are believed in proportion to the cell's
  /// pose-error model against this (planner::correction_weight).
  double fused_model_sigma_mm = 0.4;
  /// jobs.phase_trace_file: where the running job is, a line per change (daemon/phase_trace.hpp); empty: none.
  std::filesystem::path phase_trace_file;
};

/// The models a job plans and executes with (the daemon's configuration; defaults for spec and settings).
struct CellModels {
  planner::CellModel cell;
  planner::SensorModel sensor;
  planner::ModelSpec spec;
  planner::PlannerSettings settings;
};

struct Progress {
  std::int64_t job = 0;
  JobState state = JobState::queued;
  int round = 0;
  int view = 0, views = 0;       // 1-based view being executed, views in the round
  double estimated = 0.0;        // planner's estimate of the whole model's measurability after this round
  double measured = 0.0;         // measured coverage of the rough model so far
  double eta_s = 0.0;            // remaining time of the round, s
  std::string event;             // what just happened (empty for a plain progress tick)
  std::string fault_axis, fault_kind;  // set with state faulted: the axis (if any) and DriverError kind or "job"
};

enum class StopRequest : int { none = 0, pause = 1, abort = 2, shutdown = 3 };

class JobRunner {
 public:
  using Report = std::function<void(const Progress&)>;
  JobRunner(Journal& journal, const CellModels& models, drivers::Positioner& positioner, ScanHeadFactory heads,
            JobSettings settings, Report report);

  /// Runs or resumes `job` until it is done, stalled, aborted or faulted, or `stop` asks it to pause or to let
  /// the daemon shut down (then the job stays resumable). Returns the state the job is left in.
  JobState run(std::int64_t job, const std::atomic<int>& stop);

 private:
  struct Job;
  bool read_request(Job& j, const JobRecord& rec);
  std::optional<JobState> plan_first_round(Job& j, const std::atomic<int>& stop);
  void restore(Job& j, const std::vector<std::int64_t>& plans);
  nlohmann::json execute_round(Job& j, const std::vector<std::int64_t>& plans, const std::atomic<int>& stop);
  std::optional<JobState> close_or_replan(Job& j, std::int64_t plan, const nlohmann::json& info, const std::atomic<int>& stop);
  void journal_round(Job& j, std::int64_t plan, const nlohmann::json& info, const std::vector<nlohmann::json>& infos);
  nlohmann::json round_info(const Job& j, const planner::ViewPlan& p, int round, int setup, const std::vector<std::uint8_t>& measured) const;
  std::optional<JobState> replan(Job& j, const std::vector<std::uint8_t>& measured_now, const std::vector<std::uint8_t>& fails,
                                 const std::vector<std::uint8_t>& retired, std::size_t n_retired, std::size_t open,
                                 const std::string& summary, const std::atomic<int>& stop);
  void execute_view(Job& j, std::int64_t plan, const ViewRecord& v, const std::atomic<int>& stop);
  /// The rough scan of a job given a bounding box: exploration views, stored, fused into jobs/ID/rough.off.
  void rough_scan(Job& j, const std::atomic<int>& stop);
  /// The end of a job, or of a setup: with setups left and enough unmeasured for a next one (issue 20), the
  /// job waits for the operator to turn the part over (awaiting_operator); otherwise it finishes in `state`.
  JobState end_setup(Job& j, JobState state, const std::string& cause);
  /// A further setup the operator has confirmed: its exploration views (the part as the operator put it
  /// down), aligned to the model so far, then the setup's first plan, journalled. An end state if the
  /// alignment is refused or nothing is left to plan.
  std::optional<JobState> start_setup(Job& j, std::int64_t exploration_plan, const std::atomic<int>& stop);
  /// The exploration samples of a further setup aligned to the model so far (planner::align_setup): the
  /// placement found (object to table), or nothing when refused; `alignment` gets the figures (and `why`).
  std::optional<Eigen::Isometry3d> align_to_model(Job& j, const std::string& name, std::int64_t exploration_plan,
                                                  const Eigen::Isometry3d& asked, const Eigen::Isometry3d& actual,
                                                  nlohmann::json& alignment);
  std::optional<JobState> plan_setup(Job& j, int setup, const nlohmann::json& exploration_info, const Eigen::Isometry3d& estimated,
                                     const nlohmann::json& alignment, const std::atomic<int>& stop);
  /// Executes the views of a plan of axis targets (rough scan, setup exploration) that are not stored yet.
  void explore(Job& j, std::int64_t plan, const planner::CellModel& table_cell, const planner::TriangleMesh& scene, const std::string& what,
               const std::atomic<int>& stop);
  void finish(Job& j, JobState state, const std::string& cause, const nlohmann::json* advice = nullptr);
  /// The job's product (cloud.ply, model.ply); what was written goes into `result`, a failure as product_error.
  struct Product {
    std::optional<CloudSummary> cloud;
    std::optional<ModelSummary> model;
  };
  Product write_product(const Job& j, const std::vector<StoredView>& stored, nlohmann::json& result);
  /// The rough model's rows in the result: unmeasured, open, hypothetical, next setup, the closed loop's account.
  void rows_into(Job& j, JobState state, const nlohmann::json* advice, nlohmann::json& result);
  /// The inspection report (issue 19) against the reference, when the product was written.
  void report_into(const Job& j, const Product& product, nlohmann::json& result);
  /// The latest further setup's exploration plan not yet followed by the setup's first plan round.
  std::optional<std::int64_t> pending_setup(std::int64_t job);
  /// Simulation: where the part really lies in setup `setup` (the placement asked, off by the simulated
  /// operator's error, jobs.sim_placement_error_*).
  Eigen::Isometry3d actual_placement(const Job& j, int setup, const Eigen::Isometry3d& asked) const;
  /// Issue 20: the stable resting pose a second setup should use, for the result (planner::plan_next_setup).
  nlohmann::json next_setup(Job& j);
  /// Every executed round's plan info, with the rows its views' sweeps passed without a profile (held_rows).
  std::vector<nlohmann::json> round_infos(const Job& j);
  /// Keeps which of a view's predicted rows its sweep passed without a profile (not held against them).
  void note_lost_profiles(Job& j, std::int64_t plan, int view, const planner::RangeImage& img,
                          const std::vector<std::uint32_t>& predicted);
  void transition(Job& j, JobState s, const std::string& cause = "");

  Journal& journal_;
  const CellModels& models_;
  drivers::Positioner& positioner_;
  ScanHeadFactory heads_;
  JobSettings settings_;
  Report report_;
  PhaseTrace trace_;
};

/// A stop request honoured at a safe point (between moves or profiles).
struct Interrupted : std::runtime_error {
  StopRequest why;
  Interrupted(StopRequest w, const std::string& what) : std::runtime_error(what), why(w) {}
};

}  // namespace scancell::daemon
