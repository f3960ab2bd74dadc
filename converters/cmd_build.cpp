// mlfe build: volume or tetrahedral mesh → adaptive hierarchy (.mlfeh) + JSON report.
#include <fmt/format.h>
#include <mlfe/core/error.h>
#include <mlfe/formats/atomic_file.h>
#include <mlfe/formats/hierarchy_levels.h>
#include <mlfe/formats/hierarchy_resample.h>
#include <mlfe/version.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <functional>
#include <limits>
#include <memory>
#include <optional>

#include "converters/commands.h"
#include "converters/label_hierarchy.h"
#include "converters/pipeline_options.h"
#include "converters/volume_options.h"

namespace mlfe::cli {
namespace {

struct BuildState {
  std::string input, output, report;
  BuildParams params;
  VolumeReadOptions read;
  /// --max-error: every sample of the decoded file within this (data units); < 0: not given.
  double max_error = -1;
  /// Share of max_error spent on quantizing the values; the rest bounds the interpolation.
  double quantization_share = 0.5;
  double psnr = 0;          ///< quantization error alone at this PSNR (dB over the value range)
  bool labels = false;      ///< --labels: a label map, stored losslessly with its table
  std::string label_table;  ///< --label-table (default: the table beside the volume)
};

// --labels: the labels checked (label_grid: bad input before any output) and the table to
// store (label_hierarchy.h): the named one, else the one beside the volume when it parses.
nlohmann::json label_metadata(const BuildState& s, const ScalarGrid& grid) {
  const LabelGrid lg = label_grid(grid);
  LabelTable table;
  if (!s.label_table.empty()) {
    table = read_label_table(s.label_table);
  } else if (const std::string found = find_label_table(grid.source); !found.empty()) {
    try {
      table = read_label_table(found);
    } catch (const Error& e) {
      std::fprintf(stderr, "mlfe: warning: %s (found beside the volume; not used)\n", e.what());
    }
  }
  return stored_label_table(table, label_counts(lg));
}

// How --max-error E is split: the build refines until every sample is within `tolerance` of
// the interpolant of the samples at the vertices, and the values are quantized within
// `quantization`, so every decoded sample is within tolerance + quantization ≤ E (the decoded
// interpolant is a convex combination of decoded vertex values). Integer data keeps integer
// values: an integer quantization bound (0 for E < 1/share: lossless values).
struct ErrorSplit {
  double tolerance = 0, quantization = 0;
  bool integer = false;
};

bool integral_values(const ScalarGrid& g) {
  for (float v : g.values)
    if (!(std::fabs(v) <= 1073741824.0f) || v != std::nearbyint(v)) return false;
  return true;
}

ErrorSplit split_max_error(const BuildState& s, const ScalarGrid& grid) {
  ErrorSplit e;
  e.integer = integral_values(grid);
  if (e.integer) {
    e.quantization = std::floor(s.quantization_share * s.max_error);
    e.tolerance = s.max_error - e.quantization;
    return e;
  }
  // The exported grid is float32: keep a margin for rounding the decoded values to it.
  double big = 0;
  for (float v : grid.values) big = std::max(big, double(std::fabs(v)));
  const double budget = std::max(0.0, s.max_error - big * std::ldexp(1.0, -22));
  e.quantization = s.quantization_share * budget;
  e.tolerance = budget - e.quantization;
  return e;
}

// The file's value bound E. Uniform quantization to steps of 2E adds at most E/√3 RMS; the
// default E = RMS/2 thus adds at most ~4 % to the approximation's RMS error while most
// surpluses round to 0.
double value_bound(const BuildState& s, double rms, double range) {
  if (s.psnr > 0) return std::sqrt(3.0) * (range > 0 ? range : 1.0) * std::pow(10.0, -s.psnr / 20.0);
  return rms > 0 ? 0.5 * rms : 1e-3 * (range > 0 ? range : 1.0);
}

struct FileFigures {
  GridErrors errors;
  double bound = 0;
  double encode_seconds = 0;
  int version = 3;
  std::string coding;    ///< "quantized", "integer", "exact"
  double tolerance = 0;  ///< --max-error: the interpolation's share
};

// Errors of the decoded values (the function linear on every leaf) against the input.
template <int D>
using Measure = std::function<GridErrors(const Hierarchy<D>&, const std::vector<double>&)>;

// Writes the v2 file: values quantized to the bound, the error figures measured against the
// input (`measure`) from exactly the values a reader decodes.
template <int D>
FileFigures write_file(const BuildState& s, const Built& b, const Approximation<D>& a,
                       const Measure<D>& measure, const nlohmann::json& input_metadata,
                       const ErrorSplit* split = nullptr) {
  FileFigures fig;
  const auto t0 = std::chrono::steady_clock::now();
  const double range = b.value_max - b.value_min;
  fig.bound = split ? split->quantization : value_bound(s, b.iterations().back().rms_error, range);
  const bool integer = split && split->integer;
  fig.coding = integer ? "integer" : fig.bound > 0 ? "quantized" : "exact";
  std::vector<double> decoded;
  try {
    decoded = integer                 ? quantize_integer(a.hierarchy, a.values, std::int64_t(fig.bound))
              : fig.coding == "exact" ? a.values
                                      : quantize_hierarchical(a.hierarchy, a.values, fig.bound);
  } catch (const Error& e) {
    throw Error(s.output + ": " + e.what());
  }
  fig.errors = measure(a.hierarchy, decoded);
  // The promise of --max-error, checked on exactly what a reader decodes, before writing.
  if (split && !(fig.errors.max <= s.max_error))
    throw Error(
        fmt::format("{}: the decoded samples are up to {:.6g} from the input, over --max-error {:.6g} ({})",
                    s.output, fig.errors.max, s.max_error, b.stop_reason()));
  HierarchyFileInfo info;
  info.transform = b.transform;
  info.space = b.space;
  info.value_min = b.value_min;
  info.value_max = b.value_max;
  info.metadata = {{"input", s.input}, {"tool", std::string("mlfe ") + MLFE_VERSION}};
  info.metadata.update(input_metadata);
  if (b.surface_driven) info.metadata["refinement"] = "surface-driven";
  info.norm = split ? "" : s.params.norm;  // the error-bounded build interpolates: no norm
  info.rms_error = fig.errors.rms;
  info.max_error = fig.errors.max;
  info.psnr_db = fig.errors.psnr;
  set_lattice_info(a, info);
  if (split) info.sample_error_bound = s.max_error;
  HierarchyWriteOptions wo;
  wo.version = 3;
  wo.max_error = fig.bound;
  wo.integer_values = integer;
  wo.zstd_level = 19;
  try {
    write_hierarchy(s.output, a.hierarchy, a.values, info, wo);
  } catch (const LevelRebuildError& e) {
    std::fprintf(stderr, "mlfe: warning: %s; writing format version 1 (exact, larger)\n", e.what());
    HierarchyFileInfo v1 = info;
    v1.on_lattice = false;
    v1.sample_error_bound = std::numeric_limits<double>::quiet_NaN();
    write_hierarchy(s.output, a.hierarchy, a.values, v1);
    fig.errors = measure(a.hierarchy, a.values);
    fig.bound = 0;
    fig.version = 1;
    fig.coding = "exact";
  }
  fig.encode_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return fig;
}

// The decoded function on the voxel grid against the volume.
template <int D>
Measure<D> on_grid(const ScalarGrid& grid, const std::string& input, double range) {
  return [&grid, input, range](const Hierarchy<D>& h, const std::vector<double>& values) {
    return grid_errors(resample_to_grid(h, values, grid.dims, grid.transform.spacing), grid.values, range,
                       input);
  };
}

// The decoded function at the mesh's points against their values (the leaves located with a
// TetMeshField of their own: it interpolates them exactly, and T0's box starts at 0 like the
// input's local frame).
Measure<3> at_mesh_points(const TetMesh& mesh, const TetMeshField& input, double range) {
  return [&mesh, &input, range](const Hierarchy<3>& h, const std::vector<double>& values) {
    TetMesh leaves = leaf_mesh(h, values);
    leaves.source = mesh.source;
    const TetMeshField u(leaves);
    // Points no tetrahedron uses (a .vtu may carry them) are not samples of the input function.
    std::vector<char> used(mesh.points.size(), 0);
    for (const auto& t : mesh.tets)
      for (std::int32_t v : t) used[static_cast<std::size_t>(v)] = 1;
    std::vector<float> approx, data;
    for (std::size_t i = 0; i < mesh.points.size(); ++i) {
      if (!used[i]) continue;
      std::array<double, 3> local;
      for (int a = 0; a < 3; ++a) local[a] = mesh.points[i][a] - input.origin()[a];
      approx.push_back(static_cast<float>(u.value(local)));
      data.push_back(static_cast<float>(mesh.values[i]));
    }
    return grid_errors(approx, data, range, mesh.source);
  };
}

void report_and_print(const BuildState& s, const Built& b, const FileFigures& fig,
                      const nlohmann::json& report, double samples, const char* per) {
  const double bytes = static_cast<double>(written_file_size(s.output));
  if (!s.report.empty()) {
    nlohmann::json r = report;
    r["file"] = {{"bytes", bytes},
                 {std::string("bits_per_") + per, 8 * bytes / samples},
                 {"format_version", fig.version},
                 {"value_coding", fig.coding},
                 {"value_bound", fig.bound},
                 {"errors_at", std::string(per) == "voxel" ? "samples (every voxel, from the decoded values)"
                                                           : "the mesh's points (from the decoded values)"},
                 {"rms_error", fig.errors.rms},
                 {"max_error", fig.errors.max},
                 {"psnr_db", fig.errors.psnr},
                 {"encode_seconds", fig.encode_seconds}};
    if (s.max_error >= 0)
      r["file"]["max_error_bound"] = {{"max_error", s.max_error},
                                      {"refinement_tolerance", fig.tolerance},
                                      {"quantization_bound", fig.bound},
                                      {"verified", fig.errors.max <= s.max_error}};
    write_json(s.report, r);
  }
  // The closing summary, like convert's: on stderr, unless --quiet.
  const auto& last = b.iterations().back();
  if (!s.params.quiet) {
    std::fprintf(stderr,
                 "mlfe build: %zu vertices, %zu elements, %d levels, RMS %.4g (%.3f%%), PSNR %.2f dB (%s)\n",
                 b.vertices(), b.leaves(), b.levels(), last.rms_error, last.rms_percent, last.psnr_db,
                 b.stop_reason().c_str());
    const bool voxels = std::string(per) == "voxel";
    std::fprintf(stderr,
                 "mlfe build: file %.0f bytes (%.3f bits/%s), values within %.4g; "
                 "%s RMS %.4g, max %.4g, PSNR %.2f dB\n",
                 bytes, 8 * bytes / samples, per, fig.bound,
                 voxels ? "on the voxels" : "at the mesh's points", fig.errors.rms, fig.errors.max,
                 fig.errors.psnr);
    if (s.max_error >= 0)
      std::fprintf(stderr,
                   "mlfe build: every voxel of the decoded file within %.6g of the input (verified)%s\n",
                   s.max_error, fig.errors.max == 0 ? ": lossless" : "");
  }
  std::printf("%s\n", s.output.c_str());
}

// A tetrahedral mesh input: its P1 interpolant is the input function.
void run_mesh_build(const BuildState& s) {
  const TetMesh mesh = read_tet_mesh(s.input, tet_mesh_read_options(s.read));
  const TetMeshField f(mesh);
  const Built b = build(f, mesh_input(f, mesh), build_options(s.params), {});
  warn_if_memory_limited(b, mesh.source, s.params.max_memory);
  const nlohmann::json meta = {
      {"points", mesh.points.size()}, {"tetrahedra", mesh.tets.size()}, {"point_data", mesh.value_name}};
  const FileFigures fig =
      write_file(s, b, b.get<3>(), at_mesh_points(mesh, f, b.value_max - b.value_min), meta);
  nlohmann::json r = build_report(s.input, nullptr, b);
  r.update(meta);
  r["degenerate_tetrahedra"] = f.degenerate_count();
  report_and_print(s, b, fig, r, double(mesh.points.size()), "point");
}

void run_volume_build(const BuildState& s, const ScalarGrid& grid, const nlohmann::json& meta);
void run_label_build(const BuildState& s, const ScalarGrid& grid, nlohmann::json meta);

void run_build(const BuildState& s) {
  check_distinct_files({{"input", s.input}}, {{"--output", s.output}, {"--report", s.report}});
  check_output_path(s.output, {".mlfeh"});
  if (!s.report.empty()) check_output_path(s.report, {});
  if (s.max_error >= 0 && s.psnr > 0) throw Error("build: give --max-error or --psnr, not both");
  if (!(s.quantization_share >= 0 && s.quantization_share < 1))
    throw Error("build: --quantization-share must be in [0, 1)");
  if (!detect_tet_mesh_format(s.input).empty()) {
    if (s.labels) throw Error(s.input + ": --labels needs a volume (a label map), not a mesh");
    if (s.max_error >= 0)
      throw Error(s.input +
                  ": --max-error bounds the error at a volume's samples; for a mesh use --rms or --psnr");
    return run_mesh_build(s);
  }
  const ScalarGrid grid = read_volume(s.input, s.read);
  nlohmann::json meta = {{"dims", grid.dims}, {"source_type", scalar_type_name(grid.source_type)}};
  if (s.labels) {
    // A label map is stored exactly: integer values at bound 0 (integer surpluses), leaves
    // refined until every sample is within a quarter of a label step of the interpolant (so
    // rounding the decoded samples gives the labels; 0 would fail on the last bits of the
    // barycentric coordinates at non-integer spacings).
    if (s.max_error >= 0 || s.psnr > 0)
      throw Error("build: --labels stores the labels exactly (no --max-error, no --psnr)");
    return run_label_build(s, grid, meta);
  }
  run_volume_build(s, grid, meta);
}

void run_label_build(const BuildState& s, const ScalarGrid& grid, nlohmann::json meta) {
  meta["labels"] = label_metadata(s, grid);
  BuildState exact = s;
  exact.labels = false;
  exact.max_error = kLabelSampleBound;
  exact.quantization_share = 0;
  run_volume_build(exact, grid, meta);
}

void run_volume_build(const BuildState& s, const ScalarGrid& grid, const nlohmann::json& meta) {
  std::optional<ErrorSplit> split;
  Built b;
  if (s.max_error >= 0) {
    split = split_max_error(s, grid);
    BuildOptions o = build_options(s.params);
    o.max_sample_error = split->tolerance;
    b = build(grid, o, {});
    warn_if_memory_limited(b, grid.source, s.params.max_memory);
  } else {
    b = build_from_grid(grid, s.params, {});
  }
  const double range = b.value_max - b.value_min;
  const ErrorSplit* sp = split ? &*split : nullptr;
  FileFigures fig = b.dim() == 2 ? write_file(s, b, b.get<2>(), on_grid<2>(grid, s.input, range), meta, sp)
                                 : write_file(s, b, b.get<3>(), on_grid<3>(grid, s.input, range), meta, sp);
  if (sp) fig.tolerance = sp->tolerance;
  report_and_print(s, b, fig, build_report(s.input, &grid, b), static_cast<double>(grid.voxel_count()),
                   "voxel");
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
  cmd->add_option("--report", state->report, "JSON report of the build");
  cmd->add_option(
         "--max-error", state->max_error,
         "every sample (voxel) of the decoded file within this of the input (data units; 0 on integer "
         "data: lossless); without it, the least-squares build of --rms with values quantized to half "
         "its RMS error")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--quantization-share", state->quantization_share,
                  "with --max-error: the share of it spent on quantizing values, the rest on interpolation "
                  "(integer data: rounded down to an integer)")
      ->capture_default_str();
  cmd->add_option("--psnr", state->psnr,
                  "value quantization error alone at this PSNR (dB over the value range)")
      ->check(CLI::PositiveNumber);
  cmd->add_flag("--labels", state->labels,
                "a label map: stored exactly (refined where labels meet) with its label table");
  cmd->add_option("--label-table", state->label_table,
                  "with --labels: names and colours to store (default: the table beside the volume)");
  add_build_options(cmd, state->params);
  add_volume_read_options(cmd, state->read);
  cmd->callback([state] {
    apply_memory_budget(state->read, state->params);
    if (!state->label_table.empty() && !state->labels)
      throw CLI::ValidationError("--label-table", "needs --labels");
    run_build(*state);
  });
}

}  // namespace

void write_label_hierarchy(const ScalarGrid& grid, const std::string& input, const std::string& output,
                           const std::string& label_table, const BuildParams& params) {
  BuildState s;
  s.input = input;
  s.output = output;
  s.params = params;
  s.labels = true;
  s.label_table = label_table;
  run_label_build(s, grid, {{"dims", grid.dims}, {"source_type", scalar_type_name(grid.source_type)}});
}

MLFE_REGISTER_COMMAND(30, add_build_command);

}  // namespace mlfe::cli
