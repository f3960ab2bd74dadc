// Grey PNG height fields (8 or 16 bit) via libpng.
#pragma once
#include <mlfe/core/field/scalar_grid.h>
#include <mlfe/formats/volume_read_options.h>

#include <string>

namespace mlfe {

/// Reads a PNG as a 2D grid (nz = 1, unit spacing, row j of the image is index j).
/// 16-bit images give uint16 values, 8-bit images uint8; colour images are converted to
/// grey by libpng (noted). Throws mlfe::Error for bad or truncated PNG data and images
/// larger than the memory limit.
ScalarGrid read_png(const std::string& path, const VolumeReadOptions& opts);

/// Throws mlfe::Error unless `bytes` (the whole file `path`) is a PNG signature and a chain of
/// chunks that lie within the file and end with IEND and nothing after it. libpng stops reading
/// once it has the pixels, so a file cut after the image data would otherwise read as whole.
/// The image data must also decode to at least the pixels IHDR declares: libpng allocates
/// what IHDR claims before it finds the data short.
void check_png_chunks(const std::string& path, const std::string& bytes);

}  // namespace mlfe
