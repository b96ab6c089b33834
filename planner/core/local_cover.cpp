#include "planner/core/local_cover.hpp"
#include "common/timing.hpp"
#include "planner/core/union_find.hpp"

#include <algorithm>
#include <chrono>
#include <numeric>
#include <stdexcept>

namespace scancell::planner {
namespace {

std::uint64_t splitmix(std::uint64_t& s) {
  std::uint64_t z = (s += 0x9e3779b97f4a7c15ULL);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

/// Rows → the columns that measure them (compressed), over rows of positive weight.
struct RowIndex {
  std::vector<std::uint64_t> start;
  std::vector<std::uint32_t> cols;
  std::size_t degree(std::uint32_t r) const { return start[r + 1] - start[r]; }
  const std::uint32_t* begin(std::uint32_t r) const { return cols.data() + start[r]; }
  const std::uint32_t* end(std::uint32_t r) const { return cols.data() + start[r + 1]; }
};

RowIndex index_rows(const MeasurabilityMatrix& m, const std::vector<double>& w) {
  RowIndex ix;
  ix.start.assign(m.n_rows + 1, 0);
  for (const auto& c : m.columns)
    c.for_each([&](std::uint32_t r) {
      if (w[r] > 0.0) ++ix.start[r + 1];
    });
  for (std::uint32_t r = 0; r < m.n_rows; ++r) ix.start[r + 1] += ix.start[r];
  ix.cols.resize(ix.start.back());
  std::vector<std::uint64_t> fill(ix.start.begin(), ix.start.end() - 1);
  for (std::uint32_t j = 0; j < m.n_cols(); ++j)
    m.columns[j].for_each([&](std::uint32_t r) {
      if (w[r] > 0.0) ix.cols[fill[r]++] = j;
    });
  return ix;
}

/// The registration graph of a set of views, its overlaps counted through the row index (every row a view
/// shares with another is visited once per pair sharing it).
class Registration {
 public:
  Registration(const MeasurabilityMatrix& m, const std::vector<double>& w, const CoverSettings& st, const RowIndex& ix)
      : m_(m), w_(w), st_(st), ix_(ix), col_w_(m.n_cols(), 0.0), slot_(m.n_cols(), kNone) {
    for (std::uint32_t j = 0; j < m.n_cols(); ++j) {
      m.columns[j].for_each([&](std::uint32_t r) { col_w_[j] += w[r]; });
      max_w_ = std::max(max_w_, col_w_[j]);
    }
  }

  double norm(std::uint32_t a, std::uint32_t b) const {
    return st_.normalizer == RegistrationNormalizer::max_view ? max_w_ : std::min(col_w_[a], col_w_[b]);
  }
  bool registers(std::uint32_t a, std::uint32_t b, double shared) const {
    const double n = norm(a, b);
    return n > 0.0 && shared > 0.0 && shared / n >= st_.registration_threshold;
  }

  /// Component label per view (index into views), and the number of components.
  std::size_t components(const std::vector<std::uint32_t>& views, std::vector<std::uint32_t>& label) {
    const std::size_t k = views.size();
    for (std::size_t i = 0; i < k; ++i) slot_[views[i]] = static_cast<std::uint32_t>(i);
    std::vector<double> shared(k * k, 0.0);
    std::vector<std::uint32_t> here;
    for (std::uint32_t r = 0; r < m_.n_rows; ++r) {
      if (ix_.degree(r) == 0) continue;
      here.clear();
      for (auto it = ix_.begin(r); it != ix_.end(r); ++it)
        if (slot_[*it] != kNone) here.push_back(slot_[*it]);
      for (std::size_t a = 0; a < here.size(); ++a)
        for (std::size_t b = a + 1; b < here.size(); ++b) shared[here[a] * k + here[b]] += w_[r];
    }
    UnionFind uf(k);
    for (std::size_t a = 0; a < k; ++a)
      for (std::size_t b = 0; b < k; ++b) {
        const double s = shared[a * k + b];
        if (a != b && registers(views[a], views[b], s)) uf.unite(static_cast<std::uint32_t>(a), static_cast<std::uint32_t>(b));
      }
    for (auto v : views) slot_[v] = kNone;
    label.assign(k, 0);
    std::size_t n = 0;
    std::vector<std::uint32_t> id(k, kNone);
    for (std::size_t i = 0; i < k; ++i) {
      const auto root = uf.find(static_cast<std::uint32_t>(i));
      if (id[root] == kNone) id[root] = static_cast<std::uint32_t>(n++);
      label[i] = id[root];
    }
    return n;
  }

  /// Adds bridge views until the registration graph is connected: each time the view (not yet chosen) that
  /// registers with views of the most components, at least two. False when no such view exists or after
  /// `max_bridges`.
  bool repair(std::vector<std::uint32_t>& views, std::size_t max_bridges) {
    std::vector<std::uint32_t> label;
    std::vector<double> shared(m_.n_cols(), 0.0);
    std::vector<std::uint32_t> touched;
    std::vector<char> chosen(m_.n_cols(), 0);
    for (std::size_t added = 0;; ++added) {
      const std::size_t n = components(views, label);
      if (n <= 1) return true;
      if (added == max_bridges) return false;
      for (auto v : views) chosen[v] = 1;
      std::vector<std::pair<std::uint32_t, std::uint32_t>> links;  // (column, component)
      for (std::size_t i = 0; i < views.size(); ++i) {
        m_.columns[views[i]].for_each([&](std::uint32_t r) {
          for (auto it = ix_.begin(r); it != ix_.end(r); ++it) {
            if (chosen[*it]) continue;
            if (shared[*it] == 0.0) touched.push_back(*it);
            shared[*it] += w_[r];
          }
        });
        for (auto j : touched) {
          if (registers(j, views[i], shared[j])) links.push_back({j, label[i]});
          shared[j] = 0.0;
        }
        touched.clear();
      }
      for (auto v : views) chosen[v] = 0;
      std::sort(links.begin(), links.end());
      links.erase(std::unique(links.begin(), links.end()), links.end());
      std::int64_t pick = -1;
      std::size_t pick_n = 1;
      for (std::size_t a = 0; a < links.size();) {
        std::size_t b = a;
        while (b < links.size() && links[b].first == links[a].first) ++b;
        if (b - a > pick_n) pick_n = b - a, pick = links[a].first;
        a = b;
      }
      if (pick < 0) return false;
      views.push_back(static_cast<std::uint32_t>(pick));
    }
  }

 private:
  static constexpr std::uint32_t kNone = 0xffffffffu;
  const MeasurabilityMatrix& m_;
  const std::vector<double>& w_;
  const CoverSettings& st_;
  const RowIndex& ix_;
  std::vector<double> col_w_;
  double max_w_ = 0.0;
  std::vector<std::uint32_t> slot_;
};

/// The search state: chosen columns, how often each row is covered, row weights and column scores.
/// score[j] = Σ ω_r over the rows j alone would newly cover (j not chosen) or would uncover (j chosen, as a
/// negative number), counting only the rows the cover must keep.
class Search {
 public:
  Search(const MeasurabilityMatrix& m, const RowIndex& ix, std::vector<char> need)
      : m_(m), ix_(ix), need_(std::move(need)), in_(m.n_cols(), 0), cnt_(m.n_rows, 0), xor_(m.n_rows, 0), omega_(m.n_rows, 1),
        score_(m.n_cols(), 0), age_(m.n_cols(), 0), pos_(m.n_rows, kNone) {
    for (std::uint32_t r = 0; r < m.n_rows; ++r)
      if (need_[r]) {
        uncover(r);
        for (auto it = ix_.begin(r); it != ix_.end(r); ++it) score_[*it] += omega_[r];
      }
  }

  const std::vector<std::uint32_t>& chosen() const { return chosen_; }
  /// Elements visited so far (column rows walked, score updates): the search's work, counted, not timed.
  std::uint64_t work() const { return work_; }
  std::size_t uncovered() const { return uncovered_.size(); }
  std::uint32_t uncovered_row(std::size_t k) const { return uncovered_[k]; }

  void add(std::uint32_t j, std::uint64_t now) {
    in_[j] = 1;
    work_ += m_.columns[j].count();
    chosen_.push_back(j);
    age_[j] = now;
    m_.columns[j].for_each([&](std::uint32_t r) {
      if (!need_[r]) return;
      xor_[r] ^= j;
      if (++cnt_[r] == 1) {
        cover(r);
        add_to_scores(r, -omega_[r], j);
      } else if (cnt_[r] == 2) {
        score_[sole_other(r, j)] += omega_[r];
      }
    });
    score_[j] = -score_[j];
  }

  void remove(std::uint32_t j, std::uint64_t now) {
    in_[j] = 0;
    work_ += m_.columns[j].count();
    chosen_.erase(std::find(chosen_.begin(), chosen_.end(), j));
    age_[j] = now;
    m_.columns[j].for_each([&](std::uint32_t r) {
      if (!need_[r]) return;
      xor_[r] ^= j;
      if (--cnt_[r] == 0) {
        uncover(r);
        add_to_scores(r, omega_[r], j);
      } else if (cnt_[r] == 1) {
        score_[sole_other(r, j)] -= omega_[r];
      }
    });
    score_[j] = -score_[j];
  }

  /// Every uncovered row weighs one more.
  void raise_uncovered_weights() {
    std::int64_t* score = score_.data();
    for (auto r : uncovered_) {
      work_ += ix_.degree(r);
      ++omega_[r];
      for (const std::uint32_t *it = ix_.begin(r), *e = ix_.end(r); it != e; ++it) ++score[*it];
    }
  }

  /// The chosen column whose removal costs least (highest score), not `tabu`; ties: oldest, lower index.
  std::int64_t best_to_remove(std::int64_t tabu) const {
    std::int64_t best = -1;
    for (auto j : chosen_) {
      if (static_cast<std::int64_t>(j) == tabu) continue;
      if (best < 0 || better(j, static_cast<std::uint32_t>(best))) best = j;
    }
    return best;
  }

  /// The column covering row r that gains most, not `tabu`; ties: oldest, lower index.
  std::int64_t best_to_add(std::uint32_t r, std::int64_t tabu) const {
    std::int64_t best = -1;
    for (auto it = ix_.begin(r); it != ix_.end(r); ++it) {
      if (static_cast<std::int64_t>(*it) == tabu) continue;
      if (best < 0 || better(*it, static_cast<std::uint32_t>(best))) best = *it;
    }
    return best;
  }

 private:
  static constexpr std::uint32_t kNone = 0xffffffffu;
  bool better(std::uint32_t a, std::uint32_t b) const {
    if (score_[a] != score_[b]) return score_[a] > score_[b];
    // Larger views first: more of the object's shape in one image registers it more firmly (a view of a
    // symmetric patch leaves directions free).
    if (m_.columns[a].count() != m_.columns[b].count()) return (m_.columns[a].count() > m_.columns[b].count()) == !in_[a];
    if (age_[a] != age_[b]) return age_[a] < age_[b];
    return a < b;
  }
  /// score += d for every column of row r but j (j measures r). The hot loop of a swap (each row a swap
  /// covers or uncovers, times its candidates): a plain pointer walk, j corrected after it, not tested in it.
  void add_to_scores(std::uint32_t r, std::int64_t d, std::uint32_t j) {
    work_ += ix_.degree(r);
    std::int64_t* score = score_.data();
    for (const std::uint32_t *it = ix_.begin(r), *e = ix_.end(r); it != e; ++it) score[*it] += d;
    score[j] -= d;
  }
  /// The one chosen column covering row r besides j, where r is covered by j and one other (or, j just left,
  /// by that one alone): the XOR of a row's chosen columns is that column, in O(1) rather than a walk over
  /// the row's candidates (on a dense mesh as given, hundreds per row, and most rows are covered twice).
  std::uint32_t sole_other(std::uint32_t r, std::uint32_t j) const {
    const std::uint32_t other = xor_[r] ^ (in_[j] ? j : 0u);
    if (other == j || !in_[other]) throw std::logic_error("local_search_cover: row count out of step with the chosen columns");
    return other;
  }
  void uncover(std::uint32_t r) {
    pos_[r] = static_cast<std::uint32_t>(uncovered_.size());
    uncovered_.push_back(r);
  }
  void cover(std::uint32_t r) {
    const std::uint32_t last = uncovered_.back();
    uncovered_[pos_[r]] = last;
    pos_[last] = pos_[r];
    uncovered_.pop_back();
    pos_[r] = kNone;
  }

  const MeasurabilityMatrix& m_;
  const RowIndex& ix_;
  std::vector<char> need_;
  std::vector<char> in_;
  std::vector<std::uint32_t> cnt_;
  std::vector<std::uint32_t> xor_;  // per row: the XOR of the chosen columns that cover it
  std::vector<std::int64_t> omega_, score_;
  std::vector<std::uint64_t> age_;
  std::vector<std::uint32_t> pos_, uncovered_, chosen_;
  std::uint64_t work_ = 0;
};

}  // namespace

std::size_t registration_component_count(const MeasurabilityMatrix& m, const std::vector<double>& w,
                                         const CoverSettings& st, const std::vector<std::uint32_t>& views) {
  if (views.empty()) return 0;
  const OverlapView o = overlap_of(m, w);
  const RowIndex ix = index_rows(o.m, o.w);
  Registration reg(o.m, o.w, st, ix);
  std::vector<std::uint32_t> label;
  return reg.components(views, label);
}

std::vector<std::uint32_t> local_search_cover(const MeasurabilityMatrix& m, const std::vector<double>& w,
                                              const CoverSettings& st, const std::vector<std::uint32_t>& start,
                                              std::uint64_t iterations, double time_limit_s, std::uint64_t seed,
                                              LocalSearchReport* report) {
  if (w.size() != m.n_rows) throw std::invalid_argument("local_search_cover: one weight per row required");
  const auto t0 = std::chrono::steady_clock::now();
  LocalSearchReport rep;
  rep.start_views = rep.best_views = start.size();
  std::vector<std::uint32_t> best = start;
  if (start.size() >= 2 && iterations > 0) {
    const RowIndex ix = index_rows(m, w);
    std::vector<char> need(m.n_rows, 0);
    for (auto j : start) m.columns[j].for_each([&](std::uint32_t r) { need[r] = w[r] > 0.0; });
    Search s(m, ix, need);
    const bool registration = registration_applies(st);
    // Registration counts overlap in its own rows when the matrix says so (MeasurabilityMatrix::overlap).
    const OverlapView o = overlap_of(m, w);
    const RowIndex overlap_ix = registration && m.overlap ? index_rows(o.m, o.w) : RowIndex{};
    Registration reg(o.m, o.w, st, registration && m.overlap ? overlap_ix : ix);
    std::uint64_t now = 1;
    for (auto j : start) s.add(j, now);
    rep.work_at_last_improvement = s.work();
    std::uint64_t rng = seed ^ 0x5ca9ce11ULL;
    std::int64_t last_added = -1;
    auto record = [&] {
      std::vector<std::uint32_t> cand = s.chosen();
      std::sort(cand.begin(), cand.end());
      if (registration && !reg.repair(cand, best.size() - cand.size() - 1)) {
        ++rep.rejected_unregistered;
        return;
      }
      if (cand.size() >= best.size()) {
        ++rep.rejected_unregistered;
        return;
      }
      best = std::move(cand);
      ++rep.improvements;
      rep.last_improvement_iteration = rep.iterations;
      rep.work_at_last_improvement = s.work();
    };
    while (rep.iterations < iterations && s.work() - rep.work_at_last_improvement < st.local_search_stall_work) {
      if ((rep.iterations & 255) == 0 &&
          seconds_since(t0) > time_limit_s) {
        rep.time_limit_hit = true;
        break;
      }
      ++now;
      if (s.uncovered() == 0) {
        if (s.chosen().size() < best.size()) record();
        if (s.chosen().size() <= 1) break;
        s.remove(static_cast<std::uint32_t>(s.best_to_remove(-1)), now);
        continue;
      }
      const std::int64_t out = s.best_to_remove(last_added);
      if (out < 0) break;
      s.remove(static_cast<std::uint32_t>(out), now);
      const std::uint32_t r = s.uncovered_row(splitmix(rng) % s.uncovered());
      std::int64_t in = s.best_to_add(r, out);
      if (in < 0) in = out;  // the row's only column
      s.add(static_cast<std::uint32_t>(in), now);
      last_added = in;
      s.raise_uncovered_weights();
      ++rep.iterations;
    }
    if (s.uncovered() == 0 && s.chosen().size() < best.size()) record();
    rep.work = s.work();
  }
  rep.best_views = best.size();
  rep.seconds = seconds_since(t0);
  if (report) *report = rep;
  return best;
}

}  // namespace scancell::planner
