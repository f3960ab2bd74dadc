// Property test for Hierarchy<D>::refine: random marking sequences (random subsets, local
// clusters, green leaves, planes, spheres, mixtures; with and without vertex limits) must never
// reach an invalid green pattern (that aborts inside refine) and must leave a conforming leaf
// mesh after every call. Each case runs in a forked child, so an abort is reported with its
// seed instead of ending the run.
//
//   refine_stress [--dim 2|3|0] [--seeds N] [--first S] [--max-leaves L] [--steps K] [--uniform U]
//                 [--no-limits] [--no-validate] [--summary] [--verbose]
//   Defaults (200 seeds per dimension up to 2*10^5 leaves) take about a minute; the >= 10 M leaf run
//   of bench/results/refine_stress_results.md uses --uniform 6 (3D) / 10 (2D) --max-leaves 10000000.
//   refine_stress --case DIM SEED   (one case in-process: for a debugger)
#include <mlfe/core/mesh/hierarchy.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <random>
#include <string>
#include <vector>

namespace {

using mlfe::ElemId;
using mlfe::ElemKind;
using mlfe::Hierarchy;
using mlfe::SimplexTraits;
using mlfe::VertexId;

struct Options {
  int dim = 0;  // 0: both
  long seeds = 200;
  long first = 1;
  std::size_t max_leaves = 200000;
  int steps = 12;
  int uniform = -1;  // uniform refinements before the random calls; -1: drawn per case (0-3 / 0-5)
  bool summary = false;
  bool verbose = false;
  bool limits = true;
  bool validate = true;  // off: see what an unvalidated caller (mlfe convert) would hit
};

[[noreturn]] void fail(const char* what, long seed, int step) {
  std::fflush(stdout);
  std::fprintf(stderr, "refine_stress: seed %ld step %d: %s\n", seed, step, what);
  std::fflush(stderr);
  std::_Exit(3);
}

// Conforming: every leaf face is shared by two leaves or lies on the box boundary, no leaf edge
// carries a midpoint, green elements are leaves, leaves have positive measure summing to the box.
template <int D>
void validate(const Hierarchy<D>& h, const std::array<double, D>& lo, const std::array<double, D>& hi,
              long seed, int step, std::size_t nv_before = 0) {
  using T = SimplexTraits<D>;
  const auto leaves = h.leaves();
  long double vol = 0;
  for (ElemId e : leaves) {
    const double m = h.measure(e);
    if (!(m > 0)) fail("degenerate leaf", seed, step);
    vol += m;
    const auto& c = h.cell(e);
    for (int i = 0; i < T::kEdges; ++i)
      if (const VertexId m = h.edge_midpoints().find(c[T::kEdgeVerts[i][0]], c[T::kEdgeVerts[i][1]]);
          m.valid()) {
        const ElemId p = h.parent(e);
        std::fprintf(stderr,
                     "leaf %u kind %d level %d parent %u (kind %d, %d children), edge %d (%u,%u) mid %u "
                     "(%s, vertex levels %d %d -> %d)\n",
                     e.value, int(h.kind(e)), h.level(e), p.value, p.valid() ? int(h.kind(p)) : -1,
                     p.valid() ? h.num_children(p) : -1, i, c[T::kEdgeVerts[i][0]].value,
                     c[T::kEdgeVerts[i][1]].value, m.value, m.value >= nv_before ? "new" : "old",
                     h.vertex_level(c[T::kEdgeVerts[i][0]]), h.vertex_level(c[T::kEdgeVerts[i][1]]),
                     h.vertex_level(m));
        fail("hanging midpoint on a leaf edge", seed, step);
      }
  }
  for (std::size_t i = 0; i < h.element_count(); ++i)
    if (h.kind(ElemId(std::uint32_t(i))) == ElemKind::kGreen && !h.is_leaf(ElemId(std::uint32_t(i))))
      fail("green element with children", seed, step);
  double box = 1;
  for (int a = 0; a < D; ++a) box *= hi[a] - lo[a];
  if (std::abs(double(vol) - box) > 1e-9 * box) fail("leaves do not tile the box", seed, step);
  const auto nb = h.face_neighbors(leaves);
  for (std::size_t i = 0; i < leaves.size(); ++i) {
    const auto& c = h.cell(leaves[i]);
    for (int f = 0; f <= D; ++f) {
      if (nb[i][f] >= 0) {
        if (nb[nb[i][f]][0] != std::int32_t(i) && nb[nb[i][f]][1] != std::int32_t(i) &&
            nb[nb[i][f]][2] != std::int32_t(i) && (D == 2 || nb[nb[i][f]][D] != std::int32_t(i)))
          fail("face neighbours not symmetric", seed, step);
        continue;
      }
      bool on_boundary = false;
      for (int a = 0; a < D; ++a) {
        bool all_lo = true, all_hi = true;
        for (int j = 0; j <= D; ++j) {
          if (j == f) continue;
          all_lo &= h.point(c[j])[a] == lo[a];
          all_hi &= h.point(c[j])[a] == hi[a];
        }
        on_boundary |= all_lo || all_hi;
      }
      if (!on_boundary) fail("interior face with one leaf: nonconforming", seed, step);
    }
  }
}

template <int D>
std::array<double, D> centroid(const Hierarchy<D>& h, ElemId e) {
  std::array<double, D> x{};
  for (VertexId v : h.cell(e))
    for (int a = 0; a < D; ++a) x[a] += h.point(v)[a] / (D + 1);
  return x;
}

// One marking of the current leaves; the strategy is drawn from rng.
template <int D>
std::vector<ElemId> draw_marking(const Hierarchy<D>& h, std::mt19937_64& rng, const std::array<double, D>& lo,
                                 const std::array<double, D>& hi, int& strategy) {
  const auto leaves = h.leaves();
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  std::vector<ElemId> out;
  strategy = int(rng() % 6);
  auto rand_point = [&] {
    std::array<double, D> x;
    for (int a = 0; a < D; ++a) x[a] = lo[a] + (hi[a] - lo[a]) * u01(rng);
    return x;
  };
  auto dist = [](const std::array<double, D>& x, const std::array<double, D>& y) {
    double s = 0;
    for (int a = 0; a < D; ++a) s += (x[a] - y[a]) * (x[a] - y[a]);
    return std::sqrt(s);
  };
  switch (strategy) {
    case 0: {  // random subset, density from sparse to dense
      const double p = std::pow(u01(rng), 3.0);
      for (ElemId e : leaves)
        if (u01(rng) < p) out.push_back(e);
      break;
    }
    case 1: {  // a few local clusters: balls around random points
      const int n = 1 + int(rng() % 4);
      for (int k = 0; k < n; ++k) {
        const auto x = rand_point();
        const double r = 0.02 + 0.2 * u01(rng);
        for (ElemId e : leaves)
          if (dist(centroid(h, e), x) < r) out.push_back(e);
      }
      break;
    }
    case 2: {  // green leaves only (each red-refines its parent)
      const double p = u01(rng);
      for (ElemId e : leaves)
        if (h.kind(e) == ElemKind::kGreen && u01(rng) < p) out.push_back(e);
      break;
    }
    case 3: {  // leaves cut by a random plane
      std::array<double, D> n;
      double len = 0;
      for (int a = 0; a < D; ++a) {
        n[a] = u01(rng) - 0.5;
        len += n[a] * n[a];
      }
      len = std::sqrt(len) + 1e-300;
      const auto x = rand_point();
      for (ElemId e : leaves) {
        double smin = 1e300, smax = -1e300;
        for (VertexId v : h.cell(e)) {
          double s = 0;
          for (int a = 0; a < D; ++a) s += (h.point(v)[a] - x[a]) * n[a] / len;
          smin = std::min(smin, s);
          smax = std::max(smax, s);
        }
        if (smin <= 0 && smax >= 0) out.push_back(e);
      }
      break;
    }
    case 4: {  // leaves cut by a sphere
      const auto x = rand_point();
      const double r = 0.05 + 0.5 * u01(rng);
      for (ElemId e : leaves) {
        double dmin = 1e300, dmax = 0;
        for (VertexId v : h.cell(e)) {
          const double d = dist(h.point(v), x);
          dmin = std::min(dmin, d);
          dmax = std::max(dmax, d);
        }
        if (dmin <= r && dmax >= r) out.push_back(e);
      }
      break;
    }
    default: {  // mixture: sparse random + green leaves near a point + one cluster
      const double p = 0.05 * u01(rng);
      const auto x = rand_point();
      const double r = 0.3 * u01(rng);
      for (ElemId e : leaves) {
        const bool near = dist(centroid(h, e), x) < r;
        if (u01(rng) < p || (near && h.kind(e) == ElemKind::kGreen) || (near && u01(rng) < 0.3))
          out.push_back(e);
      }
      break;
    }
  }
  std::shuffle(out.begin(), out.end(), rng);  // order must not matter
  return out;
}

template <int D>
void run_case(long seed, const Options& opt) {
  std::mt19937_64 rng(std::uint64_t(seed) * 0x9E3779B97F4A7C15ULL + D);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  std::array<double, D> lo{}, hi{};
  for (int a = 0; a < D; ++a) hi[a] = 1.0 + 0.5 * a * 0.3;
  Hierarchy<D> h = Hierarchy<D>::box(lo, hi);
  // Start coarse or from a few uniform refinements (a few hundred to a few 10^4 leaves).
  const int drawn = int(rng() % (D == 3 ? 4 : 6));
  const int uniform = opt.uniform >= 0 ? opt.uniform : drawn;
  for (int i = 0; i < uniform; ++i) h.refine_uniform();
  validate<D>(h, lo, hi, seed, -1);
  for (int step = 0; step < opt.steps; ++step) {
    int strategy = 0;
    std::vector<ElemId> marked = draw_marking<D>(h, rng, lo, hi, strategy);
    const std::size_t leaves_before = h.leaves().size();
    std::size_t limit = 0;
    if (rng() % 4 == 0 && opt.limits) limit = h.vertex_count() + 1 + rng() % (4 * marked.size() + 8);
    if (opt.verbose)
      std::fprintf(stderr, "  dim %d seed %ld step %d: strategy %d, %zu of %zu leaves, limit %zu\n", D, seed,
                   step, strategy, marked.size(), leaves_before, limit);
    const std::size_t nv = h.vertex_count(), ne = h.element_count(), nm = h.edge_midpoints().size();
    std::size_t reached = 0;
    const auto map = h.refine(marked, limit, &reached);
    if (opt.verbose && limit > 0)
      std::fprintf(stderr, "    reached %zu%s\n", reached, map.empty() ? " (rolled back)" : "");
    if (limit > 0 && map.empty() && !marked.empty()) {
      if (h.vertex_count() != nv || h.element_count() != ne || h.edge_midpoints().size() != nm)
        fail("rollback changed the hierarchy", seed, step);
      if (reached <= limit) fail("rolled back below the limit", seed, step);
    }
    if (opt.validate) validate<D>(h, lo, hi, seed, step, nv);
    if (h.leaves().size() > opt.max_leaves) break;
  }
  if (opt.summary)
    std::fprintf(stderr,
                 "case dim %d seed %ld: %zu leaves, %zu vertices, level %d, conforming after every call\n", D,
                 seed, h.leaves().size(), h.vertex_count(), h.max_level());
}

// Runs one case in a forked child; returns true when it passed.
bool run_forked(int dim, long seed, const Options& opt) {
  std::fflush(stdout);
  std::fflush(stderr);
  const pid_t pid = fork();
  if (pid < 0) {
    std::perror("fork");
    std::exit(2);
  }
  if (pid == 0) {
    if (dim == 2)
      run_case<2>(seed, opt);
    else
      run_case<3>(seed, opt);
    std::fflush(stderr);
    std::_Exit(0);
  }
  int status = 0;
  waitpid(pid, &status, 0);
  if (WIFEXITED(status) && WEXITSTATUS(status) == 0) return true;
  std::fprintf(stderr, "FAILED: dim %d seed %ld (%s %d)\n", dim, seed,
               WIFSIGNALED(status) ? "signal" : "exit",
               WIFSIGNALED(status) ? WTERMSIG(status) : WEXITSTATUS(status));
  return false;
}

// Looks for the smallest failing case: the box, a few uniform steps, then a few refine()
// calls each marking 1-3 leaves (positions in leaves()); prints the first failing sequence
// with the fewest leaves. Runs in-process (a failure here is a nonconforming result, checked
// before the next call could abort).
template <int D>
bool conforming(const Hierarchy<D>& h) {
  using T = SimplexTraits<D>;
  for (ElemId e : h.leaves()) {
    const auto& c = h.cell(e);
    for (int i = 0; i < T::kEdges; ++i)
      if (h.edge_midpoints().find(c[T::kEdgeVerts[i][0]], c[T::kEdgeVerts[i][1]]).valid()) return false;
  }
  return true;
}

template <int D>
void search_small(long seeds, int uniform, int calls) {
  std::size_t best = ~std::size_t(0);
  for (long seed = 1; seed <= seeds; ++seed) {
    std::mt19937_64 rng{std::uint64_t(seed)};
    std::array<double, D> lo{}, hi{};
    for (int a = 0; a < D; ++a) hi[a] = 1.0;
    Hierarchy<D> h = Hierarchy<D>::box(lo, hi);
    for (int i = 0; i < uniform; ++i) h.refine_uniform();
    std::string log;
    for (int k = 0; k < calls; ++k) {
      const auto leaves = h.leaves();
      std::vector<ElemId> marked;
      const int n = 1 + int(rng() % 3);
      log += " [";
      for (int j = 0; j < n; ++j) {
        const std::size_t i = rng() % leaves.size();
        marked.push_back(leaves[i]);
        log += std::to_string(i) + (h.kind(leaves[i]) == ElemKind::kGreen ? "g " : " ");
      }
      log += "]";
      h.refine(marked);
      if (!conforming(h)) {
        if (h.leaves().size() < best) {
          best = h.leaves().size();
          std::printf("seed %ld: nonconforming after %d calls, %zu leaves:%s\n", seed, k + 1, best,
                      log.c_str());
          std::fflush(stdout);
        }
        break;
      }
    }
  }
}

// Replays "i,j;k;..." (positions in leaves() per refine() call) on the unit box and reports
// whether each result is conforming.
bool replay(const std::string& seq) {
  Hierarchy<3> h = Hierarchy<3>::box({0, 0, 0}, {1, 1, 1});
  std::size_t pos = 0;
  int call = 0;
  while (pos <= seq.size()) {
    const std::size_t end = std::min(seq.find(';', pos), seq.size());
    const std::string part = seq.substr(pos, end - pos);
    const auto leaves = h.leaves();
    std::vector<ElemId> marked;
    std::size_t q = 0;
    while (q < part.size()) {
      const std::size_t c = std::min(part.find(',', q), part.size());
      marked.push_back(leaves.at(std::stoul(part.substr(q, c - q))));
      q = c + 1;
    }
    const std::size_t nv = h.vertex_count();
    if (std::getenv("REPLAY_DEBUG")) {
      std::printf("before call %d: marked", call + 1);
      for (ElemId e : marked)
        std::printf(" %u(kind %d, parent %u)", e.value, int(h.kind(e)), h.parent(e).value);
      std::printf("\n");
      for (std::uint32_t e = 0; e < h.coarse_count(); ++e) {
        std::printf("  coarse %u: [%u %u %u %u] children %d kind %d:", e, h.cell(ElemId(e))[0].value,
                    h.cell(ElemId(e))[1].value, h.cell(ElemId(e))[2].value, h.cell(ElemId(e))[3].value,
                    h.num_children(ElemId(e)),
                    h.num_children(ElemId(e)) ? int(h.kind(h.first_child(ElemId(e)))) : -1);
        for (int k = 0; k < h.num_children(ElemId(e)); ++k) {
          const auto& c = h.cell(ElemId(h.first_child(ElemId(e)).value + k));
          std::printf(" [%u %u %u %u]%s", c[0].value, c[1].value, c[2].value, c[3].value,
                      h.is_leaf(ElemId(h.first_child(ElemId(e)).value + k)) ? "" : "*");
        }
        std::printf("\n");
      }
    }
    h.refine(marked);
    ++call;
    std::printf("call %d: %zu leaves, %zu vertices%s\n", call, h.leaves().size(), h.vertex_count(),
                conforming(h) ? "" : " NONCONFORMING");
    if (!conforming(h) && end == seq.size()) validate<3>(h, {0, 0, 0}, {1, 1, 1}, 0, call, nv);
    pos = end + 1;
  }
  return conforming(h);
}

// Exhaustive: every sequence of `calls` refine() calls marking one leaf each (box start);
// the last call may mark two leaves. Prints the failing sequences with the fewest leaves.
void exhaustive(int calls, bool pair_last) {
  std::size_t best = ~std::size_t(0);
  std::vector<std::size_t> idx;
  const auto rec = [&](auto&& self, const Hierarchy<3>& h, int k, std::string log) -> void {
    const auto leaves = h.leaves();
    for (std::size_t i = 0; i < leaves.size(); ++i) {
      const std::size_t jmax = (pair_last && k + 1 == calls) ? leaves.size() : i + 1;
      for (std::size_t j = i; j < jmax; ++j) {
        Hierarchy<3> g = h;
        std::vector<ElemId> m{leaves[i]};
        std::string l = log + (log.empty() ? "" : ";") + std::to_string(i);
        if (j != i) {
          m.push_back(leaves[j]);
          l += "," + std::to_string(j);
        }
        g.refine(m);
        if (!conforming(g)) {
          if (g.leaves().size() <= best) {
            best = g.leaves().size();
            std::printf("%s: %zu leaves\n", l.c_str(), best);
            std::fflush(stdout);
          }
          continue;
        }
        if (k + 1 < calls) self(self, g, k + 1, l);
      }
    }
  };
  rec(rec, Hierarchy<3>::box({0, 0, 0}, {1, 1, 1}), 0, "");
}

}  // namespace

int main(int argc, char** argv) {
  Options opt;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&] { return i + 1 < argc ? std::string(argv[++i]) : std::string(); };
    if (a == "--dim")
      opt.dim = std::stoi(next());
    else if (a == "--seeds")
      opt.seeds = std::stol(next());
    else if (a == "--first")
      opt.first = std::stol(next());
    else if (a == "--max-leaves")
      opt.max_leaves = std::stoull(next());
    else if (a == "--steps")
      opt.steps = std::stoi(next());
    else if (a == "--verbose")
      opt.verbose = true;
    else if (a == "--no-limits")
      opt.limits = false;
    else if (a == "--uniform")
      opt.uniform = std::stoi(next());
    else if (a == "--summary")
      opt.summary = true;
    else if (a == "--no-validate")
      opt.validate = false;
    else if (a == "--search-small") {
      const long seeds = std::stol(next());
      const int uniform = std::stoi(next());
      const int calls = std::stoi(next());
      search_small<3>(seeds, uniform, calls);
      return 0;
    } else if (a == "--exhaustive") {
      const int calls = std::stoi(next());
      exhaustive(calls, next() == "pair");
      return 0;
    } else if (a == "--replay") {
      return replay(next()) ? 0 : 1;
    } else if (a == "--case") {
      const int dim = std::stoi(next());
      const long seed = std::stol(next());
      opt.verbose = true;
      if (dim == 2)
        run_case<2>(seed, opt);
      else
        run_case<3>(seed, opt);
      std::printf("ok\n");
      return 0;
    } else {
      std::fprintf(stderr, "unknown argument %s\n", a.c_str());
      return 2;
    }
  }
  const auto t0 = std::chrono::steady_clock::now();
  long cases = 0, failed = 0;
  for (long s = opt.first; s < opt.first + opt.seeds; ++s)
    for (int dim = 2; dim <= 3; ++dim) {
      if (opt.dim != 0 && opt.dim != dim) continue;
      ++cases;
      if (!run_forked(dim, s, opt)) ++failed;
    }
  const double sec = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("refine_stress: %ld cases, %ld failed, max-leaves %zu, steps %d, %.1f s\n", cases, failed,
              opt.max_leaves, opt.steps, sec);
  return failed ? 1 : 0;
}
