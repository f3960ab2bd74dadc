// The min/max pyramid, the surface-gap estimator and surface-driven refinement.
#include <gtest/gtest.h>
#include <mlfe/core/fem/approximation.h>
#include <mlfe/core/fem/surface_estimator.h>
#include <mlfe/core/field/field.h>
#include <mlfe/core/field/minmax_pyramid.h>
#include <tbb/global_control.h>

#include <cmath>
#include <functional>
#include <random>

namespace mlfe {
namespace {

ScalarGrid grid3(std::array<std::int64_t, 3> n, const std::function<double(double, double, double)>& f) {
  ScalarGrid g;
  g.dim = 3;
  g.dims = n;
  g.values.resize(static_cast<std::size_t>(g.voxel_count()));
  for (std::int64_t k = 0; k < n[2]; ++k)
    for (std::int64_t j = 0; j < n[1]; ++j)
      for (std::int64_t i = 0; i < n[0]; ++i)
        g.values[i + n[0] * (j + n[1] * k)] = float(f(double(i), double(j), double(k)));
  return g;
}

TEST(MinMaxPyramid, RangeContainsEverySampleOfTheBoxAndIsExactForWholeBlocks) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1, 1);
  const ScalarGrid g = grid3({37, 21, 14}, [&](double, double, double) { return u(rng); });
  const MinMaxPyramid p(g);
  std::uniform_real_distribution<double> x(-2, 40);
  for (int t = 0; t < 2000; ++t) {
    std::array<double, 3> a{x(rng), x(rng) * 0.6, x(rng) * 0.4}, b{x(rng), x(rng) * 0.6, x(rng) * 0.4};
    const auto r = p.range(a, b);
    // Brute force over the samples of every cell the clamped box overlaps.
    float lo = 1e30f, hi = -1e30f;
    std::array<std::int64_t, 2> c[3];
    for (int ax = 0; ax < 3; ++ax) {
      const double cells = double(g.dims[ax] - 1);
      const double l = std::clamp(std::min(a[ax], b[ax]), 0.0, cells),
                   h = std::clamp(std::max(a[ax], b[ax]), 0.0, cells);
      c[ax] = {std::min<std::int64_t>(std::int64_t(std::floor(l)), g.dims[ax] - 2),
               std::max<std::int64_t>(std::min<std::int64_t>(std::int64_t(std::ceil(h)), g.dims[ax] - 1), 0)};
    }
    for (std::int64_t k = c[2][0]; k <= std::max(c[2][1], c[2][0] + 1); ++k)
      for (std::int64_t j = c[1][0]; j <= std::max(c[1][1], c[1][0] + 1); ++j)
        for (std::int64_t i = c[0][0]; i <= std::max(c[0][1], c[0][0] + 1); ++i) {
          if (i >= g.dims[0] || j >= g.dims[1] || k >= g.dims[2]) continue;
          lo = std::min(lo, g.at(i, j, k));
          hi = std::max(hi, g.at(i, j, k));
        }
    ASSERT_LE(r[0], lo) << t;
    ASSERT_GE(r[1], hi) << t;
  }
  // The whole grid: exactly its range.
  const auto all = p.range({0, 0, 0}, {36, 20, 13});
  const auto vr = g.value_range();
  EXPECT_EQ(all[0], vr[0]);
  EXPECT_EQ(all[1], vr[1]);
}

TEST(MinMaxPyramid, GridFieldAnswersInTheLocalFrame) {
  ScalarGrid g = grid3({20, 20, 20}, [](double i, double, double) { return i; });
  g.transform.spacing = {2.0, 1.0, 0.5};
  const GridField f(g);
  const auto r = f.range_in_box({10.0, 3, 1.0}, {12.0, 4, 2.0});  // x in [5, 6] voxels, a small box
  EXPECT_LE(r[0], 5.0);
  EXPECT_GE(r[1], 6.0);
  EXPECT_GE(r[0], 3.0);  // not the whole grid's range
  EXPECT_LE(r[1], 8.0);
}

using Tet = std::array<std::array<double, 3>, 4>;
const Tet kTet = {{{0, 0, 0}, {8, 0, 0}, {8, 8, 0}, {8, 8, 8}}};  // a Kuhn simplex of an 8-voxel cube

std::array<double, 4> corners_of(const Field& f, const Tet& t) {
  std::array<double, 4> c;
  for (int i = 0; i < 4; ++i) c[i] = f.value({t[i][0], t[i][1], t[i][2]});
  return c;
}

TEST(SurfaceGap, LinearDataIsWithinAndAShiftedPlaneIsDistant) {
  const ScalarGrid g =
      grid3({12, 12, 12}, [](double i, double j, double k) { return i + 0.5 * j - 0.25 * k; });
  const GridField f(g);
  const auto c = corners_of(f, kTet);
  EXPECT_EQ(surface_gap<3>(kTet, c, f, {5.0}, 0.25, 1.0), SurfaceGap::kWithin);
  // The linear function's surface shifted by 2 along x (|∇| = 1.15): ~1.7 voxels apart.
  auto shifted = c;
  for (double& v : shifted) v += 2.0;
  EXPECT_EQ(surface_gap<3>(kTet, shifted, f, {5.0}, 1.0, 1.0), SurfaceGap::kDistant);
  EXPECT_EQ(surface_gap<3>(kTet, shifted, f, {5.0}, 2.0, 1.0), SurfaceGap::kWithin);
}

TEST(SurfaceGap, ASmallBlobInsideTheElementIsMissingAndFarDataIsNot) {
  // A sphere of radius 1.2 voxels around (6, 4, 2), inside kTet, on a flat background.
  const ScalarGrid g = grid3({12, 12, 12}, [](double i, double j, double k) {
    const double r = std::sqrt((i - 6) * (i - 6) + (j - 4) * (j - 4) + (k - 2) * (k - 2));
    return r < 1.2 ? 10.0 : 0.0;
  });
  const GridField f(g);
  const auto c = corners_of(f, kTet);  // all 0: the interpolant has no surface at 5
  EXPECT_EQ(surface_gap<3>(kTet, c, f, {5.0}, 0.5, std::sqrt(3.0)), SurfaceGap::kMissing);
  EXPECT_EQ(surface_gap<3>(kTet, c, f, {20.0}, 0.5, std::sqrt(3.0)), SurfaceGap::kWithin);
}

// A big sphere and, far from it, a blob of two voxels across: the surface-driven build keeps
// both, refines only near the surfaces, and gives the same hierarchy with 1 and 2 threads.
ScalarGrid spheres() {
  return grid3({64, 64, 64}, [](double i, double j, double k) {
    const double big = 20.0 - std::sqrt((i - 24) * (i - 24) + (j - 24) * (j - 24) + (k - 24) * (k - 24));
    const double small = 1.0 - std::sqrt((i - 54) * (i - 54) + (j - 54) * (j - 54) + (k - 54) * (k - 54));
    return std::max(big, small);
  });
}

TEST(SurfaceDriven, RefinesNearTheSurfacesOnlyAndFindsTheSmallPart) {
  const ScalarGrid g = spheres();
  const GridField f(g);
  ApproximationOptions o;
  o.iso_values = {0.0};
  o.surface_driven = true;
  const auto a = approximate<3>(f, o);
  EXPECT_EQ(a.stop_reason, "surfaces within tolerance");
  ASSERT_FALSE(a.surface_passes.empty());
  const auto& h = a.hierarchy;
  // u has the small blob: some leaf near (54, 54, 54) has a vertex value above 0.
  bool blob = false, far_refined = false;
  for (ElemId e : h.leaves()) {
    double lo = 1e300;
    bool near_blob = false;
    for (VertexId v : h.cell(e)) {
      const auto& p = h.point(v);
      const double d =
          std::sqrt((p[0] - 54) * (p[0] - 54) + (p[1] - 54) * (p[1] - 54) + (p[2] - 54) * (p[2] - 54));
      near_blob |= d < 3;
      lo = std::min(lo, d);
      if (near_blob && a.values[v.value] > 0) blob = true;
    }
    // Far from both surfaces (the corner at the origin is 21 voxels from the big sphere):
    const auto& p = h.point(h.cell(e)[0]);
    if (std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]) < 6 && h.level(e) > 4) far_refined = true;
  }
  EXPECT_TRUE(blob);
  EXPECT_FALSE(far_refined);
  // Far fewer leaves than a uniform mesh of voxel-sized elements (6 per voxel).
  EXPECT_LT(h.leaves().size(), 6u * 63 * 63 * 63 / 4);
}

TEST(SurfaceDriven, SameHierarchyAndValuesWithOneAndTwoThreads) {
  const ScalarGrid g = spheres();
  const GridField f(g);
  ApproximationOptions o;
  o.iso_values = {0.0, 5.0};
  o.surface_driven = true;
  Approximation<3> a, b;
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 1);
    a = approximate<3>(f, o);
  }
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 2);
    b = approximate<3>(f, o);
  }
  EXPECT_EQ(a.hierarchy.cells(), b.hierarchy.cells());
  EXPECT_EQ(a.values, b.values);
}

TEST(SurfaceDriven, MemoryBudgetStopsRefinementWithItsReason) {
  const ScalarGrid g = spheres();
  const GridField f(g);
  ApproximationOptions o;
  o.iso_values = {0.0};
  o.surface_driven = true;
  const auto full = approximate<3>(f, o);
  // Between the uniform start mesh and the full one.
  const auto& start = full.surface_passes.front();
  o.max_memory_bytes =
      (estimated_memory_bytes(3, start.vertices, start.elements) +
       estimated_memory_bytes(3, full.hierarchy.vertex_count(), full.hierarchy.leaves().size())) /
      2;
  const auto cut = approximate<3>(f, o);
  EXPECT_TRUE(cut.memory_limited);
  EXPECT_EQ(cut.stop_reason, "memory budget");
  EXPECT_LT(cut.hierarchy.vertex_count(), full.hierarchy.vertex_count());
  EXPECT_LE(estimated_memory_bytes(3, cut.hierarchy.vertex_count(), cut.hierarchy.leaves().size()),
            o.max_memory_bytes);
}

}  // namespace
}  // namespace mlfe
