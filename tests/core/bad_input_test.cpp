// Bad input reaching the core through its public API throws mlfe::Error with a message (it used
// to abort through MLFE_CHECK, which is kept for bugs in mlfe itself).
#include <gtest/gtest.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/fem/approximation.h>
#include <mlfe/core/fem/hierarchical_basis.h>
#include <mlfe/core/field/field.h>
#include <mlfe/core/mesh/hierarchy.h>
#include <mlfe/core/render/transfer_function.h>
#include <mlfe/core/render/volume_render.h>
#include <mlfe/core/surface/iso_surface.h>
#include <mlfe/core/surface/mesh_distance.h>
#include <mlfe/core/surface/triangle_mesh.h>

#include <string>
#include <vector>

namespace mlfe {
namespace {

// Runs `f` and returns the message of the mlfe::Error it throws ("" when it throws none).
template <class F>
std::string error_of(F&& f) {
  try {
    f();
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

ScalarGrid grid(std::array<std::int64_t, 3> dims) {
  ScalarGrid g;
  g.dims = dims;
  g.source = "test.nrrd";
  g.values.assign(std::size_t(dims[0] * dims[1] * dims[2]), 1.0f);
  return g;
}

TEST(BadInput, GridFieldRejectsUnusableGrids) {
  EXPECT_NE(error_of([] { GridField f(grid({1, 4, 4})); }).find("at least 2 samples"), std::string::npos);
  ScalarGrid g = grid({4, 4, 4});
  g.transform.spacing[1] = 0;
  EXPECT_NE(error_of([&] { GridField f(g); }).find("positive spacing"), std::string::npos);
  g = grid({4, 4, 4});
  g.values.pop_back();
  EXPECT_NE(error_of([&] { GridField f(g); }).find("63 values for 64 voxels"), std::string::npos);
  g = grid({4, 4, 4});
  g.dim = 4;
  EXPECT_NE(error_of([&] { GridField f(g); }).find("2D or 3D"), std::string::npos);
  EXPECT_EQ(error_of([] { GridField f(grid({2, 2, 2})); }), "");
}

TEST(BadInput, ApproximateRejectsAFieldOfTheWrongDimension) {
  const ScalarGrid g = grid({4, 4, 4});
  GridField f(g);
  EXPECT_NE(error_of([&] { approximate<2>(f, {}); }).find("the field is 3D"), std::string::npos);
}

TEST(BadInput, HierarchyRejectsBadBoxesCellsAndIds) {
  EXPECT_NE(error_of([] {
              Hierarchy<3>::box({0, 0, 0}, {1, 0, 1});
            }).find("below the upper"),
            std::string::npos);
  EXPECT_NE(error_of([] {
              Hierarchy<2>::from_coarse({{0, 0}, {1, 0}, {0, 1}}, {{VertexId(0), VertexId(1), VertexId(3)}});
            }).find("beyond the 3 points"),
            std::string::npos);
  EXPECT_NE(error_of([] {
              Hierarchy<2>::from_coarse({{0, 0}, {1, 0}, {2, 0}}, {{VertexId(0), VertexId(1), VertexId(2)}});
            }).find("degenerate"),
            std::string::npos);
  auto h = Hierarchy<2>::box({0, 0}, {1, 1});
  h.refine(h.leaves());
  const std::size_t elements = h.element_count(), vertices = h.vertex_count();
  // Element 0 is a coarse triangle, refined above: not a leaf. Nothing changes.
  EXPECT_NE(error_of([&] { h.refine({ElemId(0)}); }).find("element 0 is not a leaf"), std::string::npos);
  EXPECT_NE(error_of([&] { h.refine({ElemId(std::uint32_t(elements))}); }).find("not a leaf"),
            std::string::npos);
  EXPECT_EQ(h.element_count(), elements);
  EXPECT_EQ(h.vertex_count(), vertices);
}

TEST(BadInput, ValuesMustMatchTheHierarchy) {
  const auto h3 = Hierarchy<3>::box({0, 0, 0}, {1, 1, 1});
  const std::vector<double> few(h3.vertex_count() - 1, 0.0);
  EXPECT_NE(error_of([&] { IsoExtractor x(h3, few); }).find("7 values for 8 vertices"), std::string::npos);
  EXPECT_NE(error_of([&] { hierarchical_decompose(h3, few); }).find("7 values for 8 vertices"),
            std::string::npos);
  EXPECT_NE(error_of([&] { hierarchical_reconstruct(h3, few, -1); }).find("7 values"), std::string::npos);
  const auto h2 = Hierarchy<2>::box({0, 0}, {1, 1});
  EXPECT_NE(
      error_of([&] { height_field_surface(h2, {1.0}, GridTransform{}, 1.0, -1); }).find("1 values for 4"),
      std::string::npos);
}

TEST(BadInput, MeshesAndTransferFunctions) {
  TriangleMesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  m.triangles = {{0, 1, 3}};
  EXPECT_NE(error_of([&] { compute_area_weighted_normals(m); }).find("beyond the 3 positions"),
            std::string::npos);
  EXPECT_NE(error_of([] { mesh_distance(TriangleMesh{}, TriangleMesh{}, {}); }).find("no triangles"),
            std::string::npos);
  EXPECT_NE(error_of([] { transfer_function_preset("grey", 1.0, 1.0, 1.0); }).find("lo < hi"),
            std::string::npos);
  EXPECT_NE(error_of([] { transfer_function_preset("grey", 0.0, 1.0, 0.0); }).find("positive unit length"),
            std::string::npos);
}

// The ray caster's entry points: a camera without an image, values that do not fit the
// hierarchy, a 2D grid for the 3D reference renderer.
TEST(BadInput, RenderingRejectsCamerasValuesAndGrids) {
  EXPECT_NE(error_of([] {
              orbit_camera({0, 0, 0}, 1.0, 0, 0, false, 0, 10);
            }).find("image size"),
            std::string::npos);
  EXPECT_NE(error_of([] {
              orbit_camera({0, 0, 0}, 0.0, 0, 0, false, 10, 10);
            }).find("positive distance"),
            std::string::npos);
  const Hierarchy<3> h = Hierarchy<3>::box({0, 0, 0}, {1, 1, 1});
  EXPECT_NE(error_of([&] { TetRenderMesh m(h, std::vector<double>(3, 0.0)); }).find("3 values"),
            std::string::npos);
  ScalarGrid g2 = grid({4, 4, 1});
  g2.dim = 2;
  const TransferFunction tf = transfer_function_preset("grey", 0.0, 1.0, 1.0);
  const Camera cam = orbit_camera({0, 0, 0}, 5.0, 0, 0, false, 8, 8);
  EXPECT_NE(error_of([&] { render_grid(g2, tf, cam, RenderOptions{}); }).find("3D volume"),
            std::string::npos);
}

}  // namespace
}  // namespace mlfe
