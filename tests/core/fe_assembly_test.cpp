#include <gtest/gtest.h>
#include <mlfe/core/fe_assembly.h>
#include <mlfe/core/p1_element.h>

#include <random>

namespace mlfe {
namespace {

Hierarchy<3> graded_mesh() {
  auto h = Hierarchy<3>::box({0, 0, 0}, {2, 1, 1.5});
  h.refine_uniform();
  std::mt19937 rng(3);
  for (int it = 0; it < 3; ++it) {
    std::vector<ElemId> marked;
    for (ElemId e : h.leaves())
      if (rng() % 4 == 0) marked.push_back(e);
    h.refine(marked);
  }
  return h;
}

TEST(FeAssembly, MatrixEqualsTheTripletSumOfElementMatrices) {
  const auto h = graded_mesh();
  const auto leaves = h.leaves();
  for (double gw : {0.0, 0.7}) {
    const SparseMatrix m = assemble_matrix(h, leaves, gw);
    std::vector<Eigen::Triplet<double>> t;
    for (ElemId e : leaves) {
      std::array<std::array<double, 3>, 4> p;
      for (int i = 0; i < 4; ++i) p[i] = h.point(h.cell(e)[i]);
      const P1Element<3> el(p);
      for (int a = 0; a < 4; ++a)
        for (int b = 0; b < 4; ++b)
          t.emplace_back(h.cell(e)[a].value, h.cell(e)[b].value, el.mass(a, b) + gw * el.stiffness(a, b));
    }
    Eigen::SparseMatrix<double> ref(m.rows(), m.cols());
    ref.setFromTriplets(t.begin(), t.end());
    const Eigen::SparseMatrix<double> diff = Eigen::SparseMatrix<double>(m) - ref;
    EXPECT_LE(diff.norm(), 1e-14 * ref.norm());
    EXPECT_EQ(m.nonZeros(), ref.nonZeros());
  }
}

TEST(FeAssembly, MassMatrixIntegratesOneToTheDomainVolume) {
  const auto h = graded_mesh();
  const SparseMatrix m = assemble_matrix(h, h.leaves(), 0.0);
  const Vector one = Vector::Ones(m.rows());
  EXPECT_NEAR(one.dot(m * one), 2 * 1 * 1.5, 1e-12);  // (1, 1) = |Ω|
  // Stiffness annihilates constants: (∇1, ∇v) = 0.
  const SparseMatrix k = assemble_matrix(h, h.leaves(), 1.0);
  EXPECT_LE(((k - m) * one).norm(), 1e-12);
}

}  // namespace
}  // namespace mlfe
