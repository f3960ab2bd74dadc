// mlfe render (and convert --render): the command line's options of mlfe::pipeline::render, and
// what it prints.
#pragma once
#include <CLI/CLI.hpp>
#include <string>

#include "converters/cli/pipeline_options.h"

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

/// The typed options of `p` (mlfe::pipeline::RenderFileOptions; build, read and progress left
/// at their defaults); throws mlfe::UsageError on bad text (--size, --position, ...).
pipeline::RenderFileOptions render_options(const RenderParams& p);

/// The render mesh and one line per frame on stderr (unless quiet), then the written files on
/// stdout.
void print_render(const pipeline::RenderResult& r, bool quiet);

}  // namespace mlfe::cli
