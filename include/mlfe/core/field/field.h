// The input as a function f on the domain, evaluated at points of the grid-aligned local frame
// (physical units: index .* spacing, origin at voxel 0). The finite-element core only sees this
// interface, so VDB or unstructured inputs plug in the same way.
#pragma once
#include <mlfe/core/field/minmax_pyramid.h>
#include <mlfe/core/field/scalar_grid.h>

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>

namespace mlfe {

class Field {
 public:
  virtual ~Field() = default;
  /// 2 or 3.
  virtual int dim() const = 0;
  /// f at local point x (x[2] ignored in 2D). Points outside the domain are clamped to it.
  virtual double value(const std::array<double, 3>& x) const = 0;
  /// out[j] = value(x[j]) for j < n, bit for bit. One virtual call per batch instead of per
  /// point: element integration evaluates hundreds of points at a time. The default loops
  /// over value(); fields with a cheap per-point kernel override it.
  virtual void values(const std::array<double, 3>* x, double* out, std::size_t n) const;
  /// Upper corner of the domain [0, extent] in the local frame.
  virtual std::array<double, 3> extent() const = 0;
  /// ∇f at local point x (zero components beyond dim()); piecewise constant across voxels for
  /// interpolated grids.
  virtual std::array<double, 3> gradient(const std::array<double, 3>& x) const = 0;
  /// out[j] = gradient(x[j]) for j < n, bit for bit (see values()).
  virtual void gradients(const std::array<double, 3>* x, std::array<double, 3>* out, std::size_t n) const;
  /// Length below which f has no detail (the smallest voxel spacing).
  virtual double resolution() const = 0;
  /// Side of the cube (square in 2D) with the volume of one voxel: the length the element
  /// integration compares its sub-simplex size with (same kind of measure). Defaults to
  /// resolution().
  virtual double voxel_size() const { return resolution(); }
  /// Smallest and largest value of f.
  virtual std::array<double, 2> range() const = 0;
  /// A range that contains every value of f on the box [lo, hi] (local frame); it may be wider
  /// (conservative), never narrower. Surface-driven refinement asks it for every candidate
  /// element, so fields should answer without visiting the box's samples. Defaults to range().
  virtual std::array<double, 2> range_in_box(const std::array<double, 3>& lo,
                                             const std::array<double, 3>& hi) const;
  /// The sample grid f interpolates, when f is one (null otherwise): estimators can then test
  /// the samples themselves, the values marching cubes and the scan's own surface come from.
  virtual const ScalarGrid* samples() const { return nullptr; }
};

/// Trilinear (3D) / bilinear (2D) interpolation of a ScalarGrid's samples, which sit at the
/// voxel positions i * spacing. Holds a reference: the grid must outlive the field.
/// Throws mlfe::Error unless the grid is 2D or 3D, its values fill its dims, and every axis of
/// its dimension has at least 2 samples and a positive spacing.
class GridField final : public Field {
 public:
  explicit GridField(const ScalarGrid& grid);
  int dim() const override { return dim_; }
  double value(const std::array<double, 3>& x) const override;
  void values(const std::array<double, 3>* x, double* out, std::size_t n) const override;
  std::array<double, 3> gradient(const std::array<double, 3>& x) const override;
  void gradients(const std::array<double, 3>* x, std::array<double, 3>* out, std::size_t n) const override;
  std::array<double, 3> extent() const override { return extent_; }
  double resolution() const override { return resolution_; }
  double voxel_size() const override { return voxel_size_; }
  std::array<double, 2> range() const override { return range_; }
  /// From a min/max pyramid of the samples, built on the first call (thread-safe).
  std::array<double, 2> range_in_box(const std::array<double, 3>& lo,
                                     const std::array<double, 3>& hi) const override;
  const ScalarGrid& grid() const { return grid_; }
  const ScalarGrid* samples() const override { return &grid_; }

 private:
  const ScalarGrid& grid_;
  int dim_;
  std::array<std::int64_t, 3> n_;
  std::array<double, 3> inv_spacing_;
  std::array<double, 3> extent_;
  double resolution_;
  double voxel_size_;
  std::array<double, 2> range_;
  mutable std::once_flag pyramid_once_;
  mutable std::unique_ptr<MinMaxPyramid> pyramid_;
};

}  // namespace mlfe
