// mlfe export: a hierarchy file's approximation as a voxel grid (NIfTI, NRRD, raw + JSON,
// OpenVDB) on the grid it was built from, or its leaf mesh (VTK .vtu, Gmsh .msh) with the
// values and element levels, in the file's physical frame.
#include <fmt/format.h>
#include <mlfe/formats/file_names.h>
#include <mlfe/pipeline.h>

#include <cstdio>
#include <memory>
#include <string>

#include "converters/cli/commands.h"
#include "converters/cli/pipeline_options.h"
#include "converters/cli/volume_options.h"

namespace mlfe::cli {
namespace {

struct ExportState {
  std::string input, output;
  int level = -1;
};

void run_export(const ExportState& s) {
  pipeline::ExportOptions o;
  o.level = s.level;
  o.progress = progress_display("mlfe export", false);
  const pipeline::ExportResult r = pipeline::export_hierarchy(s.input, s.output, o);
  if (r.mesh)
    status_line(
        fmt::format("mlfe export: {} elements, {} vertices, level {}", r.elements, r.vertices, r.level));
  else
    status_line(fmt::format("mlfe export: {} x {} x {} grid from level {} (resampled in {:.3f} s)", r.dims[0],
                            r.dims[1], r.dims[2], r.level, r.resample_seconds));
  std::printf("%s\n", s.output.c_str());
}

void add_export_command(CLI::App& app) {
  auto state = std::make_shared<ExportState>();
  CLI::App* cmd = app.add_subcommand(
      "export",
      "A hierarchy file's approximation on its voxel grid (.nii.gz .nrrd .raw .vdb) or its leaf mesh "
      "with values and levels (.vtu .msh), in the file's physical frame");
  cmd->add_option("input", state->input, "hierarchy file (.mlfeh)")->required();
  cmd->add_option("-o,--output", state->output,
                  "output (.nii.gz, .nii, .nrrd, .raw + .raw.json, .vdb, .vtu, .msh)")
      ->required();
  cmd->add_option("--level", state->level, "use levels 0..K only (default: all)");
  cmd->callback([state] { run_export(*state); });
}

}  // namespace

MLFE_REGISTER_COMMAND(35, add_export_command);

}  // namespace mlfe::cli
