// mlfe build: volume or tetrahedral mesh → adaptive hierarchy (.mlfeh) + JSON report.
#include <fmt/format.h>
#include <mlfe/pipeline.h>

#include <cstdio>
#include <memory>

#include "converters/cli/commands.h"
#include "converters/cli/pipeline_options.h"
#include "converters/cli/volume_options.h"

namespace mlfe::cli {
namespace {

struct BuildState {
  std::string input, output;
  BuildParams params;
  pipeline::BuildFileOptions options;
};

// The closing summary, like convert's: on stderr, unless --quiet; the file on stdout.
void print_summary(const BuildState& s, const pipeline::BuildFileResult& r) {
  const Built& b = r.built;
  const pipeline::HierarchyFileFigures& fig = r.file;
  if (!s.params.quiet) {
    const auto& last = b.iterations().back();
    status_line(fmt::format(
        "mlfe build: {} vertices, {} elements, {} levels, RMS {:.4g} ({:.3f}%), PSNR {:.2f} dB ({})",
        b.vertices(), b.leaves(), b.levels(), last.rms_error, last.rms_percent, last.psnr_db,
        b.stop_reason()));
    const double bytes = static_cast<double>(fig.bytes);
    status_line(
        fmt::format("mlfe build: file {:.0f} bytes ({:.3f} bits/{}), values within {:.4g}; {} RMS {:.4g}, "
                    "max {:.4g}, PSNR {:.2f} dB",
                    bytes, 8 * bytes / fig.samples, fig.on_voxels ? "voxel" : "point", fig.bound,
                    fig.on_voxels ? "on the voxels" : "at the mesh's points", fig.errors.rms, fig.errors.max,
                    fig.errors.psnr));
    if (r.max_error >= 0)
      status_line(
          fmt::format("mlfe build: every voxel of the decoded file within {:.6g} of the input (verified){}",
                      r.max_error, fig.errors.max == 0 ? ": lossless" : ""));
  }
  std::printf("%s\n", s.output.c_str());
}

void run_build(BuildState& s) {
  s.options.build = build_options(s.params);
  s.options.progress = progress_display("mlfe build", s.params.quiet);
  const pipeline::BuildFileResult r = pipeline::build(s.input, s.output, s.options);
  warn_if_memory_limited(r.built, s.input, s.params.max_memory);
  print_warnings(r.warnings);
  print_summary(s, r);
}

void add_build_command(CLI::App& app) {
  auto state = std::make_shared<BuildState>();
  CLI::App* cmd = app.add_subcommand(
      "build", "Adaptive L2 (or H1) approximation of a volume on a red-green tetrahedral hierarchy");
  cmd->add_option("input", state->input,
                  "volume or height field (vdb, nrrd, nii, mha, raw+json, pgm, png) or tetrahedral mesh with "
                  "point values (vtu, msh)")
      ->required();
  cmd->add_option("-o,--output", state->output, "hierarchy file (.mlfeh)")->required();
  cmd->add_option("--report", state->options.report, "JSON report of the build");
  cmd->add_option(
      "--max-error", state->options.max_error,
      "every sample (voxel) of the decoded file within this of the input (data units; 0 on integer "
      "data: lossless); without it, the least-squares build of --rms with values quantized to half "
      "its RMS error");
  cmd->add_option("--quantization-share", state->options.quantization_share,
                  "with --max-error: the share of it spent on quantizing values, the rest on interpolation "
                  "(integer data: rounded down to an integer; 1: leaves refined until exact)")
      ->capture_default_str();
  cmd->add_option("--psnr", state->options.psnr,
                  "value quantization error alone at this PSNR (dB over the value range)");
  add_build_options(cmd, state->params);
  cmd->add_flag("--labels", state->options.labels,
                "a label map: stored exactly (refined where labels meet) with its label table");
  cmd->add_option("--label-table", state->options.label_table,
                  "with --labels: names and colours to store (default: the table beside the volume)");
  add_volume_read_options(cmd, state->options.read);
  cmd->callback([state] {
    if (!state->options.label_table.empty() && !state->options.labels)
      throw CLI::ValidationError("--label-table", "needs --labels");
    run_build(*state);
  });
}

}  // namespace

MLFE_REGISTER_COMMAND(30, add_build_command);

}  // namespace mlfe::cli
