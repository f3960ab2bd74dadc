#include <gtest/gtest.h>
#include <mlfe/core/fem/approximation.h>
#include <mlfe/core/field/field.h>
#include <mlfe/core/surface/iso_surface.h>

#include <cmath>
#include <map>
#include <set>

namespace mlfe {
namespace {

ScalarGrid grid3(int n, double spacing, const std::function<double(double, double, double)>& f) {
  ScalarGrid g;
  g.dim = 3;
  g.dims = {n, n, n};
  g.transform.spacing = {spacing, spacing, spacing};
  g.values.resize(std::size_t(n) * n * n);
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i)
        g.values[i + n * (j + n * k)] = float(f(i * spacing, j * spacing, k * spacing));
  return g;
}

double distance_to(const std::array<double, 3>& c, double x, double y, double z) {
  return std::sqrt((x - c[0]) * (x - c[0]) + (y - c[1]) * (y - c[1]) + (z - c[2]) * (z - c[2]));
}

// Closed, consistently oriented 2-manifold: every directed edge once, its reverse once.
void expect_closed_manifold(const TriangleMesh& m, int euler) {
  std::map<std::pair<std::uint32_t, std::uint32_t>, int> directed;
  for (const auto& t : m.triangles) {
    ASSERT_TRUE(t[0] != t[1] && t[1] != t[2] && t[0] != t[2]) << "degenerate triangle";
    for (int k = 0; k < 3; ++k) directed[{t[k], t[(k + 1) % 3]}]++;
  }
  for (const auto& [e, n] : directed) {
    ASSERT_EQ(n, 1) << "edge used twice in the same direction: orientation flip or non-manifold";
    ASSERT_EQ(directed.count({e.second, e.first}), 1u) << "boundary edge: surface not closed";
  }
  const long long V = m.positions.size(), F = m.triangles.size(), E = directed.size() / 2;
  EXPECT_EQ(V - E + F, euler);
}

// Every triangle's geometric normal (counter-clockwise) points to the side of its first
// vertex's normal.
void expect_winding_follows_normals(const TriangleMesh& m) {
  for (const auto& t : m.triangles) {
    const auto& p0 = m.positions[t[0]];
    const auto& p1 = m.positions[t[1]];
    const auto& p2 = m.positions[t[2]];
    const double ux = p1[0] - p0[0], uy = p1[1] - p0[1], uz = p1[2] - p0[2];
    const double vx = p2[0] - p0[0], vy = p2[1] - p0[1], vz = p2[2] - p0[2];
    const double nx = uy * vz - uz * vy, ny = uz * vx - ux * vz, nz = ux * vy - uy * vx;
    const auto& n = m.normals[t[0]];
    ASSERT_GT(nx * n[0] + ny * n[1] + nz * n[2], 0.0);
  }
}

TEST(IsoSurface, SphereIsAccurateClosedAndOrientedOutward) {
  // A bright ball: f = 20 - distance to the centre (voxels of 1 mm).
  const std::array<double, 3> c{20.3, 19.6, 21.1};
  const double R = 11.0;
  const auto g = grid3(41, 1.0, [&](double x, double y, double z) { return 20.0 - distance_to(c, x, y, z); });
  GridField f(g);
  ApproximationOptions o;
  o.target_rms = 0.02;
  o.max_level = 7;
  const auto a = approximate<3>(f, o);
  IsoExtractor x(a.hierarchy, a.values);
  const auto m = x.extract(20.0 - R, g.transform);
  ASSERT_GT(m.triangles.size(), 500u);
  double worst = 0;
  for (const auto& p : m.positions) {
    const double r = std::sqrt((p[0] - c[0]) * (p[0] - c[0]) + (p[1] - c[1]) * (p[1] - c[1]) +
                               (p[2] - c[2]) * (p[2] - c[2]));
    worst = std::max(worst, std::abs(r - R));
  }
  std::printf("sphere: %zu triangles, worst distance %.3f voxels, %zu vertices in the hierarchy\n",
              m.triangles.size(), worst, a.hierarchy.vertex_count());
  EXPECT_LT(worst, 0.25) << "max distance to the true sphere, voxels";
  expect_closed_manifold(m, 2);
  for (std::size_t i = 0; i < m.positions.size(); ++i) {
    const auto& p = m.positions[i];
    const auto& n = m.normals[i];
    const double radial = (p[0] - c[0]) * n[0] + (p[1] - c[1]) * n[1] + (p[2] - c[2]) * n[2];
    ASSERT_GT(radial, 0.9 * R) << "vertex normal not outward";
  }
  expect_winding_follows_normals(m);
}

TEST(IsoSurface, LinearFieldGivesAnExactPlane) {
  const auto g = grid3(17, 0.5, [](double x, double y, double z) { return 0.3 * x - 0.5 * y + 0.8 * z; });
  GridField f(g);
  auto h = Hierarchy<3>::box({0, 0, 0}, {8, 8, 8});
  h.refine_uniform();
  h.refine_uniform();
  ApproximationOptions o;
  const auto u = solve_best_approximation<3>(h, f, o, {});
  IsoExtractor x(h, u);
  GridTransform t;
  t.origin = {10, -5, 3};
  const auto m = x.extract(0.7, t);
  ASSERT_GT(m.triangles.size(), 10u);
  const double nn = std::sqrt(0.09 + 0.25 + 0.64);
  for (std::size_t i = 0; i < m.positions.size(); ++i) {
    const auto& p = m.positions[i];
    EXPECT_NEAR(0.3 * (p[0] - 10) - 0.5 * (p[1] + 5) + 0.8 * (p[2] - 3), 0.7, 1e-5);
    // Normal toward lower values: -∇f/|∇f|.
    EXPECT_NEAR(m.normals[i][0], -0.3 / nn, 1e-5);
    EXPECT_NEAR(m.normals[i][2], -0.8 / nn, 1e-5);
  }
}

TEST(IsoSurface, IsoValueExactlyOnVerticesLeavesNoCracksOrDegenerateTriangles) {
  // f = |x|² has integer values at lattice vertices; iso 25 passes exactly through (5,0,0),
  // (3,4,0), ... Nodal interpolation on a uniform hierarchy with unit spacing.
  auto h = Hierarchy<3>::box({-8, -8, -8}, {8, 8, 8});
  for (int l = 0; l < 4; ++l) h.refine_uniform();  // lattice spacing 1
  std::vector<double> u(h.vertex_count());
  for (std::size_t v = 0; v < u.size(); ++v) {
    const auto& p = h.point(VertexId(v));
    u[v] = p[0] * p[0] + p[1] * p[1] + p[2] * p[2];
  }
  IsoExtractor x(h, u);
  GridTransform t;
  const auto m = x.extract(25.0, t, {true, -1});
  expect_closed_manifold(m, 2);
  int on_vertex = 0;
  for (const auto& p : m.positions)
    if (std::abs(p[0] * p[0] + p[1] * p[1] + p[2] * p[2] - 25.0) < 1e-4 &&
        std::abs(p[0] - std::round(p[0])) < 1e-6 && std::abs(p[1] - std::round(p[1])) < 1e-6 &&
        std::abs(p[2] - std::round(p[2])) < 1e-6)
      ++on_vertex;
  EXPECT_GT(on_vertex, 6);  // the surface really passes through mesh vertices
}

TEST(IsoSurface, ExtractionSkipsSubtreesThatCannotContainTheIsoValue) {
  auto h = Hierarchy<3>::box({0, 0, 0}, {1, 1, 1});
  for (int l = 0; l < 5; ++l) h.refine_uniform();  // 196608 leaves
  std::vector<double> u(h.vertex_count());
  for (std::size_t v = 0; v < u.size(); ++v) {
    const auto& p = h.point(VertexId(v));
    u[v] = std::sqrt((p[0] - 0.3) * (p[0] - 0.3) + (p[1] - 0.6) * (p[1] - 0.6) + (p[2] - 0.4) * (p[2] - 0.4));
  }
  IsoExtractor x(h, u);
  const auto small = x.extract(0.05, GridTransform{});
  const std::size_t visited_small = x.visited_elements();
  const auto big = x.extract(0.3, GridTransform{});
  const std::size_t visited_big = x.visited_elements();
  EXPECT_GT(small.triangles.size(), 50u);
  EXPECT_LT(visited_small, h.element_count() / 50);
  // Work grows with the output.
  EXPECT_GT(visited_big, 5 * visited_small);
  EXPECT_GT(big.triangles.size(), 5 * small.triangles.size());
}

TEST(IsoSurface, CoarserLevelsGiveCoarserClosedSurfaces) {
  auto h = Hierarchy<3>::box({0, 0, 0}, {1, 1, 1});
  for (int l = 0; l < 4; ++l) h.refine_uniform();
  std::vector<double> u(h.vertex_count());
  for (std::size_t v = 0; v < u.size(); ++v) {
    const auto& p = h.point(VertexId(v));
    u[v] = std::sqrt((p[0] - 0.51) * (p[0] - 0.51) + (p[1] - 0.47) * (p[1] - 0.47) +
                     (p[2] - 0.5) * (p[2] - 0.5));
  }
  IsoExtractor x(h, u);
  std::size_t prev = 0;
  for (int level = 2; level <= 4; ++level) {
    const auto m = x.extract(0.31, GridTransform{}, {true, level});
    expect_closed_manifold(m, 2);
    EXPECT_GT(m.triangles.size(), prev);
    prev = m.triangles.size();
  }
  const auto a = x.extract(0.31, GridTransform{});
  const auto b = x.extract(0.31, GridTransform{});
  EXPECT_EQ(a.positions, b.positions);
  EXPECT_EQ(a.triangles, b.triangles);
}

TEST(IsoSurface, ReflectingTransformKeepsWindingConsistentWithNormals) {
  auto h = Hierarchy<3>::box({0, 0, 0}, {1, 1, 1});
  for (int l = 0; l < 3; ++l) h.refine_uniform();
  std::vector<double> u(h.vertex_count());
  for (std::size_t v = 0; v < u.size(); ++v) {
    const auto& p = h.point(VertexId(v));
    u[v] =
        -std::sqrt((p[0] - 0.5) * (p[0] - 0.5) + (p[1] - 0.5) * (p[1] - 0.5) + (p[2] - 0.5) * (p[2] - 0.5));
  }
  IsoExtractor x(h, u);
  GridTransform t;
  t.direction = {-1, 0, 0, 0, -1, 0, 0, 0, 1};  // a rotation
  GridTransform r;
  r.direction = {-1, 0, 0, 0, 1, 0, 0, 0, 1};  // a reflection
  for (const auto& tr : {t, r}) {
    const auto m = x.extract(-0.3, tr);
    expect_closed_manifold(m, 2);
    expect_winding_follows_normals(m);
  }
}

// A coarse approximation of a ball whose surface u = iso sits off the data's; snapping moves
// every vertex onto f = iso (the trilinear interpolant) without touching the triangles.
TEST(IsoSurface, SnapMovesVerticesOntoTheDataSurfaceWithoutFlips) {
  const std::array<double, 3> c{20.3, 19.6, 21.1};
  const double R = 9.5;
  const auto g = grid3(41, 1.0, [&](double x, double y, double z) {
    // Not a distance field: a radial profile plus ripples u cannot follow at this budget.
    const double r = distance_to(c, x, y, z);
    return 100.0 / (1.0 + std::exp(r - R)) + 4.0 * std::sin(0.9 * x) * std::cos(0.7 * y);
  });
  GridField f(g);
  ApproximationOptions o;
  o.max_vertices = 4000;
  o.target_rms = 0.5;
  const auto a = approximate<3>(f, o);
  IsoExtractor x(a.hierarchy, a.values);
  const double iso = 50.0;
  const auto plain = x.extract(iso, g.transform);
  IsoOptions so;
  so.snap_to = &f;
  so.snap_distance = 1.5;
  const auto snapped = x.extract(iso, g.transform, so);
  ASSERT_EQ(snapped.triangles, plain.triangles);
  ASSERT_EQ(snapped.normals, plain.normals);  // the paper's normals stay
  ASSERT_EQ(snapped.positions.size(), plain.positions.size());
  double plain_err = 0, snapped_err = 0;
  std::size_t moved = 0, on_surface = 0;
  for (std::size_t i = 0; i < plain.positions.size(); ++i) {
    const auto& p = plain.positions[i];
    const auto& q = snapped.positions[i];
    const double e0 = std::abs(f.value({p[0], p[1], p[2]}) - iso),
                 e1 = std::abs(f.value({q[0], q[1], q[2]}) - iso);
    plain_err += e0;
    snapped_err += e1;
    const double d = std::sqrt((p[0] - q[0]) * (p[0] - q[0]) + (p[1] - q[1]) * (p[1] - q[1]) +
                               (p[2] - q[2]) * (p[2] - q[2]));
    EXPECT_LE(d, 1.5 + 1e-4);
    if (d > 0) {
      ++moved;
      on_surface += e1 < 1e-3;  // float positions: f changes by up to ~25 per voxel here
    }
  }
  std::printf("snap: %zu of %zu vertices moved (hierarchy %zu, stop %s), mean |f - iso| %.3f -> %.4f\n",
              moved, plain.positions.size(), a.hierarchy.vertex_count(), a.stop_reason.c_str(),
              plain_err / plain.positions.size(), snapped_err / plain.positions.size());
  EXPECT_GT(moved, plain.positions.size() * 8 / 10);
  EXPECT_GE(on_surface, moved * 99 / 100);
  EXPECT_LT(snapped_err, plain_err / 20);
  // No triangle turns over (the guard reverts the vertices of any that would).
  for (const auto& t : plain.triangles) {
    auto normal = [&](const TriangleMesh& m) {
      const auto &a0 = m.positions[t[0]], &a1 = m.positions[t[1]], &a2 = m.positions[t[2]];
      const double u[3] = {a1[0] - a0[0], a1[1] - a0[1], a1[2] - a0[2]};
      const double v[3] = {a2[0] - a0[0], a2[1] - a0[1], a2[2] - a0[2]};
      return std::array<double, 3>{u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2],
                                   u[0] * v[1] - u[1] * v[0]};
    };
    const auto n0 = normal(plain), n1 = normal(snapped);
    ASSERT_GT(n0[0] * n1[0] + n0[1] * n1[1] + n0[2] * n1[2], 0.0);
  }
  expect_closed_manifold(snapped, 2);
}

TEST(IsoSurface, SnapLeavesExactSurfacesAndOutOfReachCrossingsAlone) {
  // A linear field: u = f exactly, so there is nothing to move.
  const auto g = grid3(9, 1.0, [](double x, double y, double z) { return 0.3 * x + 0.5 * y - 0.2 * z; });
  GridField f(g);
  const auto a = approximate<3>(f, ApproximationOptions{});
  IsoExtractor x(a.hierarchy, a.values);
  IsoOptions so;
  so.snap_to = &f;
  so.snap_distance = 1.0;
  const auto plain = x.extract(1.7, g.transform), snapped = x.extract(1.7, g.transform, so);
  ASSERT_EQ(plain.positions.size(), snapped.positions.size());
  for (std::size_t i = 0; i < plain.positions.size(); ++i)
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(snapped.positions[i][k], plain.positions[i][k], 1e-5);
  // Snapping onto a field whose surface is 3 units away with a reach of 1: nothing moves.
  const auto shifted_grid =
      grid3(9, 1.0, [](double x, double y, double z) { return 0.3 * x + 0.5 * y - 0.2 * z - 1.8; });
  GridField shifted(shifted_grid);  // f' = iso at 0.3x + 0.5y - 0.2z = 3.5: 2.9 units along the normal
  so.snap_to = &shifted;
  EXPECT_EQ(x.extract(1.7, g.transform, so).positions, plain.positions);
  so.snap_distance = 4.0;
  const auto far = x.extract(1.7, g.transform, so);
  std::size_t moved = 0;
  for (std::size_t i = 0; i < far.positions.size(); ++i) moved += far.positions[i] != plain.positions[i];
  EXPECT_GT(moved, 0u);
}

TEST(HeightField, LiftsLeafTrianglesWithUpwardNormals) {
  auto h = Hierarchy<2>::box({0, 0}, {4, 3});
  h.refine_uniform();
  h.refine_uniform();
  std::vector<double> u(h.vertex_count());
  for (std::size_t v = 0; v < u.size(); ++v) u[v] = 2 + 0.5 * h.point(VertexId(v))[0];
  GridTransform t;
  t.origin = {1, 2, 3};
  const auto m = height_field_surface(h, u, t, 2.0);
  EXPECT_EQ(m.triangles.size(), h.leaves().size());
  for (std::size_t i = 0; i < m.positions.size(); ++i) {
    EXPECT_NEAR(m.positions[i][2], 3 + 2.0 * (2 + 0.5 * (m.positions[i][0] - 1)), 1e-5);
    EXPECT_GT(m.normals[i][2], 0.0f);
  }
}

}  // namespace
}  // namespace mlfe

namespace mlfe {
namespace {

// Iso-aware refinement (ApproximationOptions::iso_values): a loose RMS target leaves the
// surface of a sharp ball coarse; naming the iso-value drives the surface error down.
TEST(IsoAwareRefinement, PullsTheSurfaceOntoTheDataWhereThePlainTargetDoesNot) {
  const std::array<double, 3> c{16.2, 15.7, 16.6};
  const double R = 9.0;
  const auto g = grid3(33, 1.0, [&](double x, double y, double z) {
    const double r = distance_to(c, x, y, z);
    return 100.0 * std::tanh((R - r) / 1.5);
  });
  GridField f(g);
  auto worst_distance = [&](bool iso_aware) {
    ApproximationOptions o;
    o.target_rms = 10.0;  // 5% of the range
    o.start_level = 1;
    if (iso_aware) {
      o.iso_values = {0.0};
      o.surface_tolerance = 0.2;
    }
    const auto a = approximate<3>(f, o);
    IsoExtractor x(a.hierarchy, a.values);
    const auto m = x.extract(0.0, g.transform);
    double worst = 0;
    for (const auto& p : m.positions) {
      const double r = std::sqrt((p[0] - c[0]) * (p[0] - c[0]) + (p[1] - c[1]) * (p[1] - c[1]) +
                                 (p[2] - c[2]) * (p[2] - c[2]));
      worst = std::max(worst, std::abs(r - R));
    }
    std::printf("iso-aware %d: %zu vertices, %zu triangles, worst surface distance %.3f voxels\n",
                int(iso_aware), a.hierarchy.vertex_count(), m.triangles.size(), worst);
    return worst;
  };
  const double plain = worst_distance(false);
  const double aware = worst_distance(true);
  EXPECT_GT(plain, 0.5);
  EXPECT_LT(aware, 0.35);
}

}  // namespace
}  // namespace mlfe
