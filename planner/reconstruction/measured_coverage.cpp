#include "planner/reconstruction/measured_coverage.hpp"

#include <algorithm>
#include <cmath>

#include "planner/config.hpp"
#include "common/errors.hpp"

namespace scancell::planner {
namespace {

std::uint32_t cell_key(long iu, long iv) {
  iu = std::clamp(iu, -32767L, 32767L);
  iv = std::clamp(iv, -32767L, 32767L);
  return (static_cast<std::uint32_t>(static_cast<std::uint16_t>(iu)) << 16) | static_cast<std::uint16_t>(iv);
}

std::uint64_t grid_key(long x, long y, long z) {
  constexpr long kBias = 1L << 20;
  return (static_cast<std::uint64_t>(x + kBias) << 42) | (static_cast<std::uint64_t>(y + kBias) << 21) |
         static_cast<std::uint64_t>(z + kBias);
}

/// Inside a convex polygon of either orientation (cell centres on an edge count).
bool inside_convex(const std::vector<Eigen::Vector2d>& poly, const Eigen::Vector2d& q) {
  bool pos = false, neg = false;
  for (std::size_t k = 0; k < poly.size(); ++k) {
    const Eigen::Vector2d a = poly[k], b = poly[(k + 1) % poly.size()];
    const double c = (b - a).x() * (q - a).y() - (b - a).y() * (q - a).x();
    pos = pos || c > 1e-12;
    neg = neg || c < -1e-12;
  }
  return !(pos && neg);
}

/// A compliant sample fills every footprint cell whose centre lies within ¾ of a cell of it along each tangent
/// axis, not only the cell it rounds into: the verifier's sample cell reaches ¾ of a chord for the same reason
/// (docs/verification.md), range noise and the projection into a row's tangent plane move samples, and
/// rounding each to one cell left slivers of empty cells on surface the samples cover. On the tube's single
/// shot 29 of the 66 cells left empty in the rows predicted measured had a compliant sample within ¾ cell.
/// A gap over 1½ cells between samples can leave a cell empty, one of 2½ cells always does.
constexpr double kFillReach = 0.75;

}  // namespace

MeasuredCoverage::MeasuredCoverage(const RoughModel& rough, const ModelSpec& spec, CoverageOptions options)
    : points_(rough.points), normals_(rough.normals), area_(rough.area_mm2), total_area_(rough.total_area_mm2),
      spec_(spec), options_(options) {
  validate(spec);
  if (!(options.row_fraction > 0.0 && options.row_fraction <= 1.0))
    throw ConfigError("coverage.row_fraction must be in (0, 1], got " + std::to_string(options.row_fraction));
  const std::size_t n = points_.size();
  cell_ = 1.0 / std::sqrt(spec.density_per_mm2);
  tolerance_ = options.normal_tolerance_mm > 0.0 ? options.normal_tolerance_mm : std::max(2.0, 0.5 * rough.mean_edge_mm);
  u_.resize(n);
  v_.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d& nn = normals_[i];
    const Eigen::Vector3d any = std::abs(nn.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
    u_[i] = nn.cross(any).normalized();
    v_[i] = nn.cross(u_[i]);
  }
  // Footprints: per adjacent triangle, the quad (vertex, edge midpoint, centroid, edge midpoint), projected
  // into the row's tangent plane and rasterised by cell centre; the vertex's own cell always belongs.
  // Each cell also keeps where its centre lies on the triangle it came from, with that triangle's normal: the
  // samples a replan predicts an open row's unfilled cells by (open_footprints).
  struct Cell {
    std::uint32_t key;
    Eigen::Vector3f point, normal;
  };
  std::vector<std::vector<Cell>> cells(n);
  bend_.assign(n, 0.0);
  double extent = 0.0, max_bend = 0.0;
  for (const auto& t : rough.triangles) {
    const Eigen::Vector3d centroid = (points_[t[0]] + points_[t[1]] + points_[t[2]]) / 3.0;
    const Eigen::Vector3d face = (points_[t[1]] - points_[t[0]]).cross(points_[t[2]] - points_[t[0]]);
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t i = t[k];
      const Eigen::Vector3d& p = points_[i];
      const Eigen::Vector3d corners[4] = {p, 0.5 * (p + points_[t[(k + 1) % 3]]), centroid, 0.5 * (p + points_[t[(k + 2) % 3]])};
      std::vector<Eigen::Vector2d> poly;
      Eigen::AlignedBox2d box;
      for (const auto& c : corners) {
        const Eigen::Vector3d d = c - p;
        extent = std::max(extent, d.norm());
        // A footprint bent over an edge leaves the tangent plane: its own height widens the tolerance.
        bend_[i] = std::max(bend_[i], std::abs(d.dot(normals_[i])));
        poly.emplace_back(d.dot(u_[i]) / cell_, d.dot(v_[i]) / cell_);
        box.extend(poly.back());
      }
      // The cell centre lifted from the tangent plane onto the triangle's plane, along the row's normal
      // (a triangle steeper than 80° to the tangent plane keeps the centre in the tangent plane).
      Eigen::Vector3d fn = face.norm() > 0.0 ? face.normalized() : normals_[i];
      if (fn.dot(normals_[i]) < 0.0) fn = -fn;
      const double lift_den = fn.dot(normals_[i]);
      for (long iu = std::lround(std::floor(box.min().x())); iu <= std::lround(std::ceil(box.max().x())); ++iu)
        for (long iv = std::lround(std::floor(box.min().y())); iv <= std::lround(std::ceil(box.max().y())); ++iv)
          if (inside_convex(poly, Eigen::Vector2d(static_cast<double>(iu), static_cast<double>(iv)))) {
            const Eigen::Vector3d d = cell_ * (static_cast<double>(iu) * u_[i] + static_cast<double>(iv) * v_[i]);
            const double h = lift_den > 0.17 ? -d.dot(fn) / lift_den : 0.0;
            cells[i].push_back({cell_key(iu, iv), (p + d + h * normals_[i]).cast<float>(), fn.cast<float>()});
          }
    }
  }
  footprint_.assign(n, {});
  cell_point_.assign(n, {});
  cell_normal_.assign(n, {});
  for (std::size_t i = 0; i < n; ++i) {
    auto& c = cells[i];
    c.push_back({cell_key(0, 0), points_[i].cast<float>(), normals_[i].cast<float>()});
    // The first triangle's lift of a cell that several triangles share: deterministic (triangle order).
    std::stable_sort(c.begin(), c.end(), [](const Cell& a, const Cell& b) { return a.key < b.key; });
    c.erase(std::unique(c.begin(), c.end(), [](const Cell& a, const Cell& b) { return a.key == b.key; }), c.end());
    for (const auto& e : c) {
      footprint_[i].push_back(e.key);
      cell_point_[i].push_back(e.point);
      cell_normal_[i].push_back(e.normal);
    }
  }
  filled_.resize(n);
  for (std::size_t i = 0; i < n; ++i) filled_[i].assign(footprint_[i].size(), 0);
  filled_count_.assign(n, 0);
  for (double b : bend_) max_bend = std::max(max_bend, b);
  reach_ = std::max(extent + kFillReach * cell_ * std::sqrt(2.0) + tolerance_ + max_bend, 1e-3);
  row_grid_.reserve(n);
  for (std::uint32_t i = 0; i < n; ++i) {
    const Eigen::Vector3d& p = points_[i];
    row_grid_.emplace_back(grid_key(std::lround(std::floor(p.x() / reach_)), std::lround(std::floor(p.y() / reach_)),
                                    std::lround(std::floor(p.z() / reach_))),
                           i);
  }
  std::sort(row_grid_.begin(), row_grid_.end());
}

std::vector<std::uint8_t> MeasuredCoverage::compliant_samples(const RangeImage& img, const ModelSpec& spec) {
  std::vector<std::uint8_t> out(img.samples.size(), 0);
  for (int j = 0; j < img.rows; ++j)
    for (int i = 0; i < img.columns; ++i) {
      const RangeSample& s = img.at(i, j);
      out[static_cast<std::size_t>(j) * static_cast<std::size_t>(img.columns) + static_cast<std::size_t>(i)] =
          s.valid() && s.sigma_z_mm <= spec.precision_mm && sample_density_per_mm2(img, i, j) >= spec.density_per_mm2;
    }
  return out;
}

std::size_t MeasuredCoverage::add(const RangeImage& img, const std::vector<std::uint8_t>* given) {
  if (given && given->size() != img.samples.size())
    throw DataError("measured coverage: " + std::to_string(given->size()) + " compliance flags for " + std::to_string(img.samples.size()) + " samples");
  const std::vector<std::uint8_t> mask = given ? std::vector<std::uint8_t>{} : compliant_samples(img, spec_);
  const std::vector<std::uint8_t>& compliant = given ? *given : mask;
  const Eigen::Matrix3d rot = img.pose.camera_to_object.linear();
  std::size_t landed = 0;
  for (int j = 0; j < img.rows; ++j)
    for (int i = 0; i < img.columns; ++i) {
      const RangeSample& s = img.at(i, j);
      if (!s.valid() || !compliant[static_cast<std::size_t>(j) * static_cast<std::size_t>(img.columns) + static_cast<std::size_t>(i)]) continue;
      const Eigen::Vector3d p = s.object_mm.cast<double>();
      // Towards the laser: in a line scan the laser of this profile sits at (0, y, 0) in the camera frame, y
      // being the sample's own y; a random-access camera's laser is at the origin.
      Eigen::Vector3d to_laser = -s.camera_mm.cast<double>();
      if (img.kind == SensorKind::line_scan) to_laser.y() = 0.0;
      to_laser = rot * to_laser;
      const long cx = std::lround(std::floor(p.x() / reach_)), cy = std::lround(std::floor(p.y() / reach_)),
                 cz = std::lround(std::floor(p.z() / reach_));
      bool any = false;
      for (long dx = -1; dx <= 1; ++dx)
        for (long dy = -1; dy <= 1; ++dy)
          for (long dz = -1; dz <= 1; ++dz) {
            const std::uint64_t key = grid_key(cx + dx, cy + dy, cz + dz);
            for (auto it = std::lower_bound(row_grid_.begin(), row_grid_.end(), std::make_pair(key, std::uint32_t{0}));
                 it != row_grid_.end() && it->first == key; ++it) {
              const std::uint32_t r = it->second;
              const Eigen::Vector3d d = p - points_[r];
              if (d.squaredNorm() > reach_ * reach_) continue;
              if (normals_[r].dot(to_laser) <= 0.0) continue;  // the row faces away from this laser
              if (std::abs(d.dot(normals_[r])) > tolerance_ + bend_[r]) continue;
              const double du = d.dot(u_[r]) / cell_, dv = d.dot(v_[r]) / cell_;
              const auto& f = footprint_[r];
              for (long iu = std::lround(std::ceil(du - kFillReach)); iu <= std::lround(std::floor(du + kFillReach)); ++iu)
                for (long iv = std::lround(std::ceil(dv - kFillReach)); iv <= std::lround(std::floor(dv + kFillReach)); ++iv) {
                  const std::uint32_t c = cell_key(iu, iv);
                  const auto at = std::lower_bound(f.begin(), f.end(), c);
                  if (at == f.end() || *at != c) continue;
                  any = true;
                  auto& flag = filled_[r][static_cast<std::size_t>(at - f.begin())];
                  if (!flag) {
                    flag = 1;
                    ++filled_count_[r];
                  }
                }
            }
          }
      landed += any;
    }
  return landed;
}

RowFootprints MeasuredCoverage::open_footprints(const std::vector<std::uint32_t>& rows, std::size_t max_samples) const {
  if (max_samples == 0) throw ConfigError("open_footprints: max_samples must be at least 1");
  std::vector<std::uint32_t> sorted = rows;
  std::sort(sorted.begin(), sorted.end());
  sorted.erase(std::unique(sorted.begin(), sorted.end()), sorted.end());
  return open_footprints(sorted, std::vector<std::size_t>(sorted.size(), max_samples));
}

RowFootprints MeasuredCoverage::open_footprints(const std::vector<std::uint32_t>& rows, const std::vector<std::size_t>& max_samples) const {
  if (max_samples.size() != rows.size())
    throw DataError("open_footprints: " + std::to_string(max_samples.size()) + " sample caps for " + std::to_string(rows.size()) + " rows");
  RowFootprints f;
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const std::uint32_t r = rows[i];
    if (r >= this->rows()) throw DataError("open_footprints: row " + std::to_string(r) + " past the " + std::to_string(this->rows()) + " rows");
    if (i > 0 && r <= rows[i - 1]) throw DataError("open_footprints: row " + std::to_string(r) + " after row " + std::to_string(rows[i - 1]) + " (ascending, no repeats)");
    if (max_samples[i] == 0) throw ConfigError("open_footprints: row " + std::to_string(r) + " capped at 0 samples (at least 1)");
    const std::size_t cells = footprint_[r].size();
    if (measured(r)) continue;
    const auto need = static_cast<std::size_t>(std::ceil(options_.row_fraction * static_cast<double>(cells) - 1e-9));
    std::vector<std::size_t> open;
    for (std::size_t c = 0; c < cells; ++c)
      if (!filled_[r][c]) open.push_back(c);
    // At most max_samples of the unfilled cells, evenly through them (keys are row-major in the tangent
    // plane, so every part of the gap is sampled); a view must measure the share of them the row lacks.
    const std::size_t k = std::min(open.size(), max_samples[i]);
    for (std::size_t s = 0; s < k; ++s) {
      const std::size_t c = open[(2 * s + 1) * open.size() / (2 * k)];
      f.points.push_back(cell_point_[r][c].cast<double>());
      f.normals.push_back(cell_normal_[r][c].cast<double>().normalized());
    }
    const double share = static_cast<double>(need - filled_count_[r]) / static_cast<double>(open.size());
    f.rows.push_back(r);
    f.needed.push_back(static_cast<std::uint32_t>(std::max(1.0, std::ceil(share * static_cast<double>(k) - 1e-9))));
    f.first.push_back(static_cast<std::uint32_t>(f.points.size()));
  }
  return f;
}

double MeasuredCoverage::row_fraction(std::size_t row) const {
  return static_cast<double>(filled_count_[row]) / static_cast<double>(footprint_[row].size());
}

std::vector<std::uint8_t> MeasuredCoverage::measured_rows() const {
  std::vector<std::uint8_t> out(rows());
  for (std::size_t i = 0; i < rows(); ++i) out[i] = measured(i);
  return out;
}

std::vector<std::uint32_t> MeasuredCoverage::unmeasured_rows() const {
  std::vector<std::uint32_t> out;
  for (std::uint32_t i = 0; i < rows(); ++i)
    if (!measured(i)) out.push_back(i);
  return out;
}

double MeasuredCoverage::coverage() const {
  double a = 0.0;
  for (std::size_t i = 0; i < rows(); ++i)
    if (measured(i)) a += area_[i];
  return total_area_ > 0.0 ? a / total_area_ : 0.0;
}

RowFootprints whole_row_footprints(const RoughModel& rough, const ModelSpec& spec, const WholeRowSampling& s, CoverageOptions options) {
  if (s.max_samples == 0) throw ConfigError("whole_row_footprints: max_samples must be at least 1");
  if (!(s.sample_area_mm2 >= 0.0)) throw ConfigError("whole_row_footprints: sample_area_mm2 must be >= 0, got " + std::to_string(s.sample_area_mm2));
  const MeasuredCoverage coverage(rough, spec, options);
  std::vector<std::uint32_t> rows;
  std::vector<std::size_t> caps;
  std::size_t next_crease = 0;
  for (std::uint32_t r = 0; r < rough.size(); ++r) {
    // Sampled finer than the rough model is already, a row adds no resolution its vertex lacks: the band a
    // vertex mispredicts, by a plate's rim or a cleft's wall, is as wide as its row (docs/quality.md).
    std::size_t k = s.max_samples;
    if (s.sample_area_mm2 > 0.0) k = std::min(k, static_cast<std::size_t>(std::floor(rough.area_mm2[r] / s.sample_area_mm2)));
    while (next_crease < s.crease.size() && s.crease[next_crease] < r) ++next_crease;
    const bool crease = s.crease_samples > 0 && next_crease < s.crease.size() && s.crease[next_crease] == r;
    if (crease) k = std::max(k, s.crease_samples);
    if (k < (crease ? 1u : 2u)) continue;
    rows.push_back(r);
    caps.push_back(k);
  }
  return coverage.open_footprints(rows, caps);
}

}  // namespace scancell::planner
