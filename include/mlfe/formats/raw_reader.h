// Headerless raw volumes described by a JSON sidecar (FILE.json) or by command-line flags, and the
// reading of any volume whose voxels lie in a file as raw data does (RawLayout).
#pragma once
#include <mlfe/core/field/scalar_grid.h>
#include <mlfe/formats/safe_read.h>
#include <mlfe/formats/volume_read_options.h>

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>

namespace mlfe {

/// Reads raw voxels at `path`. The sidecar "<path>.json" (or the path with its extension
/// replaced by .json) holds {"dims":[nx,ny(,nz)], "dtype":"float32", "endian":"little",
/// "spacing":[..], "origin":[..], "offset":0, "direction":[9 numbers, row-major],
/// "space":"RAS"|"LPS"}; dims and dtype are required unless given in opts (raw_*), which
/// override the sidecar. The file size must equal offset + voxel bytes exactly.
/// Throws mlfe::Error naming the data file or the sidecar and the problem.
ScalarGrid read_raw(const std::string& path, const VolumeReadOptions& opts);

/// Where a volume's voxels lie in a file and how they become read_volume's values: the layout a
/// raw sidecar describes, and the one NIfTI, NRRD and MetaImage headers describe
/// (nifti_layout, nrrd_layout, metaimage_layout), so that VolumeWindows reads all of them box by
/// box the same way (read_raw_box).
struct RawLayout {
  /// The grid's frame without values (dims, transform, space, source_type, notes).
  ScalarGrid frame;
  /// The file that holds the voxels, or their compressed stream.
  std::string data_file;
  /// The first voxel's byte: in data_file, or in the decoded stream when `packing` is set.
  std::uint64_t offset = 0;
  /// Whether multi-byte values are in the other byte order than the host's.
  bool swap = false;
  /// Set when the voxels are compressed: the stream of this kind that starts at byte packed_at
  /// of data_file (and runs to the file's end).
  std::optional<Compression> packing;
  std::uint64_t packed_at = 0;
  /// Whether the decoded stream must end with the last voxel (MetaImage); else the rest of it
  /// is ignored (further NIfTI volumes).
  bool packed_exactly = false;
  /// Values become value * slope + inter when set (NIfTI scl_slope and scl_inter).
  std::optional<std::array<double, 2>> scaling;
};

/// The bytes of the layout's voxels as stored (decoded, for a packed layout), overflow-checked.
std::uint64_t stored_bytes(const std::string& path, const RawLayout& layout);

/// Throws as check_memory when the stored voxels and their float32 grid together exceed the
/// memory limit of `opts`: what a reader that holds both at once needs (`what` names them).
void check_memory_for_copy(const std::string& path, const RawLayout& layout, const VolumeReadOptions& opts,
                           const std::string& what);

/// read_raw's checks (sidecar, flags, the file's exact size) without reading the voxels.
RawLayout raw_layout(const std::string& path, const VolumeReadOptions& opts);

/// The voxels [lo, hi) (inside the frame's dims; CHECK) of the volume `layout` describes,
/// converted to float (and scaled), x fastest, into dst, read from `data`: layout.data_file, or
/// for a packed layout the decoded stream (unpack_raw). Reads only those voxels' rows (several
/// threads may read one file at once). Throws "<data's path>: truncated ..." when the file ends
/// early, and as scale_values when the scaling overflows.
void read_raw_box(const RegularFile& data, const RawLayout& layout, const std::array<std::int64_t, 3>& lo,
                  const std::array<std::int64_t, 3>& hi, float* dst);

/// The decoded stream of the packed layout `layout` up to its last voxel, decoded once in pieces
/// of 1 MB into a scratch file (RegularFile::scratch, named `path`), so that read_raw_box reads
/// boxes of it at random: memory stays bounded by the pieces, whatever the volume's size; the
/// disk holds the decoded voxels until the file is destroyed. Throws "<path>: truncated
/// compressed data (N of M bytes)" when the stream ends early, "<path>: compressed data does not
/// inflate to the M bytes of the dimensions" when a layout that must end there holds more, and
/// "<path>: corrupt compressed data (...)".
std::unique_ptr<RegularFile> unpack_raw(const std::string& path, const RawLayout& layout);

/// Applies layout.scaling to the n values at v (NaN stays NaN). Throws "<path>: scl_slope S and
/// scl_inter I take the value V to W, which overflows a float" for a finite value that would
/// become infinite.
void scale_values(const std::string& path, const RawLayout& layout, float* v, std::size_t n);

/// Reads n values of type t from `in`'s read position in chunks (so no second full-size buffer
/// is needed), swapping bytes when `swap`, into dst. Throws "<path>: truncated ..." when the
/// file ends early.
void read_raw_values(const std::string& path, RegularFile& in, ScalarType t, bool swap, float* dst,
                     std::size_t n);

}  // namespace mlfe
