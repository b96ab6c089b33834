#include "planner/reconstruction/registration.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <stdexcept>

#include <Eigen/Dense>

#include "planner/core/rough_model.hpp"
#include "planner/geometry/point_kdtree.hpp"

namespace scancell::planner {

struct ModelCloud::Data {
  std::vector<Eigen::Vector3d> points, normals;
  PointsAdaptor adaptor{&points};
  PointKdTree index;
  Data(std::vector<Eigen::Vector3d> p, std::vector<Eigen::Vector3d> n)
      : points(std::move(p)), normals(std::move(n)), index(3, adaptor, nanoflann::KDTreeSingleIndexAdaptorParams(16)) {
    index.buildIndex();
  }
};

std::size_t ModelCloud::size() const { return data_ ? data_->points.size() : 0; }
const Eigen::Vector3d& ModelCloud::point(std::size_t i) const { return data_->points[i]; }
const Eigen::Vector3d& ModelCloud::normal(std::size_t i) const { return data_->normals[i]; }

namespace {

Eigen::Matrix3d crossmat(const Eigen::Vector3d& a) {
  Eigen::Matrix3d m;
  m << 0.0, -a.z(), a.y(), a.z(), 0.0, -a.x(), -a.y(), a.x(), 0.0;
  return m;
}

/// A point of a triangle's curved PN patch (Vlachos et al. 2001): the cubic Bézier triangle through the
/// corners, tangent there to the planes of the vertex normals. (w, u, v): barycentric weights of a, b, c.
Eigen::Vector3d pn_point(const std::array<Eigen::Vector3d, 3>& p, const std::array<Eigen::Vector3d, 3>& n, double w, double u, double v) {
  auto edge = [&](int i, int j) { return (2.0 * p[static_cast<std::size_t>(i)] + p[static_cast<std::size_t>(j)] -
                                          (p[static_cast<std::size_t>(j)] - p[static_cast<std::size_t>(i)]).dot(n[static_cast<std::size_t>(i)]) * n[static_cast<std::size_t>(i)]) / 3.0; };
  const Eigen::Vector3d b210 = edge(0, 1), b120 = edge(1, 0), b021 = edge(1, 2), b012 = edge(2, 1), b102 = edge(2, 0), b201 = edge(0, 2);
  const Eigen::Vector3d e = (b210 + b120 + b021 + b012 + b102 + b201) / 6.0, mid = (p[0] + p[1] + p[2]) / 3.0;
  const Eigen::Vector3d b111 = e + (e - mid) / 2.0;
  return p[0] * w * w * w + p[1] * u * u * u + p[2] * v * v * v + 3.0 * (b210 * w * w * u + b120 * w * u * u + b201 * w * w * v +
                                                                         b021 * u * u * v + b102 * w * v * v + b012 * u * v * v) +
         6.0 * b111 * w * u * v;
}

}  // namespace

ModelCloud ModelCloud::from_mesh(const TriangleMesh& mesh, double spacing) {
  // A coarse mesh's flat triangles are chords, inside a convex surface by ~e²/8R (edge e, radius R: 0.1 mm
  // for 7 mm edges on a 60 mm radius), and point-to-plane ICP would pull every view that far along its
  // rays. Where the surface is smooth the target is the triangle's PN patch instead (its vertices lie on the
  // surface and their normals say how it bends); across a crease (a vertex normal more than ~25° off the
  // face's) the flat triangle is the better guess.
  const std::vector<Eigen::Vector3d> vn = area_weighted_normals(mesh);
  std::vector<Eigen::Vector3d> points, normals;
  for (const auto& t : mesh.triangles) {
    const std::array<Eigen::Vector3d, 3> p = {mesh.vertices[t[0]], mesh.vertices[t[1]], mesh.vertices[t[2]]};
    const Eigen::Vector3d fn = (p[1] - p[0]).cross(p[2] - p[0]);
    if (!(fn.norm() > 0.0)) continue;
    const Eigen::Vector3d n0 = fn.normalized();
    const std::array<Eigen::Vector3d, 3> n = {vn[t[0]], vn[t[1]], vn[t[2]]};
    const bool smooth = n[0].dot(n0) > 0.9 && n[1].dot(n0) > 0.9 && n[2].dot(n0) > 0.9;
    const double longest = std::max({(p[1] - p[0]).norm(), (p[2] - p[1]).norm(), (p[0] - p[2]).norm()});
    const int k = std::max(1, static_cast<int>(std::ceil(longest / spacing)));
    const double h = 1e-3;
    for (int i = 0; i <= k; ++i)
      for (int j = 0; i + j <= k; ++j) {
        const double u = static_cast<double>(i) / k, v = static_cast<double>(j) / k, w = 1.0 - u - v;
        if (!smooth) {
          points.push_back(w * p[0] + u * p[1] + v * p[2]);
          normals.push_back(n0);
          continue;
        }
        points.push_back(pn_point(p, n, w, u, v));
        // The patch's normal from its two tangents (central differences, within the patch's extension).
        const Eigen::Vector3d du = pn_point(p, n, w - h, u + h, v) - pn_point(p, n, w + h, u - h, v);
        const Eigen::Vector3d dv = pn_point(p, n, w - h, u, v + h) - pn_point(p, n, w + h, u, v - h);
        Eigen::Vector3d pn = du.cross(dv);
        pn = pn.norm() > 0.0 && pn.dot(n0) > 0.0 ? pn.normalized() : n0;
        normals.push_back(pn);
      }
  }
  ModelCloud c;
  c.data_ = std::make_shared<const Data>(std::move(points), std::move(normals));
  return c;
}

void ModelCloud::add(const std::vector<Eigen::Vector3d>& points, const std::vector<Eigen::Vector3d>& normals) {
  std::vector<Eigen::Vector3d> p = data_ ? data_->points : std::vector<Eigen::Vector3d>{};
  std::vector<Eigen::Vector3d> n = data_ ? data_->normals : std::vector<Eigen::Vector3d>{};
  p.insert(p.end(), points.begin(), points.end());
  n.insert(n.end(), normals.begin(), normals.end());
  data_ = std::make_shared<const Data>(std::move(p), std::move(n));
}

long ModelCloud::nearest(const Eigen::Vector3d& p, double max_mm) const {
  if (!data_ || data_->points.empty()) return -1;
  unsigned idx = 0;
  double d2 = 0.0;
  const double q[3] = {p.x(), p.y(), p.z()};
  if (data_->index.knnSearch(q, 1, &idx, &d2) != 1 || d2 > max_mm * max_mm) return -1;
  return static_cast<long>(idx);
}

namespace {

/// A sample's surface normal from its four image neighbours, turned towards the laser; zero at the image's
/// border, next to a missing sample, or across a depth step (a neighbour more than 5 mm away).
Eigen::Vector3d neighbour_normal(const RangeImage& img, int i, int j) {
  if (i < 1 || j < 1 || i + 1 >= img.columns || j + 1 >= img.rows) return Eigen::Vector3d::Zero();
  const RangeSample& s = img.at(i, j);
  const RangeSample &l = img.at(i - 1, j), &r = img.at(i + 1, j), &d = img.at(i, j - 1), &u = img.at(i, j + 1);
  if (!s.valid() || !l.valid() || !r.valid() || !d.valid() || !u.valid()) return Eigen::Vector3d::Zero();
  const Eigen::Vector3d a = (r.object_mm - l.object_mm).cast<double>(), b = (u.object_mm - d.object_mm).cast<double>();
  Eigen::Vector3d n = a.cross(b);
  if (!(n.norm() > 0.0) || a.norm() > 5.0 || b.norm() > 5.0) return Eigen::Vector3d::Zero();
  n.normalize();
  Eigen::Vector3d to_laser = -s.camera_mm.cast<double>();
  if (img.kind == SensorKind::line_scan) to_laser.y() = 0.0;
  return n.dot(img.pose.camera_to_object.linear() * to_laser) < 0.0 ? Eigen::Vector3d(-n) : n;
}

/// The pivot of a sample: on its profile's boresight (a line scan's profile at its own y), at the image's
/// mean depth. Turning a profile about any point of its boresight and shifting it is the same family of
/// motions as turning it about the laser; at the scene's depth the turn and the shift stay apart, where
/// about a laser 250 mm away a large turn and a large shift nearly cancel on the samples and the solve
/// could run off along them.
double pivot_depth(const RangeImage& img) {
  double z = 0.0;
  std::size_t n = 0;
  for (const auto& s : img.samples)
    if (s.valid()) {
      z += s.camera_mm.z();
      ++n;
    }
  return n ? z / static_cast<double>(n) : 0.0;
}

Eigen::Vector3d pivot_of(const RangeImage& img, const RangeSample& s, double depth) {
  return img.pose.camera_to_object * Eigen::Vector3d(0.0, img.kind == SensorKind::line_scan ? s.camera_mm.y() : 0.0, depth);
}

}  // namespace

void image_points_normals(const RangeImage& img, int stride, std::vector<Eigen::Vector3d>& pts,
                          std::vector<Eigen::Vector3d>& nrm) {
  for (int j = 1; j + 1 < img.rows; j += stride)
    for (int i = 1; i + 1 < img.columns; i += stride) {
      const Eigen::Vector3d n = neighbour_normal(img, i, j);
      if (n.isZero()) continue;
      pts.push_back(img.at(i, j).object_mm.cast<double>());
      nrm.push_back(n);
    }
}

ScanSamples scan_samples(const RangeImage& img) {
  ScanSamples out;
  const double depth = pivot_depth(img);
  for (int j = 0; j < img.rows; ++j)
    for (int i = 0; i < img.columns; ++i) {
      const RangeSample& s = img.at(i, j);
      if (!s.valid()) continue;
      out.points.push_back(s.object_mm.cast<double>());
      out.pivots.push_back(pivot_of(img, s, depth));
      out.normals.push_back(neighbour_normal(img, i, j));
    }
  return out;
}

IcpResult register_scan(const ScanSamples& s, const ModelCloud& model, const IcpOptions& o) {
  return register_points(s.points, model, o, s.pivots, s.normals);
}

void apply_correction(RangeImage& img, const Eigen::Isometry3d& c) {
  const Eigen::Matrix3d& w = c.linear();
  const double depth = pivot_depth(img);
  for (auto& s : img.samples)
    if (s.valid()) {
      const Eigen::Vector3d o = pivot_of(img, s, depth);
      s.object_mm = (w * (s.object_mm.cast<double>() - o) + o + c.translation()).cast<float>();
    }
  // The camera moves as the profile at y = 0 does: about the pivot on its boresight.
  const Eigen::Vector3d cam = img.pose.camera_to_object.translation();
  const Eigen::Vector3d o = img.pose.camera_to_object * Eigen::Vector3d(0.0, 0.0, depth);
  img.pose.camera_to_object.linear() = w * img.pose.camera_to_object.linear();
  img.pose.camera_to_object.translation() = w * (cam - o) + o + c.translation();
  const Eigen::Isometry3d to_view = img.pose.camera_to_object.inverse();
  for (auto& s : img.samples)
    if (s.valid()) s.camera_mm = (to_view * s.object_mm.cast<double>()).cast<float>();
}

namespace {

using Vec6 = Eigen::Matrix<double, 6, 1>;
using Mat6 = Eigen::Matrix<double, 6, 6>;

/// The samples ICP works on: at most ~20k, evenly strided (plenty for six unknowns, and the cost stays
/// bounded); where normals are known, a sample without one (an image border, a depth step) is left out: its
/// pair could only be checked by the offset direction, which lets a face's edge pair with the next face.
struct IcpSamples {
  std::vector<Eigen::Vector3d> pts, pivots, normals;
};
IcpSamples icp_samples(const std::vector<Eigen::Vector3d>& pts_in, const std::vector<Eigen::Vector3d>& pivots_in,
                       const std::vector<Eigen::Vector3d>& normals_in) {
  if (!pivots_in.empty() && pivots_in.size() != pts_in.size())
    throw std::invalid_argument("register_points: " + std::to_string(pivots_in.size()) + " pivots for " + std::to_string(pts_in.size()) + " points");
  if (!normals_in.empty() && normals_in.size() != pts_in.size())
    throw std::invalid_argument("register_points: " + std::to_string(normals_in.size()) + " normals for " + std::to_string(pts_in.size()) + " points");
  const std::size_t stride = std::max<std::size_t>(1, pts_in.size() / 20000);
  IcpSamples out;
  for (std::size_t i = 0; i < pts_in.size(); i += stride) {
    if (!normals_in.empty() && !(normals_in[i].squaredNorm() > 0.5)) continue;
    out.pts.push_back(pts_in[i]);
    out.pivots.push_back(pivots_in.empty() ? Eigen::Vector3d::Zero() : pivots_in[i]);
    out.normals.push_back(normals_in.empty() ? Eigen::Vector3d::Zero() : normals_in[i]);
  }
  return out;
}

/// One iteration's point-to-plane normal equations about the current correction (rotation w about each
/// sample's pivot, then translation d): ata x = atb, with disp the samples' own motion per unknown.
struct NormalEquations {
  Mat6 ata = Mat6::Zero(), disp = Mat6::Zero();
  Vec6 atb = Vec6::Zero();
  std::size_t pairs = 0;
  double ss = 0.0;
};
NormalEquations pair_with_model(const IcpSamples& s, const std::vector<Eigen::Vector3d>& moved, const std::vector<Eigen::Vector3d>& lever,
                                const Eigen::Matrix3d& w, const ModelCloud& model, const IcpOptions& o) {
  const double cos_max = std::cos(o.max_normal_angle_rad);
  NormalEquations e;
  for (std::size_t i = 0; i < s.pts.size(); ++i) {
    const Eigen::Vector3d& p = moved[i];
    const long k = model.nearest(p, o.max_distance_mm);
    if (k < 0) continue;
    const Eigen::Vector3d& q = model.point(static_cast<std::size_t>(k));
    const Eigen::Vector3d& n = model.normal(static_cast<std::size_t>(k));
    const Eigen::Vector3d off = p - q;
    if (s.normals[i].squaredNorm() > 0.5) {
      // The sample's own normal (turned with the correction) must agree with the model's.
      if ((w * s.normals[i]).dot(n) < cos_max) continue;
    } else if (off.norm() > 1e-9 && std::abs(off.normalized().dot(n)) < cos_max && off.norm() > 0.5 * o.max_distance_mm) {
      continue;  // normal unknown: reject pairs across thin walls by the offset direction
    }
    // Point-to-plane, linearised about the current correction: a motion (ω, v) moves the sample by
    // g = ω × l + v (l its lever from its pivot) and its residual n·(p - q) by n·g; rotations in units of
    // lever_mm so that the unknowns compare like with like.
    Eigen::Matrix<double, 3, 6> g;
    g.leftCols<3>() = -crossmat(lever[i]) / o.lever_mm;
    g.rightCols<3>().setIdentity();
    const Vec6 row = g.transpose() * n;
    const double res = n.dot(off);
    e.ata += row * row.transpose();
    e.disp += g.transpose() * g;
    e.atb -= row * res;
    e.ss += res * res;
    ++e.pairs;
  }
  return e;
}

/// Solves in the generalized eigenbasis (disp-orthonormal: x = Σ v_e (v_e·atb) / λ_e), leaving out the slides
/// (λ under min_conditioning), which it counts in r.free_directions. N unknowns: all six motions, or the
/// three plate motions (solve_plate_motions).
template <int N>
Eigen::Matrix<double, N, 1> solve_fixed_directions(const Eigen::GeneralizedSelfAdjointEigenSolver<Eigen::Matrix<double, N, N>>& es,
                                                   const Eigen::Matrix<double, N, 1>& atb, const IcpOptions& o, IcpResult& r) {
  Eigen::Matrix<double, N, 1> x = Eigen::Matrix<double, N, 1>::Zero();
  r.free_directions = 0;
  for (int e = 0; e < N; ++e) {
    const double lambda = es.eigenvalues()(e);
    if (lambda < o.min_conditioning) {
      ++r.free_directions;
      continue;
    }
    x += es.eigenvectors().col(e) * (es.eigenvectors().col(e).dot(atb) / lambda);
  }
  return x;
}

/// The plate motions (IcpOptions::plate_axis) as a basis of the six unknowns (ω·lever_mm, v): a turn θ about
/// the axis through P (as the samples have moved so far: P = W p0 + d, direction u = W u0) moves a sample at
/// lever l by θ u × (l + d − P), i.e. ω = θ u and v = θ u × (d − P); and the two shifts across u.
Eigen::Matrix<double, 6, 3> plate_basis(const IcpOptions::PlateAxis& a, const Eigen::Matrix3d& w, const Eigen::Vector3d& d,
                                        double lever_mm) {
  const Eigen::Vector3d u = (w * a.direction).normalized(), p = w * a.point + d;
  const Eigen::Vector3d e1 = u.unitOrthogonal(), e2 = u.cross(e1);
  Eigen::Matrix<double, 6, 3> b = Eigen::Matrix<double, 6, 3>::Zero();
  b.col(0) << u, u.cross(d - p) / lever_mm;
  b.col(1).tail<3>() = e1;
  b.col(2).tail<3>() = e2;
  return b;
}

/// solve_fixed_directions within the plate motions: the same generalized eigenproblem on the reduced
/// equations, the step mapped back to the six unknowns.
Vec6 solve_plate_motions(const NormalEquations& e, const Eigen::Matrix<double, 6, 3>& b, const IcpOptions& o, IcpResult& r) {
  const Eigen::Matrix3d a = b.transpose() * e.ata * b, disp = b.transpose() * e.disp * b;
  const Eigen::Vector3d atb = b.transpose() * e.atb;
  Eigen::GeneralizedSelfAdjointEigenSolver<Eigen::Matrix3d> es(a, disp);
  r.conditioning = es.eigenvalues()(0);
  r.weakest = (b * es.eigenvectors().col(0)).normalized();
  return b * solve_fixed_directions<3>(es, atb, o, r);
}

/// Trust region: no sample moves more than half the pairing distance in one step, so that a poorly fixed
/// direction cannot throw the view off the model before the correspondences catch up; and the view turns by
/// at most 0.05 rad (3°) a step, where the linearisation holds.
void limit_step(Vec6& x, const std::vector<Eigen::Vector3d>& lever, const IcpOptions& o) {
  double most = 0.0;
  const Eigen::Vector3d om = x.head<3>() / o.lever_mm;
  for (std::size_t i = 0; i < lever.size(); i += std::max<std::size_t>(1, lever.size() / 200))
    most = std::max(most, (om.cross(lever[i]) + x.tail<3>()).norm());
  if (most > 0.5 * o.max_distance_mm) x *= 0.5 * o.max_distance_mm / most;
  const double turn = x.head<3>().norm() / o.lever_mm;
  if (turn > 0.05) x *= 0.05 / turn;
}

/// An angle in degrees, to 0.1°.
std::string fmt_deg(double rad) {
  char b[32];
  std::snprintf(b, sizeof b, "%.1f", rad * 180.0 / std::numbers::pi);
  return b;
}

/// The converged correction's account: how far it moves the samples, refused when farther than the positioner
/// can err (a slide along a weakly fixed direction: a face with a sliver of another, not the pose error).
void accept(const IcpSamples& s, const Eigen::Matrix3d& w, const Eigen::Vector3d& d, const IcpOptions& o, IcpResult& r) {
  r.correction = Eigen::Isometry3d::Identity();
  r.correction.linear() = w;
  r.correction.translation() = d;
  double farthest = 0.0, sum = 0.0;
  for (std::size_t i = 0; i < s.pts.size(); ++i) {
    const double m = (w * (s.pts[i] - s.pivots[i]) + s.pivots[i] + d - s.pts[i]).norm();
    farthest = std::max(farthest, m);
    sum += m;
  }
  r.moved_mean_mm = sum / static_cast<double>(s.pts.size());
  r.moved_max_mm = farthest;
  if (farthest > o.max_distance_mm) {
    r.why = "the correction moves samples " + std::to_string(farthest) + " mm, beyond the pose error bound of " +
            std::to_string(o.max_distance_mm) + " mm (a slide along a weakly fixed direction; conditioning " +
            std::to_string(r.conditioning) + ")";
    return;
  }
  const double turn = Eigen::AngleAxisd(w).angle();
  if (turn > o.max_turn_rad) {
    r.why = "the correction turns the view " + fmt_deg(turn) + "°, beyond the pose error bound of " + fmt_deg(o.max_turn_rad) +
            "° (a fit the patch's shape lets settle turned; conditioning " + std::to_string(r.conditioning) + ", " +
            std::to_string(r.free_directions) + " directions free)";
    return;
  }
  r.ok = true;
  if (r.free_directions) r.why = "ill-conditioned in " + std::to_string(r.free_directions) + " of 6 directions: registered in the others";
}

}  // namespace

IcpResult register_points(const std::vector<Eigen::Vector3d>& pts_in, const ModelCloud& model, const IcpOptions& o,
                          const std::vector<Eigen::Vector3d>& pivots_in, const std::vector<Eigen::Vector3d>& normals_in) {
  IcpResult r;
  if (o.plate_axis && !pivots_in.empty())
    throw std::invalid_argument("register_points: plate motions are rigid motions; they take no pivots");
  const IcpSamples s = icp_samples(pts_in, pivots_in, normals_in);
  if (s.pts.size() < 50) {
    r.why = std::to_string(s.pts.size()) + " samples" + (normals_in.empty() ? "" : " with a surface normal") + ", too few to register";
    return r;
  }
  // The correction so far: rotation w about each point's pivot, then translation d (see the header).
  Eigen::Matrix3d w = Eigen::Matrix3d::Identity();
  Eigen::Vector3d d = Eigen::Vector3d::Zero();
  for (r.iterations = 1; r.iterations <= o.max_iterations; ++r.iterations) {
    std::vector<Eigen::Vector3d> moved(s.pts.size()), lever(s.pts.size());
    for (std::size_t i = 0; i < s.pts.size(); ++i) {
      lever[i] = w * (s.pts[i] - s.pivots[i]);  // from the moved pivot, pivot + d
      moved[i] = lever[i] + s.pivots[i] + d;
    }
    NormalEquations e = pair_with_model(s, moved, lever, w, model, o);
    r.overlap = static_cast<double>(e.pairs) / static_cast<double>(s.pts.size());
    if (r.overlap < o.min_overlap) {
      r.why = "too little overlap with the model (" + std::to_string(static_cast<int>(100 * r.overlap)) + " % of the samples)";
      return r;
    }
    r.rms_mm = std::sqrt(e.ss / static_cast<double>(e.pairs));
    // Which motions does the view's shape fix? For a motion x, x'·ata·x is how much it changes the residuals
    // and x'·disp·x how far it moves the samples: their ratio λ (0..1, the share of the motion across the
    // surface) is near 0 for a slide — along a plane, an edge, round a surface of revolution (thesis 8.2).
    // Judged on the samples' motion, not on the unknowns. A motion that moves no sample at all (a flat face's
    // stripes are lines: turning the camera about them changes nothing) is neither fixed nor a slide; the
    // ridge makes it cost a little, so that it reads as free and the fixed directions carry none of it.
    e.disp += Mat6::Identity() * (1e-4 * e.disp.trace() / 6.0);
    Vec6 x;
    if (o.plate_axis) {
      x = solve_plate_motions(e, plate_basis(*o.plate_axis, w, d, o.lever_mm), o, r);
    } else {
      Eigen::GeneralizedSelfAdjointEigenSolver<Mat6> es(e.ata, e.disp);
      r.conditioning = es.eigenvalues()(0);
      r.weakest = es.eigenvectors().col(0).normalized();
      x = solve_fixed_directions<6>(es, e.atb, o, r);
    }
    if (r.conditioning < o.min_conditioning && !o.partial) {
      r.why = "ill-conditioned: the view's shape does not fix its pose (conditioning " + std::to_string(r.conditioning) +
              "; a plane or a surface of revolution slides)";
      return r;
    }
    limit_step(x, lever, o);
    const Eigen::Vector3d omega = x.head<3>() / o.lever_mm, v = x.tail<3>();
    Eigen::Matrix3d step = Eigen::Matrix3d::Identity();
    if (omega.norm() > 0.0) step = Eigen::AngleAxisd(omega.norm(), omega.normalized()).toRotationMatrix();
    // Composition about the moved pivots: W(p - o) + o + d, then S(· - (o + d)) + o + d + v.
    w = step * w;
    d += v;
    // The largest motion of any sample under this step.
    double moved_most = 0.0;
    for (std::size_t i = 0; i < s.pts.size(); i += std::max<std::size_t>(1, s.pts.size() / 200))
      moved_most = std::max(moved_most, (step * lever[i] - lever[i] + v).norm());
    if (moved_most < o.converged_mm) {
      accept(s, w, d, o, r);
      return r;
    }
  }
  r.why = "did not converge in " + std::to_string(o.max_iterations) + " iterations";
  r.correction = Eigen::Isometry3d::Identity();
  r.correction.linear() = w;
  r.correction.translation() = d;
  return r;
}

IcpOptions for_model_error(IcpOptions o, double model_error_mm) {
  if (!(model_error_mm >= 0.0)) throw std::invalid_argument("for_model_error: model error " + std::to_string(model_error_mm) + " mm; must be >= 0");
  o.min_conditioning = std::max(o.min_conditioning, std::pow(model_error_mm / o.max_distance_mm, 2));
  return o;
}

double correction_weight(const PoseErrorModel& e, double range_mm, double model_sigma_mm) {
  const double pose2 = e.sigma_p_mm * e.sigma_p_mm + std::pow(e.sigma_a_rad * range_mm, 2);
  const double model2 = model_sigma_mm * model_sigma_mm;
  if (!(pose2 + model2 > 0.0)) return 1.0;
  return pose2 / (pose2 + model2);
}

Eigen::Isometry3d scale_correction(const Eigen::Isometry3d& c, double weight) {
  const Eigen::AngleAxisd turn(c.linear());
  Eigen::Isometry3d out = Eigen::Isometry3d::Identity();
  out.linear() = Eigen::AngleAxisd(weight * turn.angle(), turn.axis()).toRotationMatrix();
  out.translation() = weight * c.translation();
  return out;
}

}  // namespace scancell::planner
