#include <mlfe/core/base/check.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/field/field.h>

#include <algorithm>
#include <cmath>

namespace mlfe {

void Field::values(const std::array<double, 3>* x, double* out, std::size_t n) const {
  for (std::size_t j = 0; j < n; ++j) out[j] = value(x[j]);
}

void Field::gradients(const std::array<double, 3>* x, std::array<double, 3>* out, std::size_t n) const {
  for (std::size_t j = 0; j < n; ++j) out[j] = gradient(x[j]);
}

std::array<double, 2> Field::range_in_box(const std::array<double, 3>&, const std::array<double, 3>&) const {
  return range();
}

namespace {

// The sample lattice as plain locals: the batched loops write doubles through `out`, which
// the compiler would otherwise assume may alias the field's members and reload them per point.
struct Lattice {
  const float* v;
  std::int64_t n[3];
  double inv_spacing[3];
};

// Cell of x (index of its lower corner) and the offsets t in [0, 1] inside it; Dim is a
// template parameter so the per-point loops carry no dimension branches. Single-point and
// batched evaluation share these kernels, so they agree bit for bit.
Lattice make_lattice(const float* v, const std::array<std::int64_t, 3>& n,
                     const std::array<double, 3>& inv_spacing) {
  return {v, {n[0], n[1], n[2]}, {inv_spacing[0], inv_spacing[1], inv_spacing[2]}};
}

template <int Dim>
inline std::int64_t locate(const Lattice& l, const std::array<double, 3>& x, double t[3]) {
  std::int64_t i0[3];
  for (int a = 0; a < 3; ++a) {
    if (a >= Dim) {
      i0[a] = 0;
      t[a] = 0;
      continue;
    }
    const double maxs = double(l.n[a] - 1);
    const double s = std::clamp(x[a] * l.inv_spacing[a], 0.0, maxs);
    std::int64_t i = static_cast<std::int64_t>(s);
    if (i >= l.n[a] - 1) i = l.n[a] - 2;
    i0[a] = i;
    t[a] = s - double(i);
  }
  return i0[0] + l.n[0] * (i0[1] + l.n[1] * i0[2]);
}

template <int Dim>
inline double interpolate(const Lattice& l, const std::array<double, 3>& x) {
  double t[3];
  const std::int64_t base = locate<Dim>(l, x, t);
  const float* v = l.v;
  const std::int64_t sx = 1, sy = l.n[0], sz = l.n[0] * l.n[1];
  if constexpr (Dim == 2) {
    const double v00 = v[base], v10 = v[base + sx], v01 = v[base + sy], v11 = v[base + sx + sy];
    const double a = v00 + t[0] * (v10 - v00);
    const double b = v01 + t[0] * (v11 - v01);
    return a + t[1] * (b - a);
  } else {
    const double c000 = v[base], c100 = v[base + sx], c010 = v[base + sy], c110 = v[base + sx + sy];
    const double c001 = v[base + sz], c101 = v[base + sx + sz], c011 = v[base + sy + sz],
                 c111 = v[base + sx + sy + sz];
    const double c00 = c000 + t[0] * (c100 - c000), c10 = c010 + t[0] * (c110 - c010);
    const double c01 = c001 + t[0] * (c101 - c001), c11 = c011 + t[0] * (c111 - c011);
    const double c0 = c00 + t[1] * (c10 - c00), c1 = c01 + t[1] * (c11 - c01);
    return c0 + t[2] * (c1 - c0);
  }
}

template <int Dim>
inline std::array<double, 3> interpolate_gradient(const Lattice& l, const std::array<double, 3>& x) {
  double t[3];
  const std::int64_t base = locate<Dim>(l, x, t);
  const float* v = l.v;
  const std::int64_t sx = 1, sy = l.n[0], sz = l.n[0] * l.n[1];
  if constexpr (Dim == 2) {
    const double v00 = v[base], v10 = v[base + sx], v01 = v[base + sy], v11 = v[base + sx + sy];
    const double gx = (1 - t[1]) * (v10 - v00) + t[1] * (v11 - v01);
    const double gy = (1 - t[0]) * (v01 - v00) + t[0] * (v11 - v10);
    return {gx * l.inv_spacing[0], gy * l.inv_spacing[1], 0.0};
  } else {
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
    return {gx * l.inv_spacing[0], gy * l.inv_spacing[1], gz * l.inv_spacing[2]};
  }
}

}  // namespace

GridField::GridField(const ScalarGrid& grid) : grid_(grid), dim_(grid.dim), n_(grid.dims) {
  if (dim_ != 2 && dim_ != 3)
    throw Error(grid.source + ": a grid is 2D or 3D, not " + std::to_string(dim_) + "D");
  if (grid.values.size() != static_cast<std::size_t>(grid.voxel_count()))
    throw Error(grid.source + ": " + std::to_string(grid.values.size()) + " values for " +
                std::to_string(grid.voxel_count()) + " voxels");
  resolution_ = 1e300;
  double voxel_volume = 1;
  for (int a = 0; a < 3; ++a) {
    if (a < dim_) {
      if (n_[a] < 2 || !(grid.transform.spacing[a] > 0))
        throw Error(grid.source + ": needs at least 2 samples and a positive spacing along every axis");
      inv_spacing_[a] = 1.0 / grid.transform.spacing[a];
      resolution_ = std::min(resolution_, grid.transform.spacing[a]);
      voxel_volume *= grid.transform.spacing[a];
    } else {
      inv_spacing_[a] = 0.0;
    }
  }
  voxel_size_ = std::pow(voxel_volume, 1.0 / dim_);
  extent_ = grid.local_extent();
  const auto r = grid.value_range();
  range_ = {r[0], r[1]};
}

double GridField::value(const std::array<double, 3>& x) const {
  const Lattice l = make_lattice(grid_.values.data(), n_, inv_spacing_);
  return dim_ == 2 ? interpolate<2>(l, x) : interpolate<3>(l, x);
}

void GridField::values(const std::array<double, 3>* x, double* out, std::size_t n) const {
  const Lattice l = make_lattice(grid_.values.data(), n_, inv_spacing_);
  if (dim_ == 2) {
    for (std::size_t j = 0; j < n; ++j) out[j] = interpolate<2>(l, x[j]);
  } else {
    for (std::size_t j = 0; j < n; ++j) out[j] = interpolate<3>(l, x[j]);
  }
}

std::array<double, 3> GridField::gradient(const std::array<double, 3>& x) const {
  const Lattice l = make_lattice(grid_.values.data(), n_, inv_spacing_);
  return dim_ == 2 ? interpolate_gradient<2>(l, x) : interpolate_gradient<3>(l, x);
}

void GridField::gradients(const std::array<double, 3>* x, std::array<double, 3>* out, std::size_t n) const {
  const Lattice l = make_lattice(grid_.values.data(), n_, inv_spacing_);
  if (dim_ == 2) {
    for (std::size_t j = 0; j < n; ++j) out[j] = interpolate_gradient<2>(l, x[j]);
  } else {
    for (std::size_t j = 0; j < n; ++j) out[j] = interpolate_gradient<3>(l, x[j]);
  }
}

std::array<double, 2> GridField::range_in_box(const std::array<double, 3>& lo,
                                              const std::array<double, 3>& hi) const {
  std::call_once(pyramid_once_, [&] { pyramid_ = std::make_unique<MinMaxPyramid>(grid_); });
  std::array<double, 3> i0{0, 0, 0}, i1{0, 0, 0};
  for (int a = 0; a < dim_; ++a) {
    i0[a] = lo[a] * inv_spacing_[a];
    i1[a] = hi[a] * inv_spacing_[a];
  }
  const auto r = pyramid_->range(i0, i1);
  return {r[0], r[1]};
}

}  // namespace mlfe
