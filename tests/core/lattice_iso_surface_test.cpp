// lattice_iso_surface: marching cubes on the samples (core/surface/lattice_iso_surface.cpp).
#include <gtest/gtest.h>
#include <mlfe/core/surface/iso_surface.h>
#include <mlfe/core/surface/triangle_mesh.h>
#include <tbb/global_control.h>

#include <cmath>
#include <functional>
#include <random>

#include "tests/core/test_hierarchies.h"

namespace mlfe {
namespace {

using test::function_grid;

// Closed or cut only by the volume's faces, welded, manifold, consistently oriented.
void expect_clean(const TriangleMesh& m, const ScalarGrid& g, bool closed) {
  const std::array<double, 3> lo{0, 0, 0};
  const std::array<double, 3> hi{double(g.dims[0] - 1) * g.transform.spacing[0],
                                 double(g.dims[1] - 1) * g.transform.spacing[1],
                                 double(g.dims[2] - 1) * g.transform.spacing[2]};
  const MeshTopology t = mesh_topology(m, &lo, &hi, 1e-5);
  EXPECT_TRUE(t.welded_manifold()) << t.duplicate_vertices << " duplicates, " << t.degenerate_triangles
                                   << " degenerate, " << t.non_manifold_edges << " non-manifold edges, "
                                   << t.non_manifold_vertices << " vertices, " << t.inconsistent_edges
                                   << " flips";
  EXPECT_EQ(t.boundary_edges_off_box, 0u);
  if (closed) EXPECT_EQ(t.boundary_edges, 0u);
}

// Counter-clockwise triangles face where their vertices' normals point.
std::size_t winding_against_normals(const TriangleMesh& m) {
  std::size_t bad = 0;
  for (const auto& t : m.triangles) {
    const auto &a = m.positions[t[0]], &b = m.positions[t[1]], &c = m.positions[t[2]];
    const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]},
                 v[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    const double n[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
    double s = 0;
    for (int k = 0; k < 3; ++k)
      for (int x = 0; x < 3; ++x) s += n[x] * m.normals[t[k]][x];
    bad += s <= 0;
  }
  return bad;
}

TEST(LatticeIsoSurface, SphereIsClosedAccurateAndFacesLowerValues) {
  const double r = 6.3;
  const ScalarGrid g = function_grid({19, 20, 21}, {1, 1, 1}, [&](auto i, auto j, auto k) {
    return 100 - std::sqrt((i - 9.2) * (i - 9.2) + (j - 9.6) * (j - 9.6) + (k - 10.1) * (k - 10.1)) * 10;
  });
  const TriangleMesh m = lattice_iso_surface(g, 100 - r * 10);
  ASSERT_GT(m.triangles.size(), 500u);
  expect_clean(m, g, true);
  // Vertices interpolate a distance field linearly along lattice edges: within a tenth of a
  // voxel of the sphere.
  for (const auto& p : m.positions) {
    const double d =
        std::sqrt((p[0] - 9.2) * (p[0] - 9.2) + (p[1] - 9.6) * (p[1] - 9.6) + (p[2] - 10.1) * (p[2] - 10.1));
    EXPECT_NEAR(d, r, 0.1);
  }
  // Normals toward lower values: outward; triangles wound to match.
  for (std::size_t v = 0; v < m.positions.size(); ++v) {
    const auto& p = m.positions[v];
    const auto& n = m.normals[v];
    EXPECT_GT((p[0] - 9.2) * n[0] + (p[1] - 9.6) * n[1] + (p[2] - 10.1) * n[2], 0.0);
  }
  EXPECT_EQ(winding_against_normals(m), 0u);
  // Toward higher values: the same surface wound the other way.
  IsoOptions up;
  up.normals_toward_higher = true;
  const TriangleMesh n = lattice_iso_surface(g, 100 - r * 10, up);
  ASSERT_EQ(n.triangles.size(), m.triangles.size());
  EXPECT_EQ(n.triangles[0][0], m.triangles[0][0]);
  EXPECT_EQ(n.triangles[0][1], m.triangles[0][2]);
  EXPECT_EQ(winding_against_normals(n), 0u);
}

TEST(LatticeIsoSurface, NoiseGivesAClosedManifoldSurfaceWhateverTheAmbiguousFaces) {
  // Random values make every ambiguous face and cube configuration occur; the border below the
  // iso-value closes the surface.
  for (unsigned seed : {1u, 2u, 3u}) {
    std::mt19937 rng(seed);
    std::normal_distribution<double> noise(0, 1);
    const std::array<std::int64_t, 3> dims{13, 11, 9};
    const ScalarGrid g = function_grid(dims, {1, 1, 1}, [&](auto i, auto j, auto k) {
      const bool border =
          i == 0 || j == 0 || k == 0 || i == dims[0] - 1 || j == dims[1] - 1 || k == dims[2] - 1;
      const double x = noise(rng);
      return border ? -5.0 : x;
    });
    const TriangleMesh m = lattice_iso_surface(g, 0.0);
    ASSERT_GT(m.triangles.size(), 1000u);
    expect_clean(m, g, true);
    // Normals toward lower values point out of the region above: the enclosed volume is positive
    // and at most the volume of the samples above (each owns at most a voxel).
    double volume = 0;
    for (const auto& t : m.triangles) {
      const auto &a = m.positions[t[0]], &b = m.positions[t[1]], &c = m.positions[t[2]];
      volume += (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) +
                 a[2] * (b[0] * c[1] - b[1] * c[0])) /
                6;
    }
    std::size_t above = 0;
    for (float v : g.values) above += v > 0;
    EXPECT_GT(volume, 0.0);
    EXPECT_LT(volume, double(above));
  }
}

TEST(LatticeIsoSurface, OddAnisotropicVolumeIsCutOnlyAtItsFacesAndVerticesLieOnLatticeEdges) {
  const std::array<double, 3> sp{0.7, 1.3, 2.9};
  const ScalarGrid g = function_grid({8, 13, 6}, sp, [&](auto i, auto j, auto k) {
    return std::sin(0.9 * i) + std::cos(0.7 * j) + 0.4 * k + 0.1 * ((i * 7 + j * 3 + k) % 5);
  });
  const TriangleMesh m = lattice_iso_surface(g, 1.1);
  ASSERT_GT(m.triangles.size(), 50u);
  expect_clean(m, g, false);
  for (const auto& p : m.positions) {
    int on_lattice = 0;
    for (int a = 0; a < 3; ++a) {
      const double q = p[a] / sp[a];
      on_lattice += std::abs(q - std::round(q)) < 1e-4;
    }
    EXPECT_EQ(on_lattice, 2) << "a crossing lies on a lattice edge: two coordinates on samples";
  }
}

TEST(LatticeIsoSurface, SingleSampleSpikeAndIsoValuesOnSamples) {
  // One sample above a flat volume: its surface is the octahedron around it.
  const ScalarGrid spike = function_grid(
      {5, 5, 5}, {1, 1, 1}, [](auto i, auto j, auto k) { return i == 2 && j == 2 && k == 2 ? 10.0 : 0.0; });
  const TriangleMesh m = lattice_iso_surface(spike, 5.0);
  EXPECT_EQ(m.positions.size(), 6u);
  EXPECT_EQ(m.triangles.size(), 8u);
  expect_clean(m, spike, true);
  // Integer data at an integer iso-value: crossings at samples move off them, no duplicates.
  const ScalarGrid steps =
      function_grid({9, 9, 9}, {1, 1, 1}, [](auto i, auto j, auto k) { return double((i + j + k) % 4); });
  const TriangleMesh s = lattice_iso_surface(steps, 2.0);
  ASSERT_GT(s.triangles.size(), 0u);
  expect_clean(s, steps, false);
}

TEST(LatticeIsoSurface, SameBytesWithOneAndTwoThreadsAndSmallPartsDropped) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(0, 1);
  const ScalarGrid g = function_grid({40, 33, 27}, {1, 1, 1}, [&](auto, auto, auto) { return u(rng); });
  TriangleMesh one, two;
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 1);
    one = lattice_iso_surface(g, 0.7);
  }
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 2);
    two = lattice_iso_surface(g, 0.7);
  }
  EXPECT_EQ(one.triangles, two.triangles);
  EXPECT_EQ(one.positions, two.positions);
  EXPECT_EQ(one.normals, two.normals);
  // Isolated samples above 0.7 make specks of 8 triangles in up to 8 cells; drop them.
  Dropped d;
  IsoOptions o;
  o.min_component = 9;
  o.dropped = &d;
  const TriangleMesh big = lattice_iso_surface(g, 0.7, o);
  EXPECT_GT(d.parts, 0u);
  EXPECT_EQ(big.triangles.size() + d.triangles, one.triangles.size());
  EXPECT_LT(big.positions.size(), one.positions.size());
}

}  // namespace
}  // namespace mlfe
