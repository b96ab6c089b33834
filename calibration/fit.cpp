#include "calibration/fit.hpp"

#include <cmath>

#include <Eigen/Dense>

#include "common/errors.hpp"

namespace scancell::calibration {

using scancell::DataError;

PlaneFit fit_plane(const std::vector<Eigen::Vector3d>& pts, const std::string& what) {
  if (pts.size() < 10) throw DataError(what + ": " + std::to_string(pts.size()) + " points, a plane fit needs at least 10");
  PlaneFit f;
  f.n = pts.size();
  for (const auto& p : pts) f.point += p;
  f.point /= static_cast<double>(pts.size());
  Eigen::Matrix3d c = Eigen::Matrix3d::Zero();
  for (const auto& p : pts) c += (p - f.point) * (p - f.point).transpose();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(c);
  // The points must spread in two directions: a line (one profile) does not define a plane.
  if (es.eigenvalues()(1) < 1e-6 * es.eigenvalues()(2) || es.eigenvalues()(1) <= 0.0)
    throw DataError(what + ": the points lie on a line; no plane");
  f.normal = es.eigenvectors().col(0);
  double ss = 0.0;
  for (const auto& p : pts) ss += std::pow((p - f.point).dot(f.normal), 2);
  f.rms = std::sqrt(ss / static_cast<double>(pts.size() - 3));
  return f;
}

SphereFit fit_sphere(const std::vector<Eigen::Vector3d>& pts, const std::string& what, double known_r) {
  if (pts.size() < 10) throw DataError(what + ": " + std::to_string(pts.size()) + " points, a sphere fit needs at least 10");
  // Algebraic start: |p|² = 2 c·p + (r² - |c|²), linear in (c, d).
  Eigen::MatrixXd a(pts.size(), 4);
  Eigen::VectorXd b(pts.size());
  for (std::size_t i = 0; i < pts.size(); ++i) {
    a.row(static_cast<Eigen::Index>(i)) << 2 * pts[i].x(), 2 * pts[i].y(), 2 * pts[i].z(), 1.0;
    b(static_cast<Eigen::Index>(i)) = pts[i].squaredNorm();
  }
  const Eigen::Vector4d s = a.colPivHouseholderQr().solve(b);
  SphereFit f;
  f.n = pts.size();
  f.centre = s.head<3>();
  const double r2 = s(3) + f.centre.squaredNorm();
  if (!(r2 > 0.0) || !f.centre.allFinite()) throw DataError(what + ": the points do not lie on a sphere");
  f.radius = known_r > 0.0 ? known_r : std::sqrt(r2);
  // Gauss-Newton on the geometric residuals |p - c| - r.
  const int unknowns = known_r > 0.0 ? 3 : 4;
  for (f.iterations = 1; f.iterations <= 50; ++f.iterations) {
    Eigen::MatrixXd j(pts.size(), unknowns);
    Eigen::VectorXd r(pts.size());
    for (std::size_t i = 0; i < pts.size(); ++i) {
      const Eigen::Vector3d d = pts[i] - f.centre;
      const double len = d.norm();
      if (len < 1e-12) throw DataError(what + ": a point at the sphere's centre");
      const auto row = static_cast<Eigen::Index>(i);
      j.block<1, 3>(row, 0) = -(d / len).transpose();
      if (unknowns == 4) j(row, 3) = -1.0;
      r(row) = len - f.radius;
    }
    const Eigen::VectorXd step = j.colPivHouseholderQr().solve(-r);
    if (!step.allFinite()) throw DataError(what + ": sphere fit is singular (points on too small a cap?)");
    f.centre += step.head<3>();
    if (unknowns == 4) f.radius += step(3);
    if (step.norm() < 1e-10) break;
  }
  if (f.iterations > 50) throw DataError(what + ": sphere fit did not converge in 50 iterations");
  double ss = 0.0;
  for (const auto& p : pts) ss += std::pow((p - f.centre).norm() - f.radius, 2);
  f.rms = std::sqrt(ss / static_cast<double>(pts.size() - static_cast<std::size_t>(unknowns)));
  return f;
}

CircleFit fit_circle(const std::vector<Eigen::Vector3d>& pts, const std::string& what) {
  if (pts.size() < 3) throw DataError(what + ": " + std::to_string(pts.size()) + " points, a circle needs at least 3");
  CircleFit f;
  f.n = pts.size();
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& p : pts) mean += p;
  mean /= static_cast<double>(pts.size());
  Eigen::Matrix3d c = Eigen::Matrix3d::Zero();
  for (const auto& p : pts) c += (p - mean) * (p - mean).transpose();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(c);
  if (es.eigenvalues()(1) < 1e-9 * es.eigenvalues()(2) || es.eigenvalues()(2) <= 0.0)
    throw DataError(what + ": the points are collinear or coincide; no circle");
  f.normal = es.eigenvectors().col(0);
  const Eigen::Vector3d u = es.eigenvectors().col(2), v = f.normal.cross(u);
  // Kasa fit in the plane: x² + y² = 2 a x + 2 b y + c.
  Eigen::MatrixXd a(pts.size(), 3);
  Eigen::VectorXd b(pts.size());
  for (std::size_t i = 0; i < pts.size(); ++i) {
    const double x = (pts[i] - mean).dot(u), y = (pts[i] - mean).dot(v);
    a.row(static_cast<Eigen::Index>(i)) << 2 * x, 2 * y, 1.0;
    b(static_cast<Eigen::Index>(i)) = x * x + y * y;
  }
  const Eigen::Vector3d s = a.colPivHouseholderQr().solve(b);
  f.radius = std::sqrt(s(2) + s(0) * s(0) + s(1) * s(1));
  if (!std::isfinite(f.radius)) throw DataError(what + ": circle fit failed");
  f.centre = mean + s(0) * u + s(1) * v;
  double ss = 0.0;
  for (const auto& p : pts) {
    const Eigen::Vector3d d = p - f.centre;
    const double h = d.dot(f.normal);
    const double rho = (d - h * f.normal).norm();
    ss += h * h + std::pow(rho - f.radius, 2);
  }
  f.rms = pts.size() > 3 ? std::sqrt(ss / static_cast<double>(pts.size() - 3)) : 0.0;
  return f;
}

ProportionalFit fit_proportional(const std::vector<double>& x, const std::vector<double>& y, const std::string& what) {
  if (x.size() != y.size() || x.size() < 2)
    throw DataError(what + ": " + std::to_string(x.size()) + " points, a fit of y = k x needs at least 2");
  double sxx = 0.0, sxy = 0.0;
  for (std::size_t i = 0; i < x.size(); ++i) {
    sxx += x[i] * x[i];
    sxy += x[i] * y[i];
  }
  if (!(sxx > 0.0)) throw DataError(what + ": all x are zero");
  ProportionalFit f;
  f.n = x.size();
  f.k = sxy / sxx;
  double ss = 0.0;
  for (std::size_t i = 0; i < x.size(); ++i) ss += std::pow(y[i] - f.k * x[i], 2);
  f.rms = std::sqrt(ss / static_cast<double>(x.size() - 1));
  f.se = f.rms / std::sqrt(sxx);
  return f;
}

}  // namespace scancell::calibration
