// mlfe render: ray-cast EXR images of a hierarchy (.mlfeh), a volume (built first with the
// same defaults as mlfe build) or an unstructured tetrahedral mesh (.vtu/.msh, as it is), face
// to face through the tetrahedra; the work is mlfe::pipeline::render.
#include <fmt/format.h>
#include <mlfe/pipeline.h>

#include <cstdio>
#include <memory>

#include "converters/cli/commands.h"
#include "converters/cli/render_command.h"
#include "converters/cli/volume_options.h"

namespace mlfe::cli {

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
  pipeline::RenderFileOptions render;
  BuildParams build;
  VolumeReadOptions read;
};

void run_render(const RenderState& s) {
  pipeline::RenderFileOptions o = s.render;
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
  add_fields(cmd, pipeline::render_fields(), state->render);
  add_build_options(cmd, state->build);
  add_volume_read_options(cmd, state->read);
  cmd->callback([state] { run_render(*state); });
}

}  // namespace

MLFE_REGISTER_COMMAND(45, add_render_command);

}  // namespace mlfe::cli
