// Verified measurability: full coverage of a plane, unique coverage of a view, estimated vs verified on the
// thesis' convex patch (fig. 4.10), pose error, the plan file round trip, synthetic objects and baselines.
#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "planner/sim/baselines.hpp"
#include "common/errors.hpp"
#include "planner/plan.hpp"
#include "planner/plan_file.hpp"
#include "planner/sim/synthetic.hpp"
#include "planner/sim/verify.hpp"
#include "common/gnuplot.hpp"
#include "common/test_png.hpp"
#include "test_meshes.hpp"

namespace sp = scancell::planner;

namespace {

sp::ScanPose above(double x, double y, double range, double scan_length) {
  sp::Viewpoint v;
  v.position = Eigen::Vector3d(x, y, range);
  v.axis = -Eigen::Vector3d::UnitZ();
  v.scan_length_mm = scan_length;
  return sp::scan_pose(v);
}

/// Signed volume of a closed mesh (divergence theorem); positive when the normals point outwards.
double volume(const sp::TriangleMesh& m) {
  double v = 0.0;
  for (const auto& t : m.triangles) v += m.vertices[t[0]].dot(m.vertices[t[1]].cross(m.vertices[t[2]])) / 6.0;
  return v;
}

/// Every edge used exactly twice, once in each direction: closed and consistently oriented.
bool closed_and_oriented(const sp::TriangleMesh& m) {
  std::multiset<std::pair<std::uint32_t, std::uint32_t>> directed;
  for (const auto& t : m.triangles)
    for (int k = 0; k < 3; ++k) directed.insert({t[k], t[(k + 1) % 3]});
  for (const auto& e : directed)
    if (directed.count(e) != 1 || directed.count({e.second, e.first}) != 1) return false;
  return true;
}

}  // namespace

TEST(Verify, OneViewCoveringAPlaneMeasuresAllOfIt) {
  const sp::SensorModel s = sp::testing::thesis_sensor();
  const sp::ModelSpec spec = sp::testing::thesis_spec();
  // 40 mm square, 1 mm grid; a view from 160 mm has a 76.8 × 60 mm footprint, σz 0.0127 mm, ρ 7.0 /mm².
  const sp::TriangleMesh plane = sp::testing::flat_patch(40, 1);
  const auto v = sp::verify_views(plane, s, spec, {above(0, 0, 160, 60)}, {1.0});
  EXPECT_NEAR(v.area_mm2, 1600.0, 1e-6);
  EXPECT_GT(v.mv, 0.995);
  EXPECT_LE(v.mv, 1.0);
  EXPECT_GT(v.mv_analytic, 0.995);
  EXPECT_NEAR(v.estimated - v.mv, 0.0, 0.005);
  // Out of the depth of field: nothing.
  const auto none = sp::verify_views(plane, s, spec, {above(0, 0, 420, 60)}, {});
  EXPECT_EQ(none.mv, 0.0);
  // Too long a sweep misses the density spec: L = 300 mm gives δy = 1.18 mm, ρ < 0.7 /mm².
  const auto sparse = sp::verify_views(plane, s, spec, {above(0, 0, 160, 300)}, {});
  EXPECT_LT(sparse.mv, 0.01);
}

TEST(Verify, AViewMeasuresItsFootprintAndHalfAChordBeyondNotASpecSpacing) {
  // One view inside a larger plane: the measured area is the footprint the samples span, w × L, plus at most
  // the cells' reach (¾ chord) on each side. The former criterion (any compliant sample within 1/√ρ = 0.71 mm)
  // added a whole spec spacing on every side: (w + 1.41)(L + 1.41), 3 % more than was sampled.
  const sp::SensorModel s = sp::testing::thesis_sensor();
  const sp::ModelSpec spec = sp::testing::thesis_spec();
  const sp::TriangleMesh plane = sp::testing::flat_patch(100, 0.25);
  sp::VerifyOptions opt;
  opt.noise = false;
  opt.analytic = false;
  const double z = 160.0, length = 60.0;
  const auto v = sp::verify_views(plane, s, spec, {above(0, 0, z, length)}, {}, opt);
  const double w = 2.0 * z * std::tan(0.5 * s.fov_x_rad);
  // Rays at equal angles: the outermost chord is the longest, z·Δφ/cos²(Φx/2).
  const double dx = z * (s.fov_x_rad / (s.samples_x - 1)) / std::pow(std::cos(0.5 * s.fov_x_rad), 2);
  const double dy = length / (s.samples_y - 1);
  const double measured = v.views[0].alone_mm2;
  const double spacing = 1.0 / std::sqrt(spec.density_per_mm2);
  EXPECT_GT(measured, (w - 0.25) * (length - 0.25));  // the vertex grid resolves the border to 0.125 mm
  EXPECT_LT(measured, (w + 1.5 * dx + 0.25) * (length + 1.5 * dy + 0.25));
  EXPECT_LT(measured, (w + 2 * spacing) * (length + 2 * spacing) - 0.5 * (w + length) * spacing)
      << "w " << w << " L " << length << " chords " << dx << ", " << dy;
}

TEST(Verify, RemovingAViewLowersMvByItsUniqueCoverage) {
  const sp::SensorModel s = sp::testing::thesis_sensor();
  const sp::ModelSpec spec = sp::testing::thesis_spec();
  sp::TriangleMesh strip;
  sp::testing::add_grid(strip, Eigen::Vector3d(-70, -20, 0), Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY(), 141, 41, 1.0);
  const std::vector<sp::ScanPose> views = {above(-45, 0, 160, 50), above(0, 0, 160, 50), above(45, 0, 160, 50)};
  sp::VerifyOptions opt;
  opt.noise = false;  // removing a view shifts the per-view noise streams; the geometry alone is exact
  opt.analytic = false;
  const auto all = sp::verify_views(strip, s, spec, views, {}, opt);
  ASSERT_GT(all.mv, 0.9);
  for (std::size_t k = 0; k < views.size(); ++k) {
    std::vector<sp::ScanPose> rest = views;
    rest.erase(rest.begin() + static_cast<long>(k));
    const auto less = sp::verify_views(strip, s, spec, rest, {}, opt);
    EXPECT_GT(all.views[k].unique_mm2, 100.0) << "view " << k;
    EXPECT_NEAR((all.mv - less.mv) * all.area_mm2, all.views[k].unique_mm2, 1e-6) << "view " << k;
  }
  // Cumulative figures add up: the gains sum to the measured area.
  double gained = 0.0;
  for (const auto& w : all.views) gained += w.gain_mm2;
  EXPECT_NEAR(gained / all.area_mm2, all.mv, 1e-12);
}

TEST(Verify, EstimatedAgreesWithVerifiedOnTheThesisConvexPatch) {
  // Thesis 4.4.2 / fig. 4.10: D/W = 0.04, r_f ≈ 2.55, ρ_rel = −6, spec (50 µm, 2 /mm²): m_v = 0.9965 and
  // estimated close to verified.
  const sp::SensorModel s = sp::testing::thesis_sensor();
  const sp::ModelSpec spec = sp::testing::thesis_spec();
  const double fs = sp::sensor_footprint_mm2(s, spec);
  const double width = std::sqrt(2.55 * fs);
  const sp::TriangleMesh patch = sp::convex_patch(width, 0.04, 1.0);
  sp::RoughModelOptions rough;
  rough.rho_rel = -6.0;
  const sp::ViewPlan plan = sp::plan_views(patch, s, spec, sp::PlannerSettings{}, rough);
  std::vector<sp::ScanPose> poses;
  for (const auto& v : plan.views) poses.push_back(sp::scan_pose(v));
  const auto v = sp::verify_views(patch, s, spec, poses, plan.cover.cumulative_fraction);
  EXPECT_GE(plan.views.size(), 3u);  // ⌈r_f⌉
  EXPECT_GT(v.mv, 0.99);
  EXPECT_NEAR(v.estimated, v.mv, 0.02);
  // Per view: verified progression is monotonic and the estimate tracks it.
  for (std::size_t k = 1; k < v.views.size(); ++k) EXPECT_GE(v.views[k].cumulative, v.views[k - 1].cumulative);
}

TEST(Verify, AnalyticMvEqualsTheEstimateWhenTheRoughModelIsTheFineModel) {
  // No decimation, no noise: the planner's estimate and the verifier's analytic test are the same test on the
  // same points at the same poses, so they agree view by view (a cross-check of the plan's poses and columns).
  const sp::SensorModel s = sp::testing::thesis_sensor();
  const sp::ModelSpec spec = sp::testing::thesis_spec();
  const sp::TriangleMesh cavity = sp::cavity_patch(60, 48, 0.5, 2.0);
  sp::PlannerSettings settings;
  settings.viewpoints.open_direction_views = false;  // their columns use a detuned spec
  const sp::ViewPlan plan = sp::plan_views(cavity, s, spec, settings, {});
  std::vector<sp::ScanPose> poses;
  for (const auto& v : plan.views) poses.push_back(sp::scan_pose(v));
  const auto v = sp::verify_views(cavity, s, spec, poses, plan.cover.cumulative_fraction);
  ASSERT_EQ(v.views.size(), plan.views.size());
  for (std::size_t k = 0; k < v.views.size(); ++k)
    EXPECT_NEAR(v.views[k].cumulative_analytic, plan.cover.cumulative_fraction[k], 1e-9) << "view " << k;
  // The virtual scanner agrees with both within 2 %.
  EXPECT_NEAR(v.mv, v.mv_analytic, 0.02);
}

TEST(Verify, PoseErrorErodesCoverageAndIsSeeded) {
  const sp::SensorModel s = sp::testing::thesis_sensor();
  const sp::ModelSpec spec = sp::testing::thesis_spec();
  sp::TriangleMesh strip;
  sp::testing::add_grid(strip, Eigen::Vector3d(-70, -20, 0), Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY(), 141, 41, 1.0);
  // Views that just abut: a few mm of positioning error opens gaps.
  const std::vector<sp::ScanPose> views = {above(-38, 0, 150, 50), above(38, 0, 150, 50)};
  sp::VerifyOptions opt;
  opt.analytic = false;
  const auto exact = sp::verify_views(strip, s, spec, views, {}, opt);
  opt.pose_error = {8.0, 0.05, 0.05};
  const auto a = sp::verify_views(strip, s, spec, views, {}, opt);
  const auto b = sp::verify_views(strip, s, spec, views, {}, opt);
  EXPECT_LT(a.mv, exact.mv);
  EXPECT_EQ(a.mv, b.mv);  // same seed, same result
  EXPECT_FALSE(a.views[0].executed.camera_to_object.isApprox(views[0].camera_to_object));
  EXPECT_EQ(exact.views[0].executed.camera_to_object.matrix(), views[0].camera_to_object.matrix());
  // The perturbed pose is still a rigid motion.
  const Eigen::Matrix3d r = a.views[0].executed.camera_to_object.linear();
  EXPECT_TRUE((r.transpose() * r).isApprox(Eigen::Matrix3d::Identity(), 1e-12));
}

TEST(PlanFile, RoundTripsThePlanAndNamesDamage) {
  const sp::SensorModel s = sp::testing::thesis_sensor();
  const sp::ModelSpec spec = sp::testing::thesis_spec();
  const sp::TriangleMesh patch = sp::convex_patch(120, 0.04, 2.0);
  sp::RoughModelOptions rough;
  rough.target_vertices = 300;
  sp::ViewPlan plan = sp::plan_views(patch, s, spec, sp::PlannerSettings{}, rough);
  plan.object.mesh_path = "patch.off";
  plan.object.scale = 2.0;
  const auto dir = std::filesystem::temp_directory_path() / "scancell_planfile_test";
  std::filesystem::create_directories(dir);
  nlohmann::json j = sp::plan_to_json(plan);
  std::ofstream(dir / "plan.json") << j.dump(1);
  const sp::PlanFile f = sp::load_plan_file(dir / "plan.json");
  EXPECT_EQ(f.mesh_path, "patch.off");
  EXPECT_DOUBLE_EQ(f.object_transform(0, 0), 2.0);
  EXPECT_EQ(f.sensor.samples_x, s.samples_x);
  EXPECT_DOUBLE_EQ(f.spec.precision_mm, spec.precision_mm);
  ASSERT_EQ(f.views.size(), plan.views.size());
  for (std::size_t k = 0; k < plan.views.size(); ++k) {
    EXPECT_TRUE(f.views[k].camera_to_object.matrix().isApprox(plan.views[k].transform(), 1e-12));
    EXPECT_DOUBLE_EQ(f.views[k].scan_length_mm, plan.views[k].scan_length_mm);
    EXPECT_TRUE(f.viewpoints[k].rotation().isApprox(plan.views[k].rotation(), 1e-9));
    EXPECT_DOUBLE_EQ(f.estimated_cumulative[k], plan.cover.cumulative_fraction[k]);
  }
  auto refused = [&](nlohmann::json bad, const std::string& expect) {
    std::ofstream(dir / "bad.json") << bad.dump();
    try {
      sp::load_plan_file(dir / "bad.json");
      ADD_FAILURE() << "accepted: " << expect;
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find(expect), std::string::npos) << e.what();
    }
  };
  nlohmann::json bad = j;
  bad["views"][1]["camera_to_object_row_major"][0] = 3.0;
  refused(bad, "views[1].camera_to_object_row_major: rotation part is not a rotation");
  bad = j;
  bad["views"][0].erase("scan_length_mm");
  refused(bad, "views[0].scan_length_mm: missing");
  bad = j;
  bad["sensor"]["range_min_mm"] = -1;
  refused(bad, "sensor: range_min_mm");
  bad = j;
  bad["format"] = "something";
  refused(bad, "format");
  std::ofstream(dir / "bad.json") << "{\"format\": \"scancell-plan\", ";
  EXPECT_THROW(sp::load_plan_file(dir / "bad.json"), scancell::DataError);
  // Issue 16, defect 3: a sensor nested 200,000 levels deep crashed the recursive serializer (stack overflow);
  // it is refused while parsing, naming the file, and so is a key given twice.
  {
    std::string deep = j.dump();
    const std::string nest = std::string(200000, '[') + std::string(200000, ']');
    deep.replace(deep.find("\"sensor\":") + 9, 0, "{\"x\":" + nest + ",\"y\":");
    deep.replace(deep.find("\"spec\":") - 1, 0, "}");
    std::ofstream(dir / "bad.json") << deep;
  }
  try {
    sp::load_plan_file(dir / "bad.json");
    ADD_FAILURE() << "a 200,000-deep plan was accepted";
  } catch (const scancell::DataError& e) {
    EXPECT_THAT(e.what(), testing::HasSubstr("bad.json: nested deeper than 32 levels"));
  }
  std::ofstream(dir / "bad.json") << "{\"format\": \"scancell-plan\", \"format\": \"other\"}";
  try {
    sp::load_plan_file(dir / "bad.json");
    ADD_FAILURE() << "a duplicate key was accepted";
  } catch (const scancell::DataError& e) {
    EXPECT_THAT(e.what(), testing::HasSubstr("key 'format' given twice"));
  }
  std::filesystem::remove_all(dir);
}

TEST(Synthetic, ClosedShapesAreWatertightWithTheirVolume) {
  const sp::TriangleMesh box = sp::box_with_blind_hole({120, 80, 60}, 30, 30, 2.0);
  EXPECT_TRUE(closed_and_oriented(box));
  // 120·80·60 minus the hole (a polygon inscribed in the 15 mm circle, within 0.5 % of π r²).
  const double hole = M_PI * 15 * 15 * 30;
  EXPECT_NEAR(volume(box), 120.0 * 80 * 60 - hole, 0.005 * hole);
  const sp::TriangleMesh tube = sp::cylinder_with_bore(80, 40, 60, 2.0);
  EXPECT_TRUE(closed_and_oriented(tube));
  const double tube_volume = M_PI * (40.0 * 40 - 20.0 * 20) * 60;
  EXPECT_NEAR(volume(tube), tube_volume, 0.005 * tube_volume);
}

TEST(Synthetic, EdgeRefinementKeepsTheSurfaceAndItsTopology) {
  const sp::TriangleMesh coarse = sp::box_with_blind_hole({120, 80, 60}, 30, 30, 20.0);
  const sp::TriangleMesh fine = sp::refine_edges(coarse, 1.5);
  EXPECT_TRUE(closed_and_oriented(fine));
  EXPECT_NEAR(volume(fine), volume(coarse), 1e-6 * volume(coarse));
  double area_c = 0, area_f = 0, longest = 0;
  for (const auto& t : coarse.triangles) area_c += sp::triangle_area(coarse, t);
  for (const auto& t : fine.triangles) {
    area_f += sp::triangle_area(fine, t);
    for (int k = 0; k < 3; ++k) longest = std::max(longest, (fine.vertices[t[k]] - fine.vertices[t[(k + 1) % 3]]).norm());
  }
  EXPECT_NEAR(area_f, area_c, 1e-6 * area_c);
  EXPECT_LE(longest, 1.5);
  EXPECT_GT(fine.vertices.size(), 10 * coarse.vertices.size());
}

TEST(Synthetic, PatchesHaveTheirDepthToWidthRatio) {
  const sp::TriangleMesh cavity = sp::cavity_patch(60, 46, 0.5, 1.0);
  double zmin = 0.0, zmax = -1.0;
  for (const auto& v : cavity.vertices) zmin = std::min(zmin, v.z()), zmax = std::max(zmax, v.z());
  EXPECT_NEAR(zmin, -23.0, 0.05);  // D = 0.5 · 46
  EXPECT_NEAR(zmax, 0.0, 1e-12);
  const sp::TriangleMesh convex = sp::convex_patch(126, 0.04, 1.0);
  zmax = -1.0;
  for (const auto& v : convex.vertices) zmax = std::max(zmax, v.z());
  EXPECT_NEAR(zmax, 5.04, 1e-9);  // D = 0.04 · 126 at the centre vertex
  // F_s of the thesis sensor: 2·f_d·R_o·tan(Φx/2)·L_y with L_y the design scan length at f_d·R_o.
  const sp::SensorModel s = sp::testing::thesis_sensor();
  const double fs = sp::sensor_footprint_mm2(s, sp::testing::thesis_spec());
  const double width = 2 * 1.02 * 142 * std::tan(0.5 * s.fov_x_rad);
  EXPECT_NEAR(fs / width, sp::design_scan_length_mm(s, sp::testing::thesis_spec(), 1.02 * 142, M_PI / 6), 1e-9);
}

TEST(Baselines, TurntableAndViewSphereLookAtTheCentre) {
  const sp::SensorModel s = sp::testing::thesis_sensor();
  const sp::ModelSpec spec = sp::testing::thesis_spec();
  const sp::TriangleMesh box = sp::box_with_blind_hole({120, 80, 60}, 30, 30, 4.0);
  const Eigen::Vector3d centre(0, 0, 30);
  const auto tt = sp::turntable_program(box, s, spec, 8, {-M_PI / 6, M_PI / 6});
  ASSERT_EQ(tt.size(), 16u);
  const double d = std::min(142.0 + 0.5 * std::sqrt(120.0 * 120 + 80 * 80 + 60 * 60), 407.0);
  for (const auto& v : tt) {
    EXPECT_NEAR((v.position - centre).norm(), d, 1e-9);
    EXPECT_NEAR((v.position + d * v.axis - centre).norm(), 0.0, 1e-9);  // boresight through the centre
    EXPECT_NEAR(v.rotation().col(1).z(), 0.0, 1e-9);                    // baseline horizontal
  }
  EXPECT_EQ(sp::icosphere_directions(2).size(), 162u);
  EXPECT_EQ(sp::icosphere_directions(3).size(), 642u);
  const auto sphere = sp::view_sphere_candidates(box, s, spec, 2, 4);
  EXPECT_EQ(sphere.size(), 162u * 4u);
}

// Issue 19: the coverage picture people read — labelled views, legend, title — and, without gnuplot, the bare
// views with the reason returned (never passed off as the labelled one).
TEST(CoveragePicture, LabelledWithGnuplotBareWithTheReasonWithout) {
  const scancell::ScratchDir dir("scancell-coverage-picture-test");
  sp::TriangleMesh box;
  scancell::planner::testing::add_box(box, {-30, -20, -10}, {30, 20, 10}, 5.0);
  std::vector<std::uint8_t> measured(box.vertices.size(), 1);
  for (std::size_t i = 0; i < box.vertices.size(); ++i) measured[i] = box.vertices[i].z() > -9.0;  // the base not
  const auto png = dir.path / "coverage.png";
  EXPECT_EQ(sp::write_coverage_picture(box, measured, "box: 3 views\nverified m_v 0.83", png), "");
  scancell::test_support::expect_whole_png(png.string(), 1240, 860, 10000);
  const std::string old_path = std::getenv("PATH") ? std::getenv("PATH") : "";
  setenv("PATH", dir.path.c_str(), 1);  // no gnuplot there
  const std::string why = sp::write_coverage_picture(box, measured, "box", png);
  setenv("PATH", old_path.c_str(), 1);
  EXPECT_THAT(why, ::testing::HasSubstr("needs gnuplot on the PATH"));
  EXPECT_THAT(why, ::testing::HasSubstr("no legend or title"));
  scancell::test_support::expect_whole_png(png.string(), 960, 640, 1000);  // the six bare 320-px views
}
