// Fast iso-surface simplification through meshoptimizer (meshopt_simplify, Debian
// libmeshoptimizer-dev; A. Kapoulkine, quadric-ordered edge collapses after Garland & Heckbert
// 1997); see surface_simplification.h for the contract.
//
// meshopt_simplify is sequential. A big surface is cut into slabs of equal triangle counts
// along its longest axis, each simplified on its own with its cut locked (a locked border of
// the submesh), and the band of triangles around the cuts is simplified once more, so the
// seams do not stay at full resolution. The slab count depends on the triangle count alone,
// never on the thread count, so the output is the same with any number of threads.
#include <meshoptimizer.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/simplify/surface_simplification.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
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

}  // namespace

TriangleMesh simplify_fast(const TriangleMesh& mesh, double tolerance) {
  if (!(tolerance > 0) || !std::isfinite(tolerance))
    throw Error("simplification tolerance must be positive and finite (got " + std::to_string(tolerance) +
                ")");
  const std::size_t nv = mesh.positions.size();
  // Pick: triangles without a repeated corner.
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
  const std::size_t slabs = std::min(kMaxSlabs, nt / kSlabTriangles);
  std::vector<unsigned> kept;
  if (slabs < 2) {
    kept = collapse(mesh.positions, in, tolerance);
  } else {
    // Slab: by the centroid along the longest axis, cut at the triangle-count quantiles.
    float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (const auto& p : mesh.positions)
      for (int k = 0; k < 3; ++k) {
        lo[k] = std::min(lo[k], p[k]);
        hi[k] = std::max(hi[k], p[k]);
      }
    int axis = 0;
    for (int k = 1; k < 3; ++k)
      if (hi[k] - lo[k] > hi[axis] - lo[axis]) axis = k;
    std::vector<float> key(nt);
    for (std::size_t t = 0; t < nt; ++t)
      key[t] = mesh.positions[in[3 * t]][axis] + mesh.positions[in[3 * t + 1]][axis] +
               mesh.positions[in[3 * t + 2]][axis];
    std::vector<float> cuts(slabs - 1);
    {
      std::vector<float> sorted(key);
      for (std::size_t s = 1; s < slabs; ++s) {
        const auto at = sorted.begin() + static_cast<std::ptrdiff_t>(s * nt / slabs);
        std::nth_element(sorted.begin(), at, sorted.end());
        cuts[s - 1] = *at;
      }
      std::sort(cuts.begin(), cuts.end());
    }
    std::vector<std::vector<unsigned>> part(slabs);
    std::vector<unsigned> slab_of(nt);
    for (std::size_t t = 0; t < nt; ++t) {
      const auto s = static_cast<unsigned>(std::upper_bound(cuts.begin(), cuts.end(), key[t]) - cuts.begin());
      slab_of[t] = s;
      part[s].insert(part[s].end(), in.begin() + 3 * t, in.begin() + 3 * t + 3);
    }
    // Seam vertices: in triangles of more than one slab. They stay in place in the slabs.
    std::vector<unsigned> first_slab(nv, ~0u);
    std::vector<std::uint8_t> seam(nv, 0);
    for (std::size_t t = 0; t < nt; ++t)
      for (int c = 0; c < 3; ++c) {
        const unsigned v = in[3 * t + c];
        if (first_slab[v] == ~0u)
          first_slab[v] = slab_of[t];
        else if (first_slab[v] != slab_of[t])
          seam[v] = 1;
      }
    // Collapse each slab, in parallel.
    tbb::parallel_for(std::size_t(0), slabs,
                      [&](std::size_t s) { part[s] = collapse(mesh.positions, part[s], tolerance); });
    // Band: the triangles around the seams, simplified once more; its outer ring is its locked
    // border, so the rest of the surface is not touched again.
    std::vector<unsigned> band;
    for (const auto& p : part)
      for (std::size_t i = 0; i < p.size(); i += 3) {
        const bool at_seam = seam[p[i]] || seam[p[i + 1]] || seam[p[i + 2]];
        (at_seam ? band : kept).insert((at_seam ? band : kept).end(), p.begin() + i, p.begin() + i + 3);
      }
    const auto band_kept = collapse(mesh.positions, band, tolerance);
    kept.insert(kept.end(), band_kept.begin(), band_kept.end());
  }
  // Compact: used vertices in input order.
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
