// Marching tetrahedra on the multilevel hierarchy (Grosso, Lürig & Ertl, IEEE Vis 1997, Sec. 5).
#include <mlfe/core/base/check.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/base/vec.h>
#include <mlfe/core/fem/hierarchical_basis.h>
#include <mlfe/core/fem/p1_element.h>
#include <mlfe/core/mesh/edge_map.h>
#include <mlfe/core/surface/iso_surface.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <unordered_map>

#include "surface/surface_parts.h"

namespace mlfe {

namespace {

double det3(const std::array<double, 9>& m) {
  return m[0] * (m[4] * m[8] - m[5] * m[7]) - m[1] * (m[3] * m[8] - m[5] * m[6]) +
         m[2] * (m[3] * m[7] - m[4] * m[6]);
}

std::array<float, 3> to_float_unit(const Vec3& v) {
  const double n = norm(v);
  if (n == 0) return {0.f, 0.f, 1.f};
  return {float(v[0] / n), float(v[1] / n), float(v[2] / n)};
}

// The crossing of f = iso nearest to x along the unit direction d, |t| <= reach: samples
// every `step` outward on both sides (nearer first, + before - at equal distance), then
// regula falsi (Illinois) in the first bracket. Returns false when there is none.
bool nearest_crossing(const Field& f, double iso, const Vec3& x, const Vec3& d, double reach, double step,
                      double& t) {
  auto g = [&](double s) { return f.value(axpy(x, s, d)) - iso; };
  const double g0 = g(0);
  if (g0 == 0) {
    t = 0;
    return true;
  }
  double prev[2] = {g0, g0};
  const int n = int(std::ceil(reach / step));
  for (int k = 1; k <= n; ++k) {
    for (int side = 0; side < 2; ++side) {
      const double sgn = side == 0 ? 1.0 : -1.0;
      const double s1 = sgn * std::min(reach, k * step), s0 = sgn * std::min(reach, (k - 1) * step);
      const double g1 = g(s1);
      if ((g1 > 0) != (prev[side] > 0) || g1 == 0) {
        double a = s0, b = s1, ga = prev[side], gb = g1;
        int last = 0;
        for (int it = 0; it < 40 && gb != 0 && std::abs(b - a) > 1e-7 * step; ++it) {
          const double c = (a * gb - b * ga) / (gb - ga);
          const double gc = g(c);
          if ((gc > 0) == (gb > 0)) {
            b = c;
            gb = gc;
            if (last == -1) ga *= 0.5;
            last = -1;
          } else {
            a = b;
            ga = gb;
            b = c;
            gb = gc;
            last = 1;
          }
        }
        t = b;
        return true;
      }
      prev[side] = g1;
    }
  }
  return false;
}

// Moves the surface's vertices (local frame) onto f = iso along u's gradient; reverts the
// vertices of any triangle the moves would flip or collapse, until none does.
void snap_to_data(const Field& f, double iso, double reach, const std::vector<Vec3>& grad,
                  const TriangleMesh& mesh, std::vector<Vec3>& local) {
  const std::vector<Vec3> original = local;
  const Vec3 hi = f.extent();
  const double step = f.resolution() / 4;
  // No crossing lies farther than the domain's diagonal: a larger reach only costs samples.
  reach = std::min(reach, norm(hi));
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, local.size(), 1024), [&](const auto& r) {
    for (std::size_t i = r.begin(); i != r.end(); ++i) {
      if (!(norm(grad[i]) > 0)) continue;
      const Vec3 d = normalized(grad[i]);
      double t = 0;
      if (!nearest_crossing(f, iso, original[i], d, reach, step, t)) continue;
      const Vec3 q = axpy(original[i], t, d);
      bool inside = true;
      for (int k = 0; k < f.dim(); ++k) inside = inside && q[k] >= 0 && q[k] <= hi[k];
      if (inside) local[i] = q;
    }
  });
  for (bool changed = true; changed;) {
    changed = false;
    for (const auto& tri : mesh.triangles) {
      const Vec3 before =
          cross(sub(original[tri[1]], original[tri[0]]), sub(original[tri[2]], original[tri[0]]));
      const Vec3 after = cross(sub(local[tri[1]], local[tri[0]]), sub(local[tri[2]], local[tri[0]]));
      if (dot(before, after) > 0.1 * std::sqrt(dot(before, before) * dot(after, after))) continue;
      for (auto v : tri)
        if (local[v] != original[v]) {
          local[v] = original[v];
          changed = true;
        }
    }
  }
}

// Sutherland–Hodgman against the planes x_a = hi_a of the box [0, hi] (the surface never
// leaves the lower faces: T0 starts at 0). Cut points are keyed by their surface edge and the
// plane, computed from the lower vertex id, so neighbours share them bit for bit; vertices
// no triangle uses any more are dropped, the others keep their order.
void clip_to_box(const Vec3& hi, TriangleMesh& mesh, std::vector<Vec3>& local, std::vector<Vec3>& grad) {
  double scale = 0;
  for (int a = 0; a < 3; ++a) scale = std::max(scale, std::abs(hi[a]));
  const double eps = 1e-9 * scale;
  auto inside = [&](const Vec3& p, int a) { return p[a] <= hi[a] + eps; };
  // On the lattice, surface vertices often lie on a face already (cut edges in it): an edge
  // from such a vertex leaves the box there, and a cut point would be a second vertex at its
  // position (a duplicate, and degenerate triangles around it).
  auto on_face = [&](const Vec3& p, int a) { return std::abs(p[a] - hi[a]) <= eps; };
  bool any_out = false;
  for (const Vec3& p : local)
    for (int a = 0; a < 3; ++a) any_out |= !inside(p, a);
  if (!any_out) return;
  std::unordered_map<std::uint64_t, std::uint32_t> cuts;  // (edge, plane) -> vertex
  auto cut_point = [&](std::uint32_t i, std::uint32_t j, int a) {
    if (i > j) std::swap(i, j);
    const std::uint64_t exact = (std::uint64_t(i) << 34) | (std::uint64_t(j) << 2) | std::uint64_t(a);
    auto it = cuts.find(exact);
    if (it != cuts.end()) return it->second;
    const Vec3 pi = local[i], pj = local[j];
    const double t = (hi[a] - pi[a]) / (pj[a] - pi[a]);
    Vec3 p, g;
    for (int k = 0; k < 3; ++k) {
      p[k] = pi[k] + t * (pj[k] - pi[k]);
      g[k] = grad[i][k] + t * (grad[j][k] - grad[i][k]);
    }
    p[a] = hi[a];
    const auto id = static_cast<std::uint32_t>(local.size());
    local.push_back(p);
    grad.push_back(g);
    cuts.emplace(exact, id);
    return id;
  };
  std::vector<std::array<std::uint32_t, 3>> kept;
  std::vector<std::uint32_t> poly, next;
  for (const auto& t : mesh.triangles) {
    poly.assign(t.begin(), t.end());
    for (int a = 0; a < 3 && !poly.empty(); ++a) {
      next.clear();
      for (std::size_t k = 0; k < poly.size(); ++k) {
        const std::uint32_t p = poly[k], q = poly[(k + 1) % poly.size()];
        const bool pin = inside(local[p], a), qin = inside(local[q], a);
        if (pin) next.push_back(p);
        if (pin != qin && !on_face(local[p], a) && !on_face(local[q], a)) next.push_back(cut_point(p, q, a));
      }
      poly.swap(next);
    }
    for (std::size_t k = 1; k + 1 < poly.size(); ++k)
      if (poly[0] != poly[k] && poly[k] != poly[k + 1] && poly[0] != poly[k + 1])
        kept.push_back({poly[0], poly[k], poly[k + 1]});
  }
  // Compact: used vertices in their order.
  std::vector<std::uint32_t> remap(local.size(), ~0u);
  for (const auto& t : kept)
    for (auto i : t) remap[i] = 0;
  std::uint32_t n = 0;
  std::vector<Vec3> nl, ng;
  for (std::size_t i = 0; i < local.size(); ++i)
    if (remap[i] == 0) {
      remap[i] = n++;
      nl.push_back(local[i]);
      ng.push_back(grad[i]);
    }
  for (auto& t : kept)
    for (auto& i : t) i = remap[i];
  mesh.triangles = std::move(kept);
  local = std::move(nl);
  grad = std::move(ng);
}

template <int D>
P1Element<D> element_of(const Hierarchy<D>& h, ElemId e) {
  return P1Element<D>(h.corner_points(e));
}

// Depth-first walk over the elements of T_level whose subtree range passes `keep`, in a fixed
// order (roots by id, children in order).
template <class Keep, class Emit>
std::size_t walk_level(const Hierarchy<3>& h, int level, Keep&& keep, Emit&& emit) {
  std::size_t visited = 0;
  std::vector<ElemId> stack;
  for (std::size_t r = h.coarse_count(); r-- > 0;) stack.push_back(ElemId(static_cast<std::uint32_t>(r)));
  while (!stack.empty()) {
    const ElemId e = stack.back();
    stack.pop_back();
    ++visited;
    if (!keep(e)) continue;
    if (h.is_leaf(e) || h.level(e) >= level) {
      emit(e);
      continue;
    }
    for (int i = h.num_children(e); i-- > 0;) stack.push_back(ElemId(h.first_child(e).value + i));
  }
  return visited;
}

// An output vertex of the extraction: on the edge (a above the iso-value, b at or below) at
// parameter t from a; t = 1 with u(b) = iso is the mesh vertex b itself.
struct OutVertex {
  VertexId a, b;
  double t;
};

// The output of one chunk of cut elements, its vertices numbered in order of first use.
struct Chunk {
  std::vector<OutVertex> verts;
  std::vector<Vec3> local;  // per vertex: its point on the cut edge, local frame
  std::vector<std::array<std::uint32_t, 3>> tris;
};

// The chunks' vertices merged, chunk by chunk, a vertex keeping the number of its first use, and
// their triangles renumbered into `mesh`; `chunks` is released.
void merge_chunks(std::vector<Chunk>& chunks, const std::vector<double>& u, double iso,
                  std::vector<OutVertex>& verts, std::vector<Vec3>& local, TriangleMesh& mesh) {
  const std::size_t nchunks = chunks.size();
  std::vector<std::vector<std::uint32_t>> to_global(nchunks);
  {
    EdgeMap on_edge;
    std::size_t total = 0;
    for (const auto& ch : chunks) total += ch.verts.size();
    on_edge.reserve(total);
    std::unordered_map<std::uint32_t, std::uint32_t> on_vertex;
    for (std::size_t k = 0; k < nchunks; ++k) {
      const Chunk& ch = chunks[k];
      auto& map = to_global[k];
      map.resize(ch.verts.size());
      for (std::size_t j = 0; j < ch.verts.size(); ++j) {
        const OutVertex& ov = ch.verts[j];
        const auto next = static_cast<std::uint32_t>(verts.size());
        std::uint32_t id = next;
        if (ov.t == 1.0 && u[ov.b.value] == iso) {
          id = on_vertex.emplace(ov.b.value, next).first->second;
        } else if (nchunks > 1) {
          const VertexId found = on_edge.find(ov.a, ov.b);
          if (found.valid())
            id = found.value;
          else
            on_edge.insert(ov.a, ov.b, VertexId(next));
        }
        if (id == next) {
          verts.push_back(ov);
          local.push_back(ch.local[j]);
        }
        map[j] = id;
      }
    }
  }
  {
    std::vector<std::size_t> offset(nchunks + 1, 0);
    for (std::size_t k = 0; k < nchunks; ++k) offset[k + 1] = offset[k] + chunks[k].tris.size();
    mesh.triangles.resize(offset.back());
    tbb::parallel_for(std::size_t(0), nchunks, [&](std::size_t k) {
      const auto& map = to_global[k];
      std::size_t at = offset[k];
      for (const auto& t : chunks[k].tris) mesh.triangles[at++] = {map[t[0]], map[t[1]], map[t[2]]};
    });
    std::vector<Chunk>().swap(chunks);
  }
}

// Steps 3 and 4 of IsoExtractor::extract: vertex normals at the mesh vertices that carry output
// vertices, as the volume-weighted mean of the gradients of all tetrahedra around them (those
// have a vertex value inside [lo, hi] of the needed vertices, so the same range walk finds all
// of them), then the gradients of u at the output vertices, interpolated along the cut edge.
std::vector<Vec3> gradients_at(const Hierarchy<3>& h, int level, const std::vector<double>& u,
                               const std::vector<float>& lo, const std::vector<float>& hi,
                               const std::vector<OutVertex>& verts) {
  constexpr std::uint32_t kNotNeeded = ~std::uint32_t(0);
  std::vector<std::uint32_t> slot(h.vertex_count(), kNotNeeded);  // needed vertex -> acc slot
  std::vector<std::array<double, 4>> acc;                         // gradient sum, volume sum
  double nlo = 1e300, nhi = -1e300;
  for (const auto& ov : verts)
    for (VertexId v : {ov.a, ov.b}) {
      if (slot[v.value] != kNotNeeded) continue;
      slot[v.value] = static_cast<std::uint32_t>(acc.size());
      acc.push_back({0, 0, 0, 0});
      nlo = std::min(nlo, u[v.value]);
      nhi = std::max(nhi, u[v.value]);
    }
  if (!verts.empty()) {
    // Pick the elements around needed vertices (walk order), weigh their gradients in
    // parallel, and add them up in walk order (the sums do not depend on the thread count).
    std::vector<ElemId> around;
    walk_level(
        h, level, [&](ElemId e) { return double(hi[e.value]) >= nlo && double(lo[e.value]) <= nhi; },
        [&](ElemId e) {
          bool any = false;
          for (VertexId v : h.cell(e)) any |= slot[v.value] != kNotNeeded;
          if (any) around.push_back(e);
        });
    std::vector<std::array<double, 4>> weighted(around.size());  // measure × gradient, measure
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, around.size(), 2048),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        for (std::size_t i = r.begin(); i != r.end(); ++i) {
                          const auto& c = h.cell(around[i]);
                          const P1Element<3> el = element_of(h, around[i]);
                          Vec3 g{0, 0, 0};
                          for (int j = 0; j < 4; ++j)
                            for (int k = 0; k < 3; ++k) g[k] += u[c[j].value] * el.grad[j][k];
                          weighted[i] = {el.measure * g[0], el.measure * g[1], el.measure * g[2], el.measure};
                        }
                      });
    for (std::size_t i = 0; i < around.size(); ++i)
      for (VertexId v : h.cell(around[i]))
        if (slot[v.value] != kNotNeeded) {
          auto& s = acc[slot[v.value]];
          for (int k = 0; k < 4; ++k) s[k] += weighted[i][k];
        }
  }
  auto vertex_gradient = [&](VertexId v) {
    const auto& s = acc[slot[v.value]];
    return s[3] > 0 ? Vec3{s[0] / s[3], s[1] / s[3], s[2] / s[3]} : Vec3{0, 0, 0};
  };

  // 4. Gradients of u at the output vertices (interpolated along the cut edge).
  std::vector<Vec3> grad(verts.size());
  for (std::size_t i = 0; i < verts.size(); ++i) {
    const auto& ov = verts[i];
    const Vec3 ga = vertex_gradient(ov.a), gb = vertex_gradient(ov.b);
    grad[i] = {(1 - ov.t) * ga[0] + ov.t * gb[0], (1 - ov.t) * ga[1] + ov.t * gb[1],
               (1 - ov.t) * ga[2] + ov.t * gb[2]};
  }
  return grad;
}

}  // namespace

namespace detail {

// Drops the connected parts of `mesh` whose vertices (local frame) lie in fewer than
// `min_cells` voxel cells, and the vertices only they used (from `local` and `grad` too).
// Parts and order are a function of the mesh alone.
Dropped drop_small_parts(TriangleMesh& mesh, std::vector<Vec3>& local, std::vector<Vec3>& grad,
                         const std::array<double, 3>& spacing, std::size_t min_cells) {
  Dropped d;
  const std::size_t nv = local.size();
  // 1. Parts: union-find over the vertices of every triangle.
  std::vector<std::uint32_t> parent(nv);
  for (std::uint32_t v = 0; v < nv; ++v) parent[v] = v;
  auto find = [&](std::uint32_t x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  };
  for (const auto& t : mesh.triangles)
    for (int k = 1; k < 3; ++k) {
      const std::uint32_t a = find(t[0]), b = find(t[k]);
      if (a != b) parent[std::max(a, b)] = std::min(a, b);
    }
  // 2. Size of a part: the distinct voxel cells its vertices lie in.
  std::vector<std::pair<std::uint32_t, std::uint64_t>> cells(nv);
  for (std::uint32_t v = 0; v < nv; ++v) {
    std::uint64_t key = 0;
    for (int k = 0; k < 3; ++k)
      key = (key << 21) | (std::uint64_t(std::max(0.0, std::floor(local[v][k] / spacing[k]))) & 0x1fffff);
    cells[v] = {find(v), key};
  }
  std::sort(cells.begin(), cells.end());
  std::vector<std::uint32_t> size(nv, 0);
  for (std::size_t i = 0; i < nv; ++i)
    if (i == 0 || cells[i] != cells[i - 1]) ++size[cells[i].first];
  for (std::uint32_t v = 0; v < nv; ++v)
    if (parent[v] == v && size[v] > 0) (size[v] < min_cells ? d.parts : d.kept_parts) += 1;
  if (d.parts == 0) return d;
  // 3. Keep the triangles of big parts and the vertices they use, in order.
  std::vector<std::uint32_t> remap(nv, ~0u);
  std::vector<std::array<std::uint32_t, 3>> tris;
  tris.reserve(mesh.triangles.size());
  for (const auto& t : mesh.triangles) {
    if (size[find(t[0])] < min_cells) {
      ++d.triangles;
      continue;
    }
    tris.push_back(t);
    for (auto v : t) remap[v] = 0;
  }
  std::uint32_t next = 0;
  for (std::uint32_t v = 0; v < nv; ++v)
    if (remap[v] == 0) {
      remap[v] = next;
      local[next] = local[v];
      grad[next] = grad[v];
      ++next;
    }
  local.resize(next);
  grad.resize(next);
  for (auto& t : tris)
    for (auto& v : t) v = remap[v];
  mesh.triangles = std::move(tris);
  return d;
}

void to_physical(TriangleMesh& mesh, const std::vector<Vec3>& local, const std::vector<Vec3>& grad,
                 const GridTransform& transform, bool normals_toward_higher) {
  const double sign = normals_toward_higher ? 1.0 : -1.0;
  mesh.positions.resize(local.size());
  mesh.normals.resize(local.size());
  tbb::parallel_for(std::size_t(0), local.size(), [&](std::size_t i) {
    const Vec3 p = transform.local_to_physical(local[i]);
    mesh.positions[i] = {float(p[0]), float(p[1]), float(p[2])};
    const Vec3 n{sign * grad[i][0], sign * grad[i][1], sign * grad[i][2]};
    mesh.normals[i] = to_float_unit(transform.rotate(n));
  });
  // A reflecting transform (det < 0) turns counter-clockwise into clockwise.
  if (det3(transform.direction) < 0)
    for (auto& t : mesh.triangles) std::swap(t[1], t[2]);
}

}  // namespace detail

IsoExtractor::IsoExtractor(const Hierarchy<3>& h, const std::vector<double>& values)
    : h_(h), values_(values) {
  if (values.size() != h.vertex_count())
    throw Error("iso-surface: " + std::to_string(values.size()) + " values for " +
                std::to_string(h.vertex_count()) + " vertices");
  const std::size_t n = h.element_count();
  lo_.assign(n, 0.f);
  hi_.assign(n, 0.f);
  // Children have larger ids than their parent, so one reverse sweep builds subtree ranges.
  for (std::size_t i = n; i-- > 0;) {
    const ElemId e(static_cast<std::uint32_t>(i));
    double lo = 1e300, hi = -1e300;
    for (VertexId v : h.cell(e)) {
      lo = std::min(lo, values[v.value]);
      hi = std::max(hi, values[v.value]);
    }
    float flo = static_cast<float>(lo), fhi = static_cast<float>(hi);
    // Round outward so that the float range always contains the double values.
    if (double(flo) > lo) flo = std::nextafter(flo, -INFINITY);
    if (double(fhi) < hi) fhi = std::nextafter(fhi, INFINITY);
    for (int c = 0; c < h.num_children(e); ++c) {
      const std::uint32_t ch = h.first_child(e).value + c;
      MLFE_CHECK(ch > i);
      flo = std::min(flo, lo_[ch]);
      fhi = std::max(fhi, hi_[ch]);
    }
    lo_[i] = flo;
    hi_[i] = fhi;
  }
}

TriangleMesh IsoExtractor::extract(double iso, const GridTransform& transform, const IsoOptions& opts) const {
  const Hierarchy<3>& h = h_;
  const int level = opts.level < 0 ? h.max_level() : opts.level;
  std::vector<double> coarse;
  if (level < h.max_level()) coarse = hierarchical_reconstruct(h, hierarchical_decompose(h, values_), level);
  const std::vector<double>& u = level < h.max_level() ? coarse : values_;

  // 1. Cut elements, output-sensitively: a cut needs a vertex above (u > iso) and one at or below.
  std::vector<ElemId> cut;
  visited_ = walk_level(
      h, level, [&](ElemId e) { return double(hi_[e.value]) > iso && double(lo_[e.value]) <= iso; },
      [&](ElemId e) {
        int above = 0;
        for (VertexId v : h.cell(e)) above += u[v.value] > iso;
        if (above > 0 && above < 4) cut.push_back(e);
      });

  // 2. Output vertices: one per cut edge, or the mesh vertex itself when u equals iso there.
  // The cut list is split into chunks (by its length alone), each numbering its own vertices
  // in order of first use, in parallel; a sequential merge then gives every vertex the
  // number of its first use in the whole list, so the mesh is the one a single pass makes.
  // The gradient of u on each cut element orients its triangles; computed in parallel (the
  // element geometry is most of the work), used in order.
  std::vector<Vec3> cut_grad(cut.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, cut.size(), 2048),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t i = r.begin(); i != r.end(); ++i) {
                        const auto& c = h.cell(cut[i]);
                        const P1Element<3> el = element_of(h, cut[i]);
                        Vec3 g{0, 0, 0};
                        for (int j = 0; j < 4; ++j)
                          for (int k = 0; k < 3; ++k) g[k] += u[c[j].value] * el.grad[j][k];
                        cut_grad[i] = g;
                      }
                    });
  constexpr std::size_t kChunkElements = 1 << 16;
  const std::size_t nchunks = std::max<std::size_t>(1, (cut.size() + kChunkElements - 1) / kChunkElements);
  std::vector<Chunk> chunks(nchunks);
  tbb::parallel_for(std::size_t(0), nchunks, [&](std::size_t k) {
    Chunk& ch = chunks[k];
    const std::size_t first = k * kChunkElements, last = std::min(cut.size(), first + kChunkElements);
    auto add_vertex = [&](VertexId a, VertexId b, double t) {
      ch.verts.push_back({a, b, t});
      const auto& pa = h.point(a);
      const auto& pb = h.point(b);
      ch.local.push_back(axpy(pa, t, sub(pb, pa)));
    };
    EdgeMap on_edge;  // cut edge -> output vertex (flat hash: this runs once per cut edge)
    on_edge.reserve((last - first) * 2);
    std::unordered_map<std::uint32_t, std::uint32_t> on_vertex;  // rare: u == iso at a vertex
    auto out_vertex = [&](VertexId a, VertexId b) -> std::uint32_t {
      // a above, b at or below.
      const double ua = u[a.value], ub = u[b.value];
      const auto next = static_cast<std::uint32_t>(ch.verts.size());
      if (ub == iso) {  // the cut is the vertex b itself, shared by every edge through it
        auto [it, inserted] = on_vertex.emplace(b.value, next);
        if (inserted) add_vertex(a, b, 1.0);
        return it->second;
      }
      const VertexId found = on_edge.find(a, b);
      if (found.valid()) return found.value;
      on_edge.insert(a, b, VertexId(next));
      add_vertex(a, b, (ua - iso) / (ua - ub));
      return next;
    };
    for (std::size_t ci = first; ci < last; ++ci) {
      const auto& c = h.cell(cut[ci]);
      int up[4], dn[4], nu = 0, nd = 0;
      for (int i = 0; i < 4; ++i) (u[c[i].value] > iso ? up[nu++] : dn[nd++]) = i;
      std::array<std::uint32_t, 4> poly{};
      int corners = 3;
      if (nu == 1) {
        for (int j = 0; j < 3; ++j) poly[j] = out_vertex(c[up[0]], c[dn[j]]);
      } else if (nu == 3) {
        for (int j = 0; j < 3; ++j) poly[j] = out_vertex(c[up[j]], c[dn[0]]);
      } else {
        // Quadrilateral in cyclic order around the tetrahedron.
        poly = {out_vertex(c[up[0]], c[dn[0]]), out_vertex(c[up[0]], c[dn[1]]),
                out_vertex(c[up[1]], c[dn[1]]), out_vertex(c[up[1]], c[dn[0]])};
        corners = 4;
      }
      const Vec3& g = cut_grad[ci];
      const Vec3 want = opts.normals_toward_higher ? g : Vec3{-g[0], -g[1], -g[2]};
      auto emit = [&](std::uint32_t i0, std::uint32_t i1, std::uint32_t i2) {
        if (i0 == i1 || i1 == i2 || i0 == i2) return;  // collapsed by a cut through a vertex
        const Vec3 n = cross(sub(ch.local[i1], ch.local[i0]), sub(ch.local[i2], ch.local[i0]));
        if (dot(n, want) < 0) std::swap(i1, i2);
        ch.tris.push_back({i0, i1, i2});
      };
      emit(poly[0], poly[1], poly[2]);
      if (corners == 4) emit(poly[0], poly[2], poly[3]);
    }
  });
  // Merge: chunk by chunk, a vertex keeps the number of its first use.
  std::vector<OutVertex> verts;
  std::vector<Vec3> local;
  TriangleMesh mesh;
  merge_chunks(chunks, u, iso, verts, local, mesh);

  // 3, 4. Vertex normals at the mesh vertices that carry output vertices; the gradients of u at
  // the output vertices.
  std::vector<Vec3> grad = gradients_at(h, level, u, lo_, hi_, verts);
  if (opts.clip) clip_to_box(opts.clip_to, mesh, local, grad);
  if (opts.snap_to && opts.snap_distance > 0)
    snap_to_data(*opts.snap_to, iso, opts.snap_distance, grad, mesh, local);
  if (opts.min_component > 0 || opts.dropped) {
    const Dropped d = detail::drop_small_parts(mesh, local, grad, transform.spacing, opts.min_component);
    if (opts.dropped) *opts.dropped = d;
  }

  // 5. Physical positions and normals.
  detail::to_physical(mesh, local, grad, transform, opts.normals_toward_higher);
  return mesh;
}

TriangleMesh height_field_surface(const Hierarchy<2>& h, const std::vector<double>& values,
                                  const GridTransform& transform, double z_scale, int level) {
  if (values.size() != h.vertex_count())
    throw Error("height field: " + std::to_string(values.size()) + " values for " +
                std::to_string(h.vertex_count()) + " vertices");
  const int lv = level < 0 ? h.max_level() : level;
  std::vector<double> coarse;
  if (lv < h.max_level()) coarse = hierarchical_reconstruct(h, hierarchical_decompose(h, values), lv);
  const std::vector<double>& u = lv < h.max_level() ? coarse : values;
  const auto elems = lv < h.max_level() ? h.level_elements(lv) : h.leaves();
  const auto& d = transform.direction;
  const Vec3 up{d[2], d[5], d[8]};  // the third axis: heights go along it
  std::vector<std::uint32_t> remap(h.vertex_count(), ~0u);
  TriangleMesh mesh;
  std::vector<Vec3> pos;
  auto vertex = [&](VertexId v) {
    if (remap[v.value] == ~0u) {
      remap[v.value] = static_cast<std::uint32_t>(pos.size());
      const auto& p = h.point(v);
      Vec3 q = transform.local_to_physical({p[0], p[1], 0.0});
      for (int k = 0; k < 3; ++k) q[k] += z_scale * u[v.value] * up[k];
      pos.push_back(q);
    }
    return remap[v.value];
  };
  for (ElemId e : elems) {
    const auto& c = h.cell(e);
    std::array<std::uint32_t, 3> t{vertex(c[0]), vertex(c[1]), vertex(c[2])};
    if (h.signed_measure(e) < 0) std::swap(t[1], t[2]);  // counter-clockwise seen from above
    mesh.triangles.push_back(t);
  }
  if (det3(transform.direction) < 0)
    for (auto& t : mesh.triangles) std::swap(t[1], t[2]);
  std::vector<Vec3> nsum(pos.size(), Vec3{0, 0, 0});
  for (const auto& t : mesh.triangles) {
    const Vec3 n = cross(sub(pos[t[1]], pos[t[0]]), sub(pos[t[2]], pos[t[0]]));  // |n| = 2 area
    for (auto i : t)
      for (int k = 0; k < 3; ++k) nsum[i][k] += n[k];
  }
  for (std::size_t i = 0; i < pos.size(); ++i) {
    mesh.positions.push_back({float(pos[i][0]), float(pos[i][1]), float(pos[i][2])});
    mesh.normals.push_back(to_float_unit(nsum[i]));
  }
  return mesh;
}

}  // namespace mlfe
