// mesh_topology and non_manifold_vertices: each defect counted on a mesh that has it alone;
// spatially_ordered keeps the surface; triangle_spatial_order; merge_meshes; weld_piece_borders.
#include <gtest/gtest.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/surface/triangle_mesh.h>

#include <algorithm>
#include <array>
#include <set>
#include <vector>

namespace mlfe {
namespace {

// The closed surface of a tetrahedron, outward.
TriangleMesh tetrahedron(float dx = 0) {
  TriangleMesh m;
  m.positions = {{dx, 0, 0}, {dx + 1, 0, 0}, {dx, 1, 0}, {dx, 0, 1}};
  m.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  return m;
}

TEST(MeshTopology, ClosedTetrahedronIsWeldedAndManifold) {
  const MeshTopology t = mesh_topology(tetrahedron());
  EXPECT_TRUE(t.welded_manifold());
  EXPECT_EQ(t.boundary_edges, 0u);
}

TEST(MeshTopology, CountsDuplicatesAndSeesTheWeldedSurface) {
  TriangleMesh m = tetrahedron();
  // Vertex 3 split in two: one triangle uses the copy. By position it is still closed.
  m.positions.push_back(m.positions[3]);
  m.triangles[3] = {1, 2, 4};
  const MeshTopology t = mesh_topology(m);
  EXPECT_EQ(t.duplicate_vertices, 1u);
  EXPECT_EQ(t.boundary_edges, 0u);
  EXPECT_EQ(t.non_manifold_edges, 0u);
  EXPECT_FALSE(t.welded_manifold());
  // By index the split is a seam: its two edges are open and the mesh is manifold.
  const auto bad = non_manifold_vertices(m.triangles, m.positions.size());
  EXPECT_EQ(bad, std::vector<std::uint8_t>(5, 0));
}

TEST(MeshTopology, FinsAndPinchesAreNonManifold) {
  // A third triangle on edge 0-1 of the tetrahedron.
  TriangleMesh fin = tetrahedron();
  fin.positions.push_back({0.5f, -1, 0});
  fin.triangles.push_back({0, 4, 1});
  const MeshTopology f = mesh_topology(fin);
  EXPECT_EQ(f.non_manifold_edges, 1u);
  EXPECT_EQ(f.boundary_edges, 2u);
  auto bad = non_manifold_vertices(fin.triangles, fin.positions.size());
  EXPECT_TRUE(bad[0] && bad[1] && !bad[2] && !bad[3] && !bad[4]);

  // Two tetrahedra touching at one vertex (welded by position): a pinched vertex.
  const TriangleMesh one = tetrahedron();
  const TriangleMesh other = tetrahedron(-1);  // its vertex 1 is at the first one's vertex 0
  const TriangleMesh pinch = merge_meshes({&one, &other});
  const MeshTopology p = mesh_topology(pinch);
  EXPECT_EQ(p.duplicate_vertices, 1u);
  EXPECT_EQ(p.non_manifold_vertices, 1u);
  EXPECT_EQ(p.non_manifold_edges, 0u);
}

TEST(MeshTopology, FlippedTriangleIsAnInconsistentOrientation) {
  TriangleMesh m = tetrahedron();
  std::swap(m.triangles[0][1], m.triangles[0][2]);
  const MeshTopology t = mesh_topology(m);
  EXPECT_EQ(t.inconsistent_edges, 3u);
  EXPECT_EQ(t.boundary_edges, 0u);
}

TEST(MeshTopology, BoundaryEdgesOffTheBoxAreCounted) {
  // A square on the face z = 0 of the box [0, 1]^3, and a smaller one inside the box.
  TriangleMesh face;
  face.positions = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
  face.triangles = {{0, 1, 2}, {0, 2, 3}};
  const std::array<double, 3> lo{0, 0, 0}, hi{1, 1, 1};
  EXPECT_EQ(mesh_topology(face, &lo, &hi, 1e-6).boundary_edges_off_box, 0u);
  TriangleMesh inside = face;
  for (auto& p : inside.positions) p = {0.25f + 0.5f * p[0], 0.25f + 0.5f * p[1], 0.5f};
  const MeshTopology t = mesh_topology(inside, &lo, &hi, 1e-6);
  EXPECT_EQ(t.boundary_edges, 4u);
  EXPECT_EQ(t.boundary_edges_off_box, 4u);
  // One end on a face is not enough: the edge must lie on it.
  inside.positions[0] = {0, 0.25f, 0.5f};
  EXPECT_EQ(mesh_topology(inside, &lo, &hi, 1e-6).boundary_edges_off_box, 4u);
}

// A strip of quads along x whose vertices are listed back to front and shuffled: the order
// puts them front to back, each triangle is the same corner positions in the same cyclic
// order, normals travel with their vertices, and the output is a function of the input.
TEST(SpatiallyOrdered, KeepsEveryTriangleAndItsOrientation) {
  TriangleMesh m;
  const int n = 50;
  for (int i = n - 1; i >= 0; --i)
    for (int j = 0; j < 2; ++j) {
      m.positions.push_back({float(i), float(j), 0.f});
      m.normals.push_back({0.f, 0.f, float(i)});
    }
  auto at = [&](int i, int j) { return std::uint32_t(2 * (n - 1 - i) + j); };
  for (int i = 0; i + 1 < n; ++i) {
    m.triangles.push_back({at(i, 0), at(i + 1, 0), at(i + 1, 1)});
    m.triangles.push_back({at(i, 0), at(i + 1, 1), at(i, 1)});
  }
  std::reverse(m.triangles.begin(), m.triangles.end());
  const TriangleMesh o = spatially_ordered(m);
  ASSERT_EQ(o.positions.size(), m.positions.size());
  ASSERT_EQ(o.normals.size(), m.normals.size());
  ASSERT_EQ(o.triangles.size(), m.triangles.size());
  EXPECT_EQ(o.positions.front()[0], 0.f);
  EXPECT_EQ(o.positions.back()[0], float(n - 1));
  for (std::size_t v = 0; v < o.positions.size(); ++v) EXPECT_EQ(o.normals[v][2], o.positions[v][0]);
  // Triangles as corner positions, rotated to start at their smallest corner (orientation kept).
  using Corners = std::array<std::array<float, 3>, 3>;
  auto corners = [](const TriangleMesh& x) {
    std::multiset<Corners> out;
    for (const auto& t : x.triangles) {
      Corners c{x.positions[t[0]], x.positions[t[1]], x.positions[t[2]]};
      std::rotate(c.begin(), std::min_element(c.begin(), c.end()), c.end());
      out.insert(c);
    }
    return out;
  };
  EXPECT_EQ(corners(o), corners(m));
  const TriangleMesh again = spatially_ordered(m);
  EXPECT_EQ(again.positions, o.positions);
  EXPECT_EQ(again.triangles, o.triangles);
  for (std::size_t f = 1; f < o.triangles.size(); ++f)
    EXPECT_LE(*std::min_element(o.triangles[f - 1].begin(), o.triangles[f - 1].end()),
              *std::min_element(o.triangles[f].begin(), o.triangles[f].end()));
  m.triangles.push_back({0, 1, std::uint32_t(m.positions.size())});
  EXPECT_THROW(spatially_ordered(m), Error);
}

TEST(MergeMeshes, AppendsInOrderWithShiftedTriangles) {
  TriangleMesh a = tetrahedron(), b = tetrahedron(5);
  compute_area_weighted_normals(a);
  compute_area_weighted_normals(b);
  const TriangleMesh empty;
  const TriangleMesh m = merge_meshes({&a, &empty, &b});
  ASSERT_EQ(m.positions.size(), 8u);
  ASSERT_EQ(m.normals.size(), 8u);
  ASSERT_EQ(m.triangles.size(), 8u);
  EXPECT_EQ(m.positions[4], b.positions[0]);
  EXPECT_EQ(m.normals[5], b.normals[1]);
  EXPECT_EQ(m.triangles[3], a.triangles[3]);
  EXPECT_EQ(m.triangles[7], (std::array<std::uint32_t, 3>{5, 6, 7}));
  EXPECT_TRUE(merge_meshes({}).positions.empty());
}

TEST(MergeMeshes, DropsNormalsThatSomeVerticesLack) {
  TriangleMesh a = tetrahedron();
  const TriangleMesh b = tetrahedron(5);
  compute_area_weighted_normals(a);
  const TriangleMesh m = merge_meshes({&a, &b});
  EXPECT_EQ(m.positions.size(), 8u);
  EXPECT_TRUE(m.normals.empty());
}

TEST(TriangleSpatialOrder, IsAPermutationWithNearTrianglesTogether) {
  // Two tetrahedra far apart, their triangles interleaved: each comes out as one run.
  const TriangleMesh a = tetrahedron(), b = tetrahedron(100);
  TriangleMesh m = merge_meshes({&a, &b});
  for (std::size_t f = 0; f < 4; ++f) std::swap(m.triangles[2 * f], m.triangles[f + 4]);
  const std::vector<std::uint32_t> order = triangle_spatial_order(m);
  ASSERT_EQ(order.size(), 8u);
  EXPECT_EQ(std::set<std::uint32_t>(order.begin(), order.end()).size(), 8u);
  auto near_first = [&](std::uint32_t f) { return m.positions[m.triangles[f][0]][0] < 50; };
  for (std::size_t i = 0; i < 8; ++i) EXPECT_EQ(near_first(order[i]), i < 4) << i;
  m.triangles.push_back({0, 1, 8});
  EXPECT_THROW(triangle_spatial_order(m), Error);
}

TEST(WeldPieceBorders, ClosesACutSurfaceAndLeavesOtherTwinsAlone) {
  // The tetrahedron cut in two pieces of two triangles, each with its own vertices.
  TriangleMesh first = tetrahedron(), second = tetrahedron();
  first.triangles.resize(2);
  second.triangles.erase(second.triangles.begin(), second.triangles.begin() + 2);
  compute_area_weighted_normals(first);
  compute_area_weighted_normals(second);
  // A closed part holding a vertex at a cut vertex's position, not on an open edge: kept.
  TriangleMesh closed = tetrahedron(-1);  // its vertex 1 is at the cut's vertex 0
  compute_area_weighted_normals(closed);
  TriangleMesh m = merge_meshes({&first, &second, &closed});
  ASSERT_EQ(m.positions.size(), 12u);
  const std::array<float, 3> normal0 = m.normals[0];
  weld_piece_borders(m, {2, 2, 4});
  EXPECT_EQ(m.positions.size(), 8u);  // 4 of the second piece welded onto the first's
  EXPECT_EQ(m.normals.size(), 8u);
  EXPECT_EQ(m.normals[0], normal0);  // the first's normal kept
  const MeshTopology t = mesh_topology(m);
  EXPECT_EQ(t.boundary_edges, 0u);
  EXPECT_EQ(t.duplicate_vertices, 1u);  // the closed part's twin of vertex 0
  for (std::size_t f = 0; f < 4; ++f)
    for (int k = 0; k < 3; ++k)
      EXPECT_EQ(m.positions[m.triangles[f][k]], tetrahedron().positions[tetrahedron().triangles[f][k]]);
  m.triangles.push_back({0, 1, 8});
  EXPECT_THROW(weld_piece_borders(m, {2, 2, 5}), Error);
}

TEST(WeldPieceBorders, KeepsTheSurfacesOwnBoundaryTwins) {
  // An open strip of two triangles whose two boundary vertices 1 and 4 share a position (as
  // Draco's quantization can make them), written as one piece and as two: neither welds them.
  TriangleMesh strip;
  strip.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}, {1, 0, 0}, {2, 0, 0}};
  strip.triangles = {{0, 1, 2}, {2, 1, 3}, {3, 4, 5}};
  TriangleMesh whole = strip;
  weld_piece_borders(whole, {3});
  EXPECT_EQ(whole.positions.size(), 6u);
  // Cut between the first and second triangle (edge 1-2): the second piece has its own copies.
  TriangleMesh a, b;
  a.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  a.triangles = {{0, 1, 2}};
  b.positions = {{1, 0, 0}, {0, 1, 0}, {1, 1, 0}, {1, 0, 0}, {2, 0, 0}};
  b.triangles = {{1, 0, 2}, {2, 3, 4}};
  TriangleMesh m = merge_meshes({&a, &b});
  weld_piece_borders(m, {1, 2});
  EXPECT_EQ(m.positions.size(), 6u);  // the cut edge's 2 copies welded; the twins at (1,0,0) kept
  ASSERT_EQ(m.triangles.size(), 3u);
  for (std::size_t f = 0; f < 3; ++f)
    for (int k = 0; k < 3; ++k)
      EXPECT_EQ(m.positions[m.triangles[f][k]], strip.positions[strip.triangles[f][k]]);
  EXPECT_EQ(m.triangles[0][1], m.triangles[1][1]);  // the cut edge is one edge again
  EXPECT_NE(m.triangles[0][1], m.triangles[2][1]);  // the boundary twins stay two vertices
}

}  // namespace
}  // namespace mlfe
