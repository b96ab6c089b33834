#include "planner/core/cover.hpp"

#include "planner/core/union_find.hpp"

#include <algorithm>
#include <numeric>
#include <queue>
#include <stdexcept>

namespace scancell::planner {
namespace {

struct Entry {
  double gain;       // upper bound (stale) or exact (fresh) newly covered weight
  std::uint32_t col;
  std::uint32_t stamp;  // number of views chosen when the gain was computed
  bool operator<(const Entry& o) const {  // max-heap on gain, ties to the lower column index
    if (gain != o.gain) return gain < o.gain;
    return col > o.col;
  }
};

/// The rows no column measures and the measurable share of the weight (both results report them).
double fill_unmeasurable(const MeasurabilityMatrix& m, const std::vector<double>& w, CoverResult& res) {
  const double total = std::accumulate(w.begin(), w.end(), 0.0);
  res.unmeasurable_rows = m.unmeasurable_rows();
  double unmeasurable_w = 0.0;
  for (auto r : res.unmeasurable_rows) unmeasurable_w += w[r];
  res.measurable_fraction = total > 0 ? (total - unmeasurable_w) / total : 0.0;
  return total;
}

}  // namespace

namespace {

/// Calls f(row) for every row two columns share (walks the smaller, probes the larger).
template <class F>
void for_each_shared(const MeasurabilityColumn& a, const MeasurabilityColumn& b, F&& f) {
  const MeasurabilityColumn& small = a.count() <= b.count() ? a : b;
  const MeasurabilityColumn& large = a.count() <= b.count() ? b : a;
  small.for_each([&](std::uint32_t r) {
    if (large.contains(r)) f(r);
  });
}

}  // namespace

OverlapView overlap_of(const MeasurabilityMatrix& m, const std::vector<double>& w) {
  if (!m.overlap) return {m, w};
  const OverlapRows& o = *m.overlap;
  if (o.matrix.n_cols() != m.n_cols() || o.weight.size() != o.matrix.n_rows)
    throw std::invalid_argument("registration overlap: one column per matrix column and one weight per row required");
  return {o.matrix, o.weight};
}

double viewpoint_correlation(const MeasurabilityColumn& a, const MeasurabilityColumn& b, std::uint32_t m_s) {
  if (m_s == 0) return 0.0;
  std::uint32_t shared = 0;
  for_each_shared(a, b, [&](std::uint32_t) { ++shared; });
  return static_cast<double>(shared) / m_s;
}

double shared_weight(const MeasurabilityColumn& a, const MeasurabilityColumn& b, const std::vector<double>& w) {
  double shared = 0.0;
  for_each_shared(a, b, [&](std::uint32_t r) { shared += w[r]; });
  return shared;
}

namespace {

double column_weight(const MeasurabilityColumn& c, const std::vector<double>& w) {
  double s = 0.0;
  c.for_each([&](std::uint32_t r) { s += w[r]; });
  return s;
}

double max_column_weight(const MeasurabilityMatrix& m, const std::vector<double>& w) {
  double best = 0.0;
  for (const auto& c : m.columns) best = std::max(best, column_weight(c, w));
  return best;
}

/// Greedy set cover of M by gain (thesis 4.3), with lazy gains in a heap, and the registration constraint
/// (eq. 4.2, thesis 4.4.3) checked lazily: only for candidates that reach the top of the heap.
class Greedy {
 public:
  Greedy(const MeasurabilityMatrix& m, const std::vector<double>& w, const CoverSettings& st)
      : m_(m), w_(w), o_(overlap_of(m, w)), st_(st), covered_(m.n_rows, 0), chosen_(m.n_cols(), 0),
        constrained_(registration_applies(st)), registrable_(m.n_cols(), constrained_ ? 0 : 1),
        checked_upto_(constrained_ ? m.n_cols() : 0, 0), overlap_weight_(m.n_cols(), 0.0) {
    total_ = fill_unmeasurable(m, w, res_);
    for (std::uint32_t j = 0; j < m.n_cols(); ++j) {
      const double cw = column_weight(m.columns[j], w);
      res_.max_column_count = std::max(res_.max_column_count, m.columns[j].count());
      res_.max_column_weight = std::max(res_.max_column_weight, cw);
      overlap_weight_[j] = m.overlap ? column_weight(o_.m.columns[j], o_.w) : cw;
      max_overlap_weight_ = std::max(max_overlap_weight_, overlap_weight_[j]);
    }
    for (std::uint32_t j = 0; j < m.n_cols(); ++j) {
      const double g = gain_of(j);
      if (g > 0.0) heap_.push({g, j, 0});
    }
  }

  /// Picks views until the coverage goal, the minimum gain, or nothing registrable is left.
  CoverResult run() {
    res_.stop_reason = "no candidate adds coverage";
    while (true) {
      if (total_ > 0 && covered_w_ / total_ >= st_.coverage_goal - 1e-12) {
        res_.stop_reason = "coverage goal reached";
        break;
      }
      bool picked = pick_best();
      if (!picked && constrained_ && !waiting_.empty()) picked = bridge();
      if (!picked) {
        if (!waiting_.empty()) res_.stop_reason = "remaining gain needs views that cannot register (t_r)";
        break;
      }
    }
    return res_;
  }

  /// σ_kj = shared weight / normaliser(k, j) (eq. 4.2).
  double sigma(std::uint32_t a, std::uint32_t b) const {
    const double norm = normaliser(a, b);
    return norm > 0.0 ? shared(a, b) / norm : 0.0;
  }

 private:
  double shared(std::uint32_t a, std::uint32_t b) const { return shared_weight(o_.m.columns[a], o_.m.columns[b], o_.w); }
  double normaliser(std::uint32_t a, std::uint32_t b) const {
    return st_.normalizer == RegistrationNormalizer::max_view ? max_overlap_weight_ : std::min(overlap_weight_[a], overlap_weight_[b]);
  }
  // σ_kj ≥ t_r  <=>  shared ≥ t_r · normaliser(k, j).
  double needed(std::uint32_t a, std::uint32_t b) const { return st_.registration_threshold * normaliser(a, b); }

  // A candidate's overlap with each chosen view is counted once (checked_upto), and once it registers it stays
  // registrable. A row -> columns index would do it eagerly but doubles peak memory on whole objects.
  bool registers(std::uint32_t j) {
    if (registrable_[j]) return true;
    for (std::uint32_t k = checked_upto_[j]; k < res_.views.size(); ++k) {
      const double sh = shared(j, res_.views[k]);
      if (sh > 0.0 && sh >= needed(j, res_.views[k])) {
        registrable_[j] = 1;
        break;
      }
    }
    checked_upto_[j] = static_cast<std::uint32_t>(res_.views.size());
    return registrable_[j] != 0;
  }

  double gain_of(std::uint32_t j) const {
    double g = 0.0;
    m_.columns[j].for_each([&](std::uint32_t r) {
      if (!covered_[r]) g += w_[r];
    });
    return g;
  }

  void select(std::uint32_t col, double gain) {
    chosen_[col] = 1;
    res_.views.push_back(col);
    res_.gain_weight.push_back(gain);
    m_.columns[col].for_each([&](std::uint32_t r) {
      if (!covered_[r]) {
        covered_[r] = 1;
        covered_w_ += w_[r];
        ++covered_n_;
      }
    });
    res_.cumulative_fraction.push_back(total_ > 0 ? covered_w_ / total_ : 0.0);
    res_.cumulative_point_fraction.push_back(m_.n_rows ? static_cast<double>(covered_n_) / m_.n_rows : 0.0);
    if (constrained_) {
      // Waiting candidates return to the heap; their gains are now stale upper bounds, and the new view may
      // be the one they register with.
      for (auto& wentry : waiting_) heap_.push(wentry);
      waiting_.clear();
    }
  }

  /// The best fresh candidate that registers, selected; false when none is left above the minimum gain.
  bool pick_best() {
    const std::uint32_t stamp = static_cast<std::uint32_t>(res_.views.size());
    while (!heap_.empty()) {
      Entry e = heap_.top();
      heap_.pop();
      if (e.stamp != stamp) {  // stale: recompute, gains only shrink
        e.gain = gain_of(e.col);
        e.stamp = stamp;
        if (e.gain > 0.0) heap_.push(e);
        continue;
      }
      if (e.gain < st_.min_view_gain) {
        res_.stop_reason = "the best remaining view gains under the minimum (cover.min_view_gain_mm2)";
        heap_ = {};
        waiting_.clear();
        return false;
      }
      if (!res_.views.empty() && !registers(e.col)) {
        ++res_.blocked_by_registration;
        waiting_.push_back(e);
        continue;
      }
      select(e.col, e.gain);
      return true;
    }
    return false;
  }

  // When every candidate that still adds coverage is too far from the plan to register, add a bridge: a
  // view that registers with the plan and overlaps one of the best waiting candidates by t_r, preferring
  // the bridge that itself gains most. Without it the thesis' constrained greedy stalls on objects whose
  // large flat faces leave little overlap (fandisk: 8 views, 27 % measured).
  bool bridge() {
    std::vector<Entry> best = waiting_;
    std::sort(best.begin(), best.end(), [](const Entry& a, const Entry& b) { return b < a; });
    if (best.size() > 4) best.resize(4);
    for (const Entry& target : best) {
      std::int64_t pick = -1;
      double pick_gain = -1.0, pick_shared = -1.0;
      for (std::uint32_t j = 0; j < m_.n_cols(); ++j) {
        if (chosen_[j] || j == target.col) continue;
        const double sh = shared(j, target.col);
        if (sh <= 0.0 || sh < needed(j, target.col) || !registers(j)) continue;
        const double g = gain_of(j);
        if (g > pick_gain || (g == pick_gain && sh > pick_shared)) {
          pick = j;
          pick_gain = g;
          pick_shared = sh;
        }
      }
      if (pick >= 0) {
        select(static_cast<std::uint32_t>(pick), pick_gain);
        ++res_.bridge_views;
        return true;
      }
    }
    return false;
  }

  const MeasurabilityMatrix& m_;
  const std::vector<double>& w_;
  const OverlapView o_;  // what σ counts (overlap_of)
  const CoverSettings& st_;
  CoverResult res_;
  double total_ = 0.0, covered_w_ = 0.0;
  std::size_t covered_n_ = 0;
  std::vector<char> covered_, chosen_;
  const bool constrained_;
  std::vector<char> registrable_;
  std::vector<std::uint32_t> checked_upto_;
  std::vector<double> overlap_weight_;  // per column, in the overlap's rows
  double max_overlap_weight_ = 0.0;
  std::priority_queue<Entry> heap_;
  std::vector<Entry> waiting_;  // fresh-best candidates that cannot register yet
};

}  // namespace

CoverResult greedy_cover(const MeasurabilityMatrix& m, const std::vector<double>& w, const CoverSettings& st) {
  if (w.size() != m.n_rows) throw std::invalid_argument("greedy_cover: one weight per row required");
  Greedy greedy(m, w, st);
  CoverResult res = greedy.run();
  if (st.eliminate_redundant) {
    const auto kept = eliminate_redundant(m, w, st, res.views);
    const std::size_t removed = res.views.size() - kept.size();
    if (removed) {
      CoverResult d = describe_cover(m, w, st, kept);
      d.blocked_by_registration = res.blocked_by_registration;
      d.bridge_views = res.bridge_views;
      d.stop_reason = res.stop_reason;
      d.redundant_removed = removed;
      return d;
    }
  }
  // Registration graph G_r over the chosen views (thesis 4.2.5).
  const std::size_t n = res.views.size();
  UnionFind uf(n);
  for (std::uint32_t a = 0; a < n; ++a)
    for (std::uint32_t b = a + 1; b < n; ++b) {
      const double s = greedy.sigma(res.views[a], res.views[b]);
      if (s >= st.registration_threshold && s > 0.0) {
        res.registration_edges.push_back({a, b, s});
        uf.unite(a, b);
      }
    }
  for (std::uint32_t a = 0; a < n; ++a) res.registration_components += uf.find(a) == a;
  return res;
}

double registration_sigma(const MeasurabilityMatrix& m, const std::vector<double>& w, const CoverSettings& st,
                          std::uint32_t a, std::uint32_t b, double max_column_weight) {
  const OverlapView o = overlap_of(m, w);
  double norm = max_column_weight;
  if (st.normalizer == RegistrationNormalizer::smaller_view) norm = std::min(column_weight(o.m.columns[a], o.w), column_weight(o.m.columns[b], o.w));
  return norm > 0.0 ? shared_weight(o.m.columns[a], o.m.columns[b], o.w) / norm : 0.0;
}

namespace {

/// σ ≥ t_r between every pair of `views` (computed once: the passes below ask O(k³) questions of it).
std::vector<std::vector<char>> registration_adjacency(const MeasurabilityMatrix& cover_m, const std::vector<double>& cover_w,
                                                      const CoverSettings& st, const std::vector<std::uint32_t>& views) {
  const auto [m, w] = overlap_of(cover_m, cover_w);
  const std::size_t k = views.size();
  std::vector<double> vw(k);
  for (std::size_t i = 0; i < k; ++i) vw[i] = column_weight(m.columns[views[i]], w);
  const double ms = st.normalizer == RegistrationNormalizer::max_view ? max_column_weight(m, w) : 0.0;
  std::vector<std::vector<char>> adj(k, std::vector<char>(k, 0));
  for (std::size_t a = 0; a < k; ++a)
    for (std::size_t b = a + 1; b < k; ++b) {
      const double norm = st.normalizer == RegistrationNormalizer::max_view ? ms : std::min(vw[a], vw[b]);
      if (norm <= 0.0) continue;
      const double shared = shared_weight(m.columns[views[a]], m.columns[views[b]], w);
      if (shared > 0.0 && shared / norm >= st.registration_threshold) adj[a][b] = adj[b][a] = 1;
    }
  return adj;
}

/// Whether the views marked in `alive` form one connected registration graph (BFS on the adjacency).
bool connected(const std::vector<std::vector<char>>& adj, const std::vector<char>& alive) {
  std::size_t start = adj.size(), n_alive = 0;
  for (std::size_t i = 0; i < adj.size(); ++i)
    if (alive[i]) n_alive++, start = std::min(start, i);
  if (n_alive <= 1) return true;
  std::vector<char> seen(adj.size(), 0);
  std::vector<std::size_t> stack = {start};
  seen[start] = 1;
  std::size_t reached = 1;
  while (!stack.empty()) {
    const std::size_t a = stack.back();
    stack.pop_back();
    for (std::size_t b = 0; b < adj.size(); ++b)
      if (alive[b] && !seen[b] && adj[a][b]) seen[b] = 1, ++reached, stack.push_back(b);
  }
  return reached == n_alive;
}

}  // namespace

std::vector<std::uint32_t> eliminate_redundant(const MeasurabilityMatrix& m, const std::vector<double>& w,
                                               const CoverSettings& st, const std::vector<std::uint32_t>& views) {
  std::vector<std::uint32_t> count(m.n_rows, 0);
  for (auto j : views) m.columns[j].for_each([&](std::uint32_t r) { ++count[r]; });
  std::vector<char> keep(views.size(), 1);
  const bool registration = registration_applies(st);
  const auto adj = registration ? registration_adjacency(m, w, st, views) : std::vector<std::vector<char>>{};
  for (std::size_t k = views.size(); k-- > 0;) {
    bool redundant = true;
    m.columns[views[k]].for_each([&](std::uint32_t r) { redundant &= count[r] >= 2; });
    if (!redundant) continue;
    if (registration) {
      keep[k] = 0;
      const bool ok = connected(adj, keep);
      keep[k] = 1;
      if (!ok) continue;
    }
    keep[k] = 0;
    m.columns[views[k]].for_each([&](std::uint32_t r) { --count[r]; });
  }
  std::vector<std::uint32_t> out;
  for (std::size_t i = 0; i < views.size(); ++i)
    if (keep[i]) out.push_back(views[i]);
  return out;
}

std::vector<std::uint32_t> order_by_gain(const MeasurabilityMatrix& m, const std::vector<double>& w,
                                         const CoverSettings& st, std::vector<std::uint32_t> views) {
  std::sort(views.begin(), views.end());
  std::vector<char> covered(m.n_rows, 0), used(views.size(), 0), reaches(views.size(), 0);
  const bool registration = registration_applies(st);
  const auto adj = registration ? registration_adjacency(m, w, st, views) : std::vector<std::vector<char>>{};
  std::vector<std::uint32_t> out;
  while (out.size() < views.size()) {
    std::int64_t best = -1, best_reg = -1;
    double best_gain = -1.0, best_reg_gain = -1.0;
    for (std::size_t i = 0; i < views.size(); ++i) {
      if (used[i]) continue;
      double g = 0.0;
      m.columns[views[i]].for_each([&](std::uint32_t r) { if (!covered[r]) g += w[r]; });
      if (g > best_gain) best_gain = g, best = static_cast<std::int64_t>(i);
      if (reaches[i] && g > best_reg_gain) best_reg_gain = g, best_reg = static_cast<std::int64_t>(i);
    }
    const std::size_t pick = static_cast<std::size_t>(registration && best_reg >= 0 ? best_reg : best);
    used[pick] = 1;
    out.push_back(views[pick]);
    m.columns[views[pick]].for_each([&](std::uint32_t r) { covered[r] = 1; });
    if (registration)
      for (std::size_t i = 0; i < views.size(); ++i) reaches[i] |= adj[pick][i];
  }
  return out;
}

CoverResult describe_cover(const MeasurabilityMatrix& m, const std::vector<double>& w, const CoverSettings& st,
                           const std::vector<std::uint32_t>& views) {
  CoverResult res;
  const double total = fill_unmeasurable(m, w, res);
  for (std::uint32_t j = 0; j < m.n_cols(); ++j) {
    res.max_column_count = std::max(res.max_column_count, m.columns[j].count());
    res.max_column_weight = std::max(res.max_column_weight, column_weight(m.columns[j], w));
  }
  std::vector<char> covered(m.n_rows, 0);
  double covered_w = 0.0;
  std::size_t covered_n = 0;
  for (auto j : views) {
    double g = 0.0;
    m.columns[j].for_each([&](std::uint32_t r) {
      if (!covered[r]) {
        covered[r] = 1;
        g += w[r];
        ++covered_n;
      }
    });
    covered_w += g;
    res.views.push_back(j);
    res.gain_weight.push_back(g);
    res.cumulative_fraction.push_back(total > 0 ? covered_w / total : 0.0);
    res.cumulative_point_fraction.push_back(m.n_rows ? static_cast<double>(covered_n) / m.n_rows : 0.0);
  }
  const OverlapView o = overlap_of(m, w);
  std::vector<double> vw(views.size());
  for (std::size_t i = 0; i < views.size(); ++i) vw[i] = column_weight(o.m.columns[views[i]], o.w);
  const double ms = st.normalizer != RegistrationNormalizer::max_view ? 0.0
                   : m.overlap                                     ? max_column_weight(o.m, o.w)
                                                                   : res.max_column_weight;
  UnionFind uf(views.size());
  for (std::uint32_t a = 0; a < views.size(); ++a)
    for (std::uint32_t b = a + 1; b < views.size(); ++b) {
      const double norm = st.normalizer == RegistrationNormalizer::max_view ? ms : std::min(vw[a], vw[b]);
      const double s = norm > 0.0 ? shared_weight(o.m.columns[views[a]], o.m.columns[views[b]], o.w) / norm : 0.0;
      if (s >= st.registration_threshold && s > 0.0) {
        res.registration_edges.push_back({a, b, s});
        uf.unite(a, b);
      }
    }
  for (std::uint32_t a = 0; a < views.size(); ++a) res.registration_components += uf.find(a) == a;
  return res;
}

}  // namespace scancell::planner
