// Marching cubes on the samples' lattice: Lorensen & Cline, "Marching Cubes: A High Resolution 3D
// Surface Construction Algorithm", SIGGRAPH 1987, with the ambiguous faces decided by Nielson &
// Hamann's asymptotic decider ("The Asymptotic Decider: Resolving the Ambiguity in Marching
// Cubes", IEEE Visualization 1991).
//
// Why cubes on the finest level: on the samples' lattice (sample_lattice.h) the hierarchy's
// finest level carries every sample, so the data's own surface (the trilinear interpolant of the
// samples, the definition and what flying edges extracts) comes from the samples without
// building that level. Marching tetrahedra on the Kuhn triangulation of the same cubes cuts each
// cube along its diagonals: three times the triangles, slivers the simplifier then spends passes
// on, and a surface 0.05-0.06 voxel from the trilinear one on noisy scans (bench/RESULTS.md).
//
// No case table: each cube's polygons are traced from its faces. On a face, seen from outside
// with its corners counter-clockwise, a crossing edge going from below to above the iso-value is
// an entry, the reverse an exit, and each segment runs from an entry to an exit, so the region
// above lies to its left. A face with four crossings (above and below corners alternating) pairs
// them by the asymptotic decider: the above corners are joined iff the bilinear saddle is above,
// (a0 a2 > a1 a3) for a = value - iso on the above (0, 2) and below (1, 3) diagonals. Every edge
// of the cube is an entry on one of its two faces and an exit on the other, so the segments
// chain into closed loops; each loop is one polygon, fanned from its first vertex, with its
// normal toward lower values. The decision on a face reads only that face's four samples, and
// the neighbouring cube traverses the same segment in the other direction: the surface is
// closed and consistently oriented across cubes (boundary edges only at the volume's faces) and
// every vertex's triangles form one fan.
//
//   face corners, counter-clockwise from outside      segment on a face: entry -> exit
//        c3 ---- c2                                     (above to its left)
//        |        |
//        c0 ---- c1
#include <mlfe/core/base/check.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/base/vec.h>
#include <mlfe/core/surface/iso_surface.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include "surface/surface_parts.h"

namespace mlfe {

namespace {

constexpr std::uint32_t kNoVertex = std::numeric_limits<std::uint32_t>::max();
constexpr std::uint32_t kCentre = 1u << 31;  // a loop's centre vertex, numbered per plane

// Cube corner k sits at (k & 1, (k >> 1) & 1, (k >> 2) & 1). Faces: corners counter-clockwise
// seen from outside (the right-hand rule gives the outward normal).
constexpr int kFaces[6][4] = {{0, 4, 6, 2}, {1, 3, 7, 5}, {0, 1, 5, 4},
                              {2, 6, 7, 3}, {0, 2, 3, 1}, {4, 5, 7, 6}};

// Cube edges: 0-3 along x, 4-7 along y, 8-11 along z, each from its lower corner `kEdgeFrom`.
constexpr int kEdgeFrom[12] = {0, 2, 4, 6, 0, 1, 4, 5, 0, 1, 2, 3};
constexpr int kEdgeAxis[12] = {0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 2};

constexpr int edge_of(int a, int b) {
  const int lo = a < b ? a : b, diff = (a ^ b);
  const int axis = diff == 1 ? 0 : diff == 2 ? 1 : 2;
  for (int e = 0; e < 12; ++e)
    if (kEdgeFrom[e] == lo && kEdgeAxis[e] == axis) return e;
  return -1;
}

// One cube's polygons from the above/below pattern of its corners and the face decisions:
// loops of cube edges, each oriented with its normal toward lower values.
struct CubeLoops {
  int count = 0;
  int size[4] = {0, 0, 0, 0};
  int edge[4][12];
};

// next[e]: the exit each entry edge leads to on the face where e is an entry.
CubeLoops trace_loops(const float (&a)[8]) {
  int next[12];
  std::fill(next, next + 12, -1);
  for (const auto& f : kFaces) {
    bool up[4];
    for (int i = 0; i < 4; ++i) up[i] = a[f[i]] > 0;
    int entries[2], exits[2], ne = 0, nx = 0, entry_at[2], exit_at[2];
    for (int i = 0; i < 4; ++i) {
      const int j = (i + 1) & 3;
      if (up[i] == up[j]) continue;
      const int e = edge_of(f[i], f[j]);
      if (up[j]) {
        entry_at[ne] = i;
        entries[ne++] = e;
      } else {
        exit_at[nx] = i;
        exits[nx++] = e;
      }
    }
    if (ne == 1) {
      next[entries[0]] = exits[0];
    } else if (ne == 2) {
      // Alternating corners. Entry on side i (corner i below, i+1 above) and the exit on side
      // i+1 cut off the above corner i+1; the exit on side i-1 cuts off the below corner i
      // (the above corners then joined).
      int above0 = up[0] ? 0 : 1;
      const double d_above = double(a[f[above0]]) * double(a[f[above0 + 2]]);
      const double d_below = double(a[f[above0 ^ 1]]) * double(a[f[(above0 ^ 1) + 2]]);
      const bool join_above = d_above > d_below;
      for (int k = 0; k < 2; ++k) {
        const int i = entry_at[k];
        const int want = join_above ? (i + 3) & 3 : (i + 1) & 3;
        next[entries[k]] = exits[exit_at[0] == want ? 0 : 1];
      }
    }
  }
  CubeLoops loops;
  bool used[12] = {};
  for (int s = 0; s < 12; ++s) {
    if (next[s] < 0 || used[s]) continue;
    int& n = loops.size[loops.count];
    for (int e = s; !used[e]; e = next[e]) {
      MLFE_CHECK(next[e] >= 0);
      used[e] = true;
      loops.edge[loops.count][n++] = e;
    }
    ++loops.count;
  }
  return loops;
}

// Faces of the cube each edge lies on (bit f for kFaces[f]).
constexpr std::array<int, 12> kEdgeFaces = [] {
  std::array<int, 12> mask{};
  for (int f = 0; f < 6; ++f)
    for (int i = 0; i < 4; ++i) mask[edge_of(kFaces[f][i], kFaces[f][(i + 1) & 3])] |= 1 << f;
  return mask;
}();

// The first loop vertex whose fan adds no diagonal between two vertices of one face. Only a
// face with four crossings can hold two vertices of a loop that are not neighbours on it; the
// diagonal would lie in that face, where the neighbouring cube may put the same edge (four
// triangles on it). -1 when no vertex qualifies.
int fan_origin(const int* e, int n) {
  for (int o = 0; o < n; ++o) {
    bool ok = true;
    for (int s = 2; s + 1 < n && ok; ++s) ok = (kEdgeFaces[e[o]] & kEdgeFaces[e[(o + s) % n]]) == 0;
    if (ok) return o;
  }
  return -1;
}

// Where the iso-value crosses the edge from value a to value b (t in (0, 1) from a). A crossing
// at a sample itself would give the edges through it coincident vertices (degenerate
// triangles); it is moved off the sample by 1/1024 of the edge.
double crossing(double a, double b, double iso) {
  constexpr double kOff = 1.0 / 1024;
  return std::clamp((iso - a) / (b - a), kOff, 1 - kOff);
}

// The samples [lo, lo + n) of `g`, indexed from lo.
struct Lattice {
  const ScalarGrid& g;
  double iso;
  std::int64_t nx, ny, nz;
  std::array<std::int64_t, 3> lo{0, 0, 0};
  std::int64_t rows() const { return ny * nz; }
  float at(std::int64_t i, std::int64_t j, std::int64_t k) const {
    return g.at(i + lo[0], j + lo[1], k + lo[2]);
  }
  bool up(std::int64_t i, std::int64_t j, std::int64_t k) const { return double(at(i, j, k)) > iso; }
  // Crossings of the row (j, k)'s edges leaving each sample along +x, +y, +z, in order
  // (i, axis): ids[3 i + axis] = first + rank, kNoVertex where there is none.
  template <class Visit>
  std::uint32_t scan_row(std::int64_t j, std::int64_t k, std::uint32_t first, Visit&& visit) const {
    std::uint32_t id = first;
    for (std::int64_t i = 0; i < nx; ++i) {
      const bool u = up(i, j, k);
      if (i + 1 < nx && up(i + 1, j, k) != u) visit(i, 0, id++);
      if (j + 1 < ny && up(i, j + 1, k) != u) visit(i, 1, id++);
      if (k + 1 < nz && up(i, j, k + 1) != u) visit(i, 2, id++);
    }
    return id - first;
  }
};

Vec3 sample_gradient(const ScalarGrid& g, std::int64_t i, std::int64_t j, std::int64_t k) {
  const std::int64_t c[3] = {i, j, k};
  Vec3 grad{0, 0, 0};
  for (int a = 0; a < 3; ++a) {
    std::int64_t lo[3] = {i, j, k}, hi[3] = {i, j, k};
    lo[a] = std::max<std::int64_t>(0, c[a] - 1);
    hi[a] = std::min<std::int64_t>(g.dims[a] - 1, c[a] + 1);
    const double span = double(hi[a] - lo[a]) * g.transform.spacing[a];
    if (span > 0) grad[a] = (double(g.at(hi[0], hi[1], hi[2])) - double(g.at(lo[0], lo[1], lo[2]))) / span;
  }
  return grad;
}

// Crossings of a plane of cubes: triangles (centre vertices flagged kCentre, numbered per plane)
// and the centre vertices' positions and gradients.
struct Plane {
  std::vector<std::array<std::uint32_t, 3>> tris;
  std::vector<Vec3> centres, centre_grads;
};

// One cube's loops, fanned (or around a centre vertex) into the plane's triangles. `a`: the
// corners' values - iso; `vertex(e)`: the id of the crossing on cube edge e.
template <class VertexOf>
void polygonise_cube(const float (&a)[8], VertexOf&& vertex, const std::vector<Vec3>& local,
                     const std::vector<Vec3>& grad, Plane& plane) {
  const CubeLoops loops = trace_loops(a);
  for (int l = 0; l < loops.count; ++l) {
    const int* e = loops.edge[l];
    const int n = loops.size[l];
    const int origin = fan_origin(e, n);
    if (origin >= 0) {
      for (int s = 1; s + 1 < n; ++s)
        plane.tris.push_back(
            {vertex(e[origin]), vertex(e[(origin + s) % n]), vertex(e[(origin + s + 1) % n])});
      continue;
    }
    // No fan stays off the faces: a vertex at the loop's centre, numbered after the edges'.
    Vec3 c{0, 0, 0}, cg{0, 0, 0};
    for (int s = 0; s < n; ++s)
      for (int x = 0; x < 3; ++x) {
        c[x] += local[vertex(e[s])][x] / n;
        cg[x] += grad[vertex(e[s])][x] / n;
      }
    const std::uint32_t centre = kCentre | std::uint32_t(plane.centres.size());
    plane.centres.push_back(c);
    plane.centre_grads.push_back(cg);
    for (int s = 0; s < n; ++s) plane.tris.push_back({centre, vertex(e[s]), vertex(e[(s + 1) % n])});
  }
}

// The plane of cubes between sample planes k and k + 1, row by row. `first`: each sample row's
// first vertex id (count_crossings).
Plane polygonise_plane(const Lattice& L, std::int64_t k, const std::vector<std::uint32_t>& first,
                       const std::vector<Vec3>& local, const std::vector<Vec3>& grad) {
  Plane plane;
  const auto row = [&](std::int64_t j, std::int64_t kk) { return std::size_t(j + L.ny * kk); };
  // ids of the four sample rows around a row of cubes: [dj + 2 dk][3 i + axis].
  std::vector<std::uint32_t> ids[4];
  for (auto& v : ids) v.resize(std::size_t(3 * L.nx));
  for (std::int64_t j = 0; j + 1 < L.ny; ++j) {
    bool any = false;
    for (int q = 0; q < 4; ++q) {
      const std::size_t r = row(j + (q & 1), k + (q >> 1));
      any = any || first[r + 1] > first[r];
    }
    if (!any) continue;
    for (int q = 0; q < 4; ++q) {
      const std::int64_t jj = j + (q & 1), kk = k + (q >> 1);
      std::fill(ids[q].begin(), ids[q].end(), kNoVertex);
      L.scan_row(jj, kk, first[row(jj, kk)],
                 [&](std::int64_t i, int axis, std::uint32_t id) { ids[q][std::size_t(3 * i + axis)] = id; });
    }
    for (std::int64_t i = 0; i + 1 < L.nx; ++i) {
      float a[8];
      bool any_up = false, any_down = false;
      for (int c = 0; c < 8; ++c) {
        const double v = double(L.at(i + (c & 1), j + ((c >> 1) & 1), k + (c >> 2)));
        a[c] = float(v - L.iso);
        // The classification must be the one the rows used: value > iso.
        if (v > L.iso) {
          any_up = true;
          if (!(a[c] > 0)) a[c] = std::numeric_limits<float>::min();
        } else {
          any_down = true;
          if (a[c] > 0) a[c] = 0;
        }
      }
      if (!any_up || !any_down) continue;
      auto vertex = [&](int e) {
        const int c = kEdgeFrom[e];
        const std::uint32_t id =
            ids[((c >> 1) & 1) + 2 * (c >> 2)][std::size_t(3 * (i + (c & 1)) + kEdgeAxis[e])];
        MLFE_CHECK(id != kNoVertex);
        return id;
      };
      polygonise_cube(a, vertex, local, grad, plane);
    }
  }
  return plane;
}

// Each vertex's place, read back from its local position (c + t e_axis) * spacing: along the
// axes where it is an integer lattice coordinate it is one to rounding, and t stays 1/1024 off
// the samples. A loop's centre averages vertices on at least two faces of each axis' pair (a
// loop never lies in one face), so no coordinate of it comes nearer than 1/12288 to a sample.
std::vector<LatticePlace> lattice_places(const std::vector<Vec3>& local, const std::array<double, 3>& sp) {
  std::vector<LatticePlace> places(local.size());
  tbb::parallel_for(std::size_t(0), local.size(), [&](std::size_t v) {
    int integral = 0, free_axis = 3;
    for (int x = 0; x < 3; ++x) {
      const double q = local[v][x] / sp[x], r = std::round(q);
      const bool on = std::abs(q - r) < 1e-6;
      places[v].at[x] = std::int32_t(on ? r : std::floor(q));
      integral += on;
      if (!on) free_axis = x;
    }
    places[v].axis = integral == 2 ? free_axis : 3;
  });
  return places;
}

}  // namespace

namespace {

// The surface of the samples [lo, lo + n) of `grid` (gradients from `grid`'s samples around
// them), positions at the lattice coordinates lo + offset + index.
TriangleMesh extract_lattice(const ScalarGrid& grid, const std::array<std::int64_t, 3>& lo,
                             const std::array<std::int64_t, 3>& n, const std::array<std::int64_t, 3>& offset,
                             double iso, const IsoOptions& opts, std::vector<LatticePlace>* places) {
  const Lattice L{grid, iso, n[0], n[1], n[2], lo};
  const auto& sp = grid.transform.spacing;
  const auto row = [&](std::int64_t j, std::int64_t k) { return std::size_t(j + L.ny * k); };

  // 1. Count: crossings per row of samples (edges leaving each sample along +x, +y, +z).
  std::vector<std::uint32_t> first(std::size_t(L.rows()) + 1, 0);
  tbb::parallel_for(std::int64_t(0), L.nz, [&](std::int64_t k) {
    for (std::int64_t j = 0; j < L.ny; ++j)
      first[row(j, k) + 1] = L.scan_row(j, k, 0, [](auto, int, auto) {});
  });
  for (std::size_t r = 0; r < std::size_t(L.rows()); ++r) {
    if (std::uint64_t(first[r]) + first[r + 1] >= kCentre)
      throw Error("iso-surface: more than 2 billion vertices");
    first[r + 1] += first[r];
  }
  const std::size_t nv = first.back();

  // 2. Place: vertices numbered row by row, (i, axis) within a row; positions in the local
  // frame (index * spacing) and the samples' central-difference gradients along the edge.
  std::vector<Vec3> local(nv), grad(nv);
  tbb::parallel_for(std::int64_t(0), L.nz, [&](std::int64_t k) {
    for (std::int64_t j = 0; j < L.ny; ++j)
      L.scan_row(j, k, first[row(j, k)], [&](std::int64_t i, int axis, std::uint32_t id) {
        std::int64_t b[3] = {i, j, k};
        ++b[axis];
        const double t = crossing(L.at(i, j, k), L.at(b[0], b[1], b[2]), iso);
        const Vec3 g0 = sample_gradient(grid, i + lo[0], j + lo[1], k + lo[2]),
                   g1 = sample_gradient(grid, b[0] + lo[0], b[1] + lo[1], b[2] + lo[2]);
        const double c[3] = {double(i + lo[0] + offset[0]), double(j + lo[1] + offset[1]),
                             double(k + lo[2] + offset[2])};
        for (int x = 0; x < 3; ++x) {
          local[id][x] = (c[x] + (x == axis ? t : 0.0)) * sp[x];
          grad[id][x] = (1 - t) * g0[x] + t * g1[x];
        }
      });
  });

  // 3. Polygons: planes of cubes in parallel, joined in plane order (centre vertices numbered
  // after the edges'), so the order does not depend on the threads.
  std::vector<Plane> per_plane(std::size_t(std::max<std::int64_t>(0, L.nz - 1)));
  tbb::parallel_for(std::int64_t(0), L.nz - 1, [&](std::int64_t k) {
    per_plane[std::size_t(k)] = polygonise_plane(L, k, first, local, grad);
  });
  TriangleMesh mesh;
  std::size_t nt = 0;
  for (const auto& p : per_plane) nt += p.tris.size();
  mesh.triangles.reserve(nt);
  for (auto& p : per_plane) {
    const auto base = std::uint32_t(local.size());
    if (std::uint64_t(base) + p.centres.size() >= kCentre)
      throw Error("iso-surface: more than 2 billion vertices");
    local.insert(local.end(), p.centres.begin(), p.centres.end());
    grad.insert(grad.end(), p.centre_grads.begin(), p.centre_grads.end());
    for (auto t : p.tris) {
      for (auto& v : t)
        if (v & kCentre) v = base + (v & ~kCentre);
      mesh.triangles.push_back(t);
    }
    Plane().tris.swap(p.tris);
  }

  // 4. Parts below the size floor.
  if (opts.min_component > 0 || opts.dropped) {
    const Dropped d = detail::drop_small_parts(mesh, local, grad, sp, opts.min_component);
    if (opts.dropped) *opts.dropped = d;
  }

  if (places) *places = lattice_places(local, sp);

  // 5. Physical positions and normals (the samples' gradients). Loops are traced with normals
  // toward lower values, so toward higher ones reverses them.
  if (opts.normals_toward_higher)
    for (auto& t : mesh.triangles) std::swap(t[1], t[2]);
  detail::to_physical(mesh, local, grad, grid.transform, opts.normals_toward_higher);
  return mesh;
}

}  // namespace

TriangleMesh lattice_iso_surface(const ScalarGrid& grid, double iso, const IsoOptions& opts,
                                 std::vector<LatticePlace>* places) {
  MLFE_CHECK(grid.dim == 3);
  MLFE_CHECK(grid.values.size() == std::size_t(grid.voxel_count()));
  return extract_lattice(grid, {0, 0, 0}, grid.dims, {0, 0, 0}, iso, opts, places);
}

TriangleMesh lattice_iso_surface(const ScalarGrid& window, const std::array<std::int64_t, 3>& window_at,
                                 const std::array<std::int64_t, 3>& lo, const std::array<std::int64_t, 3>& hi,
                                 double iso, const IsoOptions& opts, std::vector<LatticePlace>* places) {
  MLFE_CHECK(window.dim == 3);
  MLFE_CHECK(window.values.size() == std::size_t(window.voxel_count()));
  for (int x = 0; x < 3; ++x) MLFE_CHECK(0 <= lo[x] && lo[x] < hi[x] && hi[x] <= window.dims[x]);
  return extract_lattice(window, lo, {hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]}, window_at, iso, opts,
                         places);
}

}  // namespace mlfe
