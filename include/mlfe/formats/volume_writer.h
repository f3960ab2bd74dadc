// Float32 voxel grids written in the formats mlfe reads (NIfTI, NRRD, raw + JSON sidecar,
// OpenVDB), keeping the grid's index-to-physical transform, so `mlfe export` output opens in
// other tools in the frame of the data it came from.
#pragma once
#include <mlfe/core/field/scalar_grid.h>

#include <string>

namespace mlfe {

/// Writes grid.values (float32, x fastest) with grid.dims and grid.transform to `path`, in the
/// format its extension names:
///   .nii / .nii.gz  NIfTI-1 (libnifti2), sform and qform = the transform in RAS (an "LPS" grid
///                   is converted: x and y negated), pixdim = spacing;
///   .nrrd           NRRD (Teem), gzip-encoded when Teem has zlib, space "right-anterior-
///                   superior" / "left-posterior-superior" from grid.space (none when empty),
///                   space directions and origin = the transform;
///   .raw            little-endian float32 plus the sidecar "<path>.json" that read_raw reads
///                   (dims, dtype, endian, spacing, origin, direction, space);
///   .vdb            one OpenVDB FloatGrid "density" with every grid voxel active at index
///                   (i, j, k) and the linear transform (world = origin + direction·(ijk .* spacing)).
/// Each file appears whole or not at all (formats/atomic_file.h); for .raw, a failure writing
/// the sidecar removes the data file again. Throws mlfe::Error ("<path>: ...") for an unknown
/// extension, a grid whose value count does not match its dims, or a file that cannot be written.
void write_volume(const std::string& path, const ScalarGrid& grid);

/// True when write_volume knows the extension of `path`.
bool is_volume_output(const std::string& path);

}  // namespace mlfe
