#include <gtest/gtest.h>
#include <mlfe/core/fem/element_integrals.h>
#include <mlfe/core/fem/p1_element.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <random>
#include <utility>

namespace mlfe {
namespace {

std::uint64_t bits(double v) {
  std::uint64_t b;
  std::memcpy(&b, &v, sizeof b);
  return b;
}

std::uint32_t bits(float v) {
  std::uint32_t b;
  std::memcpy(&b, &v, sizeof b);
  return b;
}

// The rule written point by point, as a plain recursion over the red children. The batched
// implementation must reproduce it bit for bit: the build's output may not depend on how the
// points are enumerated.
template <int D>
struct Reference {
  using Bary = std::array<double, D + 1>;
  using Simplex = std::array<Bary, D + 1>;
  const std::array<std::array<double, D>, D + 1>& p;
  const Field& f;
  double weight;
  bool gradients;
  ElementIntegrals<D> out;
  ElementGradients<D> grads;

  static Bary mid(const Bary& a, const Bary& b) {
    Bary m;
    for (int i = 0; i <= D; ++i) m[i] = 0.5 * (a[i] + b[i]);
    return m;
  }

  void leaf(const Simplex& s) {
    constexpr double a = D == 2 ? 2.0 / 3.0 : 0.5854101966249685;
    constexpr double b = D == 2 ? 1.0 / 6.0 : 0.1381966011250105;
    for (int q = 0; q <= D; ++q) {
      Bary lam{};
      for (int k = 0; k <= D; ++k)
        for (int i = 0; i <= D; ++i) lam[i] += (k == q ? a : b) * s[k][i];
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
          grads.grad[c] += weight * g[c];
          grads.grad2 += weight * g[c] * g[c];
        }
      }
    }
    out.points += D + 1;
  }

  void recurse(const Simplex& x, int depth) {
    if (depth == 0) return leaf(x);
    if constexpr (D == 2) {
      const auto m01 = mid(x[0], x[1]), m02 = mid(x[0], x[2]), m12 = mid(x[1], x[2]);
      for (const Simplex& c : {Simplex{x[0], m01, m02}, Simplex{m01, x[1], m12}, Simplex{m02, m12, x[2]},
                               Simplex{m01, m12, m02}})
        recurse(c, depth - 1);
    } else {
      const auto x01 = mid(x[0], x[1]), x02 = mid(x[0], x[2]), x03 = mid(x[0], x[3]);
      const auto x12 = mid(x[1], x[2]), x13 = mid(x[1], x[3]), x23 = mid(x[2], x[3]);
      for (const Simplex& c :
           {Simplex{x[0], x01, x02, x03}, Simplex{x01, x[1], x12, x13}, Simplex{x02, x12, x[2], x23},
            Simplex{x03, x13, x23, x[3]}, Simplex{x01, x02, x03, x13}, Simplex{x01, x02, x12, x13},
            Simplex{x02, x03, x13, x23}, Simplex{x02, x12, x13, x23}})
        recurse(c, depth - 1);
    }
  }

  static std::pair<ElementIntegrals<D>, ElementGradients<D>> run(
      const std::array<std::array<double, D>, D + 1>& p, const Field& f, double max_sub_edge,
      bool gradients) {
    const double measure = P1Element<D>(p).measure;
    const double size = std::pow(measure * (D == 2 ? 2.0 : 6.0), 1.0 / D);
    const int depth = integration_depth(size, max_sub_edge);
    const double subs = std::pow(double(1 << D), depth);
    Reference r{p, f, measure / subs / (D + 1), gradients, {}, {}};
    Simplex root;
    for (int i = 0; i <= D; ++i)
      for (int k = 0; k <= D; ++k) root[i][k] = i == k ? 1.0 : 0.0;
    r.recurse(root, depth);
    return {r.out, r.grads};
  }
};

template <int D>
void expect_bitwise_equal(const ElementIntegrals<D>& a, const ElementIntegrals<D>& b) {
  EXPECT_EQ(bits(a.f2), bits(b.f2));
  for (int i = 0; i <= D; ++i) EXPECT_EQ(bits(a.fphi[i]), bits(b.fphi[i])) << i;
  EXPECT_EQ(bits(a.fmin), bits(b.fmin));
  EXPECT_EQ(bits(a.fmax), bits(b.fmax));
  EXPECT_EQ(a.points, b.points);
}

// integrate_element, with the H1 sums or without, bit for bit equal to the reference.
template <int D>
void expect_matches_reference(const std::array<std::array<double, D>, D + 1>& p, const Field& f,
                              double max_sub_edge, bool gradients) {
  ElementGradients<D> ga;
  const ElementIntegrals<D> a = integrate_element<D>(p, f, max_sub_edge, gradients ? &ga : nullptr);
  const auto [b, gb] = Reference<D>::run(p, f, max_sub_edge, gradients);
  expect_bitwise_equal<D>(a, b);
  for (int c = 0; c < D; ++c) EXPECT_EQ(bits(ga.grad[c]), bits(gb.grad[c])) << c;
  EXPECT_EQ(bits(ga.grad2), bits(gb.grad2));
  if (gradients) {
    EXPECT_NE(ga.grad2, 0.0);  // the sums did arrive
  }
}

ScalarGrid random_grid(int dim, std::array<std::int64_t, 3> dims, std::array<double, 3> spacing) {
  ScalarGrid g;
  g.dim = dim;
  g.dims = dims;
  g.transform.spacing = spacing;
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(-50.0f, 200.0f);
  g.values.resize(std::size_t(g.voxel_count()));
  for (float& v : g.values) v = u(rng);
  return g;
}

// A field without a batched override, so integration goes through Field's default loops.
class WavyField final : public Field {
 public:
  int dim() const override { return 3; }
  double value(const std::array<double, 3>& x) const override {
    return std::sin(1.3 * x[0]) * std::cos(0.7 * x[1]) + 0.25 * x[2];
  }
  std::array<double, 3> extent() const override { return {10, 10, 10}; }
  std::array<double, 3> gradient(const std::array<double, 3>& x) const override {
    return {1.3 * std::cos(1.3 * x[0]) * std::cos(0.7 * x[1]),
            -0.7 * std::sin(1.3 * x[0]) * std::sin(0.7 * x[1]), 0.25};
  }
  double resolution() const override { return 1; }
  std::array<double, 2> range() const override { return {-1.0, 3.5}; }
};

TEST(ElementIntegrals, BatchedGridEvaluationMatchesSinglePoints) {
  for (int dim : {2, 3}) {
    const ScalarGrid g =
        dim == 2 ? random_grid(2, {17, 13, 1}, {0.5, 1.25, 1}) : random_grid(3, {9, 7, 5}, {0.7, 1.1, 0.9});
    const GridField f(g);
    std::mt19937 rng(11);
    // Reaches past the domain on both sides, so clamping is covered too.
    std::uniform_real_distribution<double> u(-2.0, 12.0);
    std::vector<std::array<double, 3>> x(301);
    for (auto& p : x) p = {u(rng), u(rng), u(rng)};
    std::vector<double> v(x.size());
    std::vector<std::array<double, 3>> gr(x.size());
    f.values(x.data(), v.data(), x.size());
    f.gradients(x.data(), gr.data(), x.size());
    for (std::size_t j = 0; j < x.size(); ++j) {
      EXPECT_EQ(bits(v[j]), bits(f.value(x[j])));
      const auto g1 = f.gradient(x[j]);
      for (int c = 0; c < 3; ++c) EXPECT_EQ(bits(gr[j][c]), bits(g1[c]));
    }
  }
}

TEST(ElementIntegrals, BitwiseEqualToPointByPointRule3d) {
  const ScalarGrid g = random_grid(3, {13, 11, 9}, {0.7, 1.1, 0.9});
  const GridField grid_field(g);
  const WavyField wavy;
  const std::array<std::array<double, 3>, 4> p{
      {{-0.3, 0.2, 0.1}, {8.9, 1.0, 0.5}, {2.0, 9.7, 1.5}, {1.0, 2.0, 7.9}}};
  // Depths 0 to 4: from the single-batch tables to elements split into several batches.
  for (const Field* f : {static_cast<const Field*>(&grid_field), static_cast<const Field*>(&wavy)}) {
    for (double max_sub_edge : {20.0, 8.0, 4.0, 2.0, 1.0})
      for (bool gradients : {false, true}) {
        SCOPED_TRACE(testing::Message() << "max_sub_edge " << max_sub_edge << " gradients " << gradients);
        expect_matches_reference<3>(p, *f, max_sub_edge, gradients);
      }
  }
}

TEST(ElementIntegrals, BitwiseEqualToPointByPointRule2d) {
  const ScalarGrid g = random_grid(2, {17, 13, 1}, {0.5, 1.25, 1});
  const GridField f(g);
  const std::array<std::array<double, 2>, 3> p{{{-0.4, 0.3}, {8.7, 1.1}, {2.5, 15.8}}};
  // Depths 0 to 6 (the 2D batches are 3 levels deep).
  for (double max_sub_edge : {40.0, 8.0, 4.0, 2.0, 1.0, 0.5, 0.25})
    for (bool gradients : {false, true}) {
      SCOPED_TRACE(testing::Message() << "max_sub_edge " << max_sub_edge << " gradients " << gradients);
      expect_matches_reference<2>(p, f, max_sub_edge, gradients);
    }
}

}  // namespace
}  // namespace mlfe
