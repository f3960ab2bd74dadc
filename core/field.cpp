#include "core/field.h"

#include <algorithm>
#include <cmath>

#include "core/check.h"

namespace mlfe {

GridField::GridField(const ScalarGrid& grid) : grid_(grid), dim_(grid.dim), n_(grid.dims) {
  MLFE_CHECK(dim_ == 2 || dim_ == 3);
  MLFE_CHECK(grid.values.size() == static_cast<std::size_t>(grid.voxel_count()));
  resolution_ = 1e300;
  for (int a = 0; a < 3; ++a) {
    if (a < dim_) {
      MLFE_CHECK(n_[a] >= 2 && grid.transform.spacing[a] > 0);
      inv_spacing_[a] = 1.0 / grid.transform.spacing[a];
      resolution_ = std::min(resolution_, grid.transform.spacing[a]);
    } else {
      inv_spacing_[a] = 0.0;
    }
  }
  extent_ = grid.local_extent();
  const auto r = grid.value_range();
  range_ = {r[0], r[1]};
}

void GridField::locate(const std::array<double, 3>& x, std::int64_t& base, double t[3]) const {
  std::int64_t i0[3];
  for (int a = 0; a < 3; ++a) {
    if (a >= dim_) {
      i0[a] = 0;
      t[a] = 0;
      continue;
    }
    const double maxs = double(n_[a] - 1);
    const double s = std::clamp(x[a] * inv_spacing_[a], 0.0, maxs);
    std::int64_t i = static_cast<std::int64_t>(s);
    if (i >= n_[a] - 1) i = n_[a] - 2;
    i0[a] = i;
    t[a] = s - double(i);
  }
  base = i0[0] + n_[0] * (i0[1] + n_[1] * i0[2]);
}

double GridField::value(const std::array<double, 3>& x) const {
  std::int64_t base;
  double t[3];
  locate(x, base, t);
  const float* v = grid_.values.data();
  const std::int64_t sx = 1, sy = n_[0], sz = n_[0] * n_[1];
  if (dim_ == 2) {
    const double v00 = v[base], v10 = v[base + sx], v01 = v[base + sy], v11 = v[base + sx + sy];
    const double a = v00 + t[0] * (v10 - v00);
    const double b = v01 + t[0] * (v11 - v01);
    return a + t[1] * (b - a);
  }
  const double c000 = v[base], c100 = v[base + sx], c010 = v[base + sy], c110 = v[base + sx + sy];
  const double c001 = v[base + sz], c101 = v[base + sx + sz], c011 = v[base + sy + sz],
               c111 = v[base + sx + sy + sz];
  const double c00 = c000 + t[0] * (c100 - c000), c10 = c010 + t[0] * (c110 - c010);
  const double c01 = c001 + t[0] * (c101 - c001), c11 = c011 + t[0] * (c111 - c011);
  const double c0 = c00 + t[1] * (c10 - c00), c1 = c01 + t[1] * (c11 - c01);
  return c0 + t[2] * (c1 - c0);
}

std::array<double, 3> GridField::gradient(const std::array<double, 3>& x) const {
  std::int64_t base;
  double t[3];
  locate(x, base, t);
  const float* v = grid_.values.data();
  const std::int64_t sx = 1, sy = n_[0], sz = n_[0] * n_[1];
  if (dim_ == 2) {
    const double v00 = v[base], v10 = v[base + sx], v01 = v[base + sy], v11 = v[base + sx + sy];
    const double gx = (1 - t[1]) * (v10 - v00) + t[1] * (v11 - v01);
    const double gy = (1 - t[0]) * (v01 - v00) + t[0] * (v11 - v10);
    return {gx * inv_spacing_[0], gy * inv_spacing_[1], 0.0};
  }
  double c[2][2][2];
  for (int k = 0; k < 2; ++k)
    for (int j = 0; j < 2; ++j)
      for (int i = 0; i < 2; ++i) c[k][j][i] = v[base + i * sx + j * sy + k * sz];
  auto lerp = [](double a, double b, double s) { return a + s * (b - a); };
  const double gx = lerp(lerp(c[0][0][1] - c[0][0][0], c[0][1][1] - c[0][1][0], t[1]),
                         lerp(c[1][0][1] - c[1][0][0], c[1][1][1] - c[1][1][0], t[1]), t[2]);
  const double gy = lerp(lerp(c[0][1][0] - c[0][0][0], c[0][1][1] - c[0][0][1], t[0]),
                         lerp(c[1][1][0] - c[1][0][0], c[1][1][1] - c[1][0][1], t[0]), t[2]);
  const double gz = lerp(lerp(c[1][0][0] - c[0][0][0], c[1][0][1] - c[0][0][1], t[0]),
                         lerp(c[1][1][0] - c[0][1][0], c[1][1][1] - c[0][1][1], t[0]), t[1]);
  return {gx * inv_spacing_[0], gy * inv_spacing_[1], gz * inv_spacing_[2]};
}

}  // namespace mlfe
