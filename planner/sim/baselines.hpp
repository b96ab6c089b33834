#pragma once
// What a cell operator would run instead of a 3M plan, for the plan-quality benchmark:
// - a fixed turntable program: k equal turntable steps at a few scanner elevations, boresight at the object's
//   centre, stand-off putting the object in the depth of field where possible;
// - a view sphere: an icosahedral tessellation at a fixed radius around the object, boresight to the centre,
//   several twists each — the candidates a generic planner would set-cover.
#include <vector>

#include "planner/geometry/mesh.hpp"
#include "planner/core/sensor.hpp"
#include "planner/core/viewpoint.hpp"

namespace scancell::planner {

/// Distance from the camera to the bounding-box centre used by both baselines: R_min plus the bounding-sphere
/// radius (the whole object beyond R_min), capped at R_max.
double baseline_standoff_mm(const TriangleMesh& object, const SensorModel& sensor);

/// Turntable about the object's +Z through the bounding-box centre: `steps` equal steps of 2π/steps at each
/// elevation (rad, positive looking down). The baseline (camera +y) is horizontal, tangent to the turntable.
/// Scan length: the longest whose eq. 3.8 density meets the spec at the centre's range and the design incidence.
std::vector<Viewpoint> turntable_program(const TriangleMesh& object, const SensorModel& sensor, const ModelSpec& spec,
                                         int steps, const std::vector<double>& elevations_rad,
                                         double design_incidence_rad = 0.5235987755982988);

/// Unit directions of an icosahedron subdivided `subdivisions` times (12, 42, 162, 642 ...), deterministic order.
std::vector<Eigen::Vector3d> icosphere_directions(int subdivisions);

/// View-sphere candidates: one view per icosphere direction and twist level, looking at the centre.
std::vector<Viewpoint> view_sphere_candidates(const TriangleMesh& object, const SensorModel& sensor,
                                              const ModelSpec& spec, int subdivisions, int twist_levels,
                                              double design_incidence_rad = 0.5235987755982988);

}  // namespace scancell::planner
