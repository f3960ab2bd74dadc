// Fast iso-surface simplification through meshoptimizer (meshopt_simplify, Debian
// libmeshoptimizer-dev; A. Kapoulkine, quadric-ordered edge collapses after Garland & Heckbert
// 1997); see surface_simplification.h for the contract.
//
// meshopt_simplify is sequential. A big surface is cut into slabs of equal triangle counts
// along its longest axis, each simplified on its own with its cut locked (a locked border of
// the submesh), and the band of triangles around the cuts is simplified once more, so the
// seams do not stay at full resolution. The slab count depends on the triangle count alone,
// never on the thread count, so the output is the same with any number of threads.
//
// meshopt_simplify does not test the link condition (Dey, Edelsbrunner, Guha & Nekhayev,
// "Topology preserving edge contraction", 1999), so a collapse across a thin part or a narrow
// gap can leave an edge in three or four triangles or two sheets pinched at a vertex: the
// non-manifold edges that viewers show as seams and that Draco's Edgebreaker splits into
// duplicate vertices. Such spots are rare and local: the input triangles around each one are
// kept as extracted and the slabs that hold them simplified again, the kept triangles' rim
// locked, with a radius that grows until no spot is left.
#include <meshoptimizer.h>
#include <mlfe/core/check.h>
#include <mlfe/core/error.h>
#include <mlfe/core/surface_simplification.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

namespace mlfe {
namespace {

using Positions = std::vector<std::array<float, 3>>;

// Triangles per slab: below twice this a surface is simplified in one piece.
constexpr std::size_t kSlabTriangles = 150000;
constexpr std::size_t kMaxSlabs = 64;

// meshopt_simplify over the triangles `tris` (indices into `pos`), at an absolute error.
// Returns the kept triangles as indices into `pos`.
std::vector<unsigned> collapse(const Positions& pos, const std::vector<unsigned>& tris, double tolerance) {
  if (tris.empty()) return {};
  // Local numbering: meshoptimizer allocates per vertex of the buffer it is given.
  std::vector<unsigned> global;
  std::vector<unsigned> local(tris.size());
  {
    std::vector<unsigned> slot(pos.size(), ~0u);
    for (std::size_t i = 0; i < tris.size(); ++i) {
      unsigned& s = slot[tris[i]];
      if (s == ~0u) {
        s = static_cast<unsigned>(global.size());
        global.push_back(tris[i]);
      }
      local[i] = s;
    }
  }
  Positions lp(global.size());
  for (std::size_t i = 0; i < global.size(); ++i) lp[i] = pos[global[i]];
  // meshoptimizer's error is relative to the extent of what it is given.
  const float scale = meshopt_simplifyScale(&lp[0][0], lp.size(), sizeof(float) * 3);
  const float target = scale > 0 ? float(tolerance / scale) : 0.0f;
  std::vector<unsigned> kept(local.size());
  kept.resize(meshopt_simplify(kept.data(), local.data(), local.size(), &lp[0][0], lp.size(),
                               sizeof(float) * 3, 0, target, meshopt_SimplifyLockBorder, nullptr));
  for (auto& v : kept) v = global[v];
  return kept;
}

// Slabs: a partition of the triangles along the longest axis, by centroid, at triangle-count
// quantiles, and the seam vertices that triangles of more than one slab share.
struct Slabs {
  std::size_t count = 1;
  std::vector<unsigned> of;        // per triangle
  std::vector<std::uint8_t> seam;  // per vertex
};

Slabs make_slabs(const Positions& pos, const std::vector<unsigned>& in) {
  Slabs sl;
  const std::size_t nt = in.size() / 3;
  sl.count = std::max<std::size_t>(1, std::min(kMaxSlabs, nt / kSlabTriangles));
  sl.of.assign(nt, 0);
  sl.seam.assign(pos.size(), 0);
  if (sl.count < 2) {
    sl.count = 1;
    return sl;
  }
  float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  for (const auto& p : pos)
    for (int k = 0; k < 3; ++k) {
      lo[k] = std::min(lo[k], p[k]);
      hi[k] = std::max(hi[k], p[k]);
    }
  int axis = 0;
  for (int k = 1; k < 3; ++k)
    if (hi[k] - lo[k] > hi[axis] - lo[axis]) axis = k;
  std::vector<float> key(nt);
  for (std::size_t t = 0; t < nt; ++t)
    key[t] = pos[in[3 * t]][axis] + pos[in[3 * t + 1]][axis] + pos[in[3 * t + 2]][axis];
  std::vector<float> cuts(sl.count - 1);
  {
    std::vector<float> sorted(key);
    for (std::size_t s = 1; s < sl.count; ++s) {
      const auto at = sorted.begin() + static_cast<std::ptrdiff_t>(s * nt / sl.count);
      std::nth_element(sorted.begin(), at, sorted.end());
      cuts[s - 1] = *at;
    }
    std::sort(cuts.begin(), cuts.end());
  }
  std::vector<unsigned> first_slab(pos.size(), ~0u);
  for (std::size_t t = 0; t < nt; ++t) {
    sl.of[t] = static_cast<unsigned>(std::upper_bound(cuts.begin(), cuts.end(), key[t]) - cuts.begin());
    for (int c = 0; c < 3; ++c) {
      const unsigned v = in[3 * t + c];
      if (first_slab[v] == ~0u)
        first_slab[v] = sl.of[t];
      else if (first_slab[v] != sl.of[t])
        sl.seam[v] = 1;
    }
  }
  return sl;
}

// Input vertices near the spots: within `radius[i]` of spots[i] (a uniform grid of the input
// vertices answers the queries).
std::vector<std::uint8_t> near_spots(const Positions& pos, const std::vector<unsigned>& spots,
                                     const std::vector<float>& radius) {
  std::vector<std::uint8_t> near(pos.size(), 0);
  float cell = 0;
  for (float r : radius) cell = std::max(cell, r);
  if (!(cell > 0)) {
    for (unsigned s : spots) near[s] = 1;
    return near;
  }
  auto key = [&](const std::array<float, 3>& p, int dx, int dy, int dz) {
    const auto c = [&](int k, int d) {
      return std::uint64_t(std::int64_t(std::floor(p[k] / cell)) + d + (1 << 20)) & 0x1fffff;
    };
    return (c(0, dx) << 42) | (c(1, dy) << 21) | c(2, dz);
  };
  std::vector<std::pair<std::uint64_t, unsigned>> grid(pos.size());
  for (unsigned v = 0; v < pos.size(); ++v) grid[v] = {key(pos[v], 0, 0, 0), v};
  std::sort(grid.begin(), grid.end());
  for (std::size_t i = 0; i < spots.size(); ++i) {
    const auto& c = pos[spots[i]];
    const float r2 = radius[i] * radius[i];
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dz = -1; dz <= 1; ++dz) {
          const std::uint64_t k = key(c, dx, dy, dz);
          for (auto it = std::lower_bound(grid.begin(), grid.end(), std::make_pair(k, 0u));
               it != grid.end() && it->first == k; ++it) {
            const auto& p = pos[it->second];
            const float d2 =
                (p[0] - c[0]) * (p[0] - c[0]) + (p[1] - c[1]) * (p[1] - c[1]) + (p[2] - c[2]) * (p[2] - c[2]);
            if (d2 <= r2) near[it->second] = 1;
          }
        }
  }
  return near;
}

}  // namespace

TriangleMesh simplify_fast(const TriangleMesh& mesh, double tolerance) {
  if (!(tolerance > 0) || !std::isfinite(tolerance))
    throw Error("simplification tolerance must be positive and finite (got " + std::to_string(tolerance) +
                ")");
  const std::size_t nv = mesh.positions.size();
  const Positions& pos = mesh.positions;
  // 1. Pick: triangles without a repeated corner.
  std::vector<unsigned> in;
  in.reserve(mesh.triangles.size() * 3);
  for (const auto& t : mesh.triangles) {
    for (auto v : t)
      if (v >= nv) throw Error("simplification: triangle index " + std::to_string(v) + " out of range");
    if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2]) continue;
    in.insert(in.end(), t.begin(), t.end());
  }
  TriangleMesh out;
  if (in.empty()) return out;
  const std::size_t nt = in.size() / 3;
  auto as_triangles = [](const std::vector<unsigned>& flat) {
    std::vector<std::array<std::uint32_t, 3>> t(flat.size() / 3);
    for (std::size_t i = 0; i < t.size(); ++i) t[i] = {flat[3 * i], flat[3 * i + 1], flat[3 * i + 2]};
    return t;
  };
  // Spots already in the input are not the simplification's to repair.
  const std::vector<std::uint8_t> bad_in = non_manifold_vertices(as_triangles(in), nv);

  // 2. Slabs, each collapsed on its own in parallel, then the band around the seams.
  const Slabs slabs = make_slabs(pos, in);
  std::vector<std::uint8_t> kept_raw(nt, 0);  // per input triangle: kept as extracted
  std::vector<std::vector<unsigned>> part(slabs.count);
  std::vector<std::uint8_t> redo(slabs.count, 1);
  std::vector<unsigned> kept;
  std::vector<float> reach(nv, 0);  // per vertex: the radius of its last repair
  // A first repair keeps the input triangles within two mean input edges of the spot.
  float first_reach = 0;
  {
    double sum = 0;
    for (std::size_t i = 0; i < in.size(); i += 3)
      for (int k = 0; k < 3; ++k) {
        const auto &a = pos[in[i + k]], &b = pos[in[i + (k + 1) % 3]];
        sum += std::sqrt(double(a[0] - b[0]) * (a[0] - b[0]) + double(a[1] - b[1]) * (a[1] - b[1]) +
                         double(a[2] - b[2]) * (a[2] - b[2]));
      }
    first_reach = float(2 * sum / double(in.size()));
  }
  std::vector<std::vector<unsigned>> members(slabs.count);
  for (std::size_t t = 0; t < nt; ++t) members[slabs.of[t]].push_back(static_cast<unsigned>(t));
  for (int round = 0;; ++round) {
    tbb::parallel_for(std::size_t(0), slabs.count, [&](std::size_t s) {
      if (!redo[s]) return;
      std::vector<unsigned> tris;
      tris.reserve(members[s].size() * 3);
      for (unsigned t : members[s])
        if (!kept_raw[t]) tris.insert(tris.end(), in.begin() + 3 * t, in.begin() + 3 * t + 3);
      part[s] = collapse(pos, tris, tolerance);
    });
    kept.clear();
    if (slabs.count == 1) {
      kept = part[0];
    } else {
      // Band: the triangles around the seams, simplified once more; its outer ring is its
      // locked border, so the rest of the surface is not touched again.
      std::vector<unsigned> band;
      for (const auto& p : part)
        for (std::size_t i = 0; i < p.size(); i += 3) {
          const bool at_seam = slabs.seam[p[i]] || slabs.seam[p[i + 1]] || slabs.seam[p[i + 2]];
          (at_seam ? band : kept).insert((at_seam ? band : kept).end(), p.begin() + i, p.begin() + i + 3);
        }
      const auto band_kept = collapse(pos, band, tolerance);
      kept.insert(kept.end(), band_kept.begin(), band_kept.end());
    }
    for (std::size_t t = 0; t < nt; ++t)
      if (kept_raw[t]) kept.insert(kept.end(), in.begin() + 3 * t, in.begin() + 3 * t + 3);

    // 3. Repair: spots the collapses made non-manifold keep their input triangles within a
    // radius of twice the longest kept edge there (what the collapses around it spanned),
    // doubled every round; the slabs holding them are simplified again.
    const std::vector<std::uint8_t> bad = non_manifold_vertices(as_triangles(kept), nv);
    std::vector<unsigned> spots;
    for (unsigned v = 0; v < nv; ++v)
      if (bad[v] && !bad_in[v]) spots.push_back(v);
    if (spots.empty()) break;
    std::vector<float> radius(spots.size(), 0);
    {
      std::vector<float> longest(nv, 0);
      for (std::size_t i = 0; i < kept.size(); i += 3)
        for (int k = 0; k < 3; ++k) {
          const auto &a = pos[kept[i + k]], &b = pos[kept[i + (k + 1) % 3]];
          const float d = std::sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) +
                                    (a[2] - b[2]) * (a[2] - b[2]));
          longest[kept[i + k]] = std::max(longest[kept[i + k]], d);
          longest[kept[i + (k + 1) % 3]] = std::max(longest[kept[i + (k + 1) % 3]], d);
        }
      for (std::size_t i = 0; i < spots.size(); ++i) {
        radius[i] = std::max(first_reach, 2 * reach[spots[i]]);
        reach[spots[i]] = radius[i];
      }
    }
    const std::vector<std::uint8_t> near = near_spots(pos, spots, radius);
    std::fill(redo.begin(), redo.end(), 0);
    bool grew = false;
    for (std::size_t t = 0; t < nt; ++t) {
      if (kept_raw[t] || !(near[in[3 * t]] || near[in[3 * t + 1]] || near[in[3 * t + 2]])) continue;
      kept_raw[t] = 1;
      redo[slabs.of[t]] = 1;
      grew = true;
    }
    // A spot whose neighbourhood is all kept as extracted is the input's own (it cannot be
    // the collapses'): nothing is left to repair there.
    if (!grew) break;
  }
  // 4. Compact: used vertices in input order.
  std::vector<unsigned> remap(nv, ~0u);
  for (unsigned v : kept) remap[v] = 0;
  const bool normals = mesh.normals.size() == nv;
  for (std::size_t v = 0; v < nv; ++v) {
    if (remap[v] == ~0u) continue;
    remap[v] = static_cast<unsigned>(out.positions.size());
    out.positions.push_back(mesh.positions[v]);
    if (normals) out.normals.push_back(mesh.normals[v]);
  }
  out.triangles.reserve(kept.size() / 3);
  for (std::size_t i = 0; i < kept.size(); i += 3)
    out.triangles.push_back({remap[kept[i]], remap[kept[i + 1]], remap[kept[i + 2]]});
  return out;
}

}  // namespace mlfe
