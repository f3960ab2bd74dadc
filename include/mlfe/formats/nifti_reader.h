// NIfTI-1 and NIfTI-2 (.nii, .nii.gz, .hdr+.img, also Analyze 7.5 pairs) via libnifti2.
#pragma once
#include <mlfe/core/field/scalar_grid.h>
#include <mlfe/formats/raw_reader.h>
#include <mlfe/formats/volume_read_options.h>

#include <string>

namespace mlfe {

/// Reads a NIfTI image of type uint8..float64 (either byte order; gzip through znz).
/// scl_slope/scl_inter are applied when slope is non-zero and not the identity. The transform
/// is the sform when sform_code > 0, else the qform when qform_code > 0 (space "RAS"), else
/// pixdim spacing with origin 0 (space ""). Images with more than 3 dimensions yield their
/// first 3D volume (noted). The header is checked (dims, type, data size against the file
/// size and the memory limit) before any voxel memory is allocated; libnifti's messages are
/// silenced and its failures become mlfe::Error.
ScalarGrid read_nifti(const std::string& path, const VolumeReadOptions& opts);

/// read_nifti's header checks (all but the memory limit) without reading the voxels: where they
/// lie (the .nii, or the .img of a pair; gzip-packed for a .gz), their byte order, the scaling
/// and the frame read_nifti gives.
RawLayout nifti_layout(const std::string& path, const VolumeReadOptions& opts);

}  // namespace mlfe
