#pragma once
// Calibration targets as meshes in their own frame, which sits on the turntable: the frame's origin on the
// table axis at the table top, z up. In simulation they are what the scanner sees; on a real cell they
// describe the physical target (a ground plate, a machined ramp, reference spheres) the operator mounts.
#include <array>
#include <vector>

#include <Eigen/Core>

#include "planner/geometry/mesh.hpp"

namespace scancell::calibration {

/// A flat square plate, `side_mm` wide, its top face at z = `thickness_mm`.
planner::TriangleMesh plate_target(double side_mm = 200.0, double thickness_mm = 5.0);

/// A wedge whose top face rises towards -y with slope `slope_rad`: outward normal (0, sin α, cos α), so it
/// faces both the laser and the receiver (at camera +y) when the camera's y runs along the target's y; the
/// face spans x in [-half_width, half_width], y in [-half_depth, half_depth].
struct Ramp {
  double slope_rad = 1.1344640137963142;  // 65°
  double half_width_mm = 30.0, half_depth_mm = 20.0;
  Eigen::Vector3d offset_mm{135.0, 0.0, 0.0};  // where its base centre sits on the table
  Eigen::Vector3d normal() const;
  Eigen::Vector3d centre() const;  // of the sloped face
};
planner::TriangleMesh ramp_target(const Ramp& ramp);
/// Whether a target-frame point lies on the ramp's sloped face, `margin_mm` inside its edges, within
/// `tolerance_mm` of the face.
bool on_ramp_face(const Ramp& ramp, const Eigen::Vector3d& p, double margin_mm, double tolerance_mm);

/// The sensor run's artefact: a 200 × 200 × 5 mm plate at the table centre (noise and t_xz scans, made with
/// the ramp turned away to the far side) and the ramp beside it at +x (t_yz scans).
planner::TriangleMesh sensor_target(const Ramp& ramp = {});
inline constexpr double kPlateSideMm = 200.0, kPlateThicknessMm = 5.0;

/// Reference spheres (radius known, centres in the target frame); the mesh is each sphere as a fine UV
/// sphere (chord error below 0.01 mm: the fits see a sphere, not facets).
struct Spheres {
  double radius_mm = 12.5;
  std::vector<Eigen::Vector3d> centres;
};
planner::TriangleMesh spheres_target(const Spheres& s);

/// One sphere off the axis (turntable-axis run) and three at different heights (positioner run: the three
/// centres fix the target's full pose).
Spheres axis_sphere(double radius_from_axis_mm = 55.0, double height_mm = 40.0);
Spheres tripod();

}  // namespace scancell::calibration
