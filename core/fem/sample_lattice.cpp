// The samples' lattice and least squares at the samples; see sample_lattice.h.
#include <mlfe/core/base/check.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/fem/sample_lattice.h>

#include <algorithm>
#include <cmath>
#include <string>

namespace mlfe {

namespace {

using I64 = std::int64_t;

// ⌊a / b⌋ for b > 0.
I64 floor_div(I64 a, I64 b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

// Corners in index space: lattice points, so integers (CHECKed: a corner off the lattice is a
// bug of T0 or of the refinement).
template <int D>
std::array<std::array<I64, D>, D + 1> index_corners(const std::array<std::array<double, D>, D + 1>& p,
                                                    const SampleLattice& lat) {
  std::array<std::array<I64, D>, D + 1> c;
  for (int i = 0; i <= D; ++i)
    for (int a = 0; a < D; ++a) {
      const double x = p[i][a] / lat.spacing[a];
      const double r = std::nearbyint(x);
      MLFE_CHECK_MSG(std::fabs(x - r) < 1e-6, "element corner off the samples' lattice");
      c[i][a] = static_cast<I64>(r);
    }
  return c;
}

// Barycentric numerators as affine functions of the sample index: N_i(x) = n_i · x + k_i with
// N_i(c_i) > 0 and N_i = 0 on the face opposite corner i; λ_i = N_i(x) / N_i(c_i).
template <int D>
struct Numerators {
  std::array<std::array<I64, D>, D + 1> n;
  std::array<I64, D + 1> k;
  std::array<I64, D + 1> at_corner;
};

template <int D>
Numerators<D> numerators(const std::array<std::array<I64, D>, D + 1>& c) {
  Numerators<D> out;
  for (int i = 0; i <= D; ++i) {
    // The face opposite i: corners f[0..D-1].
    std::array<int, D> f;
    for (int j = 0, m = 0; j <= D; ++j)
      if (j != i) f[static_cast<std::size_t>(m++)] = j;
    std::array<I64, D> nv;
    if constexpr (D == 2) {
      const I64 ex = c[f[1]][0] - c[f[0]][0], ey = c[f[1]][1] - c[f[0]][1];
      nv = {-ey, ex};
    } else {
      I64 a[3], b[3];
      for (int t = 0; t < 3; ++t) {
        a[t] = c[f[1]][t] - c[f[0]][t];
        b[t] = c[f[2]][t] - c[f[0]][t];
      }
      nv = {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
    }
    I64 k = 0;
    for (int a = 0; a < D; ++a) k -= nv[a] * c[f[0]][a];
    I64 at = k;
    for (int a = 0; a < D; ++a) at += nv[a] * c[i][a];
    MLFE_CHECK_MSG(at != 0, "degenerate element");
    if (at < 0) {
      for (int a = 0; a < D; ++a) nv[a] = -nv[a];
      k = -k;
      at = -at;
    }
    out.n[i] = nv;
    out.k[i] = k;
    out.at_corner[i] = at;
  }
  return out;
}

// Whether a sample with numerator N (= 0: on the face) belongs to the side of the face the
// numerator grows into, for the push direction (s0, s1 ε, s2 ε²): the sign of the first
// non-zero component of n ⊙ s decides (the direction is never parallel to a face).
template <int D>
bool pushed_inside(const std::array<I64, D>& n, const std::array<int, D>& s) {
  for (int a = 0; a < D; ++a) {
    const I64 d = n[a] * s[a];
    if (d != 0) return d > 0;
  }
  return false;
}

// An element's lattice corners, barycentric numerators and the numerators' reciprocals at the
// corners (λ_i = N_i · inv_i).
template <int D>
struct LatticeSimplex {
  std::array<std::array<I64, D>, D + 1> c;
  Numerators<D> num;
  std::array<double, D + 1> inv;
};

template <int D>
LatticeSimplex<D> lattice_simplex(const std::array<std::array<double, D>, D + 1>& p,
                                  const SampleLattice& lat) {
  LatticeSimplex<D> s;
  s.c = index_corners<D>(p, lat);
  s.num = numerators<D>(s.c);
  for (int i = 0; i <= D; ++i) s.inv[i] = 1.0 / double(s.num.at_corner[i]);
  return s;
}

// A sample's index in the grid's values (x fastest).
inline std::size_t linear_index(const std::array<I64, 3>& q, const SampleLattice& lat) {
  return static_cast<std::size_t>(q[0] + lat.dims[0] * (q[1] + lat.dims[1] * q[2]));
}

}  // namespace

std::array<double, 3> SampleLattice::data_extent() const {
  std::array<double, 3> e{0, 0, 0};
  for (int a = 0; a < dim; ++a) e[a] = double(dims[a] - 1) * spacing[a];
  return e;
}

std::array<double, 3> SampleLattice::box_extent() const {
  std::array<double, 3> e{0, 0, 0};
  for (int a = 0; a < dim; ++a) e[a] = double(width) * spacing[a];
  return e;
}

SampleLattice sample_lattice(const ScalarGrid& grid) {
  SampleLattice lat;
  lat.dim = grid.dim;
  if (grid.dim != 2 && grid.dim != 3) throw Error(grid.source + ": the grid must be 2D or 3D");
  I64 longest = 1;
  lat.sample_weight = 1;
  for (int a = 0; a < grid.dim; ++a) {
    if (grid.dims[a] < 2)
      throw Error(grid.source + ": every axis needs at least 2 samples (axis " + std::to_string(a) + " has " +
                  std::to_string(grid.dims[a]) + ")");
    if (grid.dims[a] > (I64(1) << 24))
      throw Error(grid.source + ": more than 2^24 samples along axis " + std::to_string(a));
    lat.dims[a] = grid.dims[a];
    lat.spacing[a] = grid.transform.spacing[a];
    lat.sample_weight *= grid.transform.spacing[a];
    longest = std::max(longest, grid.dims[a] - 1);
  }
  while (lat.width < longest) {
    lat.width *= 2;
    ++lat.level;
  }
  return lat;
}

SampleLattice sample_lattice(int dim, const std::array<std::int64_t, 3>& dims,
                             const std::array<double, 3>& spacing, int level) {
  MLFE_CHECK((dim == 2 || dim == 3) && level >= 0 && level < 62);
  SampleLattice lat;
  lat.dim = dim;
  lat.dims = dims;
  lat.level = level;
  lat.width = std::int64_t(1) << level;
  lat.sample_weight = 1;
  for (int a = 0; a < 3; ++a) {
    lat.spacing[a] = spacing[a];
    if (a < dim) lat.sample_weight *= spacing[a];
  }
  return lat;
}

template <int D>
bool outside_data(const std::array<std::array<double, D>, D + 1>& p, const SampleLattice& lat) {
  const auto ext = lat.data_extent();
  for (int a = 0; a < D; ++a) {
    double lo = p[0][a];
    for (int i = 1; i <= D; ++i) lo = std::min(lo, p[i][a]);
    // Corners are lattice points: lo is at least half a sample away from ext unless equal.
    if (lo >= ext[a] - 0.5 * lat.spacing[a]) return true;
  }
  return false;
}

namespace {

// Calls visit(q, nn) for every sample the element with lattice corners c owns (sample_lattice.h:
// the exact integer rule), nn being the barycentric numerators; visit returns false to stop.
template <int D, class Visit>
void for_each_owned_sample(const std::array<std::array<I64, D>, D + 1>& c, const Numerators<D>& num,
                           const SampleLattice& lat, Visit&& visit) {
  std::array<I64, 3> lo{0, 0, 0}, hi{0, 0, 0};
  for (int a = 0; a < D; ++a) {
    lo[a] = hi[a] = c[0][a];
    for (int i = 1; i <= D; ++i) {
      lo[a] = std::min(lo[a], c[i][a]);
      hi[a] = std::max(hi[a], c[i][a]);
    }
    lo[a] = std::max<I64>(lo[a], 0);
    hi[a] = std::min<I64>(hi[a], lat.dims[a] - 1);
  }
  // Row by row: the samples of a row (fixed y, z) inside the closed simplex form one interval
  // of x, found from the D + 1 face inequalities; only samples on a face (a numerator 0) need
  // the push rule.
  for (I64 z = lo[2]; z <= hi[2]; ++z)
    for (I64 y = lo[1]; y <= hi[1]; ++y) {
      const I64 q12[3] = {0, y, z};
      I64 xa = lo[0], xb = hi[0];
      std::array<I64, D + 1> r;
      for (int i = 0; i <= D; ++i) {
        I64 v = num.k[i];
        for (int a = 1; a < D; ++a) v += num.n[i][a] * q12[a];
        r[i] = v;
        const I64 cx = num.n[i][0];  // N_i(x) = cx x + v >= 0
        if (cx > 0) {
          xa = std::max(xa, floor_div(-v + cx - 1, cx));
        } else if (cx < 0) {
          xb = std::min(xb, floor_div(v, -cx));
        } else if (v < 0) {
          xb = xa - 1;
        }
      }
      for (I64 x = xa; x <= xb; ++x) {
        const std::array<I64, 3> q{x, y, z};
        std::array<I64, D + 1> nn;
        bool tie = false;
        for (int i = 0; i <= D; ++i) {
          nn[i] = r[i] + num.n[i][0] * x;
          tie |= nn[i] == 0;
        }
        if (tie) {
          std::array<int, D> s;
          for (int a = 0; a < D; ++a) s[a] = q[a] == lat.dims[a] - 1 ? -1 : 1;
          bool inside = true;
          for (int i = 0; i <= D && inside; ++i)
            inside = nn[i] > 0 || (nn[i] == 0 && pushed_inside<D>(num.n[i], s));
          if (!inside) continue;
        }
        if (!visit(q, nn)) return;
      }
    }
}

}  // namespace

template <int D>
ElementIntegrals<D> sample_integrals(const std::array<std::array<double, D>, D + 1>& p,
                                     const SampleLattice& lat, const ScalarGrid& grid, const Field& f,
                                     ElementGradients<D>* gradients) {
  ElementIntegrals<D> out;
  ElementGradients<D> gs;
  out.sampled = true;
  const LatticeSimplex<D> t = lattice_simplex<D>(p, lat);
  const auto& inv = t.inv;
  const double w = lat.sample_weight;
  float fmin = 0, fmax = 0;
  bool any = false;
  for_each_owned_sample<D>(t.c, t.num, lat,
                           [&](const std::array<I64, 3>& q, const std::array<I64, D + 1>& nn) {
                             const float fv = grid.values[linear_index(q, lat)];
                             const double fs = fv;
                             std::array<double, D + 1> lam;
                             for (int i = 0; i <= D; ++i) lam[i] = double(nn[i]) * inv[i];
                             add_sample_terms<D>(w, fs, lam, out.f2, out.fphi, out.mass);
                             if (gradients) {
                               std::array<double, 3> xl{0, 0, 0};
                               for (int a = 0; a < D; ++a) xl[a] = double(q[a]) * lat.spacing[a];
                               const auto g = f.gradient(xl);
                               for (int a = 0; a < D; ++a) {
                                 gs.grad[a] += w * g[a];
                                 gs.grad2 += w * g[a] * g[a];
                               }
                             }
                             if (!any || fv < fmin) fmin = fv;
                             if (!any || fv > fmax) fmax = fv;
                             any = true;
                             ++out.points;
                             return true;
                           });
  out.fmin = fmin;
  out.fmax = fmax;
  if (gradients) *gradients = gs;
  return out;
}

template <int D>
void owned_samples(const std::array<std::array<double, D>, D + 1>& p, const SampleLattice& lat,
                   std::vector<OwnedSample<D>>& out) {
  out.clear();
  const LatticeSimplex<D> t = lattice_simplex<D>(p, lat);
  for_each_owned_sample<D>(t.c, t.num, lat,
                           [&](const std::array<I64, 3>& q, const std::array<I64, D + 1>& nn) {
                             OwnedSample<D> s;
                             s.index = static_cast<std::int64_t>(linear_index(q, lat));
                             for (int i = 0; i <= D; ++i) s.lambda[i] = double(nn[i]) * t.inv[i];
                             out.push_back(s);
                             return true;
                           });
}

template <int D>
SampleDeviation sample_deviation(const std::array<std::array<double, D>, D + 1>& p, const SampleLattice& lat,
                                 const ScalarGrid& grid, const std::array<double, D + 1>& v, double stop) {
  SampleDeviation out;
  const LatticeSimplex<D> t = lattice_simplex<D>(p, lat);
  const auto& inv = t.inv;
  for_each_owned_sample<D>(t.c, t.num, lat,
                           [&](const std::array<I64, 3>& q, const std::array<I64, D + 1>& nn) {
                             const double fs = grid.values[linear_index(q, lat)];
                             // Relative to corner 0, so a flat element interpolates its value bit for bit,
                             // and at a corner (λ exactly a unit vector) the interpolant is that corner's
                             // value.
                             double u = v[0];
                             for (int i = 1; i <= D; ++i)
                               if (nn[i] != 0) u += double(nn[i]) * inv[i] * (v[i] - v[0]);
                             const double d = std::fabs(fs - u);
                             out.max = std::max(out.max, d);
                             out.sum2 += d * d;
                             ++out.samples;
                             return !(out.max > stop);
                           });
  return out;
}

template <int D>
std::vector<ElemId> leaves_in_data(Hierarchy<D>& h, std::vector<double>& values, const SampleLattice& lat) {
  MLFE_CHECK(values.empty() || values.size() == h.vertex_count());
  const auto ext = lat.data_extent();
  auto corners = [&](ElemId e) {
    std::array<std::array<double, D>, D + 1> p;
    for (int i = 0; i <= D; ++i) p[i] = h.point(h.cell(e)[i]);
    return p;
  };
  for (;;) {
    std::vector<ElemId> inside, straddling;
    for (ElemId e : h.leaves()) {
      const auto p = corners(e);
      if (outside_data<D>(p, lat)) continue;
      bool across = false;
      for (int i = 0; i <= D; ++i)
        for (int a = 0; a < D; ++a) across |= p[i][a] > ext[a] + 0.25 * lat.spacing[a];
      (across ? straddling : inside).push_back(e);
    }
    if (straddling.empty()) return inside;
    const std::size_t before = h.vertex_count();
    h.refine(std::move(straddling));
    if (values.empty()) continue;
    values.resize(h.vertex_count());
    for (std::size_t v = before; v < values.size(); ++v) {
      const auto& par = h.vertex_parents(VertexId(static_cast<std::uint32_t>(v)));
      values[v] = 0.5 * (values[par[0].value] + values[par[1].value]);
    }
  }
}

template std::vector<ElemId> leaves_in_data<2>(Hierarchy<2>&, std::vector<double>&, const SampleLattice&);
template std::vector<ElemId> leaves_in_data<3>(Hierarchy<3>&, std::vector<double>&, const SampleLattice&);
template ElementIntegrals<2> sample_integrals<2>(const std::array<std::array<double, 2>, 3>&,
                                                 const SampleLattice&, const ScalarGrid&, const Field&,
                                                 ElementGradients<2>*);
template ElementIntegrals<3> sample_integrals<3>(const std::array<std::array<double, 3>, 4>&,
                                                 const SampleLattice&, const ScalarGrid&, const Field&,
                                                 ElementGradients<3>*);
template void owned_samples<2>(const std::array<std::array<double, 2>, 3>&, const SampleLattice&,
                               std::vector<OwnedSample<2>>&);
template void owned_samples<3>(const std::array<std::array<double, 3>, 4>&, const SampleLattice&,
                               std::vector<OwnedSample<3>>&);
template SampleDeviation sample_deviation<2>(const std::array<std::array<double, 2>, 3>&,
                                             const SampleLattice&, const ScalarGrid&,
                                             const std::array<double, 3>&, double);
template SampleDeviation sample_deviation<3>(const std::array<std::array<double, 3>, 4>&,
                                             const SampleLattice&, const ScalarGrid&,
                                             const std::array<double, 4>&, double);
template bool outside_data<2>(const std::array<std::array<double, 2>, 3>&, const SampleLattice&);
template bool outside_data<3>(const std::array<std::array<double, 3>, 4>&, const SampleLattice&);

}  // namespace mlfe
