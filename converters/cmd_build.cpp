// mlfe build: volume → adaptive hierarchy (.mlfeh) + JSON report.
#include <fmt/format.h>

#include <memory>

#include "converters/commands.h"
#include "converters/pipeline_options.h"
#include "converters/volume_options.h"
#include "core/error.h"
#include "mlfe/version.h"

namespace mlfe::cli {
namespace {

struct BuildState {
  std::string input, output, report;
  BuildParams params;
  VolumeReadOptions read;
};

void run_build(const BuildState& s) {
  check_output_path(s.output, {".mlfeh"});
  if (!s.report.empty()) check_output_path(s.report, {});
  const ScalarGrid grid = read_volume(s.input, s.read);
  const Built b = build_from_grid(grid, s.params, {});
  nlohmann::json prov = {{"input", s.input}, {"tool", std::string("mlfe ") + MLFE_VERSION}};
  write_built(s.output, b, prov);
  if (!s.report.empty()) write_json(s.report, build_report(s.input, &grid, b));
  const auto& last = b.iterations().back();
  std::fprintf(stderr, "mlfe build: %zu vertices, %zu elements, %d levels, RMS %.4g (%.3f%%), PSNR %.2f dB (%s)\n",
               b.vertices(), b.leaves(), b.levels(), last.rms_error, last.rms_percent, last.psnr_db,
               b.stop_reason().c_str());
  std::printf("%s\n", s.output.c_str());
}

void add_build_command(CLI::App& app) {
  auto state = std::make_shared<BuildState>();
  CLI::App* cmd = app.add_subcommand(
      "build", "Adaptive L2 (or H1) approximation of a volume on a red-green tetrahedral hierarchy");
  cmd->add_option("input", state->input, "volume or height field (vdb, nrrd, nii, mha, raw+json, pgm, png)")
      ->required();
  cmd->add_option("-o,--output", state->output, "hierarchy file (.mlfeh)")->required();
  cmd->add_option("--report", state->report, "JSON report of the build");
  add_build_options(cmd, state->params);
  add_volume_read_options(cmd, state->read);
  cmd->callback([state] { run_build(*state); });
}

}  // namespace

MLFE_REGISTER_COMMAND(30, add_build_command);

}  // namespace mlfe::cli
