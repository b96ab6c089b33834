// Cell-native candidates (cell_viewpoints.hpp) on a box on the turntable cell's plate: every candidate is a
// pose the axes reach with the scanner body clear; a top face is seen from the steepest tilt the axis has
// (clamped, not dropped); the bisector pair straddles a wall's normal by half the triangulation angle.
#include <cmath>
#include <numbers>

#include <gtest/gtest.h>

#include "planner/kinematics/cell.hpp"
#include "planner/core/cell_viewpoints.hpp"
#include "planner/core/measurability.hpp"
#include "planner/core/rough_model.hpp"
#include "planner/geometry/scene.hpp"
#include "test_meshes.hpp"

namespace sp = scancell::planner;

namespace {

struct BoxOnPlate {
  sp::CellModel cell = sp::load_cell(sp::testing::source_path("config/cells/turntable-lift-tilt.yaml"));
  sp::SensorModel sensor = sp::testing::thesis_sensor();
  sp::ModelSpec spec = sp::testing::thesis_spec();
  sp::ViewpointSettings settings;
  sp::RoughModel rough;
  std::vector<sp::Viewpoint> views;
  sp::CellGenerationReport report;
  BoxOnPlate() {
    sp::TriangleMesh box;
    sp::testing::add_box(box, {-50, -50, 0}, {50, 50, 60}, 10);  // on the table top (z = 0)
    rough = sp::make_rough_model(box);
    const sp::OcclusionScene scene(sp::with_fixtures(rough.mesh(), cell));
    settings.position_decimation = 2;
    const auto seeds = sp::generate_viewpoints(rough, scene, sensor, spec, settings);
    const sp::CollisionChecker checker(cell, rough.mesh());
    views = sp::cell_viewpoints(rough, seeds, sensor, spec, settings, cell, checker, &report);
  }
  Eigen::Isometry3d pose(const sp::Viewpoint& v) const {
    Eigen::Isometry3d p;
    p.matrix() = v.transform();
    return p;
  }
};

/// A slope rising from the plate along `up_slope` (x = 30 at z = 0) on the cell in `file`, facing the plate.
struct SlopeOnPlate {
  sp::RoughModel rough;
  sp::CellModel cell;
  sp::SensorModel sensor = sp::testing::thesis_sensor();
  sp::ModelSpec spec = sp::testing::thesis_spec();
  sp::ViewpointSettings settings;
  sp::OcclusionScene scene;
  sp::CollisionChecker checker;
  SlopeOnPlate(const Eigen::Vector3d& up_slope, const char* file)
      : rough(slope_rows(up_slope)),
        cell(sp::load_cell(sp::testing::source_path(file))),
        scene(sp::with_fixtures(rough.mesh(), cell)),
        checker(cell, rough.mesh()) {}
  static sp::RoughModel slope_rows(const Eigen::Vector3d& up_slope) {
    sp::TriangleMesh slope;
    sp::testing::add_grid(slope, {30.0, -30.0, 0.0}, Eigen::Vector3d::UnitY(), up_slope, 13, 10, 5.0);
    return sp::make_rough_model(slope);
  }
  /// The rows 1-10 mm over the plate (its top is the table's z = 0, the object frame's too), away from the sides.
  std::vector<std::uint32_t> low_rows() const {
    std::vector<std::uint32_t> out;
    for (std::uint32_t r = 0; r < rough.size(); ++r)
      if (rough.points[r].z() > 1.0 && rough.points[r].z() <= 10.0 && std::abs(rough.points[r].y()) <= 20.0) out.push_back(r);
    return out;
  }
  /// The cell's views aimed at row `r` along its normal at f_d·R_o.
  std::vector<sp::Viewpoint> views_of(std::uint32_t r) const {
    return sp::cell_viewpoints_at({{rough.points[r], rough.normals[r], 1.02 * sensor.optimal_standoff_mm, static_cast<std::int32_t>(r)}},
                                  sensor, spec, settings, cell, checker);
  }
};

}  // namespace

TEST(CellViewpoints, EveryCandidateIsReachableClearAndHasTheCellsTwist) {
  BoxOnPlate b;
  ASSERT_GT(b.views.size(), 100u);
  EXPECT_EQ(b.report.candidates, b.views.size());
  const sp::CollisionChecker checker(b.cell, b.rough.mesh());
  for (const auto& v : b.views) {
    const auto ik = sp::inverse_kinematics(b.cell, b.pose(v), v.scan_length_mm);
    ASSERT_TRUE(ik.ok) << ik.why;
    EXPECT_FALSE(checker.collides(b.pose(v), v.scan_length_mm));
    const Eigen::Vector3d y_table = (b.cell.object_on_table * b.pose(v)).linear().col(1);
    EXPECT_NEAR(y_table.z(), 0.0, 1e-9);  // the baseline lies horizontal
    // The stand-off is kept: the targeted point lies on the boresight at that distance.
    const Eigen::Vector3d target = b.rough.points[static_cast<std::size_t>(v.target_row)];
    EXPECT_NEAR((target - v.position).norm(), v.standoff_mm, 1e-9);
    EXPECT_NEAR((target - v.position).normalized().dot(v.axis), 1.0, 1e-9);
  }
}

TEST(CellViewpoints, ATopFaceIsSeenFromTheSteepestTiltNotDropped) {
  BoxOnPlate b;
  const double tilt_max = 1.40;  // config/cells/turntable-lift-tilt.yaml: tilt in [-1.40, 1.40] rad
  std::size_t top = 0;
  for (const auto& v : b.views) {
    const auto r = static_cast<std::size_t>(v.target_row);
    if (b.rough.normals[r].z() < 0.999999 || v.twist_level != 0) continue;
    ++top;
    // Looking down: the boresight's elevation is −tilt_max, not −90° (unreachable) and not dropped.
    EXPECT_NEAR(std::asin(v.axis.z()), -tilt_max, 1e-9);
  }
  EXPECT_GE(top, 3u);
  EXPECT_GE(b.report.clamped, top);
}

TEST(CellViewpoints, TheBisectorPairStraddlesAWallsNormalByHalfTheTriangulationAngle) {
  BoxOnPlate b;
  std::size_t pairs = 0;
  for (const auto& v : b.views) {
    const auto r = static_cast<std::size_t>(v.target_row);
    if (std::abs(b.rough.normals[r].x()) < 0.999999 || (v.twist_level != 1 && v.twist_level != 2)) continue;
    ++pairs;
    // atan(b / R) / 2 with b = 180 mm and the view's own stand-off (at R = 144.84 mm: 25.59°).
    const double half = 0.5 * std::atan2(180.0, v.standoff_mm);
    EXPECT_NEAR(std::acos(v.axis.dot(-b.rough.normals[r])), half, 1e-9);
    EXPECT_NEAR(v.axis.z(), 0.0, 1e-9);  // turned about the table axis only
  }
  EXPECT_GT(pairs, 5u);
}

// A replan's aim points (footprint_aims): views aimed at a point that is no rough-model row, along its own
// normal, each reachable and clear, the aim on its boresight at its stand-off, the row credited; the first
// (the thesis' view) looks straight along the wall's normal.
TEST(CellViewpoints, AViewAimedAtAPointOffTheRowsLooksAtItAlongItsOwnNormal) {
  BoxOnPlate b;
  const sp::AimPoint a{{50.0, 17.0, 31.0}, {1.0, 0.0, 0.0}, 1.02 * b.sensor.optimal_standoff_mm, 7};
  const sp::CollisionChecker checker(b.cell, b.rough.mesh());
  sp::CellGenerationReport rep;
  const auto views = sp::cell_viewpoints_at({a}, b.sensor, b.spec, b.settings, b.cell, checker, &rep);
  ASSERT_GE(views.size(), 3u);
  EXPECT_LE(views.size(), 5u);
  EXPECT_EQ(rep.seeds, 1u);
  EXPECT_EQ(rep.candidates, views.size());
  for (const auto& v : views) {
    EXPECT_EQ(v.target_row, 7);
    const auto ik = sp::inverse_kinematics(b.cell, b.pose(v), v.scan_length_mm);
    ASSERT_TRUE(ik.ok) << ik.why;
    EXPECT_FALSE(checker.collides(b.pose(v), v.scan_length_mm));
    EXPECT_GE(v.standoff_mm, a.standoff_mm - 1e-9);
    EXPECT_NEAR((a.point - v.position).norm(), v.standoff_mm, 1e-9);
    EXPECT_NEAR((a.point - v.position).normalized().dot(v.axis), 1.0, 1e-9);
  }
  ASSERT_EQ(views.front().twist_level, 0);
  EXPECT_NEAR(views.front().axis.dot(-a.normal), 1.0, 1e-9);
}

// arm_turntable: the wrist takes any twist, so a free candidate is kept as it is where the arm reaches it
// with the scanner body clear; where not, it steps back along its own boresight (same target, same
// orientation, a longer stand-off) instead of being dropped as projection (thesis 6.3.2) drops it.
TEST(CellViewpoints, TheArmKeepsFreeCandidatesAndStepsBackTheOnesThatWouldHitThePlate) {
  const sp::CellModel cell = sp::load_cell(sp::testing::source_path("config/cells/arm-turntable.yaml"));
  const sp::SensorModel sensor = sp::testing::thesis_sensor();
  const sp::ModelSpec spec = sp::testing::thesis_spec();
  sp::ViewpointSettings settings;
  settings.position_decimation = 2;
  sp::TriangleMesh box;
  sp::testing::add_box(box, {-50, -50, 0}, {50, 50, 30}, 10);  // low on the plate: its walls' views graze it
  const sp::RoughModel rough = sp::make_rough_model(box);
  const sp::OcclusionScene scene(sp::with_fixtures(rough.mesh(), cell));
  const auto seeds = sp::generate_viewpoints(rough, scene, sensor, spec, settings);
  const sp::CollisionChecker checker(cell, rough.mesh());
  sp::CellGenerationReport report;
  const auto views = sp::cell_viewpoints(rough, seeds, sensor, spec, settings, cell, checker, &report);
  ASSERT_TRUE(sp::has_cell_native_viewpoints(cell));
  EXPECT_EQ(report.seeds, seeds.size());
  EXPECT_EQ(report.candidates, views.size());
  EXPECT_EQ(report.candidates + report.unreachable + report.colliding, seeds.size());
  // What projection would keep: the seeds the arm reaches exactly with the body clear, but for those whose
  // camera stands below the plate's top (z = 0) aiming above it, which look through the plate and are lowered.
  std::size_t as_is = 0;
  for (const auto& s : seeds) {
    Eigen::Isometry3d p;
    p.matrix() = s.transform();
    const Eigen::Vector3d target = s.position + s.standoff_mm * s.axis;
    const bool through_plate = s.position.z() < 0.0 && target.z() > 0.0;
    as_is += !through_plate && sp::inverse_kinematics(cell, p, s.scan_length_mm).ok && !checker.collides(p, s.scan_length_mm);
  }
  EXPECT_GT(report.stepped_back, 0u);
  EXPECT_EQ(views.size(), as_is + report.stepped_back);
  std::size_t stepped = 0;
  for (const auto& v : views) {
    Eigen::Isometry3d p;
    p.matrix() = v.transform();
    ASSERT_TRUE(sp::inverse_kinematics(cell, p, v.scan_length_mm).ok);
    EXPECT_FALSE(checker.collides(p, v.scan_length_mm));
    // Every view still aims at its target row at its own stand-off.
    const Eigen::Vector3d target = rough.points[static_cast<std::size_t>(v.target_row)];
    EXPECT_NEAR((target - v.position).norm(), v.standoff_mm, 1e-6);
    EXPECT_NEAR((target - v.position).normalized().dot(v.axis), 1.0, 1e-9);
    stepped += v.standoff_mm > sensor.optimal_standoff_mm * settings.standoff_factor + 1.0;
  }
  EXPECT_GT(stepped, 0u);
}

namespace {

// A welded 20 mm cube on 8 vertices: each corner's normal is the mean of its three faces (54.7° from each).
sp::RoughModel welded_cube() {
  sp::TriangleMesh m;
  for (int k = 0; k < 8; ++k) m.vertices.emplace_back(k & 1 ? 20.0 : 0.0, k & 2 ? 20.0 : 0.0, k & 4 ? 20.0 : 0.0);
  m.triangles = {{0, 2, 1}, {1, 2, 3}, {4, 5, 6}, {5, 7, 6},   // -z, +z
                 {0, 1, 4}, {1, 5, 4}, {2, 6, 3}, {3, 6, 7},   // -y, +y
                 {0, 4, 2}, {2, 4, 6}, {1, 3, 5}, {3, 7, 5}};  // -x, +x
  return sp::make_rough_model(m);
}

}  // namespace

// A row nothing measures is aimed at square to each face that turns from its normal (face_aims): the cube's
// top corner gets the three face normals, each aimed inside its own footprint on that face; a threshold above
// the 54.7° they turn gives none, and a row of a flat patch none either.
TEST(FaceAims, ACornerIsAimedAtSquareToEachOfItsThreeFaces) {
  const sp::RoughModel cube = welded_cube();
  std::uint32_t corner = 0;
  for (std::uint32_t r = 0; r < cube.size(); ++r)
    if (cube.points[r].isApprox(Eigen::Vector3d(20, 20, 20))) corner = r;
  ASSERT_TRUE(cube.points[corner].isApprox(Eigen::Vector3d(20, 20, 20)));
  ASSERT_NEAR(cube.normals[corner].dot(Eigen::Vector3d::UnitZ()), 1.0 / std::sqrt(3.0), 1e-9);
  const auto aims = sp::face_aims(cube, {corner}, 20.0 * std::numbers::pi / 180.0, 150.0);
  ASSERT_EQ(aims.size(), 3u);
  std::vector<int> axes;
  for (const auto& a : aims) {
    EXPECT_EQ(a.row, static_cast<std::int32_t>(corner));
    EXPECT_DOUBLE_EQ(a.standoff_mm, 150.0);
    int axis = -1;
    for (int i = 0; i < 3; ++i)
      if (std::abs(a.normal[i] - 1.0) < 1e-12) axis = i;
    ASSERT_GE(axis, 0) << a.normal.transpose();
    axes.push_back(axis);
    // On that face (coordinate 20), within its triangle, between the corner and the centroid.
    EXPECT_NEAR(a.point[axis], 20.0, 1e-9);
    EXPECT_LT((a.point - cube.points[corner]).norm(), 10.0);
    EXPECT_GT((a.point - cube.points[corner]).norm(), 4.0);
  }
  std::sort(axes.begin(), axes.end());
  EXPECT_EQ(axes, (std::vector<int>{0, 1, 2}));
  EXPECT_TRUE(sp::face_aims(cube, {corner}, 60.0 * std::numbers::pi / 180.0, 150.0).empty());
  const sp::RoughModel patch = sp::make_rough_model(sp::testing::flat_patch(40.0, 4.0));
  std::uint32_t middle = 0;
  for (std::uint32_t r = 0; r < patch.size(); ++r)
    if (patch.points[r].norm() < patch.points[middle].norm()) middle = r;
  EXPECT_TRUE(sp::face_aims(patch, {middle}, 0.01, 150.0).empty());
  EXPECT_THROW(sp::face_aims(cube, {8}, 0.3, 150.0), std::out_of_range);
}

// A view's laser stands at least R_min from what it measures, within the widest incidence of the normal
// (atan √(tan² 70° + tan² 60°) = 72.9° for the thesis sensor): an aim blocked that near in every such
// direction gets no view (aims_open_to_sensor).
TEST(OpenAims, AFaceOnThePlateAndASlotFloorAreClosedTheRestOpen) {
  const BoxOnPlate b;
  const sp::OcclusionScene on_plate(sp::with_fixtures(b.rough.mesh(), b.cell));
  const Eigen::Vector3d X = Eigen::Vector3d::UnitX(), Z = Eigen::Vector3d::UnitZ();
  const std::vector<sp::AimPoint> aims{{{0, 0, 60}, Z, 150, 0},    // the top
                                       {{0, 0, 0}, -Z, 150, 1},    // the face resting on the plate
                                       {{50, 0, 1}, X, 150, 2},    // a wall's foot: the plate blocks half its cap
                                       {{-20, 10, 0}, -Z, 150, 3}};
  std::size_t closed = 0;
  const auto open = sp::aims_open_to_sensor(aims, on_plate, b.sensor, 0.01, &closed);
  ASSERT_EQ(open.size(), 2u);
  EXPECT_EQ(open[0].row, 0);  // in order
  EXPECT_EQ(open[1].row, 2);
  EXPECT_EQ(closed, 2u);
  // A slot 6 mm wide and 100 mm deep: its floor is open only within 2° of straight up, where neither the laser
  // nor the receiver, 24° apart at least (atan(b / R_max)), can both pass; a pocket 60 mm wide and 20 mm deep is open.
  const sp::OcclusionScene slot(sp::testing::square_cavity(6, 100, 40, 2));
  const sp::OcclusionScene pocket(sp::testing::square_cavity(60, 20, 80, 5));
  const std::vector<sp::AimPoint> floor{{{0, 0, -100}, Z, 150, 7}};
  const std::vector<sp::AimPoint> pocket_floor{{{0, 0, -20}, Z, 150, 8}};
  EXPECT_TRUE(sp::aims_open_to_sensor(floor, slot, b.sensor, 0.01).empty());
  EXPECT_EQ(sp::aims_open_to_sensor(pocket_floor, pocket, b.sensor, 0.01).size(), 1u);
  // The probes stop at R_min: with R_min 10 mm the slot's floor is open (its walls lie 40 mm along the steepest probe).
  sp::SensorModel near = b.sensor;
  near.range_min_mm = 10.0;
  EXPECT_EQ(sp::aims_open_to_sensor(floor, slot, near, 0.01).size(), 1u);
  const std::vector<sp::AimPoint> no_normal{{{0, 0, 0}, Eigen::Vector3d::Zero(), 150, 9}};
  EXPECT_EQ(sp::aims_open_to_sensor(no_normal, on_plate, b.sensor, 0.01).size(), 1u);  // not judged, kept
  EXPECT_THROW(sp::aims_open_to_sensor(aims, on_plate, b.sensor, 0.01, nullptr, 0), std::invalid_argument);
}

// A face turned to the plate, low above it (the underside of a part that flares out from its foot): a slope
// whose normal points 26.6° below the horizontal, from the plate top up to 40 mm. The thesis' view along the
// normal looks up from 65 mm below the point, and the oblique views 20° above and below it from 10-16 mm
// below: all look through the plate. The view is capped where its camera stands at the plate's height (the
// elevation asin(h / d) for a point h above the plate at stand-off d), and then measures the point at
// 26.6° − asin(h / d) incidence. On both cells, every row of the slope's lowest 10 mm gets such a view.
TEST(CellViewpoints, AFaceTurnedToThePlateIsSeenFromThePlatesHeightNotThroughIt) {
  const Eigen::Vector3d up_slope = Eigen::Vector3d(20.0, 0.0, 40.0).normalized();  // from x = 30 at z = 0 to x = 50 at z = 40
  const Eigen::Vector3d normal = Eigen::Vector3d::UnitY().cross(up_slope);  // (0.894, 0, −0.447)
  ASSERT_NEAR(std::asin(normal.z()), -std::atan(0.5), 1e-12);
  for (const char* file : {"config/cells/turntable-lift-tilt.yaml", "config/cells/arm-turntable.yaml"}) {
    SCOPED_TRACE(file);
    const SlopeOnPlate t(up_slope, file);
    const auto low = t.low_rows();
    EXPECT_GE(low.size(), 9u);
    for (const auto r : low) {
      const double h = t.rough.points[r].z();
      ASSERT_NEAR(t.rough.normals[r].dot(normal), 1.0, 1e-9);
      const auto views = t.views_of(r);
      ASSERT_FALSE(views.empty()) << "row at h " << h;
      // The first view: the thesis' view capped at the plate's height, elevation asin(h / d).
      const sp::Viewpoint& v = views.front();
      EXPECT_NEAR(std::asin(v.axis.z()), std::asin(h / v.standoff_mm), 1e-9) << "h " << h;
      EXPECT_NEAR(v.position.z(), 0.0, 1e-9);
      std::size_t measuring = 0;
      for (const auto& w : views) {
        EXPECT_GE(w.position.z(), -1e-9);  // no camera below the plate's top
        measuring += sp::measurable(t.rough, t.scene, t.sensor, t.spec, w, r);
      }
      EXPECT_GE(measuring, 1u) << "row at h " << h;
    }
  }
}

TEST(CellViewpoints, AFaceSteeplyTurnedToThePlateIsSweptShortEnoughToMeetTheDensity) {
  // The torus's underside band (generated_objects.hpp): a face whose normal points 63° below the horizontal,
  // 1-10 mm over the plate. Its views are capped level at the plate's height, so each sees it 62-64° off in
  // the x-z plane; at the design sweep (30°) the density there is 0.8-1.6 samples/mm² and no view measured it.
  const double down = 63.0 * std::numbers::pi / 180.0;
  const SlopeOnPlate t(Eigen::Vector3d(std::sin(down), 0.0, std::cos(down)), "config/cells/turntable-lift-tilt.yaml");
  const auto low = t.low_rows();
  EXPECT_GE(low.size(), 9u);
  for (const auto r : low) {
    const double h = t.rough.points[r].z();
    ASSERT_NEAR(std::asin(t.rough.normals[r].z()), -down, 1e-9);
    const auto views = t.views_of(r);
    ASSERT_FALSE(views.empty()) << "row at h " << h;
    std::size_t measuring = 0;
    for (const auto& v : views) {
      const double design = sp::design_scan_length_mm(t.sensor, t.spec, v.standoff_mm, t.settings.scan_length_design_incidence_rad);
      EXPECT_NEAR(v.scan_length_mm, sp::aimed_scan_length_mm(t.sensor, t.spec, v.standoff_mm, v.rotation(), t.rough.normals[r],
                                                             t.settings.scan_length_design_incidence_rad), 1e-9);
      EXPECT_LT(v.scan_length_mm, 0.8 * design) << "row at h " << h;
      if (!sp::measurable(t.rough, t.scene, t.sensor, t.spec, v, r)) continue;
      ++measuring;
      sp::Viewpoint at_design = v;  // the same pose swept at the design length misses the density spec there
      at_design.scan_length_mm = design;
      EXPECT_FALSE(sp::measurable(t.rough, t.scene, t.sensor, t.spec, at_design, r)) << "row at h " << h;
    }
    EXPECT_GE(measuring, 1u) << "row at h " << h;
  }
}
