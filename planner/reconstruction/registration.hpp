#pragma once
// Registration of an executed view (thesis 1.1.4, 4.2): point-to-plane ICP of the view's samples against the
// current model (a point cloud with normals: the rough model's surface, plus views already registered). With
// an imperfect positioner the acquired image must be registered before its coverage can be trusted; a view
// whose geometry cannot fix all six degrees of freedom (a plane, a cylinder: thesis 8.2) is flagged as
// ill-conditioned instead of drifting along its free directions.
#include <cstdint>
#include <memory>
#include <numbers>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "planner/geometry/mesh.hpp"
#include "planner/kinematics/pose_error.hpp"
#include "planner/scan/range_image.hpp"

namespace scancell::planner {

/// Target of the registration: points with unit normals, mm, object frame, and a grid for nearest neighbours.
class ModelCloud {
 public:
  ModelCloud() = default;
  /// Samples `mesh` at about `spacing_mm` (vertices plus points on each triangle) with face normals.
  static ModelCloud from_mesh(const TriangleMesh& mesh, double spacing_mm);
  void add(const std::vector<Eigen::Vector3d>& points, const std::vector<Eigen::Vector3d>& normals);
  std::size_t size() const;
  /// The nearest point within `max_mm`, or -1.
  long nearest(const Eigen::Vector3d& p, double max_mm) const;
  const Eigen::Vector3d& point(std::size_t i) const;
  const Eigen::Vector3d& normal(std::size_t i) const;

 private:
  // Points, normals and the nanoflann k-d tree over them live together on the heap, so that the tree's
  // reference to its points survives copies and moves of the cloud.
  struct Data;
  std::shared_ptr<const Data> data_;
};

struct IcpOptions {
  double max_distance_mm = 5.0;     // pairs farther apart are not correspondences (the pose error bound)
  double max_normal_angle_rad = 0.5;
  int max_iterations = 100;
  double converged_mm = 1e-3;       // stop when the update moves no sample more than this
  double min_overlap = 0.3;         // share of the samples that must find a partner
  double min_conditioning = 1e-2;   // least share of a motion's sample displacement across the surface (0..1; 0: a slide)
  double lever_mm = 100.0;          // rotations are scaled by this to compare them with translations
  /// A correction that turns the view farther than this is refused: no positioner errs by it, so it is a fit
  /// that a small or nearly symmetric patch let settle turned (a mushroom's cap rim seen alone: 11.5° with a
  /// 0.5° pose error, samples left 3 mm off), not the pose error. π: no bound.
  double max_turn_rad = std::numbers::pi;
  /// false: an ill-conditioned view is refused. true: it is registered in the directions its shape fixes and
  /// left where the positioner put it in the others (a face-on plane: only its distance and tilt), and the
  /// result says how many directions were left.
  bool partial = false;
  /// Plate motions only (a part resting on a plate): turns about this axis and shifts across it; its height
  /// along the axis and its tilt stay where the positioner put them (the plate fixes them). A point on the
  /// axis and its direction, in the frame of the points as given. Needs points without pivots (rigid motions).
  struct PlateAxis {
    Eigen::Vector3d point = Eigen::Vector3d::Zero();
    Eigen::Vector3d direction = Eigen::Vector3d::UnitZ();
  };
  std::optional<PlateAxis> plate_axis;
};

struct IcpResult {
  bool ok = false;
  std::string why;                  // when not ok: too little overlap, ill-conditioned, did not converge
  Eigen::Isometry3d correction = Eigen::Isometry3d::Identity();  // apply to the view's samples (object frame)
  double rms_mm = 0.0;              // point-to-plane residual after registration
  double moved_mean_mm = 0.0, moved_max_mm = 0.0;  // how far the correction moves the samples
  double overlap = 0.0;
  double conditioning = 0.0;
  int iterations = 0;
  int free_directions = 0;          // partial: motions the view could not fix (left as the positioner had them)
  Eigen::Matrix<double, 6, 1> weakest = Eigen::Matrix<double, 6, 1>::Zero();  // the least constrained motion
};

/// A range image's samples (every `stride`-th row and column) with normals from their image neighbours,
/// turned towards the laser: what a registered view adds to the model.
void image_points_normals(const RangeImage& image, int stride, std::vector<Eigen::Vector3d>& points,
                          std::vector<Eigen::Vector3d>& normals);

/// An image's valid samples as registration takes them, in sample order (object frame, mm): each sample's
/// pivot — a point on the boresight of its profile for a line scan (a camera orientation error turns each
/// profile about its own laser, not the image about one point), of the camera for a random-access sensor,
/// at the image's mean depth — and its surface
/// normal from its image neighbours, turned towards the laser (zero where a neighbour is missing or across
/// a depth step).
struct ScanSamples {
  std::vector<Eigen::Vector3d> points, pivots, normals;
};
ScanSamples scan_samples(const RangeImage& image);

/// Applies a registration correction (see register_points) to an image, rotating each sample about its own
/// pivot (scan_samples); the pose moves as the mid-sweep profile does. camera_mm is re-expressed
/// in the new pose, as acquisition does.
void apply_correction(RangeImage& image, const Eigen::Isometry3d& correction);

/// Registers `points` (object frame as the positioner believed) to `model`. The correction (W, δ) moves a
/// point p measured from pivot o to W (p − o) + o + δ. Without pivots (o = 0) that is the rigid motion W p + δ.
/// With a line scan's profile pivots it is the motion a camera orientation error really causes: the sweep
/// axis carries every profile along the same line, each turned by W about its own laser origin, so the image
/// is sheared, not rigidly turned (0.5° over a 110 mm sweep: ±0.5 mm at its ends).
/// Samples with known normals pair only with model points whose normal is within max_normal_angle_rad: a
/// face's samples near its edge are not the neighbouring face's (those pairs would invent a constraint along
/// the face, and a plane would not be flagged).
IcpResult register_points(const std::vector<Eigen::Vector3d>& points, const ModelCloud& model, const IcpOptions& options = {},
                          const std::vector<Eigen::Vector3d>& pivots = {}, const std::vector<Eigen::Vector3d>& normals = {});
IcpResult register_scan(const ScanSamples& samples, const ModelCloud& model, const IcpOptions& options = {});

/// `o` for registering to a model that is itself off by up to `model_error_mm` (a fused rough model: about
/// its voxel). A motion that changes the residuals by √λ of how far it moves the samples (λ as in
/// IcpOptions::min_conditioning) turns an error e of the model into a pose error of about e / √λ; it is
/// taken as fixed only while that stays within the pose error bound, λ ≥ (e / max_distance_mm)², and left as
/// positioned otherwise (a face seen with slivers of its sides, registered to a voxel model: the slivers'
/// weak hold on its slides dragged it 20° round). 0: `o` as it is; negative: std::invalid_argument.
IcpOptions for_model_error(IcpOptions o, double model_error_mm);

/// How much of a registration correction to believe (0..1): the positioner's expected error against the
/// target's. A correction measured against a model that is itself off by σ_model tells the pose only as far
/// as the pose is less certain than the model (the linear-Gaussian estimate σ_pose² / (σ_pose² + σ_model²)).
/// σ_pose: the sample displacement the cell's pose-error model predicts at `range_mm`.
double correction_weight(const PoseErrorModel& positioner, double range_mm, double model_sigma_mm);

/// The correction scaled by `weight`: its turn (angle about the same axis) and its shift.
Eigen::Isometry3d scale_correction(const Eigen::Isometry3d& correction, double weight);

}  // namespace scancell::planner
