// The brick pass, the weld and the seam pass; the design and why the bound holds are in
// bricked_iso_surface.h.
#include <mlfe/core/base/check.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/simplify/bricked_iso_surface.h>
#include <mlfe/core/simplify/surface_simplification.h>
#include <mlfe/core/surface/surface_fitting.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

namespace mlfe {

namespace {

using Id32 = std::uint32_t;
constexpr Id32 kNone = std::numeric_limits<Id32>::max();

// Rings of triangles around the face vertices that the seam pass simplifies again: one ring
// holds the face vertices' own triangles; the second lets the collapses that remove a face
// vertex also move its neighbours, whose rim would otherwise be locked.
constexpr int kSeamRings = 2;

// A brick's estimated run starts with the Simplifier's blocks whatever its size: the brick is
// the unit of parallelism, and inside it the blocks' sequential cheapest-first collapses do the
// work with less overhead than the passes.
constexpr std::size_t kBrickBlocksFrom = 0;

// The lattice's bricks: cubes per axis, bricks per axis, and the brick edge in cubes.
struct BrickGrid {
  std::array<std::int64_t, 3> samples{}, count{};
  std::int64_t edge = 0;

  // A lattice coordinate on a sample plane that two bricks share.
  bool shared_plane(int axis, std::int64_t c) const {
    return c > 0 && c < samples[axis] - 1 && c % edge == 0;
  }
  std::size_t brick_of_cube(const std::array<std::int64_t, 3>& c) const {
    return std::size_t(c[0] / edge + count[0] * (c[1] / edge + count[1] * (c[2] / edge)));
  }
  std::size_t bricks() const { return std::size_t(count[0] * count[1] * count[2]); }
};

BrickGrid brick_grid(const std::array<std::int64_t, 3>& dims, std::int64_t brick) {
  if (brick < 2 || (brick & (brick - 1)) != 0)
    throw Error("bricks: the brick edge must be a power of two of at least 2, got " + std::to_string(brick));
  BrickGrid g;
  g.samples = dims;
  g.edge = brick;
  for (int x = 0; x < 3; ++x) g.count[x] = std::max<std::int64_t>(1, (dims[x] - 1 + brick - 1) / brick);
  return g;
}

// Per vertex: 1 where it lies on a lattice edge in a sample plane two bricks share.
std::vector<std::uint8_t> face_vertices(const std::vector<LatticePlace>& places, const BrickGrid& g) {
  std::vector<std::uint8_t> face(places.size(), 0);
  for (std::size_t v = 0; v < places.size(); ++v) {
    const LatticePlace& p = places[v];
    for (int x = 0; x < 3; ++x) {
      if (p.at[x] < 0 || p.at[x] >= g.samples[x] || p.axis < 0 || p.axis > 3)
        throw Error("bricks: a vertex's lattice place lies outside the lattice");
      if (p.axis < 3 && x != p.axis && g.shared_plane(x, p.at[x])) face[v] = 1;
    }
  }
  return face;
}

// Per brick, its triangles in input order. A triangle's cube is, along each axis, the least
// lower coordinate of its vertices' places: an edge vertex lies on the cube's lower or upper
// face (or along the axis, at the cube's own coordinate), a centre vertex inside, and no
// triangle has all three corners on one face of its cube (the extraction draws no diagonal in
// a face).
std::vector<std::vector<Id32>> triangles_by_brick(const TriangleMesh& mesh,
                                                  const std::vector<LatticePlace>& places,
                                                  const BrickGrid& g) {
  std::vector<std::vector<Id32>> by_brick(g.bricks());
  for (Id32 t = 0; t < Id32(mesh.triangles.size()); ++t) {
    std::array<std::int64_t, 3> cube{};
    for (int x = 0; x < 3; ++x) {
      std::int64_t c = std::numeric_limits<std::int64_t>::max();
      for (Id32 v : mesh.triangles[t]) c = std::min<std::int64_t>(c, places[v].at[x]);
      cube[x] = std::min(c, g.samples[x] - 2);
    }
    by_brick[g.brick_of_cube(cube)].push_back(t);
  }
  return by_brick;
}

// A part of the surface taken out to be simplified on its own: its mesh, and per vertex the
// whole surface's vertex it is.
struct Part {
  TriangleMesh mesh;
  std::vector<Id32> vertex;
};

// The triangles `tris` of `m`, with the vertices they use in ascending order.
Part cut_out(const TriangleMesh& m, const std::vector<Id32>& tris, std::vector<Id32>& scratch_map) {
  Part p;
  for (Id32 t : tris)
    for (Id32 v : m.triangles[t]) p.vertex.push_back(v);
  std::sort(p.vertex.begin(), p.vertex.end());
  p.vertex.erase(std::unique(p.vertex.begin(), p.vertex.end()), p.vertex.end());
  for (Id32 i = 0; i < Id32(p.vertex.size()); ++i) scratch_map[p.vertex[i]] = i;
  p.mesh.positions.reserve(p.vertex.size());
  for (Id32 v : p.vertex) {
    p.mesh.positions.push_back(m.positions[v]);
    if (!m.normals.empty()) p.mesh.normals.push_back(m.normals[v]);
  }
  p.mesh.triangles.reserve(tris.size());
  for (Id32 t : tris) {
    const auto& tri = m.triangles[t];
    p.mesh.triangles.push_back({scratch_map[tri[0]], scratch_map[tri[1]], scratch_map[tri[2]]});
  }
  return p;
}

// A brick after the brick pass: its simplified mesh, per output vertex the input vertex it is,
// and the last run's points with the output triangles they are attached to.
struct BrickResult {
  TriangleMesh mesh;
  std::vector<Id32> vertex;
  std::vector<std::array<float, 3>> points;
  std::vector<Id32> point_face;
};

// One brick through `stages` (simplify_stages), its face vertices locked in every run.
BrickResult simplify_brick(Part part, const std::vector<std::uint8_t>& face,
                           std::vector<SimplifyOptions> stages, double ratio) {
  BrickResult r;
  SimplifyCarry carry;
  for (auto& s : stages) {
    s.min_triangles = std::size_t(ratio * double(part.mesh.triangles.size()));
    s.blocks_from = kBrickBlocksFrom;
  }
  for (const SimplifyOptions& s : stages) {
    if (&s != &stages.front()) {
      // As simplify() does between its runs; the vertices keep their whole surface's numbers.
      std::vector<Id32> order;
      part.mesh = spatially_ordered(part.mesh, &order);
      std::vector<Id32> vertex(order.size());
      for (std::size_t i = 0; i < order.size(); ++i) vertex[i] = part.vertex[order[i]];
      part.vertex = std::move(vertex);
    }
    carry.locked.resize(part.vertex.size());
    for (std::size_t i = 0; i < part.vertex.size(); ++i) carry.locked[i] = face[part.vertex[i]];
    const TriangleMesh in = std::move(part.mesh);
    part.mesh = simplify_within(in, s, nullptr, &carry);
    // The last run's points are its input's vertices.
    r.points = in.positions;
    std::vector<Id32> vertex(carry.source.size());
    for (std::size_t i = 0; i < vertex.size(); ++i) vertex[i] = part.vertex[carry.source[i]];
    part.vertex = std::move(vertex);
  }
  r.mesh = std::move(part.mesh);
  r.vertex = std::move(part.vertex);
  r.point_face = std::move(carry.point_face);
  if (r.point_face.empty()) r.points.clear();
  // Points on no triangle (none in an extraction) carry nothing.
  std::size_t kept = 0;
  for (std::size_t p = 0; p < r.point_face.size(); ++p)
    if (r.point_face[p] != kNone) {
      r.points[kept] = r.points[p];
      r.point_face[kept++] = r.point_face[p];
    }
  r.points.resize(kept);
  r.point_face.resize(kept);
  return r;
}

// The welded surface: the bricks' meshes joined by the extracted vertex each vertex is, with
// the points and per vertex whether it is a face vertex.
struct Welded {
  TriangleMesh mesh;
  std::vector<std::uint8_t> face;
  std::vector<std::array<float, 3>> points;
  std::vector<Id32> point_face;
};

Welded weld(const std::vector<BrickResult>& bricks, const std::vector<std::uint8_t>& face, std::size_t nv,
            bool normals) {
  Welded w;
  std::vector<Id32> id(nv, kNone);
  for (const BrickResult& b : bricks) {
    const Id32 base = Id32(w.mesh.triangles.size());
    for (std::size_t i = 0; i < b.vertex.size(); ++i) {
      Id32& to = id[b.vertex[i]];
      if (to != kNone) {
        // Only a face vertex is in two bricks, and it is locked: the same everywhere.
        MLFE_CHECK(face[b.vertex[i]] && w.mesh.positions[to] == b.mesh.positions[i]);
        continue;
      }
      to = Id32(w.mesh.positions.size());
      w.mesh.positions.push_back(b.mesh.positions[i]);
      if (normals) w.mesh.normals.push_back(b.mesh.normals[i]);
      w.face.push_back(face[b.vertex[i]]);
    }
    for (const auto& t : b.mesh.triangles)
      w.mesh.triangles.push_back({id[b.vertex[t[0]]], id[b.vertex[t[1]]], id[b.vertex[t[2]]]});
    w.points.insert(w.points.end(), b.points.begin(), b.points.end());
    for (Id32 f : b.point_face) w.point_face.push_back(base + f);
  }
  return w;
}

// The seam strips: triangles within kSeamRings rings of a face vertex (1 per triangle).
std::vector<std::uint8_t> strip_triangles(const Welded& w) {
  std::vector<std::uint8_t> near = w.face, strip(w.mesh.triangles.size(), 0);
  for (int ring = 0; ring < kSeamRings; ++ring) {
    for (std::size_t t = 0; t < strip.size(); ++t)
      for (Id32 v : w.mesh.triangles[t])
        if (near[v] == 1) strip[t] = 1;
    for (std::size_t t = 0; t < strip.size(); ++t)
      if (strip[t])
        for (Id32 v : w.mesh.triangles[t]) near[v] = near[v] ? near[v] : 2;
    for (auto& n : near) n = n ? 1 : 0;
  }
  return strip;
}

// The seam pass: the strips simplified with their rim locked and the points attached to them,
// under `opts` (the brick pass's last run) down to `budget` triangles of the whole surface.
TriangleMesh seam_pass(Welded w, SimplifyOptions opts, std::size_t budget, BrickStats& stats) {
  const std::vector<std::uint8_t> strip = strip_triangles(w);
  std::vector<Id32> inside, outside;
  for (Id32 t = 0; t < Id32(strip.size()); ++t) (strip[t] ? inside : outside).push_back(t);
  std::vector<Id32> map(w.mesh.positions.size(), kNone);
  Part part = cut_out(w.mesh, inside, map);
  // The rim: strip vertices that a triangle outside the strips also uses.
  std::vector<std::uint8_t> rim(w.mesh.positions.size(), 0);
  for (Id32 t : outside)
    for (Id32 v : w.mesh.triangles[t]) rim[v] = 1;
  SimplifyCarry carry;
  carry.locked.resize(part.vertex.size());
  for (std::size_t i = 0; i < part.vertex.size(); ++i) carry.locked[i] = rim[part.vertex[i]];
  if (opts.verify_bound) {
    std::vector<Id32> strip_index(strip.size(), kNone);
    for (Id32 i = 0; i < Id32(inside.size()); ++i) strip_index[inside[i]] = i;
    for (std::size_t p = 0; p < w.points.size(); ++p)
      if (strip[w.point_face[p]]) {
        carry.points.push_back(w.points[p]);
        carry.point_face.push_back(strip_index[w.point_face[p]]);
      }
  }
  opts.min_triangles = budget > outside.size() ? budget - outside.size() : 0;
  stats.seam_triangles = inside.size();
  const TriangleMesh seams =
      inside.empty() ? TriangleMesh{} : simplify_within(part.mesh, opts, nullptr, &carry);
  stats.seam_output = seams.triangles.size();

  // The strips' vertices take their simplified places (a moving survivor); the surface is the
  // triangles outside, then the strips', with the vertices in use in welded order.
  std::vector<Id32> seam_vertex(seams.positions.size());
  for (std::size_t i = 0; i < seams.positions.size(); ++i) {
    seam_vertex[i] = part.vertex[carry.source[i]];
    w.mesh.positions[seam_vertex[i]] = seams.positions[i];
    if (!w.mesh.normals.empty()) w.mesh.normals[seam_vertex[i]] = seams.normals[i];
  }
  std::vector<std::array<Id32, 3>> tris;
  tris.reserve(outside.size() + seams.triangles.size());
  for (Id32 t : outside) tris.push_back(w.mesh.triangles[t]);
  for (const auto& t : seams.triangles)
    tris.push_back({seam_vertex[t[0]], seam_vertex[t[1]], seam_vertex[t[2]]});
  TriangleMesh out;
  std::fill(map.begin(), map.end(), kNone);
  for (const auto& t : tris)
    for (Id32 v : t) map[v] = 0;
  for (Id32 v = 0; v < Id32(map.size()); ++v)
    if (map[v] != kNone) {
      map[v] = Id32(out.positions.size());
      out.positions.push_back(w.mesh.positions[v]);
      if (!w.mesh.normals.empty()) out.normals.push_back(w.mesh.normals[v]);
    }
  out.triangles.reserve(tris.size());
  for (const auto& t : tris) out.triangles.push_back({map[t[0]], map[t[1]], map[t[2]]});
  return out;
}

}  // namespace

TriangleMesh simplify_in_bricks(const TriangleMesh& mesh, const std::vector<LatticePlace>& places,
                                const std::array<std::int64_t, 3>& dims, const SimplifierOptions& o,
                                std::int64_t brick, BrickStats* stats) {
  if (o.kind == Simplifier::kMeshopt)
    throw Error(
        "bricks: the meshopt simplifier cannot lock the bricks' face vertices (use auto, fast or bounded)");
  if (places.size() != mesh.positions.size())
    throw Error("bricks: the lattice places are not one per vertex");
  if (!(o.tolerance > 0) || !std::isfinite(o.tolerance))
    throw Error("simplification: the tolerance must be positive and finite");
  const BrickGrid g = brick_grid(dims, brick);
  for (const auto& t : mesh.triangles)
    for (Id32 v : t)
      if (v >= mesh.positions.size()) throw Error("bricks: triangle index out of range");
  const std::vector<std::uint8_t> face = face_vertices(places, g);
  const std::vector<std::vector<Id32>> by_brick = triangles_by_brick(mesh, places, g);
  // The whole surface's runs (kAuto decides by its size), each brick to its share of the ratio.
  const std::vector<SimplifyOptions> stages = simplify_stages(o, mesh.triangles.size());

  std::vector<BrickResult> results(by_brick.size());
  tbb::parallel_for(std::size_t(0), by_brick.size(), std::size_t(1), [&](std::size_t b) {
    if (by_brick[b].empty()) return;
    std::vector<Id32> map(mesh.positions.size());
    results[b] = simplify_brick(cut_out(mesh, by_brick[b], map), face, stages, o.ratio);
  });

  BrickStats st;
  for (const auto& b : by_brick) st.bricks += !b.empty();
  for (std::uint8_t f : face) st.face_vertices += f;
  Welded w = weld(results, face, mesh.positions.size(), !mesh.normals.empty());
  results.clear();
  st.welded_triangles = w.mesh.triangles.size();
  TriangleMesh out =
      seam_pass(std::move(w), stages.back(), std::size_t(o.ratio * double(mesh.triangles.size())), st);
  if (o.placement == Placement::kOptimal) {
    SurfaceFitOptions fo;
    fo.tolerance = o.tolerance;
    fit_surface(out, mesh, fo);
  }
  if (stats) *stats = st;
  return out;
}

}  // namespace mlfe
