#pragma once
// The rough scan (thesis 1.2.2, 3.1): before anything is known of the object but its approximate size, a
// preprogrammed exploration — turntable steps × a few camera elevations, far out, long sweeps — whose range
// images are fused (planner/fusion.hpp) into the rough model the planner starts from.
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "planner/kinematics/cell.hpp"
#include "planner/reconstruction/fusion.hpp"
#include "planner/core/sensor.hpp"

namespace scancell::planner {

struct ExplorationOptions {
  int table_steps = 8;                              // turntable angles over a turn
  std::vector<double> tilts_rad = {1.15, 0.75, 0.35};  // camera elevations (1.15: steep from above)
  FusionOptions fusion;                             // voxel size etc. of the fused rough model
};

struct ExplorationView {
  JointVector q;
  double scan_length_mm = 0.0;
};

/// Views of a box `size_mm` (x, y, z) standing centred on the turntable (its base on the table top, z = 0 of
/// the cell's object frame, which must be the table frame). The box's centre sits mid-range, aimed at from
/// one height, or several up the box when it is taller than the profile's fan covers; poses the cell cannot
/// reach are skipped and named in `skipped`. DataError when the box is larger than the sensor's
/// range can take or no pose is reachable.
std::vector<ExplorationView> exploration_views(const CellModel& cell, const SensorModel& sensor, const Eigen::Vector3d& size_mm,
                                               const ExplorationOptions& options, std::vector<std::string>* skipped = nullptr);

/// The volume the rough model is fused in: the box with a margin, in the table frame.
Eigen::AlignedBox3d exploration_bounds(const Eigen::Vector3d& size_mm);

/// A mesh written as OFF (written to a temp file and renamed).
void write_off(const TriangleMesh& mesh, const std::string& path);

/// The vertices of `mesh` flagged in `flags` (the rough scan's hypothetical ones), one "x y z" line each in
/// the OFF's own precision, so they can be found again in the mesh as loaded (the loader welds and reorders).
void write_flagged_vertices(const TriangleMesh& mesh, const std::vector<std::uint8_t>& flags, const std::string& path);

/// Per vertex of `mesh`: 1 where a vertex listed in `path` lies (within 2 µm). DataError when the file is
/// unreadable or malformed (naming the line), or when a listed vertex is not in the mesh (not its list).
std::vector<std::uint8_t> read_flagged_vertices(const TriangleMesh& mesh, const std::string& path);

}  // namespace scancell::planner
