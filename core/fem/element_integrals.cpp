#include <mlfe/core/base/check.h>
#include <mlfe/core/fem/element_integrals.h>
#include <mlfe/core/fem/p1_element.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <vector>

namespace mlfe {

namespace {

template <int D>
using Bary = std::array<double, D + 1>;

template <int D>
struct SubSimplex {
  std::array<Bary<D>, D + 1> bary;  // barycentric coordinates of its vertices
};

template <int D>
constexpr int kChildren = 1 << D;

// The bottom levels of the refinement are expanded into one batch of quadrature points, which
// is evaluated with a single Field::values call and then accumulated. 64 leaves per batch keeps
// the buffers on the stack and in L1 (~22 KB in 3D); deeper elements are cut into such batches.
template <int D>
constexpr int kBatchLevels = D == 2 ? 3 : 2;
template <int D>
constexpr std::size_t kBatchPoints = (std::size_t(1) << (D * kBatchLevels<D>)) * (D + 1);

template <int D>
Bary<D> mid_bary(const Bary<D>& a, const Bary<D>& b) {
  Bary<D> m;
  for (int i = 0; i <= D; ++i) m[i] = 0.5 * (a[i] + b[i]);
  return m;
}

// One red refinement step. The child order fixes the order in which the points are summed,
// and with it every bit of the result.
template <int D>
void red_children(const SubSimplex<D>& s, SubSimplex<D>* child) {
  const auto& x = s.bary;
  if constexpr (D == 2) {
    const auto m01 = mid_bary<D>(x[0], x[1]), m02 = mid_bary<D>(x[0], x[2]), m12 = mid_bary<D>(x[1], x[2]);
    child[0] = {{x[0], m01, m02}};
    child[1] = {{m01, x[1], m12}};
    child[2] = {{m02, m12, x[2]}};
    child[3] = {{m01, m12, m02}};
  } else {
    const auto x01 = mid_bary<D>(x[0], x[1]), x02 = mid_bary<D>(x[0], x[2]), x03 = mid_bary<D>(x[0], x[3]);
    const auto x12 = mid_bary<D>(x[1], x[2]), x13 = mid_bary<D>(x[1], x[3]), x23 = mid_bary<D>(x[2], x[3]);
    // Bey's children keep at most 3 shapes, so the longest edge halves every level.
    child[0] = {{x[0], x01, x02, x03}};
    child[1] = {{x01, x[1], x12, x13}};
    child[2] = {{x02, x12, x[2], x23}};
    child[3] = {{x03, x13, x23, x[3]}};
    child[4] = {{x01, x02, x03, x13}};
    child[5] = {{x01, x02, x12, x13}};
    child[6] = {{x02, x03, x13, x23}};
    child[7] = {{x02, x12, x13, x23}};
  }
}

// Degree-2 rule: points (a, b, ..., b) and permutations in the sub-simplex's barycentrics,
// written to lam[0..D]; returns lam + D + 1.
template <int D>
Bary<D>* leaf_points(const SubSimplex<D>& s, Bary<D>* lam) {
  constexpr double a = D == 2 ? 2.0 / 3.0 : 0.5854101966249685;
  constexpr double b = D == 2 ? 1.0 / 6.0 : 0.1381966011250105;
  for (int q = 0; q <= D; ++q) {
    Bary<D> l{};
    for (int k = 0; k <= D; ++k) {
      const double w = k == q ? a : b;
      for (int i = 0; i <= D; ++i) l[i] += w * s.bary[k][i];
    }
    lam[q] = l;
  }
  return lam + D + 1;
}

// Quadrature points of the leaves of s refined `levels` times, in depth-first order.
template <int D>
Bary<D>* emit_points(const SubSimplex<D>& s, int levels, Bary<D>* lam) {
  if (levels == 0) return leaf_points<D>(s, lam);
  SubSimplex<D> child[kChildren<D>];
  red_children<D>(s, child);
  for (const auto& c : child) lam = emit_points<D>(c, levels - 1, lam);
  return lam;
}

template <int D>
SubSimplex<D> root_simplex() {
  SubSimplex<D> root;
  for (int i = 0; i <= D; ++i)
    for (int k = 0; k <= D; ++k) root.bary[i][k] = i == k ? 1.0 : 0.0;
  return root;
}

// The barycentrics of the points depend only on the depth, not on the element: elements up to
// one batch deep (nearly all of them) read them from a table built once.
template <int D>
const std::vector<Bary<D>>& root_points(int depth) {
  static const auto tables = [] {
    std::array<std::vector<Bary<D>>, kBatchLevels<D> + 1> t;
    for (int d = 0; d <= kBatchLevels<D>; ++d) {
      t[d].resize((std::size_t(1) << (D * d)) * (D + 1));
      emit_points<D>(root_simplex<D>(), d, t[d].data());
    }
    return t;
  }();
  return tables[depth];
}

template <int D>
struct Integrator {
  std::array<std::array<double, D>, D + 1> p;
  const Field& f;
  double weight;  // measure of a sub-simplex / number of points
  bool gradients;
  ElementIntegrals<D> out;
  ElementGradients<D> grads;

  // Evaluates f at the points lam[0..n) (n <= kBatchPoints) in one batch, then adds them to the
  // sums in order, with the same operations per point as a point-by-point loop.
  void integrate_points(const Bary<D>* lam, std::size_t n) {
    std::array<double, 3> x[kBatchPoints<D>];
    double fv[kBatchPoints<D>];
    for (std::size_t j = 0; j < n; ++j) {
      std::array<double, 3> y{0, 0, 0};
      for (int i = 0; i <= D; ++i)
        for (int c = 0; c < D; ++c) y[c] += lam[j][i] * p[i][c];
      x[j] = y;
    }
    f.values(x, fv, n);
    // A local copy stays in registers; stores into `out` could alias lam as far as the
    // compiler knows.
    ElementIntegrals<D> s = out;
    if (s.points == 0) s.fmin = s.fmax = float(fv[0]);
    for (std::size_t j = 0; j < n; ++j) {
      const double v = fv[j];
      s.fmin = std::min(s.fmin, float(v));
      s.fmax = std::max(s.fmax, float(v));
      const double wv = weight * v;
      s.f2 += wv * v;
      for (int i = 0; i <= D; ++i) s.fphi[i] += wv * lam[j][i];
    }
    if (gradients) {
      std::array<double, 3> g[kBatchPoints<D>];
      f.gradients(x, g, n);
      ElementGradients<D> sg = grads;
      for (std::size_t j = 0; j < n; ++j) {
        for (int c = 0; c < D; ++c) {
          const double wg = weight * g[j][c];
          sg.grad[c] += wg;
          sg.grad2 += wg * g[j][c];
        }
      }
      grads = sg;
    }
    s.points += static_cast<std::uint32_t>(n);
    out = s;
  }

  // Refines down to sub-simplices one batch deep, in depth-first order.
  void recurse(const SubSimplex<D>& s, int depth) {
    if (depth <= kBatchLevels<D>) {
      Bary<D> lam[kBatchPoints<D>];
      const Bary<D>* end = emit_points<D>(s, depth, lam);
      integrate_points(lam, std::size_t(end - lam));
      return;
    }
    SubSimplex<D> child[kChildren<D>];
    red_children<D>(s, child);
    for (const auto& c : child) recurse(c, depth - 1);
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
ElementIntegrals<D> integrate_element(const std::array<std::array<double, D>, D + 1>& p, const Field& f,
                                      double max_sub_edge, ElementGradients<D>* gradients) {
  // Size = side of the cube that D! copies of the simplex would fill (Kuhn simplices of a
  // voxel-sized cube have size one voxel), so sub-simplices hold ~D! samples per voxel.
  const double measure = P1Element<D>(p).measure;
  const double size = std::pow(measure * (D == 2 ? 2.0 : 6.0), 1.0 / D);
  const int depth = integration_depth(size, max_sub_edge);
  const double subs = std::pow(double(1 << D), depth);
  Integrator<D> it{p, f, measure / subs / (D + 1), gradients != nullptr, {}, {}};
  if (depth <= kBatchLevels<D>) {
    const auto& lam = root_points<D>(depth);
    it.integrate_points(lam.data(), lam.size());
  } else {
    it.recurse(root_simplex<D>(), depth);
  }
  if (gradients) *gradients = it.grads;
  return it.out;
}

template ElementIntegrals<2> integrate_element<2>(const std::array<std::array<double, 2>, 3>&, const Field&,
                                                  double, ElementGradients<2>*);
template ElementIntegrals<3> integrate_element<3>(const std::array<std::array<double, 3>, 4>&, const Field&,
                                                  double, ElementGradients<3>*);

}  // namespace mlfe
