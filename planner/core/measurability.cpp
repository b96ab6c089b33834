#include "planner/core/measurability.hpp"

#include "common/errors.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <numbers>
#include <stdexcept>

#include <tbb/parallel_for.h>

namespace scancell::planner {
namespace {

constexpr std::uint32_t kBlock = 32;  // rows per culling block (consecutive in Morton order)
constexpr std::size_t kPairsPerFlush = 128;  // 256 occlusion rays per Embree stream

struct Block {
  Eigen::Vector3d centre;
  double radius;
  Eigen::Vector3d normal_axis;  // the axis of its rows' normal cone
  double min_facing_dot;        // a camera whose +z has less than this with the axis measures none of its rows
};

/// How far (rad) from the camera's +z a normal the element test can pass turns at most: the grazing thresholds
/// (eq. 3.4's U_i) bound the normal's inclination in x-z by θ_xz plus the ray's own (half the fan) and in y-z
/// by θ_yz (plus half the frame's height on a random-access sensor), so tan² of its angle to +z is below
/// tan²(θ_xz + Φx/2) + tan²(θ_yz + Φy/2). π when either bound reaches 90° (nothing to cull by).
double facing_limit_rad(const SensorModel& s) {
  const double a = s.grazing_xz_rad + 0.5 * s.fov_x_rad;
  const double b = s.grazing_yz_rad + (s.kind == SensorKind::random_access ? 0.5 * s.fov_y_rad : 0.0);
  if (!(a < 0.5 * std::numbers::pi) || !(b < 0.5 * std::numbers::pi)) return std::numbers::pi;
  return std::atan(std::hypot(std::tan(a), std::tan(b)));
}

/// Blocks of kBlock consecutive rows: a bounding sphere for the frustum cull, and a normal cone (axis, half
/// angle α) for the facing cull: a row's normal is at least (angle(axis, +z) − α) from the camera's +z, so a
/// block whose axis turns more than α + facing_limit_rad from it holds no row the test can pass.
std::vector<Block> make_blocks(const RoughModel& rough, double facing_limit) {
  std::vector<Block> blocks;
  for (std::uint32_t b = 0; b < rough.size(); b += kBlock) {
    const std::uint32_t e = std::min<std::uint32_t>(b + kBlock, rough.size());
    Eigen::Vector3d lo = rough.points[b], hi = rough.points[b], sum = Eigen::Vector3d::Zero();
    for (std::uint32_t i = b; i < e; ++i) {
      lo = lo.cwiseMin(rough.points[i]);
      hi = hi.cwiseMax(rough.points[i]);
      sum += rough.normals[i];
    }
    const Eigen::Vector3d c = 0.5 * (lo + hi);
    double r = 0.0;
    for (std::uint32_t i = b; i < e; ++i) r = std::max(r, (rough.points[i] - c).norm());
    Block block{c, r, Eigen::Vector3d::UnitZ(), -2.0};  // -2: never culled by facing
    if (sum.norm() > 1e-9 && facing_limit < std::numbers::pi) {
      block.normal_axis = sum.normalized();
      double cos_alpha = 1.0;
      for (std::uint32_t i = b; i < e; ++i) cos_alpha = std::min(cos_alpha, block.normal_axis.dot(rough.normals[i].normalized()));
      const double reach = std::acos(std::clamp(cos_alpha, -1.0, 1.0)) + facing_limit + 1e-6;  // slack for rounding
      if (reach < std::numbers::pi) block.min_facing_dot = std::cos(reach);
    }
    blocks.push_back(block);
  }
  return blocks;
}

/// Conservative: false only when no point of the sphere can be inside the frustum at a depth up to `z_max_mm`
/// (compliant_depth_max_mm: deeper, no point meets the spec).
bool sphere_may_touch_frustum(const SensorModel& s, const FrustumTerms& f, double scan_length_mm, double z_max_mm,
                              const Eigen::Vector3d& c, double r) {
  const double z = -c.z();
  if (z + r < s.range_min_mm || z - r > z_max_mm) return false;
  const double zfar = std::min(z + r, z_max_mm);
  if (std::abs(c.x()) - r > zfar * f.tan_half_x) return false;
  const double half_y = s.kind == SensorKind::line_scan ? 0.5 * scan_length_mm : zfar * f.tan_half_y;
  return std::abs(c.y()) - r <= half_y;
}

/// The occlusion rays of a pair: from just off the surface to the laser source and to the receiver (2 rays), or
/// with a near-miss margin m > 0 the 8 rays to both displaced by ±m along camera x and y (the margin's extra
/// rays: the caller casts the 2 undisplaced ones first and these only for pairs those leave clear).
std::size_t pair_rays(const Eigen::Vector3d& s, const Eigen::Vector3d& n, const Viewpoint& v, const Eigen::Matrix3d& r,
                      const PointTest& t, double eps, double margin, OcclusionRay* out) {
  const Eigen::Vector3d origin = s + eps * n;
  const Eigen::Vector3d yc = r.col(1), xc = r.col(0);
  const Eigen::Vector3d ends[2] = {v.position + t.laser_y_mm * yc, v.position + t.receiver_y_mm * yc};
  const Eigen::Vector3d centre[1] = {Eigen::Vector3d::Zero()};
  const Eigen::Vector3d shifts[4] = {margin * xc, -margin * xc, margin * yc, -margin * yc};
  const Eigen::Vector3d* offsets = margin > 0.0 ? shifts : centre;
  const int n_offsets = margin > 0.0 ? 4 : 1;
  std::size_t k = 0;
  for (const auto& end : ends)
    for (int q = 0; q < n_offsets; ++q, ++k) {
      const Eigen::Vector3d d = end + offsets[q] - origin;
      const double length = std::max(d.norm(), eps * 2.0);
      out[k].origin = origin.cast<float>();
      out[k].dir = d.cast<float>();
      out[k].t_near = static_cast<float>(kOffSurfaceStart * eps / length);
      out[k].t_far = static_cast<float>(1.0 - eps / length);
    }
  return k;
}

/// One level of the element test: the sensor and specification a (possibly detuned, thesis 7.4.7) test uses.
/// The density formula keeps the real Φx (the sample spacing does not change); only the frustum test uses the
/// narrowed width, and the sweep is shortened for the frustum but not for the density.
struct TestLevel {
  SensorModel sensor;
  ModelSpec spec;
  FrustumTerms terms;
  double length_factor;
  double margin_mm;
  TestLevel(const SensorModel& s, const ModelSpec& sp, const Countermeasures& cm)
      : sensor(detuned_sensor(s, cm)), spec(detuned_spec(sp, cm)), terms(s), length_factor(1.0 - cm.frustum_detune),
        margin_mm(cm.visibility_margin_mm) {
    terms.tan_half_x *= length_factor;
    terms.tan_half_y *= length_factor;
  }
  PointTest test(double scan_length_mm, const Eigen::Vector3d& pc, const Eigen::Vector3d& nc) const {
    PointTest t = test_point(sensor, terms, spec, scan_length_mm * length_factor, pc, nc);
    if (t.compliant && length_factor < 1.0) t.compliant = test_point(sensor, terms, spec, scan_length_mm, pc, nc).compliant;
    return t;
  }
};

/// Whether none of a pair's `n` occlusion rays (flags from OcclusionScene::occluded) is blocked.
bool all_clear(const std::uint8_t* occluded, std::size_t n) {
  return std::none_of(occluded, occluded + n, [](std::uint8_t o) { return o != 0; });
}

struct Counters {
  std::atomic<std::uint64_t> block_culled{0}, normal_culled{0}, in_frustum{0}, surviving{0}, compliant{0}, rays{0}, measurable{0};
  void export_to(MatrixStats* stats, std::uint64_t total) const {
    if (!stats) return;
    stats->pairs_total = total;
    stats->pairs_block_culled = block_culled;
    stats->pairs_normal_culled = normal_culled;
    stats->pairs_in_frustum = in_frustum;
    stats->pairs_surviving = surviving;
    stats->pairs_compliant = compliant;
    stats->rays_cast = rays;
    stats->pairs_measurable = measurable;
  }
};

}  // namespace

double ray_offset_mm(const RoughModel& rough, const MatrixSettings& st) {
  return st.ray_offset_mm > 0.0 ? st.ray_offset_mm : 0.01 * rough.mean_edge_mm;
}

SensorModel detuned_sensor(const SensorModel& sensor, const Countermeasures& c) {
  SensorModel s = sensor;
  s.range_min_mm += c.dof_margin_mm;
  s.range_max_mm = std::max(s.range_min_mm, s.range_max_mm - c.dof_margin_mm);
  return s;
}

ModelSpec detuned_spec(const ModelSpec& spec, const Countermeasures& c) {
  ModelSpec s = spec;
  s.precision_mm /= 1.0 + c.compliance_buffer;
  s.density_per_mm2 *= 1.0 + c.compliance_buffer;
  return s;
}

std::optional<Countermeasures> open_direction_margin(const Countermeasures& matrix_cm) {
  if (!(matrix_cm.compliance_buffer < kOpenDirectionComplianceMargin)) return std::nullopt;
  Countermeasures cm = matrix_cm;
  cm.compliance_buffer = kOpenDirectionComplianceMargin;
  return cm;
}

MeasurabilityColumn::MeasurabilityColumn(std::vector<std::uint32_t> sorted_rows, std::uint32_t n_rows)
    : count_(static_cast<std::uint32_t>(sorted_rows.size())) {
  const std::size_t words = (n_rows + 63) / 64;
  if (sorted_rows.size() * 4 > words * 8) {
    bits_.assign(words, 0);
    for (auto r : sorted_rows) bits_[r >> 6] |= 1ull << (r & 63);
  } else {
    rows_ = std::move(sorted_rows);
    rows_.shrink_to_fit();
  }
}

bool MeasurabilityColumn::contains(std::uint32_t row) const {
  if (!bits_.empty()) return (row >> 6) < bits_.size() && (bits_[row >> 6] >> (row & 63) & 1);
  return std::binary_search(rows_.begin(), rows_.end(), row);
}

std::vector<std::uint32_t> MeasurabilityColumn::rows() const {
  std::vector<std::uint32_t> out;
  out.reserve(count_);
  for_each([&](std::uint32_t r) { out.push_back(r); });
  return out;
}

std::size_t MeasurabilityMatrix::nonzeros() const {
  std::size_t n = 0;
  for (const auto& c : columns) n += c.count();
  return n;
}

double MeasurabilityMatrix::density() const {
  const double cells = static_cast<double>(n_rows) * static_cast<double>(columns.size());
  return cells > 0 ? nonzeros() / cells : 0.0;
}

std::size_t MeasurabilityMatrix::memory_bytes() const {
  std::size_t b = columns.capacity() * sizeof(MeasurabilityColumn);
  for (const auto& c : columns) b += c.memory_bytes();
  return b;
}

std::vector<std::uint32_t> MeasurabilityMatrix::unmeasurable_rows() const {
  std::vector<char> seen(n_rows, 0);
  for (const auto& c : columns) c.for_each([&](std::uint32_t r) { seen[r] = 1; });
  std::vector<std::uint32_t> out;
  for (std::uint32_t r = 0; r < n_rows; ++r)
    if (!seen[r]) out.push_back(r);
  return out;
}

namespace {

/// The two test levels of one build (see build_measurability) and how many rays a pair casts at each.
struct Levels {
  TestLevel tight, wide;
  bool same_test;         // no plain matrix: the wide level is the tight one with its undisplaced rays only
  bool tight_extra_rays;  // the tight level's near-miss rays, cast only for pairs the wide level's leave clear
  std::size_t wide_rays;
};

/// One worker's share of the matrix: for each candidate, the rows in its frustum tested at both levels, their
/// occlusion rays cast in streams of kPairsPerFlush pairs, and its column (and plain column) collected.
class ColumnWorker {
 public:
  ColumnWorker(const RoughModel& rough, const OcclusionScene& scene, const std::vector<Block>& blocks, const Levels& lv, double eps,
               bool plain, const std::vector<std::uint8_t>* plain_rows = nullptr)
      : rough_(rough), scene_(scene), blocks_(blocks), lv_(lv), eps_(eps), plain_(plain), plain_rows_(plain_rows),
        occ_(lv.wide_rays * kPairsPerFlush), extra_occ_(8 * kPairsPerFlush) {
    pending_.reserve(kPairsPerFlush);
    rays_.reserve(lv.wide_rays * kPairsPerFlush);
    extra_rays_.reserve(8 * kPairsPerFlush);
  }

  /// Candidate v's column (rows ascending) and, with a plain matrix, its plain column; counted into `cnt`.
  /// With `only` (ascending rows), those rows alone are tested, without block culling; the rest count as culled.
  void build(const Viewpoint& v, std::vector<std::uint32_t>& column, std::vector<std::uint32_t>& plain_column, Counters& cnt,
             const std::vector<std::uint32_t>* only = nullptr) {
    r_ = v.rotation();
    rt_ = r_.transpose();
    const auto n_rows = static_cast<std::uint32_t>(rough_.size());
    tally_ = {};
    column.clear();
    plain_column.clear();
    if (only) {
      for (std::size_t k = 0; k < only->size(); ++k) {
        const std::uint32_t i = (*only)[k];
        if (i >= n_rows || (k > 0 && i <= (*only)[k - 1]))
          throw std::invalid_argument("build_measurability: the rows to test are not ascending rows of the model");
        test_row(v, i, column, plain_column);
      }
      tally_.culled = n_rows - only->size();
    } else {
      // The wide level's spec is the looser one; the full sweep's density is the lower (TestLevel::test).
      const double z_max = compliant_depth_max_mm(lv_.wide.sensor, lv_.wide.terms, lv_.wide.spec, v.scan_length_mm);
      for (std::uint32_t b = 0; b < blocks_.size(); ++b) {
        const std::uint32_t begin = b * kBlock, end = std::min<std::uint32_t>(begin + kBlock, n_rows);
        if (r_.col(2).dot(blocks_[b].normal_axis) < blocks_[b].min_facing_dot) {  // the block faces away
          tally_.normal_culled += end - begin;
          continue;
        }
        if (!sphere_may_touch_frustum(lv_.wide.sensor, lv_.wide.terms, v.scan_length_mm * lv_.wide.length_factor, z_max,
                                      rt_ * (blocks_[b].centre - v.position), blocks_[b].radius)) {
          tally_.culled += end - begin;
          continue;
        }
        for (std::uint32_t i = begin; i < end; ++i) test_row(v, i, column, plain_column);
      }
    }
    flush(v, r_, column, plain_column);
    if (plain_) std::sort(plain_column.begin(), plain_column.end());  // rows the near-miss rays failed joined late
    cnt.block_culled += tally_.culled;
    cnt.normal_culled += tally_.normal_culled;
    cnt.in_frustum += tally_.in_frustum;
    cnt.surviving += tally_.surviving;
    cnt.compliant += tally_.compliant;
    cnt.measurable += column.size();
  }

  std::uint64_t rays_cast = 0;

 private:
  /// Row i against the current candidate (r_, rt_): the analytic test, then its rays queued.
  void test_row(const Viewpoint& v, std::uint32_t i, std::vector<std::uint32_t>& column, std::vector<std::uint32_t>& plain_column) {
    const Eigen::Vector3d pc = rt_ * (rough_.points[i] - v.position);
    const Eigen::Vector3d nc = rt_ * rough_.normals[i];
    const PointTest t = lv_.tight.test(v.scan_length_mm, pc, nc);
    tally_.in_frustum += t.in_frustum;
    tally_.surviving += t.facing;
    tally_.compliant += t.compliant;
    if (!t.compliant && (lv_.same_test || (plain_rows_ && !(*plain_rows_)[i]) || !lv_.wide.test(v.scan_length_mm, pc, nc).compliant))
      return;
    pending_.push_back({i, t.compliant, t});
    rays_.resize(rays_.size() + lv_.wide_rays);
    OcclusionRay* out = &rays_[rays_.size() - lv_.wide_rays];
    out += pair_rays(rough_.points[i], rough_.normals[i], v, r_, t, eps_, 0.0, out);
    if (lv_.wide.margin_mm > 0.0) pair_rays(rough_.points[i], rough_.normals[i], v, r_, t, eps_, lv_.wide.margin_mm, out);
    if (pending_.size() == kPairsPerFlush) flush(v, r_, column, plain_column);
  }

  struct Tally {
    std::uint64_t culled = 0, normal_culled = 0, in_frustum = 0, surviving = 0, compliant = 0;
  };
  struct Pending {
    std::uint32_t row;
    bool tight;  // the tight test is compliant too
    PointTest test;
  };

  /// clear_[p]: whether the wide level's rays of pending pair p are all clear. They are cast in stages, each
  /// for the pairs every earlier one left clear: the ray to the laser, the ray to the receiver, then a
  /// margin's eight near-miss rays. Most pairs that pass the analytic test are shadowed (two in three on the
  /// arm's knot), and a blocked pair needs no further ray to be known.
  void cast_wide_rays() {
    const std::size_t n = pending_.size(), k = lv_.wide_rays;
    clear_.assign(n, 1);
    const std::size_t bounds[] = {0, 1, 2, k};
    for (std::size_t s = 0; s + 1 < std::size(bounds); ++s) {
      const std::size_t from = std::min(bounds[s], k), to = std::min(bounds[s + 1], k), w = to - from;
      if (from >= to) continue;
      stage_rays_.clear();
      stage_pairs_.clear();
      for (std::size_t p = 0; p < n; ++p) {
        if (!clear_[p]) continue;
        stage_pairs_.push_back(p);
        stage_rays_.insert(stage_rays_.end(), rays_.begin() + static_cast<std::ptrdiff_t>(k * p + from),
                           rays_.begin() + static_cast<std::ptrdiff_t>(k * p + to));
      }
      if (stage_pairs_.empty()) return;
      scene_.occluded(stage_rays_.data(), stage_rays_.size(), occ_.data());
      rays_cast += stage_rays_.size();
      for (std::size_t q = 0; q < stage_pairs_.size(); ++q) clear_[stage_pairs_[q]] = all_clear(&occ_[w * q], w);
    }
  }

  /// Casts the pending pairs' rays; pairs the wide level's rays leave clear are plain elements, and tight
  /// elements once the tight level's near-miss rays (when it has its own) are clear too.
  void flush(const Viewpoint& v, const Eigen::Matrix3d& r, std::vector<std::uint32_t>& column, std::vector<std::uint32_t>& plain_column) {
    if (pending_.empty()) return;
    cast_wide_rays();
    extra_rays_.clear();
    extra_rows_.clear();
    for (std::size_t p = 0; p < pending_.size(); ++p) {
      if (!clear_[p]) continue;
      const Pending& e = pending_[p];
      if (plain_ && !e.tight) plain_column.push_back(e.row);
      if (!e.tight) continue;
      if (!lv_.tight_extra_rays) {
        column.push_back(e.row);
        continue;
      }
      extra_rows_.push_back(e.row);
      extra_rays_.resize(extra_rays_.size() + 8);
      pair_rays(rough_.points[e.row], rough_.normals[e.row], v, r, e.test, eps_, lv_.tight.margin_mm, &extra_rays_[extra_rays_.size() - 8]);
    }
    if (!extra_rows_.empty()) {
      scene_.occluded(extra_rays_.data(), extra_rays_.size(), extra_occ_.data());
      rays_cast += extra_rays_.size();
      for (std::size_t p = 0; p < extra_rows_.size(); ++p) {
        if (all_clear(&extra_occ_[8 * p], 8))
          column.push_back(extra_rows_[p]);
        else if (plain_ && (!plain_rows_ || (*plain_rows_)[extra_rows_[p]]))
          plain_column.push_back(extra_rows_[p]);
      }
    }
    pending_.clear();
    rays_.clear();
  }

  const RoughModel& rough_;
  const OcclusionScene& scene_;
  const std::vector<Block>& blocks_;
  const Levels& lv_;
  const double eps_;
  const bool plain_;
  const std::vector<std::uint8_t>* plain_rows_;  // PlainElements::rows
  std::vector<Pending> pending_;
  std::vector<OcclusionRay> rays_, extra_rays_, stage_rays_;
  std::vector<std::uint8_t> occ_, extra_occ_, clear_;
  std::vector<std::size_t> stage_pairs_;
  std::vector<std::uint32_t> extra_rows_;
  Eigen::Matrix3d r_, rt_;  // the current candidate's rotation and its transpose
  Tally tally_;
};

}  // namespace

std::size_t keep_plain_elements_of_lost_rows(MeasurabilityMatrix& m, const PlainElements& plain) {
  if (plain.matrix.n_cols() != m.n_cols())
    throw DataError("plain elements: " + std::to_string(plain.matrix.n_cols()) + " columns for a matrix of " +
                    std::to_string(m.n_cols()));
  const std::vector<std::uint32_t> lost = m.unmeasurable_rows();
  if (lost.empty()) return 0;
  std::vector<std::uint8_t> is_lost(m.n_rows, 0), gained(m.n_rows, 0);
  for (auto r : lost) is_lost[r] = 1;
  for (std::size_t j = 0; j < m.columns.size(); ++j) {
    std::vector<std::uint32_t> add;
    plain.matrix.columns[j].for_each([&](std::uint32_t r) {
      if (is_lost[r]) add.push_back(r), gained[r] = 1;
    });
    if (add.empty()) continue;  // most columns: left as they are, not copied
    std::vector<std::uint32_t> rows = m.columns[j].rows();
    rows.insert(rows.end(), add.begin(), add.end());
    std::sort(rows.begin(), rows.end());
    m.columns[j] = MeasurabilityColumn(std::move(rows), m.n_rows);
  }
  return static_cast<std::size_t>(std::count(gained.begin(), gained.end(), 1));
}

MeasurabilityMatrix build_measurability(const RoughModel& rough, const OcclusionScene& scene, const SensorModel& sensor,
                                        const ModelSpec& spec, const std::vector<Viewpoint>& candidates,
                                        const MatrixSettings& settings, MatrixStats* stats, const std::atomic<int>* cancel,
                                        PlainElements* plain, const RowsToTest* only) {
  MeasurabilityMatrix m;
  m.n_rows = static_cast<std::uint32_t>(rough.size());
  m.columns.resize(candidates.size());
  const auto blocks = make_blocks(rough, facing_limit_rad(sensor));
  const double eps = ray_offset_mm(rough, settings);
  // Two levels of the same test: `tight` makes the matrix; `wide` is the plain one whose elements the caller
  // also wants, or (without) the tight one with its undisplaced rays only. Every level's countermeasures are
  // at least the wide one's, so a tight element is always a wide one: blocks are culled and rays cast at the
  // wide level first, and the near-miss rays (4x as many) only for the pairs the undisplaced rays leave clear.
  Countermeasures wide_cm = plain ? plain->countermeasures : settings.countermeasures;
  if (!plain) wide_cm.visibility_margin_mm = 0.0;
  const TestLevel tight(sensor, spec, settings.countermeasures), wide(sensor, spec, wide_cm);
  const Levels lv{tight, wide, !plain, tight.margin_mm > 0.0 && tight.margin_mm != wide.margin_mm, wide.margin_mm > 0.0 ? 10u : 2u};
  if (plain) {
    const Countermeasures& t = settings.countermeasures;
    if (wide_cm.frustum_detune > t.frustum_detune || wide_cm.dof_margin_mm > t.dof_margin_mm ||
        wide_cm.compliance_buffer > t.compliance_buffer || wide_cm.visibility_margin_mm > t.visibility_margin_mm)
      throw std::invalid_argument("build_measurability: the plain test's countermeasures exceed the matrix's");
    if (plain->rows && plain->rows->size() != rough.size())
      throw std::invalid_argument("build_measurability: " + std::to_string(plain->rows->size()) + " plain-row flags for " +
                                  std::to_string(rough.size()) + " rows");
    plain->matrix = MeasurabilityMatrix{};
    plain->matrix.n_rows = m.n_rows;
    plain->matrix.columns.resize(candidates.size());
  }
  Counters cnt;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, candidates.size(), 4), [&](const auto& range) {
    ColumnWorker worker(rough, scene, blocks, lv, eps, plain != nullptr, plain ? plain->rows : nullptr);
    std::vector<std::uint32_t> column, plain_column, rows_to_test;
    for (std::size_t j = range.begin(); j != range.end(); ++j) {
      if (cancel && cancel->load(std::memory_order_relaxed) != 0) return;  // the caller stops planning
      if (only) {
        rows_to_test.clear();
        (*only)(j, rows_to_test);
      }
      worker.build(candidates[j], column, plain_column, cnt, only ? &rows_to_test : nullptr);
      m.columns[j] = MeasurabilityColumn(column, m.n_rows);
      if (plain) plain->matrix.columns[j] = MeasurabilityColumn(plain_column, m.n_rows);
    }
    cnt.rays += worker.rays_cast;
  });
  if (cancel && cancel->load() != 0)
    throw PlanCancelled("planning stopped by request while building the measurability matrix (" + std::to_string(candidates.size()) +
                        " candidates)");
  cnt.export_to(stats, static_cast<std::uint64_t>(m.n_rows) * candidates.size());
  return m;
}

MeasurabilityMatrix build_measurability_naive(const RoughModel& rough, const OcclusionScene& scene,
                                              const SensorModel& sensor, const ModelSpec& spec,
                                              const std::vector<Viewpoint>& candidates, const MatrixSettings& settings,
                                              MatrixStats* stats) {
  MeasurabilityMatrix m;
  m.n_rows = static_cast<std::uint32_t>(rough.size());
  m.columns.resize(candidates.size());
  const double eps = ray_offset_mm(rough, settings);
  const FrustumTerms terms(sensor);
  Counters cnt;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, candidates.size(), 1), [&](const auto& range) {
    std::vector<OcclusionRay> rays(2 * kPairsPerFlush);
    std::vector<std::uint8_t> occ(2 * kPairsPerFlush);
    std::vector<PointTest> tests(kPairsPerFlush);
    for (std::size_t j = range.begin(); j != range.end(); ++j) {
      const Viewpoint& v = candidates[j];
      const Eigen::Matrix3d r = v.rotation();
      const Eigen::Matrix3d rt = r.transpose();
      std::vector<std::uint32_t> column;
      for (std::uint32_t b = 0; b < m.n_rows; b += kPairsPerFlush) {
        const std::uint32_t e = std::min<std::uint32_t>(b + kPairsPerFlush, m.n_rows);
        for (std::uint32_t i = b; i < e; ++i) {
          const Eigen::Vector3d pc = rt * (rough.points[i] - v.position);
          PointTest t = test_point(sensor, terms, spec, v.scan_length_mm, pc, rt * rough.normals[i]);
          if (!t.in_frustum) {  // rays go where the laser would be for this y, in or out of the frustum
            t.laser_y_mm = sensor.kind == SensorKind::line_scan ? pc.y() : 0.0;
            t.receiver_y_mm = t.laser_y_mm + sensor.baseline_mm;
          }
          tests[i - b] = t;
          (void)pair_rays(rough.points[i], rough.normals[i], v, r, t, eps, 0.0, &rays[2 * (i - b)]);
        }
        scene.occluded(rays.data(), 2 * (e - b), occ.data());
        cnt.rays += 2 * (e - b);
        for (std::uint32_t i = b; i < e; ++i)
          if (tests[i - b].compliant && !occ[2 * (i - b)] && !occ[2 * (i - b) + 1]) column.push_back(i);
      }
      cnt.measurable += column.size();
      m.columns[j] = MeasurabilityColumn(column, m.n_rows);
    }
  });
  cnt.export_to(stats, static_cast<std::uint64_t>(m.n_rows) * candidates.size());
  return m;
}

bool measurable(const RoughModel& rough, const OcclusionScene& scene, const SensorModel& sensor, const ModelSpec& spec,
                const Viewpoint& v, std::uint32_t row, const MatrixSettings& settings) {
  const Eigen::Matrix3d r = v.rotation();
  const PointTest t =
      test_point(sensor, spec, v.scan_length_mm, r.transpose() * (rough.points[row] - v.position), r.transpose() * rough.normals[row]);
  if (!t.compliant) return false;
  OcclusionRay rays[2];
  (void)pair_rays(rough.points[row], rough.normals[row], v, r, t, ray_offset_mm(rough, settings), 0.0, rays);
  std::uint8_t occ[2];
  scene.occluded(rays, 2, occ);
  return !occ[0] && !occ[1];
}

}  // namespace scancell::planner
