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

/// True when VolumeWindows reads `path` box by box from the file, false when it would read it
/// whole: true for OME-Zarr stores, raw volumes, NIfTI, MetaImage, and NRRD with raw or gzip data
/// (nrrd_layout). Reads the header only; throws as read_volume does for a bad one.
bool reads_in_windows(const std::string& path, const VolumeReadOptions& opts);

/// A volume opened for reading box by box (`mlfe convert --bricks`): its frame at once, its
/// samples window by window. What reads_in_windows accepts is read box by box from the file
/// (only a window's voxels in memory): OME-Zarr by chunks; raw, NIfTI, NRRD and MetaImage data
/// by file offsets (read_raw_box on the header's RawLayout), their compressed data (.nii.gz,
/// NRRD gzip, MetaImage CompressedData) decoded once, by the first read, into an unlinked
/// temporary file (unpack_raw: disk, not memory) that the boxes are read from. The other
/// formats are read whole once and their windows copied from memory. A window holds the values
/// read_volume would give there.
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
  /// i,j,k) ..." with the volume's index. Data found bad only now (truncated or corrupt
  /// compressed data, a file that shrank) throws read_volume's one line; a bad compressed stream
  /// throws again at every later read. Thread-safe.
  ScalarGrid read(const std::array<std::int64_t, 3>& lo, const std::array<std::int64_t, 3>& hi) const;

  struct Impl;  ///< formats/volume_reader.cpp

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace mlfe
