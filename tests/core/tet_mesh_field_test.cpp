#include <gtest/gtest.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/field/tet_mesh_field.h>

#include <cmath>
#include <random>

#include "tests/tet_meshes.h"

namespace mlfe {
namespace {

using V3 = std::array<double, 3>;

double linear(const V3& p) { return 1.5 + 2.0 * p[0] - 3.0 * p[1] + 0.7 * p[2]; }
double curved(const V3& p) { return p[0] * p[0] + std::sin(3 * p[1]) + p[2] * p[2] * p[2]; }

// A Kuhn mesh of a shifted, scaled box with its interior points moved at random, so the
// tetrahedra are irregular.
TetMesh jittered_mesh(int n, double size, const V3& origin, double (*f)(const V3&)) {
  TetMesh m = test::kuhn_mesh(n, f, {}, size, origin);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> jitter(-0.2 * size / n, 0.2 * size / n);
  for (std::size_t i = 0; i < m.points.size(); ++i) {
    auto& p = m.points[i];
    bool interior = true;
    for (int a = 0; a < 3; ++a)
      interior &= std::abs(p[a] - origin[a]) > 1e-9 && std::abs(p[a] - origin[a] - size) > 1e-9;
    if (interior)
      for (int a = 0; a < 3; ++a) p[a] += jitter(rng);
    m.values[i] = f(p);
  }
  return m;
}

TEST(TetMeshField, ReproducesALinearFunctionInsideTheMesh) {
  const V3 origin{2.0, -1.0, 0.5};
  const TetMesh m = jittered_mesh(6, 3.0, origin, linear);
  const TetMeshField f(m);
  EXPECT_EQ(f.origin(), origin);
  for (int a = 0; a < 3; ++a) EXPECT_NEAR(f.extent()[a], 3.0, 1e-15);
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> u(0.0, 3.0);
  std::vector<V3> xs;
  for (int i = 0; i < 2000; ++i) xs.push_back({u(rng), u(rng), u(rng)});
  std::vector<double> batch(xs.size());
  f.values(xs.data(), batch.data(), xs.size());
  std::vector<V3> grads(xs.size());
  f.gradients(xs.data(), grads.data(), xs.size());
  for (std::size_t i = 0; i < xs.size(); ++i) {
    const V3 phys{xs[i][0] + origin[0], xs[i][1] + origin[1], xs[i][2] + origin[2]};
    ASSERT_TRUE(f.inside(xs[i]));
    EXPECT_NEAR(f.value(xs[i]), linear(phys), 1e-12 * 20);
    EXPECT_EQ(f.value(xs[i]), batch[i]);  // batched evaluation is bit for bit the same
    EXPECT_NEAR(grads[i][0], 2.0, 1e-12);
    EXPECT_NEAR(grads[i][1], -3.0, 1e-12);
    EXPECT_NEAR(grads[i][2], 0.7, 1e-12);
  }
}

TEST(TetMeshField, InterpolatesAtVerticesEdgesAndFaces) {
  const TetMesh m = jittered_mesh(5, 1.0, {0, 0, 0}, curved);
  const TetMeshField f(m);
  for (std::size_t i = 0; i < m.points.size(); ++i) EXPECT_NEAR(f.value(m.points[i]), m.values[i], 1e-12);
  for (const auto& t : m.tets) {
    for (int a = 0; a < 4; ++a)
      for (int b = a + 1; b < 4; ++b) {
        V3 mid;
        for (int k = 0; k < 3; ++k) mid[k] = 0.5 * (m.points[t[a]][k] + m.points[t[b]][k]);
        EXPECT_NEAR(f.value(mid), 0.5 * (m.values[t[a]] + m.values[t[b]]), 1e-12);
      }
    for (int skip = 0; skip < 4; ++skip) {
      V3 c{0, 0, 0};
      double v = 0;
      for (int a = 0; a < 4; ++a)
        if (a != skip) {
          for (int k = 0; k < 3; ++k) c[k] += m.points[t[a]][k] / 3;
          v += m.values[t[a]] / 3;
        }
      EXPECT_NEAR(f.value(c), v, 1e-12);
    }
  }
  // The 10th percentile edge of a Kuhn mesh of side h is h (of edges h, h√2, h√3); jittered a
  // little shorter at most by 0.4 h.
  EXPECT_GT(f.resolution(), 0.6 / 5);
  EXPECT_LE(f.resolution(), 1.0 / 5 + 1e-12);
}

TEST(TetMeshField, TakesTheClosestPointOfTheMeshInTheCutCorner) {
  const TetMesh m = test::kuhn_mesh(8, linear, test::in_cut_corner);
  const TetMeshField f(m);
  const struct {
    V3 x, closest;
  } cases[] = {{{0.8, 0.9, 0.75}, {0.8, 0.9, 0.5}},
               {{0.6, 0.95, 0.99}, {0.5, 0.95, 0.99}},
               {{0.9, 0.55, 0.8}, {0.9, 0.5, 0.8}},
               {{0.97, 0.93, 0.9}, {0.97, 0.93, 0.5}}};
  for (const auto& c : cases) {
    EXPECT_FALSE(f.inside(c.x));
    EXPECT_NEAR(f.value(c.x), linear(c.closest), 1e-12) << c.x[0] << " " << c.x[1] << " " << c.x[2];
    EXPECT_NEAR(f.gradient(c.x)[0], 2.0, 1e-12);
  }
  EXPECT_TRUE(f.inside({0.3, 0.9, 0.9}));
  EXPECT_TRUE(f.inside({0.5, 0.9, 0.9}));  // on the cut's face
  // Outside the box: clamped onto it first.
  EXPECT_NEAR(f.value({-1.0, 0.2, 0.3}), linear({0.0, 0.2, 0.3}), 1e-12);
}

TEST(TetMeshField, RangeInBoxContainsTheValuesInsideAndOutsideTheMesh) {
  const TetMesh m = test::kuhn_mesh(10, curved, test::in_cut_corner);
  const TetMeshField f(m);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  bool narrower = false;
  for (int b = 0; b < 200; ++b) {
    V3 lo, hi;
    for (int a = 0; a < 3; ++a) {
      const double s = u(rng), t = u(rng);
      lo[a] = std::min(s, t);
      hi[a] = std::min(std::max(s, t), lo[a] + 0.3);
    }
    const auto r = f.range_in_box(lo, hi);
    narrower |= r[1] - r[0] < 0.5 * (f.range()[1] - f.range()[0]);
    for (int i = 0; i < 100; ++i) {
      V3 x;
      for (int a = 0; a < 3; ++a) x[a] = lo[a] + u(rng) * (hi[a] - lo[a]);
      const double v = f.value(x);
      ASSERT_GE(v, r[0]);
      ASSERT_LE(v, r[1]);
    }
  }
  EXPECT_TRUE(narrower);  // the buckets narrow it down: not just range()
  EXPECT_DOUBLE_EQ(f.range()[0], *std::min_element(m.values.begin(), m.values.end()));
}

TEST(TetMeshField, SkipsFlatTetrahedraAndRejectsBadMeshes) {
  TetMesh m = test::kuhn_mesh(2, linear);
  m.source = "mesh.vtu";
  const std::size_t good = m.tets.size();
  m.tets.push_back({0, 1, 2, 2});  // a repeated point
  m.tets.push_back({0, 1, 2, 3});  // four points on the face z = 0 (indices 0..8 are z = 0)
  const TetMeshField f(m);
  EXPECT_EQ(f.tet_count(), good);
  EXPECT_EQ(f.degenerate_count(), 2u);

  TetMesh flat = m;
  flat.tets = {{0, 1, 2, 3}, {0, 1, 4, 4}};
  try {
    TetMeshField g(flat);
    FAIL() << "flat mesh accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("mesh.vtu: no tetrahedron of positive volume"), std::string::npos);
  }
  TetMesh bad = m;
  bad.tets[0][2] = 1000;
  EXPECT_THROW(TetMeshField{bad}, Error);
  bad = m;
  bad.values[3] = std::nan("");
  EXPECT_THROW(TetMeshField{bad}, Error);
  bad = m;
  bad.values.pop_back();
  EXPECT_THROW(TetMeshField{bad}, Error);
}

}  // namespace
}  // namespace mlfe
