// The occlusion scene (Embree): rays cast in a batch find what the same rays find one at a time.
#include <cmath>
#include <vector>

#include <gtest/gtest.h>

#include "planner/geometry/mesh.hpp"
#include "planner/geometry/scene.hpp"
#include "planner/sim/synthetic.hpp"
#include "test_meshes.hpp"

namespace scancell::planner {
namespace {

TEST(OcclusionScene, AProfileAlongAnAxisPlaneHitsInABatchAsOneByOne) {
  // One profile of a turntable view of the fandisk (tests/data, scaled to 200 mm, edges refined to 3 mm: the
  // cell benches' object) found by bench_loop: the camera turned by π/2 about z, so the laser plane is x =
  // -86.376 up to rounding (cos(π/2) = 6e-17 in the rotation), the rays' x components ±1e-19, the sign
  // turning at the boresight. Rays just past the boresight strike the band y = 51.11 (normal +y) 230 mm off.
  // Cast as a coherent stream, Embree 3 missed those 16 hits that each ray finds alone, and the virtual
  // scanner lost the band; the scene casts incoherent streams, which agree.
  TriangleMesh fandisk = load_mesh(testing::source_path("tests/data/fandisk.off"));
  apply_scale(fandisk, fit_scale(fandisk, 200.0));
  const OcclusionScene scene(refine_edges(fandisk, 3.0));
  Eigen::Matrix3d r;
  r << -6.123233995736766e-17, -1, 0, -0.34289780745545134, 2.0996435116748197e-17, 0.93937271284737889,
      -0.93937271284737889, 5.7519989299745416e-17, -0.34289780745545134;
  const Eigen::Vector3f laser(-86.375958f, 268.274959f, -82.931399f);
  const double fov = testing::thesis_sensor().fov_x_rad;
  std::vector<OcclusionRay> rays(256);
  for (int i = 0; i < 256; ++i) {
    const double tan_x = std::tan(-0.5 * fov + fov * i / 255.0);
    rays[i] = {laser, (r * Eigen::Vector3d(tan_x, 0.0, -1.0)).cast<float>(), 0.0f, 407.0f};
  }
  std::vector<Hit> batch(rays.size());
  scene.first_hits(rays.data(), rays.size(), batch.data());
  std::size_t on_band = 0;
  for (std::size_t i = 0; i < rays.size(); ++i) {
    Hit one;
    scene.first_hits(&rays[i], 1, &one);
    EXPECT_EQ(batch[i].triangle, one.triangle) << "ray " << i;
    if (i >= 128 && i <= 137) {
      ASSERT_NE(batch[i].triangle, kNoHit) << "ray " << i;
      const Eigen::Vector3d n = batch[i].geometric_normal.normalized();
      on_band += n.y() > 0.999 && std::abs(batch[i].t - 230.5) < 1.5;
    }
  }
  EXPECT_EQ(on_band, 10u);
}

TEST(OcclusionScene, RaysInThePlaneOfAGridLineDoNotSlipThroughItsEdges) {
  // A view turned by a whole quarter turn casts its laser plane along a world axis up to rounding: the rays'
  // component across the plane is ±1e-17-ish, not zero. When that plane holds a line of the mesh's edges (a
  // CAD part's grid, a rough row's own vertex the view aims at), Embree 3's fast triangle test let such rays
  // pass between the two triangles of each edge: on this flat 100 mm grid (2 mm cells), 95,141 of 311,682
  // rays aimed at it from 200 mm above, fanned in the planes x = -40 ... 40 mm through its grid lines, found
  // nothing, a third of every profile. A component of exactly 0, or of 1e-7 and more, hit. The scene is built
  // robust (RTC_SCENE_FLAG_ROBUST), and every ray hits the grid.
  const TriangleMesh patch = convex_patch(100.0, 0.0, 2.0);
  const OcclusionScene scene(patch);
  std::size_t aimed = 0, missed = 0, unoccluded = 0;
  for (int line = -20; line <= 20; line += 4) {
    const float x = 2.0f * static_cast<float>(line);
    for (const float across : {1e-19f, -1e-19f, 1e-12f, -1e-9f}) {
      const Eigen::Vector3f laser(x, -10.0f, 200.0f);
      std::vector<OcclusionRay> rays;
      for (int i = 0; i < 256; ++i) {
        const float tan_y = -0.19f + 0.38f * static_cast<float>(i) / 255.0f;  // y from -48 to 28 mm
        rays.push_back({laser, Eigen::Vector3f(across, tan_y, -1.0f), 0.0f, 400.0f});
      }
      std::vector<Hit> hits(rays.size());
      std::vector<std::uint8_t> occluded(rays.size());
      scene.first_hits(rays.data(), rays.size(), hits.data());
      scene.occluded(rays.data(), rays.size(), occluded.data());
      for (std::size_t i = 0; i < rays.size(); ++i) {
        ++aimed;
        missed += hits[i].triangle == kNoHit || std::abs(hits[i].t - 200.0f) > 0.01f;
        unoccluded += occluded[i] == 0;
      }
    }
  }
  EXPECT_EQ(aimed, 11u * 4u * 256u);
  EXPECT_EQ(missed, 0u);
  EXPECT_EQ(unoccluded, 0u);
}


TEST(OcclusionScene, RaysParallelUpToRoundingAreCastAlikeWhateverTheSignOfTheirTinyComponent) {
  // Found by the arm's plans of the bored tube: a view turned by a whole quarter turn casts rays across the bore
  // from the wall's vertices on a world axis, directions like (-2e-19, -209.8, 0). Cast in one stream, rays whose
  // tiny component differed in sign from their neighbours' read clear though each, cast alone, strikes the far
  // wall: 86 such rays in one plan, so points in the bore read measurable from views that cannot see them.
  const TriangleMesh tube = weld(cylinder_with_bore(80.0, 50.0, 50.0, 3.0));
  const OcclusionScene scene(tube);
  std::vector<OcclusionRay> rays;
  const float tiny[] = {-2e-19f, 3e-21f, 0.0f, -8.8e-16f, 1e-19f, -0.0f};
  for (const auto& v : tube.vertices) {
    const bool on_y = std::abs(v.x()) < 1e-9 && std::abs(v.y() - 25.0) < 0.1;   // the bore wall at +y
    const bool on_x = std::abs(v.y()) < 1e-9 && std::abs(v.x() + 25.0) < 0.1;   // the bore wall at -x
    if (!(on_y || on_x) || v.z() < 1.0 || v.z() > 49.0) continue;
    for (std::size_t k = 0; k < std::size(tiny); ++k) {
      const float t = tiny[(k + rays.size()) % std::size(tiny)];
      const Eigen::Vector3f dir = on_y ? Eigen::Vector3f(t, -210.0f, 0.0f) : Eigen::Vector3f(210.0f, t, 0.0f);
      const Eigen::Vector3f inward = on_y ? Eigen::Vector3f(0.0f, -0.003f, 0.0f) : Eigen::Vector3f(0.003f, 0.0f, 0.0f);
      rays.push_back({v.cast<float>() + inward, dir, 1e-5f, 0.9999f});
    }
  }
  ASSERT_GE(rays.size(), 100u);
  std::vector<std::uint8_t> batch(rays.size());
  scene.occluded(rays.data(), rays.size(), batch.data());
  std::size_t clear = 0;
  for (std::size_t i = 0; i < rays.size(); ++i) {
    std::uint8_t one = 0;
    scene.occluded(&rays[i], 1, &one);
    EXPECT_EQ(batch[i], one) << "ray " << i;
    clear += batch[i] == 0;
  }
  EXPECT_EQ(clear, 0u) << "of " << rays.size() << " rays across the bore";
}

}  // namespace
}  // namespace scancell::planner
