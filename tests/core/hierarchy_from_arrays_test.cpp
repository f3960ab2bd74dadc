#include <gtest/gtest.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/mesh/hierarchy.h>

#include <cmath>
#include <functional>
#include <string>

#include "tests/core/test_hierarchies.h"

namespace mlfe {
namespace {

// A hierarchy with red and green elements at several levels: refine toward a corner.
template <int D>
Hierarchy<D> adapted() {
  typename Hierarchy<D>::Point lo, hi;
  lo.fill(0.0);
  hi.fill(1.0);
  return test::refine_toward_origin(Hierarchy<D>::box(lo, hi), 3);
}

template <int D>
typename Hierarchy<D>::Arrays arrays_of(const Hierarchy<D>& h) {
  return {h.points(),       h.vertex_parents_array(), h.vertex_level_array(), h.cells(),
          h.parent_array(), h.first_child_array(),    h.num_children_array(), h.level_array(),
          h.kind_array()};
}

TEST(HierarchyFromArrays, RebuildsAnAdaptedHierarchyExactlyIn2DAnd3D) {
  const auto h2 = adapted<2>();
  const auto h3 = adapted<3>();
  bool has_green = false;
  for (ElemKind k : h3.kind_array()) has_green |= k == ElemKind::kGreen;
  ASSERT_TRUE(has_green) << "the fixture should exercise green closure";
  test::expect_same_hierarchy(h2, Hierarchy<2>::from_arrays(arrays_of(h2)));
  test::expect_same_hierarchy(h3, Hierarchy<3>::from_arrays(arrays_of(h3)));
}

TEST(HierarchyFromArrays, RebuiltHierarchyRefinesLikeTheOriginal) {
  auto a = adapted<3>();
  auto b = Hierarchy<3>::from_arrays(arrays_of(a));
  // The edge map was rebuilt from vertex_parents: refining both must give the same result.
  a.refine_uniform();
  b.refine_uniform();
  test::expect_same_hierarchy(a, b);
}

// Applies `corrupt` to the arrays of the fixture and expects an Error containing `needle`.
void expect_rejected(const std::function<void(Hierarchy<3>::Arrays&)>& corrupt, const std::string& needle) {
  auto a = arrays_of(adapted<3>());
  ASSERT_GT(a.points.size(), 20u);
  corrupt(a);
  try {
    Hierarchy<3>::from_arrays(std::move(a), "test.mlfeh");
    ADD_FAILURE() << "accepted; expected an error containing '" << needle << "'";
  } catch (const Error& e) {
    const std::string msg = e.what();
    EXPECT_EQ(msg.rfind("test.mlfeh: ", 0), 0u) << msg;
    EXPECT_NE(msg.find(needle), std::string::npos) << msg;
    EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
  }
}

std::size_t first_refined(const Hierarchy<3>::Arrays& a, ElemKind child_kind) {
  for (std::size_t e = 0; e < a.cells.size(); ++e)
    if (a.num_children[e] > 0 && a.kind[a.first_child[e].value] == child_kind) return e;
  ADD_FAILURE() << "fixture lacks such an element";
  return 0;
}
std::size_t first_midpoint(const Hierarchy<3>::Arrays&) { return 8; }  // box corners are 0..7

TEST(HierarchyFromArrays, RejectsArraysOfDifferentSizes) {
  expect_rejected([](auto& a) { a.vertex_level.pop_back(); }, "vertex arrays differ");
  expect_rejected([](auto& a) { a.kind.pop_back(); }, "element arrays differ");
}

TEST(HierarchyFromArrays, RejectsVertexIndicesOutOfRangeOrRepeated) {
  expect_rejected([](auto& a) { a.cells[3][2] = VertexId(static_cast<std::uint32_t>(a.points.size())); },
                  "out of range");
  expect_rejected([](auto& a) { a.cells[3][2] = a.cells[3][1]; }, "repeats vertex");
}

TEST(HierarchyFromArrays, RejectsBadVertexParents) {
  expect_rejected([](auto& a) { std::swap(a.vertex_parents[8][0], a.vertex_parents[8][1]); },
                  "invalid parents");
  expect_rejected([](auto& a) { a.vertex_parents[8][1] = VertexId(8); }, "invalid parents");
  expect_rejected(
      [](auto& a) {
        a.vertex_parents[9] = a.vertex_parents[8];
        a.points[9] = a.points[8];
      },
      "bisected twice");
  expect_rejected([](auto& a) { a.vertex_level[8] = 0; }, "level");
}

TEST(HierarchyFromArrays, RejectsAMidpointOffTheMeanOfItsParents) {
  expect_rejected([](auto& a) { a.points[first_midpoint(a)][1] += 1e-6; }, "not the midpoint");
  expect_rejected([](auto& a) { a.points[3][0] = std::nan(""); }, "non-finite");
}

TEST(HierarchyFromArrays, AcceptsMidpointRoundingWithinTheTolerance) {
  auto a = arrays_of(adapted<3>());
  a.points[first_midpoint(a)][0] += 1e-13;
  EXPECT_NO_THROW(Hierarchy<3>::from_arrays(std::move(a)));
}

TEST(HierarchyFromArrays, RejectsInconsistentParentChildLinks) {
  // The true parent (processed first) notices that its child names another parent.
  expect_rejected([](auto& a) { a.parent[a.cells.size() - 1] = ElemId(0); }, "names another parent");
  expect_rejected([](auto& a) { a.first_child[first_refined(a, ElemKind::kRed)] = ElemId(0); },
                  "child range");
  expect_rejected([](auto& a) { a.num_children[first_refined(a, ElemKind::kRed)] = 7; }, "child range");
  expect_rejected([](auto& a) { a.parent[6] = ElemId(9); }, "names another parent");
  expect_rejected([](auto& a) { a.first_child[a.cells.size() - 1] = ElemId(0); },
                  "leaf but has a first child");
}

TEST(HierarchyFromArrays, RejectsWrongLevelsAndKinds) {
  expect_rejected([](auto& a) { a.level[a.cells.size() - 1] += 1; }, "level");
  expect_rejected([](auto& a) { a.kind[a.cells.size() - 1] = static_cast<ElemKind>(3); }, "invalid kind");
  expect_rejected([](auto& a) { a.kind[0] = ElemKind::kRed; }, "invalid parent");
  expect_rejected([](auto& a) { a.level[0] = 255; }, "limit");
}

TEST(HierarchyFromArrays, RejectsGreenElementsWithChildren) {
  expect_rejected(
      [](auto& a) {
        // A refined non-coarse element and all its siblings become green, so only the
        // "green elements are never refined" rule is broken.
        for (std::size_t i = 0; i < a.cells.size(); ++i)
          if (a.num_children[i] > 0 && a.kind[i] == ElemKind::kRed) {
            const std::size_t p = a.parent[i].value;
            for (std::size_t k = 0; k < a.num_children[p]; ++k)
              a.kind[a.first_child[p].value + k] = ElemKind::kGreen;
            return;
          }
        ADD_FAILURE() << "fixture lacks a refined red element";
      },
      "green but has children");
}

TEST(HierarchyFromArrays, RejectsChildrenThatDoNotMatchTheRefinementPattern) {
  expect_rejected(
      [](auto& a) {
        const std::size_t e = first_refined(a, ElemKind::kRed);
        std::swap(a.cells[a.first_child[e].value][0], a.cells[a.first_child[e].value][1]);
      },
      "red pattern");
  expect_rejected(
      [](auto& a) {
        const std::size_t e = first_refined(a, ElemKind::kGreen);
        a.cells[a.first_child[e].value][0] = VertexId(0) == a.cells[e][0] ? a.cells[e][1] : VertexId(0);
      },
      "");  // a repeated vertex, a foreign vertex or a broken tiling: any of them is an error
}

}  // namespace
}  // namespace mlfe
