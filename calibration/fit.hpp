#pragma once
// Least-squares fits for the calibration runs: plane (total least squares), sphere (algebraic start, then
// Gauss-Newton on the geometric distance), circle in 3D (plane of the points, then a sphere-free 2D circle),
// and a proportional law y = k·x with its standard error. Every fit refuses data it cannot fit with a
// scancell::DataError naming what is missing (too few points, degenerate layout, no convergence).
#include <cstddef>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace scancell::calibration {

struct PlaneFit {
  Eigen::Vector3d point = Eigen::Vector3d::Zero();   // centroid
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  // unit; sign as the caller orients it
  double rms = 0.0;                                   // of the signed distances, n - 3 degrees of freedom
  std::size_t n = 0;
};
PlaneFit fit_plane(const std::vector<Eigen::Vector3d>& points, const std::string& what);

struct SphereFit {
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  double radius = 0.0, rms = 0.0;
  std::size_t n = 0;
  int iterations = 0;
};
/// `known_radius_mm` > 0 fixes the radius (a calibrated sphere target): only the centre is fitted, which is
/// better conditioned when the scan sees a cap of the sphere.
SphereFit fit_sphere(const std::vector<Eigen::Vector3d>& points, const std::string& what, double known_radius_mm = 0.0);

struct CircleFit {
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  // the circle's axis, unit
  double radius = 0.0, rms = 0.0;                      // rms: in-plane radial and out-of-plane residuals
  std::size_t n = 0;
};
CircleFit fit_circle(const std::vector<Eigen::Vector3d>& points, const std::string& what);

struct ProportionalFit {
  double k = 0.0;          // y = k·x
  double se = 0.0;         // standard error of k (from the residuals, n - 1 degrees of freedom)
  double rms = 0.0;
  std::size_t n = 0;
  double ci95() const { return 1.96 * se; }
};
ProportionalFit fit_proportional(const std::vector<double>& x, const std::vector<double>& y, const std::string& what);

}  // namespace scancell::calibration
