// Fast iso-surface simplification through meshoptimizer (meshopt_simplify, Debian
// libmeshoptimizer-dev); see surface_simplification.h for the contract.
#include <meshoptimizer.h>

#include <cmath>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/surface_simplification.h"

namespace mlfe {

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
  // Collapse: meshoptimizer's error is relative to the mesh's extent.
  const float scale = meshopt_simplifyScale(&mesh.positions[0][0], nv, sizeof(float) * 3);
  const float target = scale > 0 ? float(tolerance / scale) : 0.0f;
  std::vector<unsigned> kept(in.size());
  kept.resize(meshopt_simplify(kept.data(), in.data(), in.size(), &mesh.positions[0][0], nv,
                               sizeof(float) * 3, 0, target, meshopt_SimplifyLockBorder, nullptr));
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
