// The rough model from a rough scan: range images of a sphere and of a box fused into a TSDF volume and
// contoured with marching tetrahedra come back closed, manifold and within one voxel of the truth; what no ray
// saw is closed conservatively and marked hypothetical.
#include <filesystem>
#include <fstream>
#include <map>
#include <set>

#include <unistd.h>

#include <gtest/gtest.h>

#include "planner/sim/virtual_scanner.hpp"
#include "planner/config.hpp"
#include "common/errors.hpp"
#include "planner/reconstruction/fusion.hpp"
#include "planner/core/rough_model.hpp"
#include "planner/reconstruction/rough_scan.hpp"
#include "test_meshes.hpp"

namespace scancell::planner {
namespace {

/// Views from 14 directions (faces and corners of a cube) at `standoff_mm` from `centre`.
std::vector<RangeImage> scans_around(const TriangleMesh& m, const Eigen::Vector3d& centre, double standoff_mm,
                                     bool skip_below = false) {
  const SensorModel s = load_sensor(testing::source_path("config/sensors/line-scan-thesis.yaml"));
  const OcclusionScene scene(m);
  std::vector<RangeImage> out;
  std::vector<Eigen::Vector3d> dirs = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
  for (int x : {-1, 1})
    for (int y : {-1, 1})
      for (int z : {-1, 1}) dirs.emplace_back(x, y, z);
  for (auto d : dirs) {
    d.normalize();
    if (skip_below && d.z() < -0.1) continue;
    const Eigen::Vector3d y = std::abs(d.z()) > 0.99 ? Eigen::Vector3d::UnitY() : Eigen::Vector3d::UnitZ().cross(d).normalized();
    ScanPose pose;
    pose.camera_to_object.linear() << y.cross(d), y, d;
    pose.camera_to_object.translation() = centre + standoff_mm * d;
    pose.scan_length_mm = 110.0;
    out.push_back(virtual_scan(scene, s, pose));
  }
  return out;
}

/// Edges not shared by exactly two triangles (0: closed; an empty mesh is not).
std::size_t open_edges(const TriangleMesh& m) {
  const EdgeCounts c = count_edges(m);
  return c.edges == 0 ? 1 : c.open + c.non_manifold;
}

/// Defects of an oriented closed 2-manifold: directed edges not used exactly once with their reverse used
/// exactly once (a non-manifold or inconsistently wound edge), and vertices whose triangles form more than
/// one fan (two sheets touching at a point).
std::size_t manifold_defects(const TriangleMesh& m) {
  std::map<std::pair<std::uint32_t, std::uint32_t>, int> directed;
  std::vector<std::map<std::uint32_t, std::uint32_t>> fan(m.vertices.size());  // around v: a -> b of each (v, a, b)
  std::size_t bad = 0;
  for (const auto& t : m.triangles)
    for (int k = 0; k < 3; ++k) {
      ++directed[{t[k], t[(k + 1) % 3]}];
      bad += !fan[t[k]].emplace(t[(k + 1) % 3], t[(k + 2) % 3]).second;
    }
  for (const auto& [e, n] : directed) {
    const auto r = directed.find({e.second, e.first});
    bad += n != 1 || r == directed.end() || r->second != 1;
  }
  for (const auto& f : fan) {
    if (f.empty()) continue;
    // One cycle through every neighbour.
    std::size_t steps = 0;
    std::uint32_t a = f.begin()->first;
    do {
      const auto it = f.find(a);
      if (it == f.end()) break;
      a = it->second;
      ++steps;
    } while (a != f.begin()->first && steps <= f.size());
    bad += steps != f.size();
  }
  return bad;
}

double volume(const TriangleMesh& m) {
  double v = 0.0;
  for (const auto& t : m.triangles) v += m.vertices[t[0]].dot(m.vertices[t[1]].cross(m.vertices[t[2]])) / 6.0;
  return v;
}

TEST(Fusion, SphereComesBackClosedWithinOneVoxel) {
  const Eigen::Vector3d c(0, 0, 0);
  const double r = 40.0;
  const TriangleMesh truth = testing::uv_sphere(c, r);
  TsdfVolume vol(Eigen::AlignedBox3d(Eigen::Vector3d::Constant(-50), Eigen::Vector3d::Constant(50)));
  for (const auto& img : scans_around(truth, c, 230.0)) vol.integrate(img);
  const FusedModel f = vol.extract();
  ASSERT_GT(f.mesh.vertices.size(), 1000u);
  EXPECT_EQ(open_edges(f.mesh), 0u);
  EXPECT_EQ(manifold_defects(f.mesh), 0u);
  std::size_t measured = 0;
  double worst = 0.0;
  for (std::size_t v = 0; v < f.mesh.vertices.size(); ++v) {
    if (f.hypothetical[v]) continue;
    ++measured;
    worst = std::max(worst, std::abs((f.mesh.vertices[v] - c).norm() - r));
  }
  EXPECT_LE(worst, vol.voxel_mm());
  EXPECT_GT(measured, 0.95 * static_cast<double>(f.mesh.vertices.size()));
  EXPECT_NEAR(volume(f.mesh), 4.0 / 3.0 * M_PI * r * r * r, 0.03 * 4.0 / 3.0 * M_PI * r * r * r);
}

TEST(Fusion, BoxOnATableIsClosedUnderneathAndTheGuessIsMarked) {
  // The cube seen from above and around only (the table hides its underside): the top and sides come back
  // within a voxel, the unseen bottom is closed and every vertex there is hypothetical.
  TriangleMesh truth = load_mesh(testing::source_path("tests/data/cube50.off"));
  const Eigen::Vector3d c(25, 25, 25);
  FusionOptions o;
  o.floor_z_mm = 0.0;  // the table top
  TsdfVolume vol(Eigen::AlignedBox3d(Eigen::Vector3d::Constant(-8), Eigen::Vector3d::Constant(58)), o);
  for (const auto& img : scans_around(truth, c, 220.0, true)) vol.integrate(img);
  const FusedModel f = vol.extract();
  EXPECT_EQ(open_edges(f.mesh), 0u);
  EXPECT_EQ(manifold_defects(f.mesh), 0u);
  auto to_box = [](const Eigen::Vector3d& p) {
    const Eigen::Vector3d lo = p, hi = Eigen::Vector3d::Constant(50) - p;
    return std::min({std::abs(lo.x()), std::abs(lo.y()), std::abs(lo.z()), std::abs(hi.x()), std::abs(hi.y()), std::abs(hi.z())});
  };
  double worst = 0.0;
  std::size_t bottom = 0, bottom_guess = 0;
  for (std::size_t v = 0; v < f.mesh.vertices.size(); ++v) {
    const Eigen::Vector3d& p = f.mesh.vertices[v];
    if (p.z() < 1.0 && p.x() > 5 && p.x() < 45 && p.y() > 5 && p.y() < 45) {
      ++bottom;
      bottom_guess += f.hypothetical[v];
    }
    if (!f.hypothetical[v]) worst = std::max(worst, to_box(p));
  }
  EXPECT_LE(worst, vol.voxel_mm());
  EXPECT_GT(bottom, 100u);
  EXPECT_EQ(bottom_guess, bottom);
}

TEST(Fusion, HypotheticalFlagsSurviveTheFileAndTheDecimation) {
  // The cube on its table: written as OFF with its flag list, loaded back (the loader welds and reorders),
  // decimated to 300 rows: the rows on the unseen underside are hypothetical, the others are not.
  TriangleMesh truth = load_mesh(testing::source_path("tests/data/cube50.off"));
  FusionOptions o;
  o.floor_z_mm = 0.0;
  TsdfVolume vol(Eigen::AlignedBox3d(Eigen::Vector3d::Constant(-8), Eigen::Vector3d::Constant(58)), o);
  for (const auto& img : scans_around(truth, {25, 25, 25}, 220.0, true)) vol.integrate(img);
  const FusedModel f = vol.extract();
  const auto dir = std::filesystem::temp_directory_path() / ("scancell_flags_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  write_flagged_vertices(f.mesh, f.hypothetical, (dir / "rough.hypothetical.xyz").string());
  write_off(f.mesh, (dir / "rough.off").string());
  const TriangleMesh loaded = load_mesh(dir / "rough.off");
  RoughModelOptions ro;
  ro.target_vertices = 300;
  ro.vertex_hypothetical = read_flagged_vertices(loaded, (dir / "rough.hypothetical.xyz").string());
  std::size_t flagged = 0, guessed = 0;
  for (std::size_t i = 0; i < f.hypothetical.size(); ++i) flagged += f.hypothetical[i];
  for (auto h : ro.vertex_hypothetical) guessed += h;
  EXPECT_EQ(guessed, flagged);
  const RoughModel rough = build_rough_model(loaded, ro);
  ASSERT_EQ(rough.hypothetical.size(), rough.size());
  std::size_t bottom = 0, bottom_guess = 0, wrong = 0;
  for (std::size_t r = 0; r < rough.size(); ++r) {
    if (rough.normals[r].z() < -0.9) {  // facing the plate
      ++bottom;
      bottom_guess += rough.hypothetical[r];
    } else if (rough.points[r].z() > 3.0) {
      wrong += rough.hypothetical[r];  // seen surface marked a guess
    }
  }
  EXPECT_GT(bottom, 3u);
  EXPECT_EQ(bottom_guess, bottom);
  EXPECT_EQ(wrong, 0u);
  // A list that is not this model's is refused, naming the line.
  {
    std::ofstream bad(dir / "other.xyz");
    bad << "# x y z\n12.5 900.0 3.0\n";
  }
  try {
    read_flagged_vertices(loaded, (dir / "other.xyz").string());
    ADD_FAILURE() << "a foreign list was accepted";
  } catch (const DataError& e) {
    EXPECT_NE(std::string(e.what()).find("other.xyz:2"), std::string::npos) << e.what();
  }
  std::filesystem::remove_all(dir);
}

TEST(RoughScan, ExplorationAimsUpATallBoxAtSeveralHeights) {
  // The profile's fan is ~130 mm wide at the exploration stand-off: a 60 mm box is aimed at from its middle,
  // a 170 mm one from two heights (42.5 and 127.5 mm), each covering its half.
  CellModel cell = load_cell(testing::source_path("config/cells/turntable-lift-tilt.yaml"));
  cell.object_on_table = Eigen::Isometry3d::Identity();
  const SensorModel s = load_sensor(testing::source_path("config/sensors/line-scan-thesis.yaml"));
  auto aim_heights = [&](const Eigen::Vector3d& size) {
    std::vector<std::string> skipped;
    std::set<long> heights;
    for (const auto& v : exploration_views(cell, s, size, {}, &skipped)) {
      // Where the boresight passes the turntable's axis (x = y = 0 of the table frame).
      const Eigen::Isometry3d cam = forward_kinematics(cell, v.q);
      const Eigen::Vector3d o = cam.translation(), d = cam.linear().col(2);
      const double t = -(o.head<2>().dot(d.head<2>())) / d.head<2>().squaredNorm();
      EXPECT_LT((o + t * d).head<2>().norm(), 0.5);
      heights.insert(std::lround((o + t * d).z() * 2.0));  // half-millimetre bins
    }
    EXPECT_TRUE(skipped.empty()) << skipped.front();
    return heights;
  };
  EXPECT_EQ(aim_heights({60, 60, 60}), (std::set<long>{60}));
  EXPECT_EQ(aim_heights({60, 60, 170}), (std::set<long>{85, 255}));
}

TEST(Fusion, ThinAndConcaveShapesStayManifoldAndDecimateWithoutLosingFaces) {
  // The mushroom (a thin cap over a stalk, a recess under it) at 1.5 mm voxels: where two sheets of the
  // surface come within a voxel, surface nets and plain marching cubes join them at a vertex or edge and the
  // rough-model decimator drops faces there (holes). Marching tetrahedra has no such case.
  TriangleMesh truth = load_mesh(testing::source_path("tests/data/mushroom.off"));
  apply_scale(truth, fit_scale(truth, 120.0));
  Eigen::AlignedBox3d box;
  for (const auto& v : truth.vertices) box.extend(v);
  TsdfVolume vol(Eigen::AlignedBox3d(box.min() - Eigen::Vector3d::Constant(6), box.max() + Eigen::Vector3d::Constant(6)));
  for (const auto& img : scans_around(truth, box.center(), 230.0)) vol.integrate(img);
  const FusedModel f = vol.extract();
  ASSERT_GT(f.mesh.triangles.size(), 1000u);
  EXPECT_EQ(open_edges(f.mesh), 0u);
  EXPECT_EQ(manifold_defects(f.mesh), 0u);
  RoughModelOptions ro;
  ro.target_vertices = 2000;
  RoughModelReport report;
  const RoughModel rough = build_rough_model(f.mesh, ro, &report);
  EXPECT_EQ(report.faces_rejected_by_decimator, 0u);
  EXPECT_EQ(open_edges(rough.mesh()), 0u);
}

}  // namespace
}  // namespace scancell::planner
