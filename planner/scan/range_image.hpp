#pragma once
// A scan as any line-scan or random-access range camera delivers it (thesis 3.3): the pose the camera was
// at, one sample per pixel with its predicted precision, which profiles were acquired, and the range image
// file. Nothing here depends on how the image was made; simulation adds only the optional `truth`.
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "planner/core/sensor.hpp"

namespace scancell::planner {

/// Triangle id of a sample without simulation truth.
inline constexpr std::uint32_t kNoTriangle = 0xFFFFFFFFu;

/// Where the camera actually is (what the positioner reached) and its sensor setting.
struct ScanPose {
  Eigen::Isometry3d camera_to_object = Eigen::Isometry3d::Identity();
  double scan_length_mm = 0.0;  // L_y, line-scan only
};

/// One pixel of a range image, as any scanner reports it.
struct RangeSample {
  Eigen::Vector3f camera_mm = Eigen::Vector3f::Zero();  // measured point (with noise), camera frame
  Eigen::Vector3f object_mm = Eigen::Vector3f::Zero();  // measured point (with noise), object frame
  float sigma_z_mm = 0.0f;                              // predicted depth noise there, eq. 3.4
  bool measured = false;                                // a return came back at this pixel
  bool valid() const { return measured; }
};

/// What only a simulated scanner knows about a sample: the noise-free surface point the laser hit and the
/// fine-mesh triangle it lies on. Ground-truth checks (verification, the simulated cell's result) read it;
/// nothing that must work with a real scanner may.
struct SampleTruth {
  Eigen::Vector3f object_mm = Eigen::Vector3f::Zero();
  std::uint32_t triangle = kNoTriangle;
};

/// One scan: rows = profiles (index j), columns = laser rays across Φx (index i).
struct RangeImage {
  SensorKind kind = SensorKind::line_scan;
  int columns = 0;  // N_x
  int rows = 0;     // N_y
  ScanPose pose;
  /// The scan job that measured it (`comment job N` in the file), 0 when none did (offline, a test). A
  /// product is made from one job's images: `scancell fuse` refuses a mix.
  std::int64_t job = 0;
  std::vector<RangeSample> samples;  // row-major, j * columns + i
  /// Line scan on the cell: 1 for each row whose profile was acquired, 0 for a profile the sweep passed
  /// without firing (the position compare missed it). A lost row holds no samples and says nothing about
  /// the surface. Empty: every row was acquired (the virtual scanner, a stored file).
  std::vector<std::uint8_t> acquired_rows;
  /// Simulation only, parallel to `samples`: the virtual scanner's ground truth. Empty from a real scanner.
  std::vector<SampleTruth> truth;

  /// Whether every sample has its simulation truth (an image of the in-process virtual scanner).
  bool has_truth() const { return truth.size() == samples.size(); }
  const RangeSample& at(int i, int j) const { return samples[static_cast<std::size_t>(j) * columns + i]; }
  std::size_t valid_count() const;
};

/// Local sampling density of sample (i, j) from the measured samples themselves: the eq. 3.5-3.8 chords δx, δy
/// are the mean distances to the two neighbours along the profile and across profiles (the nearer one alone
/// where the other is over twice as far: a depth step); ρ = 1/(δx² + δy²).
/// Zero when the sample has no valid neighbour in one of the two directions (isolated samples are not a
/// surface measurement).
double sample_density_per_mm2(const RangeImage& image, int i, int j);

/// The patch of surface sample (i, j) stands for: the parallelogram spanned by its chord vectors along the
/// profile (`along_mm`) and across profiles (`across_mm`), centred on the sample, so that a grid of samples
/// tiles the surface it measured and no more (a half chord past the last sample, not a whole spacing).
/// Each chord is the same neighbour choice as sample_density_per_mm2 (the mean of both sides, or the nearer
/// across a depth step). `valid` is false where sample_density_per_mm2 is zero.
struct SampleCell {
  bool valid = false;
  Eigen::Vector3d along_mm = Eigen::Vector3d::Zero();
  Eigen::Vector3d across_mm = Eigen::Vector3d::Zero();
  double along_length_mm = 0.0;   ///< δx: the mean chord length (not the mean chord's length), for eq. 3.8
  double across_length_mm = 0.0;  ///< δy
  double density_per_mm2() const;
  /// True when `offset_mm` (point minus sample) lies inside the cell: its in-plane coordinates on the two
  /// chords within ±`reach` (½: the cell itself), and its distance off the cell's plane within the longer
  /// half chord.
  bool contains(const Eigen::Vector3d& offset_mm, double reach = 0.5) const;
};
SampleCell sample_cell(const RangeImage& image, int i, int j);

/// Binary little-endian PLY, one `vertex` per valid sample (documented in docs/range-image-format.md). The
/// temporary-file-and-rename write means a reader never sees half a file.
/// The range image file's bytes (docs/range-image-format.md) and back; the parser refuses damage like
/// load_range_image, naming `name` (the daemon journals scans as these bytes).
std::string range_image_to_ply(const RangeImage& image);
RangeImage range_image_from_ply(const std::string& bytes, const std::string& name);
void save_range_image(const RangeImage& image, const std::filesystem::path& path);
/// Reads exactly what save_range_image writes; throws DataError naming the file and what is wrong.
RangeImage load_range_image(const std::filesystem::path& path);

}  // namespace scancell::planner
