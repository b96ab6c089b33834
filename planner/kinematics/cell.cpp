#include "planner/kinematics/cell.hpp"

#include <algorithm>
#include <cmath>
#include <memory>
#include <numbers>

#include <Eigen/QR>

#include <fcl/geometry/bvh/BVH_model.h>
#include <fcl/geometry/shape/box.h>
#include <fcl/narrowphase/collision.h>
#include <fcl/narrowphase/detail/traversal/collision/mesh_shape_collision_traversal_node.h>
#include <fcl/narrowphase/detail/traversal/collision_node.h>
#include <kdl/chain.hpp>
#include <kdl/chainfksolverpos_recursive.hpp>
#include <kdl/chainiksolverpos_lma.hpp>
#include <kdl/chainjnttojacsolver.hpp>
#include <kdl/frames.hpp>

#include "common/errors.hpp"
#include "planner/kinematics/arm_ik.hpp"

namespace scancell::planner {
namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;
constexpr double kTol = 1e-9;

Eigen::Isometry3d rot_z(double a) {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.linear() = Eigen::AngleAxisd(a, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  return t;
}

/// turntable_lift_tilt camera axes at tilt φ: y = world +Y, boresight (−z) = (−cos φ, 0, −sin φ).
Eigen::Matrix3d tilt_rotation(double phi) {
  Eigen::Matrix3d r;
  r.col(0) = Eigen::Vector3d(std::sin(phi), 0.0, -std::cos(phi));
  r.col(1) = Eigen::Vector3d::UnitY();
  r.col(2) = Eigen::Vector3d(std::cos(phi), 0.0, std::sin(phi));
  return r;
}

/// The angle equal to `a` modulo 2π that lies within [lo, hi] and nearest `near`; nullopt if none.
std::optional<double> wrap_into(double a, double lo, double hi, double near) {
  std::optional<double> best;
  const double base = a + kTwoPi * std::round((near - a) / kTwoPi);
  for (int k = -2; k <= 2; ++k) {
    const double c = base + k * kTwoPi;
    if (c < lo - kTol || c > hi + kTol) continue;
    if (!best || std::abs(c - near) < std::abs(*best - near)) best = std::clamp(c, lo, hi);
  }
  return best;
}

bool within(const Axis& a, double v) { return v >= a.min - kTol && v <= a.max + kTol; }

KDL::Chain arm_chain(const CellModel& c) {
  KDL::Chain chain;
  for (const auto& row : c.dh)
    chain.addSegment(KDL::Segment(KDL::Joint(KDL::Joint::RotZ), KDL::Frame::DH(row[0], row[1], row[2], row[3])));
  return chain;
}

Eigen::Isometry3d to_eigen(const KDL::Frame& f) {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  for (int r = 0; r < 3; ++r) {
    for (int k = 0; k < 3; ++k) t.linear()(r, k) = f.M(r, k);
    t.translation()[r] = f.p[r];
  }
  return t;
}

KDL::Frame to_kdl(const Eigen::Isometry3d& t) {
  const Eigen::Matrix3d& r = t.linear();
  return KDL::Frame(KDL::Rotation(r(0, 0), r(0, 1), r(0, 2), r(1, 0), r(1, 1), r(1, 2), r(2, 0), r(2, 1), r(2, 2)),
                    KDL::Vector(t.translation().x(), t.translation().y(), t.translation().z()));
}

double pose_error(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
  const double dp = (a.translation() - b.translation()).norm();
  const double dr = Eigen::AngleAxisd(a.linear().transpose() * b.linear()).angle();
  return std::max(dp, dr);
}

}  // namespace

bool CellModel::arm_ik_closed_form() const {
  return arm_ik == ArmIkSolver::closed_form || (arm_ik == ArmIkSolver::automatic && has_ur_geometry(dh));
}

Eigen::Isometry3d table_to_world(const CellModel& c, double angle) {
  if (c.nominal_table_axis()) return rot_z(angle);
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.linear() = Eigen::AngleAxisd(angle, c.table_axis_direction.normalized()).toRotationMatrix();
  t.translation() = c.table_axis_point_mm - t.linear() * c.table_axis_point_mm;
  return t;
}

namespace {

/// The arm's camera in the object frame at axes `q`, by the solver `fk` of the cell's chain (arm_chain).
Eigen::Isometry3d arm_camera_in_object(const CellModel& c, KDL::ChainFkSolverPos_recursive& fk, const JointVector& q) {
  KDL::JntArray j(6);
  for (int k = 0; k < 6; ++k) j(k) = q[1 + k];
  KDL::Frame flange;
  fk.JntToCart(j, flange);
  return (table_to_world(c, q[0]) * c.object_on_table).inverse() * c.arm_base * to_eigen(flange) * c.tool;
}

}  // namespace

Eigen::Isometry3d forward_kinematics(const CellModel& c, const JointVector& q) {
  if (q.size() != c.axes.size()) throw std::invalid_argument("forward_kinematics: one value per axis");
  if (c.kinematics != CellKinematics::turntable_lift_tilt) {
    const KDL::Chain chain = arm_chain(c);
    KDL::ChainFkSolverPos_recursive fk(chain);
    return arm_camera_in_object(c, fk, q);
  }
  const double reach = q[1], lift = q[2], tilt = q[3], sweep = q[4];
  Eigen::Isometry3d camera_to_world = Eigen::Isometry3d::Identity();
  camera_to_world.linear() = tilt_rotation(tilt);
  camera_to_world.translation() = Eigen::Vector3d(reach, sweep, lift) + tilt_rotation(tilt) * c.camera_offset_mm;
  return (table_to_world(c, q[0]) * c.object_on_table).inverse() * camera_to_world;
}

IkResult look_at(const CellModel& cell, const Eigen::Vector3d& p, double standoff, double tilt, double table,
                 double scan_length) {
  const Eigen::Isometry3d object_to_world = table_to_world(cell, table) * cell.object_on_table;
  const Eigen::Vector3d z(std::cos(tilt), 0.0, std::sin(tilt)), y = Eigen::Vector3d::UnitY();
  Eigen::Isometry3d camera_to_world = Eigen::Isometry3d::Identity();
  camera_to_world.linear().col(0) = y.cross(z);
  camera_to_world.linear().col(1) = y;
  camera_to_world.linear().col(2) = z;
  camera_to_world.translation() = object_to_world * p + standoff * z;
  return inverse_kinematics(cell, object_to_world.inverse() * camera_to_world, scan_length);
}

namespace {

const char* const kLiftTiltAxes[] = {"turntable", "reach", "lift", "tilt", "sweep"};

/// The first of axes 1-4 of a turntable_lift_tilt cell outside its limits, or nothing.
std::optional<std::string> lift_tilt_out_of_limits(const CellModel& c, const JointVector& q) {
  for (int k = 1; k < 5; ++k)
    if (!within(c.axes[k], q[k])) return std::string(kLiftTiltAxes[k]) + " out of its limits";
  return std::nullopt;
}

/// A calibrated axis tilted off world Z: the nominal solution polished with Gauss-Newton on the pose error
/// (positions in mm, rotations in rad on a 1 m lever); five axes cannot follow a baseline the tilt has taken
/// off the horizontal, so what remains is a rotation of at most the tilt. False when that does not hold.
bool polish_for_tilted_axis(const CellModel& c, const Eigen::Isometry3d& desired, JointVector& q) {
  const double tilt = std::acos(std::clamp(c.table_axis_direction.normalized().z(), -1.0, 1.0));
  auto error = [&](const JointVector& x) {
    const Eigen::Isometry3d now = forward_kinematics(c, x);
    Eigen::Matrix<double, 6, 1> e;
    e.head<3>() = desired.translation() - now.translation();
    const Eigen::AngleAxisd w(Eigen::Quaterniond(desired.linear() * now.linear().transpose()).normalized());
    e.tail<3>() = 1000.0 * w.angle() * w.axis();
    return e;
  };
  for (int it = 0; it < 10; ++it) {
    const Eigen::Matrix<double, 6, 1> e0 = error(q);
    if (e0.norm() < 1e-10) break;
    Eigen::Matrix<double, 6, 5> jac;
    for (int k = 0; k < 5; ++k) {
      JointVector a = q, b = q;
      const double h = 1e-6;
      a[k] += h;
      b[k] -= h;
      jac.col(k) = -(error(a) - error(b)) / (2 * h);
    }
    const Eigen::Matrix<double, 5, 1> dq = jac.completeOrthogonalDecomposition().solve(e0);
    for (int k = 0; k < 5; ++k) q[k] += dq[k];
    if (dq.norm() < 1e-12) break;
  }
  const Eigen::Isometry3d got = forward_kinematics(c, q);
  const double rot = Eigen::AngleAxisd(got.linear().transpose() * desired.linear()).angle();
  return (got.translation() - desired.translation()).norm() <= 1e-3 && rot <= tilt + 1e-6;
}

/// turntable_lift_tilt in closed form: the table turns the baseline onto world Y, the tilt follows the
/// boresight's elevation, reach / lift / sweep the camera's position.
IkResult ik_lift_tilt(const CellModel& c, const Eigen::Isometry3d& desired, const Eigen::Isometry3d& camera_to_table,
                      double scan_length_mm, const JointVector& near) {
  IkResult res;
  const Axis& table = c.axes[0];
  const Eigen::Vector3d y = camera_to_table.linear().col(1);
  // A calibrated axis tilted off world Z tilts the table frame: the baseline may then lean by the tilt.
  const double lean = c.nominal_table_axis() ? kTol : std::sin(std::acos(std::clamp(c.table_axis_direction.z(), -1.0, 1.0))) + 1e-9;
  if (std::abs(y.z()) > lean) {
    res.why = "baseline not horizontal (this cell keeps camera y along world Y)";
    return res;
  }
  const auto theta = wrap_into(std::numbers::pi / 2 - std::atan2(y.y(), y.x()), table.min, table.max, near[0]);
  if (!theta) {
    res.why = "turntable: angle outside its limits";
    return res;
  }
  const Eigen::Isometry3d camera_to_world = rot_z(*theta) * camera_to_table;
  const Eigen::Vector3d z = camera_to_world.linear().col(2);
  const double phi = std::atan2(z.z(), z.x());
  const Eigen::Vector3d pivot = camera_to_world.translation() - tilt_rotation(phi) * c.camera_offset_mm;
  JointVector q = {*theta, pivot.x(), pivot.z(), phi, pivot.y()};
  if (const auto why = lift_tilt_out_of_limits(c, q)) {
    res.why = *why;
    return res;
  }
  if (!c.nominal_table_axis()) {
    if (!polish_for_tilted_axis(c, desired, q)) {
      res.why = "not reachable with the calibrated turntable axis";
      return res;
    }
    if (const auto why = lift_tilt_out_of_limits(c, q)) {
      res.why = *why;
      return res;
    }
  }
  const Axis& sweep = c.axes[4];
  if (q[4] - 0.5 * scan_length_mm < sweep.min - kTol || q[4] + 0.5 * scan_length_mm > sweep.max + kTol) {
    res.why = "sweep cannot travel the scan length here";
    return res;
  }
  res.ok = true;
  res.q = q;
  return res;
}

/// Newton steps with the exact Jacobian and an exact rotation error (quaternion log map) finish what LMA
/// started: KDL's own rotation error (via acos) cannot see below ~1e-8 rad, 1e-6 mm at the camera.
void polish_arm(KDL::ChainFkSolverPos_recursive& fk, KDL::ChainJntToJacSolver& jacobian, const Eigen::Isometry3d& goal, KDL::JntArray& out) {
  for (int polish = 0; polish < 12; ++polish) {
    KDL::Frame at;
    fk.JntToCart(out, at);
    const Eigen::Isometry3d now = to_eigen(at);
    if (pose_error(now, goal) < 1e-12) break;
    Eigen::Matrix<double, 6, 1> err;
    err.head<3>() = goal.translation() - now.translation();
    const Eigen::AngleAxisd w(Eigen::Quaterniond(goal.linear() * now.linear().transpose()).normalized());
    err.tail<3>() = w.angle() * w.axis();
    KDL::Jacobian jac(6);
    jacobian.JntToJac(out, jac);
    const Eigen::Matrix<double, 6, 1> dq = jac.data.completeOrthogonalDecomposition().solve(err);
    for (int k = 0; k < 6; ++k) out(k) += dq[k];
  }
}

/// LMA iterations per seed: of 60k solves for the box's plan with every row nothing measures aimed at (plan.cpp
/// make_matrix), 95 % converged in under 100 and 4 % stalled to the former cap of 2000, those 4 % being 80 % of
/// the iterations; polish_arm finishes a slow converger from where LMA stops. The same plans on eight objects;
/// that plan 45 s -> 15 s.
constexpr unsigned kArmLmaIterations = 300;

/// An arm solution `out` (joint angles of the chain) at turntable angle `theta`, polished, wrapped into the
/// joint limits nearest `near` and checked by forward kinematics against `desired`; nothing when it fails.
std::optional<JointVector> accept_arm_solution(const CellModel& c, double theta, KDL::JntArray out, const Eigen::Isometry3d& desired,
                                               const Eigen::Isometry3d& flange, const JointVector& near,
                                               KDL::ChainFkSolverPos_recursive& fk, KDL::ChainJntToJacSolver& jacobian) {
  polish_arm(fk, jacobian, flange, out);
  JointVector q(7);
  q[0] = theta;
  for (int k = 0; k < 6; ++k) {
    const auto w = wrap_into(out(k), c.axes[1 + k].min, c.axes[1 + k].max, near[1 + k]);
    if (!w) return std::nullopt;
    q[1 + k] = *w;
  }
  if (pose_error(arm_camera_in_object(c, fk, q), desired) > kTol) return std::nullopt;
  return q;
}

/// The Universal Robots geometry in closed form (arm_ik.hpp): of every branch within the joint limits, the one
/// the axes reach soonest from `near`.
std::optional<JointVector> ur_arm_solution(const CellModel& c, double theta, const Eigen::Isometry3d& desired,
                                           const Eigen::Isometry3d& flange, const JointVector& near,
                                           KDL::ChainFkSolverPos_recursive& fk, KDL::ChainJntToJacSolver& jacobian) {
  std::optional<JointVector> best;
  double best_time = 0.0;
  for (const auto& branch : ur_inverse_kinematics(c.dh, flange, near[6])) {
    KDL::JntArray out(6);
    for (int k = 0; k < 6; ++k) out(k) = branch[k];
    const auto q = accept_arm_solution(c, theta, out, desired, flange, near, fk, jacobian);
    if (!q) continue;
    const double t = move_time_s(c, near, *q);
    if (!best || t < best_time) {
      best = q;
      best_time = t;
    }
  }
  return best;
}

/// Any other DH chain: KDL's LMA from a few seeds about `near`, the first exact solution within the limits.
std::optional<JointVector> lma_arm_solution(const CellModel& c, const KDL::Chain& chain, double theta, const Eigen::Isometry3d& desired,
                                            const Eigen::Isometry3d& flange, const JointVector& near,
                                            KDL::ChainFkSolverPos_recursive& fk, KDL::ChainJntToJacSolver& jacobian) {
  // LMA's own verdict is not the test (it reports "increment too small" at a converged pose); the FK error is.
  // Weights: positions in mm, rotations in rad scaled by a 1 m lever, so both converge to 1e-9 at the camera.
  Eigen::Matrix<double, 6, 1> weights;
  weights << 1.0, 1.0, 1.0, 1000.0, 1000.0, 1000.0;
  KDL::ChainIkSolverPos_LMA ik(chain, weights, 1e-20, kArmLmaIterations, 1e-15);  // keeps a reference to chain
  KDL::JntArray s0(6);
  for (int k = 0; k < 6; ++k) s0(k) = near[1 + k];
  std::vector<KDL::JntArray> seeds{s0};
  for (double off : {0.8, -0.8, 1.6}) {
    KDL::JntArray s = s0;
    s(0) += off;
    s(2) -= 0.5 * off;
    seeds.push_back(s);
  }
  for (const auto& s : seeds) {
    KDL::JntArray out(6);
    // LMA can stall at ~1e-5 far from its seed; accept_arm_solution polishes from where it stopped (quadratically
    // close to the solution).
    ik.CartToJnt(s, to_kdl(flange), out);
    if (auto q = accept_arm_solution(c, theta, out, desired, flange, near, fk, jacobian)) return q;
  }
  return std::nullopt;
}

/// arm_turntable: turn the object so the camera stands on the arm's side, then solve the arm; accept only exact
/// solutions within the joint limits.
IkResult ik_arm(const CellModel& c, const Eigen::Isometry3d& desired, const Eigen::Isometry3d& camera_to_table, const JointVector& near) {
  IkResult res;
  const Axis& table = c.axes[0];
  const KDL::Chain chain = arm_chain(c);
  KDL::ChainFkSolverPos_recursive fk(chain);
  KDL::ChainJntToJacSolver jacobian(chain);
  if (c.arm_ik == ArmIkSolver::closed_form && !has_ur_geometry(c.dh)) {
    res.why = "arm: closed-form inverse kinematics needs the Universal Robots geometry (arm.ik)";
    return res;
  }
  const bool closed_form = c.arm_ik_closed_form();
  const Eigen::Vector3d p = camera_to_table.translation();
  const double arm_azimuth = std::atan2(c.arm_base.translation().y(), c.arm_base.translation().x());
  const double base_theta = arm_azimuth - std::atan2(p.y(), p.x());
  for (double dtheta : {0.0, 0.35, -0.35, 0.7, -0.7, 1.2, -1.2}) {
    const auto theta = wrap_into(base_theta + dtheta, table.min, table.max, near[0]);
    if (!theta) continue;
    const Eigen::Isometry3d flange = c.arm_base.inverse() * table_to_world(c, *theta) * camera_to_table * c.tool.inverse();
    const auto q = closed_form ? ur_arm_solution(c, *theta, desired, flange, near, fk, jacobian)
                               : lma_arm_solution(c, chain, *theta, desired, flange, near, fk, jacobian);
    if (q) {
      res.ok = true;
      res.q = *q;
      return res;
    }
  }
  res.why = "arm: no solution within the joint limits";
  return res;
}

}  // namespace

IkResult inverse_kinematics(const CellModel& c, const Eigen::Isometry3d& desired, double scan_length_mm,
                            const JointVector* seed) {
  const JointVector near = seed && seed->size() == c.axes.size() ? *seed : c.home();
  const Eigen::Isometry3d camera_to_table = c.object_on_table * desired;
  if (c.kinematics == CellKinematics::turntable_lift_tilt) return ik_lift_tilt(c, desired, camera_to_table, scan_length_mm, near);
  return ik_arm(c, desired, camera_to_table, near);
}

std::optional<Eigen::Isometry3d> nearest_reachable(const CellModel& c, const Eigen::Isometry3d& desired,
                                                   double scan_length_mm, JointVector* q, std::string* why) {
  IkResult r = inverse_kinematics(c, desired, scan_length_mm);
  if (r.ok) {
    if (q) *q = r.q;
    return desired;
  }
  if (c.kinematics != CellKinematics::turntable_lift_tilt) {
    if (why) *why = r.why;
    return std::nullopt;
  }
  // Turn the view about its boresight until the baseline is horizontal: y = ±normalize(Z × z).
  const Eigen::Isometry3d to_table = c.object_on_table;
  const Eigen::Matrix3d rt = (to_table * desired).linear();
  const Eigen::Vector3d z = rt.col(2);
  Eigen::Vector3d h = Eigen::Vector3d::UnitZ().cross(z);
  if (h.norm() < 1e-9) h = Eigen::Vector3d(rt.col(1).x(), rt.col(1).y(), 0.0);  // looking straight down or up
  if (h.norm() < 1e-12) h = Eigen::Vector3d::UnitY();
  h.normalize();
  std::optional<Eigen::Isometry3d> best;
  double best_turn = 1e9;
  std::string last_why = r.why;
  for (double sign : {1.0, -1.0}) {
    const Eigen::Vector3d y = sign * h;
    Eigen::Matrix3d m;
    m.col(1) = y;
    m.col(2) = z;
    m.col(0) = y.cross(z);
    Eigen::Isometry3d cand = desired;
    cand.linear() = to_table.linear().transpose() * m;
    const IkResult ri = inverse_kinematics(c, cand, scan_length_mm);
    if (!ri.ok) {
      last_why = ri.why;
      continue;
    }
    const double turn = std::acos(std::clamp(y.dot(rt.col(1)), -1.0, 1.0));
    if (turn < best_turn) {
      best_turn = turn;
      best = cand;
      if (q) *q = ri.q;
    }
  }
  if (!best && why) *why = last_why;
  return best;
}

double axis_move_time_s(const Axis& a, double distance) {
  const double d = std::abs(distance);
  if (d == 0.0) return 0.0;
  const double ramp = a.max_speed * a.max_speed / a.max_accel;  // distance to accelerate and brake
  if (d >= ramp) return d / a.max_speed + a.max_speed / a.max_accel;
  return 2.0 * std::sqrt(d / a.max_accel);
}

double move_time_s(const CellModel& c, const JointVector& from, const JointVector& to) {
  double t = 0.0;
  for (std::size_t k = 0; k < c.axes.size(); ++k) t = std::max(t, axis_move_time_s(c.axes[k], to[k] - from[k]));
  return t;
}

double scan_time_s(const CellModel& c, double scan_length_mm) { return scan_length_mm / c.scan_speed_mm_s; }

// ---- collisions (FCL) ----

struct CollisionChecker::Impl {
  const CellModel* cell;
  std::shared_ptr<fcl::BVHModel<fcl::OBBRSSd>> mesh;
  std::unique_ptr<fcl::CollisionObjectd> object;
  std::vector<std::unique_ptr<fcl::CollisionObjectd>> table_fixtures;  // in the object frame
};

CollisionChecker::CollisionChecker(const CellModel& cell, const TriangleMesh& object) : impl_(new Impl) {
  impl_->cell = &cell;
  impl_->mesh = std::make_shared<fcl::BVHModel<fcl::OBBRSSd>>();
  std::vector<fcl::Vector3d> pts(object.vertices.begin(), object.vertices.end());
  std::vector<fcl::Triangle> tris;
  for (const auto& t : object.triangles) tris.emplace_back(t[0], t[1], t[2]);
  impl_->mesh->beginModel();
  impl_->mesh->addSubModel(pts, tris);
  impl_->mesh->endModel();
  impl_->object = std::make_unique<fcl::CollisionObjectd>(impl_->mesh, fcl::Transform3d::Identity());
  const Eigen::Isometry3d table_to_object = cell.object_on_table.inverse();
  for (const auto& f : cell.fixtures) {
    if (!f.on_table) continue;  // world fixtures depend on the turntable angle: see collides()
    auto box = std::make_shared<fcl::Boxd>(f.box.max - f.box.min);
    fcl::Transform3d tf = fcl::Transform3d::Identity();
    tf.linear() = table_to_object.linear();
    tf.translation() = table_to_object * (0.5 * (f.box.min + f.box.max));
    impl_->table_fixtures.push_back(std::make_unique<fcl::CollisionObjectd>(box, tf));
  }
}

CollisionChecker::~CollisionChecker() { delete impl_; }

namespace {

/// Whether the triangle (a, b, c) and the box centred at the origin with half extents `h`, in the box's frame,
/// overlap: the separating-axis test of a box and a triangle (Akenine-Möller 2001), 13 axes (the box's three,
/// the triangle's normal, the nine edge × axis products); touching counts as overlap.
bool box_triangle_overlap(const Eigen::Vector3d& h, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                          const Eigen::Vector3d& c) {
  for (int k = 0; k < 3; ++k)
    if (std::min({a[k], b[k], c[k]}) > h[k] || std::max({a[k], b[k], c[k]}) < -h[k]) return false;
  const Eigen::Vector3d e[3] = {b - a, c - b, a - c};
  const Eigen::Vector3d n = e[0].cross(e[1]);
  if (std::abs(n.dot(a)) > h.dot(n.cwiseAbs())) return false;
  for (const auto& edge : e)
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d axis = Eigen::Vector3d::Unit(k).cross(edge);
      const double pa = axis.dot(a), pb = axis.dot(b), pc = axis.dot(c), r = h.dot(axis.cwiseAbs());
      if (std::min({pa, pb, pc}) > r || std::max({pa, pb, pc}) < -r) return false;
    }
  return true;
}

/// FCL's narrow phase for the traversal of the object's BVH against the body box: the exact separating-axis
/// test instead of FCL's GJK/MPR (libccd) on each leaf triangle, which took more than half the collision
/// checks' time (knot1 on the turntable: 8.6 % of the plan's CPU; docs/quality.md). FCL keeps the BVH and its
/// traversal; only the leaf test is this.
struct BoxTriangleSat {
  Eigen::Isometry3d mesh_to_box;  // the mesh's frame (tf1) into the box's (tf2), fixed over one traversal
  Eigen::Vector3d half;

  bool shapeTriangleIntersect(const fcl::Boxd&, const fcl::Transform3d&, const fcl::Vector3d& p1, const fcl::Vector3d& p2,
                              const fcl::Vector3d& p3, const fcl::Transform3d&, fcl::Vector3d* point, double* depth,
                              fcl::Vector3d* normal) const {
    // Contacts are never asked for (CollisionRequest::enable_contact is off); what they would read is defined.
    if (point) *point = (p1 + p2 + p3) / 3.0;
    if (depth) *depth = 0.0;
    if (normal) *normal = fcl::Vector3d::Zero();
    return box_triangle_overlap(half, mesh_to_box * p1, mesh_to_box * p2, mesh_to_box * p3);
  }
  // The base node's leaf test (an unoriented BVH, never taken for OBBRSS) must compile too.
  bool shapeTriangleIntersect(const fcl::Boxd& box, const fcl::Transform3d& tf, const fcl::Vector3d& p1, const fcl::Vector3d& p2,
                              const fcl::Vector3d& p3, fcl::Vector3d* point, double* depth, fcl::Vector3d* normal) const {
    return shapeTriangleIntersect(box, tf, p1, p2, p3, tf, point, depth, normal);
  }
};

}  // namespace

bool CollisionChecker::collides(const Eigen::Isometry3d& camera_to_object, double scan_length_mm) const {
  const CellModel& c = *impl_->cell;
  // The body grown by the clearance, and along camera y by the sweep's travel.
  Eigen::Vector3d lo = c.scanner_body.min.array() - c.clearance_mm, hi = c.scanner_body.max.array() + c.clearance_mm;
  lo.y() -= 0.5 * scan_length_mm;
  hi.y() += 0.5 * scan_length_mm;
  const fcl::Boxd box(hi - lo);
  fcl::Transform3d tf = fcl::Transform3d::Identity();
  tf.linear() = camera_to_object.linear();
  tf.translation() = camera_to_object * (0.5 * (lo + hi));
  fcl::CollisionRequestd req;
  {
    fcl::CollisionResultd res;
    BoxTriangleSat sat{Eigen::Isometry3d(tf.inverse(Eigen::Isometry)), 0.5 * (hi - lo)};
    fcl::detail::MeshShapeCollisionTraversalNodeOBBRSS<fcl::Boxd, BoxTriangleSat> node;
    fcl::detail::initialize(node, *impl_->mesh, fcl::Transform3d::Identity(), box, tf, &sat, req, res);
    fcl::detail::collide(&node);
    if (res.isCollision()) return true;
  }
  const fcl::CollisionObjectd body(std::make_shared<fcl::Boxd>(box), tf);
  for (const auto& f : impl_->table_fixtures) {
    fcl::CollisionResultd r2;
    fcl::collide(&body, f.get(), req, r2);
    if (r2.isCollision()) return true;
  }
  return false;
}

TriangleMesh fixture_mesh(const CellModel& c) {
  TriangleMesh m;
  const Eigen::Isometry3d table_to_object = c.object_on_table.inverse();
  for (const auto& f : c.fixtures) {
    const auto base = static_cast<std::uint32_t>(m.vertices.size());
    for (int k = 0; k < 8; ++k) {
      const Eigen::Vector3d corner((k & 1) ? f.box.max.x() : f.box.min.x(), (k & 2) ? f.box.max.y() : f.box.min.y(),
                                   (k & 4) ? f.box.max.z() : f.box.min.z());
      m.vertices.push_back(table_to_object * corner);
    }
    // Outward-wound faces of the box (corner bit 0: x, bit 1: y, bit 2: z).
    const int faces[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
    for (const auto& q : faces) {
      m.triangles.push_back({base + q[0], base + q[1], base + q[2]});
      m.triangles.push_back({base + q[0], base + q[2], base + q[3]});
    }
  }
  return m;
}

TriangleMesh with_fixtures(const TriangleMesh& object, const CellModel& c) {
  TriangleMesh m = object;
  append_mesh(m, fixture_mesh(c));
  return m;
}

std::vector<std::size_t> travel_order(const CellModel& c, const std::vector<JointVector>& targets, const JointVector& start) {
  const std::size_t n = targets.size();
  std::vector<std::size_t> order;
  if (n == 0) return order;
  // Nearest neighbour from the start.
  std::vector<char> used(n, 0);
  JointVector at = start;
  for (std::size_t k = 0; k < n; ++k) {
    std::size_t best = n;
    double bt = 1e300;
    for (std::size_t i = 0; i < n; ++i)
      if (!used[i]) {
        const double t = move_time_s(c, at, targets[i]);
        if (t < bt) bt = t, best = i;
      }
    used[best] = 1;
    order.push_back(best);
    at = targets[best];
  }
  // 2-opt on the open path start -> order[0] -> ... -> order[n-1].
  auto node = [&](std::ptrdiff_t i) -> const JointVector& { return i < 0 ? start : targets[order[static_cast<std::size_t>(i)]]; };
  for (bool improved = true; improved;) {
    improved = false;
    for (std::ptrdiff_t i = 0; i + 1 < static_cast<std::ptrdiff_t>(n); ++i)
      for (std::ptrdiff_t j = i + 1; j < static_cast<std::ptrdiff_t>(n); ++j) {
        // Reverse order[i..j]: edges (i-1, i) and (j, j+1) become (i-1, j) and (i, j+1).
        const double before = move_time_s(c, node(i - 1), node(i)) +
                              (j + 1 < static_cast<std::ptrdiff_t>(n) ? move_time_s(c, node(j), node(j + 1)) : 0.0);
        const double after = move_time_s(c, node(i - 1), node(j)) +
                             (j + 1 < static_cast<std::ptrdiff_t>(n) ? move_time_s(c, node(i), node(j + 1)) : 0.0);
        if (after < before - 1e-9) {
          std::reverse(order.begin() + i, order.begin() + j + 1);
          improved = true;
        }
      }
  }
  return order;
}

namespace {

double tour_move_s(const CellModel& c, const std::vector<JointVector>& targets, const std::vector<std::size_t>& order,
                   const JointVector& start) {
  double t = 0.0;
  const JointVector* at = &start;
  for (const auto k : order) {
    t += move_time_s(c, *at, targets[k]);
    at = &targets[k];
  }
  return t;
}

}  // namespace

Travel plan_travel(const CellModel& c, const std::vector<Eigen::Isometry3d>& poses, const std::vector<double>& scan_length_mm,
                   std::vector<JointVector> targets, const JointVector& start, int rounds) {
  if (poses.size() != targets.size() || scan_length_mm.size() != targets.size())
    throw std::invalid_argument("plan_travel: one pose, scan length and target per view");
  Travel best;
  best.order = travel_order(c, targets, start);
  best.targets = std::move(targets);
  best.move_s = tour_move_s(c, best.targets, best.order, start);
  for (int round = 0; round < rounds; ++round) {
    // Solved from the view before, a view may take another turn of the table or another arm branch: the
    // same camera pose, a shorter move. Every target stays an exact solution (a failed re-solve keeps its own).
    std::vector<JointVector> again = best.targets;
    const JointVector* at = &start;
    for (const auto k : best.order) {
      const IkResult r = inverse_kinematics(c, poses[k], scan_length_mm[k], at);
      if (r.ok) again[k] = r.q;
      at = &again[k];
    }
    std::vector<std::size_t> order = travel_order(c, again, start);
    const double t = tour_move_s(c, again, order, start);
    if (!(t < best.move_s - 1e-9)) break;
    best = {std::move(order), std::move(again), t};
  }
  return best;
}

}  // namespace scancell::planner
