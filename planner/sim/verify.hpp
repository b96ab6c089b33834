#pragma once
// Verified measurability m_v (thesis 3.3.2, 4.4.1): execute a view plan with the virtual scanner against the
// fine model and measure, area-weighted over the fine mesh's vertices, what was measured to specification.
//
// A fine vertex counts as measured by a view when it lies in the cell (SampleCell: ¾ of a chord to each
// side of the sample; docs/verification.md says why ¾) of a sample of that view on a triangle facing the same
// side as the vertex, with predicted σz ≤ the spec's precision and a local density (chords to its
// range-image neighbours, sample_density_per_mm2) ≥ the spec's.
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "planner/geometry/mesh.hpp"
#include "planner/kinematics/pose_error.hpp"
#include "planner/core/sensor.hpp"
#include "planner/core/viewpoint.hpp"
#include "planner/sim/virtual_scanner.hpp"

namespace scancell::planner {

struct VerifyOptions {
  std::uint64_t seed = 1;          // range-noise streams (per view: mix_seed(seed, view))
  bool noise = true;
  PoseErrorModel pose_error;       // positioner error (thesis 7.2.4), drawn per view
  std::uint64_t pose_seed = 1;     // pose-error stream (per view: mix_seed(pose_seed, view, 1))
  double ray_offset_mm = 0.02;
  bool analytic = true;            // also evaluate the analytic test on the fine mesh (QUALITY-TARGETS' m_v)
  TriangleMesh occluders;          // cell fixtures in the object frame (the plate): they block, they are not measured
};

struct ViewVerification {
  ScanPose executed;                 // the pose actually scanned (with pose error, if any)
  ScanStats scan;
  std::size_t compliant_samples = 0; // σz and local density meet the spec
  double alone_mm2 = 0.0;            // fine area this view measures by itself
  double gain_mm2 = 0.0;             // newly measured, in plan order
  double unique_mm2 = 0.0;           // measured by this view and by no other view of the plan
  double cumulative = 0.0;           // verified m_v after this view
  double cumulative_analytic = 0.0;  // analytic m_v after this view (0 unless options.analytic)
  double cumulative_estimated = 0.0; // the plan's estimate (NaN when not given)
};

struct Verification {
  double area_mm2 = 0.0;                // fine model area
  double mv = 0.0;                      // verified measurability, virtual scanner
  double mv_analytic = 0.0;             // analytic test on the fine mesh (no noise, eq. 3.4/3.8 formulas)
  double estimated = 0.0;               // the plan's final estimate, NaN when not given
  std::vector<ViewVerification> views;
  std::vector<std::uint8_t> measured;   // per fine vertex: 1 when some view measured it
  std::vector<double> vertex_area_mm2;  // each vertex's share of the area (one third of each adjacent triangle)
  double seconds = 0.0;
};

/// Executes `views` in order on the fine mesh (object frame, mm). `estimated_cumulative` may be empty.
Verification verify_views(const TriangleMesh& fine_mm, const SensorModel& sensor, const ModelSpec& spec,
                          const std::vector<ScanPose>& views, const std::vector<double>& estimated_cumulative,
                          const VerifyOptions& options = {});

/// The scan pose of a planned viewpoint (its frame and scan length).
inline ScanPose scan_pose(const Viewpoint& v) {
  ScanPose p;
  p.camera_to_object.matrix() = v.transform();
  p.scan_length_mm = v.scan_length_mm;
  return p;
}

/// Monte Carlo over pose error (thesis fig. 7.12-7.15): the plan executed `trials` times, each with its own
/// pose-error draw (pose_seed = mix_seed(options.pose_seed, trial)) and the same range-noise stream, so zero
/// error reproduces the deterministic m_v exactly.
/// Verified measurability of range images already acquired (the daemon's stored scans, simulated against
/// this fine model): the same sample-to-vertex test as verify_views, no scanning. DataError when a sample's
/// triangle is not one of `fine`'s.
Verification verify_images(const TriangleMesh& fine, const ModelSpec& spec, const std::vector<RangeImage>& images);

struct MonteCarloResult {
  std::vector<double> mv;  // per trial
  double mean = 0.0, sd = 0.0, min = 0.0, max = 0.0;
  double seconds = 0.0;
};
MonteCarloResult verify_monte_carlo(const TriangleMesh& fine_mm, const SensorModel& sensor, const ModelSpec& spec,
                                    const std::vector<ScanPose>& views, const VerifyOptions& options, int trials);

/// A table for people: per view samples, alone / gain / unique area, cumulative verified vs estimated.
std::string verification_summary(const Verification& v);

/// Fine mesh with per-vertex colour: light grey measured, red not (ASCII PLY, readable by any mesh viewer).
void write_coverage_ply(const TriangleMesh& mesh, const std::vector<std::uint8_t>& measured,
                        const std::filesystem::path& path);

/// Measurability projection (thesis 3.3.2): orthographic renders of the coverage from +X, −X, +Y, −Y, +Z, −Z
/// (tiles left to right, top to bottom), shaded by the surface normal, measured grey, unmeasured red.
void write_measurability_png(const TriangleMesh& mesh, const std::vector<std::uint8_t>& measured,
                             const std::filesystem::path& path, int tile_px = 320);

/// The coverage picture people read (issue 19): write_measurability_png's six views, each labelled with its
/// direction, a legend below and `title` (the headline numbers) above, drawn by gnuplot (1240 × 860).
/// Returns "" when drawn. Without gnuplot, or when it fails, `png` gets the bare views and the return value
/// says why (the caller reports it: a picture without its legend is not passed off as the real one).
std::string write_coverage_picture(const TriangleMesh& mesh, const std::vector<std::uint8_t>& measured,
                                   const std::string& title, const std::filesystem::path& png);

}  // namespace scancell::planner
