#include <gtest/gtest.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/simplify/surface_simplification.h>
#include <mlfe/core/surface/surface_fitting.h>
#include <tbb/global_control.h>

#include <cmath>
#include <map>
#include <random>
#include <set>
#include <utility>

#include "tests/test_meshes.h"

namespace mlfe {
namespace {

using test::icosphere;
using test::one_sided_hausdorff;

// A bumpy sphere (radius 10 with a radial ripple and noise): a surface whose simplification
// leaves room for a better fit.
TriangleMesh bumpy_sphere() {
  TriangleMesh m = icosphere(5, 10.0f);
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> noise(-0.03f, 0.03f);
  for (auto& p : m.positions) {
    const float r = std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
    const float s = (10.0f + 0.3f * std::sin(p[0]) * std::cos(p[1]) + noise(rng)) / r;
    for (auto& c : p) c *= s;
  }
  return m;
}

TriangleMesh simplified(const TriangleMesh& dense, double tol) {
  SimplifyOptions o;
  o.tolerance = tol;
  o.placement = Placement::kOptimal;
  o.min_triangles = dense.triangles.size() / 10;
  return simplify_within(dense, o);
}

TEST(SurfaceFit, LowersTheErrorAndKeepsTheBoundBothWays) {
  const TriangleMesh dense = bumpy_sphere();
  const double tol = 0.15;
  const TriangleMesh before = simplified(dense, tol);
  TriangleMesh after = before;
  SurfaceFitOptions o;
  o.tolerance = tol;
  const SurfaceFitReport r = fit_surface(after, dense, o);
  EXPECT_EQ(r.samples, dense.positions.size());
  EXPECT_GT(r.moved, before.positions.size() / 2);
  EXPECT_LT(r.rms_after, 0.9 * r.rms_before) << r.rms_before << " -> " << r.rms_after;
  // Connectivity untouched, the bound held both ways (every dense vertex near the result, every
  // vertex of the result near the dense surface).
  EXPECT_EQ(after.triangles, before.triangles);
  EXPECT_LE(one_sided_hausdorff(dense, after), tol * 1.001);
  EXPECT_LE(one_sided_hausdorff(after, dense), tol * 1.001);
  // The mean distance of the dense vertices falls too (the fit's purpose), measured independently.
  auto mean_to = [&](const TriangleMesh& m) {
    double sum = 0;
    for (std::size_t i = 0; i < dense.positions.size(); i += 7) {
      TriangleMesh one;
      one.positions = {dense.positions[i]};
      sum += one_sided_hausdorff(one, m);
    }
    return sum;
  };
  EXPECT_LT(mean_to(after), mean_to(before));
}

TEST(SurfaceFit, SameResultWithOneAndTwoThreads) {
  const TriangleMesh dense = bumpy_sphere();
  const TriangleMesh coarse = simplified(dense, 0.15);
  SurfaceFitOptions o;
  o.tolerance = 0.15;
  TriangleMesh one = coarse, two = coarse;
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 1);
    fit_surface(one, dense, o);
  }
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 2);
    fit_surface(two, dense, o);
  }
  EXPECT_EQ(one.positions, two.positions);
}

TEST(SurfaceFit, BoundaryVerticesStay) {
  // The upper half of the sphere: an open surface whose rim must not move.
  const TriangleMesh full = bumpy_sphere();
  TriangleMesh dense = full;
  dense.triangles.clear();
  for (const auto& t : full.triangles)
    if (full.positions[t[0]][2] > 0 && full.positions[t[1]][2] > 0 && full.positions[t[2]][2] > 0)
      dense.triangles.push_back(t);
  TriangleMesh coarse = simplified(dense, 0.15);
  const TriangleMesh before = coarse;
  SurfaceFitOptions o;
  o.tolerance = 0.15;
  const SurfaceFitReport r = fit_surface(coarse, dense, o);
  EXPECT_GT(r.moved, 0u);
  std::map<std::pair<std::uint32_t, std::uint32_t>, int> use;
  for (const auto& t : before.triangles)
    for (int k = 0; k < 3; ++k) ++use[std::minmax(t[k], t[(k + 1) % 3])];
  std::size_t rim = 0;
  for (const auto& [e, n] : use)
    if (n == 1) {
      EXPECT_EQ(coarse.positions[e.first], before.positions[e.first]);
      EXPECT_EQ(coarse.positions[e.second], before.positions[e.second]);
      ++rim;
    }
  EXPECT_GT(rim, 10u);
}

TEST(SurfaceFit, RejectsABadTolerance) {
  TriangleMesh m = icosphere(1, 1.0f);
  const TriangleMesh dense = icosphere(3, 1.0f);
  SurfaceFitOptions o;
  o.tolerance = 0;
  EXPECT_THROW(fit_surface(m, dense, o), Error);
  o.tolerance = std::nan("");
  EXPECT_THROW(fit_surface(m, dense, o), Error);
}

}  // namespace
}  // namespace mlfe
