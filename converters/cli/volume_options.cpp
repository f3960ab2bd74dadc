#include "converters/cli/volume_options.h"

#include <vector>

namespace mlfe::cli {

void add_volume_read_options(CLI::App* cmd, VolumeReadOptions& opts) {
  VolumeReadOptions* o = &opts;
  cmd->add_option("--grid", opts.grid_name,
                  "VDB: name of the grid to read (default: the first scalar grid); .vtu/.msh: the point-data "
                  "array or $NodeData view (default: the first scalar one)");
  cmd->add_flag("--vec-magnitude", opts.vec_magnitude, "VDB: read a vector grid as its magnitude");
  cmd->add_option_function<double>(
      "--nan-as", [o](const double& v) { o->nan_as = v; },
      "replace NaN/Inf voxels by this value (default: NaN/Inf is an error)");
  cmd->add_option("--space", opts.space,
                  "output coordinate convention: ras or lps (flips x and y as needed)");
  cmd->add_option_function<std::vector<std::int64_t>>(
         "--raw-dims",
         [o](const std::vector<std::int64_t>& v) {
           o->raw_dims = std::array<std::int64_t, 3>{v[0], v[1], v.size() > 2 ? v[2] : 1};
         },
         "raw data without sidecar: NX NY [NZ]")
      ->expected(2, 3);
  cmd->add_option("--raw-type", opts.raw_dtype,
                  "raw data type: uint8 int8 uint16 int16 uint32 int32 float32 float64");
  cmd->add_option("--raw-endian", opts.raw_endian, "raw data byte order: little (default) or big");
  cmd->add_option_function<std::vector<double>>(
         "--raw-spacing",
         [o](const std::vector<double>& v) {
           o->raw_spacing = std::array<double, 3>{v[0], v[1], v.size() > 2 ? v[2] : 1.0};
         },
         "raw data: voxel spacing SX SY [SZ]")
      ->expected(2, 3);
  cmd->add_option_function<std::vector<double>>(
         "--raw-origin",
         [o](const std::vector<double>& v) {
           o->raw_origin = std::array<double, 3>{v[0], v[1], v.size() > 2 ? v[2] : 0.0};
         },
         "raw data: physical position of voxel (0,0,0): OX OY [OZ]")
      ->expected(2, 3);
  cmd->add_option("--raw-offset", opts.raw_offset, "raw data: bytes to skip before the voxels");
  cmd->add_option("--zarr-level", opts.zarr_level,
                  "OME-Zarr: the resolution level to read (0: full resolution)");
}

}  // namespace mlfe::cli
