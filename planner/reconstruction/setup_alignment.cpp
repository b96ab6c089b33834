#include "planner/reconstruction/setup_alignment.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>

#include <Eigen/Eigenvalues>

namespace scancell::planner {
namespace {

/// The turn by `angle` about the line through `c` along unit `axis`.
Eigen::Isometry3d turn_about(const Eigen::Vector3d& c, const Eigen::Vector3d& axis, double angle) {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.linear() = Eigen::AngleAxisd(angle, axis).toRotationMatrix();
  t.translation() = c - t.linear() * c;
  return t;
}

void moved(const Eigen::Isometry3d& t, const std::vector<Eigen::Vector3d>& p, const std::vector<Eigen::Vector3d>& n,
           std::vector<Eigen::Vector3d>& p_out, std::vector<Eigen::Vector3d>& n_out) {
  p_out.resize(p.size());
  n_out.resize(n.size());
  for (std::size_t i = 0; i < p.size(); ++i) p_out[i] = t * p[i];
  for (std::size_t i = 0; i < n.size(); ++i) n_out[i] = t.linear() * n[i];
}

/// Swing-twist: the rotation's turn about `axis` in (-π, π], and the angle of what is left (its tilt off it).
double turn_about_axis(const Eigen::Matrix3d& r, const Eigen::Vector3d& axis, double* tilt) {
  const Eigen::Quaterniond q(r);
  const double proj = q.vec().dot(axis);
  double turn = 2.0 * std::atan2(proj, q.w());
  if (turn > std::numbers::pi) turn -= 2.0 * std::numbers::pi;
  if (turn <= -std::numbers::pi) turn += 2.0 * std::numbers::pi;
  Eigen::Quaterniond twist(q.w(), axis.x() * proj, axis.y() * proj, axis.z() * proj);
  if (twist.norm() < 1e-12) twist = Eigen::Quaterniond::Identity();
  twist.normalize();
  const Eigen::Quaterniond swing = q * twist.inverse();
  *tilt = 2.0 * std::acos(std::min(1.0, std::abs(swing.w())));
  return turn;
}

/// How well the shape fixes the part on the plate: its turn about any axis parallel to the table's and its
/// shift across the plate, the three motions a misplaced part has. For the least fixed combination, the share
/// of its sample motion that crosses the surface (register_points' measure; 0: it slides, as a surface of
/// revolution turns about its own axis), over the samples pairing with the model within `max_mm`.
/// `turn_share`: how much of that least fixed motion is a turn (rotation scaled by `lever_mm`), 0..1.
double plate_conditioning(const std::vector<Eigen::Vector3d>& pts, const ModelCloud& model, const Eigen::Vector3d& c,
                          const Eigen::Vector3d& axis, double max_mm, double lever_mm, double* turn_share) {
  const Eigen::Vector3d u = axis.unitOrthogonal(), v = axis.cross(u);
  Eigen::Matrix3d ata = Eigen::Matrix3d::Zero(), disp = Eigen::Matrix3d::Zero();
  for (std::size_t i = 0; i < pts.size(); i += std::max<std::size_t>(1, pts.size() / 5000)) {
    const long k = model.nearest(pts[i], max_mm);
    if (k < 0) continue;
    Eigen::Matrix3d g;
    g << axis.cross(pts[i] - c) / lever_mm, u, v;
    const Eigen::Vector3d row = g.transpose() * model.normal(static_cast<std::size_t>(k));
    ata += row * row.transpose();
    disp += g.transpose() * g;
  }
  *turn_share = 0.0;
  if (!(disp.trace() > 0.0)) return 0.0;
  Eigen::GeneralizedSelfAdjointEigenSolver<Eigen::Matrix3d> es(ata, disp);
  const Eigen::Vector3d x = es.eigenvectors().col(0);
  *turn_share = std::abs(x(0)) / std::max(1e-12, x.norm());
  return es.eigenvalues()(0);
}

bool distinct(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b, const Eigen::Vector3d& centroid,
              const SetupAlignmentOptions& o) {
  const double angle = Eigen::AngleAxisd(a.linear() * b.linear().transpose()).angle();
  return angle > o.distinct_angle_rad || (a * centroid - b * centroid).norm() > o.distinct_shift_mm;
}

void validate(const std::vector<Eigen::Vector3d>& points, const std::vector<Eigen::Vector3d>& normals,
              const SetupAlignmentOptions& o) {
  if (!normals.empty() && normals.size() != points.size())
    throw std::invalid_argument("align_setup: " + std::to_string(normals.size()) + " normals for " +
                                std::to_string(points.size()) + " points");
  if (o.refined_outcomes < 1 || o.refined_outcomes > 360)
    throw std::invalid_argument("align_setup: refined_outcomes must be in [1, 360], got " + std::to_string(o.refined_outcomes));
  if (o.angle_steps < 1 || o.angle_steps > 360)
    throw std::invalid_argument("align_setup: angle_steps must be in [1, 360], got " + std::to_string(o.angle_steps));
  if (!(o.coarse_distance_mm > 0.0 && o.fine_distance_mm > 0.0 && o.max_rms_mm > 0.0))
    throw std::invalid_argument("align_setup: pairing distances and max_rms_mm must be > 0");
  if (!(o.axis_direction.norm() > 1e-9)) throw std::invalid_argument("align_setup: the table axis has no direction");
}

/// Coarse stage: a start at each of `angle_steps` turns about the table axis, on an even subset of the samples
/// with the wide pairing distance (the placement error's bound). One fit per start, in start order.
std::vector<SetupAlignmentFit> coarse_fits(const std::vector<Eigen::Vector3d>& points, const std::vector<Eigen::Vector3d>& normals,
                                           const ModelCloud& model, const Eigen::Vector3d& axis, const SetupAlignmentOptions& o) {
  const std::size_t stride = std::max<std::size_t>(1, points.size() / std::max<std::size_t>(1, o.coarse_samples));
  std::vector<Eigen::Vector3d> sub_p, sub_n, tp, tn;
  for (std::size_t i = 0; i < points.size(); i += stride) {
    sub_p.push_back(points[i]);
    if (!normals.empty()) sub_n.push_back(normals[i]);
  }
  // Partial: what the shape cannot fix (the height of a part with vertical walls, its tilt) stays where the
  // resting pose put it, which the plate fixes; the turn about the table axis is checked on its own below.
  IcpOptions coarse;
  coarse.partial = true;
  coarse.max_distance_mm = o.coarse_distance_mm;
  coarse.min_overlap = 0.5 * o.min_overlap;
  coarse.max_iterations = 25;  // a start only has to come near: the refinement converges
  coarse.converged_mm = 0.05;
  // Plate motions only: the part rests on the face the resting pose names, so the plate fixes its height and
  // tilt exactly; left free, the samples' noise and the model's facets would tilt the fit (0.035° on an
  // elephant, 0.05 mm at its centre).
  coarse.plate_axis = IcpOptions::PlateAxis{o.axis_point, axis};
  std::vector<SetupAlignmentFit> fits;
  for (int k = 0; k < o.angle_steps; ++k) {
    SetupAlignmentFit f;
    f.start_angle_rad = 2.0 * std::numbers::pi * k / o.angle_steps;
    const Eigen::Isometry3d start = turn_about(o.axis_point, axis, f.start_angle_rad);
    moved(start, sub_p, sub_n, tp, tn);
    const IcpResult icp = register_points(tp, model, coarse, {}, tn);
    f.ok = icp.ok;
    f.why = icp.why;
    f.rms_mm = icp.rms_mm;
    f.overlap = icp.overlap;
    f.correction = icp.correction * start;
    fits.push_back(f);
  }
  return fits;
}

/// Distinct coarse outcomes, best first (residual per paired share), at most `refined_outcomes`. A start still
/// moving after the coarse iterations is an outcome too.
std::vector<int> distinct_outcomes(const std::vector<SetupAlignmentFit>& fits, const Eigen::Vector3d& centroid,
                                   const SetupAlignmentOptions& o) {
  std::vector<int> order;
  for (int k = 0; k < static_cast<int>(fits.size()); ++k)
    if (fits[k].ok || fits[k].why.rfind("did not converge", 0) == 0) order.push_back(k);
  auto score = [&](int k) { return fits[k].rms_mm / std::max(1e-9, fits[k].overlap); };
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return score(a) < score(b); });
  std::vector<int> out;
  for (int k : order) {
    bool is_new = true;
    for (int d : out) is_new &= distinct(fits[k].correction, fits[d].correction, centroid, o);
    if (is_new) out.push_back(k);
    if (static_cast<int>(out.size()) == o.refined_outcomes) break;
  }
  return out;
}

/// The pairing of the fine stage: every sample, the fine distance, converged to 0.1 µm.
IcpOptions fine_options(const SetupAlignmentOptions& o) {
  IcpOptions fine;
  fine.partial = true;
  fine.max_distance_mm = o.fine_distance_mm;
  fine.min_overlap = o.min_overlap;
  fine.converged_mm = 1e-4;
  return fine;
}

/// Fine stage: each distinct outcome refined on every sample, about the table axis where that outcome put it.
void refine(std::vector<SetupAlignmentFit>& fits, const std::vector<int>& outcomes, const std::vector<Eigen::Vector3d>& points,
            const std::vector<Eigen::Vector3d>& normals, const ModelCloud& model, const Eigen::Vector3d& axis,
            const SetupAlignmentOptions& o) {
  IcpOptions fine = fine_options(o);
  std::vector<Eigen::Vector3d> tp, tn;
  for (int k : outcomes) {
    SetupAlignmentFit& f = fits[k];
    moved(f.correction, points, normals, tp, tn);
    fine.plate_axis = IcpOptions::PlateAxis{f.correction * o.axis_point, f.correction.linear() * axis};
    const IcpResult icp = register_points(tp, model, fine, {}, tn);
    f.refined = true;
    f.ok = icp.ok;
    f.why = icp.why;
    f.rms_mm = icp.rms_mm;
    f.overlap = icp.overlap;
    if (icp.ok) f.correction = icp.correction * f.correction;
    f.free_directions = icp.free_directions;
  }
}

/// Whether the shape fixes the best fit on the plate at all (a surface of revolution does not fix its turn);
/// false with `res.why` set when it does not.
bool shape_fixes_the_part(SetupAlignmentResult& res, const std::vector<Eigen::Vector3d>& points, const ModelCloud& model,
                          const Eigen::Vector3d& axis, const SetupAlignmentOptions& o) {
  std::vector<Eigen::Vector3d> at_best, unused;
  moved(res.correction, points, {}, at_best, unused);
  double turn_share = 0.0;
  res.plate_conditioning = plate_conditioning(at_best, model, res.correction * o.axis_point, res.correction.linear() * axis,
                                              o.fine_distance_mm, fine_options(o).lever_mm, &turn_share);
  if (res.plate_conditioning >= o.min_plate_conditioning) return true;
  res.ambiguous = true;
  res.why = std::string("the part's shape does not fix ") +
            (turn_share > 0.5 ? "its turn about the table axis" : "its position on the plate") + " (conditioning " +
            std::to_string(res.plate_conditioning) + ", limit " + std::to_string(o.min_plate_conditioning) +
            "): a part that slides so cannot be aligned by its shape; not merged";
  return false;
}

/// The verdict on the best refined fit: too large a residual, or a distinct pose that fits nearly as well (the
/// turn would be a guess), refuses the alignment with `res.why`; otherwise it is ok.
void judge(SetupAlignmentResult& res, int best, const std::vector<int>& outcomes, const Eigen::Vector3d& centroid,
           const Eigen::Vector3d& axis, const SetupAlignmentOptions& o) {
  const SetupAlignmentFit& b = res.fits[best];
  for (int k : outcomes) {
    const SetupAlignmentFit& f = res.fits[k];
    if (k == best || !f.ok || !distinct(f.correction, b.correction, centroid, o)) continue;
    if (res.runner_up < 0 || f.rms_mm < res.fits[res.runner_up].rms_mm) res.runner_up = k;
  }
  if (b.rms_mm > o.max_rms_mm) {
    res.why = "the best alignment leaves " + std::to_string(b.rms_mm) + " mm RMS (limit " + std::to_string(o.max_rms_mm) +
              " mm): the new setup does not match the model measured so far; not merged";
    return;
  }
  if (res.runner_up >= 0) {
    const SetupAlignmentFit& r = res.fits[res.runner_up];
    if (r.rms_mm <= o.ambiguity_rms_ratio * b.rms_mm && r.overlap >= o.ambiguity_overlap_ratio * b.overlap) {
      double tilt = 0.0;
      const double other = turn_about_axis(r.correction.linear(), axis, &tilt);
      res.ambiguous = true;
      res.why = "ambiguous: turns of " + std::to_string(res.turn_rad * 180.0 / std::numbers::pi) + " and " +
                std::to_string(other * 180.0 / std::numbers::pi) + " deg fit alike (" + std::to_string(b.rms_mm) + " and " +
                std::to_string(r.rms_mm) + " mm RMS): the part looks the same both ways; not merged";
      return;
    }
  }
  res.ok = true;
}

}  // namespace

SetupAlignmentResult align_setup(const std::vector<Eigen::Vector3d>& points, const std::vector<Eigen::Vector3d>& normals,
                                 const ModelCloud& model, const SetupAlignmentOptions& o) {
  validate(points, normals, o);
  SetupAlignmentResult res;
  const Eigen::Vector3d axis = o.axis_direction.normalized();
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const auto& p : points) centroid += p;
  if (!points.empty()) centroid /= static_cast<double>(points.size());

  res.fits = coarse_fits(points, normals, model, axis, o);
  const std::vector<int> outcomes = distinct_outcomes(res.fits, centroid, o);
  refine(res.fits, outcomes, points, normals, model, axis, o);

  int best = -1;
  for (int k : outcomes)
    if (res.fits[k].ok && (best < 0 || res.fits[k].rms_mm < res.fits[best].rms_mm)) best = k;
  if (best < 0) {
    // The reason of the most promising start (refined, when any start came near at all).
    const SetupAlignmentFit& first = outcomes.empty() ? res.fits.front() : res.fits[outcomes.front()];
    res.why = "no start of the " + std::to_string(o.angle_steps) + " turns aligned the new setup to the model (best: " +
              first.why + "): check the resting pose the operator used";
    return res;
  }
  const SetupAlignmentFit& b = res.fits[best];
  res.correction = b.correction;
  res.rms_mm = b.rms_mm;
  res.overlap = b.overlap;
  res.turn_rad = turn_about_axis(b.correction.linear(), axis, &res.tilt_rad);
  res.shift_mm = (b.correction * centroid - centroid).norm();
  res.free_directions = b.free_directions;
  if (shape_fixes_the_part(res, points, model, axis, o)) judge(res, best, outcomes, centroid, axis, o);
  return res;
}

}  // namespace scancell::planner
