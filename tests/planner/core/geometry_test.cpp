// Known geometries: what one viewpoint can and cannot measure, and what the whole planner does with them.
#include <atomic>
#include <numbers>
#include <numeric>
#include <iterator>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "common/errors.hpp"
#include "planner/core/measurability.hpp"
#include "planner/plan.hpp"
#include "planner/sim/synthetic.hpp"
#include "test_meshes.hpp"

namespace scancell::planner {
namespace {

std::uint32_t nearest_row(const RoughModel& rm, const Eigen::Vector3d& p) {
  std::uint32_t best = 0;
  for (std::uint32_t i = 0; i < rm.size(); ++i)
    if ((rm.points[i] - p).squaredNorm() < (rm.points[best] - p).squaredNorm()) best = i;
  return best;
}

/// A camera looking straight down (-z) from `position`, with its receiver (+y) towards `receiver_dir`.
Viewpoint looking_down(const Eigen::Vector3d& position, const Eigen::Vector3d& receiver_dir, double scan_length) {
  Viewpoint v;
  v.position = position;
  v.axis = -Eigen::Vector3d::UnitZ();
  v.twist_rad = twist_towards(v.axis, receiver_dir);
  v.standoff_mm = position.z();
  v.scan_length_mm = scan_length;
  return v;
}

PlannerSettings variable_settings() {
  PlannerSettings s;
  s.viewpoints.scheme = ViewpointScheme::variable;
  return s;
}

TEST(Geometry, PatchSmallerThanFootprintNeedsOneView) {
  const ViewPlan p = plan_views(testing::flat_patch(40.0, 2.0), testing::thesis_sensor(), testing::thesis_spec(),
                                PlannerSettings{}, {});
  ASSERT_EQ(p.views.size(), 1u);
  EXPECT_DOUBLE_EQ(p.cover.cumulative_fraction.back(), 1.0);
  EXPECT_TRUE(p.cover.unmeasurable_rows.empty());
}

TEST(Geometry, WallBetweenPointAndReceiverMakesItUnmeasurable) {
  const SensorModel sensor = testing::thesis_sensor();
  const ModelSpec spec = testing::thesis_spec();
  const TriangleMesh floor = testing::flat_patch(100.0, 5.0);
  // Camera 150 mm above the origin, receiver towards +y: the receiver ray from the origin rises to
  // (0, 180, 150); it crosses y = 30 at z = 25. The laser ray goes straight up.
  const Viewpoint v = looking_down({0, 0, 150}, Eigen::Vector3d::UnitY(), 100.0);
  {
    const RoughModel rm = make_rough_model(floor);
    const OcclusionScene scene(rm.mesh());
    EXPECT_TRUE(measurable(rm, scene, sensor, spec, v, nearest_row(rm, {0, 0, 0})));
  }
  TriangleMesh walled = floor;
  testing::add_grid(walled, {-20, 30, 5}, Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitZ(), 9, 12, 5.0);  // z 5..60
  const RoughModel rm = make_rough_model(walled);
  const OcclusionScene scene(rm.mesh());
  EXPECT_FALSE(measurable(rm, scene, sensor, spec, v, nearest_row(rm, {0, 0, 0})));
  // The same wall does not shadow a point on the far side of it from the receiver's view... of the laser:
  // a receiver towards -y sees the origin again.
  EXPECT_TRUE(measurable(rm, scene, sensor, spec, looking_down({0, 0, 150}, -Eigen::Vector3d::UnitY(), 100.0),
                         nearest_row(rm, {0, 0, 0})));
}

TEST(Geometry, DeepCavityFloorCornersDependOnTwist) {
  // D/W = 1: 60 mm wide, 60 mm deep. From 250 mm above the floor, the receiver 180 mm off along y sees the
  // floor only within 60 - 180·60/250 = 16.8 mm of the wall on the receiver's far side.
  const SensorModel sensor = testing::thesis_sensor();
  const ModelSpec spec = testing::thesis_spec();
  const RoughModel rm = make_rough_model(testing::square_cavity(60.0, 60.0, 90.0, 3.0));
  const OcclusionScene scene(rm.mesh());
  const std::uint32_t low = nearest_row(rm, {-27, -27, -60}), high = nearest_row(rm, {27, 27, -60});
  ASSERT_NEAR((rm.points[low] - Eigen::Vector3d(-27, -27, -60)).norm(), 0.0, 1e-9);
  ASSERT_NEAR((rm.points[high] - Eigen::Vector3d(27, 27, -60)).norm(), 0.0, 1e-9);
  const Viewpoint plus_y = looking_down({0, 0, 190}, Eigen::Vector3d::UnitY(), 100.0);
  const Viewpoint minus_y = looking_down({0, 0, 190}, -Eigen::Vector3d::UnitY(), 100.0);
  EXPECT_TRUE(measurable(rm, scene, sensor, spec, plus_y, low));
  EXPECT_FALSE(measurable(rm, scene, sensor, spec, plus_y, high));
  EXPECT_TRUE(measurable(rm, scene, sensor, spec, minus_y, high));
  EXPECT_FALSE(measurable(rm, scene, sensor, spec, minus_y, low));
  // The laser alone sees both corners: what fails is the receiver's line of sight, not the frustum.
  EXPECT_TRUE(test_point(sensor, spec, 100.0, plus_y.rotation().transpose() * (rm.points[high] - plus_y.position),
                         plus_y.rotation().transpose() * rm.normals[high]).compliant);
}

TEST(Geometry, DeepCavityIsCoveredByThePlanner) {
  // With bisecting views every floor row is measurable by some candidate, and plain greedy measures all
  // that is measurable.
  PlannerSettings greedy;
  greedy.cover.mode = CoverMode::greedy;
  const ViewPlan p = plan_views(testing::square_cavity(60.0, 60.0, 90.0, 3.0), testing::thesis_sensor(),
                                testing::thesis_spec(), greedy, {});
  for (auto r : p.cover.unmeasurable_rows) EXPECT_GT(p.rough.points[r].z(), -60.0 + 1e-9) << "floor row unmeasurable";
  EXPECT_NEAR(p.cover.cumulative_fraction.back(), p.cover.measurable_fraction, 1e-12);
  EXPECT_GE(p.views.size(), 2u);
  // Without them (the thesis' optimal scanning zone) the middle of the floor is out of reach of the receiver.
  greedy.viewpoints.bisector_tilt = false;
  greedy.viewpoints.open_direction_views = false;
  const ViewPlan q = plan_views(testing::square_cavity(60.0, 60.0, 90.0, 3.0), testing::thesis_sensor(),
                                testing::thesis_spec(), greedy, {});
  auto centre_unmeasurable = [](const ViewPlan& v) {
    bool out = false;
    for (auto r : v.cover.unmeasurable_rows) out |= (v.rough.points[r] - Eigen::Vector3d(0, 0, -60)).norm() < 1e-9;
    return out;
  };
  EXPECT_TRUE(centre_unmeasurable(q));
  // Open-direction views alone rescue it: straight down the cavity from farther out, where the triangulation
  // angle atan(b/R) is narrower, and the rows they were made for are reported.
  greedy.viewpoints.open_direction_views = true;
  const ViewPlan o = plan_views(testing::square_cavity(60.0, 60.0, 90.0, 3.0), testing::thesis_sensor(),
                                testing::thesis_spec(), greedy, {});
  EXPECT_FALSE(centre_unmeasurable(o));
  EXPECT_GT(o.generation.rows_unmeasurable_before, 0u);
  EXPECT_GT(o.generation.open_direction_rows, 0u);
  EXPECT_LT(o.cover.unmeasurable_rows.size(), o.generation.rows_unmeasurable_before);
}

TEST(Geometry, RegistrationConstraintReportsWhatItCannotReach) {
  // Floor-only views overlap the rim views too little for t_r = 0.3: constrained greedy must say so and keep
  // its registration graph connected rather than add views that cannot register.
  PlannerSettings st;
  st.cover.registration_threshold = 0.3;
  st.viewpoints.open_direction_views = false;  // the far views would bridge floor and rim
  const ViewPlan p = plan_views(testing::square_cavity(60.0, 60.0, 90.0, 3.0), testing::thesis_sensor(),
                                testing::thesis_spec(), st, {});
  EXPECT_EQ(p.cover.registration_components, 1u);
  EXPECT_LT(p.cover.cumulative_fraction.back(), p.cover.measurable_fraction - 0.01);
  EXPECT_EQ(p.cover.stop_reason, "remaining gain needs views that cannot register (t_r)");
  for (const auto& e : p.cover.registration_edges) EXPECT_GE(e.sigma, 0.3);
}

TEST(Geometry, PatchWithFootprintRatio2_5NeedsAtLeastThreeViews) {
  // Sensor footprint at the stand-off 1.02·R_min: fan width 2·144.84·tan(13.5°) = 69.55 mm times the design
  // scan length 140.45 mm = 9768 mm². A 156 mm square is 24336 mm², r_f = 2.49: at least ⌈r_f⌉ = 3 views.
  const ViewPlan p = plan_views(testing::flat_patch(156.0, 3.0), testing::thesis_sensor(), testing::thesis_spec(),
                                PlannerSettings{}, {});
  EXPECT_GE(p.views.size(), 3u);
  EXPECT_LE(p.views.size(), 9u);  // the thesis' greedy needed 7 on its r_f = 2.55 patch
  EXPECT_DOUBLE_EQ(p.cover.cumulative_fraction.back(), 1.0);
  EXPECT_NEAR(p.views.front().scan_length_mm, 140.448, 1e-3);
}

TEST(Geometry, CandidatesInsideOrTooCloseAreDropped) {
  // Plate at z = 0 under a 20 mm slab (z 140..160): its optimal viewpoints (z = 144.84) fall inside the slab.
  TriangleMesh m = testing::flat_patch(60.0, 5.0);
  const std::size_t plate_vertices = m.vertices.size();
  testing::add_box(m, {-100, -100, 140}, {100, 100, 160}, 10.0);
  const RoughModel rm = make_rough_model(m);
  const OcclusionScene scene(rm.mesh());
  auto plate_candidates = [&](const std::vector<Viewpoint>& c) {
    std::size_t n = 0;
    for (const auto& v : c) n += rm.points[v.target_row].z() == 0.0;
    return n;
  };
  ViewpointSettings st = variable_settings().viewpoints;
  GenerationReport rep;
  auto c = generate_viewpoints(rm, scene, testing::thesis_sensor(), testing::thesis_spec(), st, &rep);
  EXPECT_EQ(plate_candidates(c), 0u);
  EXPECT_GE(rep.dropped_clearance, plate_vertices);
  st.clearance_mm = 0.0;  // now only the inside test can catch them
  c = generate_viewpoints(rm, scene, testing::thesis_sensor(), testing::thesis_spec(), st, &rep);
  EXPECT_EQ(plate_candidates(c), 0u);
  EXPECT_GE(rep.dropped_inside, plate_vertices);
}

TEST(Geometry, TheStandOffRisesByThePatchTowardsTheCameraOutToTheFootprintCylindersCorners) {
  // Thesis 6.3 (VARIABLE/DECOUPLED): stand-off = (R_o + R_a)·f_d, R_a the rise of the rough points within the
  // footprint cylinder around the normal (radius and half height r = hypot(fan half width, half the design
  // scan length) = hypot(34.09, 70.22) = 78.06 mm) that face the camera's side. A plate at z = 0 with a box
  // 30 mm high on it: a plate position whose distance across to the box's top is under r has R_a = 30 mm,
  // even where the top lies in the cylinder's corner, farther than r from the position itself (from 72 mm
  // across, √(72² + 30²) > r). Farther across, R_a = 0. Every plate row is a position here.
  TriangleMesh m = testing::flat_patch(300.0, 5.0);
  testing::add_box(m, {-25, -25, 0}, {25, 25, 30}, 5.0);
  const RoughModel rm = make_rough_model(m);
  const OcclusionScene scene(rm.mesh());
  const SensorModel sensor = testing::thesis_sensor();
  const ModelSpec spec = testing::thesis_spec();
  ViewpointSettings st;
  st.position_decimation = 1;
  st.min_position_spacing_fraction = 0.0;
  st.free_space_min_position_spacing_fraction = 0.0;
  st.twist_levels = 1;
  st.bisector_tilt = false;
  const double r = std::hypot(sensor.optimal_standoff_mm * std::tan(0.5 * sensor.fov_x_rad),
                              0.5 * design_scan_length_mm(sensor, spec, sensor.optimal_standoff_mm * st.standoff_factor,
                                                          st.scan_length_design_incidence_rad));
  ASSERT_NEAR(r, 78.06, 0.01);
  ASSERT_GT(max_range_for_precision_mm(sensor, spec), (sensor.optimal_standoff_mm + 30.0) * st.standoff_factor);  // no range cap
  std::size_t risen = 0, corner = 0, flat = 0;
  for (const auto& v : generate_viewpoints(rm, scene, sensor, spec, st)) {
    const Eigen::Vector3d p = rm.points[v.target_row];
    const double across = std::hypot(std::max(std::abs(p.x()) - 25.0, 0.0), std::max(std::abs(p.y()) - 25.0, 0.0));
    if (p.z() != 0.0 || across == 0.0 || std::abs(across - r) < 2.0) continue;  // the plate around the box, off the boundary
    const double rise = across < r ? 30.0 : 0.0;
    ASSERT_NEAR(v.standoff_mm, (sensor.optimal_standoff_mm + rise) * st.standoff_factor, 1e-9) << "plate row at " << p.transpose();
    risen += rise > 0.0;
    corner += rise > 0.0 && across > 72.0;
    flat += rise == 0.0;
  }
  EXPECT_GT(risen, 100u);
  EXPECT_GT(corner, 10u);
  EXPECT_GT(flat, 100u);
}

TEST(Geometry, CulledMatrixEqualsNaiveAllPairs) {
  const TriangleMesh m = testing::test_mesh_mm("mushroom.off");
  RoughModelOptions o;
  o.target_vertices = 400;
  const RoughModel rm = build_rough_model(m, o);
  const OcclusionScene scene(rm.mesh());
  const SensorModel sensor = testing::thesis_sensor();
  const ModelSpec spec = testing::thesis_spec();
  const auto cands = generate_viewpoints(rm, scene, sensor, spec, ViewpointSettings{});
  ASSERT_GT(cands.size(), 500u);
  MatrixStats fast_stats, naive_stats;
  const auto fast = build_measurability(rm, scene, sensor, spec, cands, {}, &fast_stats);
  const auto naive = build_measurability_naive(rm, scene, sensor, spec, cands, {}, &naive_stats);
  auto same_columns = [&](const MeasurabilityMatrix& a, const MeasurabilityMatrix& b, const char* what) {
    ASSERT_EQ(a.n_cols(), b.n_cols());
    for (std::size_t j = 0; j < a.n_cols(); ++j) ASSERT_EQ(a.columns[j].rows(), b.columns[j].rows()) << what << ", column " << j;
    EXPECT_GT(a.nonzeros(), 0u) << what;
  };
  ASSERT_NO_FATAL_FAILURE(same_columns(fast, naive, "blocks culled"));
  EXPECT_LT(fast_stats.rays_cast, naive_stats.rays_cast / 5);  // culling does its job
  EXPECT_GT(fast_stats.pairs_block_culled, 0u);
  EXPECT_GT(fast_stats.pairs_normal_culled, 0u);  // blocks facing away, skipped whole: the columns are still equal
  // The same columns as naive's also when every row is listed for testing (the footprint samples' path, no
  // block culling), with the sensor's range cut by a depth-of-field margin and the spec tightened (the culls'
  // deepest compliant z moves; one level, so naive can take the detuned sensor and spec), and for a
  // random-access sensor (its frustum bounded in y by its field of view, its normal cones wider).
  const RowsToTest every_row = [&](std::size_t, std::vector<std::uint32_t>& rows) {
    for (std::uint32_t i = 0; i < rm.size(); ++i) rows.push_back(i);
  };
  same_columns(build_measurability(rm, scene, sensor, spec, cands, {}, nullptr, nullptr, nullptr, &every_row), naive, "rows listed");
  MatrixSettings detuned;
  detuned.countermeasures.dof_margin_mm = 40.0;
  detuned.countermeasures.compliance_buffer = 0.3;
  same_columns(build_measurability(rm, scene, sensor, spec, cands, detuned),
               build_measurability_naive(rm, scene, detuned_sensor(sensor, detuned.countermeasures),
                                         detuned_spec(spec, detuned.countermeasures), cands, {}),
               "depth-of-field margin");
  SensorModel area = sensor;
  area.kind = SensorKind::random_access;
  area.fov_y_rad = 0.5 * sensor.fov_x_rad;
  same_columns(build_measurability(rm, scene, area, spec, cands, {}), build_measurability_naive(rm, scene, area, spec, cands, {}),
               "random access");
  // Single-pair evaluation agrees with the matrix.
  for (std::size_t j = 0; j < fast.n_cols(); j += 97)
    for (std::uint32_t i = 0; i < rm.size(); i += 7) EXPECT_EQ(measurable(rm, scene, sensor, spec, cands[j], i), fast.columns[j].contains(i));
  // Issue 16: a cancel request stops the build (the daemon's abort waited minutes for planning); without one
  // the flag changes nothing.
  std::atomic<int> cancel{0};
  EXPECT_EQ(build_measurability(rm, scene, sensor, spec, cands, {}, nullptr, &cancel).nonzeros(), fast.nonzeros());
  cancel = 2;
  try {
    build_measurability(rm, scene, sensor, spec, cands, {}, nullptr, &cancel);
    ADD_FAILURE() << "the matrix build ignored the cancel request";
  } catch (const PlanCancelled& e) {
    EXPECT_THAT(e.what(), ::testing::HasSubstr("while building the measurability matrix"));
  }
}

TEST(Geometry, TheMarginsNearMissRaysAndThePlainElementsComeFromOnePass) {
  // A bore's wall: near-miss rays matter there. The tight matrix (margin 1 mm, buffer 0.1) with the plain
  // elements from the same pass must equal two separate builds: tight, and plain minus tight.
  const RoughModel rm = make_rough_model(cylinder_with_bore(80, 30, 50, 4.0));
  const OcclusionScene scene(rm.mesh());
  const SensorModel sensor = testing::thesis_sensor();
  const ModelSpec spec = testing::thesis_spec();
  ViewpointSettings vs;
  vs.twist_levels = 4;
  const auto cands = generate_viewpoints(rm, scene, sensor, spec, vs);
  ASSERT_GT(cands.size(), 100u);
  MatrixSettings tight;
  tight.countermeasures.compliance_buffer = 0.1;
  tight.countermeasures.visibility_margin_mm = 1.0;
  PlainElements plain{{}, {}};
  MatrixStats st;
  const auto one_pass = build_measurability(rm, scene, sensor, spec, cands, tight, &st, nullptr, &plain);
  const auto plain_alone = build_measurability(rm, scene, sensor, spec, cands, {});
  ASSERT_EQ(plain.matrix.n_cols(), cands.size());
  std::size_t extra = 0, tight_nonzeros = 0;
  for (std::size_t j = 0; j < cands.size(); ++j) {
    const auto t = one_pass.columns[j].rows(), e = plain.matrix.columns[j].rows();
    std::vector<std::uint32_t> both;
    std::set_union(t.begin(), t.end(), e.begin(), e.end(), std::back_inserter(both));
    ASSERT_EQ(both.size(), t.size() + e.size()) << "column " << j << ": a row is both tight and plain-only";
    ASSERT_EQ(both, plain_alone.columns[j].rows()) << "column " << j;
    extra += e.size();
    tight_nonzeros += t.size();
  }
  EXPECT_GT(extra, tight_nonzeros / 20);  // the margin does cut elements here
  // Near-miss rays only for pairs the two undisplaced rays leave clear: fewer than 10 per compliant pair.
  EXPECT_LT(st.rays_cast, 10 * st.pairs_compliant);
  // Without the plain request the same tight matrix.
  const auto alone = build_measurability(rm, scene, sensor, spec, cands, tight);
  for (std::size_t j = 0; j < cands.size(); ++j) ASSERT_EQ(alone.columns[j].rows(), one_pass.columns[j].rows());
  // Plain elements wanted for some rows only (every third): the same elements on those rows, none elsewhere,
  // the tight matrix unchanged, and fewer rays.
  std::vector<std::uint8_t> every_third(rm.size(), 0);
  for (std::size_t r = 0; r < rm.size(); r += 3) every_third[r] = 1;
  PlainElements some{{}, {}, &every_third};
  MatrixStats st_some;
  const auto masked = build_measurability(rm, scene, sensor, spec, cands, tight, &st_some, nullptr, &some);
  for (std::size_t j = 0; j < cands.size(); ++j) {
    ASSERT_EQ(masked.columns[j].rows(), one_pass.columns[j].rows()) << "column " << j;
    std::vector<std::uint32_t> expected;
    for (auto r : plain.matrix.columns[j].rows())
      if (every_third[r]) expected.push_back(r);
    ASSERT_EQ(some.matrix.columns[j].rows(), expected) << "column " << j;
  }
  EXPECT_LT(st_some.rays_cast, st.rays_cast);
  std::vector<std::uint8_t> short_flags(rm.size() - 1, 1);
  PlainElements short_mask{{}, {}, &short_flags};
  EXPECT_THROW(build_measurability(rm, scene, sensor, spec, cands, tight, nullptr, nullptr, &short_mask), std::invalid_argument);
  // A plain test tighter than the matrix's is a programming error, refused.
  PlainElements wrong{{0, 0, 0.2, 0}, {}};
  EXPECT_THROW(build_measurability(rm, scene, sensor, spec, cands, tight, nullptr, nullptr, &wrong), std::invalid_argument);
}

TEST(Geometry, OpenDirectionViewsClaimRowsWithTheMarginOnce) {
  // Thesis spec: σz ≤ 0.05 mm, ρ ≥ 2 samples/mm². The 10 % margin alone: 0.05 / 1.1 and 2.2.
  const ModelSpec spec = testing::thesis_spec();
  ASSERT_DOUBLE_EQ(spec.precision_mm, 0.05);
  ASSERT_DOUBLE_EQ(spec.density_per_mm2, 2.0);
  // The spec the columns test those rows by: the matrix's own countermeasures, topped up by the margin.
  auto as_built = [&](double buffer) {
    Countermeasures cm;
    cm.compliance_buffer = buffer;
    return detuned_spec(spec, open_direction_margin(cm).value_or(cm));
  };
  EXPECT_NEAR(as_built(0.0).precision_mm, 0.05 / 1.1, 1e-12);
  EXPECT_NEAR(as_built(0.0).density_per_mm2, 2.2, 1e-12);
  // Under the free-space margin (the matrix already holds every column to σz ≤ spec/1.1) it adds nothing: the
  // two together must still be 1.1, not 1.21.
  EXPECT_FALSE(open_direction_margin(Countermeasures{.compliance_buffer = 0.1}).has_value());
  EXPECT_NEAR(as_built(0.1).precision_mm, 0.05 / 1.1, 1e-12);
  EXPECT_NEAR(as_built(0.1).density_per_mm2, 2.2, 1e-12);
  // A smaller buffer is topped up to the margin; a larger one is not loosened.
  EXPECT_NEAR(as_built(0.05).precision_mm, 0.05 / 1.1, 1e-12);
  EXPECT_NEAR(as_built(0.25).precision_mm, 0.05 / 1.25, 1e-12);
  EXPECT_NEAR(as_built(0.25).density_per_mm2, 2.5, 1e-12);
}

TEST(Geometry, ViewpointPositionsFollowTheFootprintNotTheMeshDensity) {
  // A 40 mm sphere sampled finely: d_v = 4 alone would give a position every 4 rows. The footprint of the
  // thesis sensor at R_o = 142 mm is 2·142·tan(13.5°) = 68.18 mm wide; at 0.07 of it (4.773 mm) positions
  // are no denser than one per 22.78 mm², i.e. ceil(area / 22.72) of them.
  const RoughModel rm = make_rough_model(testing::uv_sphere({0, 0, 0}, 40.0, 80, 160));
  const OcclusionScene scene(rm.mesh());
  const double area = std::accumulate(rm.area_mm2.begin(), rm.area_mm2.end(), 0.0);
  ASSERT_NEAR(area, 4 * std::numbers::pi * 40 * 40, 0.01 * 4 * std::numbers::pi * 40 * 40);
  ViewpointSettings st;
  st.bisector_tilt = false;
  st.twist_levels = 1;
  GenerationReport rep;
  (void)generate_viewpoints(rm, scene, testing::thesis_sensor(), testing::thesis_spec(), st, &rep);
  const double spacing = 0.07 * 68.18;
  EXPECT_EQ(rep.positions_by_decimation, rm.size() / 4);
  EXPECT_NEAR(double(rep.positions), std::ceil(area / (spacing * spacing)), 1.0);
  EXPECT_LT(rep.positions, rm.size() / 4);
  // 0 turns the limit off: d_v alone.
  st.min_position_spacing_fraction = 0.0;
  (void)generate_viewpoints(rm, scene, testing::thesis_sensor(), testing::thesis_spec(), st, &rep);
  EXPECT_EQ(rep.positions, rm.size() / 4);
}

TEST(Geometry, SingleBestViewSeesAWholeSmallSegment) {
  const RoughModel rm = make_rough_model(testing::flat_patch(50.0, 2.5));
  const OcclusionScene scene(rm.mesh());
  std::vector<std::uint32_t> all(rm.size());
  for (std::uint32_t i = 0; i < rm.size(); ++i) all[i] = i;
  const auto views = single_best_views(rm, all, testing::thesis_sensor(), testing::thesis_spec(), 4);
  ASSERT_EQ(views.size(), 4u);
  const auto m = build_measurability(rm, scene, testing::thesis_sensor(), testing::thesis_spec(), views);
  EXPECT_EQ(m.columns[0].count(), rm.size());
}

}  // namespace
}  // namespace scancell::planner

namespace scancell::planner {
namespace {

TEST(Geometry, SegmentsAddSingleBestViewsThatCoverAPatchInOneView) {
  // Two separate 50 mm plates, labelled 0 and 1, each smaller than the footprint: with segments the cover
  // may take one single-best view per plate.
  TriangleMesh m = testing::flat_patch(50.0, 2.5);
  const std::size_t first = m.vertices.size();
  testing::add_grid(m, {200, -25, 0}, Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY(), 21, 21, 2.5);
  RoughModelOptions o;
  o.vertex_labels.assign(m.vertices.size(), 1);
  std::fill(o.vertex_labels.begin(), o.vertex_labels.begin() + first, 0);
  PlannerSettings st;
  st.cover.mode = CoverMode::greedy;
  const ViewPlan p = plan_views(m, testing::thesis_sensor(), testing::thesis_spec(), st, o);
  EXPECT_EQ(p.segments, 2u);
  EXPECT_EQ(p.generation.single_best_views, 8u);
  EXPECT_EQ(p.views.size(), 2u);
  EXPECT_DOUBLE_EQ(p.cover.cumulative_fraction.back(), 1.0);
  // Labels must match the vertex count.
  o.vertex_labels.pop_back();
  EXPECT_THROW(plan_views(m, testing::thesis_sensor(), testing::thesis_spec(), st, o), ConfigError);
}

TEST(SensorModel, RandomAccessDensityUsesTheYFieldOfView) {
  SensorModel s = testing::thesis_sensor();
  s.kind = SensorKind::random_access;
  s.fov_y_rad = s.fov_x_rad;
  // Square raster: δy = δx = 142·Φ/255 = 0.262414 mm, ρ = 1 / (2 δx²) = 7.26099.
  EXPECT_NEAR(predicted_density_per_mm2(s, {142.0, 0.0, 0.0, 0.0}, 0.0), 7.2609160, 1e-6);
  // The receiver sits a baseline from a fixed laser at the origin, whatever the point's y.
  const PointTest t = test_point(s, testing::thesis_spec(), 0.0, {0, 20, -150}, {0, 0, 1});
  EXPECT_EQ(t.laser_y_mm, 0.0);
  EXPECT_EQ(t.receiver_y_mm, 180.0);
}

}  // namespace
}  // namespace scancell::planner
