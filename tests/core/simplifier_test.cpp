// simplify(): each kind reaches the algorithm it names, with the same output as calling it.
#include <gtest/gtest.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/simplify/simplifier.h>

#include "tests/test_meshes.h"

namespace mlfe {
namespace {

void expect_same(const TriangleMesh& a, const TriangleMesh& b) {
  EXPECT_EQ(a.positions, b.positions);
  EXPECT_EQ(a.normals, b.normals);
  EXPECT_EQ(a.triangles, b.triangles);
}

TEST(Simplifier, EachKindIsTheAlgorithmItNames) {
  const TriangleMesh in = test::icosphere(4, 10.0f);
  SimplifierOptions o;
  o.tolerance = 0.2;
  o.ratio = 0.3;
  SimplifyOptions within;
  within.tolerance = o.tolerance;
  within.min_triangles = std::size_t(o.ratio * double(in.triangles.size()));
  o.kind = Simplifier::kBounded;
  expect_same(simplify(in, o), simplify_within(in, within));
  // auto takes the verified bound on a surface this small.
  o.kind = Simplifier::kAuto;
  expect_same(simplify(in, o), simplify_within(in, within));
  o.kind = Simplifier::kFast;
  within.verify_bound = false;
  expect_same(simplify(in, o), simplify_within(in, within));
  o.kind = Simplifier::kMeshopt;
  expect_same(simplify(in, o), simplify_fast(in, o.tolerance));
  o.tolerance = 0;
  EXPECT_THROW(simplify(in, o), Error);
}

}  // namespace
}  // namespace mlfe
