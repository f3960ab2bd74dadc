// mlfe render: ray-cast EXR images of a hierarchy (.mlfeh), a volume (built first with the
// same defaults as mlfe build) or an unstructured tetrahedral mesh (.vtu/.msh, as it is), face
// to face through the tetrahedra; the work is mlfe::pipeline::render.
#include <fmt/format.h>
#include <mlfe/formats/transfer_function_io.h>
#include <mlfe/pipeline.h>

#include <cstdio>
#include <memory>

#include "converters/cli/commands.h"
#include "converters/cli/render_command.h"
#include "converters/cli/volume_options.h"

namespace mlfe::cli {

void add_render_options(CLI::App* cmd, RenderParams& p) {
  std::string presets;
  for (const auto& n : transfer_function_presets()) presets += (presets.empty() ? "" : ", ") + n;
  cmd->add_option("--tf", p.tf,
                  "transfer function: a preset (" + presets + ") or a ParaView colour map .json")
      ->capture_default_str();
  cmd->add_option("--tf-unit", p.tf_unit,
                  "length (mm) the opacities refer to (0: one voxel for presets, a mesh's fine edge for "
                  "presets on a .vtu/.msh, 1 for ParaView files)");
  cmd->add_option("--camera", p.camera, "projection")->capture_default_str();
  cmd->add_option("--azimuth", p.azimuth, "degrees about +z (0: looking along +y)");
  cmd->add_option("--elevation", p.elevation, "degrees above the horizontal plane");
  cmd->add_option("--position", p.position, "camera position x,y,z (physical frame; replaces the orbit)");
  cmd->add_option("--target", p.target, "point looked at, x,y,z (default: the volume's centre)");
  cmd->add_option("--up", p.up, "up direction x,y,z (default 0,0,1)");
  cmd->add_option("--size", p.size, "image size WxH")->capture_default_str();
  cmd->add_option(
      "--level", p.level,
      "render the approximation on this hierarchy level (-1: finest); a .mlfeh file is read only up to it");
  cmd->add_flag("--reference", p.reference, "ray-cast the original voxels instead (volume input)");
  cmd->add_option(
         "--integration", p.integration,
         "segment integration: pre-integrated with the tabulated mean transmittance, with the exact one, "
         "or the trapezoid rule")
      ->capture_default_str();
  cmd->add_flag("--shading", p.shading, "shade with the per-tetrahedron gradient (headlight)");
  cmd->add_flag("--no-skip", p.no_skip, "no empty-space skipping");
  cmd->add_option("--png", p.png, "also write an sRGB PNG preview over the background");
  cmd->add_option("--frames", p.frames, "turntable: this many frames around +z, numbered files");
  cmd->add_option("--background", p.background, "PNG background, linear r,g,b in [0,1]")
      ->capture_default_str();
  cmd->add_option("--stop-opacity", p.stop_opacity, "early ray termination")->capture_default_str();
  cmd->add_option("--z-opacity", p.z_opacity, "Z is where the accumulated opacity reaches this")
      ->capture_default_str();
}

pipeline::RenderFileOptions render_options(const RenderParams& p) {
  pipeline::RenderFileOptions o;
  o.tf = p.tf;
  o.tf_unit = p.tf_unit;
  o.camera = pipeline::parse_enum<pipeline::Projection>(p.camera, "camera");
  o.azimuth = p.azimuth;
  o.elevation = p.elevation;
  if (!p.position.empty()) o.position = pipeline::parse_vector3(p.position, "position");
  if (!p.target.empty()) o.target = pipeline::parse_vector3(p.target, "target");
  if (!p.up.empty()) o.up = pipeline::parse_vector3(p.up, "up");
  o.size = pipeline::parse_image_size(p.size, "size");
  o.level = p.level;
  o.reference = p.reference;
  o.integration = pipeline::parse_enum<RayAccumulator::Rule>(p.integration, "integration");
  o.shading = p.shading;
  o.skip_empty = !p.no_skip;
  o.png = p.png;
  o.frames = p.frames;
  o.background = pipeline::parse_vector3(p.background, "background");
  o.stop_opacity = p.stop_opacity;
  o.z_opacity = p.z_opacity;
  return o;
}

void print_render(const pipeline::RenderResult& r, bool quiet) {
  if (!quiet) {
    if (r.tetrahedra > 0)
      status_line(fmt::format(
          "mlfe render: {} tetrahedra on level {}, renderer adds {:.1f} MB ({:.0f} bytes/tetrahedron)",
          r.tetrahedra, r.level, r.mesh_bytes / 1e6, double(r.mesh_bytes) / double(r.tetrahedra)));
    for (const auto& f : r.frames) {
      const RenderStats& st = f.stats;
      status_line(fmt::format(
          "mlfe render: {}x{} in {:.3f} s, {} rays, {} segments, {} skips, {} relocated, {} at the "
          "step bound{} -> {}",
          f.width, f.height, f.seconds, st.rays, st.segments, st.skips, st.relocations, st.step_bound_hits,
          st.reentries ? fmt::format(", {} re-entries", st.reentries) : std::string(), f.exr));
    }
  }
  for (const auto& f : r.written) std::printf("%s\n", f.c_str());
}

namespace {

struct RenderState {
  std::string input, output;
  RenderParams render;
  BuildParams build;
  VolumeReadOptions read;
};

void run_render(const RenderState& s) {
  check_distinct_files({{"input", s.input}, {"--tf", s.render.tf}},
                       {{"--output", s.output}, {"--png", s.render.png}});
  pipeline::RenderFileOptions o = render_options(s.render);
  o.build = build_options(s.build);
  o.read = s.read;
  o.progress = progress_display("mlfe render", s.build.quiet);
  const pipeline::RenderResult r = pipeline::render(s.input, s.output, o);
  warn_if_memory_limited(r.built, s.input, s.build.max_memory);
  print_render(r, s.build.quiet);
}

void add_render_command(CLI::App& app) {
  auto state = std::make_shared<RenderState>();
  CLI::App* cmd = app.add_subcommand(
      "render",
      "Ray-cast EXR image of a hierarchy, a volume or an unstructured tetrahedral mesh (.vtu/.msh), face to "
      "face through the tetrahedra");
  cmd->add_option("input", state->input,
                  "hierarchy (.mlfeh), 3D volume (built first, as mlfe build) or tetrahedral mesh with point "
                  "values (.vtu, .msh; rendered as it is, --grid names the array)")
      ->required();
  cmd->add_option("-o,--output", state->output, "image (.exr; numbered with --frames)")->required();
  add_render_options(cmd, state->render);
  add_build_options(cmd, state->build);
  add_volume_read_options(cmd, state->read);
  cmd->callback([state] { run_render(*state); });
}

}  // namespace

MLFE_REGISTER_COMMAND(45, add_render_command);

}  // namespace mlfe::cli
