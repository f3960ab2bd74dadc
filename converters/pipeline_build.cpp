// mlfe::pipeline::build (`mlfe build`): a volume or tetrahedral mesh to a hierarchy file whose
// values are quantized (or bounded by max_error), the error figures measured from exactly what a
// reader decodes, and the JSON report.
#include <fmt/format.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/base/usage_error.h>
#include <mlfe/core/fem/hierarchy_resample.h>
#include <mlfe/formats/atomic_file.h>
#include <mlfe/formats/hierarchy_levels.h>
#include <mlfe/pipeline.h>
#include <mlfe/version.h>

#include <chrono>
#include <cmath>
#include <functional>
#include <limits>
#include <optional>

#include "converters/label_hierarchy.h"
#include "converters/progress_reporter.h"

namespace mlfe::pipeline {
namespace {

// How max_error E is split: the build refines until every sample is within `tolerance` of
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

ErrorSplit split_max_error(const BuildFileOptions& s, const ScalarGrid& grid) {
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
double value_bound(const BuildFileOptions& s, double rms, double range) {
  if (s.psnr > 0) return std::sqrt(3.0) * (range > 0 ? range : 1.0) * std::pow(10.0, -s.psnr / 20.0);
  return rms > 0 ? 0.5 * rms : 1e-3 * (range > 0 ? range : 1.0);
}

// Errors of the decoded values (the function linear on every leaf) against the input.
template <int D>
using Measure = std::function<GridErrors(const Hierarchy<D>&, const std::vector<double>&)>;

// What one write needs besides the approximation.
struct FileJob {
  const std::string& input;
  const std::string& output;
  const BuildFileOptions& options;
  const ErrorSplit* split;
  nlohmann::json input_metadata;
};

// The values a reader decodes, quantized to the file's bound (wo: how the file is written).
template <int D>
std::vector<double> decoded_values(const FileJob& job, const Approximation<D>& a,
                                   const LevelDescription<D>& levels, const HierarchyFileInfo& info,
                                   const HierarchyWriteOptions& wo) {
  try {
    return wo.residual_quantization ? residual_quantized_values(a.hierarchy, levels, a.values, info, wo)
           : wo.integer_values      ? quantize_integer(a.hierarchy, a.values, std::int64_t(wo.max_error))
           : wo.max_error > 0       ? quantize_hierarchical(a.hierarchy, a.values, wo.max_error)
                                    : a.values;
  } catch (const Error& e) {
    throw Error(job.output + ": " + e.what());
  }
}

// The file's header but for the error figures of the decoded values: frame, lattice,
// provenance.
template <int D>
HierarchyFileInfo file_info(const FileJob& job, const Built& b, const Approximation<D>& a) {
  HierarchyFileInfo info;
  info.transform = b.transform;
  info.space = b.space;
  info.value_min = b.value_min;
  info.value_max = b.value_max;
  info.metadata = {{"input", job.input}, {"tool", std::string("mlfe ") + MLFE_VERSION}};
  info.metadata.update(job.input_metadata);
  if (b.surface_driven) info.metadata["refinement"] = "surface-driven";
  info.metadata["build"] = build_record(b);
  // The error-bounded build interpolates: no norm.
  info.norm = job.split ? "" : enum_name(job.options.build.norm);
  set_lattice_info(a, info);
  if (job.split) info.sample_error_bound = job.options.max_error;
  return info;
}

// Writes the v3 file: the build's hierarchy renumbered into its levels' file order first (the
// encoder then needs no second hierarchy), values quantized to the bound, the error figures
// measured against the input (`measure`) from exactly the values a reader decodes.
template <int D>
HierarchyFileFigures write_file(const FileJob& job, const Built& b, Approximation<D>& a,
                                const Measure<D>& measure) {
  HierarchyFileFigures fig;
  const auto t0 = std::chrono::steady_clock::now();
  const double range = b.value_max - b.value_min;
  const double last_rms = b.iterations().empty() ? 0.0 : b.iterations().back().rms_error;
  // Step 1: the file's numbering. The per-leaf errors (not in the file, and in the old leaf
  // order) go first, not to count in the rebuild's peak. The build's hierarchy is freed before
  // its rebuild, so a rebuild that fails (a bug: every refine() history rebuilds) leaves no
  // hierarchy to write in format version 1 instead.
  std::vector<double>().swap(a.leaf_errors);
  LevelDescription<D> levels;
  try {
    levels = renumber_canonically(a.hierarchy, {&a.values, &a.data_values});
  } catch (const LevelRebuildError& e) {
    throw Error(job.output + ": " + e.what() + " (please report this)");
  }
  // Step 2: the decoded values and their errors. An error-bounded build quantizes each level
  // against the prediction its coder chose (as SZ3 does): wide bounds then code most values
  // as 0 where the data is smooth.
  fig.bound = job.split ? job.split->quantization : value_bound(job.options, last_rms, range);
  const bool integer = job.split && job.split->integer;
  fig.coding = integer ? "integer" : fig.bound > 0 ? "quantized" : "exact";
  HierarchyWriteOptions wo;
  wo.version = fig.version;
  wo.max_error = fig.bound;
  wo.integer_values = integer;
  wo.residual_quantization = job.split && fig.bound > 0;
  wo.zstd_level = 19;
  HierarchyFileInfo info = file_info(job, b, a);
  fig.errors = measure(a.hierarchy, decoded_values(job, a, levels, info, wo));
  // The promise of max_error, checked on exactly what a reader decodes, before writing.
  if (job.split && !(fig.errors.max <= job.options.max_error))
    throw OptionInputError(fmt::format(
        "{}: the decoded samples are up to {:.6g} from the input, over {} {:.6g} ({})", job.output,
        fig.errors.max, option_ref("max_error"), job.options.max_error, b.stop_reason()));
  // Step 3: the file.
  info.rms_error = fig.errors.rms;
  info.max_error = fig.errors.max;
  info.psnr_db = fig.errors.psnr;
  write_hierarchy(job.output, a.hierarchy, levels, a.values, info, wo);
  fig.encode_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  fig.bytes = written_file_size(job.output);
  return fig;
}

// Whether rounding a value within E of an integer keeps it within E of that integer: for an
// integer E (it rounds into [x - E, x + E]) and below 1/2 (it rounds to x).
bool rounding_keeps(double e) { return e < 0.5 || e == std::floor(e); }

// The decoded function on the voxel grid against the volume.
// With `integers` (an error-bounded build of integer data at a bound rounding keeps), the
// decoded samples are rounded to integers, as mlfe export writes them: the barycentric weights
// of a sample on a vertex are not exactly 0 and 1 at every spacing (0.8 mm: errors of 1e-14
// beside zero samples), so E = 0 gives the voxels back.
template <int D>
Measure<D> on_grid(const ScalarGrid& grid, const std::string& input, double range, bool integers) {
  return [&grid, input, range, integers](const Hierarchy<D>& h, const std::vector<double>& values) {
    std::vector<float> decoded = resample_to_grid(h, values, grid.dims, grid.transform.spacing);
    if (integers)
      for (float& v : decoded) v = std::nearbyint(v);
    return grid_errors(decoded, grid.values, range, input);
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

// The report: build_report plus the file's figures.
void write_report(const BuildFileOptions& s, const BuildFileResult& r, nlohmann::json report) {
  const HierarchyFileFigures& fig = r.file;
  const char* per = fig.on_voxels ? "voxel" : "point";
  const double bytes = static_cast<double>(fig.bytes);
  report["file"] = {{"bytes", bytes},
                    {std::string("bits_per_") + per, 8 * bytes / fig.samples},
                    {"format_version", fig.version},
                    {"value_coding", fig.coding},
                    {"value_bound", fig.bound},
                    {"errors_at", fig.on_voxels ? "samples (every voxel, from the decoded values)"
                                                : "the mesh's points (from the decoded values)"},
                    {"rms_error", fig.errors.rms},
                    {"max_error", fig.errors.max},
                    {"psnr_db", fig.errors.psnr},
                    {"encode_seconds", fig.encode_seconds}};
  if (s.max_error >= 0)
    report["file"]["max_error_bound"] = {{"max_error", s.max_error},
                                         {"refinement_tolerance", fig.tolerance},
                                         {"quantization_bound", fig.bound},
                                         {"verified", fig.errors.max <= s.max_error}};
  write_json(s.report, report);
}

// Build (0..0.85 of the call), then the file.
BuildOptions with_progress(const BuildFileOptions& s, const detail::Reporter& report) {
  BuildOptions o = s.build;
  if (report) o.fraction_progress = report.share(0, 0.85).as_progress();
  return o;
}

// A tetrahedral mesh input: its P1 interpolant is the input function.
BuildFileResult build_mesh(const std::string& input, const std::string& output, const BuildFileOptions& s,
                           const detail::Reporter& report) {
  const TetMesh mesh = read_tet_mesh(input, tet_mesh_read_options(s.read));
  const TetMeshField f(mesh);
  BuildFileResult r;
  r.built = mlfe::build(f, mesh_input(f, mesh), with_progress(s, report), {});
  const Built& b = r.built;
  report(0.85, "writing");
  FileJob job{
      input,
      output,
      s,
      nullptr,
      {{"points", mesh.points.size()}, {"tetrahedra", mesh.tets.size()}, {"point_data", mesh.value_name}}};
  detail::OutputGuard written;
  r.file = write_file(job, b, r.built.get<3>(), at_mesh_points(mesh, f, b.value_max - b.value_min));
  written.add(output);
  r.file.samples = double(mesh.points.size());
  r.file.on_voxels = false;
  r.written.push_back(output);
  if (!s.report.empty()) {
    nlohmann::json rep = build_report(input, nullptr, b);
    rep.update(job.input_metadata);
    rep["degenerate_tetrahedra"] = f.degenerate_count();
    write_report(s, r, rep);
    r.written.push_back(s.report);
  }
  written.release();
  return r;
}

void check_build_file_options(const std::string& input, const BuildFileOptions& s,
                              const std::string& output) {
  NamedFiles inputs = {{"input", input}};
  if (s.labels)
    inputs.emplace_back(option_ref("label_table"), detail::label_table_file(s.label_table, input));
  check_distinct_files(inputs, {{"output", output}, {"report", s.report}});
  check_output_path(output, {".mlfeh"});
  if (!s.report.empty()) check_output_path(s.report, {});
  check_options(s);
  if (s.max_error >= 0 && s.psnr > 0)
    throw OptionInputError(
        fmt::format("build: give {} or {}, not both", option_ref("max_error"), option_ref("psnr")));
  if (s.labels && (s.max_error >= 0 || s.psnr > 0))
    throw OptionInputError(fmt::format("build: {} stores the labels exactly (no {}, no {})",
                                       option_ref("labels"), option_ref("max_error"), option_ref("psnr")));
  if (!s.labels && !s.label_table.empty())
    throw OptionInputError(
        fmt::format("build: {} needs {}", option_ref("label_table"), option_ref("labels")));
}

}  // namespace

BuildFileResult build(const std::string& input, const std::string& output, const BuildFileOptions& options) {
  check_build_file_options(input, options, output);
  const detail::Reporter report(options.progress);
  report(0, "reading");
  BuildFileOptions s = options;
  // The readers refuse, before allocating, a volume over the budget the build keeps to.
  if (s.read.max_bytes == 0) s.read.max_bytes = s.build.max_memory.bytes();
  if (!detect_tet_mesh_format(input).empty()) {
    if (s.labels)
      throw OptionInputError(input + ": " + option_ref("labels") +
                             " needs a volume (a label map), not a mesh");
    if (s.max_error >= 0)
      throw OptionInputError(
          fmt::format("{}: {} bounds the error at a volume's samples; for a mesh use {} or {}", input,
                      option_ref("max_error"), option_ref("rms"), option_ref("psnr")));
    BuildFileResult r = build_mesh(input, output, s, report);
    report.finish("writing");
    return r;
  }
  const ScalarGrid grid = read_volume(input, s.read);
  BuildFileResult r;
  nlohmann::json meta = {{"dims", grid.dims}, {"source_type", scalar_type_name(grid.source_type)}};
  if (s.labels) {
    // A label map is stored exactly: integer values at bound 0 (integer surpluses), leaves
    // refined until every sample is within a quarter of a label step of the interpolant (so
    // rounding the decoded samples gives the labels; 0 would fail on the last bits of the
    // barycentric coordinates at non-integer spacings).
    meta["labels"] = detail::label_metadata(grid, s.label_table, r.warnings);
    s.max_error = detail::kLabelSampleBound;
    s.quantization_share = 0;
  }
  std::optional<ErrorSplit> split;
  BuildOptions o = with_progress(s, report);
  if (s.max_error >= 0) {
    split = split_max_error(s, grid);
    o.max_sample_error = split->tolerance;
  }
  r.max_error = s.max_error;
  r.built = mlfe::build(grid, o, {});
  const Built& b = r.built;
  report(0.85, "writing");
  const double range = b.value_max - b.value_min;
  FileJob job{input, output, s, split ? &*split : nullptr, meta};
  detail::OutputGuard written;
  const bool integers = split && split->integer && rounding_keeps(s.max_error);
  r.file = b.dim() == 2 ? write_file(job, b, r.built.get<2>(), on_grid<2>(grid, input, range, integers))
                        : write_file(job, b, r.built.get<3>(), on_grid<3>(grid, input, range, integers));
  if (split) r.file.tolerance = split->tolerance;
  r.file.samples = static_cast<double>(grid.voxel_count());
  r.written.push_back(output);
  written.add(output);
  if (!s.report.empty()) {
    write_report(s, r, build_report(input, &grid, b));
    r.written.push_back(s.report);
  }
  written.release();
  report.finish("writing");
  return r;
}

}  // namespace mlfe::pipeline
