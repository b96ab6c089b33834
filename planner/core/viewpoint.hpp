#pragma once
// Candidate viewpoints (thesis ch. 6): the optimal scanning zone (each targeted rough-model vertex dilated
// along its normal by the stand-off), the VARIABLE per-view rules and the DECOUPLED position/twist sampling.
#include <array>
#include <cstdint>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "planner/core/rough_model.hpp"
#include "planner/geometry/scene.hpp"
#include "planner/core/sensor.hpp"

namespace scancell::planner {

/// Which generator made a candidate (the plan JSON's `source`): the optimal scanning zone (thesis ch. 6; on a
/// cell-native cell, the views it expands each position into), a segment's single-best view (6.3.4), a
/// replan's aim at what an open row lacks, a cell's view of a row nothing else measured, or a view along an
/// open direction (holes, undercuts).
enum class ViewSource : std::uint8_t { optimal_zone, single_best, footprint_aim, self_aim, open_direction };
const char* to_string(ViewSource s);

/// A generalized viewpoint (v, λs): pose (position, axis, twist) plus the sensor setting (scan length).
struct Viewpoint {
  Eigen::Vector3d position = Eigen::Vector3d::Zero();  // camera origin (laser rest position), object frame, mm
  Eigen::Vector3d axis = -Eigen::Vector3d::UnitZ();    // unit boresight (camera -z) in the object frame
  double twist_rad = 0.0;                              // rotation about the boresight, see camera_rotation()
  double standoff_mm = 0.0;                            // distance from position to the targeted point
  double scan_length_mm = 0.0;                         // L_y (line-scan)
  std::int32_t target_row = -1;                        // rough-model row it was generated for, -1 if none
  std::int32_t twist_level = 0;                        // DECOUPLED twist index k (twist = base + 2πk/d_t)
  double tilt_rad = 0.0;                               // bisector tilt about camera x (0: laser along normal)
  ViewSource source = ViewSource::optimal_zone;        // the generator that made it

  /// Camera-to-object rotation: columns are the camera x, y, z axes in object coordinates.
  Eigen::Matrix3d rotation() const;
  /// Camera-to-object homogeneous transform.
  Eigen::Matrix4d transform() const;
  /// The pose rounded (rotation to 1e-9, position to 1e-6 mm): views with equal keys are one pose (the scan
  /// length aside), for merging candidates that coincide.
  std::array<long long, 12> pose_key() const;
};

/// Camera-to-object rotation of a view with boresight `axis`, twist, and a tilt about the resulting camera x
/// axis (positive tilt turns the boresight towards camera -y, moving the camera towards the receiver side).
Eigen::Matrix3d camera_rotation(const Eigen::Vector3d& axis, double twist_rad, double tilt_rad);

/// Twist zero is a fixed reference: camera x = normalize(u × z_c) with u = object +Z (object +X when the
/// boresight is within ~25° of Z), camera y = z_c × x. Twist rotates x towards y about z_c = -axis.
Eigen::Matrix3d camera_rotation(const Eigen::Vector3d& axis, double twist_rad);
/// The viewpoint whose frame is the given camera-to-object rotation and origin (axis and twist recovered; any
/// rotation is one axis and one twist). standoff, target_row and tilt are left at their defaults.
Viewpoint viewpoint_from_pose(const Eigen::Matrix3d& camera_to_object, const Eigen::Vector3d& position,
                              double scan_length_mm);

/// The twist that puts the camera +y (the baseline, receiver side) along the component of dir ⊥ axis.
double twist_towards(const Eigen::Vector3d& axis, const Eigen::Vector3d& dir);

enum class ViewpointScheme { variable, decoupled };

struct ViewpointSettings {
  ViewpointScheme scheme = ViewpointScheme::decoupled;
  double standoff_factor = 1.02;                 // f_d
  int position_decimation = 4;                   // d_v (DECOUPLED)
  /// Positions no denser than one per (f·w)² of surface, w the footprint width at R_o (DECOUPLED; 0: d_v alone).
  /// d_v alone ties the candidate count to the mesh's vertex count: a 38k-vertex mesh as given had 9.4k
  /// positions 3 mm apart under a 68 mm footprint, and the matrix cost grows with positions × rows. At 0.07
  /// (4.8 mm for the thesis sensor) 5k-row rough models of 200 mm objects keep every position.
  double min_position_spacing_fraction = 0.07;
  /// The same for plans without a cell. In free space every position takes every orientation; on a cell the
  /// reachable set thins the candidates of each position, so the cell is offered denser positions. At 0.1
  /// (6.8 mm) the bunny as given (37.7k rows) plans 45 views at verified m_v 0.999 with half the matrix time
  /// of 0.07; 5k-row rough models (one position per 55 mm² at most) keep every position either way.
  double free_space_min_position_spacing_fraction = 0.1;
  int twist_levels = 8;                          // d_t (DECOUPLED)
  double standoff_adjust_max_mm = 60.0;          // cap on R_a
  double scan_length_design_incidence_rad = 0.5235987755982988;  // incidence at which the density must hold
  double clearance_mm = 20.0;                    // minimum distance from the camera to the object
  /// Also generate, for every position and twist, the view tilted about camera x so that the targeted normal
  /// bisects the laser and receiver rays (each at half the triangulation angle atan(b/R)). The thesis' views
  /// put the laser along the normal and the receiver a full triangulation angle off it, which cannot see the
  /// floor of a cavity as deep as it is wide; the bisecting view can.
  bool bisector_tilt = true;
  /// Rows no candidate measures get a second chance (open-direction viewpoints): views along the directions
  /// from which the point is actually open to the outside, at stand-offs from f_d·R_o out to the longest
  /// range that still meets the precision spec. A longer stand-off narrows the triangulation angle, which is
  /// what lets a bi-static sensor see the floor of a hole as deep as it is wide.
  bool open_direction_views = true;
  int open_direction_standoffs = 3;   // stand-off levels between f_d·R_o and the precision-limited range
  int open_directions_per_row = 5;    // open directions kept per targeted row
  /// Cell-native candidates (cell_viewpoints.hpp): elevation offset of the two oblique views, and how many
  /// stand-offs (from the optimal zone's out to the precision-limited range) a colliding view may try.
  bool cell_native = true;             // false: project free candidates onto the cell instead (thesis 6.3.2)
  double cell_oblique_rad = 0.35;
  int cell_standoff_steps = 3;
  /// Rows nothing measures are aimed at along their own normal and, where an adjacent triangle's normal turns
  /// more than this from it, square to that face too (up to three faces; 0: off). cell_viewpoints.hpp: face_aims.
  double cell_face_aim_min_angle_rad = 0.0;
};

struct GenerationReport {
  std::size_t positions = 0;         // viewpoint positions (RM_v vertices)
  std::size_t positions_by_decimation = 0;  // what d_v alone asked for (more when the spacing limit applied)
  std::size_t candidates = 0;        // kept
  std::size_t dropped_inside = 0;    // camera position inside the object
  std::size_t dropped_clearance = 0; // camera position closer to the object than the clearance
  std::size_t dropped_no_normal = 0;
  std::size_t single_best_views = 0;  // added per segment (thesis 6.3.4)
  std::size_t open_direction_rows = 0;        // unmeasurable rows targeted by open-direction views
  std::size_t open_direction_candidates = 0;  // candidates added for them
  std::size_t rows_unmeasurable_before = 0;   // rows no candidate measured before they were added
  std::size_t rows_without_margin = 0;        // free space: rows only the plain test (no margin) lets a view measure
};

/// Longest scan length within the sensor's range whose eq. 3.8 density still meets the spec at the given
/// range with both incidence angles at the design incidence; the shortest allowed when none does.
double design_scan_length_mm(const SensorModel& sensor, const ModelSpec& spec, double range_mm,
                             double design_incidence_rad);

/// design_scan_length_mm for a view that sees the surface it is aimed at (outward unit `normal`, object frame)
/// more obliquely than the design incidence: the incidence in each plane (eq. 3.4's θ_xz, θ_yz of the normal at
/// the boresight, camera `rotation`) is the larger of the design's and the surface's, so that eq. 3.8 still
/// holds there. A view whose elevation the cell caps (a face turned to the plate, seen level from the plate's
/// height; a top steeper than the tilt range) sees its aim at 60° and more: at the design sweep its samples
/// there fall under the density spec and the view measures nothing of what it was made for. A surface not
/// facing the view: the design length.
double aimed_scan_length_mm(const SensorModel& sensor, const ModelSpec& spec, double range_mm, const Eigen::Matrix3d& rotation,
                            const Eigen::Vector3d& normal, double design_incidence_rad);

/// `count` rows spread by farthest-point sampling in (position, normal_weight_mm · normal) space, starting from
/// row 0. Deterministic for any thread count.
std::vector<std::uint32_t> farthest_point_sample(const RoughModel& rough, std::size_t count, double normal_weight_mm);

/// Candidate viewpoints for the whole rough model. Deterministic; parallel over positions.
std::vector<Viewpoint> generate_viewpoints(const RoughModel& rough, const OcclusionScene& scene,
                                           const SensorModel& sensor, const ModelSpec& spec,
                                           const ViewpointSettings& settings, GenerationReport* report = nullptr);

/// `count` unit directions spread evenly (a Fibonacci spiral) over the cap of half-angle `cap_rad` around +Z.
std::vector<Eigen::Vector3d> cap_directions(double cap_rad, int count);

/// Open-direction viewpoints for `rows` (typically those no ordinary candidate measures): for each targeted
/// row (farthest-point sampled, at most `max_rows`), directions within the grazing limits of its normal are
/// probed with rays; the open ones (nothing hit out to the precision-limited range) are thinned to
/// settings.open_directions_per_row spread directions, and each gets views at settings.open_direction_standoffs
/// stand-offs and settings.twist_levels twists, looking back along the direction. Deterministic.
std::vector<Viewpoint> open_direction_viewpoints(const RoughModel& rough, const OcclusionScene& scene,
                                                 const SensorModel& sensor, const ModelSpec& spec,
                                                 const ViewpointSettings& settings,
                                                 const std::vector<std::uint32_t>& rows, std::size_t max_rows,
                                                 std::size_t* targeted_rows = nullptr);

/// Thesis 6.3.4 single-best-view candidates for one segment (rows of the rough model): axis opposite the
/// segment's mean normal, position dilated from the segment's centre vertex far enough that the segment fits
/// the field of view (times f_d), twist sampled at `twist_levels` levels, scan length matched to the segment.
std::vector<Viewpoint> single_best_views(const RoughModel& rough, const std::vector<std::uint32_t>& segment_rows,
                                         const SensorModel& sensor, const ModelSpec& spec, int twist_levels,
                                         double standoff_factor = 1.02);

}  // namespace scancell::planner
