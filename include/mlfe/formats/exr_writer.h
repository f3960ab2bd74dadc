// Rendered images out: OpenEXR (half RGBA, linear, premultiplied alpha, float Z) through the
// OpenEXR library, and an sRGB PNG preview through libpng.
//
// EXR layout: channels A, B, G, R (HALF) and Z (FLOAT), ZIP compression, scanlines top to
// bottom. Header attributes: worldToCamera and worldToNDC (OpenEXR standard attributes; Imath
// row-vector convention, p' = p · M), and string attributes given by the caller (mlfe writes
// the transfer function, the source and the Z convention).
#pragma once
#include <mlfe/core/render/volume_render.h>

#include <array>
#include <string>
#include <utility>
#include <vector>

namespace mlfe {

struct ExrAttributes {
  std::array<double, 16> world_to_camera{};  ///< row-major, column vectors (Camera)
  std::array<double, 16> world_to_ndc{};
  std::vector<std::pair<std::string, std::string>> strings;
};

/// Writes `img` to `path` atomically. The bytes depend only on the arguments. Throws
/// mlfe::Error ("<path>: <problem>") when the file cannot be written (nothing left behind).
void write_exr(const std::string& path, const RenderImage& img, const ExrAttributes& attributes);

/// Writes an 8-bit sRGB PNG of `img` composited over `background` (linear RGB) atomically.
void write_png_preview(const std::string& path, const RenderImage& img,
                       const std::array<double, 3>& background);

}  // namespace mlfe
