#include "planner/core/footprint.hpp"

#include <algorithm>
#include <iterator>
#include <stdexcept>
#include <string>
#include <utility>

#include <tbb/parallel_for.h>

#include "common/errors.hpp"

namespace scancell::planner {

void RowFootprints::validate(std::uint32_t n_rows) const {
  const std::string what = "row footprints: ";
  if (first.size() != rows.size() + 1 || first.front() != 0 || first.back() != points.size())
    throw DataError(what + "offsets do not span the " + std::to_string(points.size()) + " samples of " + std::to_string(rows.size()) + " rows");
  if (normals.size() != points.size() || needed.size() != rows.size())
    throw DataError(what + std::to_string(normals.size()) + " normals and " + std::to_string(needed.size()) + " needed counts for " +
                    std::to_string(points.size()) + " samples of " + std::to_string(rows.size()) + " rows");
  for (std::size_t k = 0; k < rows.size(); ++k) {
    if (rows[k] >= n_rows || (k > 0 && rows[k] <= rows[k - 1]))
      throw DataError(what + "row " + std::to_string(rows[k]) + " (entry " + std::to_string(k) + ") is out of order or past the " +
                      std::to_string(n_rows) + " rows");
    if (first[k + 1] < first[k] || needed[k] > first[k + 1] - first[k])
      throw DataError(what + "row " + std::to_string(rows[k]) + " needs " + std::to_string(needed[k]) + " of its " +
                      std::to_string(first[k + 1] - first[k]) + " samples");
  }
}

std::vector<AimPoint> footprint_aims(const RowFootprints& f, double standoff_mm) {
  std::vector<AimPoint> out;
  for (std::size_t k = 0; k < f.rows.size(); ++k) {
    const std::uint32_t b = f.first[k], e = f.first[k + 1];
    if (b == e) continue;
    Eigen::Vector3d middle = Eigen::Vector3d::Zero();
    for (std::uint32_t s = b; s < e; ++s) middle += f.points[s];
    middle /= static_cast<double>(e - b);
    std::uint32_t best = b;
    for (std::uint32_t s = b + 1; s < e; ++s)
      if ((f.points[s] - middle).squaredNorm() < (f.points[best] - middle).squaredNorm()) best = s;
    if (!(f.normals[best].squaredNorm() > 0.5)) continue;  // no surface direction to aim along
    out.push_back({f.points[best], f.normals[best], standoff_mm, static_cast<std::int32_t>(f.rows[k])});
  }
  return out;
}

namespace {

/// Per column j of `m`: the samples of the footprint rows that j measures or that lie within two triangles
/// (of `triangles`) of one it measures. A row's samples lie on its own triangles; a sample that passes where
/// nothing around its triangle does is a sliver at the frustum's edge, or on a triangle larger than the
/// frustum, which this leaves out (cover_by_samples).
///
/// Footprint rows are few (crease rows: a twentieth of a 26k-row mesh), so each row is indexed once by the
/// footprint rows within two rings of it, and a column visits only its own rows: what spreading two rings
/// around every measured row and sorting them gave, at a fraction of the work.
RowsToTest samples_near_measured_rows(const MeasurabilityMatrix& m, const RowFootprints& f, const std::vector<Triangle>& triangles) {
  std::vector<std::vector<std::uint32_t>> ring(m.n_rows);
  for (const auto& t : triangles)
    for (int a = 0; a < 3; ++a) {
      if (t[a] >= m.n_rows || t[(a + 1) % 3] >= m.n_rows)
        throw DataError("row footprints: a triangle names row " + std::to_string(std::max(t[a], t[(a + 1) % 3])) + " past the " +
                        std::to_string(m.n_rows) + " rows");
      ring[t[a]].push_back(t[(a + 1) % 3]);
      ring[t[(a + 1) % 3]].push_back(t[a]);
    }
  // near[r]: the footprint entries k whose row is within two rings of row r, ascending. The ring graph is
  // symmetric, so these are the rows two rings around each footprint row, inverted.
  auto near = std::make_shared<std::vector<std::vector<std::uint32_t>>>(m.n_rows);
  std::vector<std::uint32_t> within;  // rows within two rings of one footprint row
  std::vector<std::uint8_t> seen(m.n_rows, 0);
  for (std::size_t k = 0; k < f.size(); ++k) {
    within.assign(1, f.rows[k]);
    seen[f.rows[k]] = 1;
    // Two rings: the corners of the sample's triangle and of the triangles around it. One ring missed 1.7 % of
    // a bunny's sample elements, two 0.8 % (docs/quality.md).
    for (std::size_t g = 0, begin = 0; g < 2; ++g)
      for (std::size_t i = std::exchange(begin, within.size()), n = within.size(); i < n; ++i)
        for (const auto q : ring[within[i]])
          if (!seen[q]) seen[q] = 1, within.push_back(q);
    for (const auto r : within) seen[r] = 0, (*near)[r].push_back(static_cast<std::uint32_t>(k));
  }
  return [&m, &f, near](std::size_t j, std::vector<std::uint32_t>& out) {
    thread_local std::vector<std::uint8_t> marked;  // all zero between calls
    thread_local std::vector<std::uint32_t> entries;
    if (marked.size() < f.size()) marked.resize(f.size(), 0);
    entries.clear();
    m.columns[j].for_each([&](std::uint32_t r) {
      for (const std::uint32_t k : (*near)[r])
        if (!marked[k]) marked[k] = 1, entries.push_back(k);
    });
    std::sort(entries.begin(), entries.end());  // footprint rows in row order, as the samples are
    for (const auto k : entries) {
      marked[k] = 0;
      for (std::uint32_t s = f.first[k]; s < f.first[k + 1]; ++s) out.push_back(s);
    }
  };
}

}  // namespace

SampleCover cover_by_samples(const MeasurabilityMatrix& matrix, const std::vector<double>& row_weight, const RowFootprints& f,
                             const OcclusionScene& scene, const SensorModel& sensor, const ModelSpec& spec,
                             const std::vector<Viewpoint>& candidates, const MatrixSettings& settings, double mean_edge_mm,
                             const std::atomic<int>* cancel, const Countermeasures* plain, const std::vector<Triangle>* near_on) {
  f.validate(matrix.n_rows);
  if (candidates.size() != matrix.n_cols())
    throw DataError("row footprints: " + std::to_string(candidates.size()) + " candidates for a matrix of " +
                    std::to_string(matrix.n_cols()) + " columns");
  if (row_weight.size() != matrix.n_rows)
    throw DataError("row footprints: " + std::to_string(row_weight.size()) + " row weights for " + std::to_string(matrix.n_rows) + " rows");
  SampleCover c;
  c.n_rows = matrix.n_rows;
  const auto n_samples = static_cast<std::uint32_t>(f.points.size());
  c.owner.resize(n_samples);
  for (std::size_t k = 0; k < f.size(); ++k)
    for (std::uint32_t s = f.first[k]; s < f.first[k + 1]; ++s) c.owner[s] = static_cast<std::uint32_t>(k);
  c.weight = row_weight;
  c.weight.resize(matrix.n_rows + n_samples, 0.0);
  std::vector<std::uint8_t> is_footprint_row(matrix.n_rows, 0);
  for (std::size_t k = 0; k < f.size(); ++k) {
    const std::uint32_t r = f.rows[k], n = f.first[k + 1] - f.first[k];
    is_footprint_row[r] = 1;
    for (std::uint32_t s = f.first[k]; s < f.first[k + 1]; ++s) c.weight[matrix.n_rows + s] = row_weight[r] / n;
    c.weight[r] = 0.0;
  }
  // The samples as rows of their own: the matrix builder's element test, culling and rays, unchanged. They
  // come row by row in the rough model's Morton order, so its culling blocks stay compact.
  RoughModel samples;
  samples.points = f.points;
  samples.normals = f.normals;
  samples.area_mm2.assign(f.points.size(), 0.0);
  samples.mean_edge_mm = mean_edge_mm;  // the same ray offset as the rows'
  // With a margin (`plain`: the test without it), a sample keeps what the plain test gives it when the margin
  // leaves it no view, as the rows do (keep_plain_elements_of_lost_rows).
  MeasurabilityMatrix by_sample{0, std::vector<MeasurabilityColumn>(candidates.size()), nullptr};
  if (!f.points.empty()) {
    PlainElements plain_elements{plain ? *plain : Countermeasures{}, {}};
    const RowsToTest near = near_on ? samples_near_measured_rows(matrix, f, *near_on) : RowsToTest{};
    by_sample = build_measurability(samples, scene, sensor, spec, candidates, settings, nullptr, cancel,
                                    plain ? &plain_elements : nullptr, near_on ? &near : nullptr);
    if (plain) keep_plain_elements_of_lost_rows(by_sample, plain_elements);
  }
  c.matrix.n_rows = matrix.n_rows + n_samples;
  c.matrix.columns.resize(matrix.n_cols());
  tbb::parallel_for(std::size_t{0}, matrix.n_cols(), [&](std::size_t j) {  // each column its own: any thread count
    std::vector<std::uint32_t> rows;
    matrix.columns[j].for_each([&](std::uint32_t r) {
      if (!is_footprint_row[r]) rows.push_back(r);
    });
    by_sample.columns[j].for_each([&](std::uint32_t s) { rows.push_back(matrix.n_rows + s); });
    c.matrix.columns[j] = MeasurabilityColumn(std::move(rows), c.matrix.n_rows);
  });
  return c;
}

std::vector<std::uint8_t> finished_rows(const SampleCover& c, const RowFootprints& f, const std::vector<std::uint32_t>& views) {
  std::vector<std::uint8_t> seen(c.owner.size(), 0), out(c.n_rows, 0);
  std::vector<std::uint32_t> count(f.size(), 0);
  for (const auto j : views)
    c.matrix.columns.at(j).for_each([&](std::uint32_t r) {
      if (r < c.n_rows || seen[r - c.n_rows]) return;
      seen[r - c.n_rows] = 1;
      ++count[c.owner[r - c.n_rows]];
    });
  for (std::size_t k = 0; k < f.size(); ++k) out[f.rows[k]] = f.needed[k] > 0 && count[k] >= f.needed[k];
  return out;
}

std::vector<std::uint32_t> column_rows(const SampleCover& c, const RowFootprints& f, std::uint32_t column,
                                       const std::vector<std::uint8_t>& finished) {
  // Both come in ascending order: the rows themselves, then the samples, whose owners ascend with them.
  std::vector<std::uint32_t> direct, by_samples;
  c.matrix.columns.at(column).for_each([&](std::uint32_t r) {
    if (r < c.n_rows) direct.push_back(r);
    else if (const std::uint32_t row = f.rows[c.owner[r - c.n_rows]]; finished[row] && (by_samples.empty() || by_samples.back() != row))
      by_samples.push_back(row);
  });
  std::vector<std::uint32_t> rows;
  rows.reserve(direct.size() + by_samples.size());
  std::set_union(direct.begin(), direct.end(), by_samples.begin(), by_samples.end(), std::back_inserter(rows));
  return rows;
}

std::shared_ptr<const OverlapRows> overlap_by_footprint_rows(const SampleCover& c, const RowFootprints& f,
                                                             const std::vector<double>& row_weight) {
  if (row_weight.size() != c.n_rows) throw std::invalid_argument("overlap_by_footprint_rows: one weight per rough-model row required");
  auto o = std::make_shared<OverlapRows>();
  o->matrix.n_rows = c.n_rows;
  o->matrix.columns.resize(c.matrix.n_cols());
  const std::vector<std::uint8_t> any_sample(c.n_rows, 1);
  tbb::parallel_for(std::uint32_t{0}, static_cast<std::uint32_t>(c.matrix.n_cols()), [&](std::uint32_t j) {
    o->matrix.columns[j] = MeasurabilityColumn(column_rows(c, f, j, any_sample), c.n_rows);
  });
  o->weight = row_weight;
  return o;
}

}  // namespace scancell::planner
