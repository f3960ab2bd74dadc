// Reading images for comparison (mlfe compare): OpenEXR (any channels, read as float) and PNG
// (8/16 bit grey, grey+alpha, RGB, RGBA, values scaled to [0, 1]).
#pragma once
#include <map>
#include <string>
#include <vector>

namespace mlfe {

struct ImageChannel {
  std::string name;           ///< EXR channel name ("R", "Z", "depth.V", ...); PNG: "Y", "A", "R", "G", "B"
  std::string type;           ///< "half", "float", "uint" (EXR) or "uint8" / "uint16" (PNG)
  std::vector<float> values;  ///< width * height, row by row from the top
};

struct Image {
  std::string format;  ///< "exr" or "png"
  int width = 0, height = 0;
  std::vector<ImageChannel> channels;  ///< EXR: alphabetical (the file's order); PNG: file order
  /// Header attributes other than the channel list, "type: value" (EXR); PNG: sample depth,
  /// colour and alpha.
  std::map<std::string, std::string> attributes;
};

/// True when `path` starts with the OpenEXR or the PNG signature.
bool is_image_file(const std::string& path);

/// Reads an EXR (scan-line or tiled, single part, first part of multi-part files, full data
/// window) or PNG file. Throws mlfe::Error ("<path>: <problem>") for unreadable, truncated or
/// unsupported files (deep images).
Image read_image(const std::string& path);

}  // namespace mlfe
