#include <mlfe/core/base/check.h>
#include <mlfe/core/field/scalar_grid.h>

#include <algorithm>
#include <limits>

namespace mlfe {

const char* scalar_type_name(ScalarType t) {
  switch (t) {
    case ScalarType::U8:
      return "uint8";
    case ScalarType::I8:
      return "int8";
    case ScalarType::U16:
      return "uint16";
    case ScalarType::I16:
      return "int16";
    case ScalarType::U32:
      return "uint32";
    case ScalarType::I32:
      return "int32";
    case ScalarType::F32:
      return "float32";
    case ScalarType::F64:
      return "float64";
  }
  return "unknown";
}

int scalar_type_size(ScalarType t) {
  switch (t) {
    case ScalarType::U8:
    case ScalarType::I8:
      return 1;
    case ScalarType::U16:
    case ScalarType::I16:
      return 2;
    case ScalarType::U32:
    case ScalarType::I32:
    case ScalarType::F32:
      return 4;
    case ScalarType::F64:
      return 8;
  }
  return 0;
}

std::array<double, 3> GridTransform::index_to_physical(double i, double j, double k) const {
  return local_to_physical({i * spacing[0], j * spacing[1], k * spacing[2]});
}

std::array<double, 3> GridTransform::rotate(const std::array<double, 3>& v) const {
  const auto& d = direction;
  return {d[0] * v[0] + d[1] * v[1] + d[2] * v[2], d[3] * v[0] + d[4] * v[1] + d[5] * v[2],
          d[6] * v[0] + d[7] * v[1] + d[8] * v[2]};
}

std::array<double, 3> GridTransform::local_to_physical(const std::array<double, 3>& local) const {
  auto r = rotate(local);
  return {origin[0] + r[0], origin[1] + r[1], origin[2] + r[2]};
}

std::array<float, 2> ScalarGrid::value_range() const {
  float lo = std::numeric_limits<float>::infinity();
  float hi = -std::numeric_limits<float>::infinity();
  for (float v : values) {
    lo = std::min(lo, v);
    hi = std::max(hi, v);
  }
  return {lo, hi};
}

std::array<double, 3> ScalarGrid::local_extent() const {
  std::array<double, 3> e{};
  for (int a = 0; a < 3; ++a) e[a] = dims[a] > 1 ? double(dims[a] - 1) * transform.spacing[a] : 0.0;
  return e;
}

ScalarGrid window_of(const ScalarGrid& grid, const std::array<std::int64_t, 3>& lo,
                     const std::array<std::int64_t, 3>& hi) {
  MLFE_CHECK(grid.dim == 3);
  for (int a = 0; a < 3; ++a) MLFE_CHECK(0 <= lo[a] && lo[a] < hi[a] && hi[a] <= grid.dims[a]);
  ScalarGrid w;
  w.dims = {hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]};
  w.transform = grid.transform;
  w.values.resize(std::size_t(w.voxel_count()));
  float* to = w.values.data();
  for (std::int64_t k = lo[2]; k < hi[2]; ++k)
    for (std::int64_t j = lo[1]; j < hi[1]; ++j) {
      const float* row = &grid.values[std::size_t(lo[0] + grid.dims[0] * (j + grid.dims[1] * k))];
      to = std::copy(row, row + w.dims[0], to);
    }
  return w;
}

}  // namespace mlfe
