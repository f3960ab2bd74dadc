// Headerless raw volumes described by a JSON sidecar (FILE.json) or by command-line flags.
#pragma once
#include <mlfe/core/field/scalar_grid.h>
#include <mlfe/formats/safe_read.h>
#include <mlfe/formats/volume_read_options.h>

#include <cstddef>
#include <string>

namespace mlfe {

/// Reads raw voxels at `path`. The sidecar "<path>.json" (or the path with its extension
/// replaced by .json) holds {"dims":[nx,ny(,nz)], "dtype":"float32", "endian":"little",
/// "spacing":[..], "origin":[..], "offset":0, "direction":[9 numbers, row-major],
/// "space":"RAS"|"LPS"}; dims and dtype are required unless given in opts (raw_*), which
/// override the sidecar. The file size must equal offset + voxel bytes exactly.
/// Throws mlfe::Error naming the data file or the sidecar and the problem.
ScalarGrid read_raw(const std::string& path, const VolumeReadOptions& opts);

/// Reads n values of type t from `in`'s read position in chunks (so no second full-size buffer
/// is needed), swapping bytes when `swap`, into dst. Throws "<path>: truncated ..." when the
/// file ends early.
void read_raw_values(const std::string& path, RegularFile& in, ScalarType t, bool swap, float* dst,
                     std::size_t n);

}  // namespace mlfe
