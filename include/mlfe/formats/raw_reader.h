// Headerless raw volumes described by a JSON sidecar (FILE.json) or by command-line flags.
#pragma once
#include <mlfe/core/field/scalar_grid.h>
#include <mlfe/formats/safe_read.h>
#include <mlfe/formats/volume_read_options.h>

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>

namespace mlfe {

/// Reads raw voxels at `path`. The sidecar "<path>.json" (or the path with its extension
/// replaced by .json) holds {"dims":[nx,ny(,nz)], "dtype":"float32", "endian":"little",
/// "spacing":[..], "origin":[..], "offset":0, "direction":[9 numbers, row-major],
/// "space":"RAS"|"LPS"}; dims and dtype are required unless given in opts (raw_*), which
/// override the sidecar. The file size must equal offset + voxel bytes exactly.
/// Throws mlfe::Error naming the data file or the sidecar and the problem.
ScalarGrid read_raw(const std::string& path, const VolumeReadOptions& opts);

/// Where a raw volume's voxels lie: the grid's frame without values (dims, transform, space,
/// source_type, notes), the first voxel's byte offset, and whether bytes are swapped.
struct RawLayout {
  ScalarGrid frame;
  std::uint64_t offset = 0;
  bool swap = false;
};

/// read_raw's checks (sidecar, flags, the file's exact size) without reading the voxels.
RawLayout raw_layout(const std::string& path, const VolumeReadOptions& opts);

/// The voxels [lo, hi) (inside the frame's dims; CHECK) of the raw volume `layout` describes,
/// converted to float, x fastest, into dst. Reads only those voxels' rows. Throws
/// "<path>: truncated ..." when the file ends early.
void read_raw_box(const std::string& path, const RawLayout& layout, const std::array<std::int64_t, 3>& lo,
                  const std::array<std::int64_t, 3>& hi, float* dst);

/// Reads n values of type t from `in`'s read position in chunks (so no second full-size buffer
/// is needed), swapping bytes when `swap`, into dst. Throws "<path>: truncated ..." when the
/// file ends early.
void read_raw_values(const std::string& path, RegularFile& in, ScalarType t, bool swap, float* dst,
                     std::size_t n);

}  // namespace mlfe
