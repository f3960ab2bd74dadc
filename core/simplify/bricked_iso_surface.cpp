// The brick pass, the weld and the seam pass; the design and why the bound holds are in
// bricked_iso_surface.h.
#include <mlfe/core/base/check.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/simplify/bricked_iso_surface.h>
#include <mlfe/core/simplify/surface_simplification.h>
#include <mlfe/core/surface/surface_fitting.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>
#include <tbb/task_arena.h>
#include <tbb/task_group.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <numeric>
#include <string>
#include <unordered_map>

namespace mlfe {

namespace {

using Id32 = std::uint32_t;
constexpr Id32 kNone = std::numeric_limits<Id32>::max();

// Rings of triangles around the face vertices that the seam pass simplifies again: one ring
// holds the face vertices' own triangles; the second lets the collapses that remove a face
// vertex also move its neighbours, whose rim would otherwise be locked.
constexpr int kSeamRings = 2;

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

// One brick's runs: simplify()'s for a big surface (a brick is part of one: kAuto's estimated
// run first, then the verified one), each stopping at `ratio` of the brick's triangles and
// starting with the blocks whatever the brick's size (the brick is the unit of parallelism,
// and inside it the blocks' sequential cheapest-first collapses do the work with less overhead
// than the passes).
std::vector<SimplifyOptions> brick_stages(const SimplifierOptions& o, std::size_t triangles) {
  constexpr std::size_t kBigSurface = std::size_t(1) << 31;
  std::vector<SimplifyOptions> stages = simplify_stages(o, kBigSurface);
  for (auto& s : stages) {
    s.min_triangles = std::size_t(o.ratio * double(triangles));
    s.blocks_from = 0;
  }
  return stages;
}

// The brick's simplified surface: per output vertex the extracted vertex it is, and the last
// run's points with the output triangles they are attached to (verified bound).
struct Simplified {
  TriangleMesh mesh;
  std::vector<Id32> vertex;
  std::vector<std::array<float, 3>> points;
  std::vector<Id32> point_face;
};

// `mesh` through `stages`, the vertices flagged in `face` locked in every run.
Simplified run_stages(const TriangleMesh& mesh, const std::vector<std::uint8_t>& face,
                      const std::vector<SimplifyOptions>& stages) {
  Simplified r;
  r.mesh = mesh;
  r.vertex.resize(mesh.positions.size());
  std::iota(r.vertex.begin(), r.vertex.end(), Id32(0));
  SimplifyCarry carry;
  for (const SimplifyOptions& s : stages) {
    if (&s != &stages.front()) {
      // As simplify() does between its runs.
      std::vector<Id32> order;
      r.mesh = spatially_ordered(r.mesh, &order);
      std::vector<Id32> vertex(order.size());
      for (std::size_t i = 0; i < order.size(); ++i) vertex[i] = r.vertex[order[i]];
      r.vertex = std::move(vertex);
    }
    carry.locked.resize(r.vertex.size());
    for (std::size_t i = 0; i < r.vertex.size(); ++i) carry.locked[i] = face[r.vertex[i]];
    const TriangleMesh in = std::move(r.mesh);
    r.mesh = simplify_within(in, s, nullptr, &carry);
    r.points = in.positions;  // the last run's points are its input's vertices
    std::vector<Id32> vertex(carry.source.size());
    for (std::size_t i = 0; i < vertex.size(); ++i) vertex[i] = r.vertex[carry.source[i]];
    r.vertex = std::move(vertex);
  }
  r.point_face = std::move(carry.point_face);
  if (r.point_face.empty()) r.points.clear();
  return r;
}

// Triangles within kSeamRings rings of a vertex flagged in `face` (1 per triangle). A face
// vertex's ring in the welded surface is its rings in the bricks that share it, and every other
// vertex is in one brick only: a brick's own strips are its share of the welded surface's.
std::vector<std::uint8_t> strip_triangles(const TriangleMesh& m, std::vector<std::uint8_t> near) {
  std::vector<std::uint8_t> strip(m.triangles.size(), 0);
  for (int ring = 0; ring < kSeamRings; ++ring) {
    for (std::size_t t = 0; t < strip.size(); ++t)
      for (Id32 v : m.triangles[t])
        if (near[v] == 1) strip[t] = 1;
    for (std::size_t t = 0; t < strip.size(); ++t)
      if (strip[t])
        for (Id32 v : m.triangles[t]) near[v] = near[v] ? near[v] : 2;
    for (auto& n : near) n = n ? 1 : 0;
  }
  return strip;
}

// The least-squares refit of the triangles outside the strips to the brick's extraction, as
// simplify() ends with kOptimal. Cut out, the strips' rim lies on the cut's boundary, which
// fit_surface keeps: the strips, and the points attached to them, stay as they are for the seam
// pass.
void refit_outside_strips(TriangleMesh& mesh, const std::vector<std::uint8_t>& strip,
                          const TriangleMesh& dense, double tolerance) {
  std::vector<Id32> outside;
  for (Id32 t = 0; t < Id32(strip.size()); ++t)
    if (!strip[t]) outside.push_back(t);
  if (outside.empty()) return;
  std::vector<Id32> map(mesh.positions.size());
  Part part = cut_out(mesh, outside, map);
  SurfaceFitOptions fo;
  fo.tolerance = tolerance;
  fit_surface(part.mesh, dense, fo);
  for (std::size_t i = 0; i < part.vertex.size(); ++i)
    mesh.positions[part.vertex[i]] = part.mesh.positions[i];
}

// A sample coordinate on a plane two bricks share.
bool shared_plane(const BrickLayout& l, int axis, std::int64_t c) {
  return c > 0 && c < l.dims[axis] - 1 && c % l.edge == 0;
}

// A vertex on a lattice edge that lies in a shared sample plane.
bool on_shared_plane(const BrickLayout& l, const LatticePlace& p) {
  if (p.axis < 0 || p.axis > 2) return false;
  for (int x = 0; x < 3; ++x)
    if (x != p.axis && shared_plane(l, x, p.at[x])) return true;
  return false;
}

// What a vertex of a join is: one brick's (or closed by an earlier join), a face vertex whose
// bricks all lie in the join (its strips are simplified now), or one still shared with bricks
// outside it (locked, kept with its place for a later join).
enum : std::uint8_t { kInner = 0, kClosing = 1, kOpen = 2 };

// A face vertex that stays shared with bricks outside the slabs [first, end): it lies on the
// group's bottom or top sample plane, and those planes are shared with other slabs.
bool open_in(const BrickLayout& l, const LatticePlace& p, std::size_t first, std::size_t end) {
  if (p.axis == 2) return false;
  const std::int64_t z = p.at[2];
  return (first > 0 && z == std::int64_t(first) * l.edge) ||
         (end < std::size_t(l.count[2]) && z == std::int64_t(end) * l.edge);
}

// The pieces of a join welded: per vertex what it is, the open vertices (ascending) with their
// places, and the points.
struct Welded {
  TriangleMesh mesh;
  std::vector<std::uint8_t> face;
  std::vector<Id32> open;
  std::vector<LatticePlace> open_place;
  std::vector<std::array<float, 3>> points;
  std::vector<Id32> point_face;
  std::size_t extracted_triangles = 0;
};

struct PlaceKey {
  std::int32_t at[3];
  int axis;
  bool operator==(const PlaceKey& o) const {
    return at[0] == o.at[0] && at[1] == o.at[1] && at[2] == o.at[2] && axis == o.axis;
  }
};
struct PlaceHash {
  std::size_t operator()(const PlaceKey& k) const {
    std::uint64_t h = std::uint64_t(std::uint32_t(k.at[0]));
    h = h * 0x9E3779B97F4A7C15ull ^ std::uint32_t(k.at[1]);
    h = h * 0x9E3779B97F4A7C15ull ^ std::uint32_t(k.at[2]);
    h = h * 0x9E3779B97F4A7C15ull ^ std::uint32_t(k.axis);
    return std::size_t(h ^ (h >> 29));
  }
};

// A piece's own consistency, before any of it is welded.
void check_piece(const BrickPart& b) {
  if (b.face_place.size() != b.face_vertex.size())
    throw Error("bricks: a brick's face places are not one per face vertex");
  for (std::size_t k = 0; k < b.face_vertex.size(); ++k)
    if (b.face_vertex[k] >= b.mesh.positions.size() || (k > 0 && b.face_vertex[k] <= b.face_vertex[k - 1]))
      throw Error("bricks: a brick's face vertices are not ascending vertices");
  if (!b.mesh.normals.empty() && b.mesh.normals.size() != b.mesh.positions.size())
    throw Error("bricks: a brick's normals are not one per vertex");
  for (const auto& t : b.mesh.triangles)
    for (Id32 v : t)
      if (v >= b.mesh.positions.size()) throw Error("bricks: a brick's triangle index is out of range");
  if (b.points.size() != b.point_face.size())
    throw Error("bricks: a brick's points and their faces differ in number");
  for (Id32 f : b.point_face)
    if (f >= b.mesh.triangles.size()) throw Error("bricks: a brick's point is attached to no triangle");
}

// The pieces of the slabs [first, end) joined at their face vertices. Each piece is released once
// appended, and the welded arrays are reserved at their final size (at most), so the pieces and
// the welded surface are not both held, nor grown by doubling.
Welded weld(std::vector<BrickPart> parts, const BrickLayout& l, std::size_t first, std::size_t end) {
  Welded w;
  std::size_t vertices = 0, triangles = 0, points = 0;
  for (const BrickPart& b : parts) {
    vertices += b.mesh.positions.size();
    triangles += b.mesh.triangles.size();
    points += b.points.size();
    w.extracted_triangles += b.extracted_triangles;
  }
  w.mesh.positions.reserve(vertices);
  w.mesh.triangles.reserve(triangles);
  w.face.reserve(vertices);
  w.points.reserve(points);
  w.point_face.reserve(points);
  std::unordered_map<PlaceKey, Id32, PlaceHash> joined;
  std::unordered_map<Id32, Id32> uses;  // per closing vertex, how many pieces have it
  for (BrickPart& part : parts) {
    const BrickPart b = std::move(part);
    check_piece(b);
    if (b.mesh.positions.empty()) continue;
    const bool normals = !b.mesh.normals.empty();
    if (normals != !w.mesh.normals.empty() && !w.mesh.positions.empty())
      throw Error("bricks: the bricks' parts disagree on normals");
    if (normals && w.mesh.normals.capacity() == 0) w.mesh.normals.reserve(vertices);
    const Id32 base = Id32(w.mesh.triangles.size());
    std::vector<Id32> id(b.mesh.positions.size());
    std::size_t next_face = 0;  // into b.face_vertex
    for (std::size_t i = 0; i < id.size(); ++i) {
      std::uint8_t kind = kInner;
      if (next_face < b.face_vertex.size() && b.face_vertex[next_face] == i) {
        const LatticePlace& p = b.face_place[next_face++];
        const auto [it, fresh] =
            joined.try_emplace(PlaceKey{{p.at[0], p.at[1], p.at[2]}, p.axis}, Id32(w.mesh.positions.size()));
        id[i] = it->second;
        if (!fresh) {
          if (w.mesh.positions[id[i]] != b.mesh.positions[i])
            throw Error(
                "bricks: two bricks' parts place a shared vertex differently (parts of different volumes?)");
          if (w.face[id[i]] == kClosing) ++uses[id[i]];
          continue;
        }
        kind = open_in(l, p, first, end) ? kOpen : kClosing;
        if (kind == kOpen) {
          w.open.push_back(id[i]);
          w.open_place.push_back(p);
        } else {
          uses[id[i]] = 1;
        }
      } else {
        id[i] = Id32(w.mesh.positions.size());
      }
      w.mesh.positions.push_back(b.mesh.positions[i]);
      if (normals) w.mesh.normals.push_back(b.mesh.normals[i]);
      w.face.push_back(kind);
    }
    for (const auto& t : b.mesh.triangles) w.mesh.triangles.push_back({id[t[0]], id[t[1]], id[t[2]]});
    w.points.insert(w.points.end(), b.points.begin(), b.points.end());
    for (Id32 f : b.point_face) w.point_face.push_back(base + f);
  }
  for (const auto& [v, n] : uses)
    if (n < 2)
      throw Error(
          "bricks: a vertex on a shared face is in one brick's part only (parts of different volumes?)");
  return w;
}

// The join's piece: the triangles outside the strips, then the strips' simplified ones
// (`seams`, whose vertex i is the welded vertex strip_vertex[carry.source[i]]), with the
// vertices in use in welded order; the open vertices with their places; the points attached to
// triangles within kSeamRings rings of an open vertex (the only triangles a later join takes
// again): `kept_points` on the outside triangles `kept_face` (welded indices), then the seam
// pass's.
BrickPart compact(Welded w, const std::vector<Id32>& outside, const std::vector<Id32>& strip_vertex,
                  const TriangleMesh& seams, const SimplifyCarry& carry,
                  std::vector<std::array<float, 3>> kept_points, std::vector<Id32> kept_face) {
  // The strips' vertices take their simplified places (a moving survivor).
  std::vector<Id32> seam_vertex(seams.positions.size());
  for (std::size_t i = 0; i < seams.positions.size(); ++i) {
    seam_vertex[i] = strip_vertex[carry.source[i]];
    w.mesh.positions[seam_vertex[i]] = seams.positions[i];
    if (!w.mesh.normals.empty()) w.mesh.normals[seam_vertex[i]] = seams.normals[i];
  }
  {
    std::vector<Id32> new_index(w.mesh.triangles.size(), kNone);
    for (Id32 i = 0; i < Id32(outside.size()); ++i) new_index[outside[i]] = i;
    for (Id32& f : kept_face) f = new_index[f];
  }
  for (std::size_t p = 0; p < carry.points.size(); ++p)
    if (carry.point_face[p] != kNone) {
      kept_points.push_back(carry.points[p]);
      kept_face.push_back(Id32(outside.size()) + carry.point_face[p]);
    }
  // Compacted in place (a vertex only moves down), so the surface is not held twice.
  std::vector<std::array<Id32, 3>> tris;
  tris.reserve(outside.size() + seams.triangles.size());
  for (Id32 t : outside) tris.push_back(w.mesh.triangles[t]);
  for (const auto& t : seams.triangles)
    tris.push_back({seam_vertex[t[0]], seam_vertex[t[1]], seam_vertex[t[2]]});
  BrickPart out;
  out.extracted_triangles = w.extracted_triangles;
  out.mesh = std::move(w.mesh);
  std::vector<std::array<Id32, 3>>().swap(out.mesh.triangles);
  std::vector<Id32> map(out.mesh.positions.size(), kNone);
  for (const auto& t : tris)
    for (Id32 v : t) map[v] = 0;
  Id32 used = 0;
  for (Id32 v = 0; v < Id32(map.size()); ++v)
    if (map[v] != kNone) {
      map[v] = used;
      out.mesh.positions[used] = out.mesh.positions[v];
      if (!out.mesh.normals.empty()) out.mesh.normals[used] = out.mesh.normals[v];
      ++used;
    }
  out.mesh.positions.resize(used);
  if (!out.mesh.normals.empty()) out.mesh.normals.resize(used);
  for (auto& t : tris) t = {map[t[0]], map[t[1]], map[t[2]]};
  out.mesh.triangles = std::move(tris);
  // An open vertex is locked, so it is still in use.
  std::vector<std::uint8_t> open(used, 0);
  for (Id32 v : w.open) {
    MLFE_CHECK(map[v] != kNone);
    out.face_vertex.push_back(map[v]);
    open[map[v]] = 1;
  }
  out.face_place = std::move(w.open_place);
  if (!out.face_vertex.empty()) {
    const std::vector<std::uint8_t> near = strip_triangles(out.mesh, std::move(open));
    for (std::size_t p = 0; p < kept_face.size(); ++p)
      if (near[kept_face[p]]) {
        out.points.push_back(kept_points[p]);
        out.point_face.push_back(kept_face[p]);
      }
  }
  for (auto* v : {&out.mesh.positions, &out.mesh.normals, &out.points}) v->shrink_to_fit();
  out.point_face.shrink_to_fit();
  return out;
}

// The join's piece: the welded surface with the strips around its closing vertices simplified
// (their rim and the open vertices locked, the points attached to them kept within the
// tolerance) under `opts` (the brick pass's last run), down to `budget` triangles of the
// join's surface; it keeps the open vertices' places and the points near them for later joins.
BrickPart seam_pass(Welded w, SimplifyOptions opts, std::size_t budget, BrickStats& stats) {
  std::vector<std::uint8_t> closing(w.face.size());
  for (std::size_t v = 0; v < closing.size(); ++v) closing[v] = w.face[v] == kClosing;
  std::vector<std::uint8_t> strip = strip_triangles(w.mesh, std::move(closing));
  std::vector<Id32> inside, outside;
  for (Id32 t = 0; t < Id32(strip.size()); ++t) (strip[t] ? inside : outside).push_back(t);
  std::vector<Id32> map(w.mesh.positions.size(), kNone);
  Part part = cut_out(w.mesh, inside, map);
  // Locked: the rim (strip vertices that a triangle outside the strips also uses) and the
  // vertices still shared with bricks outside the join.
  std::vector<std::uint8_t> rim(w.mesh.positions.size(), 0);
  for (Id32 t : outside)
    for (Id32 v : w.mesh.triangles[t]) rim[v] = 1;
  SimplifyCarry carry;
  carry.locked.resize(part.vertex.size());
  for (std::size_t i = 0; i < part.vertex.size(); ++i)
    carry.locked[i] = rim[part.vertex[i]] || w.face[part.vertex[i]] == kOpen;
  // The points: those on the strips go to the seam pass; the others stay on their triangle.
  std::vector<Id32> new_index(strip.size(), kNone);
  for (Id32 i = 0; i < Id32(inside.size()); ++i) new_index[inside[i]] = i;
  std::vector<std::array<float, 3>> kept_points;
  std::vector<Id32> kept_face;
  if (opts.verify_bound)
    for (std::size_t p = 0; p < w.points.size(); ++p) {
      const Id32 f = w.point_face[p];
      if (strip[f]) {
        carry.points.push_back(w.points[p]);
        carry.point_face.push_back(new_index[f]);
      } else {
        kept_points.push_back(w.points[p]);
        kept_face.push_back(f);
      }
    }
  // What the strips' simplification does not need is released before it runs.
  std::vector<std::uint8_t>().swap(rim);
  std::vector<std::array<float, 3>>().swap(w.points);
  std::vector<Id32>().swap(w.point_face);
  std::vector<Id32>().swap(map);
  std::vector<std::uint8_t>().swap(strip);
  std::vector<Id32>().swap(new_index);
  stats.seam_triangles += inside.size();
  std::vector<Id32>().swap(inside);
  opts.min_triangles = budget > outside.size() ? budget - outside.size() : 0;
  const bool simplify = !part.mesh.triangles.empty();
  const TriangleMesh seams = simplify ? simplify_within(part.mesh, opts, nullptr, &carry) : TriangleMesh{};
  stats.seam_output += seams.triangles.size();
  part.mesh = TriangleMesh{};
  return compact(std::move(w), outside, part.vertex, seams, carry, kept_points, kept_face);
}
// Connected parts of the triangles (joined through shared vertices).
std::size_t count_parts(const TriangleMesh& m) {
  std::vector<Id32> up(m.positions.size());
  std::iota(up.begin(), up.end(), Id32(0));
  auto find = [&](Id32 v) {
    while (up[v] != v) v = up[v] = up[up[v]];
    return v;
  };
  std::vector<std::uint8_t> used(m.positions.size(), 0);
  for (const auto& t : m.triangles)
    for (int k = 0; k < 3; ++k) {
      used[t[k]] = 1;
      up[find(t[k])] = find(t[(k + 1) % 3]);
    }
  std::size_t parts = 0;
  for (Id32 v = 0; v < Id32(up.size()); ++v) parts += used[v] && find(v) == v;
  return parts;
}

}  // namespace

void BrickLayout::samples(std::size_t b, std::array<std::int64_t, 3>& lo,
                          std::array<std::int64_t, 3>& hi) const {
  MLFE_CHECK(b < bricks());
  std::int64_t rest = std::int64_t(b);
  for (int x = 0; x < 3; ++x) {
    const std::int64_t c = rest % count[x];
    rest /= count[x];
    lo[x] = c * edge;
    hi[x] = std::min(lo[x] + edge, dims[x] - 1) + 1;
  }
}

void BrickLayout::window(std::size_t b, std::array<std::int64_t, 3>& lo,
                         std::array<std::int64_t, 3>& hi) const {
  samples(b, lo, hi);
  for (int x = 0; x < 3; ++x) {
    lo[x] = std::max<std::int64_t>(0, lo[x] - 1);
    hi[x] = std::min(dims[x], hi[x] + 1);
  }
}

BrickLayout brick_layout(const std::array<std::int64_t, 3>& dims, std::int64_t edge) {
  if (edge < 2 || (edge & (edge - 1)) != 0)
    throw Error("bricks: the brick edge must be a power of two of at least 2, got " + std::to_string(edge));
  BrickLayout l;
  l.dims = dims;
  l.edge = edge;
  for (int x = 0; x < 3; ++x) {
    if (dims[x] < 2) throw Error("bricks: a volume of fewer than 2 samples along an axis has no cubes");
    if (dims[x] > std::numeric_limits<std::int32_t>::max())
      throw Error("bricks: more than 2^31 samples along an axis");
    l.count[x] = (dims[x] - 1 + edge - 1) / edge;
  }
  return l;
}

BrickPart brick_pass(const ScalarGrid& window, const BrickLayout& layout, std::size_t b, double iso,
                     const BrickedIsoOptions& o) {
  if (o.simplifier.kind == Simplifier::kMeshopt)
    throw Error(
        "bricks: the meshopt simplifier cannot lock the bricks' face vertices (use auto, fast or bounded)");
  if (!(o.simplifier.tolerance > 0) || !std::isfinite(o.simplifier.tolerance))
    throw Error("simplification: the tolerance must be positive and finite");
  if (b >= layout.bricks()) throw Error("bricks: brick " + std::to_string(b) + " is not in the layout");
  std::array<std::int64_t, 3> wlo, whi, lo, hi;
  layout.window(b, wlo, whi);
  layout.samples(b, lo, hi);
  for (int x = 0; x < 3; ++x)
    if (window.dim != 3 || window.dims[x] != whi[x] - wlo[x] ||
        window.values.size() != std::size_t(window.voxel_count()))
      throw Error("bricks: brick " + std::to_string(b) + "'s window has the wrong size");
  // 1. Extract the brick's part of the surface.
  BrickPart part;
  std::vector<LatticePlace> places;
  IsoOptions io;
  io.normals_toward_higher = o.normals_toward_higher;
  const TriangleMesh extracted =
      lattice_iso_surface(window, wlo, {lo[0] - wlo[0], lo[1] - wlo[1], lo[2] - wlo[2]},
                          {hi[0] - wlo[0], hi[1] - wlo[1], hi[2] - wlo[2]}, iso, io, &places);
  part.extracted_triangles = extracted.triangles.size();
  if (extracted.triangles.empty()) return part;
  // 2. Lock the face vertices and simplify.
  std::vector<std::uint8_t> face(places.size());
  for (std::size_t v = 0; v < places.size(); ++v) face[v] = on_shared_plane(layout, places[v]);
  Simplified s = run_stages(extracted, face, brick_stages(o.simplifier, extracted.triangles.size()));
  // 3. Refit outside the strips.
  std::vector<std::uint8_t> out_face(s.vertex.size());
  for (std::size_t i = 0; i < s.vertex.size(); ++i) out_face[i] = face[s.vertex[i]];
  const std::vector<std::uint8_t> strip = strip_triangles(s.mesh, out_face);
  if (o.simplifier.placement == Placement::kOptimal)
    refit_outside_strips(s.mesh, strip, extracted, o.simplifier.tolerance);
  // 4. Keep what the join needs, at its size (every brick's part is held until the join): the
  // face vertices' places, the points on the strips.
  for (Id32 i = 0; i < Id32(s.vertex.size()); ++i)
    if (out_face[i]) {
      part.face_vertex.push_back(i);
      part.face_place.push_back(places[s.vertex[i]]);
    }
  for (std::size_t p = 0; p < s.point_face.size(); ++p)
    if (s.point_face[p] != kNone && strip[s.point_face[p]]) {
      part.points.push_back(s.points[p]);
      part.point_face.push_back(s.point_face[p]);
    }
  part.mesh = std::move(s.mesh);
  for (auto* v : {&part.mesh.positions, &part.mesh.normals, &part.points}) v->shrink_to_fit();
  part.mesh.triangles.shrink_to_fit();
  part.face_vertex.shrink_to_fit();
  part.face_place.shrink_to_fit();
  part.point_face.shrink_to_fit();
  return part;
}

std::size_t slab_split(std::size_t first, std::size_t end) {
  MLFE_CHECK(end > first + 1);
  return first + (end - first) / 2;
}

BrickPart join_slabs(std::vector<BrickPart> pieces, const BrickLayout& layout, std::size_t first,
                     std::size_t end, const BrickedIsoOptions& o, BrickStats* stats) {
  if (!(first < end && end <= layout.slabs()))
    throw Error("bricks: slabs [" + std::to_string(first) + ", " + std::to_string(end) +
                ") are not the layout's");
  const std::size_t expected = end == first + 1 ? layout.slab_bricks() : 2;
  if (pieces.size() != expected)
    throw Error("bricks: " + std::to_string(pieces.size()) + " pieces for slabs [" + std::to_string(first) +
                ", " + std::to_string(end) + "), which join " + std::to_string(expected));
  BrickStats st;
  if (end == first + 1)
    for (const BrickPart& p : pieces) {
      st.bricks += !p.mesh.triangles.empty();
      st.welded_triangles += p.mesh.triangles.size();
    }
  Welded w = weld(std::move(pieces), layout, first, end);
  for (std::uint8_t f : w.face) st.face_vertices += f == kClosing;
  const std::vector<SimplifyOptions> stages = brick_stages(o.simplifier, w.extracted_triangles);
  BrickPart out = seam_pass(std::move(w), stages.back(), stages.back().min_triangles, st);
  if (stats) *stats = st;
  return out;
}

namespace {

// Runs `f` in a task context of its own: another brick's or join's exception cancels the tree's
// tasks, but not a simplification under way, whose parallel parts cancelled midway would leave
// it waiting for them.
template <class F>
void uncancelled(const F& f) {
  tbb::task_group_context own(tbb::task_group_context::isolated);
  tbb::task_group g(own);
  g.run_and_wait(f);
}

void add(BrickStats& to, const BrickStats& s) {
  to.bricks += s.bricks;
  to.face_vertices += s.face_vertices;
  to.seam_triangles += s.seam_triangles;
  to.seam_output += s.seam_output;
  to.welded_triangles += s.welded_triangles;
}

// The pieces (one per surface) of the tree's node [first, end), and the stats of the joins run
// for it.
struct Node {
  std::vector<BrickPart> pieces;
  std::vector<BrickStats> stats;
};

Node join_node(const SlabSource& source, const BrickLayout& layout, std::size_t first, std::size_t end,
               std::size_t surfaces, const BrickedIsoOptions& o) {
  Node n;
  n.stats.resize(surfaces);
  if (source.joined) n.pieces = source.joined(first, end);
  if (!n.pieces.empty()) {
    if (n.pieces.size() != surfaces) throw Error("bricks: a joined piece has the wrong number of surfaces");
    return n;
  }
  std::vector<std::vector<BrickPart>> in;
  if (end == first + 1) {
    in = source.bricks(first);
  } else {
    const std::size_t split = slab_split(first, end);
    Node a, b;
    tbb::parallel_invoke([&] { a = join_node(source, layout, first, split, surfaces, o); },
                         [&] { b = join_node(source, layout, split, end, surfaces, o); });
    // A half is missing when the other's exception cancelled it (that exception is the one
    // thrown from the tree).
    if (a.pieces.size() != surfaces || b.pieces.size() != surfaces)
      throw Error("bricks: a half was cancelled");
    in.resize(surfaces);
    for (std::size_t i = 0; i < surfaces; ++i) {
      in[i].push_back(std::move(a.pieces[i]));
      in[i].push_back(std::move(b.pieces[i]));
      add(n.stats[i], a.stats[i]);
      add(n.stats[i], b.stats[i]);
    }
  }
  if (in.size() != surfaces) throw Error("bricks: a slab's parts have the wrong number of surfaces");
  for (std::size_t i = 0; i < surfaces; ++i) {
    BrickStats st;
    uncancelled([&] { n.pieces.push_back(join_slabs(std::move(in[i]), layout, first, end, o, &st)); });
    add(n.stats[i], st);
  }
  return n;
}

}  // namespace

std::vector<TriangleMesh> join_tree(const SlabSource& source, const BrickLayout& layout, std::size_t surfaces,
                                    const BrickedIsoOptions& o, std::vector<BrickStats>* stats) {
  Node root = join_node(source, layout, 0, layout.slabs(), surfaces, o);
  std::vector<TriangleMesh> out;
  for (std::size_t i = 0; i < surfaces; ++i) {
    BrickPart& p = root.pieces[i];
    if (!p.face_vertex.empty()) throw Error("bricks: the whole surface still has shared face vertices");
    root.stats[i].extracted_triangles = p.extracted_triangles;
    root.stats[i].parts = count_parts(p.mesh);
    out.push_back(std::move(p.mesh));
  }
  if (stats) *stats = std::move(root.stats);
  return out;
}

TriangleMesh join_bricks(std::vector<BrickPart> parts, const BrickLayout& layout, const BrickedIsoOptions& o,
                         BrickStats* stats) {
  if (parts.size() != layout.bricks())
    throw Error("bricks: " + std::to_string(parts.size()) + " parts for " + std::to_string(layout.bricks()) +
                " bricks");
  SlabSource source;
  source.bricks = [&](std::size_t slab) {
    const std::size_t n = layout.slab_bricks();
    std::vector<std::vector<BrickPart>> in(1);
    for (std::size_t b = slab * n; b < (slab + 1) * n; ++b) in[0].push_back(std::move(parts[b]));
    return in;
  };
  std::vector<BrickStats> st;
  std::vector<TriangleMesh> out = join_tree(source, layout, 1, o, &st);
  if (stats) *stats = st[0];
  return std::move(out[0]);
}

WindowReader grid_windows(const ScalarGrid& grid) {
  MLFE_CHECK(grid.dim == 3);
  return [&grid](const std::array<std::int64_t, 3>& lo, const std::array<std::int64_t, 3>& hi) {
    return window_of(grid, lo, hi);
  };
}

std::vector<TriangleMesh> bricked_iso_surfaces(const WindowReader& read,
                                               const std::array<std::int64_t, 3>& dims, std::int64_t edge,
                                               const std::vector<double>& isos, const BrickedIsoOptions& o,
                                               std::vector<BrickStats>* stats,
                                               const BrickProgress& progress) {
  const BrickLayout layout = brick_layout(dims, edge);
  std::atomic<std::size_t> done{0};
  std::atomic<bool> stop{false};
  SlabSource source;
  // A slab's bricks are passed when its join needs them, so the parts held are those of the
  // slabs in work, beside the pieces joined so far.
  source.bricks = [&](std::size_t slab) {
    const std::size_t n = layout.slab_bricks(), first = slab * n;
    std::vector<std::vector<BrickPart>> parts(isos.size(), std::vector<BrickPart>(n));
    std::atomic<std::size_t> passed{0};
    tbb::parallel_for(first, first + n, std::size_t(1), [&](std::size_t b) {
      if (stop) return;
      // Isolated: a thread waiting inside a brick's parallel parts takes no other brick, so no
      // more windows are held than threads run.
      tbb::this_task_arena::isolate([&] {
        uncancelled([&] {
          std::array<std::int64_t, 3> lo, hi;
          layout.window(b, lo, hi);
          const ScalarGrid window = read(lo, hi);
          for (std::size_t i = 0; i < isos.size(); ++i)
            parts[i][b - first] = brick_pass(window, layout, b, isos[i], o);
        });
      });
      ++passed;
      const std::size_t k = ++done;
      if (progress && !progress(k, layout.bricks())) stop = true;
    });
    // Fewer passed: stopped, or cancelled by another brick's exception (which is the one thrown).
    if (stop || passed != n) throw Error("bricks: cancelled");
    return parts;
  };
  return join_tree(source, layout, isos.size(), o, stats);
}

}  // namespace mlfe
