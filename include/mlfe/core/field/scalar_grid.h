// A scalar grid (2D height field or 3D volume) with its index-to-physical transform.
// Every importer in formats/ produces one; the core samples it as a function f.
//
// Layout: values are float32, x fastest, then y, then z: value(i,j,k) = values[i + nx*(j + ny*k)].
// A 2D grid has dims[2] == 1.
//
// Physical position of voxel (i,j,k), in millimetres (or the file's unit):
//     p = origin + direction * (spacing .* (i,j,k))
// direction is a row-major 3x3 matrix with unit columns (the axes of i, j, k in the output space).
// `space` names the output convention of p ("RAS", "LPS", or "" when the file says nothing).
#pragma once
#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace mlfe {

enum class ScalarType : std::uint8_t { U8, I8, U16, I16, U32, I32, F32, F64 };

/// Name as used on the command line and in JSON ("uint8", "float32", ...).
const char* scalar_type_name(ScalarType t);
/// Size in bytes of one value of type t.
int scalar_type_size(ScalarType t);

struct GridTransform {
  std::array<double, 3> spacing{1.0, 1.0, 1.0};
  std::array<double, 3> origin{0.0, 0.0, 0.0};
  std::array<double, 9> direction{1, 0, 0, 0, 1, 0, 0, 0, 1};

  /// Physical point of continuous index coordinates (i, j, k).
  std::array<double, 3> index_to_physical(double i, double j, double k) const;
  /// Physical point of a point given in the grid-aligned local frame (index .* spacing),
  /// which is the frame the finite-element core works in.
  std::array<double, 3> local_to_physical(const std::array<double, 3>& local) const;
  /// Rotation part applied to a direction given in the local frame.
  std::array<double, 3> rotate(const std::array<double, 3>& v) const;
};

struct ScalarGrid {
  int dim = 3;                                ///< 2 or 3
  std::array<std::int64_t, 3> dims{0, 0, 0};  ///< nx, ny, nz (nz == 1 in 2D)
  std::vector<float> values;                  ///< nx*ny*nz values, x fastest
  GridTransform transform;
  std::string space;                         ///< "RAS", "LPS" or ""
  ScalarType source_type = ScalarType::F32;  ///< the type stored in the file
  std::string format;                        ///< "nrrd", "nifti", "raw", "vdb", ...
  std::string source;                        ///< the file it came from
  std::string notes;                         ///< conversions applied, one per line

  std::int64_t voxel_count() const { return dims[0] * dims[1] * dims[2]; }
  float at(std::int64_t i, std::int64_t j, std::int64_t k) const {
    return values[static_cast<std::size_t>(i + dims[0] * (j + dims[1] * k))];
  }
  /// Minimum and maximum value (NaN-free grids only).
  std::array<float, 2> value_range() const;
  /// Extent of the grid-aligned local frame: (n-1)*spacing per axis (0 for unused axes).
  std::array<double, 3> local_extent() const;
};

/// The samples [lo, hi) of the 3D grid `grid` (inside its dims; CHECK) as a grid with its
/// transform (the window keeps the whole grid's lattice frame, not one moved to lo).
ScalarGrid window_of(const ScalarGrid& grid, const std::array<std::int64_t, 3>& lo,
                     const std::array<std::int64_t, 3>& hi);

}  // namespace mlfe
