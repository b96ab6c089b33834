#pragma once
// Virtual range camera (thesis 3.3.2, 4.4.1): executes one generalized viewpoint against a fine model and
// returns the range image the real camera would record, with the calibrated noise of eq. 3.3/3.4. The
// verifier closes the 3M loop with it, and the daemon's simulated scanner is the same code.
//
// Geometry (camera frame of sensor.hpp): a line-scan camera records N_y profiles; profile j has the laser at
// (0, y_j, 0), y_j = -L_y/2 + j·L_y/(N_y-1), and fans N_x rays in the x-z plane across Φx; the receiver sits
// at (0, y_j + b, 0). A random-access camera keeps the laser at the origin and steers each ray to
// (tan φx, tan φy, -1); the receiver sits at (0, b, 0). Ray directions are scaled so that the ray parameter is
// the range z along the boresight.
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "planner/geometry/scene.hpp"
#include "planner/scan/range_image.hpp"
#include "planner/core/sensor.hpp"

namespace scancell::planner {

/// Why rays gave no sample (each ray counts once, in this order).
struct ScanStats {
  std::uint64_t rays = 0;
  std::uint64_t missed = 0;             // nothing within R_max (or a fixture, not the object, was hit)
  std::uint64_t too_close = 0;          // first surface nearer than R_min
  std::uint64_t back_facing = 0;        // surface faces away from laser or receiver
  std::uint64_t beyond_grazing = 0;     // θxz ≥ t_xz or θyz ≥ t_yz
  std::uint64_t receiver_occluded = 0;  // bi-static shadow
  std::uint64_t samples = 0;
};

struct ScanOptions {
  std::uint64_t seed = 1;       // noise stream; same seed, same image, any thread count
  bool noise = true;            // false: the noise-free image (tests, diagnostics)
  double ray_offset_mm = 0.02;  // receiver rays start this far off the surface along its normal
  /// Triangles at or past this index belong to cell fixtures (the plate): they block rays but are not the
  /// object, so a laser hit on them is no sample. 0: every triangle is the object.
  std::size_t object_triangles = 0;
};

/// Executes one view. Parallel over profiles (oneTBB); deterministic.
RangeImage virtual_scan(const OcclusionScene& scene, const SensorModel& sensor, const ScanPose& pose,
                        const ScanOptions& options = {}, ScanStats* stats = nullptr);

/// 64-bit mix of a seed and stream indices (splitmix64), for per-view and per-profile random streams.
std::uint64_t mix_seed(std::uint64_t seed, std::uint64_t a, std::uint64_t b = 0);

}  // namespace scancell::planner
