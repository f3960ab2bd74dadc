// OpenVDB volumes (.vdb): level sets, fog volumes and other scalar grids.
#pragma once
#include <mlfe/core/field/scalar_grid.h>
#include <mlfe/formats/volume_read_options.h>

#include <string>
#include <vector>

namespace mlfe {

/// Reads one grid of an OpenVDB file into a dense grid over its active-voxel bounding box.
/// The grid is opts.grid_name, or by default the first scalar grid (float, double; int32,
/// int64 and bool are converted with a note). Vector grids are an error unless
/// opts.vec_magnitude, which reads their length. Voxels inside the box that are not active
/// keep the value the tree stores for them: the background, or -background inside a level
/// set, so signed distances keep their sign. The transform must be linear (affine); the voxel
/// at the box's minimum corner becomes index (0,0,0). ScalarGrid::space is "" (VDB does not say).
/// Throws mlfe::Error for bad magic, unreadable files, missing or empty grids, non-linear
/// transforms and boxes larger than the memory limit.
ScalarGrid read_vdb(const std::string& path, const VolumeReadOptions& opts);

/// "name (type, class)" for every grid in the file, for `mlfe info`. Throws like read_vdb.
std::vector<std::string> list_vdb_grids(const std::string& path);

}  // namespace mlfe
