#pragma once
// How an object can rest on the turntable plate (issue 15 item 5, issue 20). A rigid body on a plane rests on
// a face of its convex hull; it stays there when its centre of mass stands over that face (the support
// polygon), and it topples over the edge it overhangs otherwise. The resting pose decides what a turntable
// cell can see: the support face and what the plate shadows are never measured in that setup.
#include <cstddef>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "planner/geometry/mesh.hpp"

namespace scancell::planner {

struct RestingPoseOptions {
  // Hull facets closer to coplanar than this merge into one support face (qhull's pre-merge centrum radius,
  // mm): a face tessellated or measured with noise still rests as one. 0: 0.002 of the bounding-box diagonal.
  double merge_mm = 0.0;
};

struct RestingPose {
  Eigen::Vector3d down_object = -Eigen::Vector3d::UnitZ();  // outward normal of the support face (object frame)
  Eigen::Matrix3d object_to_table = Eigen::Matrix3d::Identity();  // least rotation taking down_object to table -z
  // Quasi-static drop model: the share of random orientations that settle here. A face's share is the solid
  // angle it subtends from the centre of mass over 4π; an unstable face's share follows its roll to the face
  // it ends on.
  double probability = 0.0;
  double margin_mm = 0.0;        // from the centre of mass's foot to the nearest edge of the support polygon
  double com_height_mm = 0.0;    // centre of mass above the plate
  double tip_angle_rad = 0.0;    // atan(margin / height): the tilt that topples it (a low one is marginal)
  double support_area_mm2 = 0.0;
};

struct RestingPoses {
  Eigen::Vector3d centre_of_mass = Eigen::Vector3d::Zero();  // object frame, mm
  bool solid = false;            // true: of the enclosed volume (closed mesh); false: of the surface (open mesh)
  std::size_t hull_faces = 0;    // support faces of the convex hull, after merging
  std::vector<RestingPose> poses;  // statically stable ones, most probable first
  struct Basin {
    Eigen::Vector3d normal;      // a hull face's outward normal (object frame)
    double offset = 0.0;         // normal·x + offset = 0 on it
    int pose = -1;               // the pose an object lowered onto this face settles in (-1: none)
  };
  std::vector<Basin> basins;     // every hull face
};

/// The pose an object held with `down_object` (object frame) pointing at the plate settles in when let go:
/// the hull face straight below its centre of mass, then the faces it topples over to. -1 when none.
int settling_pose(const RestingPoses& rest, const Eigen::Vector3d& down_object);

/// Choosing how the object rests for a turntable job (planner/placement.hpp): what each evaluated pose gave.
struct PlacementOption {
  int pose = -1;                 // index into RestingPoses::poses; -1: the orientation as given, not a stable pose
  bool as_given = false;         // the cell's configured orientation (object_rpy_rad, default the mesh's +z up)
  int settles_on = -1;           // as given and not a stable pose: the pose it would settle in, if let go
  double settle_angle_rad = 0.0; // and how far that pose is from it
  Eigen::Matrix3d object_to_table = Eigen::Matrix3d::Identity();
  double probability = 0.0, tip_angle_rad = 0.0;  // of the pose (0 for an unstable as-given orientation)
  double estimated_coverage = 0.0;  // the plan's estimate: measured share of the whole rough-model area
  std::size_t views = 0;
  double cell_time_s = 0.0;         // move + scan at the cell's speeds
  double plan_s = 0.0;
};

struct PlacementChoice {
  RestingPoses rest;
  std::vector<PlacementOption> options;  // as evaluated: the most probable stable poses, then as given if none is it
  int chosen = -1;                       // index into options
  std::string reason;                    // one line for people
};

/// The stable resting poses of `mesh` (mm) on a horizontal plate. Throws DataError naming the mesh's extent
/// when it is flat or degenerate (no hull), or qhull's message.
RestingPoses resting_poses(const TriangleMesh& mesh, const RestingPoseOptions& options = {});

/// The object on the plate: rotated by `rotation` (object to table), its rotated bounding box centred on the
/// turntable axis and its lowest point on the table top, then moved by `offset_mm` (table frame).
Eigen::Isometry3d place_on_plate(const TriangleMesh& mesh, const Eigen::Matrix3d& rotation,
                                 const Eigen::Vector3d& offset_mm = Eigen::Vector3d::Zero());
/// The offset that makes place_on_plate(mesh, pose.linear(), offset) return `pose`: how a placement known
/// exactly (a setup aligned to the model, off centre and turned as the operator put it down) is handed to
/// the planner, which places by rotation and offset.
Eigen::Vector3d plate_offset_of(const TriangleMesh& mesh, const Eigen::Isometry3d& pose);

}  // namespace scancell::planner
