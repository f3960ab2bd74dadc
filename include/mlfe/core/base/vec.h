// Arithmetic of 3-vectors held as std::array<double, 3>, the one copy for every room (points of
// meshes, rays and tetrahedra). Each function is the plain component-wise formula, so results
// are the same bits wherever it is inlined. Eigen is there for linear algebra; these are for the
// inner loops that keep points as arrays.
#pragma once
#include <array>
#include <cmath>

namespace mlfe {

using Vec3 = std::array<double, 3>;

/// A float point (how meshes store their positions and normals) widened to double.
inline Vec3 to_vec3(const std::array<float, 3>& p) { return {p[0], p[1], p[2]}; }
inline Vec3 add(const Vec3& a, const Vec3& b) { return {a[0] + b[0], a[1] + b[1], a[2] + b[2]}; }
inline Vec3 sub(const Vec3& a, const Vec3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
inline Vec3 scale(const Vec3& a, double s) { return {a[0] * s, a[1] * s, a[2] * s}; }
/// p + s d.
inline Vec3 axpy(const Vec3& p, double s, const Vec3& d) {
  return {p[0] + s * d[0], p[1] + s * d[1], p[2] + s * d[2]};
}
inline double dot(const Vec3& a, const Vec3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
inline Vec3 cross(const Vec3& a, const Vec3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
inline double norm(const Vec3& a) { return std::sqrt(dot(a, a)); }
inline double distance(const Vec3& a, const Vec3& b) { return norm(sub(a, b)); }
/// a / |a| (a must not be zero).
inline Vec3 normalized(const Vec3& a) {
  const double n = norm(a);
  return {a[0] / n, a[1] / n, a[2] / n};
}

/// Six times the signed volume of the tetrahedron (a, b, c, d): positive when b − a, c − a and
/// d − a are right-handed, the positive orientation of VTK's and Gmsh's tetrahedra. Red-green
/// refinement keeps no orientation, so whoever hands tetrahedra out orders them by its sign
/// (swapping c and d of a negative one), in the frame it hands out.
inline double signed_volume6(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d) {
  const Vec3 u = sub(b, a), v = sub(c, a), w = sub(d, a);
  return u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0]) +
         u[2] * (v[0] * w[1] - v[1] * w[0]);
}

}  // namespace mlfe
