// The piecewise-linear function of a hierarchy's leaves sampled back onto a voxel grid, for
// `mlfe export` and for the error figures of the hierarchy file against its source.
#pragma once
#include <mlfe/core/field/scalar_grid.h>
#include <mlfe/core/mesh/hierarchy.h>

#include <array>
#include <cstdint>
#include <vector>

namespace mlfe {

/// The grid a hierarchy was built on: T0 spans [0, (n−1)·spacing] in the local frame, so
/// n = round(max / spacing) + 1 per axis (1 for the unused third axis in 2D). Throws
/// mlfe::Error when T0 does not start at the origin or the extent is not close (1e-6
/// relative) to a whole number of spacings.
template <int D>
std::array<std::int64_t, 3> hierarchy_grid_dims(const Hierarchy<D>& h, const std::array<double, 3>& spacing);

/// Values at the grid points (index .* spacing, local frame; x fastest) of the function that
/// is linear on every leaf of h with the given vertex values. A point on a shared face takes
/// the value of the first leaf in id order that contains it (the others agree up to
/// rounding); a point in no leaf (outside T0's union) is NaN. Parallel over z-slabs; the
/// result does not depend on the thread count.
template <int D>
std::vector<float> resample_to_grid(const Hierarchy<D>& h, const std::vector<double>& values,
                                    const std::array<std::int64_t, 3>& dims,
                                    const std::array<double, 3>& spacing);

struct GridErrors {
  double rms = 0;   ///< sqrt(mean (a − b)²) over all points
  double max = 0;   ///< max |a − b|
  double psnr = 0;  ///< 20 log10(range / rms), dB (infinity when rms = 0)
};

/// a against b (same size, CHECKed; no NaN in either, else mlfe::Error naming `what`); the
/// PSNR is over `range` (> 0; 1 when the data is constant).
GridErrors grid_errors(const std::vector<float>& a, const std::vector<float>& b, double range,
                       const std::string& what);

extern template std::vector<float> resample_to_grid<2>(const Hierarchy<2>&, const std::vector<double>&,
                                                       const std::array<std::int64_t, 3>&,
                                                       const std::array<double, 3>&);
extern template std::vector<float> resample_to_grid<3>(const Hierarchy<3>&, const std::vector<double>&,
                                                       const std::array<std::int64_t, 3>&,
                                                       const std::array<double, 3>&);

}  // namespace mlfe
