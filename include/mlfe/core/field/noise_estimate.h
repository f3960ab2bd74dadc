// The noise level of a scan, for a default error target that does not store the noise.
//
// Robust estimate from second differences (the finest-scale detail, as Donoho & Johnstone's
// MAD of the finest wavelet coefficients, "Ideal spatial adaptation by wavelet shrinkage",
// Biometrika 1994): for white noise of deviation σ, d = f[i−1] − 2 f[i] + f[i+1] along an axis
// has deviation √6 σ, and edges and texture occupy few samples, so the median of |d| is
// ≈ 0.6745 √6 σ. The estimate is local, per block of 8³ samples (16² in 2D), and the scan's
// is the median of the blocks': edges and texture raise a minority of the blocks, and noise
// that varies over the scan (Rician noise is weaker in air) is taken at its middle. Within a block, the
// smallest of the axes' estimates is taken (structure along an axis only adds to it). Second differences that
// are exactly 0 are left out, and blocks where most are: constant regions (a brain-extracted scan's zero
// background, air clipped to 0) carry no noise and would drive the estimate to 0.
#pragma once
#include <mlfe/core/field/scalar_grid.h>

namespace mlfe {

/// σ of the grid's sample noise in data units (0 when the data has no non-zero second
/// difference). Deterministic; reads every sample once per axis of the grid's dimension.
double estimate_noise_sigma(const ScalarGrid& grid);

}  // namespace mlfe
