// Least squares at the samples applied from the samples (sampled_least_squares.h): the same
// operator, load and errors as the matrix assembled from the per-element sampled integrals, on
// graded meshes with coarse leaves (kept as sums) and fine ones (kept as samples), across
// refinements, and the same bits whatever the thread count.
#include <gtest/gtest.h>
#include <mlfe/core/fem/fe_assembly.h>
#include <mlfe/core/fem/sample_lattice.h>
#include <mlfe/core/fem/sampled_least_squares.h>
#include <mlfe/core/field/field.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "tests/core/test_hierarchies.h"

namespace mlfe {
namespace {

using test::random_grid;

template <int D>
Hierarchy<D> lattice_box(const SampleLattice& lat) {
  typename Hierarchy<D>::Point lo, hi;
  const auto ext = lat.box_extent();
  for (int a = 0; a < D; ++a) {
    lo[a] = 0;
    hi[a] = ext[a];
  }
  return Hierarchy<D>::box(lo, hi);
}

// Refines a random half of the leaves inside the data (the mesh gets graded), returns the remap.
template <int D>
std::vector<ElemId> refine_some(Hierarchy<D>& h, const SampleLattice& lat, std::mt19937& rng, double share) {
  std::vector<ElemId> pick;
  std::bernoulli_distribution coin(share);
  for (ElemId e : h.leaves()) {
    std::array<std::array<double, D>, D + 1> p;
    for (int i = 0; i <= D; ++i) p[i] = h.point(h.cell(e)[i]);
    if (h.level(e) < lat.level && !outside_data<D>(p, lat) && coin(rng)) pick.push_back(e);
  }
  return h.refine(pick);
}

double max_abs(const Vector& v) { return v.size() ? v.cwiseAbs().maxCoeff() : 0.0; }

// The operator against the matrix, load and errors assembled from compute_element_integrals.
template <int D>
void expect_matches_assembly(const Hierarchy<D>& h, const SampledLeastSquares<D>& op, const GridField& f,
                             const SampleLattice& lat, unsigned seed) {
  const auto leaves = h.leaves();
  const auto in = compute_element_integrals<D>(h, leaves, f, 1.0, nullptr, &lat);
  const SparseMatrix m = assemble_matrix<D>(h, leaves, 0.0, &in);
  const Vector rhs = assemble_load<D>(h, leaves, in, 0.0);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-40, 40);
  std::vector<double> xv(h.vertex_count());
  for (double& v : xv) v = u(rng);
  const Vector x = Eigen::Map<const Vector>(xv.data(), static_cast<Eigen::Index>(xv.size()));
  // The operator's vectors are in its own vertex order.
  const auto by_vertex = [&](const Vector& v) {
    std::vector<double> out;
    op.from_operator_order(v, out);
    return Vector(Eigen::Map<const Vector>(out.data(), static_cast<Eigen::Index>(out.size())));
  };
  Vector xo, yo;
  op.to_operator_order(xv, xo);
  op.apply(xo, yo);
  const Vector y = by_vertex(yo);
  const Vector y_ref = m * x;
  // The barycentrics are kept as floats: relative differences of ~1e-7 at most.
  EXPECT_LE(max_abs(y - y_ref), 1e-6 * max_abs(y_ref));
  Vector load_o, diagonal_o;
  op.load(load_o, diagonal_o);
  const Vector load = by_vertex(load_o), diagonal = by_vertex(diagonal_o);
  EXPECT_LE(max_abs(load - rhs), 1e-6 * max_abs(rhs));
  EXPECT_LE(max_abs(diagonal - Vector(m.diagonal())), 1e-6 * max_abs(Vector(m.diagonal())));
  std::vector<double> err;
  std::vector<std::uint32_t> samples;
  op.leaf_errors(xo, leaves, err, samples);
  const std::vector<double> err_ref = element_errors<D>(h, leaves, in, x, 0.0);
  double scale = 0;
  for (double e : err_ref) scale = std::max(scale, e);
  std::int64_t owned = 0;
  for (std::size_t i = 0; i < leaves.size(); ++i) {
    EXPECT_NEAR(err[i], err_ref[i], 1e-6 * scale) << "leaf " << i;
    EXPECT_EQ(samples[i], in[i].points) << "leaf " << i;
    owned += samples[i];
  }
  EXPECT_EQ(owned, lat.samples());
}

template <int D>
void check_against_assembly(std::array<std::int64_t, 3> dims, std::array<double, 3> spacing, unsigned seed) {
  const ScalarGrid g = random_grid(D, dims, spacing, seed);
  const GridField f(g);
  const SampleLattice lat = sample_lattice(g);
  Hierarchy<D> h = lattice_box<D>(lat);
  SampledLeastSquares<D> op(lat, g);
  op.update(h, {}, std::vector<double>(h.vertex_count(), 0.0));
  expect_matches_assembly(h, op, f, lat, seed);  // coarse: every leaf with samples kept as sums
  std::mt19937 rng(seed);
  bool some_summed = false, some_sampled = false;
  for (int step = 0; step < 2 * lat.level; ++step) {
    const std::vector<ElemId> remap = refine_some(h, lat, rng, 0.6);
    op.update(h, remap, std::vector<double>(h.vertex_count(), 0.0));
    expect_matches_assembly(h, op, f, lat, seed + unsigned(step));
    const auto leaves = h.leaves();
    const auto in = compute_element_integrals<D>(h, leaves, f, 1.0, nullptr, &lat);
    for (const auto& i : in) {
      some_summed |= i.points >= SampledLeastSquares<D>::kSummedLeaf;
      some_sampled |= i.points > 0 && i.points < SampledLeastSquares<D>::kSummedLeaf;
    }
  }
  EXPECT_TRUE(some_summed);
  EXPECT_TRUE(some_sampled);
}

TEST(SampledLeastSquares, MatchesTheAssembledSystem2D) {
  check_against_assembly<2>({37, 23, 1}, {0.7, 1.3, 1}, 5);
}
TEST(SampledLeastSquares, MatchesTheAssembledSystem3D) {
  check_against_assembly<3>({19, 13, 11}, {0.7, 1.3, 2.1}, 6);
}

TEST(SampledLeastSquares, PaddingWeightsOnTheDiagonal) {
  const ScalarGrid g = random_grid(3, {9, 6, 5}, {1, 1, 1}, 3);
  const SampleLattice lat = sample_lattice(g);
  Hierarchy<3> h = lattice_box<3>(lat);
  h.refine_uniform();
  SampledLeastSquares<3> op(lat, g);
  std::vector<double> pad(h.vertex_count(), 0.0);
  pad[1] = 0.5;
  op.update(h, {}, std::vector<double>(h.vertex_count(), 0.0));
  const std::vector<double> ones(h.vertex_count(), 1.0);
  Vector x, y0, y1, load, d0, d1;
  op.to_operator_order(ones, x);
  op.apply(x, y0);
  op.load(load, d0);
  op.update(h, std::vector<ElemId>(), pad);
  op.apply(x, y1);
  op.load(load, d1);
  std::vector<double> a0, a1, b0, b1;
  op.from_operator_order(y0, a0);
  op.from_operator_order(y1, a1);
  op.from_operator_order(d0, b0);
  op.from_operator_order(d1, b1);
  EXPECT_DOUBLE_EQ(a1[1] - a0[1], 0.5);
  EXPECT_DOUBLE_EQ(b1[1] - b0[1], 0.5);
  EXPECT_EQ(a1[0], a0[0]);
}

// Same bits with 1 and 2 threads: the tiles' colouring fixes every sum's order.
TEST(SampledLeastSquares, SameBitsWithOneAndTwoThreads) {
  const ScalarGrid g = random_grid(3, {33, 29, 31}, {1, 1, 1.5}, 9);
  const SampleLattice lat = sample_lattice(g);
  Hierarchy<3> h = lattice_box<3>(lat);
  std::mt19937 rng(9);
  for (int step = 0; step < 7; ++step) refine_some(h, lat, rng, 0.7);
  const auto leaves = h.leaves();
  Vector x(static_cast<Eigen::Index>(h.vertex_count()));
  for (Eigen::Index i = 0; i < x.size(); ++i) x[i] = std::sin(0.37 * double(i));
  std::vector<Vector> y(2), load(2), diag(2);
  std::vector<std::vector<double>> err(2);
  std::vector<std::uint32_t> samples;
  for (int t = 0; t < 2; ++t) {
    tbb::global_control threads(tbb::global_control::max_allowed_parallelism, std::size_t(t + 1));
    SampledLeastSquares<3> op(lat, g);
    op.update(h, {}, std::vector<double>(h.vertex_count(), 0.0));
    op.apply(x, y[t]);  // x read in the operator's order: the same vector for both
    op.load(load[t], diag[t]);
    op.leaf_errors(x, leaves, err[t], samples);
  }
  EXPECT_TRUE(y[0] == y[1]);
  EXPECT_TRUE(load[0] == load[1]);
  EXPECT_TRUE(diag[0] == diag[1]);
  EXPECT_TRUE(err[0] == err[1]);
}

}  // namespace
}  // namespace mlfe
