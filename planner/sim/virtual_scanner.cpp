#include "planner/sim/virtual_scanner.hpp"

#include <atomic>
#include <bit>
#include <limits>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <random>
#include <sstream>
#include <string>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "common/errors.hpp"

namespace scancell::planner {

std::uint64_t mix_seed(std::uint64_t seed, std::uint64_t a, std::uint64_t b) {
  auto splitmix = [](std::uint64_t x) {
    x += 0x9E3779B97F4A7C15ull;
    x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
    x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
    return x ^ (x >> 31);
  };
  return splitmix(splitmix(splitmix(seed) ^ a) ^ (b * 0xD1B54A32D192ED03ull));
}

namespace {

/// What one thread's profiles dropped and kept, summed into ScanStats at the end.
struct Tally {
  std::uint64_t missed = 0, close = 0, back = 0, grazing = 0, shadow = 0, kept = 0;
};

/// Returns of one profile that pass the surface tests, waiting for their line of sight to the receiver.
struct Returns {
  std::vector<OcclusionRay> to_receiver;
  std::vector<int> column;
  std::vector<Eigen::Vector3d> cam_point;  // the noise-free hit, camera frame
  std::vector<double> sigma;               // eq. 3.4 at that hit
  void clear() {
    to_receiver.clear();
    column.clear();
    cam_point.clear();
    sigma.clear();
  }
};

/// One view's scan, profile by profile: the laser's rays, the tests a return must pass (range, facing both
/// lines of sight, grazing, eq. 3.3/3.4), the receiver's line of sight, then the noisy sample.
class ProfileScanner {
 public:
  ProfileScanner(const OcclusionScene& scene, const SensorModel& s, const ScanOptions& options, RangeImage& img)
      : scene_(scene), s_(s), o_(options), img_(img), R_(img.pose.camera_to_object.linear()), T_(img.pose.camera_to_object.translation()),
        cos_t_xz_(std::cos(s.grazing_xz_rad)), cos_t_yz_(std::cos(s.grazing_yz_rad)), tan_x_(img.columns) {
    // Per-column tangent of the laser scan angle; identical for every profile.
    for (int i = 0; i < img.columns; ++i) tan_x_[i] = std::tan(-0.5 * s.fov_x_rad + s.fov_x_rad * i / (img.columns - 1));
  }

  void profile(int j, Tally& t) {
    Eigen::Vector3d laser = Eigen::Vector3d::Zero();
    double tan_y = 0.0;
    if (s_.kind == SensorKind::line_scan) {
      laser.y() = -0.5 * img_.pose.scan_length_mm + img_.pose.scan_length_mm * j / (img_.rows - 1);
    } else {
      tan_y = std::tan(-0.5 * s_.fov_y_rad + s_.fov_y_rad * j / (img_.rows - 1));
    }
    const Eigen::Vector3d receiver = laser + Eigen::Vector3d(0.0, s_.baseline_mm, 0.0);
    cast_laser(laser, tan_y);
    test_returns(laser, receiver, tan_y, t);
    blocked_.assign(returns_.to_receiver.size(), 0);
    if (!returns_.to_receiver.empty()) scene_.occluded(returns_.to_receiver.data(), returns_.to_receiver.size(), blocked_.data());
    write_samples(j, t);
  }

 private:
  void cast_laser(const Eigen::Vector3d& laser, double tan_y) {
    rays_.resize(img_.columns);
    hits_.resize(img_.columns);
    const Eigen::Vector3d laser_obj = R_ * laser + T_;
    for (int i = 0; i < img_.columns; ++i) {
      // Direction with unit boresight component: the ray parameter is the range z.
      const Eigen::Vector3d d = R_ * Eigen::Vector3d(tan_x_[i], tan_y, -1.0);
      rays_[i] = {laser_obj.cast<float>(), d.cast<float>(), 0.0f, static_cast<float>(s_.range_max_mm)};
    }
    scene_.first_hits(rays_.data(), rays_.size(), hits_.data());
  }

  void test_returns(const Eigen::Vector3d& laser, const Eigen::Vector3d& receiver, double tan_y, Tally& t) {
    returns_.clear();
    const Eigen::Vector3d receiver_obj = R_ * receiver + T_;
    for (int i = 0; i < img_.columns; ++i) {
      const Hit& h = hits_[i];
      if (h.triangle == kNoHit || (o_.object_triangles && h.triangle >= o_.object_triangles)) { ++t.missed; continue; }
      const double z = h.t;
      if (z < s_.range_min_mm) { ++t.close; continue; }
      const Eigen::Vector3d p(laser.x() + tan_x_[i] * z, laser.y() + tan_y * z, -z);
      const Eigen::Vector3d n_obj = h.geometric_normal.normalized();
      const Eigen::Vector3d n = R_.transpose() * n_obj;
      if (n.dot(laser - p) <= 0.0 || n.dot(receiver - p) <= 0.0) { ++t.back; continue; }
      // Incidence in the x-z plane against the laser ray, and in the y-z plane (eq. 3.3/3.4).
      const double cos_phi = z / std::sqrt(p.x() * p.x() + z * z);
      const double cos_xz = cos_between(n.x(), n.z(), -(p.x() - laser.x()), z, cos_phi);
      const double cos_yz = s_.kind == SensorKind::line_scan ? cos_between(n.y(), n.z(), 0.0, 1.0, 1.0)
                                                             : cos_between(n.y(), n.z(), -(p.y() - laser.y()), z, 1.0);
      if (!(cos_xz > cos_t_xz_) || !(cos_yz > cos_t_yz_)) { ++t.grazing; continue; }
      const Eigen::Vector3d origin = R_ * p + T_ + o_.ray_offset_mm * n_obj;
      const double to_receiver_mm = std::max((receiver_obj - origin).norm(), 1e-9);
      returns_.to_receiver.push_back({origin.cast<float>(), (receiver_obj - origin).cast<float>(),
                                      static_cast<float>(kOffSurfaceStart * o_.ray_offset_mm / to_receiver_mm), 1.0f});
      returns_.column.push_back(i);
      returns_.cam_point.push_back(p);
      returns_.sigma.push_back(s_.noise_cz_per_mm * z * z / cos_yz);
    }
  }

  void write_samples(int j, Tally& t) {
    // Noise: one stream per (seed, profile), drawn in column order, so the image does not depend on threads.
    std::mt19937_64 rng(mix_seed(o_.seed, static_cast<std::uint64_t>(j)));
    std::normal_distribution<double> unit(0.0, 1.0);
    for (std::size_t k = 0; k < returns_.column.size(); ++k) {
      if (blocked_[k]) { ++t.shadow; continue; }
      const int i = returns_.column[k];
      const Eigen::Vector3d& p = returns_.cam_point[k];
      const double z = -p.z();
      Eigen::Vector3d m = p;
      if (o_.noise) {
        m.x() += s_.noise_cx * z * unit(rng);
        m.y() += s_.noise_cy * z * unit(rng);
        m.z() -= returns_.sigma[k] * unit(rng);  // range error along the boresight
      }
      const std::size_t at = static_cast<std::size_t>(j) * img_.columns + i;
      RangeSample& out = img_.samples[at];
      out.camera_mm = m.cast<float>();
      out.object_mm = (R_ * m + T_).cast<float>();
      out.sigma_z_mm = static_cast<float>(returns_.sigma[k]);
      out.measured = true;
      img_.truth[at] = {(R_ * p + T_).cast<float>(), hits_[i].triangle};
      ++t.kept;
    }
  }

  const OcclusionScene& scene_;
  const SensorModel& s_;
  const ScanOptions& o_;
  RangeImage& img_;
  const Eigen::Matrix3d R_;
  const Eigen::Vector3d T_;
  const double cos_t_xz_, cos_t_yz_;
  std::vector<double> tan_x_;
  std::vector<OcclusionRay> rays_;
  std::vector<Hit> hits_;
  Returns returns_;
  std::vector<std::uint8_t> blocked_;
};

}  // namespace

RangeImage virtual_scan(const OcclusionScene& scene, const SensorModel& s, const ScanPose& pose,
                        const ScanOptions& options, ScanStats* stats) {
  if (s.kind == SensorKind::line_scan && !(pose.scan_length_mm > 0.0))
    throw std::invalid_argument("virtual_scan: line-scan view needs scan_length_mm > 0");
  RangeImage img;
  img.kind = s.kind;
  img.columns = s.samples_x;
  img.rows = s.samples_y;
  img.pose = pose;
  img.samples.resize(static_cast<std::size_t>(img.columns) * img.rows);
  img.truth.resize(img.samples.size());

  std::atomic<std::uint64_t> missed{0}, close{0}, back{0}, grazing{0}, shadow{0}, kept{0};
  tbb::parallel_for(tbb::blocked_range<int>(0, img.rows, 4), [&](const tbb::blocked_range<int>& range) {
    ProfileScanner scanner(scene, s, options, img);
    Tally t;
    for (int j = range.begin(); j != range.end(); ++j) scanner.profile(j, t);
    missed += t.missed; close += t.close; back += t.back; grazing += t.grazing; shadow += t.shadow; kept += t.kept;
  });
  if (stats) {
    stats->rays = static_cast<std::uint64_t>(img.columns) * img.rows;
    stats->missed = missed;
    stats->too_close = close;
    stats->back_facing = back;
    stats->beyond_grazing = grazing;
    stats->receiver_occluded = shadow;
    stats->samples = kept;
  }
  return img;
}

}  // namespace scancell::planner
