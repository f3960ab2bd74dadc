#include <gtest/gtest.h>
#include <mlfe/core/fem/fe_assembly.h>
#include <mlfe/core/fem/p1_element.h>

#include <algorithm>
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

// Sampled integrals with random masses and loads for every element id (only the leaves' are read).
std::vector<ElementIntegrals<3>> random_sampled_integrals(const Hierarchy<3>& h, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0.1, 1.0);
  std::vector<ElementIntegrals<3>> in(h.element_count());
  for (auto& x : in) {
    x.sampled = true;
    for (double& v : x.fphi) v = u(rng) * 100;
    for (double& v : x.mass) v = u(rng);
  }
  return in;
}

TEST(FeAssembly, SystemEqualsMatrixAndLoadBitForBitWithAReusedWorkspace) {
  auto coarse_mesh = Hierarchy<3>::box({0, 0, 0}, {2, 1, 1.5});
  coarse_mesh.refine_uniform();
  const Hierarchy<3>& coarse = coarse_mesh;
  const auto graded = graded_mesh();
  AssemblyWorkspace ws;
  SparseMatrix m;
  Vector rhs;
  // Coarse, graded, coarse again: the workspace and m's storage grow, then are reused larger
  // than needed; nothing of an earlier call may show.
  for (const Hierarchy<3>* h : {&coarse, &graded, &coarse}) {
    const auto leaves = h->leaves();
    const auto by_id = random_sampled_integrals(*h, 7);
    std::vector<ElementIntegrals<3>> in_order;
    for (ElemId e : leaves) in_order.push_back(by_id[e.value]);
    for (IntegralIndex index : {IntegralIndex::kElementId, IntegralIndex::kLeafOrder}) {
      const auto& in = index == IntegralIndex::kElementId ? by_id : in_order;
      assemble_system(*h, leaves, 0.0, in, index, ws, m, rhs);
      const SparseMatrix fresh = assemble_matrix(*h, leaves, 0.0, &in, index);
      ASSERT_EQ(m.nonZeros(), fresh.nonZeros());
      EXPECT_TRUE(std::equal(m.valuePtr(), m.valuePtr() + m.nonZeros(), fresh.valuePtr()));
      EXPECT_TRUE(std::equal(m.innerIndexPtr(), m.innerIndexPtr() + m.nonZeros(), fresh.innerIndexPtr()));
      EXPECT_TRUE(std::equal(m.outerIndexPtr(), m.outerIndexPtr() + m.rows() + 1, fresh.outerIndexPtr()));
      // The load summed in the row pass, against assemble_load's own loop over the leaves.
      EXPECT_TRUE(rhs == assemble_load(*h, leaves, in, 0.0, index));
      // The sampled masses, against a triplet sum.
      std::vector<Eigen::Triplet<double>> t;
      for (std::size_t i = 0; i < leaves.size(); ++i)
        for (int a = 0; a < 4; ++a)
          for (int b = 0; b < 4; ++b)
            t.emplace_back(h->cell(leaves[i])[a].value, h->cell(leaves[i])[b].value,
                           in_order[i].mass_at(a, b));
      Eigen::SparseMatrix<double> ref(m.rows(), m.cols());
      ref.setFromTriplets(t.begin(), t.end());
      EXPECT_LE((Eigen::SparseMatrix<double>(m) - ref).norm(), 1e-14 * ref.norm());
    }
  }
}

}  // namespace
}  // namespace mlfe
