// Hierarchies and hierarchy helpers shared by the core and format tests: refined examples,
// random marking, barycentric coordinates, equality of every stored array.
#pragma once
#include <gtest/gtest.h>
#include <mlfe/core/field/scalar_grid.h>
#include <mlfe/core/mesh/hierarchy.h>

#include <array>
#include <cmath>
#include <cstddef>
#include <functional>
#include <random>
#include <vector>

namespace mlfe::test {

/// A grid of uniform random values in [-50, 50) (rounded with `integers`); 2D grids have one
/// sample along z.
inline ScalarGrid random_grid(int dim, std::array<std::int64_t, 3> dims, std::array<double, 3> spacing,
                              unsigned seed, bool integers = false) {
  ScalarGrid g;
  g.dim = dim;
  g.dims = dims;
  if (dim == 2) g.dims[2] = 1;
  g.transform.spacing = spacing;
  g.values.resize(static_cast<std::size_t>(g.voxel_count()));
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-50.f, 50.f);
  for (float& v : g.values) v = integers ? std::round(u(rng)) : u(rng);
  return g;
}

/// A 3D grid of f(i, j, k) at every sample.
inline ScalarGrid function_grid(std::array<std::int64_t, 3> dims, std::array<double, 3> spacing,
                                const std::function<double(std::int64_t, std::int64_t, std::int64_t)>& f) {
  ScalarGrid g;
  g.dim = 3;
  g.dims = dims;
  g.transform.spacing = spacing;
  g.values.resize(std::size_t(dims[0] * dims[1] * dims[2]));
  for (std::int64_t k = 0; k < dims[2]; ++k)
    for (std::int64_t j = 0; j < dims[1]; ++j)
      for (std::int64_t i = 0; i < dims[0]; ++i)
        g.values[std::size_t(i + dims[0] * (j + dims[1] * k))] = float(f(i, j, k));
  return g;
}

/// Red and green elements at several levels: `rounds` times, refines every leaf with a vertex
/// in [0, 0.25]^D (the corner at the origin).
template <int D>
Hierarchy<D> refine_toward_origin(Hierarchy<D> h, int rounds) {
  for (int round = 0; round < rounds; ++round) {
    std::vector<ElemId> marked;
    for (ElemId e : h.leaves()) {
      bool near = false;
      for (VertexId v : h.cell(e)) {
        bool in = true;
        for (int i = 0; i < D; ++i) in = in && h.point(v)[i] <= 0.25;
        near = near || in;
      }
      if (near) marked.push_back(e);
    }
    h.refine(marked);
  }
  return h;
}

/// Random marks: `picks` leaves drawn uniformly (repeats allowed), then every green leaf with
/// probability 1/green_one_in (marking green leaves exercises the parent-red rule).
template <int D>
std::vector<ElemId> random_marking(const Hierarchy<D>& h, std::mt19937& rng, int picks,
                                   unsigned green_one_in) {
  const auto leaves = h.leaves();
  std::vector<ElemId> marked;
  std::uniform_int_distribution<std::size_t> pick(0, leaves.size() - 1);
  for (int k = 0; k < picks; ++k) marked.push_back(leaves[pick(rng)]);
  for (ElemId e : leaves)
    if (h.kind(e) == ElemKind::kGreen && rng() % green_one_in == 0) marked.push_back(e);
  return marked;
}

/// Barycentric coordinates of `x` in element `e` (Cramer's rule; x inside iff all >= 0).
template <int D>
std::array<double, D + 1> barycentric(const Hierarchy<D>& h, ElemId e,
                                      const typename Hierarchy<D>::Point& x) {
  const auto& c = h.cell(e);
  const auto& a = h.point(c[0]);
  std::array<double, D + 1> bary{};
  if constexpr (D == 2) {
    const auto& b = h.point(c[1]);
    const auto& d = h.point(c[2]);
    const double det = (b[0] - a[0]) * (d[1] - a[1]) - (b[1] - a[1]) * (d[0] - a[0]);
    bary[1] = ((x[0] - a[0]) * (d[1] - a[1]) - (x[1] - a[1]) * (d[0] - a[0])) / det;
    bary[2] = ((b[0] - a[0]) * (x[1] - a[1]) - (b[1] - a[1]) * (x[0] - a[0])) / det;
    bary[0] = 1 - bary[1] - bary[2];
  } else {
    double m[3][3], r[3];
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) m[i][j] = h.point(c[j + 1])[i] - a[i];
      r[i] = x[i] - a[i];
    }
    auto det3 = [](double q[3][3]) {
      return q[0][0] * (q[1][1] * q[2][2] - q[1][2] * q[2][1]) -
             q[0][1] * (q[1][0] * q[2][2] - q[1][2] * q[2][0]) +
             q[0][2] * (q[1][0] * q[2][1] - q[1][1] * q[2][0]);
    };
    const double det = det3(m);
    double s = 0;
    for (int j = 0; j < 3; ++j) {
      double q[3][3];
      for (int i = 0; i < 3; ++i)
        for (int k = 0; k < 3; ++k) q[i][k] = k == j ? r[i] : m[i][k];
      bary[j + 1] = det3(q) / det;
      s += bary[j + 1];
    }
    bary[0] = 1 - s;
  }
  return bary;
}

/// Every stored array of the two hierarchies is equal.
template <int D>
void expect_same_hierarchy(const Hierarchy<D>& a, const Hierarchy<D>& b) {
  EXPECT_EQ(a.points(), b.points());
  EXPECT_EQ(a.vertex_parents_array(), b.vertex_parents_array());
  EXPECT_EQ(a.vertex_level_array(), b.vertex_level_array());
  EXPECT_EQ(a.cells(), b.cells());
  EXPECT_EQ(a.parent_array(), b.parent_array());
  EXPECT_EQ(a.first_child_array(), b.first_child_array());
  EXPECT_EQ(a.num_children_array(), b.num_children_array());
  EXPECT_EQ(a.level_array(), b.level_array());
  EXPECT_EQ(a.kind_array(), b.kind_array());
  EXPECT_EQ(a.coarse_count(), b.coarse_count());
  EXPECT_EQ(a.edge_midpoints().size(), b.edge_midpoints().size());
}

}  // namespace mlfe::test
