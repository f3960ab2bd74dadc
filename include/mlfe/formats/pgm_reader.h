// Binary PGM (P5) height fields, 8 or 16 bit.
#pragma once
#include <mlfe/core/field/scalar_grid.h>
#include <mlfe/formats/volume_read_options.h>

#include <string>

namespace mlfe {

/// Reads a binary PGM (P5): maxval 1..255 gives uint8, 256..65535 big-endian uint16.
/// Result is a 2D grid (nz = 1) with unit spacing; row j of the file is index j.
/// Throws mlfe::Error for a bad magic or header, maxval out of range, or truncated data.
ScalarGrid read_pgm(const std::string& path, const VolumeReadOptions& opts);

}  // namespace mlfe
