// The samples' lattice and least squares at the samples; see sample_lattice.h.
#include <mlfe/core/check.h>
#include <mlfe/core/error.h>
#include <mlfe/core/sample_lattice.h>

#include <algorithm>
#include <cmath>
#include <string>

namespace mlfe {

namespace {

using I64 = std::int64_t;

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

template <int D>
ElementIntegrals<D> sample_integrals(const std::array<std::array<double, D>, D + 1>& p,
                                     const SampleLattice& lat, const ScalarGrid& grid, const Field& f,
                                     bool gradients) {
  ElementIntegrals<D> out;
  out.sampled = true;
  const auto c = index_corners<D>(p, lat);
  const Numerators<D> num = numerators<D>(c);
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
  std::array<double, D + 1> inv;
  for (int i = 0; i <= D; ++i) inv[i] = 1.0 / double(num.at_corner[i]);
  const double w = lat.sample_weight;
  float fmin = 0, fmax = 0;
  bool any = false;
  const I64 nx = lat.dims[0], ny = lat.dims[1];
  for (I64 z = lo[2]; z <= hi[2]; ++z)
    for (I64 y = lo[1]; y <= hi[1]; ++y)
      for (I64 x = lo[0]; x <= hi[0]; ++x) {
        const I64 q[3] = {x, y, z};
        std::array<int, D> s;
        for (int a = 0; a < D; ++a) s[a] = q[a] == lat.dims[a] - 1 ? -1 : 1;
        std::array<I64, D + 1> nn;
        bool inside = true;
        for (int i = 0; i <= D && inside; ++i) {
          I64 v = num.k[i];
          for (int a = 0; a < D; ++a) v += num.n[i][a] * q[a];
          nn[i] = v;
          inside = v > 0 || (v == 0 && pushed_inside<D>(num.n[i], s));
        }
        if (!inside) continue;
        const float fv = grid.values[static_cast<std::size_t>(x + nx * (y + ny * z))];
        const double fs = fv;
        std::array<double, D + 1> lam;
        for (int i = 0; i <= D; ++i) lam[i] = double(nn[i]) * inv[i];
        out.f2 += w * fs * fs;
        for (int i = 0, m = 0; i <= D; ++i) {
          out.fphi[i] += w * fs * lam[i];
          for (int j = i; j <= D; ++j) out.mass[static_cast<std::size_t>(m++)] += w * lam[i] * lam[j];
        }
        if (gradients) {
          std::array<double, 3> xl{0, 0, 0};
          for (int a = 0; a < D; ++a) xl[a] = double(q[a]) * lat.spacing[a];
          const auto g = f.gradient(xl);
          for (int a = 0; a < D; ++a) {
            out.grad[a] += w * g[a];
            out.grad2 += w * g[a] * g[a];
          }
        }
        if (!any || fv < fmin) fmin = fv;
        if (!any || fv > fmax) fmax = fv;
        any = true;
        ++out.points;
      }
  out.fmin = fmin;
  out.fmax = fmax;
  return out;
}

template ElementIntegrals<2> sample_integrals<2>(const std::array<std::array<double, 2>, 3>&,
                                                 const SampleLattice&, const ScalarGrid&, const Field&, bool);
template ElementIntegrals<3> sample_integrals<3>(const std::array<std::array<double, 3>, 4>&,
                                                 const SampleLattice&, const ScalarGrid&, const Field&, bool);
template bool outside_data<2>(const std::array<std::array<double, 2>, 3>&, const SampleLattice&);
template bool outside_data<3>(const std::array<std::array<double, 3>, 4>&, const SampleLattice&);

}  // namespace mlfe
