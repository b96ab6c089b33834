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

  const Eigen::Matrix3d R = pose.camera_to_object.linear();
  const Eigen::Vector3d T = pose.camera_to_object.translation();
  const double cos_t_xz = std::cos(s.grazing_xz_rad), cos_t_yz = std::cos(s.grazing_yz_rad);
  // Per-column tangent of the laser scan angle; identical for every profile.
  std::vector<double> tan_x(img.columns);
  for (int i = 0; i < img.columns; ++i)
    tan_x[i] = std::tan(-0.5 * s.fov_x_rad + s.fov_x_rad * i / (img.columns - 1));

  std::atomic<std::uint64_t> missed{0}, close{0}, back{0}, grazing{0}, shadow{0}, kept{0};
  tbb::parallel_for(tbb::blocked_range<int>(0, img.rows, 4), [&](const tbb::blocked_range<int>& range) {
    std::vector<OcclusionRay> rays(img.columns), to_receiver;
    std::vector<Hit> hits(img.columns);
    std::vector<int> candidate_column;
    std::vector<Eigen::Vector3d> cam_point, cam_normal;
    std::vector<double> sigma;
    std::vector<std::uint8_t> blocked;
    std::uint64_t c_missed = 0, c_close = 0, c_back = 0, c_grazing = 0, c_shadow = 0, c_kept = 0;
    for (int j = range.begin(); j != range.end(); ++j) {
      Eigen::Vector3d laser = Eigen::Vector3d::Zero();
      double tan_y = 0.0;
      if (s.kind == SensorKind::line_scan) {
        laser.y() = -0.5 * pose.scan_length_mm + pose.scan_length_mm * j / (img.rows - 1);
      } else {
        tan_y = std::tan(-0.5 * s.fov_y_rad + s.fov_y_rad * j / (img.rows - 1));
      }
      const Eigen::Vector3d receiver = laser + Eigen::Vector3d(0.0, s.baseline_mm, 0.0);
      const Eigen::Vector3d laser_obj = R * laser + T, receiver_obj = R * receiver + T;
      for (int i = 0; i < img.columns; ++i) {
        // Direction with unit boresight component: the ray parameter is the range z.
        const Eigen::Vector3d d = R * Eigen::Vector3d(tan_x[i], tan_y, -1.0);
        rays[i] = {laser_obj.cast<float>(), d.cast<float>(), 0.0f, static_cast<float>(s.range_max_mm)};
      }
      scene.first_hits(rays.data(), rays.size(), hits.data());

      candidate_column.clear();
      cam_point.clear();
      cam_normal.clear();
      sigma.clear();
      to_receiver.clear();
      for (int i = 0; i < img.columns; ++i) {
        const Hit& h = hits[i];
        if (h.triangle == kNoHit || (options.object_triangles && h.triangle >= options.object_triangles)) { ++c_missed; continue; }
        const double z = h.t;
        if (z < s.range_min_mm) { ++c_close; continue; }
        const Eigen::Vector3d p(laser.x() + tan_x[i] * z, laser.y() + tan_y * z, -z);
        const Eigen::Vector3d n_obj = h.geometric_normal.normalized();
        const Eigen::Vector3d n = R.transpose() * n_obj;
        if (n.dot(laser - p) <= 0.0 || n.dot(receiver - p) <= 0.0) { ++c_back; continue; }
        // Incidence in the x-z plane against the laser ray, and in the y-z plane (eq. 3.3/3.4).
        const double cos_phi = z / std::sqrt(p.x() * p.x() + z * z);
        const double cos_xz = cos_between(n.x(), n.z(), -(p.x() - laser.x()), z, cos_phi);
        const double cos_yz = s.kind == SensorKind::line_scan ? cos_between(n.y(), n.z(), 0.0, 1.0, 1.0)
                                                              : cos_between(n.y(), n.z(), -(p.y() - laser.y()), z, 1.0);
        if (!(cos_xz > cos_t_xz) || !(cos_yz > cos_t_yz)) { ++c_grazing; continue; }
        const Eigen::Vector3d p_obj = R * p + T;
        const Eigen::Vector3d origin = p_obj + options.ray_offset_mm * n_obj;
        const Eigen::Vector3d to = receiver_obj - origin;
        to_receiver.push_back({origin.cast<float>(), to.cast<float>(), 0.0f, 1.0f});
        candidate_column.push_back(i);
        cam_point.push_back(p);
        cam_normal.push_back(n);
        sigma.push_back(s.noise_cz_per_mm * z * z / cos_yz);
      }
      blocked.assign(to_receiver.size(), 0);
      if (!to_receiver.empty()) scene.occluded(to_receiver.data(), to_receiver.size(), blocked.data());

      // Noise: one stream per (seed, profile), drawn in column order, so the image does not depend on threads.
      std::mt19937_64 rng(mix_seed(options.seed, static_cast<std::uint64_t>(j)));
      std::normal_distribution<double> unit(0.0, 1.0);
      for (std::size_t k = 0; k < candidate_column.size(); ++k) {
        if (blocked[k]) { ++c_shadow; continue; }
        const int i = candidate_column[k];
        const Eigen::Vector3d& p = cam_point[k];
        const double z = -p.z();
        Eigen::Vector3d m = p;
        if (options.noise) {
          m.x() += s.noise_cx * z * unit(rng);
          m.y() += s.noise_cy * z * unit(rng);
          m.z() -= sigma[k] * unit(rng);  // range error along the boresight
        }
        const std::size_t at = static_cast<std::size_t>(j) * img.columns + i;
        RangeSample& out = img.samples[at];
        out.camera_mm = m.cast<float>();
        out.object_mm = (R * m + T).cast<float>();
        out.sigma_z_mm = static_cast<float>(sigma[k]);
        out.measured = true;
        img.truth[at] = {(R * p + T).cast<float>(), hits[i].triangle};
        ++c_kept;
      }
    }
    missed += c_missed; close += c_close; back += c_back; grazing += c_grazing; shadow += c_shadow; kept += c_kept;
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
