// The benches' judge (bench/cell_oracle.hpp judge_model): a vertex on a crease is judged by its faces, not by
// a bisector normal no surface has; the area is conserved and lands on the face it belongs to. And the cell
// oracle's account of what a cell never reaches, on a box resting on the plate.
#include <gtest/gtest.h>

#include "bench/cell_oracle.hpp"
#include "planner/config.hpp"
#include "planner/kinematics/resting_poses.hpp"
#include "planner/sim/synthetic.hpp"
#include "test_meshes.hpp"

namespace scancell::bench {
namespace {

TEST(JudgeModel, ABoxsEdgeVerticesAreJudgedByTheirFacesAndTheAreaLandsOnEachFace) {
  sp::TriangleMesh box;
  sp::testing::add_box(box, {0, 0, 0}, {60, 40, 20}, 10.0);
  box = sp::weld(box);
  const sp::RoughModel plain = sp::make_rough_model(box);
  const sp::RoughModel judged = judge_model(box);
  const std::size_t n = box.vertices.size();
  ASSERT_GT(judged.size(), n);

  // Per face, the area of the rows whose normal is that face's: 60x40, 60x20 and 40x20 mm, two of each.
  auto area_facing = [](const sp::RoughModel& m, const Eigen::Vector3d& dir) {
    double a = 0.0;
    for (std::size_t r = 0; r < m.size(); ++r) a += m.normals[r].dot(dir) > 0.999 ? m.area_mm2[r] : 0.0;
    return a;
  };
  const std::pair<Eigen::Vector3d, double> faces[] = {{Eigen::Vector3d::UnitZ(), 2400.0}, {-Eigen::Vector3d::UnitZ(), 2400.0},
                                                      {Eigen::Vector3d::UnitX(), 800.0},  {-Eigen::Vector3d::UnitX(), 800.0},
                                                      {Eigen::Vector3d::UnitY(), 1200.0}, {-Eigen::Vector3d::UnitY(), 1200.0}};
  double total = 0.0;
  for (const auto& [dir, area] : faces) {
    EXPECT_NEAR(area_facing(judged, dir), area, 1e-6) << dir.transpose();
    EXPECT_LT(area_facing(plain, dir), area - 100.0) << "the vertex normals judged a face's edge band by a bisector";
    total += area;
  }
  double sum = 0.0;
  for (double a : judged.area_mm2) sum += a;
  EXPECT_NEAR(sum, total, 1e-6);
  EXPECT_NEAR(judged.total_area_mm2, total, 1e-6);

  // The vertex rows keep their order and place; an edge vertex keeps no area; a face's own vertex keeps its area.
  for (std::size_t r = 0; r < n; ++r) {
    ASSERT_EQ(judged.points[r], plain.points[r]);
    const Eigen::Vector3d& p = plain.points[r];
    const int on_bounds = (p.x() == 0 || p.x() == 60) + (p.y() == 0 || p.y() == 40) + (p.z() == 0 || p.z() == 20);
    if (on_bounds >= 2)
      EXPECT_EQ(judged.area_mm2[r], 0.0) << p.transpose();
    else
      EXPECT_EQ(judged.area_mm2[r], plain.area_mm2[r]) << p.transpose();
  }
  // The face rows lie on their face, off its edges (a ray test at the edge itself is degenerate).
  for (std::size_t r = n; r < judged.size(); ++r) {
    const Eigen::Vector3d& p = judged.points[r];
    const Eigen::Vector3d& d = judged.normals[r];
    for (int k = 0; k < 3; ++k) {
      const double hi = k == 0 ? 60.0 : k == 1 ? 40.0 : 20.0;
      if (std::abs(d[k]) > 0.999)
        EXPECT_DOUBLE_EQ(p[k], d[k] > 0 ? hi : 0.0);
      else
        EXPECT_TRUE(p[k] > 0.0 && p[k] < hi) << p.transpose() << " is on an edge";
    }
  }
}

// A 90 x 60 x 30 mm box lying on the turntable cell's plate: its bottom face (90 x 60 mm, 3/11 of the area) is
// what the plate takes, and no cause, counted on the views along the normals, is negative. Here the views
// along the normals lose 0.069 of the area to the axes' ranges and the cell's other views regain as much;
// before `regained` was split out, that came out as a collision share of -0.069.
TEST(CellOracle, ABoxOnThePlateLosesItsBottomToThePlateAndNoCauseIsNegative) {
  const std::string src = SCANCELL_SOURCE_DIR;
  sp::TriangleMesh box;
  sp::testing::add_box(box, {0, 0, 0}, {90, 60, 30}, 5.0);
  box = sp::weld(box);
  sp::CellModel cell = sp::load_cell(src + "/config/cells/turntable-lift-tilt.yaml");
  cell.object_on_table = sp::place_on_plate(box, Eigen::Matrix3d::Identity());
  const sp::RoughModel fine = judge_model(box);
  sp::TriangleMesh scene_mesh = box;
  sp::append_mesh(scene_mesh, sp::fixture_mesh(cell));
  const sp::OcclusionScene scene(scene_mesh);
  const auto sensor = sp::load_sensor(src + "/config/sensors/line-scan-thesis.yaml");
  const auto spec = sp::load_spec(src + "/config/spec/thesis.yaml");
  const CellOracle o = cell_oracle(box, fine, scene, sensor, spec, &cell, 2, &shipped_cell_space());

  const double bottom = 90.0 * 60.0 / (2.0 * (90.0 * 60.0 + 90.0 * 30.0 + 60.0 * 30.0));  // 3/11
  EXPECT_NEAR(o.total_area_mm2, 2.0 * (90.0 * 60.0 + 90.0 * 30.0 + 60.0 * 30.0), 1e-6);
  EXPECT_GE(o.lost_plate, bottom - 1e-9) << "the bottom face rests on the plate";
  EXPECT_LT(o.lost_plate, bottom + 0.05) << "the plate takes little of the sides beyond their lowest edge";
  for (double lost : {o.lost_range, o.lost_axes, o.lost_collision, o.regained}) EXPECT_GE(lost, -1e-12);
  EXPECT_NEAR(o.reachable(), 1.0 - o.lost_range - o.lost_plate - o.lost_axes - o.lost_collision + o.regained, 1e-9);
  EXPECT_GT(o.reachable(), 0.65) << "the top and the four sides are in reach";
}

}  // namespace
}  // namespace scancell::bench
