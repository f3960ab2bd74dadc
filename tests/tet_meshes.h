// Tetrahedral meshes with point values for the unstructured-input tests (TetMeshField, the
// .vtu/.msh readers, the paper's Poisson example): Kuhn-split cube grids, optionally with
// cubes left out. Header-only.
#pragma once
#include <mlfe/core/field/tet_mesh_field.h>
#include <mlfe/core/mesh/hierarchy.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <functional>
#include <vector>

namespace mlfe::test {

/// The unit cube [0, 1]^3 (scaled by `size`, shifted by `origin`) as n^3 cubes of 6 Kuhn
/// tetrahedra each (around the cube's main diagonal, so neighbours match), leaving out the
/// cubes whose centre `drop` accepts; values f(point).
inline TetMesh kuhn_mesh(int n, const std::function<double(const std::array<double, 3>&)>& f,
                         const std::function<bool(const std::array<double, 3>&)>& drop = {},
                         double size = 1.0, const std::array<double, 3>& origin = {0, 0, 0}) {
  TetMesh m;
  m.source = "kuhn mesh";
  const auto id = [n](int i, int j, int k) { return std::int32_t(i + (n + 1) * (j + (n + 1) * k)); };
  for (int k = 0; k <= n; ++k)
    for (int j = 0; j <= n; ++j)
      for (int i = 0; i <= n; ++i) {
        const std::array<double, 3> p{origin[0] + size * i / n, origin[1] + size * j / n,
                                      origin[2] + size * k / n};
        m.points.push_back(p);
        m.values.push_back(f(p));
      }
  // The six paths from corner 0 to corner 7 through the cube's edges.
  static const int kPerm[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const std::array<double, 3> c{origin[0] + size * (i + 0.5) / n, origin[1] + size * (j + 0.5) / n,
                                      origin[2] + size * (k + 0.5) / n};
        if (drop && drop(c)) continue;
        for (const auto& p : kPerm) {
          int at[3] = {i, j, k};
          std::array<std::int32_t, 4> t;
          t[0] = id(at[0], at[1], at[2]);
          for (int s = 0; s < 3; ++s) {
            ++at[p[s]];
            t[s + 1] = id(at[0], at[1], at[2]);
          }
          m.tets.push_back(t);
        }
      }
  return m;
}

/// The paper's Poisson example: the L-shape solution r^(2/3) sin(2θ/3) around the re-entrant
/// edge x = y = 0.5 of the cube with the corner [0.5, 1]^3 cut away, extruded along z (below
/// z = 0.5, where the cube is whole, it is 0 over x, y > 0.5). θ runs from
/// the face y = 0.5 (x > 0.5) through the material to the face x = 0.5 (y > 0.5), 3π/2 in
/// all, so u vanishes on both faces of the cut and is harmonic.
inline double poisson_u(const std::array<double, 3>& p) {
  const double x = p[0] - 0.5, y = p[1] - 0.5;
  const double r = std::sqrt(x * x + y * y);
  if (r == 0) return 0;
  double theta = std::atan2(y, x);   // (-π, π]; the cut is θ in (0, π/2)
  if (theta < 0) theta += 2 * M_PI;  // [0, 2π)
  // The material is θ in [π/2, 2π] (the cut x, y > 0.5 is θ in (0, π/2)); measure from π/2.
  const double phi = std::clamp(theta - M_PI / 2, 0.0, 1.5 * M_PI);
  return std::pow(r, 2.0 / 3.0) * std::sin(2.0 * phi / 3.0);
}

/// Whether p lies in the cut corner [0.5, 1]^3 (strictly inside in x and y and z).
inline bool in_cut_corner(const std::array<double, 3>& p) { return p[0] > 0.5 && p[1] > 0.5 && p[2] > 0.5; }

/// The mesh as T0 of a hierarchy (the tetrahedra in their order, vertex ids as they are).
inline Hierarchy<3> coarse_hierarchy(const TetMesh& m) {
  std::vector<Hierarchy<3>::Cell> cells;
  for (const auto& t : m.tets)
    cells.push_back({VertexId(std::uint32_t(t[0])), VertexId(std::uint32_t(t[1])),
                     VertexId(std::uint32_t(t[2])), VertexId(std::uint32_t(t[3]))});
  return Hierarchy<3>::from_coarse(m.points, cells);
}

/// Length of the ray o + t d (t ≥ 0) inside the box [lo, hi], computed independently of the
/// renderers (slab clipping), for checks of ray-cast images.
inline double box_chord(const std::array<double, 3>& lo, const std::array<double, 3>& hi,
                        const std::array<double, 3>& o, const std::array<double, 3>& d) {
  double t0 = 0, t1 = 1e300;
  for (int a = 0; a < 3; ++a) {
    if (d[a] == 0) {
      if (o[a] < lo[a] || o[a] > hi[a]) return 0;
      continue;
    }
    const double ta = (lo[a] - o[a]) / d[a], tb = (hi[a] - o[a]) / d[a];
    t0 = std::max(t0, std::min(ta, tb));
    t1 = std::min(t1, std::max(ta, tb));
  }
  return std::max(0.0, t1 - t0);
}

}  // namespace mlfe::test
