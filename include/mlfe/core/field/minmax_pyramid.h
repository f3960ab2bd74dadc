// Value ranges of a voxel grid over boxes, from a min/max pyramid (the "min/max octree" of
// Wilhelms & Van Gelder, "Octrees for faster isosurface generation", ACM TOG 11(3), 1992).
//
// Level 0 holds, for each block of 2x2x2 cells (cell = the 8 samples around it), the range of
// its samples; level k+1 merges 2x2x2 blocks of level k. A query covers the box by at most
// 2 blocks per axis of the level whose blocks are at least as large as the box, so it costs a
// handful of reads whatever the box's size. The interpolated field inside a cell lies within
// its samples' range, so the answer contains the range of f over the box (conservative: it may
// be wider by up to one block).
#pragma once
#include <mlfe/core/field/scalar_grid.h>

#include <array>
#include <cstdint>
#include <vector>

namespace mlfe {

class MinMaxPyramid {
 public:
  /// One pass over the grid (TBB-parallel); about 1.2 bytes per voxel. Holds no reference.
  explicit MinMaxPyramid(const ScalarGrid& grid);

  /// A range [lo, hi] that contains every sample of the cells overlapping the index-space box
  /// [i0, i1] (continuous index coordinates, clamped to the grid).
  std::array<float, 2> range(const std::array<double, 3>& i0, const std::array<double, 3>& i1) const;

  std::size_t memory_bytes() const;

 private:
  struct Level {
    std::array<std::int64_t, 3> n;  // blocks per axis
    std::vector<float> lo, hi;
  };
  std::array<std::int64_t, 3> cells_;  // cells per axis (samples - 1, at least 1)
  std::vector<Level> levels_;
};

}  // namespace mlfe
