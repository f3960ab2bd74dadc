// Small synthetic meshes and helpers shared by the mesh tests (core surface simplification,
// openmesh_io, draco_io, gltf_writer, the CLI tests). Header-only.
#pragma once
#include <gtest/gtest.h>
#include <mlfe/core/surface/triangle_mesh.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "tests/test_paths.h"

namespace mlfe::test {

/// Icosphere of `subdivisions` levels (20 * 4^s triangles), outward normals, CCW from outside.
inline TriangleMesh icosphere(int subdivisions, float radius, std::array<float, 3> center = {0, 0, 0}) {
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  std::vector<std::array<double, 3>> v = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0},
                                          {0, -1, t}, {0, 1, t}, {0, -1, -t}, {0, 1, -t},
                                          {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
  std::vector<std::array<std::uint32_t, 3>> f = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                                                 {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                                                 {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                                                 {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
  auto unit = [](std::array<double, 3> p) {
    const double l = std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
    return std::array<double, 3>{p[0] / l, p[1] / l, p[2] / l};
  };
  for (auto& p : v) p = unit(p);
  for (int s = 0; s < subdivisions; ++s) {
    std::map<std::pair<std::uint32_t, std::uint32_t>, std::uint32_t> mid;
    auto midpoint = [&](std::uint32_t a, std::uint32_t b) {
      auto key = std::minmax(a, b);
      auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      v.push_back(unit({(v[a][0] + v[b][0]) / 2, (v[a][1] + v[b][1]) / 2, (v[a][2] + v[b][2]) / 2}));
      return mid[key] = std::uint32_t(v.size() - 1);
    };
    std::vector<std::array<std::uint32_t, 3>> g;
    for (const auto& tri : f) {
      const auto a = midpoint(tri[0], tri[1]), b = midpoint(tri[1], tri[2]), c = midpoint(tri[2], tri[0]);
      g.push_back({tri[0], a, c});
      g.push_back({tri[1], b, a});
      g.push_back({tri[2], c, b});
      g.push_back({a, b, c});
    }
    f = g;
  }
  TriangleMesh m;
  for (const auto& p : v) {
    m.positions.push_back({float(center[0] + radius * p[0]), float(center[1] + radius * p[1]),
                           float(center[2] + radius * p[2])});
    m.normals.push_back({float(p[0]), float(p[1]), float(p[2])});
  }
  m.triangles = f;
  return m;
}

/// UV sphere (poles shared), `rings` x `segments`, outward normals.
inline TriangleMesh uv_sphere(int rings, int segments, float radius,
                              std::array<float, 3> center = {0, 0, 0}) {
  const double pi = 3.14159265358979323846;
  TriangleMesh m;
  auto add = [&](double theta, double phi) {
    const double n[3] = {std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta)};
    m.positions.push_back({float(center[0] + radius * n[0]), float(center[1] + radius * n[1]),
                           float(center[2] + radius * n[2])});
    m.normals.push_back({float(n[0]), float(n[1]), float(n[2])});
    return std::uint32_t(m.positions.size() - 1);
  };
  const std::uint32_t north = add(0, 0);
  std::vector<std::vector<std::uint32_t>> ring(rings - 1);
  for (int r = 1; r < rings; ++r)
    for (int s = 0; s < segments; ++s) ring[r - 1].push_back(add(pi * r / rings, 2 * pi * s / segments));
  const std::uint32_t south = add(pi, 0);
  for (int s = 0; s < segments; ++s) {
    const int s1 = (s + 1) % segments;
    m.triangles.push_back({north, ring[0][s], ring[0][s1]});
    for (int r = 0; r + 1 < rings - 1; ++r) {
      m.triangles.push_back({ring[r][s], ring[r + 1][s], ring[r + 1][s1]});
      m.triangles.push_back({ring[r][s], ring[r + 1][s1], ring[r][s1]});
    }
    m.triangles.push_back({ring[rings - 2][s], south, ring[rings - 2][s1]});
  }
  return m;
}

/// Reads a whole file (empty when missing).
inline std::string read_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

/// Writes `bytes` as the whole file at `path`, as a new file rather than a truncated one: ext4
/// flushes truncate-and-rewrite on close, which made the readers' prefix sweeps take a minute.
inline void write_bytes(const std::string& path, const std::string& bytes) {
  std::remove(path.c_str());
  std::ofstream out(path, std::ios::binary);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

inline bool file_exists(const std::string& path) { return std::ifstream(path).good(); }

/// Corner-wise oriented match of every triangle of `b` against some triangle of `a` within
/// `tol` per coordinate; returns the number of unmatched triangles (brute force on vertex
/// lists: test meshes are small).
inline std::size_t unmatched_triangles(const TriangleMesh& a, const TriangleMesh& b, double tol) {
  auto near = [&](const std::array<float, 3>& p, const std::array<float, 3>& q) {
    return std::fabs(p[0] - q[0]) <= tol && std::fabs(p[1] - q[1]) <= tol && std::fabs(p[2] - q[2]) <= tol;
  };
  std::size_t missing = 0;
  for (const auto& tb : b.triangles) {
    bool found = false;
    for (const auto& ta : a.triangles) {
      for (int r = 0; r < 3 && !found; ++r)
        found = near(a.positions[ta[r]], b.positions[tb[0]]) &&
                near(a.positions[ta[(r + 1) % 3]], b.positions[tb[1]]) &&
                near(a.positions[ta[(r + 2) % 3]], b.positions[tb[2]]);
      if (found) break;
    }
    if (!found) ++missing;
  }
  return missing;
}

// Distance from p to triangle (a, b, c) (Ericson, Real-Time Collision Detection, 5.1.5).
inline double point_triangle_distance(const std::array<double, 3>& p, const std::array<float, 3>& fa,
                                      const std::array<float, 3>& fb, const std::array<float, 3>& fc) {
  using V = std::array<double, 3>;
  auto sub = [](const V& x, const V& y) { return V{x[0] - y[0], x[1] - y[1], x[2] - y[2]}; };
  auto dot = [](const V& x, const V& y) { return x[0] * y[0] + x[1] * y[1] + x[2] * y[2]; };
  auto along = [](const V& o, const V& d, double t) {
    return V{o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]};
  };
  const V a{fa[0], fa[1], fa[2]}, b{fb[0], fb[1], fb[2]}, c{fc[0], fc[1], fc[2]};
  const V ab = sub(b, a), ac = sub(c, a), ap = sub(p, a);
  V q;
  const double d1 = dot(ab, ap), d2 = dot(ac, ap);
  const V bp = sub(p, b), cp = sub(p, c);
  const double d3 = dot(ab, bp), d4 = dot(ac, bp), d5 = dot(ab, cp), d6 = dot(ac, cp);
  const double va = d3 * d6 - d5 * d4, vb = d5 * d2 - d1 * d6, vc = d1 * d4 - d3 * d2;
  if (d1 <= 0 && d2 <= 0)
    q = a;
  else if (d3 >= 0 && d4 <= d3)
    q = b;
  else if (d6 >= 0 && d5 <= d6)
    q = c;
  else if (vc <= 0 && d1 >= 0 && d3 <= 0)
    q = along(a, ab, d1 / (d1 - d3));
  else if (vb <= 0 && d2 >= 0 && d6 <= 0)
    q = along(a, ac, d2 / (d2 - d6));
  else if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0)
    q = along(b, sub(c, b), (d4 - d3) / ((d4 - d3) + (d5 - d6)));
  else {
    const double den = 1.0 / (va + vb + vc);
    const double v = vb * den, w = vc * den;
    q = V{a[0] + ab[0] * v + ac[0] * w, a[1] + ab[1] * v + ac[1] * w, a[2] + ab[2] * v + ac[2] * w};
  }
  const V d = sub(p, q);
  return std::sqrt(dot(d, d));
}

// Largest distance from a vertex of `from` (every `stride`-th) to the surface `to` (brute force).
inline double one_sided_hausdorff(const TriangleMesh& from, const TriangleMesh& to, std::size_t stride = 1) {
  double worst = 0;
  for (std::size_t i = 0; i < from.positions.size(); i += stride) {
    const auto& fp = from.positions[i];
    const std::array<double, 3> p{fp[0], fp[1], fp[2]};
    double best = 1e300;
    for (const auto& t : to.triangles)
      best = std::min(best,
                      point_triangle_distance(p, to.positions[t[0]], to.positions[t[1]], to.positions[t[2]]));
    worst = std::max(worst, best);
  }
  return worst;
}

}  // namespace mlfe::test
