#pragma once
// Positioning-system pose error (thesis ch. 7, appendix C): the error model, its analytic single-view effects
// for a line-scan sensor in the optimal scanning configuration (tables 7.3, 7.4, 7.5, conditions of table
// 7.6), the countermeasures they suggest (7.4.7), and the sampling of perturbed poses for Monte Carlo runs.
#include <cstdint>
#include <string>

#include "planner/core/measurability.hpp"
#include "planner/core/sensor.hpp"
#include "planner/scan/range_image.hpp"

namespace scancell::planner {

/// Thesis 7.2.4: independent zero-mean errors in position (σ_p, uniformly distributed direction), boresight
/// axis (a cone of half-angle |N(0, σ_a)| about the boresight, uniform azimuth) and twist (N(0, σ_t)).
struct PoseErrorModel {
  double sigma_p_mm = 0.0;
  double sigma_a_rad = 0.0;
  double sigma_t_rad = 0.0;
  bool zero() const { return sigma_p_mm == 0.0 && sigma_a_rad == 0.0 && sigma_t_rad == 0.0; }
};

/// Mean and standard deviation of a relative performance measure.
struct Moments {
  double mean = 1.0;
  double sd = 0.0;
};

/// Tables 7.3-7.5 evaluated for one sensor (Φx, R_o), stand-off factor f_d and error model. Each effect is
/// given separately for position, axis and twist error, as in the thesis.
struct PoseErrorEffects {
  double fd = 1.02;
  // Table 7.3: relative precision P_rel (< 1 better) and relative sampling density D_rel (> 1 better).
  Moments precision_position, precision_axis, precision_twist;
  Moments density_position, density_axis, density_twist;
  // Table 7.4: relative targeted footprint TF_rel (≤ 1).
  Moments footprint_position, footprint_axis, footprint_twist;
  // Table 7.5: probability of depth-of-field (near limit) erosion.
  double dof_erosion_position = 0.0, dof_erosion_axis = 0.0;
  /// The smallest f_d that keeps both depth-of-field erosion probabilities ≤ `dof_risk`.
  double suggested_fd = 1.0;
  double dof_risk = 1e-3;
};

PoseErrorEffects pose_error_effects(const SensorModel& sensor, const PoseErrorModel& error, double fd = 1.02,
                                    double dof_risk = 1e-3);

/// Countermeasures sized from the analytic effects at two standard deviations (footprint: 1 − (μ − 2σ) of the
/// three error kinds combined; buffer: the worse of μP + 2σP − 1 and 1 − (μD − 2σD); DOF margin: 3σ_p plus the
/// axis error's range change across the half field of view; visibility: 2σ_p).
Countermeasures countermeasures_for(const SensorModel& sensor, const PoseErrorModel& error, double fd = 1.02);

/// A pose drawn from the error model around `pose` (position in the object frame, axis and twist about the
/// camera origin). Deterministic for a seed.
ScanPose sample_pose_error(const ScanPose& pose, const PoseErrorModel& error, std::uint64_t seed);

/// A table for people: tables 7.3-7.5 for this sensor and error, with the suggested f_d and countermeasures.
std::string pose_error_report(const SensorModel& sensor, const PoseErrorModel& error, double fd);

/// Standard normal cumulative distribution Φ(x).
double normal_cdf(double x);

}  // namespace scancell::planner
