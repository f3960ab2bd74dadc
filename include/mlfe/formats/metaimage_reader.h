// MetaImage (.mha with the data in the same file, .mhd with a separate data file).
#pragma once
#include <mlfe/core/field/scalar_grid.h>
#include <mlfe/formats/raw_reader.h>
#include <mlfe/formats/volume_read_options.h>

#include <string>

namespace mlfe {

/// Reads a 2D or 3D scalar MetaImage: ElementType MET_UCHAR, MET_CHAR, MET_USHORT, MET_SHORT,
/// MET_UINT, MET_INT, MET_FLOAT, MET_DOUBLE; ElementDataFile LOCAL or one file name relative
/// to the header; ElementByteOrderMSB / BinaryDataByteOrderMSB; CompressedData (zlib);
/// HeaderSize (-1: data at the end of the data file); ElementSpacing (or ElementSize),
/// Offset/Origin/Position and TransformMatrix/Rotation/Orientation (listed axis by axis, as
/// ITK writes it). MetaImage coordinates are ITK's, so ScalarGrid::space is "LPS".
/// Throws mlfe::Error for a bad header, unsupported types or channels, size mismatches,
/// truncated data and corrupt compressed data.
ScalarGrid read_metaimage(const std::string& path, const VolumeReadOptions& opts);

/// read_metaimage's header checks (all but the memory limit) without reading the voxels: where
/// they lie (zlib-packed with CompressedData, to be inflated to exactly the voxels' bytes),
/// their byte order and the frame read_metaimage gives.
RawLayout metaimage_layout(const std::string& path, const VolumeReadOptions& opts);

}  // namespace mlfe
