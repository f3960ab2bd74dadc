// Area-weighted vertex normals of an indexed triangle mesh, meshes merged into one and welded
// along their borders, its spatial (Morton) orders, and its topology counted.
#include <mlfe/core/base/check.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/surface/triangle_mesh.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <numeric>
#include <string>
#include <tuple>
#include <unordered_map>
#include <vector>

#include "base/morton.h"

namespace mlfe {

using Vec3 = Eigen::Vector3d;

TriangleMesh merge_meshes(const std::vector<const TriangleMesh*>& parts) {
  TriangleMesh all;
  std::size_t vertices = 0, triangles = 0;
  for (const TriangleMesh* p : parts) {
    MLFE_CHECK(p);
    vertices += p->positions.size();
    triangles += p->triangles.size();
  }
  if (vertices > std::numeric_limits<std::uint32_t>::max())
    throw Error("merging meshes: " + std::to_string(vertices) + " vertices do not fit 32-bit indices");
  all.positions.reserve(vertices);
  all.triangles.reserve(triangles);
  for (const TriangleMesh* p : parts) {
    const auto base = std::uint32_t(all.positions.size());
    all.positions.insert(all.positions.end(), p->positions.begin(), p->positions.end());
    all.normals.insert(all.normals.end(), p->normals.begin(), p->normals.end());
    for (const auto& t : p->triangles) all.triangles.push_back({t[0] + base, t[1] + base, t[2] + base});
  }
  // Dropped rather than kept misaligned: a writer rejects a normal count that is neither 0 nor
  // one per position, and glTF readers give NORMAL to some primitives only. The assets' own
  // surfaces never get here with mixed normals (every extraction path gives each vertex one,
  // and the label pipeline merges a single structure), so no written file changes by this.
  if (all.normals.size() != all.positions.size()) all.normals.clear();
  return all;
}

namespace {

using PositionBits = std::array<std::uint32_t, 3>;

// +0.0f turns -0 into 0, so equal coordinates give equal bits.
PositionBits position_bits(const std::array<float, 3>& p) {
  PositionBits b;
  for (int c = 0; c < 3; ++c) {
    const float v = p[c] + 0.0f;
    std::memcpy(&b[c], &v, sizeof v);
  }
  return b;
}

struct EdgeKeyHash {
  std::size_t operator()(const std::array<std::uint32_t, 6>& k) const {
    std::uint64_t h = 0;
    for (std::uint32_t bits : k) h = (h ^ bits) * 0x9E3779B97F4A7C15ull;
    return std::size_t(h ^ (h >> 29));
  }
};

// The directed edges no triangle traverses the other way, as (from, to) in triangle order.
std::vector<std::array<std::uint32_t, 2>> open_edges(
    const std::vector<std::array<std::uint32_t, 3>>& triangles, std::size_t nv) {
  std::vector<std::uint64_t> edges;
  edges.reserve(3 * triangles.size());
  for (const auto& t : triangles)
    for (int k = 0; k < 3; ++k) {
      if (t[k] >= nv) throw Error("welding borders: a triangle refers to a vertex beyond the positions");
      edges.push_back(std::uint64_t(t[k]) << 32 | t[(k + 1) % 3]);
    }
  std::vector<std::uint64_t> sorted = edges;
  tbb::parallel_sort(sorted.begin(), sorted.end());
  std::vector<std::array<std::uint32_t, 2>> open;
  for (const std::uint64_t e : edges) {
    const auto a = std::uint32_t(e >> 32), b = std::uint32_t(e);
    if (!std::binary_search(sorted.begin(), sorted.end(), std::uint64_t(b) << 32 | a)) open.push_back({a, b});
  }
  return open;
}

std::uint32_t find_root(std::vector<std::uint32_t>& parent, std::uint32_t v) {
  while (parent[v] != v) v = parent[v] = parent[parent[v]];
  return v;
}

}  // namespace

void weld_piece_borders(TriangleMesh& mesh, const std::vector<std::size_t>& piece_triangles) {
  const std::size_t nv = mesh.positions.size();
  std::size_t total = 0;
  for (std::size_t n : piece_triangles) total += n;
  MLFE_CHECK(total == mesh.triangles.size());
  // Which piece each vertex is in: pieces own their vertices (merge_meshes).
  std::vector<std::uint32_t> piece_of(nv, 0);
  for (std::size_t p = 0, f = 0; p < piece_triangles.size(); ++p)
    for (std::size_t end = f + piece_triangles[p]; f < end; ++f)
      for (std::uint32_t v : mesh.triangles[f])
        if (v < nv) piece_of[v] = std::uint32_t(p);
  const std::vector<std::array<std::uint32_t, 2>> open = open_edges(mesh.triangles, nv);
  // Match: an open edge a→b of one piece and an open edge b'→a' of another at the same
  // positions are one edge of the surface cut in two; a→a', b→b' are welded. Only matched
  // edges weld, so the surface's own boundary keeps distinct vertices that share a position.
  std::unordered_map<std::array<std::uint32_t, 6>, std::array<std::uint32_t, 2>, EdgeKeyHash> by_key;
  auto key = [&](std::uint32_t a, std::uint32_t b) {
    const PositionBits pa = position_bits(mesh.positions[a]), pb = position_bits(mesh.positions[b]);
    return std::array<std::uint32_t, 6>{pa[0], pa[1], pa[2], pb[0], pb[1], pb[2]};
  };
  for (const auto& e : open) by_key.emplace(key(e[0], e[1]), e);
  std::vector<std::uint32_t> parent(nv);
  for (std::uint32_t v = 0; v < nv; ++v) parent[v] = v;
  auto unite = [&](std::uint32_t a, std::uint32_t b) {
    a = find_root(parent, a);
    b = find_root(parent, b);
    if (a != b) parent[std::max(a, b)] = std::min(a, b);  // the first vertex stays
  };
  for (const auto& e : open) {
    const auto it = by_key.find(key(e[1], e[0]));
    if (it == by_key.end() || piece_of[it->second[0]] == piece_of[e[0]]) continue;
    unite(e[0], it->second[1]);
    unite(e[1], it->second[0]);
  }
  const bool with_normals = mesh.normals.size() == nv;
  std::vector<std::uint32_t> to(nv);
  std::uint32_t kept = 0;
  for (std::uint32_t v = 0; v < nv; ++v) {
    const std::uint32_t root = find_root(parent, v);
    if (root != v) {
      to[v] = to[root];  // root < v: already placed
      continue;
    }
    to[v] = kept;
    mesh.positions[kept] = mesh.positions[v];
    if (with_normals) mesh.normals[kept] = mesh.normals[v];
    ++kept;
  }
  mesh.positions.resize(kept);
  if (with_normals) mesh.normals.resize(kept);
  for (auto& t : mesh.triangles)
    for (auto& v : t) v = to[v];
}

namespace {

// The finite positions' bounding box and the scale that maps its largest extent onto 0..1023.
struct MortonGrid {
  std::array<float, 3> lo{}, hi{};
  double scale = 0;

  explicit MortonGrid(const std::vector<std::array<float, 3>>& positions) {
    for (int c = 0; c < 3; ++c) {
      lo[c] = std::numeric_limits<float>::infinity();
      hi[c] = -std::numeric_limits<float>::infinity();
    }
    for (const auto& p : positions)
      for (int c = 0; c < 3; ++c)
        if (std::isfinite(p[c])) {
          lo[c] = std::min(lo[c], p[c]);
          hi[c] = std::max(hi[c], p[c]);
        }
    double extent = 0;
    for (int c = 0; c < 3; ++c) extent = std::max(extent, double(hi[c]) - double(lo[c]));
    scale = extent > 0 ? 1023.0 / extent : 0.0;
  }

  // The 30-bit Morton code of the cell holding p (non-finite coordinates in cell 0).
  std::uint32_t code(const std::array<double, 3>& p) const {
    std::uint32_t code = 0;
    for (int c = 0; c < 3; ++c) {
      const double x = (p[c] - lo[c]) * scale;
      const auto q = std::uint32_t(std::isfinite(x) ? std::clamp(x, 0.0, 1023.0) : 0.0);
      code |= detail::spread_bits(q) << c;
    }
    return code;
  }
};

void check_spatial_order_input(const TriangleMesh& mesh) {
  const std::size_t nv = mesh.positions.size();
  for (const auto& t : mesh.triangles)
    if (t[0] >= nv || t[1] >= nv || t[2] >= nv)
      throw Error("spatial order: a triangle refers to a vertex beyond the " + std::to_string(nv) +
                  " positions");
}

// The low 32 bits of `keys` (codes above, indices below) in the keys' order. The keys are unique,
// so the parallel sort gives the one order a stable sort by code would, whatever the thread count.
std::vector<std::uint32_t> sorted_indices(std::vector<std::uint64_t> keys) {
  tbb::parallel_sort(keys.begin(), keys.end());
  std::vector<std::uint32_t> order(keys.size());
  for (std::size_t i = 0; i < keys.size(); ++i) order[i] = std::uint32_t(keys[i]);
  return order;
}

}  // namespace

std::vector<std::uint32_t> triangle_spatial_order(const TriangleMesh& mesh) {
  const std::size_t nt = mesh.triangles.size();
  if (nt > std::numeric_limits<std::uint32_t>::max()) throw Error("spatial order: more than 2^32 triangles");
  check_spatial_order_input(mesh);
  const MortonGrid grid(mesh.positions);
  std::vector<std::uint64_t> key(nt);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nt, 8192),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t i = r.begin(); i != r.end(); ++i) {
                        std::array<double, 3> centroid{0.0, 0.0, 0.0};
                        for (auto v : mesh.triangles[i])
                          for (int c = 0; c < 3; ++c) centroid[c] += double(mesh.positions[v][c]) / 3.0;
                        key[i] = std::uint64_t(grid.code(centroid)) << 32 | i;
                      }
                    });
  return sorted_indices(std::move(key));
}

TriangleMesh spatially_ordered(const TriangleMesh& mesh, std::vector<std::uint32_t>* new_to_old) {
  const std::size_t nv = mesh.positions.size();
  check_spatial_order_input(mesh);
  const MortonGrid grid(mesh.positions);
  std::vector<std::uint64_t> key(nv);
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, nv, 8192), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t v = r.begin(); v != r.end(); ++v) {
          const auto& p = mesh.positions[v];
          key[v] = std::uint64_t(grid.code({double(p[0]), double(p[1]), double(p[2])})) << 32 | v;
        }
      });
  const std::vector<std::uint32_t> order = sorted_indices(std::move(key));  // new -> old
  std::vector<std::uint32_t> index(nv);                                     // old -> new
  for (std::size_t i = 0; i < nv; ++i) index[order[i]] = std::uint32_t(i);
  if (new_to_old) *new_to_old = order;
  TriangleMesh out;
  out.positions.resize(nv);
  for (std::size_t i = 0; i < nv; ++i) out.positions[i] = mesh.positions[order[i]];
  if (mesh.normals.size() == nv) {
    out.normals.resize(nv);
    for (std::size_t i = 0; i < nv; ++i) out.normals[i] = mesh.normals[order[i]];
  } else {
    out.normals = mesh.normals;
  }
  // Triangles by their first new vertex, ties in input order: (first vertex, input position)
  // pairs, unique again.
  const std::size_t nt = mesh.triangles.size();
  if (nt > std::numeric_limits<std::uint32_t>::max()) throw Error("spatial order: more than 2^32 triangles");
  std::vector<std::uint64_t> by_first(nt);
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, nt, 8192), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
          const auto& t = mesh.triangles[i];
          by_first[i] = std::uint64_t(std::min({index[t[0]], index[t[1]], index[t[2]]})) << 32 | i;
        }
      });
  tbb::parallel_sort(by_first.begin(), by_first.end());
  out.triangles.resize(nt);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nt, 8192),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t i = r.begin(); i != r.end(); ++i) {
                        const auto& t = mesh.triangles[std::uint32_t(by_first[i])];
                        out.triangles[i] = {index[t[0]], index[t[1]], index[t[2]]};
                      }
                    });
  return out;
}

void compute_area_weighted_normals(TriangleMesh& mesh) {
  // Cross products are twice the area times the unit normal: summing them weights by area.
  std::vector<Vec3> sum(mesh.positions.size(), Vec3::Zero());
  for (const auto& t : mesh.triangles) {
    if (t[0] >= sum.size() || t[1] >= sum.size() || t[2] >= sum.size())
      throw Error("normals: a triangle refers to a vertex beyond the " + std::to_string(sum.size()) +
                  " positions");
    const auto &a = mesh.positions[t[0]], &b = mesh.positions[t[1]], &c = mesh.positions[t[2]];
    const Vec3 u(double(b[0]) - a[0], double(b[1]) - a[1], double(b[2]) - a[2]);
    const Vec3 v(double(c[0]) - a[0], double(c[1]) - a[1], double(c[2]) - a[2]);
    const Vec3 n = u.cross(v);
    for (auto i : t) sum[i] += n;
  }
  mesh.normals.resize(mesh.positions.size());
  for (std::size_t i = 0; i < sum.size(); ++i) {
    const double len = sum[i].norm();
    if (len > 0)
      mesh.normals[i] = {float(sum[i].x() / len), float(sum[i].y() / len), float(sum[i].z() / len)};
    else
      mesh.normals[i] = {0.0f, 0.0f, 1.0f};
  }
}

namespace {

// Edge and fan checks of triangles without repeated corners (indices < nv): adds to the edge and
// vertex counts of `r` and, when `bad` is given, marks the vertices where the surface is not an
// oriented 2-manifold. `on_box(a, b)` tells whether a boundary edge lies on the box.
template <class OnBox>
void check_edges_and_fans(const std::vector<std::array<std::uint32_t, 3>>& tris, std::size_t nv,
                          MeshTopology& r, std::vector<std::uint8_t>* bad, OnBox&& on_box) {
  if (bad) bad->assign(nv, 0);
  auto mark = [&](std::uint32_t v) {
    if (bad) (*bad)[v] = 1;
  };
  // 1. Edges: every directed triangle edge (a << 32 | b, 8 bytes: a big surface's edges are the
  // largest array here), sorted; an undirected edge is its two directions' runs.
  {
    std::vector<std::uint64_t> edges;
    edges.reserve(tris.size() * 3);
    for (const auto& t : tris)
      for (int k = 0; k < 3; ++k) edges.push_back(std::uint64_t(t[k]) << 32 | t[(k + 1) % 3]);
    std::sort(edges.begin(), edges.end());
    for (std::size_t i = 0; i < edges.size();) {
      std::size_t j = i;
      while (j < edges.size() && edges[j] == edges[i]) ++j;
      const auto a = std::uint32_t(edges[i] >> 32), b = std::uint32_t(edges[i]);
      const auto reverse = std::equal_range(edges.begin(), edges.end(), std::uint64_t(b) << 32 | a);
      const std::size_t forward = j - i, backward = std::size_t(reverse.second - reverse.first);
      i = j;
      if (a > b && backward > 0) continue;  // counted from its lo -> hi direction
      bool ok = true;
      if (forward + backward == 1) {
        ++r.boundary_edges;
        if (!on_box(std::min(a, b), std::max(a, b))) ++r.boundary_edges_off_box;
      } else if (forward + backward == 2) {
        ok = forward == 1;
        r.inconsistent_edges += !ok;
      } else {
        ok = false;
        ++r.non_manifold_edges;
      }
      if (!ok) {
        mark(a);
        mark(b);
      }
    }
  }

  // 2. Vertices: the triangles around a vertex must form one fan, i.e. one component when
  // triangles that share an edge through the vertex are joined.
  std::vector<std::uint32_t> start(nv + 1, 0);
  for (const auto& t : tris)
    for (auto v : t) ++start[v + 1];
  std::partial_sum(start.begin(), start.end(), start.begin());
  std::vector<std::uint32_t> around(start.back());
  {
    std::vector<std::uint32_t> fill(start.begin(), start.end() - 1);
    for (std::uint32_t i = 0; i < tris.size(); ++i)
      for (auto v : tris[i]) around[fill[v]++] = i;
  }
  std::vector<std::uint32_t> parent;
  std::vector<std::pair<std::uint32_t, std::uint32_t>> spokes;  // (other end, local triangle)
  for (std::uint32_t v = 0; v < nv; ++v) {
    const std::uint32_t n = start[v + 1] - start[v];
    if (n < 2) continue;
    parent.resize(n);
    std::iota(parent.begin(), parent.end(), 0u);
    auto find = [&](std::uint32_t x) {
      while (parent[x] != x) x = parent[x] = parent[parent[x]];
      return x;
    };
    spokes.clear();
    for (std::uint32_t k = 0; k < n; ++k)
      for (auto w : tris[around[start[v] + k]])
        if (w != v) spokes.push_back({w, k});
    std::sort(spokes.begin(), spokes.end());
    std::uint32_t components = n;
    for (std::size_t i = 1; i < spokes.size(); ++i)
      if (spokes[i].first == spokes[i - 1].first) {
        const std::uint32_t a = find(spokes[i].second), b = find(spokes[i - 1].second);
        if (a != b) {
          parent[a] = b;
          --components;
        }
      }
    if (components > 1) {
      ++r.non_manifold_vertices;
      mark(v);
    }
  }
}

}  // namespace

MeshTopology mesh_topology(const TriangleMesh& mesh, const std::array<double, 3>* box_min,
                           const std::array<double, 3>* box_max, double box_tolerance) {
  MeshTopology r;
  const std::size_t nv = mesh.positions.size();
  for (const auto& t : mesh.triangles)
    for (auto v : t)
      if (v >= nv)
        throw Error("topology: a triangle refers to a vertex beyond the " + std::to_string(nv) +
                    " positions");

  // Weld by exact position: the first vertex at a position stands for all of them.
  std::vector<std::uint32_t> order(nv), weld(nv);
  std::iota(order.begin(), order.end(), 0u);
  std::sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) {
    return std::tie(mesh.positions[a], a) < std::tie(mesh.positions[b], b);
  });
  for (std::size_t i = 0; i < nv; ++i) {
    const std::uint32_t v = order[i];
    const bool same = i > 0 && mesh.positions[order[i - 1]] == mesh.positions[v];
    weld[v] = same ? weld[order[i - 1]] : v;
    r.duplicate_vertices += same;
  }
  std::vector<std::array<std::uint32_t, 3>> tris;
  tris.reserve(mesh.triangles.size());
  for (const auto& t : mesh.triangles) {
    const std::array<std::uint32_t, 3> w{weld[t[0]], weld[t[1]], weld[t[2]]};
    if (w[0] == w[1] || w[1] == w[2] || w[0] == w[2])
      ++r.degenerate_triangles;
    else
      tris.push_back(w);
  }
  check_edges_and_fans(tris, nv, r, nullptr, [&](std::uint32_t a, std::uint32_t b) {
    if (!box_min || !box_max) return true;
    for (int k = 0; k < 3; ++k)
      for (const double plane : {(*box_min)[k], (*box_max)[k]})
        if (std::abs(mesh.positions[a][k] - plane) <= box_tolerance &&
            std::abs(mesh.positions[b][k] - plane) <= box_tolerance)
          return true;
    return false;
  });
  return r;
}

std::vector<std::uint8_t> non_manifold_vertices(const std::vector<std::array<std::uint32_t, 3>>& triangles,
                                                std::size_t vertex_count) {
  std::vector<std::array<std::uint32_t, 3>> tris;
  tris.reserve(triangles.size());
  for (const auto& t : triangles) {
    for (auto v : t)
      if (v >= vertex_count)
        throw Error("topology: a triangle refers to a vertex beyond the " + std::to_string(vertex_count) +
                    " vertices");
    if (t[0] != t[1] && t[1] != t[2] && t[0] != t[2]) tris.push_back(t);
  }
  MeshTopology r;
  std::vector<std::uint8_t> bad;
  check_edges_and_fans(tris, vertex_count, r, &bad, [](std::uint32_t, std::uint32_t) { return true; });
  return bad;
}

}  // namespace mlfe
