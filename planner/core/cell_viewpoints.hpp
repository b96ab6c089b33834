#pragma once
// Candidate viewpoints in the cell's own configuration space (issue 15; thesis 6.3.2 projects free 6-DoF
// candidates onto the reachable set instead).
//
// turntable_lift_tilt imposes the twist: the baseline (camera y) always lies along world +Y, so for a given
// boresight the only freedom left is the table angle, which turns the boresight's horizontal part towards
// the scanner. Projecting a free candidate keeps its position and boresight and turns it about the
// boresight; a boresight steeper than the tilt range is then simply unreachable, and a view whose body hits
// the object is dropped. Here every optimal-zone position (thesis ch. 6: target row, stand-off
// (R_o + R_a)·f_d) is instead expanded within the cell's space:
// - the thesis' view: boresight along the targeted normal, its elevation clamped to the tilt range (the
//   steepest view the cell has of a top face, not none);
// - the bisector pair: turned about the table axis by ± half the triangulation angle atan(b/R)/2, so that
//   the normal bisects the laser and receiver rays (the receiver sits beside the laser, horizontally, in
//   this cell; a yaw is the cell's own way to straddle the normal);
// - two oblique views, the elevation raised and lowered by `oblique_rad`: surfaces that face the plate or
//   sit in clefts are open only from a slant;
// - each with the one twist the cell reaches (the other sign when the first is out of reach), and, when
//   the scanner body would hit the object or the plate, stepped back along the boresight (the stand-off
//   grows towards the precision-limited range) rather than dropped.
// - each swept at the length that keeps eq. 3.8 at its aim as the view sees it (aimed_scan_length_mm): the
//   design incidence's, shorter where a capped or clamped elevation sees the aim more obliquely (a face 63°
//   below the horizontal seen level from the plate's height: 92 mm instead of 140 at R_o, or nothing of it
//   measured).
// arm_turntable: the wrist takes any twist, so every free candidate is a pose the cell may take as it is;
// one the arm cannot reach or whose scanner body hits the object or the plate steps back along its
// boresight the same way, and one looking up at a face turned to the plate is also tried lowered by
// `oblique_rad` towards the horizontal (thesis 6.3.2 would drop both).
#include <cstdint>
#include <vector>

#include "planner/kinematics/cell.hpp"
#include "planner/core/rough_model.hpp"
#include "planner/core/sensor.hpp"
#include "planner/core/viewpoint.hpp"

namespace scancell::planner {

struct CellGenerationReport {
  std::size_t seeds = 0;         // optimal-zone positions expanded
  std::size_t candidates = 0;    // kept
  std::size_t clamped = 0;       // boresight steeper than the tilt range, clamped
  /// kept at a longer stand-off to clear the object or the plate; on arm_turntable also every view kept
  /// lowered (by cell_oblique_rad, or as `lowered`), so that seeds = kept as they are + this + dropped
  std::size_t stepped_back = 0;
  /// kept with the elevation lowered so that the camera stands no lower than the top of the plate under the
  /// target (a view from below it looks through the plate)
  std::size_t lowered = 0;
  std::size_t unreachable = 0;   // no twist sign the axes reach
  std::size_t colliding = 0;     // collides at every stand-off tried
  std::size_t footprint_aims = 0, footprint_candidates = 0;  // replans: points aimed at what open rows lack, views kept
  std::size_t footprint_aims_closed = 0;  // replans: of those points, closed to every view within R_min, dropped
  std::size_t self_aims = 0, self_candidates = 0;  // rows no candidate measured, aimed at themselves; views kept
  std::size_t self_aims_closed = 0;  // of those aims, closed to every view within R_min (aims_open_to_sensor), dropped
};

/// A surface point to aim views at: where (object frame, mm), its outward unit normal, the stand-off to start
/// from, and the row the views are credited to (Viewpoint::target_row).
struct AimPoint {
  Eigen::Vector3d point, normal;
  double standoff_mm = 0.0;
  std::int32_t row = -1;
};

/// Whether `cell` gets cell-native candidates (turntable_lift_tilt, arm_turntable); others project free ones.
bool has_cell_native_viewpoints(const CellModel& cell);

/// Cell-native candidates from the optimal-zone positions of `seeds` (free-space candidates: on
/// turntable_lift_tilt one per target row is used, its stand-off and target; on arm_turntable each);
/// settings.cell_oblique_rad and cell_standoff_steps shape the expansion. Deterministic; parallel over seeds.
std::vector<Viewpoint> cell_viewpoints(const RoughModel& rough, const std::vector<Viewpoint>& seeds,
                                       const SensorModel& sensor, const ModelSpec& spec,
                                       const ViewpointSettings& settings, const CellModel& cell,
                                       const CollisionChecker& checker, CellGenerationReport* report = nullptr);

/// Cell-native candidates aimed at `aims` rather than at optimal-zone positions (a replan aims at what open
/// rows lack: planner/core/footprint.hpp): on turntable_lift_tilt each aim's five views as above; on
/// arm_turntable the free views along each normal at every twist level, stepped back or lowered as above.
/// Other cells: none. Deterministic; parallel over the aims.
std::vector<Viewpoint> cell_viewpoints_at(const std::vector<AimPoint>& aims, const SensorModel& sensor, const ModelSpec& spec,
                                          const ViewpointSettings& settings, const CellModel& cell,
                                          const CollisionChecker& checker, CellGenerationReport* report = nullptr);

/// The aims some view could see at all, in order: those with a direction within the sensor's widest incidence of
/// their normal (both grazing limits at once, atan √(tan² t_xz + tan² t_yz), eq. 3.4's domain) that nothing in
/// `scene` blocks out to R_min, probed with `probes` rays from `ray_offset_mm` off the surface. Every view's
/// laser sits at least R_min from what it measures, so an aim closed so near (a face resting on the plate, the
/// floor of a slot narrower than the cap) gets no view: its five views would only be tested and measure nothing.
/// An aim without a normal is kept. `closed` counts the aims dropped. Deterministic; parallel over the aims.
std::vector<AimPoint> aims_open_to_sensor(const std::vector<AimPoint>& aims, const OcclusionScene& scene, const SensorModel& sensor,
                                          double ray_offset_mm, std::size_t* closed = nullptr, int probes = 128);

/// Aims square to the faces of `rows` (viewpoints.cell_face_aim_min_angle_rad): per row, each adjacent triangle
/// whose normal turns more than `min_angle_rad` from the row's normal and from the faces already kept (at most
/// three), aimed at halfway from the row to the triangle's centroid (inside the row's footprint) along that
/// normal, at `standoff_mm`, credited to the row. Ascending rows give aims in row order.
std::vector<AimPoint> face_aims(const RoughModel& rough, const std::vector<std::uint32_t>& rows, double min_angle_rad, double standoff_mm);

}  // namespace scancell::planner
