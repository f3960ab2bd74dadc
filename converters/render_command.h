// mlfe render (and convert --render): ray-cast images of a hierarchy or a volume, written as
// OpenEXR (half RGBA premultiplied, float Z) with an optional sRGB PNG preview.
#pragma once
#include <CLI/CLI.hpp>
#include <string>

#include "converters/pipeline_options.h"

namespace mlfe::cli {

struct RenderParams {
  std::string tf = "grey";       ///< preset name or a ParaView .json export
  double tf_unit = 0;            ///< opacity unit length (mm); 0: one voxel (presets), 1 (JSON)
  std::string camera = "ortho";  ///< "ortho" or "perspective"
  double azimuth = 0, elevation = 0;
  std::string position, target, up;  ///< "x,y,z" in the physical frame (override the orbit)
  std::string size = "500x500";
  int level = -1;
  bool reference = false;
  std::string integration = "preintegrated";  ///< or "trapezoid"
  bool shading = false;
  bool no_skip = false;
  std::string png;
  int frames = 1;
  std::string background = "0,0,0";
  double stop_opacity = 0.99;
  double z_opacity = 0.5;
};

/// Adds the rendering options (everything but input and output) to `cmd`.
void add_render_options(CLI::App* cmd, RenderParams& p);

/// Renders `b` (or, with p.reference, `grid`, which is then required) to `out` (.exr), and the
/// PNG preview when asked; with p.frames > 1 a turntable of numbered files OUT_0000.exr, …
/// Throws mlfe::Error for bad options or unwritable files. Prints one line per frame to stderr
/// unless quiet. Returns the written files.
std::vector<std::string> render_outputs(const std::string& out, const RenderParams& p, const Built& b,
                                        const ScalarGrid* grid, const std::string& source, bool quiet);

}  // namespace mlfe::cli
