// bricked_iso_surface (core/simplify/bricked_iso_surface.cpp): the iso-surface extracted and
// simplified brick by brick against the whole surface's simplification, on shapes that cross the
// bricks' faces, edges and corners.
#include <gtest/gtest.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/simplify/bricked_iso_surface.h>
#include <mlfe/core/surface/iso_surface.h>
#include <mlfe/core/surface/mesh_distance.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <numeric>
#include <random>
#include <utility>

#include "tests/core/test_hierarchies.h"
#include "tests/test_meshes.h"

namespace mlfe {
namespace {

// Euler characteristic and connected parts of the triangles.
struct Shape {
  long euler = 0;
  std::size_t parts = 0;
};

Shape shape_of(const TriangleMesh& m) {
  std::vector<std::size_t> up(m.positions.size());
  std::iota(up.begin(), up.end(), 0);
  auto find = [&](std::size_t v) {
    while (up[v] != v) v = up[v] = up[up[v]];
    return v;
  };
  std::map<std::pair<std::uint32_t, std::uint32_t>, int> edges;
  std::vector<char> used(m.positions.size(), 0);
  for (const auto& t : m.triangles)
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t a = t[k], b = t[(k + 1) % 3];
      ++edges[{std::min(a, b), std::max(a, b)}];
      used[a] = 1;
      up[find(a)] = find(b);
    }
  Shape s;
  for (std::size_t v = 0; v < used.size(); ++v) {
    s.euler += used[v];
    s.parts += used[v] && find(v) == v;
  }
  s.euler += long(m.triangles.size()) - long(edges.size());
  return s;
}

struct Extraction {
  ScalarGrid grid;
  TriangleMesh mesh;
  std::vector<LatticePlace> places;
};

Extraction extract(ScalarGrid g, double iso) {
  Extraction e;
  e.grid = std::move(g);
  e.mesh = lattice_iso_surface(e.grid, iso, {}, &e.places);
  return e;
}

// kBounded: the bound verified against the extraction itself (kAuto's estimated first run, which
// bricks always make, keeps it only as an estimate).
SimplifierOptions options(Placement placement) {
  SimplifierOptions o;
  o.kind = Simplifier::kBounded;
  o.tolerance = 0.3;
  o.ratio = 0.1;
  o.placement = placement;
  return o;
}

TriangleMesh in_bricks(const Extraction& e, const SimplifierOptions& o, std::int64_t brick,
                       BrickStats* stats = nullptr) {
  BrickedIsoOptions bo;
  bo.simplifier = o;
  std::vector<BrickStats> st;
  std::vector<TriangleMesh> out =
      bricked_iso_surfaces(grid_windows(e.grid), e.grid.dims, brick, {0.0}, bo, &st);
  if (stats) *stats = st[0];
  return std::move(out[0]);
}

// The bricked result against the whole surface's: the same topology, closed, welded (no crack,
// no vertex twice along a face), manifold, every extracted vertex within the bound, and near
// the unbricked simplification.
void expect_as_unbricked(const Extraction& e, std::int64_t brick, Placement placement) {
  const SimplifierOptions o = options(placement);
  BrickStats stats;
  const TriangleMesh bricked = in_bricks(e, o, brick, &stats);
  const TriangleMesh whole = simplify(e.mesh, o);
  EXPECT_GT(stats.bricks, 1u);
  EXPECT_GT(stats.face_vertices, 0u);
  const MeshTopology t = mesh_topology(bricked);
  EXPECT_TRUE(t.welded_manifold()) << t.duplicate_vertices << " duplicates, " << t.non_manifold_edges
                                   << " non-manifold edges, " << t.non_manifold_vertices << " vertices, "
                                   << t.inconsistent_edges << " flips";
  EXPECT_EQ(t.boundary_edges, 0u);
  const Shape a = shape_of(bricked), b = shape_of(whole), in = shape_of(e.mesh);
  EXPECT_EQ(a.euler, in.euler);
  EXPECT_EQ(a.parts, in.parts);
  EXPECT_EQ(b.euler, in.euler);
  EXPECT_EQ(signed_volume(bricked) > 0, signed_volume(e.mesh) > 0);  // orientation kept
  EXPECT_LE(test::one_sided_hausdorff(e.mesh, bricked), o.tolerance * (1 + 1e-4));
  // As close to the extraction, both ways, as the whole surface's simplification.
  const double d = mesh_distance(e.mesh, bricked, {20000, 17}).hausdorff(),
               d_whole = mesh_distance(e.mesh, whole, {20000, 17}).hausdorff();
  std::printf(
      "brick %lld: %zu -> %zu triangles (whole: %zu; seams %zu -> %zu), Hausdorff %.3f (whole: %.3f)\n",
      static_cast<long long>(brick), e.mesh.triangles.size(), bricked.triangles.size(),
      whole.triangles.size(), stats.seam_triangles, stats.seam_output, d, d_whole);
  // Seam vertices the seam pass moved are not refitted to the extraction (it is not kept): they
  // stay within the tolerance of the strips, which are within it of the extraction.
  EXPECT_LE(d, 2 * std::max(o.tolerance, d_whole));
  // The seams end about as sparse as the rest.
  EXPECT_LE(double(bricked.triangles.size()), 1.25 * double(whole.triangles.size()));
}

ScalarGrid sphere(double r, std::array<double, 3> c) {
  return test::function_grid({40, 41, 39}, {1, 1, 1}, [&](auto i, auto j, auto k) {
    return std::hypot(double(i) - c[0], double(j) - c[1], double(k) - c[2]) - r;
  });
}

// A torus around the corner (16, 16, 16) of eight 16-sample bricks, tilted so its tube crosses
// their faces at slants.
ScalarGrid torus() {
  return test::function_grid({36, 34, 35}, {1, 1, 1}, [](auto i, auto j, auto k) {
    const double x = double(i) - 16.2, y = double(j) - 15.9, z = double(k) - 16.1;
    const double c = std::cos(0.5), s = std::sin(0.5);
    const double u = x, v = c * y - s * z, w = s * y + c * z;
    return std::hypot(std::hypot(u, v) - 9.0, w) - 3.2;
  });
}

TEST(BrickedIsoSurface, SphereAsUnbricked) {
  const Extraction e = extract(sphere(13.3, {19.6, 20.2, 19.1}), 0.0);
  for (Placement p : {Placement::kInputVertex, Placement::kOptimal}) expect_as_unbricked(e, 16, p);
  expect_as_unbricked(e, 8, Placement::kInputVertex);
}

// Noise wrinkles the surface along every brick face: collapses onto the held face vertices
// must not join two of them by an edge the neighbouring brick also has (non-manifold seams).
TEST(BrickedIsoSurface, NoisySphereInSmallBricksAsUnbricked) {
  ScalarGrid g = sphere(13.3, {19.6, 20.2, 19.1});
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> noise(-0.45f, 0.45f);
  for (float& v : g.values) v += noise(rng);
  const Extraction e = extract(std::move(g), 0.0);
  for (std::int64_t brick : {8, 16}) expect_as_unbricked(e, brick, Placement::kOptimal);
}

TEST(BrickedIsoSurface, TorusAcrossBrickCornersAsUnbricked) {
  const Extraction e = extract(torus(), 0.0);
  EXPECT_EQ(shape_of(e.mesh).euler, 0);
  for (Placement p : {Placement::kInputVertex, Placement::kOptimal}) expect_as_unbricked(e, 16, p);
}

// One sample above the iso-value on a shared sample plane: a tiny closed surface whose
// vertices are nearly all face vertices, beside a sphere so the bricks have work.
TEST(BrickedIsoSurface, SingleVoxelSpikeOnABrickFaceSurvives) {
  ScalarGrid g = sphere(8.2, {24.4, 24.6, 23.7});
  for (float& v : g.values) v = -v;  // inside above the iso-value, like the spike
  g.values[std::size_t(16 + 40 * (5 + 41 * 6))] = 100.0f;
  const Extraction e = extract(std::move(g), 0.0);
  EXPECT_EQ(shape_of(e.mesh).parts, 2u);
  expect_as_unbricked(e, 16, Placement::kOptimal);
  expect_as_unbricked(e, 16, Placement::kInputVertex);
}

TEST(BrickedIsoSurface, SameBytesForAnyThreadCount) {
  const Extraction e = extract(torus(), 0.0);
  const SimplifierOptions o = options(Placement::kOptimal);
  std::vector<TriangleMesh> out;
  for (int threads : {1, 2, 7}) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, std::size_t(threads));
    out.push_back(in_bricks(e, o, 8));
  }
  for (std::size_t i = 1; i < out.size(); ++i) {
    EXPECT_EQ(out[i].positions, out[0].positions);
    EXPECT_EQ(out[i].normals, out[0].normals);
    EXPECT_EQ(out[i].triangles, out[0].triangles);
  }
}

// The joins of disjoint slabs are independent: the tree's nodes joined apart, one by one in any
// order (as Dask tasks are), give the one-call result to the bit, and so do the bricks' parts
// handed to join_bricks.
TEST(BrickedIsoSurface, SlabJoinsApartGiveTheSameSurface) {
  const Extraction e = extract(torus(), 0.0);
  BrickedIsoOptions bo;
  bo.simplifier = options(Placement::kOptimal);
  const TriangleMesh whole = in_bricks(e, bo.simplifier, 8);
  const BrickLayout layout = brick_layout(e.grid.dims, 8);
  ASSERT_EQ(layout.slabs(), 5u);  // 34 cubes along z: a tree of two levels of nodes
  std::vector<BrickPart> parts(layout.bricks());
  for (std::size_t b = layout.bricks(); b-- > 0;) {
    std::array<std::int64_t, 3> lo, hi;
    layout.window(b, lo, hi);
    parts[b] = brick_pass(grid_windows(e.grid)(lo, hi), layout, b, 0.0, bo);
  }
  const TriangleMesh joined = join_bricks(parts, layout, bo);
  EXPECT_EQ(joined.positions, whole.positions);
  EXPECT_EQ(joined.triangles, whole.triangles);
  // Slabs last to first, then the nodes, then the root's halves through join_tree.
  std::map<std::pair<std::size_t, std::size_t>, BrickPart> pieces;
  for (std::size_t s = layout.slabs(); s-- > 0;) {
    const std::vector<BrickPart> slab(parts.begin() + s * layout.slab_bricks(),
                                      parts.begin() + (s + 1) * layout.slab_bricks());
    BrickStats st;
    const BrickPart& piece = pieces[{s, s + 1}] = join_slabs(slab, layout, s, s + 1, bo, &st);
    if (piece.mesh.triangles.empty()) continue;  // the torus is not in every slab
    EXPECT_GT(st.face_vertices, 0u);             // its faces along x and y closed
    EXPECT_FALSE(piece.face_vertex.empty());     // those on the planes shared with other slabs open
  }
  const std::size_t root = slab_split(0, 5);
  EXPECT_EQ(root, 2u);
  auto node = [&](std::size_t first, std::size_t end) {
    const std::size_t split = slab_split(first, end);
    pieces[{first, end}] =
        join_slabs({pieces.at({first, split}), pieces.at({split, end})}, layout, first, end, bo);
  };
  node(3, 5);
  node(0, 2);
  node(2, 5);
  EXPECT_THROW(join_slabs({pieces.at({0, 2})}, layout, 0, 2, bo), Error);  // one half
  SlabSource source;
  source.joined = [&](std::size_t first, std::size_t end) {
    const bool half = (first == 0 && end == root) || (first == root && end == 5);
    return half ? std::vector<BrickPart>{pieces.at({first, end})} : std::vector<BrickPart>{};
  };
  source.bricks = [](std::size_t) -> std::vector<std::vector<BrickPart>> {
    ADD_FAILURE() << "a brick was asked for";
    return {};
  };
  std::vector<BrickStats> stats;
  const std::vector<TriangleMesh> apart = join_tree(source, layout, 1, bo, &stats);
  EXPECT_EQ(apart[0].positions, whole.positions);
  EXPECT_EQ(apart[0].normals, whole.normals);
  EXPECT_EQ(apart[0].triangles, whole.triangles);
  EXPECT_EQ(stats[0].parts, 1u);
}

// Each brick's part, extracted from its window alone, is the whole extraction's triangles in
// that brick, to the bit: together the parts are the whole surface.
TEST(BrickedIsoSurface, WindowsExtractTheWholeSurfaceToTheBit) {
  const Extraction e = extract(torus(), 0.0);
  using Tri = std::array<std::array<float, 3>, 3>;
  auto triangles = [](const TriangleMesh& m) {
    std::vector<std::pair<Tri, Tri>> out;  // positions, normals
    for (const auto& t : m.triangles)
      out.push_back({{m.positions[t[0]], m.positions[t[1]], m.positions[t[2]]},
                     {m.normals[t[0]], m.normals[t[1]], m.normals[t[2]]}});
    std::sort(out.begin(), out.end());
    return out;
  };
  const BrickLayout layout = brick_layout(e.grid.dims, 8);
  const WindowReader read = grid_windows(e.grid);
  std::vector<std::pair<Tri, Tri>> parts;
  for (std::size_t b = 0; b < layout.bricks(); ++b) {
    std::array<std::int64_t, 3> wlo, whi, lo, hi;
    layout.window(b, wlo, whi);
    layout.samples(b, lo, hi);
    const TriangleMesh part =
        lattice_iso_surface(read(wlo, whi), wlo, {lo[0] - wlo[0], lo[1] - wlo[1], lo[2] - wlo[2]},
                            {hi[0] - wlo[0], hi[1] - wlo[1], hi[2] - wlo[2]}, 0.0);
    const auto t = triangles(part);
    parts.insert(parts.end(), t.begin(), t.end());
  }
  std::sort(parts.begin(), parts.end());
  EXPECT_EQ(parts, triangles(e.mesh));
}

// Parts that do not fit together (another volume's brick) are refused, not welded into cracks.
TEST(BrickedIsoSurface, JoinRefusesPartsThatDoNotFit) {
  const Extraction e = extract(torus(), 0.0), other = extract(sphere(13.3, {16.2, 15.8, 16.4}), 0.0);
  BrickedIsoOptions bo;
  bo.simplifier = options(Placement::kInputVertex);
  const BrickLayout layout = brick_layout(e.grid.dims, 16);
  std::vector<BrickPart> parts(layout.bricks());
  for (std::size_t b = 0; b < layout.bricks(); ++b) {
    std::array<std::int64_t, 3> lo, hi;
    layout.window(b, lo, hi);
    parts[b] = brick_pass(grid_windows(b == 0 ? other.grid : e.grid)(lo, hi), layout, b, 0.0, bo);
  }
  EXPECT_THROW(join_bricks(parts, layout, bo), Error);
  std::array<std::int64_t, 3> lo, hi;
  layout.window(1, lo, hi);
  EXPECT_THROW(brick_pass(grid_windows(e.grid)(lo, hi), layout, 0, 0.0, bo), Error);  // the wrong window
}

TEST(BrickedIsoSurface, RejectsWhatCannotBeBricked) {
  const Extraction e = extract(sphere(5.0, {10, 10, 10}), 0.0);
  SimplifierOptions o = options(Placement::kInputVertex);
  EXPECT_THROW(in_bricks(e, o, 12), Error);
  EXPECT_THROW(in_bricks(e, o, 1), Error);
  o.kind = Simplifier::kMeshopt;
  EXPECT_THROW(in_bricks(e, o, 16), Error);
}

}  // namespace
}  // namespace mlfe
