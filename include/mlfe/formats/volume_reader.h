// Reading scan volumes and height fields into a mlfe::ScalarGrid.
//
// Supported: the rows of the table of volume formats (formats/volume_formats.cpp), each with its
// reader's header <mlfe/formats/<name>_reader.h>; README's "Inputs" lists them.
//
// Every reader validates before it allocates: magic, version, header, then the voxel count
// and byte size with overflow checks against the file size and the memory limit. Bad input
// of any kind is reported as mlfe::Error with one line "<file>: <problem>"; the libraries'
// own diagnostics are captured and never printed, and no library may end the process.
#pragma once
#include <mlfe/core/field/scalar_grid.h>
#include <mlfe/formats/volume_read_options.h>

#include <array>
#include <cstdint>
#include <memory>
#include <string>

namespace mlfe {

/// Reads the volume or height field at `path` (format by magic bytes, then by extension; a
/// headerless file is read as raw when it has a sidecar or opts.raw_dims is set).
/// Values are converted to float32 (the file's type is kept in source_type); spacing and
/// origin are in the file's unit (usually millimetres); a grid with nz == 1 has dim == 2.
/// NaN/Inf voxels throw unless opts.nan_as is set. Throws mlfe::Error with one line
/// naming `path` and the problem for any bad, truncated or unsupported input, and when the
/// grid would need more memory than opts.max_bytes (or MemAvailable).
ScalarGrid read_volume(const std::string& path, const VolumeReadOptions& opts = {});

/// The format of `path`, the name of its row in the table ("vdb", "nrrd", "nifti", "raw", ...),
/// decided by magic bytes first and by extension second (a sidecar FILE.json means "raw").
/// Returns "" when neither identifies a format. Throws mlfe::Error when `path` cannot be read.
std::string detect_volume_format(const std::string& path);

/// True when VolumeWindows reads `path` box by box from the file (a raw volume or an OME-Zarr
/// store), false when it would read it whole. Reads at most the file's first bytes.
bool reads_in_windows(const std::string& path, const VolumeReadOptions& opts);

/// A volume opened for reading box by box (`mlfe convert --bricks`): its frame at once, its
/// samples window by window. Raw volumes and OME-Zarr stores are read box by box from the file
/// (only a window's voxels in memory); the other formats are read whole once and their windows
/// copied from memory. A window holds the values read_volume would give there.
class VolumeWindows {
 public:
  /// Opens `path` as read_volume reads it (the same checks of header and frame, `opts.space`
  /// applied), reading no voxels where the format allows. Throws as read_volume does.
  VolumeWindows(const std::string& path, const VolumeReadOptions& opts);
  ~VolumeWindows();
  VolumeWindows(VolumeWindows&&) noexcept;
  VolumeWindows& operator=(VolumeWindows&&) noexcept;

  /// The volume as read_volume returns it, without values (dims, transform, space,
  /// source_type, format, source, notes, dim).
  const ScalarGrid& frame() const;
  /// True when windows are read from the file, false when the volume is held in memory.
  bool streamed() const;
  /// The samples [lo, hi) (inside frame().dims) as a grid with frame()'s transform. NaN/Inf
  /// voxels are replaced by opts.nan_as or throw "<path>: ... NaN or infinite (first at index
  /// i,j,k) ..." with the volume's index. Thread-safe.
  ScalarGrid read(const std::array<std::int64_t, 3>& lo, const std::array<std::int64_t, 3>& hi) const;

  struct Impl;  ///< formats/volume_reader.cpp

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace mlfe
