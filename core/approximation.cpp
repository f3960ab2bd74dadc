// Adaptive multilevel FE approximation (Grosso, Lürig & Ertl, IEEE Vis 1997); see
// approximation.h. Solvers: CG with the BPX preconditioner (Bramble, Pasciak & Xu 1990).
#include "core/approximation.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/SparseCholesky>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <numeric>

#include "core/bpx.h"
#include "core/check.h"
#include "core/fe_assembly.h"
#include "core/hierarchical_basis.h"
#include "core/p1_element.h"

namespace mlfe {

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

template <int D>
double gradient_weight(const Field& f, const ApproximationOptions& o) {
  return o.h1 ? f.resolution() * f.resolution() : 0.0;
}

// Sub-simplices up to 2 voxels in size (≥ 3 points per voxel). Measured against the voxel's
// cube-equivalent size, like the element sizes: against the smallest spacing, an anisotropic
// grid (the CT skull: 3.94 × 3.94 × 3.65 mm) got one subdivision more, 24 points per voxel.
double default_quadrature_edge(const Field& f, const ApproximationOptions& o) {
  return o.quadrature_edge > 0 ? o.quadrature_edge : 2.0 * f.voxel_size();
}

template <int D>
Vector solve_system(const Hierarchy<D>& h, const SparseMatrix& m, const Vector& rhs, const Vector& start,
                    const ApproximationOptions& opts, double gw, IterationStats& st) {
  const auto n = m.rows();
  if (opts.direct_solve_max > 0 && n <= opts.direct_solve_max) {
    Eigen::SparseMatrix<double> mc = m;  // column major for the factorization
    Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt(mc);
    MLFE_CHECK_MSG(ldlt.info() == Eigen::Success, "LDLT factorization failed");
    Vector x = ldlt.solve(rhs);
    st.cg_iterations = 0;
    st.cg_residual = 0;
    return x;
  }
  SparseOperator a(m);
  std::unique_ptr<LinearOperator> pre;
  switch (opts.preconditioner) {
    case Preconditioner::kBpx:
      pre = std::make_unique<BpxPreconditioner<D>>(h, gw);
      break;
    case Preconditioner::kJacobi:
      pre = std::make_unique<JacobiPreconditioner>(m);
      break;
    case Preconditioner::kNone:
      pre = std::make_unique<IdentityOperator>(n);
      break;
  }
  Vector x = start;
  const CgResult r = conjugate_gradient(a, *pre, rhs, x, opts.cg_tolerance, 5000);
  st.cg_iterations = r.iterations;
  st.cg_residual = r.relative_residual;
  return x;
}

// The iso-aware rule: for an element that an iso-surface crosses (in f or in u), the distance
// between the surfaces of f and u is about |f - u| / |∇u|; refine while that exceeds the
// tolerance, or while u misses a crossing that f has, until elements are voxel-sized.
template <int D>
bool surface_needs_refinement(const Hierarchy<D>& h, ElemId e, const ElementIntegrals<D>& in, const Vector& u,
                              double density, const Field& f, const ApproximationOptions& opts) {
  const double size = std::pow(h.measure(e) * (D == 2 ? 2.0 : 6.0), 1.0 / D);
  if (size <= f.resolution()) return false;
  const auto& c = h.cell(e);
  double umin = 1e300, umax = -1e300;
  for (VertexId v : c) {
    umin = std::min(umin, u[v.value]);
    umax = std::max(umax, u[v.value]);
  }
  std::array<std::array<double, D>, D + 1> p;
  for (int i = 0; i <= D; ++i) p[i] = h.point(c[i]);
  const P1Element<D> el(p);
  double g2 = 0;
  for (int k = 0; k < D; ++k) {
    double g = 0;
    for (int i = 0; i <= D; ++i) g += u[c[i].value] * el.grad[i][k];
    g2 += g * g;
  }
  const double rms = std::sqrt(density);
  for (double iso : opts.iso_values) {
    const bool f_cuts = in.fmin <= iso && iso <= in.fmax;
    const bool u_cuts = umin <= iso && iso <= umax;
    if (!f_cuts && !u_cuts) continue;
    if (f_cuts && !u_cuts) return true;  // u misses this piece of the surface
    if (rms > opts.surface_tolerance * f.resolution() * std::sqrt(g2)) return true;
  }
  return false;
}

}  // namespace

template <int D>
std::vector<double> solve_best_approximation(const Hierarchy<D>& h, const Field& f,
                                             const ApproximationOptions& opts,
                                             const std::vector<double>& warm, IterationStats* stats) {
  const double gw = gradient_weight<D>(f, opts);
  const double qedge = default_quadrature_edge(f, opts);
  const auto leaves = h.leaves();
  const auto integrals = compute_element_integrals(h, leaves, f, qedge, opts.h1);
  const SparseMatrix m = assemble_matrix(h, leaves, gw);
  const Vector rhs = assemble_load(h, leaves, integrals, gw);
  Vector start = Vector::Zero(rhs.size());
  if (warm.size() == h.vertex_count())
    for (std::size_t i = 0; i < warm.size(); ++i) start[i] = warm[i];
  IterationStats local;
  const Vector x = solve_system(h, m, rhs, start, opts, gw, stats ? *stats : local);
  return std::vector<double>(x.data(), x.data() + x.size());
}

template <int D>
Approximation<D> approximate(const Field& f, const ApproximationOptions& opts) {
  MLFE_CHECK(f.dim() == D);
  const auto t0 = Clock::now();
  Approximation<D> out;
  typename Hierarchy<D>::Point lo, hi;
  const auto ext = f.extent();
  for (int a = 0; a < D; ++a) {
    lo[a] = 0;
    hi[a] = ext[a];
  }
  out.hierarchy = Hierarchy<D>::box(lo, hi);
  Hierarchy<D>& h = out.hierarchy;
  out.domain_measure = 1;
  for (int a = 0; a < D; ++a) out.domain_measure *= ext[a];
  const auto range = f.range();
  out.value_min = range[0];
  out.value_max = range[1];
  const double value_span = range[1] > range[0] ? range[1] - range[0] : 1.0;
  const double gw = gradient_weight<D>(f, opts);
  const double qedge = default_quadrature_edge(f, opts);

  // Coarse elements of a big volume cannot represent anything: start where edges are ≤ 16
  // voxels (the hierarchy still begins at T0, so levels and the hierarchical basis keep it).
  int start_level = opts.start_level;
  if (start_level < 0) {
    double longest = 0;
    for (int a = 0; a < D; ++a) longest += ext[a] * ext[a];
    longest = std::sqrt(longest);
    start_level = 0;
    while (longest > 16 * f.resolution() && start_level < opts.max_level) {
      longest *= 0.5;
      ++start_level;
    }
  }
  for (int l = 0; l < start_level; ++l) {
    if (opts.max_vertices && h.vertex_count() * (1 << D) > opts.max_vertices) break;
    h.refine_uniform();
  }

  // Integrals cached per element id (valid for leaves); refinement remaps them.
  std::vector<ElementIntegrals<D>> cache;
  std::vector<std::uint8_t> have;
  std::vector<double> values;
  double vertices_per_mark = 2.0;  // a red refinement's 3 (2D) / 6 (3D) midpoints, shared

  for (int it = 0;; ++it) {
    IterationStats st;
    st.iteration = it;
    auto ta = Clock::now();
    const auto leaves = h.leaves();
    cache.resize(h.element_count());
    have.resize(h.element_count(), 0);
    {
      std::vector<ElemId> todo;
      for (ElemId e : leaves)
        if (!have[e.value]) todo.push_back(e);
      const auto fresh = compute_element_integrals(h, todo, f, qedge, opts.h1);
      for (std::size_t i = 0; i < todo.size(); ++i) {
        cache[todo[i].value] = fresh[i];
        have[todo[i].value] = 1;
      }
    }
    // Read in place (cache[leaves[i]]): a leaf-ordered copy would move ~100 bytes per leaf
    // every iteration.
    constexpr IntegralIndex kById = IntegralIndex::kElementId;
    const SparseMatrix m = assemble_matrix(h, leaves, gw);
    const Vector rhs = assemble_load(h, leaves, cache, gw, kById);
    st.assembly_seconds = since(ta);

    auto ts = Clock::now();
    if (values.empty())
      values.assign(h.vertex_count(), 0.0);
    else
      prolongate_to_new_vertices(h, values);  // warm start: u of the previous mesh, interpolated
    Vector start = Eigen::Map<const Vector>(values.data(), static_cast<Eigen::Index>(values.size()));
    const Vector x = solve_system(h, m, rhs, start, opts, gw, st);
    values.assign(x.data(), x.data() + x.size());
    st.solve_seconds = since(ts);

    auto te = Clock::now();
    const auto err = element_errors(h, leaves, cache, x, gw, kById);
    double total = 0;
    for (double e : err) total += e;  // sequential: deterministic
    st.level = h.max_level();
    st.vertices = h.vertex_count();
    st.elements = leaves.size();
    st.l2_error = std::sqrt(total);
    st.rms_error = std::sqrt(total / out.domain_measure);
    st.rms_percent = 100.0 * st.rms_error / value_span;
    st.psnr_db = st.rms_error > 0 ? 20.0 * std::log10(value_span / st.rms_error) : 999.0;

    // Marking.
    // Marks: with iso-values, elements the surfaces need come first (an asset's accuracy is
    // its surfaces'), then the worst absolute errors (most error removed per new vertex).
    struct Mark {
      bool surface;
      double e;
      ElemId id;
    };
    std::vector<Mark> marked;
    std::size_t surface_marks = 0;
    std::string stop;
    const bool target_met = opts.target_rms > 0 && st.rms_error <= opts.target_rms;
    {
      // Once the RMS target is met only the iso-aware rule (if any) still marks.
      const double tau2 = opts.target_rms > 0 && !target_met ? opts.target_rms * opts.target_rms : 0.0;
      const double thr2 = opts.threshold * opts.threshold;
      // Decided in parallel (bit 0: mark, bit 1: surface), collected in leaf order.
      std::vector<std::uint8_t> decision(leaves.size(), 0);
      tbb::parallel_for(tbb::blocked_range<std::size_t>(0, leaves.size(), 4096),
                        [&](const tbb::blocked_range<std::size_t>& r) {
                          for (std::size_t i = r.begin(); i != r.end(); ++i) {
                            const ElemId e = leaves[i];
                            if (h.level(e) >= opts.max_level) continue;
                            const double density = err[i] / h.measure(e);  // mean square error on T
                            bool mark = false;
                            if (opts.threshold > 0) mark |= density > thr2;
                            // Equidistribution: if no element's mean square error exceeds tau²,
                            // Σ E ≤ tau² |Ω|.
                            if (tau2 > 0) mark |= density > tau2;
                            const bool surface =
                                !opts.iso_values.empty() &&
                                surface_needs_refinement(h, e, cache[e.value], x, density, f, opts);
                            decision[i] = std::uint8_t((mark ? 1 : 0) | (surface ? 2 : 0));
                          }
                        });
      for (std::size_t i = 0; i < leaves.size(); ++i) {
        if (!decision[i]) continue;
        const bool surface = decision[i] & 2;
        marked.push_back({surface, err[i], leaves[i]});
        surface_marks += surface;
      }
      if (marked.empty())
        stop = target_met           ? "target RMS error reached"
               : opts.threshold > 0 ? "no element above the threshold"
                                    : "maximum level reached";
    }
    if (stop.empty() && it >= opts.max_iterations) stop = "iteration limit";
    if (stop.empty() && opts.max_vertices && h.vertex_count() >= opts.max_vertices) stop = "vertex budget";
    st.estimate_seconds = since(te);

    if (!stop.empty()) {
      st.seconds = since(t0);
      out.iterations.push_back(st);
      if (opts.progress) opts.progress(st);
      out.stop_reason = stop;
      out.leaf_errors = err;
      break;
    }

    // Refinement, within the vertex budget: worst elements first; if a refinement overshoots
    // the budget, undo it and try fewer. How many vertices a mark costs (its own midpoints,
    // shared with neighbours, plus what the closure upgrades to red) grows from about 2 on a
    // uniform mesh to 8-12 on a graded one; it is learned from the previous attempt, so an
    // iteration usually takes one attempt instead of halving its way down to the budget.
    auto tr = Clock::now();
    const std::size_t room = opts.max_vertices ? opts.max_vertices - h.vertex_count() : 0;
    const std::size_t cap =
        opts.max_vertices ? std::min(marked.size(),
                                     std::max<std::size_t>(
                                         1, static_cast<std::size_t>(0.9 * double(room) / vertices_per_mark)))
                          : marked.size();
    // A strict total order (ties by id), so selecting the prefix first and then sorting it gives
    // the same prefix as a full sort, in O(n + cap log cap) instead of O(n log cap).
    const auto worse_first = [](const Mark& a, const Mark& b) {
      if (a.surface != b.surface) return a.surface;
      return a.e != b.e ? a.e > b.e : a.id < b.id;
    };
    if (cap < marked.size())
      std::nth_element(marked.begin(), marked.begin() + cap, marked.end(), worse_first);
    std::sort(marked.begin(), marked.begin() + cap, worse_first);
    std::size_t count = cap;
    if (opts.target_rms > 0 && opts.threshold <= 0 && !target_met) {
      // Bulk criterion (Dörfler-like): refine only the worst elements that together carry
      // 60% of the excess error Σ E − τ²|Ω|, so the last step does not overshoot the target
      // by a whole level (noisy scans would otherwise double their vertex count for nothing).
      const double excess = total - opts.target_rms * opts.target_rms * out.domain_measure;
      double acc = 0;
      std::size_t k = 0;
      for (; k < std::min(surface_marks, cap); ++k) acc += marked[k].e;  // surfaces always go
      while (k < cap && acc < 0.6 * excess) acc += marked[k++].e;
      count = std::max<std::size_t>(k, 1);
    }
    // Within half a percent of the budget, further attempts would mostly be undone.
    if (opts.max_vertices && room < std::max<std::size_t>(8, opts.max_vertices / 200)) count = 0;
    std::vector<ElemId> remap;
    bool refined = false;
    while (count > 0) {
      const std::size_t before = h.vertex_count();
      std::vector<ElemId> sel;
      for (std::size_t i = 0; i < count; ++i) sel.push_back(marked[i].id);
      // An attempt over the budget is rolled back by refine() itself (no copy of h).
      std::size_t reached = 0;
      remap = h.refine(sel, opts.max_vertices, &reached);
      const std::size_t added = reached - before;
      vertices_per_mark = std::max(1.0, double(added) / double(count));
      if (!opts.max_vertices || reached <= opts.max_vertices) {
        refined = true;
        break;
      }
      // Overshot: scale the selection by the room over what this attempt added, with a
      // margin, so the next attempt nearly always fits.
      MLFE_CHECK(h.vertex_count() == before);
      const std::size_t scaled = static_cast<std::size_t>(double(count) * 0.9 * double(room) / double(added));
      count = std::min(count - 1, scaled);
    }
    st.marked = refined ? count : 0;
    st.refine_seconds = since(tr);
    st.seconds = since(t0);
    out.iterations.push_back(st);
    if (opts.progress) opts.progress(st);
    if (!refined) {
      // The budget does not allow even one more refinement: keep the last solution.
      out.stop_reason = "vertex budget";
      out.leaf_errors = err;
      break;
    }
    // In place: compaction only moves elements down (remap[i] <= i), so a forward pass never
    // overwrites an entry it still has to read.
    // Surviving old elements get the ids 0..kept-1 in order; everything after is new.
    std::size_t kept = 0;
    for (std::size_t i = 0; i < remap.size(); ++i) {
      if (!remap[i].valid()) continue;
      MLFE_CHECK(remap[i].value == kept);
      if (have[i]) cache[kept] = cache[i];
      have[kept++] = have[i];
    }
    std::fill(have.begin() + static_cast<std::ptrdiff_t>(kept), have.end(), 0);
  }
  out.values = std::move(values);
  return out;
}

template Approximation<2> approximate<2>(const Field&, const ApproximationOptions&);
template Approximation<3> approximate<3>(const Field&, const ApproximationOptions&);
template std::vector<double> solve_best_approximation<2>(const Hierarchy<2>&, const Field&,
                                                         const ApproximationOptions&,
                                                         const std::vector<double>&, IterationStats*);
template std::vector<double> solve_best_approximation<3>(const Hierarchy<3>&, const Field&,
                                                         const ApproximationOptions&,
                                                         const std::vector<double>&, IterationStats*);

}  // namespace mlfe
