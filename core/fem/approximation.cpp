// Adaptive multilevel FE approximation (Grosso, Lürig & Ertl, IEEE Vis 1997); see
// approximation.h. Solvers: CG with the BPX preconditioner (Bramble, Pasciak & Xu 1990).
#include <mlfe/core/base/check.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/base/huge_pages.h>
#include <mlfe/core/fem/approximation.h>
#include <mlfe/core/fem/bpx.h>
#include <mlfe/core/fem/fe_assembly.h>
#include <mlfe/core/fem/hierarchical_basis.h>
#include <mlfe/core/fem/marking.h>
#include <mlfe/core/fem/p1_element.h>
#include <mlfe/core/fem/sampled_least_squares.h>
#include <mlfe/core/fem/surface_estimator.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/SparseCholesky>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <memory>
#include <new>
#include <numeric>

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
                    const ApproximationOptions& opts, double gw, IterationStats& st, bool sampled) {
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
  Preconditioner which = opts.preconditioner;
  if (which == Preconditioner::kAuto)
    which = sampled && gw == 0 ? Preconditioner::kJacobi : Preconditioner::kBpx;
  switch (which) {
    case Preconditioner::kAuto:
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

// f at x, read from the sample itself when x is a sample's position (interpolation would add
// rounding of the order of 1e-16 and break exactness at the samples).
double sample_or_value(const ScalarGrid& g, const Field& f, const std::array<double, 3>& x) {
  std::int64_t idx[3] = {0, 0, 0};
  for (int a = 0; a < g.dim; ++a) {
    const double t = x[a] / g.transform.spacing[a];
    const double r = std::nearbyint(t);
    if (!(std::fabs(t - r) < 1e-6) || r < 0 || r > double(g.dims[a] - 1)) return f.value(x);
    idx[a] = static_cast<std::int64_t>(r);
  }
  return g.at(idx[0], idx[1], idx[2]);
}

// Vertices beyond the data's box (the padding, sample_lattice.h) see few samples or none:
// their rows of the sampled mass are tiny or zero. A weight of kPaddingWeight samples pulling
// each toward f there (the data clamped to its box) makes them determined without moving
// u at the samples measurably.
constexpr double kPaddingWeight = 0.01;

// The padding's weight per vertex: kPaddingWeight samples for vertices beyond the data's box,
// 0 elsewhere.
template <int D>
std::vector<double> padding_weights(const Hierarchy<D>& h, const SampleLattice& lat) {
  const auto ext = lat.data_extent();
  const double w = kPaddingWeight * lat.sample_weight;
  std::vector<double> pad(h.vertex_count(), 0.0);
  for (std::size_t v = 0; v < h.vertex_count(); ++v) {
    const auto& p = h.point(VertexId(static_cast<std::uint32_t>(v)));
    bool outside = false;
    for (int a = 0; a < D; ++a) outside |= p[a] > ext[a] + 0.25 * lat.spacing[a];
    if (outside) pad[v] = w;
  }
  return pad;
}

// The padding's pull toward f (the data clamped to its box) in the load.
template <int D>
void add_padding_load(const Hierarchy<D>& h, const Field& f, const std::vector<double>& pad, Vector& rhs) {
  for (std::size_t v = 0; v < pad.size(); ++v) {
    if (pad[v] == 0) continue;
    std::array<double, 3> q{0, 0, 0};
    for (int a = 0; a < D; ++a) q[a] = h.point(VertexId(static_cast<std::uint32_t>(v)))[a];
    rhs[static_cast<Eigen::Index>(v)] += pad[v] * f.value(q);
  }
}

template <int D>
void regularize_padding(const Hierarchy<D>& h, const Field& f, const SampleLattice& lat, SparseMatrix& m,
                        Vector& rhs) {
  const std::vector<double> pad = padding_weights(h, lat);
  for (std::size_t v = 0; v < pad.size(); ++v)
    if (pad[v] != 0) m.coeffRef(static_cast<Eigen::Index>(v), static_cast<Eigen::Index>(v)) += pad[v];
  add_padding_load(h, f, pad, rhs);
}

std::vector<double> to_std(const Vector& x) { return std::vector<double>(x.data(), x.data() + x.size()); }

// The vertices some sample sees: a positive diagonal of the sampled mass on some leaf.
template <int D>
std::vector<std::uint8_t> seen_by_integrals(const Hierarchy<D>& h, const std::vector<ElemId>& leaves,
                                            const std::vector<ElementIntegrals<D>>& integrals,
                                            IntegralIndex index) {
  std::vector<std::uint8_t> seen(h.vertex_count(), 0);
  for (std::size_t i = 0; i < leaves.size(); ++i) {
    const auto& in = integrals[index == IntegralIndex::kLeafOrder ? i : leaves[i].value];
    const auto& c = h.cell(leaves[i]);
    for (int a = 0; a <= D; ++a)
      if (in.mass_at(a, a) > 0) seen[c[a].value] = 1;
  }
  return seen;
}

// Values of the vertices that no sample sees (padding, sample_lattice.h): they change u at no
// sample, so they get the value their parents predict (a zero surplus, nothing to store), T0's
// the field's value there (clamped to the data).
template <int D>
void fill_unseen(const Hierarchy<D>& h, const Field& f, const std::vector<std::uint8_t>& seen,
                 std::vector<double>& x) {
  for (std::size_t v = 0; v < x.size(); ++v) {
    if (seen[v]) continue;
    const auto& p = h.vertex_parents(VertexId(static_cast<std::uint32_t>(v)));
    if (p[0].valid()) {
      x[v] = 0.5 * (x[p[0].value] + x[p[1].value]);
    } else {
      std::array<double, 3> q{0, 0, 0};
      for (int a = 0; a < D; ++a) q[a] = h.point(VertexId(static_cast<std::uint32_t>(v)))[a];
      x[v] = f.value(q);
    }
  }
}

// Peak bytes per leaf and per vertex of the interpolating build (max_sample_error), which
// holds no integrals, matrix or solver vectors: the hierarchy, and in `mlfe build` the file's
// rebuild of it (which now replaces it instead of sitting beside it, so the figures below keep
// a further margin). Measured (since the encoder keeps no hash sets): 5.1 GB peak
// RSS for the noisy full head's lossless file (7.18 M vertices, 42.7 M leaves), about 300 B
// per vertex and 70 per leaf; 100 per leaf keeps a margin. (160, from a run with the hash
// sets, stopped that lossless build at the default budget with less than half of it used.)
constexpr double kInterpolatingBytesPerLeaf = 100, kInterpolatingBytesPerVertex = 300;
// The same for least squares applied from the samples (SampledSystem): the hierarchy, the
// per-leaf errors, sample counts and marks, and the samples' own 32 bytes counted per leaf
// (about two leaves per sample at a full head's noise level); per vertex the CG vectors. The
// noisy full head's default build peaks at 1.40 GB (13.7 M leaves, 2.3 M vertices; 1.85 GB
// before session 18's releases), which this puts at 2.0 GB: a margin for the allocator.
constexpr double kSampledBytesPerLeaf = 100, kSampledBytesPerVertex = 280;

// The largest vertex count a refinement may reach: max_vertices, and what max_memory_bytes
// allows at the current ratio of leaves to vertices (0: no limit). *by_memory tells which binds.
template <int D>
std::size_t vertex_limit(const ApproximationOptions& opts, std::size_t vertices, std::size_t leaves,
                         bool* by_memory, bool sampled = false) {
  std::size_t limit = opts.max_vertices;
  *by_memory = false;
  if (opts.max_memory_bytes > 0) {
    // Leaves per vertex grow while a mesh is graded toward surfaces (5.5-6.5 in 3D): a quarter
    // on top of today's ratio keeps a pass from overshooting the budget.
    const double ratio =
        1.25 * std::max(double(leaves) / double(std::max<std::size_t>(1, vertices)), D == 3 ? 5.0 : 2.0);
    const double per_vertex =
        opts.max_sample_error >= 0 ? kInterpolatingBytesPerLeaf * ratio + kInterpolatingBytesPerVertex
        : sampled                  ? kSampledBytesPerLeaf * ratio + kSampledBytesPerVertex
                  : double(estimated_memory_bytes(D, 1000, std::size_t(1000 * ratio))) / 1000.0;
    const auto mem = static_cast<std::size_t>(double(opts.max_memory_bytes) / per_vertex);
    if (limit == 0 || mem < limit) {
      limit = std::max<std::size_t>(mem, 1);
      *by_memory = true;
    }
  }
  return limit;
}

// Refines the first `count` of `marks` (in priority order); a refinement that would pass
// `limit` vertices is undone by refine() and tried again with fewer marks, scaled by the room
// over what the attempt added. Returns refine()'s remap, or an empty vector when not even one
// mark fits (count is then 0). vertices_per_mark learns what a mark costs.
template <int D>
std::vector<ElemId> refine_within(Hierarchy<D>& h, const std::vector<ElemId>& marks, std::size_t& count,
                                  std::size_t limit, double& vertices_per_mark) {
  const std::size_t room = limit ? limit - std::min(limit, h.vertex_count()) : 0;
  while (count > 0) {
    const std::size_t before = h.vertex_count();
    std::vector<ElemId> sel(marks.begin(), marks.begin() + static_cast<std::ptrdiff_t>(count));
    std::size_t reached = 0;
    auto remap = h.refine(sel, limit, &reached);
    const std::size_t added = reached - before;
    vertices_per_mark = std::max(1.0, double(added) / double(count));
    if (!limit || reached <= limit) return remap;
    MLFE_CHECK(h.vertex_count() == before);
    // (A mesh already over the limit, e.g. its uniform start, has no room: nothing fits.)
    const std::size_t scaled =
        added > 0 ? static_cast<std::size_t>(double(count) * 0.9 * double(room) / double(added)) : 0;
    count = std::min(count - 1, scaled);
  }
  return {};
}

// Before the first solve (surface_driven): passes over the leaves pick those whose data range
// brackets an iso-value, check the surface gap against f's interpolant (out.data_values), and
// refine every leaf over the tolerance at once. A leaf that passed keeps passing (its corners
// do not change), so each pass checks only the leaves the previous one created. Returns a stop
// reason when a budget ended it, else "".
template <int D>
std::string refine_toward_surfaces(Hierarchy<D>& h, const Field& f, const ApproximationOptions& opts,
                                   Clock::time_point t0, Approximation<D>& out,
                                   const SampleLattice* lattice) {
  std::vector<double>& fv = out.data_values;  // the interpolant's nodal values
  double vertices_per_mark = 2.0;
  // refine() keeps the old elements first: a pass checks only the elements from `fresh` on.
  std::size_t fresh = 0;
  for (;;) {
    sample_at_vertices(h, f, fv);
    // Pick the new leaves and check them (in parallel, each in its own slot).
    const std::size_t ne = h.element_count();
    std::vector<std::uint8_t> decision(ne - fresh, 0);  // bit 0: candidate, bit 1: mark
    tbb::parallel_for(
        tbb::blocked_range<std::size_t>(fresh, ne, 256), [&](const tbb::blocked_range<std::size_t>& r) {
          for (std::size_t i = r.begin(); i != r.end(); ++i) {
            const ElemId e(static_cast<std::uint32_t>(i));
            if (!h.is_leaf(e)) continue;
            if (lattice && outside_data<D>(h.corner_points(e), *lattice)) continue;  // padding
            bool candidate = false;
            const bool mark = surface_gap_mark(h, e, fv, f, opts, opts.surface_tolerance, &candidate);
            decision[i - fresh] = std::uint8_t((candidate ? 1 : 0) | (mark ? 2 : 0));
          }
        });
    SurfacePassStats st;
    std::vector<ElemId> marks;
    for (std::size_t i = fresh; i < ne; ++i) {
      st.candidates += decision[i - fresh] & 1;
      if (decision[i - fresh] & 2) marks.push_back(ElemId(static_cast<std::uint32_t>(i)));
    }
    const auto& nc = h.num_children_array();
    st.vertices = h.vertex_count();
    st.elements = static_cast<std::size_t>(std::count(nc.begin(), nc.end(), std::uint8_t(0)));
    st.marked = marks.size();
    // Refine, within the budgets.
    bool by_memory = false;
    const std::size_t limit = vertex_limit<D>(opts, h.vertex_count(), st.elements, &by_memory);
    std::size_t count = marks.size();
    std::vector<ElemId> remap;
    if (count > 0) remap = refine_within(h, marks, count, limit, vertices_per_mark);
    st.seconds = since(t0);
    out.surface_passes.push_back(st);
    if (opts.surface_progress) opts.surface_progress(st);
    if (marks.empty()) return "";
    if (count < marks.size()) {
      // A budget cut this pass short: later passes could only add what it refused.
      out.memory_limited = by_memory;
      return by_memory ? "memory budget" : "vertex budget";
    }
    // Survivors of the old elements are renumbered 0..kept-1; everything after is new.
    std::size_t kept = 0;
    for (ElemId r : remap) kept += r.valid();
    fresh = kept;
  }
}

// Whether every sample is an integer small enough for exact integer arithmetic on sums.
bool integer_samples(const ScalarGrid& g) {
  for (float v : g.values)
    if (!(std::fabs(v) <= 1073741824.0f) || v != std::nearbyint(v)) return false;
  return true;
}

// Values of the interpolating build at the vertices from values.size() on, in id order
// (parents first): the sample itself at a lattice point inside the data; in the padding the
// parents' prediction (a zero surplus: the file spends nothing on the padding), floored for
// integer data so the value stays an integer; T0's corners in the padding take the nearest
// sample (clamped index).
template <int D>
void interpolating_values(const Hierarchy<D>& h, const ScalarGrid& g, const SampleLattice& lat, bool integer,
                          std::vector<double>& values) {
  const std::size_t from = values.size();
  values.resize(h.vertex_count());
  for (std::size_t v = from; v < values.size(); ++v) {
    const VertexId id(static_cast<std::uint32_t>(v));
    std::int64_t idx[3] = {0, 0, 0};
    bool inside = true;
    for (int a = 0; a < D; ++a) {
      const double t = h.point(id)[a] / lat.spacing[a];
      idx[a] = static_cast<std::int64_t>(std::nearbyint(t));
      MLFE_CHECK_MSG(std::fabs(t - double(idx[a])) < 1e-6, "vertex off the samples' lattice");
      inside = inside && idx[a] >= 0 && idx[a] < lat.dims[a];
    }
    const auto& p = h.vertex_parents(id);
    if (!inside && p[0].valid()) {
      const double mean = 0.5 * (values[p[0].value] + values[p[1].value]);
      values[v] = integer ? std::floor(mean) : mean;
      continue;
    }
    for (int a = 0; a < D; ++a) idx[a] = std::clamp<std::int64_t>(idx[a], 0, lat.dims[a] - 1);
    values[v] = g.at(idx[0], idx[1], idx[2]);
  }
}

// Address space for a build's hierarchy up front, within the memory budget and at most
// `per_sample` elements per sample, so that refinement never copies its arrays as they grow
// (each reallocation held the old and the new arrays at once and copied them); untouched pages
// cost nothing. Returns the elements reserved, 0 when there is no budget or no address space
// to spare (strict overcommit: the arrays then grow as needed).
template <int D>
std::size_t reserve_hierarchy(std::size_t samples, const ApproximationOptions& opts, Hierarchy<D>& h,
                              std::size_t bytes_per_element, std::size_t per_sample) {
  if (opts.max_memory_bytes == 0) return 0;
  const std::size_t n = std::min(opts.max_memory_bytes / bytes_per_element, per_sample * samples);
  try {
    h.reserve(std::min(samples + samples / 4, n), n);  // a vertex per sample at most, padding aside
    return n;
  } catch (const std::bad_alloc&) {
    return 0;
  }
}

// The interpolating build (ApproximationOptions::max_sample_error): passes over the leaves
// refine every leaf owning a sample farther than the bound from the leaf's interpolant. A
// leaf's corner values never change once created, so a leaf that passed keeps passing and
// each pass checks only the leaves the previous one created. Fills out.values, the one
// statistics row and the stop reason.
template <int D>
void refine_to_sample_error(Hierarchy<D>& h, const ScalarGrid& g, const ApproximationOptions& opts,
                            Clock::time_point t0, Approximation<D>& out) {
  const SampleLattice& lat = out.lattice;
  const double bound = opts.max_sample_error;
  out.max_sample_error = bound;
  out.integer_values = integer_samples(g);
  std::vector<double>& values = out.values;
  // The interpolant's double arithmetic rounds by ~1e-16 of the values: a deviation below
  // 2^-40 of the largest sample is rounding, not error (at bound 0 a linear ramp would
  // otherwise refine to level L; any float32 output of the values rounds it away).
  double big = 1;
  for (float x : g.values) big = std::max(big, double(std::fabs(x)));
  const double slack = std::ldexp(big, -40);
  double vertices_per_mark = 2.0;
  std::size_t fresh = 0;
  std::string stop;
  // A lossless build of a noisy scan reaches 6 elements per sample.
  reserve_hierarchy(static_cast<std::size_t>(g.voxel_count()), opts, h,
                    sizeof(typename Hierarchy<D>::Cell) + 3 * sizeof(ElemId) + 3, 7);
  for (;;) {
    // Step 1: values of the new vertices, then the new leaves checked (each in its own slot).
    interpolating_values(h, g, lat, out.integer_values, values);
    const std::size_t ne = h.element_count();
    std::vector<std::uint8_t> over(ne - fresh, 0);
    tbb::parallel_for(
        tbb::blocked_range<std::size_t>(fresh, ne, 256), [&](const tbb::blocked_range<std::size_t>& r) {
          for (std::size_t i = r.begin(); i != r.end(); ++i) {
            const ElemId e(static_cast<std::uint32_t>(i));
            if (!h.is_leaf(e)) continue;
            // Red leaves of level L interpolate exactly (their samples are corners).
            if (h.kind(e) != ElemKind::kGreen && h.level(e) >= opts.max_level) continue;
            const auto p = h.corner_points(e);
            if (outside_data<D>(p, lat)) continue;  // padding: never refined
            std::array<double, D + 1> v;
            for (int k = 0; k <= D; ++k) v[k] = values[h.cell(e)[k].value];
            over[i - fresh] = sample_deviation<D>(p, lat, g, v, bound + slack).max > bound + slack;
          }
        });
    std::vector<ElemId> marks;
    for (std::size_t i = fresh; i < ne; ++i)
      if (over[i - fresh]) marks.push_back(ElemId(static_cast<std::uint32_t>(i)));
    if (marks.empty()) break;
    // Step 2: refine them all, within the budgets.
    const auto& nc = h.num_children_array();
    const auto leaves = static_cast<std::size_t>(std::count(nc.begin(), nc.end(), std::uint8_t(0)));
    bool by_memory = false;
    const std::size_t limit = vertex_limit<D>(opts, h.vertex_count(), leaves, &by_memory);
    std::size_t count = marks.size();
    const std::vector<ElemId> remap = refine_within(h, marks, count, limit, vertices_per_mark);
    if (count < marks.size()) {
      out.memory_limited = by_memory;
      stop = by_memory ? "memory budget" : "vertex budget";
      interpolating_values(h, g, lat, out.integer_values, values);
      break;
    }
    std::size_t kept = 0;
    for (ElemId r : remap) kept += r.valid();
    fresh = kept;
  }

  // Step 3: the errors at the samples, every sample counted once (by its owner).
  const std::vector<ElemId> leaves = h.leaves();
  std::vector<SampleDeviation> dev(leaves.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, leaves.size(), 256),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t i = r.begin(); i != r.end(); ++i) {
                        std::array<double, D + 1> v;
                        for (int k = 0; k <= D; ++k) v[k] = values[h.cell(leaves[i])[k].value];
                        dev[i] = sample_deviation<D>(h.corner_points(leaves[i]), lat, g, v,
                                                     std::numeric_limits<double>::infinity());
                      }
                    });
  double sum2 = 0, max = 0;
  for (const auto& d : dev) sum2 += d.sum2, max = std::max(max, d.max);  // sequential: deterministic
  IterationStats st;
  const double span = out.value_max > out.value_min ? out.value_max - out.value_min : 1.0;
  st.level = h.max_level();
  st.vertices = h.vertex_count();
  st.elements = leaves.size();
  st.rms_error = std::sqrt(sum2 / double(lat.samples()));
  st.l2_error = std::sqrt(sum2 * lat.sample_weight);
  st.rms_percent = 100.0 * st.rms_error / span;
  st.psnr_db = st.rms_error > 0 ? 20.0 * std::log10(span / st.rms_error) : 999.0;
  st.seconds = since(t0);
  out.iterations.push_back(st);
  if (opts.progress) opts.progress(st);
  if (stop.empty())
    stop = max <= bound + slack ? "every sample within the maximum error" : "maximum level reached";
  out.stop_reason = stop;
}

}  // namespace

std::size_t estimated_memory_bytes(int dim, std::size_t vertices, std::size_t leaves) {
  // Per leaf: element arrays (with ~15 % inner elements), cached integrals, the assembly's
  // incidence and corner tables, error and marking arrays. Per vertex: points, parents, edge
  // map, matrix rows, preconditioner and solver vectors, values. Calibrated on peak RSS of
  // 3D builds (bench/RESULTS.md), rounded up.
  // Least squares at the samples caches a sampled element mass too (+80 bytes per element).
  const double per_leaf = dim == 3 ? 300.0 : 220.0;
  const double per_vertex = dim == 3 ? 420.0 : 260.0;
  return static_cast<std::size_t>(per_leaf * double(leaves) + per_vertex * double(vertices));
}

template <int D>
std::vector<double> solve_best_approximation(const Hierarchy<D>& h, const Field& f,
                                             const ApproximationOptions& opts,
                                             const std::vector<double>& warm, IterationStats* stats,
                                             const SampleLattice* lattice) {
  const double gw = gradient_weight<D>(f, opts);
  const double qedge = default_quadrature_edge(f, opts);
  const auto leaves = h.leaves();
  std::vector<ElementGradients<D>> grads;
  const auto integrals = compute_element_integrals(h, leaves, f, qedge, opts.h1 ? &grads : nullptr, lattice);
  SparseMatrix m = assemble_matrix(h, leaves, gw, &integrals);
  Vector rhs = assemble_load(h, leaves, integrals, gw, IntegralIndex::kLeafOrder, &grads);
  if (lattice) regularize_padding(h, f, *lattice, m, rhs);
  Vector start = Vector::Zero(rhs.size());
  if (warm.size() == h.vertex_count())
    for (std::size_t i = 0; i < warm.size(); ++i) start[i] = warm[i];
  IterationStats local;
  std::vector<double> x =
      to_std(solve_system(h, m, rhs, start, opts, gw, stats ? *stats : local, lattice != nullptr));
  if (lattice) fill_unseen(h, f, seen_by_integrals(h, leaves, integrals, IntegralIndex::kLeafOrder), x);
  return x;
}

// Coarse elements of a big volume cannot represent anything: uniform refinement until edges
// are ≤ 16 voxels (the hierarchy still begins at T0, so levels and the hierarchical basis keep
// it). On the lattice: until T0's cube is cut into cubes 16 samples wide, padding left alone.
template <int D>
void refine_to_start_level(Hierarchy<D>& h, const Field& f, const ApproximationOptions& opts,
                           const Approximation<D>& out) {
  const auto ext = f.extent();
  int start_level = opts.start_level;
  if (start_level < 0 && out.on_lattice) {
    start_level = std::max(0, out.lattice.level - 4);
  } else if (start_level < 0) {
    double longest = 0;
    for (int a = 0; a < D; ++a) longest += ext[a] * ext[a];
    longest = std::sqrt(longest);
    start_level = 0;
    while (longest > 16 * f.resolution() && start_level < opts.max_level) {
      longest *= 0.5;
      ++start_level;
    }
  }
  start_level = std::min(start_level, opts.max_level);
  for (int l = 0; l < start_level; ++l) {
    if (opts.max_vertices && h.vertex_count() * (1 << D) > opts.max_vertices) break;
    if (!out.on_lattice) {
      h.refine_uniform();
      continue;
    }
    std::vector<ElemId> inside;
    for (ElemId e : h.leaves())
      if (!outside_data<D>(h.corner_points(e), out.lattice)) inside.push_back(e);
    h.refine(std::move(inside));
  }
}

// The integral cache's address space up front with the hierarchy's (reserve_hierarchy): its
// reallocations were the build's peak, and copying and zero-filling it took a fifth of a
// full-head build. At most 3 elements per sample (a full head at the noise level needs about
// 2.2); beyond that the vectors grow as usual.
template <int D>
void reserve_build_arrays(const Field& f, const ApproximationOptions& opts, Hierarchy<D>& h,
                          std::vector<ElementIntegrals<D>>& cache, std::vector<std::uint8_t>& have) {
  const ScalarGrid* grid = f.samples();
  if (!grid) return;
  const std::size_t n = reserve_hierarchy(static_cast<std::size_t>(grid->voxel_count()), opts, h,
                                          sizeof(ElementIntegrals<D>), 3);
  if (n == 0) return;
  try {
    cache.reserve(n);
    have.reserve(n);
    // Huge pages: a fault per 2 MB instead of per 4 KB as the arrays fill (faults were a
    // fifth of the build's profile on a VM).
    advise_huge_pages(cache);
    advise_huge_pages(have);
  } catch (const std::bad_alloc&) {
    // No address space to spare: grow as needed instead.
  }
}

// Writes zeros over v's storage from v.size() up to n elements, in parallel, when its capacity
// holds them. Before a resize(n) that value-initialises them in one thread: on fresh pages the
// kernel's zero-fill at each page's first touch was most of that resize (1.4 of 2.0 s of an
// iteration of colin27's build); this way all threads take a share, and resize() then writes
// pages already there.
template <class V>
void first_touch_in_parallel(V& v, std::size_t n) {
  if (n <= v.size() || n > v.capacity()) return;  // nothing new, or a reallocation anyway
  auto* bytes = reinterpret_cast<unsigned char*>(v.data());
  constexpr std::size_t kChunk = std::size_t(1) << 21;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(v.size() * sizeof(typename V::value_type),
                                                    n * sizeof(typename V::value_type), kChunk),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      std::memset(bytes + r.begin(), 0, r.end() - r.begin());
                    });
}

// The integrals of the leaves not cached yet (cache, grads and have are indexed by element id;
// grads, the H1 sums, only in H1).
template <int D>
void update_integral_cache(const Hierarchy<D>& h, const std::vector<ElemId>& leaves, const Field& f,
                           double qedge, const ApproximationOptions& opts, const SampleLattice* lattice,
                           std::vector<ElementIntegrals<D>>& cache, std::vector<ElementGradients<D>>& grads,
                           std::vector<std::uint8_t>& have) {
  first_touch_in_parallel(cache, h.element_count());
  cache.resize(h.element_count());
  if (opts.h1) grads.resize(h.element_count());
  have.resize(h.element_count(), 0);
  {
    std::vector<ElemId> todo;
    for (ElemId e : leaves)
      if (!have[e.value]) todo.push_back(e);
    // In place: a separate result would hold another ~140 bytes per new element at the peak.
    compute_element_integrals_into(h, todo, f, qedge, opts.h1 ? grads.data() : nullptr, lattice, cache.data(),
                                   IntegralIndex::kElementId);
    for (ElemId e : todo) have[e.value] = 1;
  }
}

// Why the refine-solve loop stops after iteration `it` ("" to go on): nothing marked (target
// reached, surfaces within tolerance, threshold, maximum level), the iteration limit, the vertex
// budget, the surface passes' own stop, the surface-driven check of u done, or a stall.
template <int D>
std::string loop_stop(const Hierarchy<D>& h, const ApproximationOptions& opts, const Approximation<D>& out,
                      const IterationStats& st, int it, bool marked_none, bool target_met,
                      bool surface_driven, const std::string& surface_stop, bool stall_checks) {
  std::string stop;
  if (marked_none)
    stop = target_met           ? "target RMS error reached"
           : surface_driven     ? (surface_stop.empty() ? "surfaces within tolerance" : surface_stop)
           : opts.threshold > 0 ? "no element above the threshold"
                                : "maximum level reached";
  if (stop.empty() && it >= opts.max_iterations) stop = "iteration limit";
  if (stop.empty() && opts.max_vertices && h.vertex_count() >= opts.max_vertices) stop = "vertex budget";
  if (stop.empty() && !surface_stop.empty()) stop = surface_stop;  // a budget ended the surface passes
  // The mesh was built around the data's surfaces before the first solve; u is checked
  // against them once, and what that refines is solved for and kept.
  if (stop.empty() && surface_driven && it >= 1 && opts.target_rms <= 0 && opts.threshold <= 0)
    stop = "surfaces built from the data, checked against u";
  // No stalled iterations: a refinement that added next to nothing ends the loop instead of
  // paying a full solve per handful of vertices.
  if (stop.empty() && stall_checks && it > 0) {
    const auto& prev = out.iterations.back();
    const double growth = double(st.vertices - prev.vertices) / double(prev.vertices);
    if (growth < opts.min_growth) {
      char buf[96];
      std::snprintf(buf, sizeof buf, "stalled: the last refinement added %.2f%% of the vertices",
                    100.0 * growth);
      stop = buf;
    }
  }
  return stop;
}

// The integral cache after refine(): compaction only moves elements down (remap[i] <= i), so a
// forward pass in place never overwrites an entry it still has to read; surviving old elements
// get the ids 0..kept-1 in order, everything after is new.
template <int D>
void remap_integral_cache(const std::vector<ElemId>& remap, std::vector<ElementIntegrals<D>>& cache,
                          std::vector<ElementGradients<D>>& grads, std::vector<std::uint8_t>& have) {
  std::size_t kept = 0;
  for (std::size_t i = 0; i < remap.size(); ++i) {
    if (!remap[i].valid()) continue;
    MLFE_CHECK(remap[i].value == kept);
    if (have[i]) cache[kept] = cache[i];
    if (have[i] && !grads.empty()) grads[kept] = grads[i];
    have[kept++] = have[i];
  }
  std::fill(have.begin() + static_cast<std::ptrdiff_t>(kept), have.end(), 0);
}

// Refinement within the vertex (or memory) budget: the worst marked elements first; if a
// refinement overshoots the budget, refine_within() undoes it and tries fewer. Returns
// refine()'s element remap; `count` is the number refined (0: the budget allows none, by_memory
// when the memory budget set it; budget_reached: a pass was cut by it). With an RMS target
// (excess ≥ 0), only as many as carry 60 % of the excess error are picked.
template <int D>
std::vector<ElemId> refine_worst(Hierarchy<D>& h, const ApproximationOptions& opts, std::size_t leaf_count,
                                 std::vector<Mark>& marked, std::size_t surface_marks, double excess,
                                 double& vertices_per_mark, std::size_t& count, bool& by_memory,
                                 bool& budget_reached, bool sampled) {
  const std::size_t limit = vertex_limit<D>(opts, h.vertex_count(), leaf_count, &by_memory, sampled);
  const std::size_t room = limit ? limit - std::min(limit, h.vertex_count()) : 0;
  const std::size_t cap =
      limit
          ? std::min(marked.size(), std::max<std::size_t>(
                                        1, static_cast<std::size_t>(0.9 * double(room) / vertices_per_mark)))
          : marked.size();
  count = rank_and_select(marked, cap, surface_marks, excess);
  // The first pass the budget cuts takes half of what fits and the next the rest, with a solve
  // between, so the last vertices go where the error is after the first half rather than all
  // where one solve ranked it (the full head at 225 657 vertices: 25.365 -> 25.378 dB at the
  // voxels, and its scalp reaches the samples' level: 33.5 -> 35.4 dB rendered).
  if (limit && excess >= 0 && opts.iso_values.empty() && count == cap && count < marked.size() &&
      !budget_reached) {
    budget_reached = true;
    count = std::max<std::size_t>(1, count / 2);
  }
  // Within half a percent of the budget, further attempts would mostly be undone.
  if (limit && room < std::max<std::size_t>(8, limit / 200)) count = 0;
  std::vector<ElemId> sel(count);
  for (std::size_t i = 0; i < count; ++i) sel[i] = marked[i].id;
  std::vector<Mark>().swap(marked);  // 16 bytes a mark, beside refine()'s peak
  // An attempt over the budget is rolled back by refine() itself (no copy of h).
  return refine_within(h, sel, count, limit, vertices_per_mark);
}

// The iteration's mesh and error figures from the leaves' squared errors; returns their sum.
template <int D>
double record_errors(IterationStats& st, const Hierarchy<D>& h, std::size_t leaf_count,
                     const std::vector<double>& err, double domain_measure, double value_span) {
  double total = 0;
  for (double e : err) total += e;  // sequential: deterministic
  st.level = h.max_level();
  st.vertices = h.vertex_count();
  st.elements = leaf_count;
  st.l2_error = std::sqrt(total);
  st.rms_error = std::sqrt(total / domain_measure);
  st.rms_percent = 100.0 * st.rms_error / value_span;
  st.psnr_db = st.rms_error > 0 ? 20.0 * std::log10(value_span / st.rms_error) : 999.0;
  return total;
}

// The start of an iteration's solve: the previous mesh's u interpolated (or, first, f's
// interpolant on a mesh built around the surfaces, else 0).
template <int D>
Vector start_values(const Hierarchy<D>& h, const Approximation<D>& out, bool surface_driven,
                    std::vector<double>& values) {
  if (values.empty() && surface_driven)
    values = out.data_values;  // f's interpolant is close to u on a mesh built around the surfaces
  else if (values.empty())
    values.assign(h.vertex_count(), 0.0);
  else
    prolongate_to_new_vertices(h, values);  // warm start: u of the previous mesh, interpolated
  return Eigen::Map<const Vector>(values.data(), static_cast<Eigen::Index>(values.size()));
}

// What one refine-solve iteration needs of the system, two ways. CachedSystem: the integrals of
// each leaf cached by element id, assembled into a sparse matrix (any field, H1, the iso-aware
// estimate, which reads f's range per leaf). SampledSystem: least squares at the samples in L2,
// applied from the samples (sampled_least_squares.h), no per-element sums and no matrix.
// Both: prepare() after the mesh changed, solve() from `values` (becomes u), errors() per
// leaf, refined() with refine()'s remap.
template <int D>
class CachedSystem {
 public:
  static constexpr bool kSampled = false;
  CachedSystem(Hierarchy<D>& h, const Field& f, const ApproximationOptions& opts,
               const SampleLattice* lattice)
      : f_(f),
        opts_(opts),
        lattice_(lattice),
        gw_(gradient_weight<D>(f, opts)),
        qedge_(default_quadrature_edge(f, opts)) {
    reserve_build_arrays(f, opts, h, cache_, have_);
  }

  void prepare(const Hierarchy<D>& h, const std::vector<ElemId>& leaves) {
    update_integral_cache(h, leaves, f_, qedge_, opts_, lattice_, cache_, grads_, have_);
    // Read in place (cache[leaves[i]]): a leaf-ordered copy would move ~100 bytes per leaf
    // every iteration.
    assemble_system(h, leaves, gw_, cache_, kById, workspace_, m_, rhs_, &grads_);
    if (lattice_) regularize_padding(h, f_, *lattice_, m_, rhs_);
  }

  Vector solve(const Hierarchy<D>& h, const std::vector<ElemId>& leaves, const Vector& start,
               std::vector<double>& values, IterationStats& st) {
    Vector x = solve_system(h, m_, rhs_, start, opts_, gw_, st, lattice_ != nullptr);
    values.assign(x.data(), x.data() + x.size());
    if (!lattice_) return x;
    fill_unseen(h, f_, seen_by_integrals(h, leaves, cache_, kById), values);
    return Eigen::Map<const Vector>(values.data(), static_cast<Eigen::Index>(values.size()));
  }

  void errors(const Hierarchy<D>& h, const std::vector<ElemId>& leaves, const Vector& x,
              std::vector<double>& err) const {
    err = element_errors(h, leaves, cache_, x, gw_, kById, &grads_);
  }

  const std::vector<std::uint32_t>* samples() const { return nullptr; }  // read from the cache
  const std::vector<ElementIntegrals<D>>* integrals() const { return &cache_; }
  void refining() {}
  void refined(const Hierarchy<D>&, std::vector<ElemId> remap) {
    remap_integral_cache(remap, cache_, grads_, have_);
  }

 private:
  static constexpr IntegralIndex kById = IntegralIndex::kElementId;
  const Field& f_;
  const ApproximationOptions& opts_;
  const SampleLattice* lattice_;
  const double gw_, qedge_;
  // Integrals cached per element id (valid for leaves); refinement remaps them.
  std::vector<ElementIntegrals<D>> cache_;
  std::vector<ElementGradients<D>> grads_;  // H1 only
  std::vector<std::uint8_t> have_;
  // The assembly's storage, reused from one iteration to the next (fe_assembly.h).
  AssemblyWorkspace workspace_;
  SparseMatrix m_;
  Vector rhs_;
};

// A preconditioner by vertex id applied to vectors in the sampled operator's order.
template <int D>
class InOperatorOrder final : public LinearOperator {
 public:
  InOperatorOrder(const SampledLeastSquares<D>& op, std::unique_ptr<LinearOperator> inner)
      : op_(op), inner_(std::move(inner)) {}
  Eigen::Index size() const override { return op_.size(); }
  void apply(const Vector& x, Vector& y) const override {
    std::vector<double> by_vertex;
    op_.from_operator_order(x, by_vertex);
    Vector out;
    inner_->apply(Eigen::Map<const Vector>(by_vertex.data(), x.size()), out);
    op_.to_operator_order(std::vector<double>(out.data(), out.data() + out.size()), y);
  }

 private:
  const SampledLeastSquares<D>& op_;
  std::unique_ptr<LinearOperator> inner_;
};

template <int D>
class SampledSystem {
 public:
  static constexpr bool kSampled = true;
  SampledSystem(Hierarchy<D>& h, const Field& f, const ApproximationOptions& opts,
                const SampleLattice& lattice)
      : f_(f), opts_(opts), lattice_(lattice), op_(lattice, *f.samples()) {
    // The hierarchy's address space up front, as CachedSystem's (the same cap per element).
    reserve_hierarchy(static_cast<std::size_t>(f.samples()->voxel_count()), opts, h,
                      sizeof(ElementIntegrals<D>), 3);
  }

  // The operator's vectors are in its own vertex order (sampled_least_squares.h); u, the
  // padding and the seen flags are by vertex id.
  void prepare(const Hierarchy<D>& h, const std::vector<ElemId>&) {
    const std::vector<double> pad = padding_weights(h, lattice_);
    op_.update(h, remap_, pad);
    std::vector<ElemId>().swap(remap_);  // 4 bytes an element, beside the next refine() and solve
    op_.load(rhs_, diagonal_);
    Vector pull = Vector::Zero(static_cast<Eigen::Index>(pad.size()));
    add_padding_load(h, f_, pad, pull);
    op_.to_operator_order(std::vector<double>(pull.data(), pull.data() + pull.size()), work_);
    rhs_ += work_;
    // Seen by a sample: a positive diagonal without the padding's weight.
    std::vector<double> diagonal;
    op_.from_operator_order(diagonal_, diagonal);
    seen_.assign(h.vertex_count(), 0);
    for (std::size_t v = 0; v < pad.size(); ++v) seen_[v] = diagonal[v] > pad[v];
  }

  Vector solve(const Hierarchy<D>& h, const std::vector<ElemId>&, const Vector&, std::vector<double>& values,
               IterationStats& st) {
    // Jacobi unless asked otherwise, as for the assembled sampled matrix (Preconditioner::kAuto).
    std::unique_ptr<LinearOperator> pre;
    if (opts_.preconditioner == Preconditioner::kBpx)
      pre = std::make_unique<InOperatorOrder<D>>(op_, std::make_unique<BpxPreconditioner<D>>(h, 0.0));
    else if (opts_.preconditioner == Preconditioner::kNone)
      pre = std::make_unique<IdentityOperator>(op_.size());
    else
      pre = std::make_unique<JacobiPreconditioner>(diagonal_);
    Vector x;
    op_.to_operator_order(values, x);  // the start (start_values)
    const CgResult r = conjugate_gradient(op_, *pre, rhs_, x, opts_.cg_tolerance, 5000);
    st.cg_iterations = r.iterations;
    st.cg_residual = r.relative_residual;
    op_.from_operator_order(x, values);
    fill_unseen(h, f_, seen_, values);
    return Eigen::Map<const Vector>(values.data(), static_cast<Eigen::Index>(values.size()));
  }

  void errors(const Hierarchy<D>&, const std::vector<ElemId>& leaves, const Vector& x,
              std::vector<double>& err) {
    // The solve is done: its right-hand side and diagonal go before the per-leaf arrays come
    // (prepare() loads them again).
    Vector().swap(rhs_);
    Vector().swap(diagonal_);
    op_.to_operator_order(x.data(), static_cast<std::size_t>(x.size()), work_);
    op_.leaf_errors(work_, leaves, err, samples_);
  }

  const std::vector<std::uint32_t>* samples() const { return &samples_; }
  const std::vector<ElementIntegrals<D>>* integrals() const { return nullptr; }
  // The per-leaf sample counts are the marking's; errors() counts them again after the next
  // solve.
  void refining() {
    std::vector<std::uint32_t>().swap(samples_);
    Vector().swap(work_);
  }
  void refined(const Hierarchy<D>&, std::vector<ElemId> remap) { remap_ = std::move(remap); }

 private:
  const Field& f_;
  const ApproximationOptions& opts_;
  const SampleLattice& lattice_;
  SampledLeastSquares<D> op_;
  std::vector<ElemId> remap_;     // refine()'s, for the next prepare()
  Vector rhs_, diagonal_, work_;  // in the operator's order
  std::vector<std::uint8_t> seen_;
  std::vector<std::uint32_t> samples_;  // per leaf, from errors()
};

// The refine-solve loop (Grosso, Lürig & Ertl, Sec. 3): prepare the system on the leaves,
// solve, estimate, mark, stop or refine the worst within the budget.
template <int D, class System>
void refine_solve(System& sys, Hierarchy<D>& h, const Field& f, const ApproximationOptions& opts,
                  Approximation<D>& out, const SampleLattice* lattice, bool surface_driven,
                  const std::string& surface_stop, Clock::time_point t0) {
  const double value_span = out.value_max > out.value_min ? out.value_max - out.value_min : 1.0;
  std::vector<double> values;
  double vertices_per_mark = 2.0;  // a red refinement's 3 (2D) / 6 (3D) midpoints, shared
  bool budget_reached = false;     // a pass was cut by the budget (refine_worst)
  // Iso-aware marking stalls (a handful of surface elements per full solve); the global rules
  // converge by themselves, and the paper's threshold rule runs to its end.
  const bool stall_checks = opts.min_growth > 0 && opts.threshold <= 0 && !opts.iso_values.empty();
  std::vector<double> err;
  for (int it = 0;; ++it) {
    IterationStats st;
    st.iteration = it;
    auto ta = Clock::now();
    auto leaves = h.leaves();
    sys.prepare(h, leaves);
    st.assembly_seconds = since(ta);

    auto ts = Clock::now();
    const Vector x = sys.solve(h, leaves, start_values(h, out, surface_driven, values), values, st);
    st.solve_seconds = since(ts);

    auto te = Clock::now();
    sys.errors(h, leaves, x, err);
    const double total = record_errors(st, h, leaves.size(), err, out.domain_measure, value_span);

    // Mark.
    const bool target_met = opts.target_rms > 0 && st.rms_error <= opts.target_rms;
    std::size_t surface_marks = 0;
    std::vector<Mark> marked = mark_leaves(h, leaves, err, sys.samples(), sys.integrals(), x, f, opts,
                                           surface_driven, target_met, &surface_marks, lattice);
    const std::string stop = loop_stop(h, opts, out, st, it, marked.empty(), target_met, surface_driven,
                                       surface_stop, stall_checks);
    st.estimate_seconds = since(te);

    if (!stop.empty()) {
      st.seconds = since(t0);
      out.iterations.push_back(st);
      if (opts.progress) opts.progress(st);
      out.stop_reason = stop;
      out.leaf_errors = std::move(err);
      break;
    }

    // Refinement, within the vertex budget: worst elements first; if a refinement overshoots
    // the budget, undo it and try fewer. How many vertices a mark costs (its own midpoints,
    // shared with neighbours, plus what the closure upgrades to red) grows from about 2 on a
    // uniform mesh to 8-12 on a graded one; it is learned from the previous attempt, so an
    // iteration usually takes one attempt instead of halving its way down to the budget.
    auto tr = Clock::now();
    // What the next solve computes again goes before refine() grows the mesh, whose peak it
    // would add to: the leaves, their errors and sample counts are 16 bytes a leaf (0.14 GB of
    // a full head's 1.7 GB peak).
    const std::size_t leaf_count = leaves.size();
    std::vector<ElemId>().swap(leaves);
    std::vector<double>().swap(err);
    sys.refining();
    // Rank and select: the worst `cap` first; with an RMS target, only as many as carry 60 %
    // of the excess error.
    const double excess = opts.target_rms > 0 && opts.threshold <= 0 && !target_met
                              ? total - opts.target_rms * opts.target_rms * out.domain_measure
                              : -1.0;
    bool by_memory = false;
    std::size_t count = 0;
    std::vector<ElemId> remap =
        refine_worst(h, opts, leaf_count, marked, surface_marks, excess, vertices_per_mark, count, by_memory,
                     budget_reached, System::kSampled);
    const bool refined = count > 0;
    st.marked = refined ? count : 0;
    st.refine_seconds = since(tr);
    st.seconds = since(t0);
    out.iterations.push_back(st);
    if (opts.progress) opts.progress(st);
    if (!refined) {
      // The budget does not allow even one more refinement: keep the last solution.
      out.memory_limited = by_memory;
      out.stop_reason = by_memory ? "memory budget" : "vertex budget";
      sys.errors(h, h.leaves(), x, err);  // released above; the mesh is the solve's
      out.leaf_errors = std::move(err);
      break;
    }
    sys.refined(h, std::move(remap));
  }
  out.values = std::move(values);
}

template <int D>
Approximation<D> approximate(const Field& f, const ApproximationOptions& opts_in) {
  if (f.dim() != D)
    throw Error("approximate<" + std::to_string(D) + ">: the field is " + std::to_string(f.dim()) + "D");
  const auto t0 = Clock::now();
  Approximation<D> out;
  ApproximationOptions opts = opts_in;
  // The samples' lattice (sample_lattice.h): T0 is a cube 2^L samples wide, level L's vertices
  // are the samples and nothing is refined below them.
  const ScalarGrid* grid = f.samples();
  out.on_lattice = opts.lattice && grid != nullptr;
  const SampleLattice* lattice = nullptr;
  typename Hierarchy<D>::Point lo, hi;
  const auto ext = f.extent();
  out.data_extent = ext;
  if (out.on_lattice) {
    out.lattice = sample_lattice(*grid);
    lattice = &out.lattice;
    opts.max_level = std::min(opts.max_level, out.lattice.level);
  }
  const bool interpolating = opts.max_sample_error >= 0;
  if (interpolating && (!out.on_lattice || !std::isfinite(opts.max_sample_error)))
    throw Error(
        "a maximum error at the samples needs a finite bound and gridded input on the samples' lattice");
  const auto box_ext = out.on_lattice ? out.lattice.box_extent() : ext;
  for (int a = 0; a < D; ++a) {
    lo[a] = 0;
    hi[a] = box_ext[a];
  }
  out.hierarchy = Hierarchy<D>::box(lo, hi);
  Hierarchy<D>& h = out.hierarchy;
  out.domain_measure = 1;
  for (int a = 0; a < D; ++a) out.domain_measure *= ext[a];
  if (out.on_lattice) out.domain_measure = double(out.lattice.samples()) * out.lattice.sample_weight;
  const auto range = f.range();
  out.value_min = range[0];
  out.value_max = range[1];

  // Coarse elements of a big volume cannot represent anything: start where edges are ≤ 16
  // voxels (the hierarchy still begins at T0, so levels and the hierarchical basis keep it).
  // On the lattice: where T0's cube is cut into cubes 16 samples wide, padding left alone.
  if (interpolating) {
    // Refinement from T0 where the samples need it: flat regions stay on coarse elements.
    refine_to_sample_error(h, *grid, opts, t0, out);
    return out;
  }
  refine_to_start_level(h, f, opts, out);
  const bool surface_driven = opts.surface_driven && !opts.iso_values.empty();
  std::string surface_stop;
  if (surface_driven) surface_stop = refine_toward_surfaces(h, f, opts, t0, out, lattice);
  if (surface_driven && !opts.solve) {
    out.values = out.data_values;
    out.stop_reason = surface_stop.empty() ? "surfaces within tolerance (u not solved)" : surface_stop;
    return out;
  }

  // Least squares at the samples in L2 without the iso-aware estimate (which reads f's range per
  // leaf from the integrals) is applied from the samples; everything else from the cache.
  if (lattice && !opts.h1 && opts.iso_values.empty()) {
    SampledSystem<D> sys(h, f, opts, *lattice);
    refine_solve(sys, h, f, opts, out, lattice, surface_driven, surface_stop, t0);
  } else {
    CachedSystem<D> sys(h, f, opts, lattice);
    refine_solve(sys, h, f, opts, out, lattice, surface_driven, surface_stop, t0);
  }
  if (surface_driven) sample_at_vertices(h, f, out.data_values);  // vertices the u check added
  return out;
}

template <int D>
void sample_at_vertices(const Hierarchy<D>& h, const Field& f, std::vector<double>& values) {
  const std::size_t from = std::min(values.size(), h.vertex_count());
  values.resize(h.vertex_count());
  const ScalarGrid* grid = f.samples();
  tbb::parallel_for(tbb::blocked_range<std::size_t>(from, values.size(), 4096),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t v = r.begin(); v != r.end(); ++v) {
                        std::array<double, 3> x{0, 0, 0};
                        for (int a = 0; a < D; ++a) x[a] = h.points()[v][a];
                        values[v] = grid ? sample_or_value(*grid, f, x) : f.value(x);
                      }
                    });
}

template Approximation<2> approximate<2>(const Field&, const ApproximationOptions&);
template void sample_at_vertices<2>(const Hierarchy<2>&, const Field&, std::vector<double>&);
template void sample_at_vertices<3>(const Hierarchy<3>&, const Field&, std::vector<double>&);
template Approximation<3> approximate<3>(const Field&, const ApproximationOptions&);
template std::vector<double> solve_best_approximation<2>(const Hierarchy<2>&, const Field&,
                                                         const ApproximationOptions&,
                                                         const std::vector<double>&, IterationStats*,
                                                         const SampleLattice*);
template std::vector<double> solve_best_approximation<3>(const Hierarchy<3>&, const Field&,
                                                         const ApproximationOptions&,
                                                         const std::vector<double>&, IterationStats*,
                                                         const SampleLattice*);

}  // namespace mlfe
