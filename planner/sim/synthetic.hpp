#pragma once
// Synthetic test objects of thesis ch. 4-5 as fine meshes (mm, outward normals): the nearly planar convex
// patch, cavity patches of a given depth-to-width ratio D/W, and closed CAD-like shapes with a blind hole and a
// bore. Repeatable, scalable and with known geometry, like the thesis' synthetic targets.
#include "planner/geometry/mesh.hpp"
#include "planner/core/sensor.hpp"

namespace scancell::planner {

/// Sensor footprint F_s (thesis 4.2.2): frustum cross-section at the optimal stand-off f_d·R_o,
/// 2·f_d·R_o·tan(Φx/2)·L_y, with L_y the design scan length there (line-scan) or 2·f_d·R_o·tan(Φy/2).
double sensor_footprint_mm2(const SensorModel& sensor, const ModelSpec& spec, double standoff_factor = 1.02,
                            double design_incidence_rad = 0.5235987755982988);

/// Square patch of side `width_mm` facing +Z, a paraboloid cap rising `depth_ratio`·width at the centre above
/// the corners (the thesis' nearly planar convex patch has D/W = 0.04).
TriangleMesh convex_patch(double width_mm, double depth_ratio, double spacing_mm);

/// Square plate of side `plate_mm` facing +Z with a round cosine-profile cavity of rim diameter W =
/// `cavity_width_mm` and depth D = depth_ratio·W at its centre (thesis fig. 4.8, D/W 0.1 ... 1.0).
TriangleMesh cavity_patch(double plate_mm, double cavity_width_mm, double depth_ratio, double spacing_mm);

/// Closed box (x, y, z sizes; base on z = 0) with a blind cylindrical hole in the centre of its top face.
TriangleMesh box_with_blind_hole(const Eigen::Vector3d& size_mm, double hole_diameter_mm, double hole_depth_mm,
                                 double spacing_mm);

/// Closed tube along Z (base on z = 0): outer and bore walls with annular end faces.
TriangleMesh cylinder_with_bore(double outer_diameter_mm, double bore_diameter_mm, double height_mm,
                                double spacing_mm);

/// Merges vertices closer than `tolerance_mm` (the generators build faces separately) and drops unused ones.
TriangleMesh weld(const TriangleMesh& mesh, double tolerance_mm = 1e-6);

/// Camera poses as the planner makes views of a 200 mm object on a cell: `count` of them, 200-400 mm from a point
/// 80 mm above the plate (object frame), from any azimuth, at elevations from -10° to 75°, with any twist,
/// looking at that point. Repeatable for a `seed` (for inverse-kinematics tests and bench_ik).
std::vector<Eigen::Isometry3d> view_like_poses(int count, unsigned seed);

}  // namespace scancell::planner
