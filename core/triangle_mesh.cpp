// Area-weighted vertex normals of an indexed triangle mesh.
#include <mlfe/core/check.h>
#include <mlfe/core/error.h>
#include <mlfe/core/triangle_mesh.h>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <vector>

namespace mlfe {

using Vec3 = Eigen::Vector3d;

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

}  // namespace mlfe
