// Virtual scanner: sample count and spacing on a plane at known range (eq. 3.6/3.7), noise statistics
// (eq. 3.4), bi-static shadow, grazing cut-off, range-image files.
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "common/errors.hpp"
#include "planner/sim/verify.hpp"
#include "planner/sim/virtual_scanner.hpp"
#include "test_meshes.hpp"

namespace sp = scancell::planner;
using sp::testing::add_grid;

namespace {

/// A camera `range` mm above the origin looking down -Z, twist 0.
sp::ScanPose looking_down(double range, double scan_length) {
  sp::Viewpoint v;
  v.position = Eigen::Vector3d(0, 0, range);
  v.axis = -Eigen::Vector3d::UnitZ();
  v.scan_length_mm = scan_length;
  return sp::scan_pose(v);
}

/// Two triangles: a square of side 2·half in the plane through the origin with the given unit normal.
sp::TriangleMesh square(double half, const Eigen::Vector3d& normal, const Eigen::Vector3d& centre = Eigen::Vector3d::Zero()) {
  const Eigen::Vector3d u = normal.unitOrthogonal(), w = normal.cross(u);
  sp::TriangleMesh m;
  m.vertices = {centre - half * u - half * w, centre + half * u - half * w, centre + half * u + half * w,
                centre - half * u + half * w};
  m.triangles = {{0, 1, 2}, {0, 2, 3}};
  return m;
}

}  // namespace

TEST(VirtualScanner, PlaneAtKnownRangeGivesEverySampleWithTheModelSpacing) {
  const sp::SensorModel s = sp::testing::thesis_sensor();
  const sp::TriangleMesh plane = square(300, Eigen::Vector3d::UnitZ());
  const sp::OcclusionScene scene(plane);
  const double z = 200.0, L = 50.0;
  sp::ScanOptions opt;
  opt.noise = false;
  sp::ScanStats st;
  const sp::RangeImage img = sp::virtual_scan(scene, s, looking_down(z, L), opt, &st);
  EXPECT_EQ(st.rays, 256u * 256u);
  EXPECT_EQ(st.samples, 256u * 256u);
  EXPECT_EQ(img.valid_count(), 256u * 256u);
  // Every sample on the plane, at range z.
  ASSERT_EQ(img.truth.size(), img.samples.size());
  for (const auto& t : img.truth) ASSERT_NEAR(t.object_mm.z(), 0.0, 1e-3);
  EXPECT_NEAR(img.at(128, 128).camera_mm.z(), -z, 1e-3);
  // eq. 3.6: δx = R_xz·Φx/(N_x − 1) at the centre (θ_xz = 0); eq. 3.7: δy = L_y/(N_y − 1).
  const double dx = z * s.fov_x_rad / 255.0, dy = L / 255.0;
  EXPECT_NEAR((img.at(128, 128).object_mm - img.at(127, 128).object_mm).norm(), dx, 1e-3 * dx);
  EXPECT_NEAR((img.at(128, 128).object_mm - img.at(128, 127).object_mm).norm(), dy, 1e-4);
  // Eq. 3.8 applied to the samples agrees with the formula at the centre: 1 / (0.3696² + 0.1961²) = 5.713 samples/mm².
  const double rho = 1.0 / (dx * dx + dy * dy);
  EXPECT_NEAR(rho, 5.713, 0.001);
  EXPECT_NEAR(sp::sample_density_per_mm2(img, 128, 128), rho, 0.01 * rho);
  // The sample's cell: the two chords, δx along the profile and δy across, and half of each to either side.
  const sp::SampleCell cell = sp::sample_cell(img, 128, 128);
  ASSERT_TRUE(cell.valid);
  EXPECT_NEAR(cell.along_mm.norm(), dx, 1e-3 * dx);
  EXPECT_NEAR(cell.across_mm.norm(), dy, 1e-4);
  EXPECT_NEAR(std::abs(cell.along_mm.normalized().dot(cell.across_mm.normalized())), 0.0, 1e-3);  // a plane square on
  const Eigen::Vector3d ex = cell.along_mm.normalized(), ey = cell.across_mm.normalized();
  EXPECT_TRUE(cell.contains(0.45 * dx * ex + 0.45 * dy * ey));
  EXPECT_FALSE(cell.contains(0.55 * dx * ex));
  EXPECT_FALSE(cell.contains(-0.55 * dy * ey));
  EXPECT_TRUE(cell.contains(0.7 * dx * ex, 0.75));
  EXPECT_FALSE(cell.contains(Eigen::Vector3d(0, 0, 0.6 * dx)));  // off the plane by more than half the longer chord
  // The first profile has no neighbour behind it: its cell takes the one chord it has.
  EXPECT_NEAR(sp::sample_cell(img, 128, 0).across_mm.norm(), dy, 1e-4);
  // And the swath edge is where the frustum says: x = z·tan(Φx/2).
  EXPECT_NEAR(std::abs(img.at(0, 128).camera_mm.x()), z * std::tan(0.5 * s.fov_x_rad), 1e-3);
}

TEST(VirtualScanner, RangeNoiseMatchesEquation34) {
  const sp::SensorModel s = sp::testing::thesis_sensor();
  const sp::TriangleMesh plane = square(300, Eigen::Vector3d::UnitZ());
  const sp::OcclusionScene scene(plane);
  const double z = 200.0;
  sp::ScanOptions opt;
  opt.seed = 7;
  const sp::RangeImage img = sp::virtual_scan(scene, s, looking_down(z, 50.0), opt);
  // σz = C_z·z²/cos θ_yz with θ_yz = 0 on this plane: 0.019837 mm at 200 mm.
  const double sigma = s.noise_cz_per_mm * z * z;
  EXPECT_NEAR(sigma, 0.019837, 1e-6);
  double sum = 0.0, sum2 = 0.0;
  std::size_t n = 0;
  for (std::size_t k = 0; k < img.samples.size(); ++k) {
    const auto& smp = img.samples[k];
    const double e = static_cast<double>(smp.object_mm.z()) - img.truth[k].object_mm.z();
    EXPECT_NEAR(smp.sigma_z_mm, sigma, 1e-6);
    sum += e;
    sum2 += e * e;
    ++n;
  }
  ASSERT_EQ(n, 65536u);
  const double mean = sum / n, sd = std::sqrt(sum2 / n - mean * mean);
  // Mean within 4 standard errors; the standard deviation within 3 % (its standard error is 0.28 %).
  EXPECT_LT(std::abs(mean), 4.0 * sigma / std::sqrt(static_cast<double>(n)));
  EXPECT_NEAR(sd, sigma, 0.03 * sigma);
  // Same seed, same image; another seed, another image.
  const sp::RangeImage again = sp::virtual_scan(scene, s, looking_down(z, 50.0), opt);
  EXPECT_EQ(again.at(17, 201).object_mm, img.at(17, 201).object_mm);
  opt.seed = 8;
  const sp::RangeImage other = sp::virtual_scan(scene, s, looking_down(z, 50.0), opt);
  EXPECT_NE(other.at(17, 201).object_mm, img.at(17, 201).object_mm);
}

TEST(VirtualScanner, PointShadowedFromTheReceiverHasNoSample) {
  const sp::SensorModel s = sp::testing::thesis_sensor();
  const double z = 200.0;
  const sp::ScanPose pose = looking_down(z, 50.0);
  const Eigen::Vector3d y_c = pose.camera_to_object.linear().col(1);  // receiver side
  // A 20 mm plate half way up the line from the image centre to the receiver (camera y = b/2 = 90 mm), outside
  // the laser's sweep (|y| <= 25 mm): it shadows the receiver, never the laser.
  sp::TriangleMesh m = square(300, Eigen::Vector3d::UnitZ());
  const sp::TriangleMesh plate = square(10, Eigen::Vector3d::UnitZ(), Eigen::Vector3d(0, 0, 100) + 90.0 * y_c);
  for (const auto& t : plate.triangles) m.triangles.push_back({t[0] + 4, t[1] + 4, t[2] + 4});
  m.vertices.insert(m.vertices.end(), plate.vertices.begin(), plate.vertices.end());
  sp::ScanOptions opt;
  opt.noise = false;
  sp::ScanStats with, without;
  const sp::RangeImage shadowed = sp::virtual_scan(sp::OcclusionScene(m), s, pose, opt, &with);
  const sp::RangeImage clear = sp::virtual_scan(sp::OcclusionScene(square(300, Eigen::Vector3d::UnitZ())), s, pose, opt, &without);
  EXPECT_TRUE(clear.at(128, 128).valid());
  EXPECT_FALSE(shadowed.at(128, 128).valid());
  EXPECT_EQ(without.receiver_occluded, 0u);
  EXPECT_GT(with.receiver_occluded, 0u);
  EXPECT_EQ(with.missed + with.too_close + with.back_facing + with.beyond_grazing + with.receiver_occluded + with.samples, with.rays);
  // The shadow is where the plate projects: points with |x| <= 20 mm near y = 0 lose their sample, the
  // swath edge (|x| ~ 48 mm) keeps it.
  EXPECT_TRUE(shadowed.at(0, 128).valid());
}

TEST(VirtualScanner, IncidenceBeyondTheGrazingThresholdDropsSamples) {
  const sp::SensorModel s = sp::testing::thesis_sensor();  // t_yz = 60°
  const sp::ScanPose pose = looking_down(200.0, 50.0);
  const Eigen::Vector3d y_c = pose.camera_to_object.linear().col(1);
  auto tilted = [&](double deg) {
    const double a = deg * M_PI / 180.0;
    // Normal tilted from +Z towards the receiver side in the camera's y-z plane: θ_yz = deg, θ_xz = 0.
    return square(300, (std::cos(a) * Eigen::Vector3d::UnitZ() + std::sin(a) * y_c).normalized(), Eigen::Vector3d(0, 0, 0));
  };
  sp::ScanOptions opt;
  opt.noise = false;
  sp::ScanStats at55, at65;
  const sp::RangeImage a = sp::virtual_scan(sp::OcclusionScene(tilted(55)), s, pose, opt, &at55);
  sp::virtual_scan(sp::OcclusionScene(tilted(65)), s, pose, opt, &at65);
  EXPECT_EQ(at55.samples, 65536u);
  EXPECT_EQ(at65.samples, 0u);
  EXPECT_EQ(at65.beyond_grazing, 65536u);
  // eq. 3.4 at 55°: σz = C_z·z²/cos 55° at the centre profile.
  const double zc = -a.at(128, 128).camera_mm.z();
  EXPECT_NEAR(a.at(128, 128).sigma_z_mm, s.noise_cz_per_mm * zc * zc / std::cos(55 * M_PI / 180), 1e-6);
}

TEST(VirtualScanner, OutOfRangeSurfaceGivesNoSample) {
  const sp::SensorModel s = sp::testing::thesis_sensor();  // R_min 142, R_max 407
  const sp::OcclusionScene scene(square(300, Eigen::Vector3d::UnitZ()));
  sp::ScanStats near, far;
  sp::virtual_scan(scene, s, looking_down(120.0, 50.0), {}, &near);
  sp::virtual_scan(scene, s, looking_down(420.0, 50.0), {}, &far);
  EXPECT_EQ(near.samples, 0u);
  EXPECT_EQ(near.too_close, 65536u);
  EXPECT_EQ(far.samples, 0u);
  EXPECT_EQ(far.missed, 65536u);
}

TEST(VirtualScanner, RangeImageFileRoundTripsAndRefusesDamage) {
  const sp::SensorModel s = sp::testing::thesis_sensor();
  sp::TriangleMesh m = sp::testing::flat_patch(60, 2);
  const sp::RangeImage img = sp::virtual_scan(sp::OcclusionScene(m), s, looking_down(180.0, 40.0));
  ASSERT_GT(img.valid_count(), 1000u);
  ASSERT_LT(img.valid_count(), 65536u);  // some rays miss the patch: only valid samples are stored
  const auto dir = std::filesystem::temp_directory_path() / "scancell_scanner_test";
  std::filesystem::create_directories(dir);
  const auto file = dir / "image.ply";
  sp::save_range_image(img, file);
  const sp::RangeImage back = sp::load_range_image(file);
  EXPECT_EQ(back.columns, img.columns);
  EXPECT_EQ(back.rows, img.rows);
  EXPECT_NEAR(back.pose.scan_length_mm, 40.0, 0);
  EXPECT_TRUE(back.pose.camera_to_object.isApprox(img.pose.camera_to_object, 1e-15));
  ASSERT_EQ(back.valid_count(), img.valid_count());
  ASSERT_EQ(back.truth.size(), back.samples.size());
  for (std::size_t k = 0; k < img.samples.size(); ++k) {
    ASSERT_EQ(back.samples[k].valid(), img.samples[k].valid());
    if (img.samples[k].valid()) {
      ASSERT_EQ(back.samples[k].object_mm, img.samples[k].object_mm);
      ASSERT_EQ(back.truth[k].triangle, img.truth[k].triangle);
      ASSERT_EQ(back.truth[k].object_mm, img.truth[k].object_mm);
    }
  }
  // A real scanner's image has no simulation truth: it is written with kNoTriangle, read back without
  // truth, and verification refuses it instead of judging it by invented triangles.
  sp::RangeImage real = img;
  real.truth.clear();
  const sp::RangeImage real_back = sp::range_image_from_ply(sp::range_image_to_ply(real), "real.ply");
  EXPECT_TRUE(real_back.truth.empty());
  ASSERT_EQ(real_back.valid_count(), img.valid_count());
  // Truth on some samples only: refused, naming how many.
  std::string mixed = sp::range_image_to_ply(img);
  const std::size_t first_record = mixed.find("end_header\n") + 11;
  const std::uint32_t none = sp::kNoTriangle;
  std::memcpy(&mixed[first_record + 48], &none, 4);
  try {
    sp::range_image_from_ply(mixed, "mixed.ply");
    ADD_FAILURE() << "mixed truth accepted";
  } catch (const scancell::DataError& e) {
    EXPECT_THAT(e.what(), ::testing::HasSubstr("mixed.ply: " + std::to_string(img.valid_count() - 1) + " of " +
                                                   std::to_string(img.valid_count()) + " samples carry a triangle id"));
  }
  // Truncated body: refused with the byte counts.
  const auto size = std::filesystem::file_size(file);
  std::filesystem::resize_file(file, size - 10);
  try {
    sp::load_range_image(file);
    FAIL() << "truncated file accepted";
  } catch (const scancell::DataError& e) {
    EXPECT_NE(std::string(e.what()).find("truncated"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("image.ply"), std::string::npos) << e.what();
  }
  // A PLY that is not ours.
  std::ofstream(dir / "other.ply") << "ply\nformat ascii 1.0\nelement vertex 0\nend_header\n";
  EXPECT_THROW(sp::load_range_image(dir / "other.ply"), scancell::DataError);
  EXPECT_THROW(sp::load_range_image(dir / "missing.ply"), scancell::DataError);
  std::filesystem::remove_all(dir);
}

// Issue 16, defect 2: 2^62 samples × 52 bytes wraps to 0 bytes, so an empty body once passed the size check
// and the reader wrote 2^62 samples into a 16-pixel image. Refused now, naming the count and the image size.
TEST(VirtualScanner, RangeImageWhoseSampleCountWrapsIsRefused) {
  const auto file = std::filesystem::path(SCANCELL_SOURCE_DIR) / "tests/data/bad/range-image-count-overflow.ply";
  try {
    sp::load_range_image(file);
    FAIL() << "a range image of 2^62 samples with no body was accepted";
  } catch (const scancell::DataError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("range-image-count-overflow.ply"), std::string::npos) << what;
    EXPECT_NE(what.find("4611686018427387904 exceeds the image's 4 x 4 pixels"), std::string::npos) << what;
  }
}

TEST(VirtualScanner, RandomAccessCameraScansBothAxesOptically) {
  sp::SensorModel s = sp::testing::thesis_sensor();
  s.kind = sp::SensorKind::random_access;
  s.fov_y_rad = 0.3;
  const sp::OcclusionScene scene(square(300, Eigen::Vector3d::UnitZ()));
  sp::ScanOptions opt;
  opt.noise = false;
  sp::ScanStats st;
  const double z = 200.0;
  const sp::RangeImage img = sp::virtual_scan(scene, s, looking_down(z, 0.0), opt, &st);
  EXPECT_EQ(st.samples, 65536u);
  // Both axes fan from the origin: spacing z·Φ/(N − 1) at the centre in x and in y, and the edge of the
  // image at z·tan(Φy/2) in y.
  EXPECT_NEAR((img.at(128, 128).object_mm - img.at(127, 128).object_mm).norm(), z * s.fov_x_rad / 255, 1e-3);
  EXPECT_NEAR((img.at(128, 128).object_mm - img.at(128, 127).object_mm).norm(), z * s.fov_y_rad / 255, 1e-3);
  EXPECT_NEAR(std::abs(img.at(128, 0).camera_mm.y()), z * std::tan(0.15), 1e-3);
  // The receiver sits at (0, b, 0) for every ray: incidence in y-z is measured against each ray, so σz grows
  // towards the image edge in y on a plane facing the camera.
  EXPECT_GT(img.at(128, 0).sigma_z_mm, img.at(128, 128).sigma_z_mm);
}
