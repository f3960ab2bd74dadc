// Marking for the adaptive approximation (Grosso, Lürig & Ertl, IEEE Vis 1997); see marking.h.
#include <mlfe/core/base/check.h>
#include <mlfe/core/fem/marking.h>
#include <mlfe/core/fem/p1_element.h>
#include <mlfe/core/fem/sample_lattice.h>
#include <mlfe/core/fem/surface_estimator.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

namespace mlfe {
namespace {

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

// (D!·|T|)^(1/D): the side of the cube D! copies of T would fill; a Kuhn simplex of a voxel has
// size one voxel.
template <int D>
double element_size(const Hierarchy<D>& h, ElemId e) {
  return D == 2 ? std::sqrt(h.measure(e) * 2.0) : std::cbrt(h.measure(e) * 6.0);
}

// Whether the data can have one of the iso-surfaces in e (range_in_box is conservative).
template <int D>
bool data_brackets(const Hierarchy<D>& h, ElemId e, const Field& f, const std::vector<double>& isos) {
  std::array<double, 3> lo{0, 0, 0}, hi{0, 0, 0};
  for (int a = 0; a < D; ++a) lo[a] = hi[a] = h.point(h.cell(e)[0])[a];
  for (VertexId v : h.cell(e))
    for (int a = 0; a < D; ++a) {
      lo[a] = std::min(lo[a], h.point(v)[a]);
      hi[a] = std::max(hi[a], h.point(v)[a]);
    }
  const auto r = f.range_in_box(lo, hi);
  for (double iso : isos)
    if (r[0] <= iso && iso <= r[1]) return true;
  return false;
}

// The surface-driven rule for leaf e and the linear function with nodal values `nodal` (f's
// interpolant while the mesh is built, u after a solve). Surfaces farther apart than the
// tolerance are refined down to elements of two voxels: below that, noise and voxel-scale
// detail would refine whole surfaces to the grid, and snapping puts the asset's vertices on
// the data's surface anyway. A piece of surface that the linear function misses altogether is
// refined down to one voxel, so small parts survive.
}  // namespace

template <int D, typename Values>
bool surface_gap_mark(const Hierarchy<D>& h, ElemId e, const Values& nodal, const Field& f,
                      const ApproximationOptions& opts, double tolerance_voxels, bool* candidate) {
  const double size = element_size(h, e), voxel = f.voxel_size();
  if (!refinable(h, e, opts.max_level) || size <= voxel) return false;
  std::array<double, D + 1> c;
  double cmin = 1e300, cmax = -1e300;
  for (int i = 0; i <= D; ++i) {
    c[i] = nodal[h.cell(e)[i].value];
    cmin = std::min(cmin, c[i]);
    cmax = std::max(cmax, c[i]);
  }
  bool linear_cuts = false;
  for (double iso : opts.iso_values) linear_cuts |= cmin <= iso && iso <= cmax;
  if (!linear_cuts && !data_brackets(h, e, f, opts.iso_values)) return false;
  if (candidate) *candidate = true;
  // Samples one voxel apart along the axes of a Kuhn simplex (its longest edge is the cube's
  // diagonal, √3 voxels per voxel): a feature of two voxels cannot fall between them.
  const bool coarse = size > 2.0 * voxel;
  const SurfaceGap gap = surface_gap<D>(h.corner_points(e), c, f, opts.iso_values, tolerance_voxels * voxel,
                                        std::sqrt(double(D)) * voxel, coarse);
  return gap == SurfaceGap::kMissing || (gap == SurfaceGap::kDistant && coarse);
}

template <int D>
std::vector<Mark> mark_leaves(const Hierarchy<D>& h, const std::vector<ElemId>& leaves,
                              const std::vector<double>& err, const std::vector<std::uint32_t>* samples,
                              const std::vector<ElementIntegrals<D>>* cache, const Vector& u, const Field& f,
                              const ApproximationOptions& opts, bool surface_driven, bool target_met,
                              std::size_t* surface_marks, const SampleLattice* lattice) {
  MLFE_CHECK(err.size() == leaves.size() && (!samples || samples->size() == leaves.size()));
  MLFE_CHECK(samples || cache);
  MLFE_CHECK(cache || surface_driven || opts.iso_values.empty());
  // Once the RMS target is met only the iso-aware rule (if any) still marks.
  const double tau2 = opts.target_rms > 0 && !target_met ? opts.target_rms * opts.target_rms : 0.0;
  const double thr2 = opts.threshold * opts.threshold;
  // Decided in parallel (bit 0: mark, bit 1: surface), collected in leaf order.
  std::vector<std::uint8_t> decision(leaves.size(), 0);
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, leaves.size(), 4096), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
          const ElemId e = leaves[i];
          if (!refinable(h, e, opts.max_level)) continue;
          // Padding holds no sample and is never refined (sample_lattice.h).
          if (lattice && outside_data<D>(h.corner_points(e), *lattice)) continue;
          // Mean square error on T: over its samples on the lattice.
          double density;
          if (samples)
            density = err[i] / (lattice->sample_weight * std::max<double>((*samples)[i], 1));
          else if (const auto& in = (*cache)[e.value]; in.sampled)
            density = err[i] / (lattice->sample_weight * std::max<double>(in.points, 1));
          else
            density = err[i] / h.measure(e);
          bool mark = false;
          if (opts.threshold > 0) mark |= density > thr2;
          // Equidistribution: if no element's mean square error exceeds tau²,
          // Σ E ≤ tau² |Ω|.
          if (tau2 > 0) mark |= density > tau2;
          const bool surface =
              !opts.iso_values.empty() &&
              // u smooths the noise that f's interpolant follows: it is held
              // to twice the tolerance (snapping moves vertices the rest).
              (surface_driven ? opts.check_surfaces_against_u &&
                                    surface_gap_mark(h, e, u, f, opts, 2 * opts.surface_tolerance)
                              : surface_needs_refinement(h, e, (*cache)[e.value], u, density, f, opts));
          decision[i] = std::uint8_t((mark ? 1 : 0) | (surface ? 2 : 0));
        }
      });
  // Counted first: growing by doubling held the old and the new array at once and copied them.
  std::vector<Mark> marked;
  marked.reserve(static_cast<std::size_t>(
      std::count_if(decision.begin(), decision.end(), [](std::uint8_t d) { return d != 0; })));
  *surface_marks = 0;
  for (std::size_t i = 0; i < leaves.size(); ++i) {
    if (!decision[i]) continue;
    const bool surface = decision[i] & 2;
    marked.push_back({err[i], leaves[i], surface});
    *surface_marks += surface;
  }
  return marked;
}

std::size_t rank_and_select(std::vector<Mark>& marks, std::size_t cap, std::size_t surface_marks,
                            double excess_error) {
  // A strict total order (ties by id), so selecting the prefix first and then sorting it gives
  // the same prefix as a full sort, in O(n + cap log cap) instead of O(n log cap).
  const auto worse_first = [](const Mark& a, const Mark& b) {
    if (a.surface != b.surface) return a.surface;
    return a.error != b.error ? a.error > b.error : a.id < b.id;
  };
  cap = std::min(cap, marks.size());
  if (cap < marks.size()) std::nth_element(marks.begin(), marks.begin() + cap, marks.end(), worse_first);
  std::sort(marks.begin(), marks.begin() + cap, worse_first);
  if (excess_error < 0) return cap;
  double acc = 0;
  std::size_t k = 0;
  for (; k < std::min(surface_marks, cap); ++k) acc += marks[k].error;  // surfaces always go
  while (k < cap && acc < 0.6 * excess_error) acc += marks[k++].error;
  return std::max<std::size_t>(k, 1);
}

template std::vector<Mark> mark_leaves<2>(const Hierarchy<2>&, const std::vector<ElemId>&,
                                          const std::vector<double>&, const std::vector<std::uint32_t>*,
                                          const std::vector<ElementIntegrals<2>>*, const Vector&,
                                          const Field&, const ApproximationOptions&, bool, bool, std::size_t*,
                                          const SampleLattice*);
template std::vector<Mark> mark_leaves<3>(const Hierarchy<3>&, const std::vector<ElemId>&,
                                          const std::vector<double>&, const std::vector<std::uint32_t>*,
                                          const std::vector<ElementIntegrals<3>>*, const Vector&,
                                          const Field&, const ApproximationOptions&, bool, bool, std::size_t*,
                                          const SampleLattice*);
template bool surface_gap_mark<2, Vector>(const Hierarchy<2>&, ElemId, const Vector&, const Field&,
                                          const ApproximationOptions&, double, bool*);
template bool surface_gap_mark<3, Vector>(const Hierarchy<3>&, ElemId, const Vector&, const Field&,
                                          const ApproximationOptions&, double, bool*);
template bool surface_gap_mark<2, std::vector<double>>(const Hierarchy<2>&, ElemId,
                                                       const std::vector<double>&, const Field&,
                                                       const ApproximationOptions&, double, bool*);
template bool surface_gap_mark<3, std::vector<double>>(const Hierarchy<3>&, ElemId,
                                                       const std::vector<double>&, const Field&,
                                                       const ApproximationOptions&, double, bool*);

}  // namespace mlfe
