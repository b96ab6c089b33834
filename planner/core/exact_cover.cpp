#include "planner/core/exact_cover.hpp"
#include "common/timing.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <functional>
#include <map>
#include <numeric>
#include <sstream>
#include <stdexcept>
#include <string>
#include <unordered_map>

#include <poll.h>
#include <sys/wait.h>
#include <unistd.h>

#include <coin/CbcConfig.h>
#include <coin/CbcEventHandler.hpp>
#include <coin/CbcModel.hpp>
#include <coin/CoinPackedMatrix.hpp>
#include <coin/OsiClpSolverInterface.hpp>

#include "common/binary.hpp"
#include "common/errors.hpp"
#include "common/worker_process.hpp"

namespace scancell::planner {
namespace {

using Clock = std::chrono::steady_clock;


/// The instance after presolve, everything the worker needs (it inherits this memory across fork).
struct Problem {
  const MeasurabilityMatrix* m = nullptr;
  const std::vector<double>* w = nullptr;
  const CoverSettings* st = nullptr;
  std::vector<double> cost;                       // per original column
  std::vector<std::vector<std::uint32_t>> cols_of;  // original row -> columns (all rows)
  std::vector<std::uint32_t> ilp_col;             // ILP column -> original column
  std::vector<std::int64_t> ilp_of;               // original column -> ILP column or -1
  std::vector<std::vector<int>> rows;             // ILP rows: ILP columns, Σ x ≥ 1
  std::vector<std::uint32_t> forced;              // original columns fixed to 1
  std::vector<double> warm;                       // ILP warm start (empty: none)
  bool registration = false;
  bool core = false;  // the ILP holds only a core of the columns
  double forced_cost = 0.0;
  // What the registration constraint counts overlap in (overlap_of): the matrix's own rows and weights, or its
  // `overlap` (a cover by footprint samples shares a rough-model row between two views: footprint.hpp).
  const MeasurabilityMatrix* om = nullptr;
  const std::vector<double>* ow = nullptr;
  std::vector<std::vector<std::uint32_t>> ocols_of;  // overlap row -> columns, when om is not m
  mutable std::unordered_map<std::uint32_t, std::vector<std::uint32_t>> neighbours_cache;

  std::vector<double> weight_of;  // per column, what it measures in what overlap is counted in (registration only)
  double max_weight = 0.0;        // the largest of weight_of: the max_view normalizer of σ

  /// Sets m and w, what overlap is counted in, the row -> columns indices and, when the registration constraint
  /// applies (set `registration` first), each column's weight for σ.
  void index(const MeasurabilityMatrix& matrix, const std::vector<double>& weight) {
    m = &matrix;
    w = &weight;
    const OverlapView o = overlap_of(matrix, weight);
    om = &o.m;
    ow = &o.w;
    cols_of.assign(m->n_rows, {});
    for (std::uint32_t j = 0; j < m->n_cols(); ++j) m->columns[j].for_each([&](std::uint32_t r) { cols_of[r].push_back(j); });
    ocols_of.clear();
    if (om != m) {
      ocols_of.assign(om->n_rows, {});
      for (std::uint32_t j = 0; j < om->n_cols(); ++j) om->columns[j].for_each([&](std::uint32_t r) { ocols_of[r].push_back(j); });
    }
    weight_of.clear();
    max_weight = 0.0;
    if (!registration) return;
    weight_of.assign(om->n_cols(), 0.0);
    for (std::uint32_t k = 0; k < om->n_cols(); ++k) {
      om->columns[k].for_each([&](std::uint32_t r) { weight_of[k] += (*ow)[r]; });
      max_weight = std::max(max_weight, weight_of[k]);
    }
  }
  /// Columns k with σ(j, k) ≥ t_r, from the row -> columns index (shared weight accumulated per column); only
  /// where the registration constraint applies, which is what index() weighs the columns for.
  const std::vector<std::uint32_t>& neighbours(std::uint32_t j) const {
    auto it = neighbours_cache.find(j);
    if (it != neighbours_cache.end()) return it->second;
    const auto& index_of = om == m ? cols_of : ocols_of;
    std::unordered_map<std::uint32_t, double> shared;
    om->columns[j].for_each([&](std::uint32_t r) {
      for (auto k : index_of[r])
        if (k != j) shared[k] += (*ow)[r];
    });
    std::vector<std::uint32_t> out;
    for (const auto& [k, sh] : shared) {
      const double norm = st->normalizer == RegistrationNormalizer::max_view ? max_weight : std::min(weight_of[j], weight_of[k]);
      if (norm > 0.0 && sh > 0.0 && sh / norm >= st->registration_threshold) out.push_back(k);
    }
    std::sort(out.begin(), out.end());
    return neighbours_cache.emplace(j, std::move(out)).first->second;
  }
  /// Components of the registration graph over a set of original columns.
  std::vector<std::vector<std::uint32_t>> components(const std::vector<std::uint32_t>& set) const {
    std::map<std::uint32_t, std::size_t> index;
    for (std::size_t i = 0; i < set.size(); ++i) index[set[i]] = i;
    std::vector<std::int64_t> comp(set.size(), -1);
    std::vector<std::vector<std::uint32_t>> out;
    for (std::size_t s = 0; s < set.size(); ++s) {
      if (comp[s] >= 0) continue;
      out.emplace_back();
      std::vector<std::size_t> stack = {s};
      comp[s] = static_cast<std::int64_t>(out.size() - 1);
      while (!stack.empty()) {
        const std::size_t a = stack.back();
        stack.pop_back();
        out.back().push_back(set[a]);
        for (auto k : neighbours(set[a])) {
          auto f = index.find(k);
          if (f != index.end() && comp[f->second] < 0) {
            comp[f->second] = comp[s];
            stack.push_back(f->second);
          }
        }
      }
    }
    return out;
  }
  std::vector<std::uint32_t> cover_of(const double* x, int n) const {
    std::vector<std::uint32_t> s = forced;
    for (int j = 0; j < n; ++j)
      if (x[j] > 0.5) s.push_back(ilp_col[j]);
    std::sort(s.begin(), s.end());
    return s;
  }
  bool covers_all(const double* x) const {
    for (const auto& r : rows) {
      bool ok = false;
      for (int j : r) ok |= x[j] > 0.5;
      if (!ok) return false;
    }
    return true;
  }
  double objective(const std::vector<std::uint32_t>& s) const {
    double c = 0.0;
    for (auto j : s) c += cost[j];
    return c;
  }
};

// ---- worker side (runs in the worker process, common/worker_process.hpp) ----

void send(int fd, const std::string& line) {
  const char* p = line.data();
  std::size_t left = line.size();
  while (left) {
    const ssize_t n = ::write(fd, p, left);
    if (n <= 0) {
      if (n < 0 && errno == EINTR) continue;
      ::_exit(3);  // parent gone
    }
    p += n;
    left -= static_cast<std::size_t>(n);
  }
}

std::string solution_line(const Problem& P, const std::vector<std::uint32_t>& s) {
  std::ostringstream os;
  os.precision(17);
  os << "S " << P.objective(s);
  for (auto j : s) os << ' ' << j;
  os << '\n';
  return os.str();
}

/// Streams every feasible (and, with the registration constraint, connected) incumbent and the bound.
class Streamer : public CbcEventHandler {
 public:
  Streamer(const Problem* p, int fd, double* best) : problem_(p), fd_(fd), best_(best) {}
  Streamer(const Streamer& o) = default;
  CbcEventHandler* clone() const override { return new Streamer(*this); }
  CbcAction event(CbcEvent e) override {
    const Problem& P = *problem_;
    if ((e == solution || e == heuristicSolution) && model_->bestSolution() &&
        model_->getNumCols() == static_cast<int>(P.ilp_col.size())) {
      const double* x = model_->bestSolution();
      if (P.covers_all(x)) {
        const auto s = P.cover_of(x, model_->getNumCols());
        const double obj = P.objective(s);
        if (obj < *best_ - 1e-9 && (!P.registration || P.components(s).size() <= 1)) {
          *best_ = obj;
          send(fd_, solution_line(P, s));
        }
      }
    } else if (e == node) {
      const double b = model_->getBestPossibleObjValue();
      if (std::isfinite(b) && b > last_bound_ + 1e-9 && b < 1e20) {
        last_bound_ = b;
        char line[64];
        std::snprintf(line, sizeof line, "B %.17g\n", b + P.forced_cost);
        send(fd_, line);
      }
    }
    return noAction;
  }

 private:
  const Problem* problem_;
  int fd_;
  double* best_;
  double last_bound_ = -1e300;
};

/// The set-cover ILP (eq. 4.7-4.9): one binary per live column at its cost, each live row covered at least once.
void load_cover_ilp(const Problem& P, OsiClpSolverInterface& solver) {
  const int n = static_cast<int>(P.ilp_col.size());
  CoinPackedMatrix a(false, 0, 0);
  a.setDimensions(0, n);
  for (const auto& r : P.rows) {
    std::vector<double> ones(r.size(), 1.0);
    a.appendRow(static_cast<int>(r.size()), r.data(), ones.data());
  }
  std::vector<double> lb(n, 0.0), ub(n, 1.0), obj(n), rlb(P.rows.size(), 1.0), rub(P.rows.size(), COIN_DBL_MAX);
  for (int j = 0; j < n; ++j) obj[j] = P.cost[P.ilp_col[j]];
  solver.loadProblem(a, lb.data(), ub.data(), obj.data(), rlb.data(), rub.data());
  for (int j = 0; j < n; ++j) solver.setInteger(j);
  solver.messageHandler()->setLogLevel(0);
}

/// A disconnected cover (eq. 4.10 by lazy constraints): one cut per component, against a chosen view of the
/// largest other component, added to `solver`; returns how many. Cuts no cover can meet end the worker.
std::size_t add_connectivity_cuts(const Problem& P, std::vector<std::vector<std::uint32_t>> comps, OsiClpSolverInterface& solver,
                                  int fd) {
  std::size_t cuts = 0;
  std::sort(comps.begin(), comps.end(), [](const auto& p1, const auto& p2) { return p1.size() > p2.size(); });
  for (std::size_t c = 0; c < comps.size(); ++c) {
    const auto& C = comps[c];
    const std::uint32_t a = C.front(), bcol = comps[c == 0 ? 1 : 0].front();
    std::vector<char> in_c(P.m->n_cols(), 0);
    for (auto k : C) in_c[k] = 1;
    std::vector<int> idx;
    for (auto k0 : C)
      for (auto k : P.neighbours(k0))
        if (!in_c[k] && P.ilp_of[k] >= 0) idx.push_back(static_cast<int>(P.ilp_of[k]));
    std::sort(idx.begin(), idx.end());
    idx.erase(std::unique(idx.begin(), idx.end()), idx.end());
    std::vector<double> el(idx.size(), 1.0);
    double rhs = -1.0;  // Σ x_N − x_a − x_b ≥ −1, constants moved for forced views
    for (std::uint32_t end : {a, bcol}) {
      if (P.ilp_of[end] >= 0) {
        idx.push_back(static_cast<int>(P.ilp_of[end]));
        el.push_back(-1.0);
      } else {
        rhs += 1.0;  // forced: x = 1
      }
    }
    if (idx.empty() && rhs > 0.0) {
      send(fd, P.core ? "E no connected cover within the core problem\n"
                      : "E infeasible: forced views cannot be connected at this t_r\n");
      ::_exit(0);
    }
    solver.addRow(static_cast<int>(idx.size()), idx.data(), el.data(), rhs, COIN_DBL_MAX);
    ++cuts;
  }
  return cuts;
}

[[noreturn]] void run_worker(const Problem& P, int fd, Clock::time_point deadline) {
  OsiClpSolverInterface solver;
  load_cover_ilp(P, solver);
  double best = 1e300;
  std::size_t cuts = 0;
  for (int round = 0;; ++round) {
    const double left = std::chrono::duration<double>(deadline - Clock::now()).count();
    if (left <= 0.05) {
      send(fd, "E time limit\n");
      ::_exit(0);
    }
    CbcModel model(solver);
    CbcMain0(model);
    model.setLogLevel(0);
    model.messageHandler()->setLogLevel(0);
    Streamer streamer(&P, fd, &best);
    model.passInEventHandler(&streamer);
    if (!P.warm.empty()) {
      std::vector<std::pair<std::string, double>> start;
      for (std::size_t j = 0; j < P.warm.size(); ++j) start.emplace_back(model.solver()->getColName(static_cast<int>(j)), P.warm[j]);
      model.setMIPStart(start);
    }
    char sec[32];
    std::snprintf(sec, sizeof sec, "%.3f", left);
    const char* args[] = {"scancell", "-log", "0", "-preprocess", "off", "-sec", sec, "-solve", "-quit"};
    CbcMain1(9, args, model);
    send(fd, "R\n");  // one solve done
    if (model.isProvenInfeasible()) {
      // On a core problem infeasibility is the core's, not the instance's.
      send(fd, P.core ? "E no connected cover within the core problem\n"
                      : round == 0 ? "E infeasible: some row has no cover\n"
                                   : "E infeasible: no cover is connected at this t_r\n");
      ::_exit(0);
    }
    const double b = model.getBestPossibleObjValue();
    if (std::isfinite(b) && b < 1e20) {
      char line[64];
      std::snprintf(line, sizeof line, "B %.17g\n", b + P.forced_cost);
      send(fd, line);
    }
    const double* x = model.bestSolution();
    if (!x) {
      send(fd, "E time limit\n");
      ::_exit(0);
    }
    const auto s = P.cover_of(x, model.getNumCols());
    auto comps = P.registration ? P.components(s) : std::vector<std::vector<std::uint32_t>>{s};
    if (comps.size() <= 1) {
      if (P.objective(s) < best - 1e-9) {
        best = P.objective(s);
        send(fd, solution_line(P, s));
      }
      send(fd, model.isProvenOptimal() ? "E optimal\n" : "E time limit\n");
      ::_exit(0);
    }
    cuts += add_connectivity_cuts(P, std::move(comps), solver, fd);
    char line[64];
    std::snprintf(line, sizeof line, "C %zu\n", cuts);
    send(fd, line);
  }
}

/// What presolve leaves: the live rows and columns, the columns forced in, and for each dominated column one
/// that covers its rows at no more cost.
struct Reduction {
  std::vector<char> row_alive, col_alive, forced;
  std::vector<std::int64_t> dominator;  // dropped column -> a column covering its rows, -1
  /// Column j as the reduced problem knows it: itself, or the column that dominated it.
  std::int64_t reduced_column(std::uint32_t j0) const {
    std::int64_t j = j0;
    while (j >= 0 && !col_alive[j] && !forced[j]) j = dominator[j];
    return j;
  }
};

/// Presolve (rounds until nothing changes): forced columns, identical rows, row dominance, and column
/// dominance where no registration constraint ties columns together. Bounded by a work budget.
void presolve(const Problem& P, Reduction& red, ExactReport& rep) {
  const MeasurabilityMatrix& m = *P.m;
  const std::uint64_t budget = 400'000'000;
  std::uint64_t work = 0;
  auto alive_cols = [&](std::uint32_t r) {
    std::vector<std::uint32_t> out;
    for (auto j : P.cols_of[r])
      if (red.col_alive[j]) out.push_back(j);
    return out;
  };
  for (int round = 0; round < 8; ++round) {
    bool changed = false;
    // Forced columns: the only cover of some row.
    for (std::uint32_t r = 0; r < m.n_rows; ++r) {
      if (!red.row_alive[r]) continue;
      const auto cs = alive_cols(r);
      if (cs.size() != 1) continue;
      const std::uint32_t j = cs.front();
      red.forced[j] = 1;
      red.col_alive[j] = 0;
      ++rep.forced_columns;
      m.columns[j].for_each([&](std::uint32_t q) { red.row_alive[q] = 0; });
      changed = true;
    }
    // Identical rows.
    std::map<std::vector<std::uint32_t>, std::uint32_t> seen;
    std::vector<std::vector<std::uint32_t>> row_cols(m.n_rows);
    for (std::uint32_t r = 0; r < m.n_rows; ++r) {
      if (!red.row_alive[r]) continue;
      row_cols[r] = alive_cols(r);
      if (!seen.emplace(row_cols[r], r).second) {
        red.row_alive[r] = 0;
        ++rep.merged_rows;
        changed = true;
      }
    }
    // Row dominance: cols(A) ⊆ cols(B) makes B redundant. Candidates B share A's rarest column.
    std::vector<std::vector<std::uint32_t>> rows_of_col(m.n_cols());
    for (std::uint32_t r = 0; r < m.n_rows; ++r)
      if (red.row_alive[r])
        for (auto j : row_cols[r]) rows_of_col[j].push_back(r);
    std::vector<std::uint32_t> order;
    for (std::uint32_t r = 0; r < m.n_rows; ++r)
      if (red.row_alive[r]) order.push_back(r);
    std::sort(order.begin(), order.end(), [&](auto a, auto b) {
      return row_cols[a].size() != row_cols[b].size() ? row_cols[a].size() < row_cols[b].size() : a < b;
    });
    for (auto a : order) {
      if (!red.row_alive[a] || work > budget) continue;
      std::uint32_t rare = row_cols[a].front();
      for (auto j : row_cols[a])
        if (rows_of_col[j].size() < rows_of_col[rare].size()) rare = j;
      for (auto b : rows_of_col[rare]) {
        if (b == a || !red.row_alive[b] || row_cols[b].size() < row_cols[a].size()) continue;
        work += row_cols[a].size() + row_cols[b].size();
        if (std::includes(row_cols[b].begin(), row_cols[b].end(), row_cols[a].begin(), row_cols[a].end())) {
          red.row_alive[b] = 0;
          ++rep.dominated_rows;
          changed = true;
        }
      }
    }
    // Column dominance (no registration constraint): rows(j) ⊆ rows(k) and c_k ≤ c_j.
    if (!P.registration) {
      std::vector<std::vector<std::uint32_t>> col_rows(m.n_cols());
      for (std::uint32_t r = 0; r < m.n_rows; ++r)
        if (red.row_alive[r])
          for (auto j : P.cols_of[r])
            if (red.col_alive[j]) col_rows[j].push_back(r);
      for (std::uint32_t j = 0; j < m.n_cols(); ++j) {
        if (!red.col_alive[j]) continue;
        if (col_rows[j].empty()) {
          red.col_alive[j] = 0;  // covers nothing that is left
          continue;
        }
        if (work > budget) continue;
        std::uint32_t rare = col_rows[j].front();
        for (auto r : col_rows[j])
          if (row_cols[r].size() < row_cols[rare].size()) rare = r;
        for (auto k : P.cols_of[rare]) {
          if (k == j || !red.col_alive[k] || P.cost[k] > P.cost[j] || col_rows[k].size() < col_rows[j].size()) continue;
          const bool same = col_rows[k].size() == col_rows[j].size() && P.cost[k] == P.cost[j];
          if (same && k > j) continue;  // identical twins: keep the lower index
          work += col_rows[j].size() + col_rows[k].size();
          if (std::includes(col_rows[k].begin(), col_rows[k].end(), col_rows[j].begin(), col_rows[j].end())) {
            red.col_alive[j] = 0;
            red.dominator[j] = k;
            ++rep.dominated_columns;
            changed = true;
            break;
          }
        }
      }
    }
    if (!changed) break;
  }
  rep.dominance_budget_hit = work > budget;

}

/// The integer program over what presolve left (P.ilp_col, P.rows, P.forced).
void build_program(Problem& P, const Reduction& red, ExactReport& rep) {
  const MeasurabilityMatrix& m = *P.m;
  P.ilp_of.assign(m.n_cols(), -1);
  for (std::uint32_t j = 0; j < m.n_cols(); ++j) {
    if (red.forced[j]) {
      P.forced.push_back(j);
      P.forced_cost += P.cost[j];
    } else if (red.col_alive[j]) {
      P.ilp_of[j] = static_cast<std::int64_t>(P.ilp_col.size());
      P.ilp_col.push_back(j);
    }
  }
  for (std::uint32_t r = 0; r < m.n_rows; ++r) {
    if (!red.row_alive[r]) continue;
    std::vector<int> row;
    for (auto j : P.cols_of[r])
      if (P.ilp_of[j] >= 0) row.push_back(static_cast<int>(P.ilp_of[j]));
    P.rows.push_back(std::move(row));
  }
  rep.rows_after_presolve = P.rows.size();
  rep.columns_after_presolve = P.ilp_col.size();

}

/// A lower bound that needs no solver: rows with pairwise disjoint covers each need their own column.
void disjoint_rows_bound(const Problem& P, ExactReport& rep) {
  {
    std::vector<char> used(P.ilp_col.size(), 0);
    std::vector<std::size_t> order(P.rows.size());
    std::iota(order.begin(), order.end(), 0);
    std::sort(order.begin(), order.end(), [&](auto a, auto b) { return P.rows[a].size() < P.rows[b].size(); });
    double lb = 0.0;
    for (auto i : order) {
      bool disjoint = true;
      for (int j : P.rows[i]) disjoint &= !used[j];
      if (!disjoint) continue;
      double cheapest = 1e300;
      for (int j : P.rows[i]) used[j] = 1, cheapest = std::min(cheapest, P.cost[P.ilp_col[j]]);
      lb += cheapest;
    }
    rep.bound = P.forced_cost + lb;
  }

}

/// The Lagrangian bound and, on large instances, the core problem (below).
void lagrangian_bound_and_core(Problem& P, const Reduction& red, const std::vector<std::uint32_t>& warm, double warm_objective,
                               const CoverSettings& st, Clock::time_point t0, ExactReport& rep) {
  // Lagrangian bound (subgradient on the row constraints): close to the LP bound at a fraction of the root
  // LP's cost, and valid whatever CBC manages before the time limit. A quarter of the limit at most.
  if (!P.rows.empty()) {
    const std::size_t nc = P.ilp_col.size();
    std::vector<std::vector<int>> rows_of(nc);
    for (std::size_t i = 0; i < P.rows.size(); ++i)
      for (int j : P.rows[i]) rows_of[j].push_back(static_cast<int>(i));
    std::vector<double> c(nc), u(P.rows.size()), reduced(nc), g(P.rows.size());
    for (std::size_t j = 0; j < nc; ++j) c[j] = P.cost[P.ilp_col[j]];
    for (std::size_t i = 0; i < P.rows.size(); ++i) {
      double best = 1e300;
      for (int j : P.rows[i]) best = std::min(best, c[j] / static_cast<double>(rows_of[j].size()));
      u[i] = best;
    }
    const double ub = warm_objective > 0.0 ? warm_objective - P.forced_cost : 1e9;
    const auto lag_deadline = t0 + std::chrono::duration_cast<Clock::duration>(
                                       std::chrono::duration<double>(std::min(2.0, 0.25 * st.exact_time_limit_s)));
    double lambda = 2.0, best_l = -1e300;
    std::vector<double> best_reduced;
    int since_better = 0;
    for (int it = 0; it < 5000 && lambda > 1e-4 && Clock::now() < lag_deadline; ++it) {
      double l = std::accumulate(u.begin(), u.end(), 0.0);
      for (std::size_t j = 0; j < nc; ++j) {
        double s = c[j];
        for (int i : rows_of[j]) s -= u[i];
        reduced[j] = s;
        if (s < 0.0) l += s;
      }
      if (l > best_l + 1e-9) best_l = l, since_better = 0, best_reduced = reduced;
      else if (++since_better >= 20) lambda *= 0.5, since_better = 0;
      double norm = 0.0;
      for (std::size_t i = 0; i < P.rows.size(); ++i) {
        double covered = 0.0;
        for (int j : P.rows[i]) covered += reduced[j] < 0.0 ? 1.0 : 0.0;
        g[i] = 1.0 - covered;
        if (u[i] <= 0.0 && g[i] < 0.0) g[i] = 0.0;  // projected: u stays ≥ 0
        norm += g[i] * g[i];
      }
      if (norm == 0.0) break;  // the relaxed solution is feasible: L is the LP optimum
      const double step = lambda * std::max(ub - l, 1e-3) / norm;
      for (std::size_t i = 0; i < P.rows.size(); ++i) u[i] = std::max(0.0, u[i] + step * g[i]);
    }
    // With integer costs the optimum is an integer: round the bound up (with a little slack for rounding).
    bool integer_costs = true;
    for (double cj : c) integer_costs &= cj == std::floor(cj);
    const double lag = integer_costs ? std::ceil(best_l - 1e-6) : best_l;
    rep.lagrangian_bound = P.forced_cost + lag;
    rep.bound = std::max(rep.bound, rep.lagrangian_bound);

    // Core problem (Caprara, Fischetti, Toth): on large instances CBC cannot finish even the root LP in the
    // limit, so it gets the columns that matter: per row the few with the smallest Lagrangian reduced cost,
    // plus the warm start. Its covers are covers of the full problem; optimality on the core is not proven
    // for the full problem, the Lagrangian bound stays the bound.
    std::size_t nnz = 0;
    for (const auto& r : P.rows) nnz += r.size();
    if (nnz > 300'000 && !best_reduced.empty()) {
      constexpr std::size_t kPerRow = 6;
      std::vector<char> in_core(nc, 0);
      for (const auto& r : P.rows) {
        std::vector<int> byc(r.begin(), r.end());
        const std::size_t k = std::min(kPerRow, byc.size());
        std::partial_sort(byc.begin(), byc.begin() + static_cast<long>(k), byc.end(), [&](int a, int b) {
          return best_reduced[a] != best_reduced[b] ? best_reduced[a] < best_reduced[b] : a < b;
        });
        for (std::size_t i = 0; i < k; ++i) in_core[byc[i]] = 1;
      }
      for (auto j0 : warm) {
        const std::int64_t j = red.reduced_column(j0);
        if (j >= 0 && P.ilp_of[j] >= 0) in_core[P.ilp_of[j]] = 1;
      }
      std::vector<std::uint32_t> core_cols;
      std::vector<std::int64_t> remap(nc, -1);
      for (std::size_t j = 0; j < nc; ++j)
        if (in_core[j]) remap[j] = static_cast<std::int64_t>(core_cols.size()), core_cols.push_back(P.ilp_col[j]);
      for (auto& r : P.rows) {
        std::vector<int> nr;
        for (int j : r)
          if (remap[j] >= 0) nr.push_back(static_cast<int>(remap[j]));
        r = std::move(nr);
      }
      std::fill(P.ilp_of.begin(), P.ilp_of.end(), -1);
      for (std::size_t j = 0; j < core_cols.size(); ++j) P.ilp_of[core_cols[j]] = static_cast<std::int64_t>(j);
      P.ilp_col = std::move(core_cols);
      rep.core_columns = P.ilp_col.size();
      P.core = true;
    }
  }
}

/// Warm start in the reduced space: the warm cover's views, a dropped view replaced by its dominator.
void warm_start(Problem& P, const Reduction& red, const std::vector<std::uint32_t>& warm) {
  P.warm.assign(P.ilp_col.size(), 0.0);
  for (auto j0 : warm) {
    const std::int64_t j = red.reduced_column(j0);
    if (j >= 0 && P.ilp_of[j] >= 0) P.warm[P.ilp_of[j]] = 1.0;
  }
  if (!P.covers_all(P.warm.data())) P.warm.clear();  // cannot happen; never hand CBC a wrong start
}

// ---- the worker's input: the problem, whole (the worker is a fresh process, common/worker_process.hpp) ----

template <class T>
void put_all(std::string& out, const std::vector<T>& v) {
  append_binary<std::uint64_t>(out, v.size());
  for (const T& x : v) append_binary<T>(out, x);
}

/// Reads what encode_problem wrote; a short or inconsistent input throws (the worker then ends without an answer).
class Reader {
 public:
  explicit Reader(const std::string& s) : s_(s) {}
  template <class T>
  T get() {
    if (at_ + sizeof(T) > s_.size()) throw std::runtime_error("exact_cover worker: truncated input");
    T v;
    std::memcpy(&v, s_.data() + at_, sizeof v);
    at_ += sizeof v;
    return v;
  }
  template <class T>
  std::vector<T> get_all() {
    const auto n = get<std::uint64_t>();
    if (n > (s_.size() - at_) / sizeof(T)) throw std::runtime_error("exact_cover worker: inconsistent input");
    std::vector<T> v(n);
    for (auto& x : v) x = get<T>();
    return v;
  }
  bool done() const { return at_ == s_.size(); }

 private:
  const std::string& s_;
  std::size_t at_ = 0;
};

/// Each column's rows (the row count is written beside them).
void put_columns(std::string& out, const MeasurabilityMatrix& m) {
  for (const auto& c : m.columns) put_all(out, c.rows());
}

/// Reads what put_columns wrote for `n_cols` columns into `m`, whose n_rows is already set.
void read_columns(Reader& in, MeasurabilityMatrix& m, std::uint64_t n_cols) {
  m.columns.resize(n_cols);
  for (auto& c : m.columns) c = MeasurabilityColumn(in.get_all<std::uint32_t>(), m.n_rows);
}

std::string encode_problem(const Problem& P, double seconds_left) {
  std::string out;
  append_binary<std::uint32_t>(out, P.m->n_rows);
  append_binary<std::uint64_t>(out, P.m->n_cols());
  put_columns(out, *P.m);
  put_all(out, *P.w);
  append_binary<std::uint8_t>(out, P.m->overlap ? 1 : 0);
  if (P.m->overlap) {
    append_binary<std::uint32_t>(out, P.om->n_rows);
    put_columns(out, *P.om);
    put_all(out, *P.ow);
  }
  append_binary<std::uint8_t>(out, static_cast<std::uint8_t>(P.st->normalizer));
  append_binary<double>(out, P.st->registration_threshold);
  put_all(out, P.cost);
  put_all(out, P.ilp_col);
  append_binary<std::uint64_t>(out, P.rows.size());
  for (const auto& r : P.rows) put_all(out, r);
  put_all(out, P.forced);
  put_all(out, P.warm);
  append_binary<std::uint8_t>(out, P.registration);
  append_binary<std::uint8_t>(out, P.core);
  append_binary<double>(out, P.forced_cost);
  append_binary<double>(out, seconds_left);
  return out;
}

constexpr const char* kWorkerKind = "exact-cover";

/// The worker's side: rebuilds the problem from stdin and solves it until its time is up.
int worker_main(int out_fd, const std::string&) try {
  const std::string input = read_worker_input();
  Reader in(input);
  MeasurabilityMatrix m;
  m.n_rows = in.get<std::uint32_t>();
  read_columns(in, m, in.get<std::uint64_t>());
  const std::vector<double> w = in.get_all<double>();
  if (in.get<std::uint8_t>() != 0) {
    auto o = std::make_shared<OverlapRows>();
    o->matrix.n_rows = in.get<std::uint32_t>();
    read_columns(in, o->matrix, m.n_cols());
    o->weight = in.get_all<double>();
    m.overlap = std::move(o);
  }
  CoverSettings st;
  st.normalizer = static_cast<RegistrationNormalizer>(in.get<std::uint8_t>());
  st.registration_threshold = in.get<double>();
  Problem P;
  P.st = &st;
  P.cost = in.get_all<double>();
  P.ilp_col = in.get_all<std::uint32_t>();
  P.rows.resize(in.get<std::uint64_t>());
  for (auto& r : P.rows) r = in.get_all<int>();
  P.forced = in.get_all<std::uint32_t>();
  P.warm = in.get_all<double>();
  P.registration = in.get<std::uint8_t>() != 0;
  P.core = in.get<std::uint8_t>() != 0;
  P.forced_cost = in.get<double>();
  const double seconds_left = in.get<double>();
  if (!in.done() || w.size() != m.n_rows || P.cost.size() != m.n_cols()) throw std::runtime_error("exact_cover worker: inconsistent input");
  P.ilp_of.assign(m.n_cols(), -1);
  for (std::size_t j = 0; j < P.ilp_col.size(); ++j) P.ilp_of.at(P.ilp_col[j]) = static_cast<std::int64_t>(j);
  P.index(m, w);
  run_worker(P, out_fd, Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(seconds_left)));
} catch (const std::exception& e) {
  send(out_fd, std::string("E the solver's worker failed: ") + e.what() + "\n");
  return 2;
}

// In an exact-cover worker this solves the problem on stdin and ends the process before main().
[[maybe_unused]] const bool worker_started = run_if_worker(kWorkerKind, &worker_main);

/// Runs CBC in a worker process until it ends or the deadline passes, taking every improving cover it reports;
/// returns how it ended. The worker is killed at the deadline (CBC's own limit is not trusted to hold). It is
/// this executable started afresh with the problem on its stdin, not a fork: a fork of this multithreaded
/// process could inherit a lock another thread held at that instant (common/worker_process.hpp).
std::string solve_in_worker(const Problem& P, Clock::time_point deadline, ExactReport& rep,
                            const std::function<void(std::vector<std::uint32_t>, double)>& take) {
  std::string end_status;
  const double seconds_left = std::chrono::duration<double>(deadline - Clock::now()).count();
  const SpawnedWorker worker = spawn_worker(kWorkerKind, "", encode_problem(P, seconds_left));
  const pid_t pid = worker.pid;
  const int rd = worker.read_fd;
  std::string buf;
  bool done = false;
  auto handle = [&](const std::string& line) {
    std::istringstream in(line);
    char kind = 0;
    in >> kind;
    if (kind == 'S') {
      double obj = 0.0;
      in >> obj;
      std::vector<std::uint32_t> s;
      for (std::uint32_t j; in >> j;) s.push_back(j);
      take(std::move(s), obj);
    } else if (kind == 'B') {
      double b = 0.0;
      in >> b;
      if (!rep.core_columns) rep.bound = std::max(rep.bound, b);  // a core's bound says nothing of the whole
    } else if (kind == 'C') {
      in >> rep.connectivity_cuts;
    } else if (kind == 'R') {
      ++rep.solves;
    } else if (kind == 'E') {
      std::getline(in >> std::ws, end_status);
      done = true;
    }
  };
  while (!done) {
    const double left_ms = std::chrono::duration<double, std::milli>(deadline - Clock::now()).count() + 250.0;
    if (left_ms <= 0.0) break;
    pollfd pfd{rd, POLLIN, 0};
    const int pr = ::poll(&pfd, 1, static_cast<int>(std::min(left_ms, 1000.0)));
    if (pr < 0 && errno == EINTR) continue;
    if (pr <= 0) continue;
    char chunk[65536];
    const ssize_t n = ::read(rd, chunk, sizeof chunk);
    if (n <= 0) break;  // worker exited (or died)
    buf.append(chunk, static_cast<std::size_t>(n));
    for (std::size_t nl; (nl = buf.find('\n')) != std::string::npos;) {
      handle(buf.substr(0, nl));
      buf.erase(0, nl + 1);
    }
  }
  ::kill(pid, SIGKILL);
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  ::close(rd);
  if (end_status.empty()) end_status = done ? "time limit" : "time limit (solver stopped)";
  return end_status;
}

/// Which rows `views` measure, a flag per row. A column out of range throws, naming `whose` cover it is in.
std::vector<char> rows_covered(const MeasurabilityMatrix& m, const std::vector<std::uint32_t>& views, const char* whose) {
  std::vector<char> cov(m.n_rows, 0);
  for (auto j : views) {
    if (j >= m.n_cols())
      throw std::invalid_argument(std::string("exact_cover: ") + whose + " column " + std::to_string(j) + " of " + std::to_string(m.n_cols()));
    m.columns[j].for_each([&](std::uint32_t r) { cov[r] = 1; });
  }
  return cov;
}

/// Whether every row the program keeps is flagged in `cov`.
bool covers_kept_rows(const Reduction& red, const std::vector<char>& cov) {
  for (std::size_t r = 0; r < cov.size(); ++r)
    if (red.row_alive[r] && !cov[r]) return false;
  return true;
}

/// Whether `start` (original columns) covers every row the program keeps and, under the registration
/// constraint, its overlap graph is connected.
bool start_is_feasible(const Problem& P, const Reduction& red, const std::vector<std::uint32_t>& start) {
  return covers_kept_rows(red, rows_covered(*P.m, start, "start")) && (!P.registration || P.components(start).size() <= 1);
}

}  // namespace

CoverSettings exact_greedy_settings(const CoverSettings& st) {
  CoverSettings gs = st;
  gs.mode = registration_applies(st) ? CoverMode::constrained : CoverMode::greedy;
  gs.coverage_goal = 1.0;
  gs.eliminate_redundant = true;
  return gs;
}

CoverResult exact_cover(const MeasurabilityMatrix& m, const std::vector<double>& w, const CoverSettings& st,
                        const std::vector<double>& cost_in, ExactReport* report, const std::vector<std::uint32_t>& start,
                        const CoverResult* greedy_in) {
  const auto t0 = Clock::now();
  if (w.size() != m.n_rows) throw std::invalid_argument("exact_cover: one weight per row required");
  if (st.coverage_goal < 1.0 - 1e-12)
    throw ConfigError("cover.mode exact covers every measurable row: the spec's coverage_goal must be 1");
  ExactReport rep;
  rep.solver = std::string("CBC ") + CBC_VERSION;
  Problem P;
  P.st = &st;
  P.registration = registration_applies(st);
  P.cost = cost_in.empty() ? std::vector<double>(m.n_cols(), 1.0) : cost_in;
  if (P.cost.size() != m.n_cols()) throw std::invalid_argument("exact_cover: one cost per column required");
  for (double c : P.cost)
    if (!(c > 0.0) || !std::isfinite(c)) throw std::invalid_argument("exact_cover: column costs must be finite and > 0");
  rep.columns = m.n_cols();

  // Warm start and answer of record: greedy (constrained when registration applies), the caller's when given.
  const CoverResult greedy = greedy_in ? *greedy_in : greedy_cover(m, w, exact_greedy_settings(st));

  P.index(m, w);
  Reduction red;
  red.row_alive.assign(m.n_rows, 0);
  red.col_alive.assign(m.n_cols(), 1);
  red.forced.assign(m.n_cols(), 0);
  red.dominator.assign(m.n_cols(), -1);
  for (std::uint32_t r = 0; r < m.n_rows; ++r) red.row_alive[r] = !P.cols_of[r].empty();
  bool greedy_feasible = true;
  {
    const std::vector<char> cov = rows_covered(m, greedy.views, "greedy");
    // cover.min_view_gain_mm2: a view is not spent on less area than this, whichever cover picks it. The rows
    // greedy leaves open for that reason are left to the closed loop here too, so greedy's cover stays a
    // feasible warm start and the answer is never worse than it (without this, CBC started from nothing).
    if (st.min_view_gain > 0.0)
      for (std::uint32_t r = 0; r < m.n_rows; ++r)
        if (red.row_alive[r] && !cov[r]) red.row_alive[r] = 0, ++rep.rows_below_min_gain;
    greedy_feasible = covers_kept_rows(red, cov) && (!P.registration || greedy.registration_components <= 1);
  }
  rep.rows = static_cast<std::size_t>(std::count(red.row_alive.begin(), red.row_alive.end(), 1));
  if (greedy_feasible)
    for (auto j : greedy.views) rep.greedy_objective += P.cost[j];
  // The caller's start (the local search's cover, plan.cpp) replaces greedy as warm start and answer of record
  // when it covers every row the program keeps, registers and costs less: the default cover improves on
  // greedy, and exact mode must never be worse than the default (knot1 in free space: 152 views after CBC's
  // 10 s from greedy's 163, where the local search had 140; docs/quality.md).
  std::vector<std::uint32_t> warm = greedy_feasible ? greedy.views : std::vector<std::uint32_t>{};
  double warm_obj = greedy_feasible ? rep.greedy_objective : 0.0;
  if (!start.empty() && start_is_feasible(P, red, start) && (warm.empty() || P.objective(start) < warm_obj - 1e-9)) {
    warm = start;
    std::sort(warm.begin(), warm.end());
    warm_obj = rep.start_objective = P.objective(warm);
  }

  presolve(P, red, rep);
  build_program(P, red, rep);
  disjoint_rows_bound(P, rep);
  lagrangian_bound_and_core(P, red, warm, warm_obj, st, t0, rep);
  if (!warm.empty()) warm_start(P, red, warm);

  std::vector<std::uint32_t> best_set = warm;
  double best_obj = warm.empty() ? 1e300 : warm_obj;
  std::string end_status;
  const auto deadline = t0 + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(st.exact_time_limit_s));

  auto take = [&](std::vector<std::uint32_t> s, double obj) {
    if (obj < best_obj - 1e-9) {
      best_obj = obj;
      best_set = std::move(s);
      ++rep.improved_solutions;
    }
  };
  const bool trivial_connected = !P.registration || P.components(P.forced).size() <= 1;
  if (P.rows.empty() && trivial_connected) {
    take(P.forced, P.forced_cost);
    end_status = "optimal";
  } else {
    end_status = solve_in_worker(P, deadline, rep, take);
  }

  if (rep.core_columns && end_status == "optimal") end_status = "optimal on the core problem";
  rep.proven_optimal = end_status == "optimal";
  if (rep.proven_optimal) rep.bound = best_obj;
  const bool infeasible = end_status.rfind("infeasible", 0) == 0;
  if (best_set.empty() && !infeasible && rep.rows > 0) end_status = "time limit, no feasible cover found";
  rep.objective = best_set.empty() ? 0.0 : best_obj;
  rep.bound = std::min(rep.bound, rep.objective > 0.0 ? rep.objective : rep.bound);
  rep.gap = rep.objective > 0.0 ? (rep.objective - rep.bound) / rep.objective : 0.0;
  if (!rep.proven_optimal && !infeasible && rep.improved_solutions == 0 && !warm.empty())
    end_status = (rep.start_objective > 0.0 ? "start kept: " : "greedy kept: ") + end_status;
  rep.status = end_status;
  rep.seconds = seconds_since(t0);

  // No feasible cover (infeasible, or none in time): keep greedy's partial cover rather than nothing, and say so.
  const bool partial = best_set.empty();
  if (partial) {
    best_set = greedy.views;
    rep.status += "; greedy's partial cover kept";
  }
  CoverResult res = describe_cover(m, w, st, partial ? best_set : order_by_gain(m, w, st, best_set));
  char reason[160];
  std::snprintf(reason, sizeof reason, "exact (%s): %s, %g views, bound %g, gap %.3f", rep.solver.c_str(),
                rep.status.c_str(), rep.objective, rep.bound, rep.gap);
  res.stop_reason = reason;
  if (rep.rows_below_min_gain > 0)
    res.stop_reason += "; " + std::to_string(rep.rows_below_min_gain) +
                       " rows left open as no view gains cover.min_view_gain_mm2 on them";
  if (report) *report = rep;
  return res;
}

}  // namespace scancell::planner
