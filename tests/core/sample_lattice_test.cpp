// The hierarchy on the samples' lattice (sample_lattice.h): vertices on samples, nothing below
// the sample spacing, every sample owned once, the finest level exact, errors at the samples.
#include <gtest/gtest.h>
#include <mlfe/core/fem/approximation.h>
#include <mlfe/core/fem/fe_assembly.h>
#include <mlfe/core/fem/sample_lattice.h>
#include <mlfe/core/field/field.h>
#include <mlfe/core/field/noise_estimate.h>
#include <mlfe/core/surface/iso_surface.h>
#include <tbb/global_control.h>

#include <cmath>
#include <cstdint>
#include <random>

#include "tests/core/test_hierarchies.h"

namespace mlfe {
namespace {

using test::random_grid;

// Index coordinates of a local-frame point, CHECKing they are integers.
template <int D>
std::array<std::int64_t, 3> index_of(const std::array<double, D>& p, const SampleLattice& lat) {
  std::array<std::int64_t, 3> q{0, 0, 0};
  for (int a = 0; a < D; ++a) {
    const double x = p[a] / lat.spacing[a];
    EXPECT_NEAR(x, std::nearbyint(x), 1e-9);
    q[a] = static_cast<std::int64_t>(std::nearbyint(x));
  }
  return q;
}

TEST(SampleLattice, LevelCoversTheLongestAxis) {
  ScalarGrid g = random_grid(3, {181, 217, 62}, {1, 1, 3}, 1, false);
  const SampleLattice lat = sample_lattice(g);
  EXPECT_EQ(lat.level, 8);  // 2^8 = 256 >= 216
  EXPECT_EQ(lat.width, 256);
  EXPECT_DOUBLE_EQ(lat.box_extent()[2], 768.0);
  EXPECT_DOUBLE_EQ(lat.data_extent()[1], 216.0);
  g.dims = {2, 2, 2};
  g.values.assign(8, 0.f);
  EXPECT_EQ(sample_lattice(g).level, 0);
}

// Every sample is owned by exactly one leaf, whatever the grading of the mesh.
template <int D>
void expect_each_sample_owned_once(unsigned seed) {
  const ScalarGrid g = random_grid(D, {13, 7, 10}, {0.7, 1.3, 2.1}, seed, false);
  const GridField f(g);
  ApproximationOptions o;
  o.target_rms = 5.0;  // a graded, partly refined mesh
  o.max_iterations = 3;
  const Approximation<D> a = approximate<D>(f, o);
  ASSERT_TRUE(a.on_lattice);
  const auto leaves = a.hierarchy.leaves();
  const auto in = compute_element_integrals<D>(a.hierarchy, leaves, f, 1.0, nullptr, &a.lattice);
  std::int64_t owned = 0;
  for (const auto& i : in) owned += i.points;
  EXPECT_EQ(owned, g.voxel_count());
  // Corners on the lattice, no level below L.
  for (const auto& p : a.hierarchy.points()) index_of<D>(p, a.lattice);
  EXPECT_LE(a.hierarchy.max_level(), a.lattice.level);
}

TEST(SampleLattice, EverySampleOwnedOnce2D) { expect_each_sample_owned_once<2>(3); }
TEST(SampleLattice, EverySampleOwnedOnce3D) { expect_each_sample_owned_once<3>(4); }

// With a target no coarser mesh meets, the build reaches level L and reproduces every sample:
// the finest level interpolates the data.
template <int D>
void expect_finest_level_exact(std::array<std::int64_t, 3> dims, std::array<double, 3> spacing) {
  const ScalarGrid g = random_grid(D, dims, spacing, 7, false);
  const GridField f(g);
  ApproximationOptions o;
  o.target_rms = 1e-9;
  const Approximation<D> a = approximate<D>(f, o);
  ASSERT_TRUE(a.on_lattice);
  EXPECT_LE(a.iterations.back().rms_error, 1e-6);
  EXPECT_EQ(a.hierarchy.max_level(), a.lattice.level);
  // Every sample is a vertex and carries the sample's value.
  std::vector<char> found(static_cast<std::size_t>(g.voxel_count()), 0);
  for (std::size_t v = 0; v < a.hierarchy.vertex_count(); ++v) {
    const auto q = index_of<D>(a.hierarchy.points()[v], a.lattice);
    bool in = true;
    for (int k = 0; k < D; ++k) in = in && q[k] < g.dims[k];
    if (!in) continue;
    const auto at = static_cast<std::size_t>(q[0] + g.dims[0] * (q[1] + g.dims[1] * q[2]));
    EXPECT_NEAR(a.values[v], g.values[at], 1e-6);
    found[at] = 1;
  }
  for (std::size_t i = 0; i < found.size(); ++i) EXPECT_TRUE(found[i]) << "sample " << i << " is no vertex";
}

TEST(SampleLattice, FinestLevelInterpolatesOddAnisotropic2D) {
  expect_finest_level_exact<2>({9, 14, 1}, {0.5, 1.7, 1});
}
TEST(SampleLattice, FinestLevelInterpolatesOddAnisotropic3D) {
  expect_finest_level_exact<3>({7, 5, 9}, {0.7, 1.3, 2.1});
}

// A checkerboard has detail at every sample: the build ends at level L (one-voxel elements),
// never below, with a bounded mesh (it used to build 8.7 M elements for 4 096 voxels).
TEST(SampleLattice, CheckerboardStopsAtTheSampleSpacing) {
  ScalarGrid g;
  g.dims = {16, 16, 16};
  g.values.resize(4096);
  for (int k = 0; k < 16; ++k)
    for (int j = 0; j < 16; ++j)
      for (int i = 0; i < 16; ++i) g.values[i + 16 * (j + 16 * k)] = float((i + j + k) % 2);
  const GridField f(g);
  ApproximationOptions o;
  o.target_rms = 0.005;  // 0.5 % of the range
  const Approximation<3> a = approximate<3>(f, o);
  EXPECT_EQ(a.hierarchy.max_level(), a.lattice.level);
  // The padded cube is 16 samples wide: at most the full lattice of 16^3 points.
  EXPECT_LE(a.hierarchy.vertex_count(), std::size_t(17 * 17 * 17));
  EXPECT_LE(a.hierarchy.leaves().size(), std::size_t(6 * 16 * 16 * 16));
  EXPECT_LE(a.iterations.back().rms_error, 0.005);
}

// A single-sample spike in a flat volume is a surface of the data: the surface-driven build on
// the lattice has a vertex on it and extracts a closed surface around it.
TEST(SampleLattice, SingleSampleSpikeHasItsSurface) {
  ScalarGrid g;
  g.dims = {33, 30, 27};
  g.values.assign(static_cast<std::size_t>(g.voxel_count()), 0.f);
  g.values[static_cast<std::size_t>(17 + 33 * (11 + 30 * 13))] = 100.f;
  const GridField f(g);
  ApproximationOptions o;
  o.iso_values = {50};
  o.surface_driven = true;
  o.solve = false;
  const Approximation<3> a = approximate<3>(f, o);
  IsoExtractor x(a.hierarchy, a.data_values);
  IsoOptions io;
  io.clip = true;
  io.clip_to = a.data_extent;
  const TriangleMesh m = x.extract(50, GridTransform{}, io);
  ASSERT_FALSE(m.triangles.empty());
  for (const auto& p : m.positions) {
    EXPECT_NEAR(p[0], 17, 1.0);
    EXPECT_NEAR(p[1], 11, 1.0);
    EXPECT_NEAR(p[2], 13, 1.0);
  }
}

// The padding is never refined and never shows: a surface of data that reaches the volume's
// upper faces ends on them (clipped), nothing lies beyond the data's box.
TEST(SampleLattice, SurfacesClipToTheDataBox) {
  ScalarGrid g;
  g.dims = {21, 19, 23};  // padded to 32^3
  g.values.resize(static_cast<std::size_t>(g.voxel_count()));
  for (std::int64_t k = 0; k < 23; ++k)
    for (std::int64_t j = 0; j < 19; ++j)
      for (std::int64_t i = 0; i < 21; ++i)
        g.values[static_cast<std::size_t>(i + 21 * (j + 19 * k))] = float(i + 0.5 * j + 0.25 * k);
  const GridField f(g);
  ApproximationOptions o;
  o.iso_values = {18.3};
  o.surface_driven = true;
  o.solve = false;
  const Approximation<3> a = approximate<3>(f, o);
  IsoExtractor x(a.hierarchy, a.data_values);
  IsoOptions io;
  io.clip = true;
  io.clip_to = a.data_extent;
  const TriangleMesh m = x.extract(18.3, GridTransform{}, io);
  ASSERT_FALSE(m.triangles.empty());
  double xmax = 0;
  for (const auto& p : m.positions) {
    for (int k = 0; k < 3; ++k) EXPECT_LE(p[k], a.data_extent[k] + 1e-6);
    xmax = std::max(xmax, double(p[0]));
  }
  // The plane i + j/2 + k/4 = 18.3 reaches x = 18.3 inside the box.
  EXPECT_GT(xmax, 18.0);
}

TEST(SampleLattice, SameBytesWithOneAndTwoThreads) {
  const ScalarGrid g = random_grid(3, {17, 12, 15}, {1, 1, 2}, 11, false);
  const GridField f(g);
  ApproximationOptions o;
  o.target_rms = 10.0;
  std::vector<double> v1, v2;
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 1);
    v1 = approximate<3>(f, o).values;
  }
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 2);
    v2 = approximate<3>(f, o).values;
  }
  EXPECT_EQ(v1, v2);
}

TEST(NoiseEstimate, FindsTheDeviationOfWhiteNoiseOnASmoothField) {
  ScalarGrid g;
  g.dims = {64, 64, 64};
  g.values.resize(static_cast<std::size_t>(g.voxel_count()));
  std::mt19937 rng(5);
  std::normal_distribution<float> n(0.f, 3.f);
  for (std::int64_t k = 0; k < 64; ++k)
    for (std::int64_t j = 0; j < 64; ++j)
      for (std::int64_t i = 0; i < 64; ++i)
        g.values[static_cast<std::size_t>(i + 64 * (j + 64 * k))] =
            float(100 + 50 * std::sin(0.05 * double(i)) * std::cos(0.04 * double(j))) + n(rng);
  EXPECT_NEAR(estimate_noise_sigma(g), 3.0, 0.3);
  // Constant data has no noise.
  std::fill(g.values.begin(), g.values.end(), 7.f);
  EXPECT_EQ(estimate_noise_sigma(g), 0.0);
}

}  // namespace
}  // namespace mlfe
