// Hierarchies shared by the core and format tests.
#pragma once
#include <gtest/gtest.h>

#include <vector>

#include "core/hierarchy.h"

namespace mlfe::test {

/// Red and green elements at several levels: `rounds` times, refines every leaf with a vertex
/// in [0, 0.25]^D (the corner at the origin).
template <int D>
Hierarchy<D> refine_toward_origin(Hierarchy<D> h, int rounds) {
  for (int round = 0; round < rounds; ++round) {
    std::vector<ElemId> marked;
    for (ElemId e : h.leaves()) {
      bool near = false;
      for (VertexId v : h.cell(e)) {
        bool in = true;
        for (int i = 0; i < D; ++i) in = in && h.point(v)[i] <= 0.25;
        near = near || in;
      }
      if (near) marked.push_back(e);
    }
    h.refine(marked);
  }
  return h;
}

/// Every stored array of the two hierarchies is equal.
template <int D>
void expect_same_hierarchy(const Hierarchy<D>& a, const Hierarchy<D>& b) {
  EXPECT_EQ(a.points(), b.points());
  EXPECT_EQ(a.vertex_parents_array(), b.vertex_parents_array());
  EXPECT_EQ(a.vertex_level_array(), b.vertex_level_array());
  EXPECT_EQ(a.cells(), b.cells());
  EXPECT_EQ(a.parent_array(), b.parent_array());
  EXPECT_EQ(a.first_child_array(), b.first_child_array());
  EXPECT_EQ(a.num_children_array(), b.num_children_array());
  EXPECT_EQ(a.level_array(), b.level_array());
  EXPECT_EQ(a.kind_array(), b.kind_array());
  EXPECT_EQ(a.coarse_count(), b.coarse_count());
  EXPECT_EQ(a.edge_midpoints().size(), b.edge_midpoints().size());
}

}  // namespace mlfe::test
