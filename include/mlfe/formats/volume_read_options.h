// What every volume reader takes: the options of a read, the memory limit they default to and
// the raw data's type names.
// The readers (formats/*_reader.cpp) include this rather than volume_reader.h, the dispatcher
// that picks one of them, so that no include runs from a reader back up to it.
#pragma once
#include <mlfe/core/field/scalar_grid.h>

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>

namespace mlfe {

struct VolumeReadOptions {
  std::string grid_name;         ///< VDB: name of the grid to read (default: first scalar grid); for a
                                 ///< .vtu/.msh input, the point-data array (tet_mesh_read_options)
  bool vec_magnitude = false;    ///< VDB vector grids are read as their magnitude
  std::optional<double> nan_as;  ///< NaN/Inf voxels become this value; unset: NaN/Inf is an error
  /// "ras", "lps" (any case) or "": convert the transform to this output convention by
  /// flipping the x and y rows, and set ScalarGrid::space. "" keeps the file's convention.
  std::string space;
  // Headerless raw files: used when there is no sidecar, and override the sidecar's fields.
  std::optional<std::array<std::int64_t, 3>> raw_dims;  ///< nz == 1 (or 0) for a 2D grid
  std::string raw_dtype;                                ///< "uint8" ... "float64" (also u8, i16, f32, ...)
  std::string raw_endian = "little";                    ///< "little" or "big"
  std::optional<std::array<double, 3>> raw_spacing, raw_origin;
  std::int64_t raw_offset = 0;  ///< bytes to skip before the voxels
  /// OME-Zarr: the resolution level to read (0: full resolution).
  int zarr_level = 0;
  /// Upper bound in bytes for what reading may allocate; 0: MemAvailable from /proc/meminfo.
  std::size_t max_bytes = 0;
};

/// The type raw_dtype names: "uint8"/"u8"/"uchar", ..., "float64"/"f64"/"double" (any case);
/// nullopt when unknown.
std::optional<ScalarType> parse_scalar_type(const std::string& name);

/// The default memory limit in bytes: MemAvailable from /proc/meminfo (16 GiB if unknown).
std::size_t default_memory_limit();

}  // namespace mlfe
