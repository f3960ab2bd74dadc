// core/mesh_distance: closest points against brute force, exact distances for planted
// displacements, sampling determinism across thread counts, signed volume and handedness.
#include <gtest/gtest.h>
#include <mlfe/core/surface/mesh_distance.h>
#include <tbb/global_control.h>

#include <cmath>
#include <random>

#include "tests/test_meshes.h"

namespace mlfe {
namespace {

double brute_force_distance(const TriangleMesh& m, const std::array<double, 3>& p) {
  // Dense barycentric sampling is not exact; instead project onto each triangle's plane and
  // edges, the textbook way, independent of the BVH's region tests.
  double best = 1e300;
  auto dist_seg = [](const std::array<double, 3>& p, const std::array<double, 3>& a,
                     const std::array<double, 3>& b) {
    std::array<double, 3> ab{b[0] - a[0], b[1] - a[1], b[2] - a[2]},
        ap{p[0] - a[0], p[1] - a[1], p[2] - a[2]};
    const double l2 = ab[0] * ab[0] + ab[1] * ab[1] + ab[2] * ab[2];
    double t = l2 > 0 ? (ap[0] * ab[0] + ap[1] * ab[1] + ap[2] * ab[2]) / l2 : 0;
    t = std::clamp(t, 0.0, 1.0);
    double d2 = 0;
    for (int k = 0; k < 3; ++k) d2 += std::pow(p[k] - (a[k] + t * ab[k]), 2);
    return std::sqrt(d2);
  };
  for (const auto& t : m.triangles) {
    std::array<std::array<double, 3>, 3> c;
    for (int i = 0; i < 3; ++i)
      for (int k = 0; k < 3; ++k) c[i][k] = m.positions[t[i]][k];
    best = std::min({best, dist_seg(p, c[0], c[1]), dist_seg(p, c[1], c[2]), dist_seg(p, c[2], c[0])});
    std::array<double, 3> e1{c[1][0] - c[0][0], c[1][1] - c[0][1], c[1][2] - c[0][2]},
        e2{c[2][0] - c[0][0], c[2][1] - c[0][1], c[2][2] - c[0][2]};
    std::array<double, 3> n{e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                            e1[0] * e2[1] - e1[1] * e2[0]};
    const double nl = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    if (nl == 0) continue;
    for (auto& x : n) x /= nl;
    const double h = (p[0] - c[0][0]) * n[0] + (p[1] - c[0][1]) * n[1] + (p[2] - c[0][2]) * n[2];
    const std::array<double, 3> q{p[0] - h * n[0], p[1] - h * n[1], p[2] - h * n[2]};
    // Inside test: same side of all three edges.
    bool inside = true;
    for (int i = 0; i < 3; ++i) {
      const auto& a = c[i];
      const auto& b = c[(i + 1) % 3];
      std::array<double, 3> ab{b[0] - a[0], b[1] - a[1], b[2] - a[2]},
          aq{q[0] - a[0], q[1] - a[1], q[2] - a[2]};
      std::array<double, 3> x{ab[1] * aq[2] - ab[2] * aq[1], ab[2] * aq[0] - ab[0] * aq[2],
                              ab[0] * aq[1] - ab[1] * aq[0]};
      if (x[0] * n[0] + x[1] * n[1] + x[2] * n[2] < 0) inside = false;
    }
    if (inside) best = std::min(best, std::abs(h));
  }
  return best;
}

TEST(TriangleBvh, ClosestPointMatchesBruteForce) {
  const TriangleMesh m = test::icosphere(2, 1.0f, {0.3f, -0.2f, 0.1f});
  const TriangleBvh bvh(m);
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-2.0, 2.0);
  for (int i = 0; i < 300; ++i) {
    const std::array<double, 3> p{u(rng), u(rng), u(rng)};
    const TriangleBvh::Hit hit = bvh.closest(p);
    ASSERT_TRUE(hit.triangle.valid());
    EXPECT_NEAR(hit.distance, brute_force_distance(m, p), 1e-9) << i;
  }
}

TEST(TriangleBvh, TriangleWithCoincidingCornersIsItsSegment) {
  // Draco's quantization makes such triangles; every corner order, points on and around them.
  const std::array<float, 3> x{0.125f, 0.25f, 0.5f}, tip{1.125f, 0.5f, 0.5f};
  TriangleMesh m;
  m.positions = {x, x, tip};
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 2.0);
  for (const std::array<std::uint32_t, 3> t : {std::array<std::uint32_t, 3>{0, 1, 2}, {1, 2, 0}, {2, 0, 1}}) {
    m.triangles = {t};
    const TriangleBvh bvh(m);
    EXPECT_EQ(bvh.closest({tip[0], tip[1], tip[2]}).distance, 0.0);
    for (int i = 0; i < 100; ++i) {
      const std::array<double, 3> p{u(rng), u(rng), u(rng)};
      EXPECT_NEAR(bvh.closest(p).distance, brute_force_distance(m, p), 1e-12) << i;
    }
  }
}

TEST(MeshDistance, IdenticalMeshesAreAtDistanceZero) {
  const TriangleMesh m = test::icosphere(3, 1.0f);
  const MeshDistance d = mesh_distance(m, m, {});
  // Area samples are computed points, so only rounding separates them from the surface.
  EXPECT_LT(d.hausdorff(), 1e-12);
  EXPECT_LT(d.mean(), 1e-12);
  EXPECT_LT(d.expected_to_actual.normal_angle_max_deg, 1e-3);
}

TEST(MeshDistance, MovedVertexGivesItsDisplacementAsHausdorff) {
  TriangleMesh a = test::icosphere(3, 1.0f);
  TriangleMesh b = a;
  // Radially outward from a convex polyhedron's vertex: the vertex itself stays the closest point.
  for (auto& x : b.positions[7]) x *= 1.05f;
  const double moved = std::sqrt(std::pow(b.positions[7][0] - a.positions[7][0], 2) +
                                 std::pow(b.positions[7][1] - a.positions[7][1], 2) +
                                 std::pow(b.positions[7][2] - a.positions[7][2], 2));
  const MeshDistance d = mesh_distance(a, b, {});
  EXPECT_NEAR(d.actual_to_expected.max, moved, 1e-6);
  EXPECT_LE(d.expected_to_actual.max, moved + 1e-6);
  EXPECT_NEAR(d.hausdorff(), moved, 1e-6);
}

TEST(MeshDistance, SameReportWithOneAndTwoThreads) {
  TriangleMesh a = test::icosphere(3, 1.0f);
  TriangleMesh b = test::uv_sphere(20, 40, 1.01f);
  MeshDistance one, two;
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 1);
    one = mesh_distance(a, b, {});
  }
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 2);
    two = mesh_distance(a, b, {});
  }
  EXPECT_EQ(one.hausdorff(), two.hausdorff());
  EXPECT_EQ(one.expected_to_actual.mean, two.expected_to_actual.mean);
  EXPECT_EQ(one.actual_to_expected.mean, two.actual_to_expected.mean);
  EXPECT_EQ(one.actual_to_expected.normal_angle_mean_deg, two.actual_to_expected.normal_angle_mean_deg);
  EXPECT_GT(one.hausdorff(), 0.0);
}

TEST(MeshDistance, SamplingIsReproducibleAndAreaWeighted) {
  const TriangleMesh m = test::icosphere(2, 1.0f);
  SurfaceSamplingOptions o;
  o.area_samples = 5000;
  const auto s1 = sample_surface(m, o), s2 = sample_surface(m, o);
  ASSERT_EQ(s1.size(), m.vertex_count() + 5000);
  for (std::size_t i = 0; i < s1.size(); ++i) ASSERT_EQ(s1[i].point, s2[i].point);
  o.seed = 18;
  const auto s3 = sample_surface(m, o);
  EXPECT_NE(s1.back().point, s3.back().point);
  // Every sample lies on the surface.
  const TriangleBvh bvh(m);
  for (const auto& s : s1) ASSERT_LT(bvh.closest(s.point).distance, 1e-6);
}

TEST(MeshDistance, SignedVolumeChangesSignWhenMirrored) {
  TriangleMesh m = test::icosphere(3, 2.0f, {5.0f, 0.0f, 0.0f});
  const double v = signed_volume(m);
  EXPECT_NEAR(v, 4.0 / 3.0 * M_PI * 8.0, 0.05 * 4.0 / 3.0 * M_PI * 8.0);
  for (auto& p : m.positions) p[0] = -p[0];
  EXPECT_NEAR(signed_volume(m), -v, 1e-3 * v);
  const auto box = bounding_box(m);
  EXPECT_NEAR(box[0][0], -7.0, 1e-5);
  EXPECT_NEAR(box[1][0], -3.0, 1e-5);
  EXPECT_NEAR(surface_area(m), 4 * M_PI * 4.0, 0.05 * 4 * M_PI * 4.0);
}

}  // namespace
}  // namespace mlfe
