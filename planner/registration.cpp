#include "planner/registration.hpp"

#include <algorithm>
#include <cmath>

#include <Eigen/Dense>
#include <nanoflann.hpp>

namespace scancell::planner {

namespace {
struct CloudAdaptor {
  const std::vector<Eigen::Vector3d>* pts;
  std::size_t kdtree_get_point_count() const { return pts->size(); }
  double kdtree_get_pt(std::size_t i, std::size_t d) const { return (*pts)[i][static_cast<Eigen::Index>(d)]; }
  template <class B>
  bool kdtree_get_bbox(B&) const { return false; }
};
}  // namespace

struct ModelCloud::Data {
  std::vector<Eigen::Vector3d> points, normals;
  CloudAdaptor adaptor{&points};
  nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<double, CloudAdaptor>, CloudAdaptor, 3> index;
  Data(std::vector<Eigen::Vector3d> p, std::vector<Eigen::Vector3d> n)
      : points(std::move(p)), normals(std::move(n)), index(3, adaptor, nanoflann::KDTreeSingleIndexAdaptorParams(16)) {
    index.buildIndex();
  }
};

std::size_t ModelCloud::size() const { return data_ ? data_->points.size() : 0; }
const Eigen::Vector3d& ModelCloud::point(std::size_t i) const { return data_->points[i]; }
const Eigen::Vector3d& ModelCloud::normal(std::size_t i) const { return data_->normals[i]; }

ModelCloud ModelCloud::from_mesh(const TriangleMesh& mesh, double spacing) {
  std::vector<Eigen::Vector3d> points, normals;
  for (const auto& t : mesh.triangles) {
    const Eigen::Vector3d a = mesh.vertices[t[0]], b = mesh.vertices[t[1]], d = mesh.vertices[t[2]];
    const Eigen::Vector3d n = (b - a).cross(d - a);
    if (!(n.norm() > 0.0)) continue;
    const double longest = std::max({(b - a).norm(), (d - b).norm(), (a - d).norm()});
    const int k = std::max(1, static_cast<int>(std::ceil(longest / spacing)));
    for (int i = 0; i <= k; ++i)
      for (int j = 0; i + j <= k; ++j) {
        points.push_back(a + (b - a) * (static_cast<double>(i) / k) + (d - a) * (static_cast<double>(j) / k));
        normals.push_back(n.normalized());
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

void image_points_normals(const RangeImage& img, int stride, std::vector<Eigen::Vector3d>& pts,
                          std::vector<Eigen::Vector3d>& nrm) {
  const Eigen::Matrix3d rot = img.pose.camera_to_object.linear();
  for (int j = 1; j + 1 < img.rows; j += stride)
    for (int i = 1; i + 1 < img.columns; i += stride) {
      const RangeSample& s = img.at(i, j);
      const RangeSample &l = img.at(i - 1, j), &r = img.at(i + 1, j), &d = img.at(i, j - 1), &u = img.at(i, j + 1);
      if (!s.valid() || !l.valid() || !r.valid() || !d.valid() || !u.valid()) continue;
      const Eigen::Vector3d a = (r.object_mm - l.object_mm).cast<double>(), b = (u.object_mm - d.object_mm).cast<double>();
      Eigen::Vector3d n = a.cross(b);
      // Neighbours across a depth step are not a surface.
      if (!(n.norm() > 0.0) || a.norm() > 5.0 || b.norm() > 5.0) continue;
      n.normalize();
      Eigen::Vector3d to_laser = -s.camera_mm.cast<double>();
      if (img.kind == SensorKind::line_scan) to_laser.y() = 0.0;
      if (n.dot(rot * to_laser) < 0.0) n = -n;
      pts.push_back(s.object_mm.cast<double>());
      nrm.push_back(n);
    }
}

void apply_correction(RangeImage& img, const Eigen::Isometry3d& c) {
  for (auto& s : img.samples)
    if (s.valid()) s.object_mm = (c * s.object_mm.cast<double>()).cast<float>();
  img.pose.camera_to_object = c * img.pose.camera_to_object;
}

IcpResult register_points(const std::vector<Eigen::Vector3d>& pts_in, const ModelCloud& model, const IcpOptions& o) {
  IcpResult r;
  // At most ~20k samples, evenly strided: plenty for six unknowns, and the cost stays bounded.
  const std::size_t stride = std::max<std::size_t>(1, pts_in.size() / 20000);
  std::vector<Eigen::Vector3d> pts;
  for (std::size_t i = 0; i < pts_in.size(); i += stride) pts.push_back(pts_in[i]);
  if (pts.size() < 50) {
    r.why = std::to_string(pts_in.size()) + " samples, too few to register";
    return r;
  }
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  const double cos_max = std::cos(o.max_normal_angle_rad);
  Eigen::Matrix<double, 6, 6> ata = Eigen::Matrix<double, 6, 6>::Zero();
  for (r.iterations = 1; r.iterations <= o.max_iterations; ++r.iterations) {
    ata.setZero();
    Eigen::Matrix<double, 6, 1> atb = Eigen::Matrix<double, 6, 1>::Zero();
    std::size_t pairs = 0;
    double ss = 0.0;
    std::vector<Eigen::Vector3d> moved(pts.size());
    for (std::size_t i = 0; i < pts.size(); ++i) moved[i] = t * pts[i];
    // Neighbours of all samples of this iteration first (the tree is read-only), then the normal equations.
    for (std::size_t i = 0; i < pts.size(); ++i) {
      const Eigen::Vector3d& p = moved[i];
      const long k = model.nearest(p, o.max_distance_mm);
      if (k < 0) continue;
      const Eigen::Vector3d& q = model.point(static_cast<std::size_t>(k));
      const Eigen::Vector3d& n = model.normal(static_cast<std::size_t>(k));
      // The sample's own normal is unknown here; reject pairs across thin walls by the offset direction.
      const Eigen::Vector3d d = p - q;
      if (d.norm() > 1e-9 && std::abs(d.normalized().dot(n)) < cos_max && d.norm() > 0.5 * o.max_distance_mm) continue;
      // Point-to-plane, linearised about the current pose: residual n·(p - q) + (p × n)·ω + n·v; rotations in
      // units of the lever so that the normal matrix compares like with like.
      Eigen::Matrix<double, 6, 1> row;
      row.head<3>() = p.cross(n) / o.lever_mm;
      row.tail<3>() = n;
      const double res = n.dot(d);
      ata += row * row.transpose();
      atb -= row * res;
      ss += res * res;
      ++pairs;
    }
    r.overlap = static_cast<double>(pairs) / static_cast<double>(pts.size());
    if (r.overlap < o.min_overlap) {
      r.why = "too little overlap with the model (" + std::to_string(static_cast<int>(100 * r.overlap)) + " % of the samples)";
      return r;
    }
    r.rms_mm = std::sqrt(ss / static_cast<double>(pairs));
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 6, 6>> es(ata);
    r.conditioning = es.eigenvalues()(0) / es.eigenvalues()(5);
    r.weakest = es.eigenvectors().col(0);
    if (r.conditioning < o.min_conditioning && !o.partial) {
      r.why = "ill-conditioned: the view's shape does not fix its pose (conditioning " + std::to_string(r.conditioning) +
              "; a plane or a surface of revolution slides)";
      return r;
    }
    // Solve in the eigenbasis, leaving out the motions the view's shape does not constrain.
    Eigen::Matrix<double, 6, 1> x = Eigen::Matrix<double, 6, 1>::Zero();
    r.free_directions = 0;
    for (int e = 0; e < 6; ++e) {
      const double lambda = es.eigenvalues()(e);
      if (lambda < o.min_conditioning * es.eigenvalues()(5)) {
        ++r.free_directions;
        continue;
      }
      x += es.eigenvectors().col(e) * (es.eigenvectors().col(e).dot(atb) / lambda);
    }
    const Eigen::Vector3d w = x.head<3>() / o.lever_mm, v = x.tail<3>();
    Eigen::Isometry3d step = Eigen::Isometry3d::Identity();
    if (w.norm() > 0.0) step.linear() = Eigen::AngleAxisd(w.norm(), w.normalized()).toRotationMatrix();
    step.translation() = v;
    t = step * t;
    // The largest motion of any sample under this step.
    double moved_most = 0.0;
    for (std::size_t i = 0; i < pts.size(); i += std::max<std::size_t>(1, pts.size() / 200))
      moved_most = std::max(moved_most, (step * moved[i] - moved[i]).norm());
    if (moved_most < o.converged_mm) {
      r.ok = true;
      r.correction = t;
      if (r.free_directions) r.why = "ill-conditioned in " + std::to_string(r.free_directions) + " of 6 directions: registered in the others";
      return r;
    }
  }
  r.why = "did not converge in " + std::to_string(o.max_iterations) + " iterations";
  r.correction = t;
  return r;
}

}  // namespace scancell::planner
