// Reading scan volumes and height fields into a mlfe::ScalarGrid.
//
// Supported: OpenVDB (.vdb), raw + JSON sidecar (FILE.json next to FILE), NRRD (.nrrd/.nhdr,
// via Teem), NIfTI-1/2 (.nii, .nii.gz, .hdr+.img, via libnifti2), MetaImage (.mha/.mhd),
// binary PGM (P5, 8/16 bit), grey PNG (8/16 bit, via libpng) and OME-Zarr 0.4 image folders
// (formats/zarr_reader.h).
//
// Every reader validates before it allocates: magic, version, header, then the voxel count
// and byte size with overflow checks against the file size and the memory limit. Bad input
// of any kind is reported as mlfe::Error with one line "<file>: <problem>"; the libraries'
// own diagnostics are captured and never printed, and no library may end the process.
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

/// Reads the volume or height field at `path` (format by magic bytes, then by extension; a
/// headerless file is read as raw when it has a sidecar or opts.raw_dims is set).
/// Values are converted to float32 (the file's type is kept in source_type); spacing and
/// origin are in the file's unit (usually millimetres); a grid with nz == 1 has dim == 2.
/// NaN/Inf voxels throw unless opts.nan_as is set. Throws mlfe::Error with one line
/// naming `path` and the problem for any bad, truncated or unsupported input, and when the
/// grid would need more memory than opts.max_bytes (or MemAvailable).
ScalarGrid read_volume(const std::string& path, const VolumeReadOptions& opts = {});

/// The format of `path`: "vdb", "nrrd", "nifti", "metaimage", "pgm", "png", "raw" or "zarr" (a
/// folder holding OME-Zarr or Zarr v2 metadata), decided
/// by magic bytes first and by extension second (a sidecar FILE.json means "raw").
/// Returns "" when neither identifies a format. Throws mlfe::Error when `path` cannot be read.
std::string detect_volume_format(const std::string& path);

/// The default memory limit in bytes: MemAvailable from /proc/meminfo (16 GiB if unknown).
std::size_t default_memory_limit();

}  // namespace mlfe
