#include "core/element_integrals.h"

#include <algorithm>
#include <cmath>

#include "core/check.h"
#include "core/p1_element.h"

namespace mlfe {

namespace {

template <int D>
struct SubSimplex {
  std::array<std::array<double, D + 1>, D + 1> bary;  // barycentric coordinates of its vertices
};

template <int D>
std::array<double, D + 1> mid_bary(const std::array<double, D + 1>& a, const std::array<double, D + 1>& b) {
  std::array<double, D + 1> m;
  for (int i = 0; i <= D; ++i) m[i] = 0.5 * (a[i] + b[i]);
  return m;
}

template <int D>
struct Integrator {
  const std::array<std::array<double, D>, D + 1>& p;
  const Field& f;
  double weight;  // measure of a sub-simplex / number of points
  bool gradients;
  ElementIntegrals<D> out;

  void leaf(const SubSimplex<D>& s) {
    // Degree-2 rule: points (a, b, ..., b) and permutations in the sub-simplex's barycentrics.
    constexpr double a = D == 2 ? 2.0 / 3.0 : 0.5854101966249685;
    constexpr double b = D == 2 ? 1.0 / 6.0 : 0.1381966011250105;
    for (int q = 0; q <= D; ++q) {
      std::array<double, D + 1> lam{};
      for (int k = 0; k <= D; ++k) {
        const double w = k == q ? a : b;
        for (int i = 0; i <= D; ++i) lam[i] += w * s.bary[k][i];
      }
      std::array<double, 3> x{0, 0, 0};
      for (int i = 0; i <= D; ++i)
        for (int c = 0; c < D; ++c) x[c] += lam[i] * p[i][c];
      const double fv = f.value(x);
      if (out.points == 0 && q == 0) {
        out.fmin = out.fmax = float(fv);
      } else {
        out.fmin = std::min(out.fmin, float(fv));
        out.fmax = std::max(out.fmax, float(fv));
      }
      out.f2 += weight * fv * fv;
      for (int i = 0; i <= D; ++i) out.fphi[i] += weight * fv * lam[i];
      if (gradients) {
        const auto g = f.gradient(x);
        for (int c = 0; c < D; ++c) {
          out.grad[c] += weight * g[c];
          out.grad2 += weight * g[c] * g[c];
        }
      }
    }
    out.points += D + 1;
  }

  void recurse(const SubSimplex<D>& s, int depth) {
    if (depth == 0) {
      leaf(s);
      return;
    }
    const auto& x = s.bary;
    if constexpr (D == 2) {
      const auto m01 = mid_bary<D>(x[0], x[1]), m02 = mid_bary<D>(x[0], x[2]), m12 = mid_bary<D>(x[1], x[2]);
      recurse({{x[0], m01, m02}}, depth - 1);
      recurse({{m01, x[1], m12}}, depth - 1);
      recurse({{m02, m12, x[2]}}, depth - 1);
      recurse({{m01, m12, m02}}, depth - 1);
    } else {
      const auto x01 = mid_bary<D>(x[0], x[1]), x02 = mid_bary<D>(x[0], x[2]), x03 = mid_bary<D>(x[0], x[3]);
      const auto x12 = mid_bary<D>(x[1], x[2]), x13 = mid_bary<D>(x[1], x[3]), x23 = mid_bary<D>(x[2], x[3]);
      // Bey's children keep at most 3 shapes, so the longest edge halves every level.
      recurse({{x[0], x01, x02, x03}}, depth - 1);
      recurse({{x01, x[1], x12, x13}}, depth - 1);
      recurse({{x02, x12, x[2], x23}}, depth - 1);
      recurse({{x03, x13, x23, x[3]}}, depth - 1);
      recurse({{x01, x02, x03, x13}}, depth - 1);
      recurse({{x01, x02, x12, x13}}, depth - 1);
      recurse({{x02, x03, x13, x23}}, depth - 1);
      recurse({{x02, x12, x13, x23}}, depth - 1);
    }
  }
};

}  // namespace

int integration_depth(double size, double max_sub_size) {
  MLFE_CHECK(max_sub_size > 0);
  int depth = 0;
  while (size > max_sub_size && depth < 12) {
    size *= 0.5;  // red refinement halves every length
    ++depth;
  }
  return depth;
}

template <int D>
ElementIntegrals<D> integrate_element(const std::array<std::array<double, D>, D + 1>& p,
                                      const Field& f, double max_sub_edge, bool gradients) {
  // Size = side of the cube that D! copies of the simplex would fill (Kuhn simplices of a
  // voxel-sized cube have size one voxel), so sub-simplices hold ~D! samples per voxel.
  const double measure = P1Element<D>(p).measure;
  const double size = std::pow(measure * (D == 2 ? 2.0 : 6.0), 1.0 / D);
  const int depth = integration_depth(size, max_sub_edge);
  const double subs = std::pow(double(1 << D), depth);
  Integrator<D> it{p, f, measure / subs / (D + 1), gradients, {}};
  SubSimplex<D> root;
  for (int i = 0; i <= D; ++i)
    for (int k = 0; k <= D; ++k) root.bary[i][k] = i == k ? 1.0 : 0.0;
  it.recurse(root, depth);
  return it.out;
}

template ElementIntegrals<2> integrate_element<2>(const std::array<std::array<double, 2>, 3>&, const Field&, double, bool);
template ElementIntegrals<3> integrate_element<3>(const std::array<std::array<double, 3>, 4>&, const Field&, double, bool);

}  // namespace mlfe
