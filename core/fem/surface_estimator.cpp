// Surface gap of a linear element against the data; see surface_estimator.h.
#include <mlfe/core/base/check.h>
#include <mlfe/core/fem/p1_element.h>
#include <mlfe/core/fem/surface_estimator.h>

#include <algorithm>
#include <cmath>
#include <limits>

namespace mlfe {

template <int D>
SurfaceGap surface_gap(const std::array<std::array<double, D>, D + 1>& p,
                       const std::array<double, D + 1>& corner_values, const Field& f,
                       const std::vector<double>& iso_values, double tolerance, double sample_spacing,
                       bool stop_at_distant) {
  MLFE_CHECK(sample_spacing > 0);
  SurfaceGap result = SurfaceGap::kWithin;
  if (iso_values.empty()) return result;
  const P1Element<D> el(p);
  double g2 = 0;
  for (int c = 0; c < D; ++c) {
    double g = 0;
    for (int i = 0; i <= D; ++i) g += corner_values[i] * el.grad[i][c];
    g2 += g * g;
  }
  const double inv_grad = g2 > 0 ? 1.0 / std::sqrt(g2) : std::numeric_limits<double>::infinity();
  const double cmin = *std::min_element(corner_values.begin(), corner_values.end());
  const double cmax = *std::max_element(corner_values.begin(), corner_values.end());
  // One sample: f's value v and the linear function's l there. A sample on different sides of
  // an iso-value lies between the surfaces; ℓ without a surface here means f has a piece ℓ
  // misses. Returns true when the answer is final.
  const auto classify = [&](double v, double l) {
    for (double iso : iso_values) {
      if ((v > iso) == (l > iso)) continue;
      if (!(cmin <= iso && iso <= cmax)) {
        result = SurfaceGap::kMissing;
        return true;
      }
      if (std::abs(l - iso) * inv_grad > tolerance) {
        result = SurfaceGap::kDistant;
        if (stop_at_distant) return true;
      }
    }
    return false;
  };

  if (const ScalarGrid* g = f.samples(); g && g->dim == D) {
    // The grid's own samples inside the simplex (barycentrics ≥ −ε), read directly.
    std::array<std::int64_t, 3> i0{0, 0, 0}, i1{0, 0, 0};
    for (int c = 0; c < D; ++c) {
      double lo = p[0][c], hi = p[0][c];
      for (int i = 1; i <= D; ++i) {
        lo = std::min(lo, p[i][c]);
        hi = std::max(hi, p[i][c]);
      }
      const double sp = g->transform.spacing[c];
      i0[c] = std::max<std::int64_t>(0, static_cast<std::int64_t>(std::ceil(lo / sp - 1e-9)));
      i1[c] = std::min<std::int64_t>(g->dims[c] - 1, static_cast<std::int64_t>(std::floor(hi / sp + 1e-9)));
    }
    for (std::int64_t k = i0[2]; k <= i1[2]; ++k)
      for (std::int64_t j = i0[1]; j <= i1[1]; ++j)
        for (std::int64_t i = i0[0]; i <= i1[0]; ++i) {
          const std::int64_t idx[3] = {i, j, k};
          std::array<double, D + 1> lam;
          lam[0] = 1;
          for (int q = 1; q <= D; ++q) {
            double l = 0;
            for (int c = 0; c < D; ++c)
              l += el.grad[q][c] * (double(idx[c]) * g->transform.spacing[c] - p[0][c]);
            lam[q] = l;
            lam[0] -= l;
          }
          bool inside = true;
          for (double l : lam) inside &= l >= -1e-9;
          if (!inside) continue;
          double l = 0;
          for (int q = 0; q <= D; ++q) l += lam[q] * corner_values[q];
          if (classify(g->at(i, j, k), l)) return result;
        }
    return result;
  }

  // Other fields: the lattice points a/n (a ∈ N^(D+1), Σa = n) with n segments on the longest
  // edge, in batches through Field::values.
  double longest = 0;
  for (int i = 0; i <= D; ++i)
    for (int j = 0; j < i; ++j) {
      double l2 = 0;
      for (int c = 0; c < D; ++c) l2 += (p[i][c] - p[j][c]) * (p[i][c] - p[j][c]);
      longest = std::max(longest, std::sqrt(l2));
    }
  const int n = std::max(1, static_cast<int>(std::ceil(longest / sample_spacing)));
  constexpr std::size_t kBatch = 256;
  std::array<double, 3> x[kBatch];
  double lin[kBatch], fv[kBatch];
  std::size_t m = 0;
  const auto flush = [&]() {
    f.values(x, fv, m);
    for (std::size_t j = 0; j < m; ++j)
      if (classify(fv[j], lin[j])) return true;
    m = 0;
    return false;
  };
  // a_1..a_D with Σ ≤ n (a_3 = 0 in 2D); a_0 = n − Σ.
  std::array<int, 4> a{};
  for (a[1] = 0; a[1] <= n; ++a[1])
    for (a[2] = 0; a[1] + a[2] <= n; ++a[2])
      for (a[3] = 0; a[3] <= (D == 3 ? n - a[1] - a[2] : 0); ++a[3]) {
        a[0] = n - a[1] - a[2] - a[3];
        std::array<double, 3> y{0, 0, 0};
        double l = 0;
        for (int i = 0; i <= D; ++i) {
          const double w = double(a[i]) / n;
          for (int c = 0; c < D; ++c) y[c] += w * p[i][c];
          l += w * corner_values[i];
        }
        x[m] = y;
        lin[m++] = l;
        if (m == kBatch && flush()) return result;
      }
  if (m > 0) flush();
  return result;
}

template SurfaceGap surface_gap<2>(const std::array<std::array<double, 2>, 3>&, const std::array<double, 3>&,
                                   const Field&, const std::vector<double>&, double, double, bool);
template SurfaceGap surface_gap<3>(const std::array<std::array<double, 3>, 4>&, const std::array<double, 4>&,
                                   const Field&, const std::vector<double>&, double, double, bool);

}  // namespace mlfe
