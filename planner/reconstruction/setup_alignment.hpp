#pragma once
// Aligning a new setup to the model measured so far (issue 20). After the operator turns the part over, the
// cell knows the resting pose it asked for, not how exactly the part was put down: a turn about the table axis
// and a shift on the plate (±15° and ±10 mm by hand; any turn when put down carelessly). The new setup's
// exploration samples, expressed in the object frame as if the part lay exactly as asked, are aligned
// globally: a coarse search over the turn about the table axis, each start refined by point-to-plane ICP
// (registration.hpp) with a wide pairing distance, distinct outcomes then refined with a tight one.
// Both stages move the part only as the plate lets it (IcpOptions::plate_axis: a turn about the table axis,
// a shift across it): the part rests on the face the resting pose names, so the plate fixes its height and
// tilt exactly. Left free, the fit traded them against the samples' noise: an elephant came out tilted
// 0.035° and 0.054 mm off at its centre, against 0.004° and 0.011 mm with plate motions only. The best fit is kept only when it is good, its shape fixes
// the turn, and no distinct pose fits nearly as well: a part symmetric about the table axis (a surface of
// revolution) or with a discrete symmetry (two or more turns fit alike) cannot tell its turn, and merging it
// would corrupt the model. Refused, named.
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "planner/reconstruction/registration.hpp"

namespace scancell::planner {

struct SetupAlignmentOptions {
  Eigen::Vector3d axis_point = Eigen::Vector3d::Zero();       // a point on the table axis (samples' frame, mm)
  Eigen::Vector3d axis_direction = Eigen::Vector3d::UnitZ();  // the table axis (samples' frame), unit
  int angle_steps = 24;               // coarse starts: the full turn in this many steps (15°)
  double coarse_distance_mm = 30.0;   // ICP pairing distance of the coarse stage: the placement error's bound
  double fine_distance_mm = 2.0;      // and of the refinement
  std::size_t coarse_samples = 3000;  // the coarse stage works on at most this many samples, evenly strided
  int refined_outcomes = 4;           // the best this many distinct coarse outcomes are refined
  double max_rms_mm = 0.5;            // a best fit with a larger point-to-plane residual is poor: refused
  double min_overlap = 0.3;           // share of the samples that must pair with the model at the fine stage
  double ambiguity_rms_ratio = 1.5;   // a distinct pose with residual within this factor and overlap within
  double ambiguity_overlap_ratio = 0.9;  // this share of the best's makes the alignment ambiguous
  double distinct_angle_rad = 0.035;  // poses farther apart than 2° ...
  double distinct_shift_mm = 2.0;     // ... or 2 mm (at the samples' centroid) are distinct
  double min_plate_conditioning = 0.01;  // share of the least fixed plate motion's sample motion across the surface
};

struct SetupAlignmentFit {
  double start_angle_rad = 0.0;       // the coarse start (turn about the table axis)
  bool ok = false;
  std::string why;                    // when not ok: ICP's reason
  double rms_mm = 0.0, overlap = 0.0;
  Eigen::Isometry3d correction = Eigen::Isometry3d::Identity();
  bool refined = false;               // a distinct outcome, refined with the fine pairing distance
  int free_directions = 0;            // motions the shape did not fix, left as the resting pose put them
};

struct SetupAlignmentResult {
  bool ok = false;
  bool ambiguous = false;             // refused because distinct poses fit alike (or the turn is not fixed)
  std::string why;                    // when not ok, for people: what was found and what to do
  Eigen::Isometry3d correction = Eigen::Isometry3d::Identity();  // samples as placed nominally -> model frame
  double rms_mm = 0.0, overlap = 0.0;
  double turn_rad = 0.0;              // the correction's turn about the table axis, (-π, π]
  double tilt_rad = 0.0;              // and its rotation off that axis (the resting pose's own error)
  double shift_mm = 0.0;              // how far it moves the samples' centroid
  int free_directions = 0;            // motions the shape did not fix (height, tilt), left as the plate put them
  double plate_conditioning = 0.0;    // how well the shape fixes its turn and shift on the plate (0..1)
  int runner_up = -1;                 // index into fits of the best distinct alternative, -1 if none
  std::vector<SetupAlignmentFit> fits;  // one per coarse start
};

/// Aligns `points` (with unit normals, or none: empty) to `model`. Deterministic.
/// Throws std::invalid_argument on mismatched sizes or options out of range.
SetupAlignmentResult align_setup(const std::vector<Eigen::Vector3d>& points, const std::vector<Eigen::Vector3d>& normals,
                                 const ModelCloud& model, const SetupAlignmentOptions& options = {});

}  // namespace scancell::planner
