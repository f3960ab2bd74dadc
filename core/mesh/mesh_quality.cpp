#include <mlfe/core/base/vec.h>
#include <mlfe/core/mesh/mesh_quality.h>

#include <algorithm>
#include <cmath>

namespace mlfe {

namespace {
constexpr double kPi = 3.14159265358979323846;
}

double min_angle_deg(const std::array<std::array<double, 2>, 3>& p) {
  double best = 180.0;
  for (int i = 0; i < 3; ++i) {
    const auto& a = p[i];
    const auto& b = p[(i + 1) % 3];
    const auto& c = p[(i + 2) % 3];
    const double ux = b[0] - a[0], uy = b[1] - a[1], vx = c[0] - a[0], vy = c[1] - a[1];
    const double nu = std::hypot(ux, uy), nv = std::hypot(vx, vy);
    if (nu == 0 || nv == 0) return 0.0;
    const double cosang = std::clamp((ux * vx + uy * vy) / (nu * nv), -1.0, 1.0);
    best = std::min(best, std::acos(cosang) * 180.0 / kPi);
  }
  return best;
}

double min_dihedral_deg(const std::array<std::array<double, 3>, 4>& p) {
  // Face normals (outward up to a common sign); the dihedral angle at the edge shared by
  // faces i and j is pi minus the angle between their outward normals.
  std::array<Vec3, 4> n;
  for (int f = 0; f < 4; ++f) {
    int idx[3], k = 0;
    for (int j = 0; j < 4; ++j)
      if (j != f) idx[k++] = j;
    auto nf = cross(sub(p[idx[1]], p[idx[0]]), sub(p[idx[2]], p[idx[0]]));
    // Orient away from the opposite vertex.
    if (dot(nf, sub(p[f], p[idx[0]])) > 0) nf = {-nf[0], -nf[1], -nf[2]};
    if (norm(nf) == 0) return 0.0;
    n[f] = normalized(nf);
  }
  double best = 180.0;
  for (int i = 0; i < 4; ++i)
    for (int j = i + 1; j < 4; ++j) {
      const double c = std::clamp(-dot(n[i], n[j]), -1.0, 1.0);
      best = std::min(best, std::acos(c) * 180.0 / kPi);
    }
  return best;
}

}  // namespace mlfe
