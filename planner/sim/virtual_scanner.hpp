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
#include "planner/core/sensor.hpp"

namespace scancell::planner {

/// Where the camera actually is (what the positioner reached) and its sensor setting.
struct ScanPose {
  Eigen::Isometry3d camera_to_object = Eigen::Isometry3d::Identity();
  double scan_length_mm = 0.0;  // L_y, line-scan only
};

struct RangeSample {
  Eigen::Vector3f camera_mm = Eigen::Vector3f::Zero();       // measured point (with noise), camera frame
  Eigen::Vector3f object_mm = Eigen::Vector3f::Zero();       // measured point (with noise), object frame
  Eigen::Vector3f true_object_mm = Eigen::Vector3f::Zero();  // the surface point the laser hit, object frame
  float sigma_z_mm = 0.0f;                                   // predicted depth noise there, eq. 3.4
  std::uint32_t triangle = kNoHit;                           // fine-mesh triangle hit; kNoHit: no sample
  bool valid() const { return triangle != kNoHit; }
};

/// One scan: rows = profiles (index j), columns = laser rays across Φx (index i).
struct RangeImage {
  SensorKind kind = SensorKind::line_scan;
  int columns = 0;  // N_x
  int rows = 0;     // N_y
  ScanPose pose;
  std::vector<RangeSample> samples;  // row-major, j * columns + i
  /// Line scan on the cell: 1 for each row whose profile was acquired, 0 for a profile the sweep passed
  /// without firing (the position compare missed it). A lost row holds no samples and says nothing about
  /// the surface. Empty: every row was acquired (the virtual scanner, a stored file).
  std::vector<std::uint8_t> acquired_rows;

  const RangeSample& at(int i, int j) const { return samples[static_cast<std::size_t>(j) * columns + i]; }
  std::size_t valid_count() const;
};

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

/// Local sampling density of sample (i, j) from the measured samples themselves: the eq. 3.5-3.8 chords δx, δy
/// are the mean distances to the two neighbours along the profile and across profiles (the nearer one alone
/// where the other is over twice as far: a depth step); ρ = 1/(δx² + δy²).
/// Zero when the sample has no valid neighbour in one of the two directions (isolated samples are not a
/// surface measurement).
double sample_density_per_mm2(const RangeImage& image, int i, int j);

/// Binary little-endian PLY, one `vertex` per valid sample (documented in docs/range-image-format.md). The
/// temporary-file-and-rename write means a reader never sees half a file.
/// The range image file's bytes (docs/range-image-format.md) and back; the parser refuses damage like
/// load_range_image, naming `name` (the daemon journals scans as these bytes).
std::string range_image_to_ply(const RangeImage& image);
RangeImage range_image_from_ply(const std::string& bytes, const std::string& name);
void save_range_image(const RangeImage& image, const std::filesystem::path& path);
/// Reads exactly what save_range_image writes; throws DataError naming the file and what is wrong.
RangeImage load_range_image(const std::filesystem::path& path);

/// 64-bit mix of a seed and stream indices (splitmix64), for per-view and per-profile random streams.
std::uint64_t mix_seed(std::uint64_t seed, std::uint64_t a, std::uint64_t b = 0);

}  // namespace scancell::planner
