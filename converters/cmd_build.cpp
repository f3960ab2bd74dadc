// mlfe build: volume → adaptive hierarchy (.mlfeh) + JSON report.
#include <fmt/format.h>
#include <mlfe/core/error.h>
#include <mlfe/formats/hierarchy_levels.h>
#include <mlfe/formats/hierarchy_resample.h>
#include <mlfe/version.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <memory>

#include "converters/commands.h"
#include "converters/pipeline_options.h"
#include "converters/volume_options.h"

namespace mlfe::cli {
namespace {

struct BuildState {
  std::string input, output, report;
  BuildParams params;
  VolumeReadOptions read;
  double max_error = 0;  ///< value bound of the file (data units); 0: from --psnr or the default
  double psnr = 0;       ///< quantization error alone at this PSNR (dB over the value range)
};

// The file's value bound E. Uniform quantization to steps of 2E adds at most E/√3 RMS; the
// default E = RMS/2 thus adds at most ~4 % to the approximation's RMS error while most
// surpluses round to 0.
double value_bound(const BuildState& s, double rms, double range) {
  if (s.max_error > 0) return s.max_error;
  if (s.psnr > 0) return std::sqrt(3.0) * (range > 0 ? range : 1.0) * std::pow(10.0, -s.psnr / 20.0);
  return rms > 0 ? 0.5 * rms : 1e-3 * (range > 0 ? range : 1.0);
}

struct FileFigures {
  GridErrors errors;
  double bound = 0;
  double encode_seconds = 0;
};

// Writes the v2 file: values quantized to the bound, the error figures measured on the voxel
// grid from exactly the values a reader decodes.
template <int D>
FileFigures write_file(const BuildState& s, const Built& b, const Approximation<D>& a,
                       const ScalarGrid& grid) {
  FileFigures fig;
  const auto t0 = std::chrono::steady_clock::now();
  const double range = b.value_max - b.value_min;
  fig.bound = value_bound(s, b.iterations().back().rms_error, range);
  std::vector<double> decoded;
  try {
    decoded = quantize_hierarchical(a.hierarchy, a.values, fig.bound);
  } catch (const Error& e) {
    throw Error(s.output + ": " + e.what());
  }
  const std::vector<float> approx = resample_to_grid(a.hierarchy, decoded, grid.dims, grid.transform.spacing);
  fig.errors = grid_errors(approx, grid.values, range, s.input);
  HierarchyFileInfo info;
  info.transform = b.transform;
  info.space = b.space;
  info.value_min = b.value_min;
  info.value_max = b.value_max;
  info.metadata = {{"input", s.input},
                   {"tool", std::string("mlfe ") + MLFE_VERSION},
                   {"dims", grid.dims},
                   {"source_type", scalar_type_name(grid.source_type)}};
  if (b.surface_driven) info.metadata["refinement"] = "surface-driven";
  info.norm = s.params.norm;
  info.rms_error = fig.errors.rms;
  info.max_error = fig.errors.max;
  info.psnr_db = fig.errors.psnr;
  HierarchyWriteOptions wo;
  wo.version = 2;
  wo.max_error = fig.bound;
  wo.zstd_level = 19;
  try {
    write_hierarchy(s.output, a.hierarchy, a.values, info, wo);
  } catch (const LevelRebuildError& e) {
    std::fprintf(stderr, "mlfe: warning: %s; writing format version 1 (exact, larger)\n", e.what());
    write_hierarchy(s.output, a.hierarchy, a.values, info);
    fig.errors = grid_errors(resample_to_grid(a.hierarchy, a.values, grid.dims, grid.transform.spacing),
                             grid.values, range, s.input);
    fig.bound = 0;
  }
  fig.encode_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return fig;
}

void run_build(const BuildState& s) {
  check_output_path(s.output, {".mlfeh"});
  if (!s.report.empty()) check_output_path(s.report, {});
  const ScalarGrid grid = read_volume(s.input, s.read);
  if (s.max_error > 0 && s.psnr > 0) throw Error("build: give --max-error or --psnr, not both");
  const Built b = build_from_grid(grid, s.params, {});
  const FileFigures fig =
      b.dim() == 2 ? write_file(s, b, b.get<2>(), grid) : write_file(s, b, b.get<3>(), grid);
  const double bytes = static_cast<double>(std::filesystem::file_size(s.output));
  if (!s.report.empty()) {
    nlohmann::json r = build_report(s.input, &grid, b);
    r["file"] = {{"bytes", bytes},
                 {"bits_per_voxel", 8 * bytes / static_cast<double>(grid.voxel_count())},
                 {"value_bound", fig.bound},
                 {"rms_error", fig.errors.rms},
                 {"max_error", fig.errors.max},
                 {"psnr_db", fig.errors.psnr},
                 {"encode_seconds", fig.encode_seconds}};
    write_json(s.report, r);
  }
  // The closing summary, like convert's: on stderr, unless --quiet.
  const auto& last = b.iterations().back();
  if (!s.params.quiet) {
    std::fprintf(stderr,
                 "mlfe build: %zu vertices, %zu elements, %d levels, RMS %.4g (%.3f%%), PSNR %.2f dB (%s)\n",
                 b.vertices(), b.leaves(), b.levels(), last.rms_error, last.rms_percent, last.psnr_db,
                 b.stop_reason().c_str());
    std::fprintf(stderr,
                 "mlfe build: file %.0f bytes (%.3f bits/voxel), values within %.4g; "
                 "on the voxels RMS %.4g, max %.4g, PSNR %.2f dB\n",
                 bytes, 8 * bytes / static_cast<double>(grid.voxel_count()), fig.bound, fig.errors.rms,
                 fig.errors.max, fig.errors.psnr);
  }
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
  cmd->add_option(
         "--max-error", state->max_error,
         "every stored vertex value within this of the approximation's (data units; default: half the "
         "achieved RMS error)")
      ->check(CLI::PositiveNumber);
  cmd->add_option("--psnr", state->psnr,
                  "value quantization error alone at this PSNR (dB over the value range)")
      ->check(CLI::PositiveNumber);
  add_build_options(cmd, state->params);
  add_volume_read_options(cmd, state->read);
  cmd->callback([state] { run_build(*state); });
}

}  // namespace

MLFE_REGISTER_COMMAND(30, add_build_command);

}  // namespace mlfe::cli
