#include "converters/pipeline_options.h"

#include <fmt/format.h>
#include <mlfe/core/error.h>
#include <mlfe/core/usage_error.h>

#include <cctype>
#include <cmath>
#include <cstdio>
#include <memory>
#include <sstream>

namespace mlfe::cli {

void add_build_options(CLI::App* cmd, BuildParams& p) {
  cmd->add_option("--rms", p.rms,
                  "target RMS error: a percentage of the value range (\"0.5%\") or an absolute value in data "
                  "units [default: 0.5% without --iso; with --iso, refinement follows the surfaces]");
  cmd->add_option(
         "--threshold", p.threshold,
         "the paper's rule: refine elements whose RMS error exceeds this (data units); replaces --rms")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--max-vertices", p.max_vertices,
                  "vertex budget (never exceeded; at least the coarsest mesh's 8 vertices, 4 for a 2D height "
                  "field) [default: none]")
      ->check(CLI::Validator(
          [](std::string& text) -> std::string {
            return text.find_first_not_of("0123456789") == std::string::npos &&
                           text.find_first_not_of('0') != std::string::npos
                       ? std::string()
                       : "expected a whole number of vertices >= 1 (omit the option for no budget), got '" +
                             text + "'";
          },
          "N"));
  cmd->add_option("--max-level", p.max_level, "deepest refinement level")
      ->check(CLI::Range(0, 40))
      ->capture_default_str();
  cmd->add_option("--start-level", p.start_level,
                  "uniform levels before adapting (-1: until edges <= 16 voxels)")
      ->check(CLI::Range(-1, 12));
  cmd->add_option("--norm", p.norm, "l2 (the paper) or h1: (u,v) + s^2 (grad u, grad v), s = voxel spacing")
      ->check(CLI::IsMember({"l2", "h1"}))
      ->capture_default_str();
  cmd->add_option("--preconditioner", p.preconditioner,
                  "CG preconditioner (auto: Jacobi for least squares at the samples, else BPX)")
      ->check(CLI::IsMember({"auto", "bpx", "jacobi", "none"}))
      ->capture_default_str();
  cmd->add_option("--surface-tolerance", p.surface_tolerance,
                  "with iso-values: refine until surfaces are within this many voxels")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_flag(
      "--check-u", p.check_against_u,
      "surface-driven builds: after the first solve, refine where u's surfaces miss the data's and solve "
      "again (more vertices; u then follows small parts too)");
  cmd->add_option(
         "--max-memory", p.max_memory,
         "memory budget of the build: a percentage of RAM (\"50%\"), bytes with K/M/G, or 0 for none; "
         "refinement stops there with a message")
      ->capture_default_str();
  cmd->add_flag("--quiet", p.quiet, "no progress on stderr");
}

void add_asset_options(CLI::App* cmd, AssetParams& p) {
  cmd->add_option("--iso", p.iso, "iso-values, comma separated (3D volumes)");
  cmd->add_option("--tolerance", p.tolerance,
                  "position tolerance in mm for Draco/quantization (default: voxel/10)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_flag("--no-draco", p.no_draco, "glTF with plain float buffers");
  cmd->add_flag("--quantize", p.quantize, "glTF with KHR_mesh_quantization (with --no-draco)");
  cmd->add_option("--lod", p.lod, "add this many coarser levels from the hierarchy (glTF)")
      ->check(CLI::Range(0, 8));
  cmd->add_option("--decimate", p.decimate,
                  "reduce every surface to this many triangles (OpenMesh quadric decimater)");
  cmd->add_option(
         "--simplify", p.simplify,
         "simplify every surface while it stays within this many voxels of the extracted one (0: the raw "
         "extraction; with --labels: the RMS distance to the smoothed interfaces each merge may reach, "
         "default 0.34)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_option(
         "--simplifier", p.simplifier,
         "--simplify's algorithm: bounded (every extracted vertex verified within the tolerance of the "
         "result, topology kept; ~10 microseconds per triangle), fast (the same collapses and topology "
         "checks, the error estimated from quadrics; about twice as fast), meshopt (meshoptimizer, error "
         "estimated; where it would change the topology the extracted triangles stay) or auto (bounded "
         "for surfaces of up to 200000 extracted triangles, fast above)")
      ->check(CLI::IsMember({"auto", "fast", "bounded", "meshopt"}))
      ->capture_default_str();
  cmd->add_option("--placement", p.placement,
                  "--simplify's vertex placement: input (every vertex stays an extracted one), optimal "
                  "(quadric minimum near the surface: fewer triangles at the same tolerance) or auto "
                  "(optimal, input with --normals gradient)")
      ->check(CLI::IsMember({"auto", "input", "optimal"}))
      ->capture_default_str();
  cmd->add_option(
         "--snap", p.snap,
         "move surface vertices onto the volume's own iso-surface, at most this many voxels "
         "along the approximation's gradient (0: keep the approximation's surface; needs the volume)")
      ->check(CLI::Range(0.0, 8.0))
      ->capture_default_str();
  cmd->add_option("--min-component", p.min_component,
                  "drop connected parts of a surface whose vertices lie in fewer than this many voxels "
                  "(with --labels: pieces of fewer voxels take their surroundings' label; 0: keep every "
                  "part; the report counts what was dropped)")
      ->capture_default_str();
  cmd->add_flag("--normals-toward-higher", p.normals_toward_higher, "normals point toward higher values");
  cmd->add_option("--normals", p.normals,
                  "vertex normals: gradient (the approximation's gradients, the paper's; kept through "
                  "--simplify), surface (area-weighted from the written triangles; smaller Draco files) "
                  "or auto (gradient, surface after --simplify/--decimate)")
      ->check(CLI::IsMember({"auto", "gradient", "surface"}))
      ->capture_default_str();
  cmd->add_option("--z-scale", p.z_scale, "2D height fields: height per data unit")->capture_default_str();
  cmd->add_option("--level", p.level, "extract on this hierarchy level (-1: finest)")
      ->check(CLI::Range(-1, 40));
}

std::vector<double> parse_values(const std::string& text, const std::string& what) {
  std::vector<double> out;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) {
    try {
      std::size_t used = 0;
      const double v = std::stod(item, &used);
      if (used != item.size() || !std::isfinite(v)) throw std::invalid_argument("bad");
      out.push_back(v);
    } catch (const std::exception&) {
      throw UsageError(fmt::format("{}: not a finite number: '{}'", what, item));
    }
  }
  return out;
}

MemoryBudget parse_memory_budget(const std::string& text) {
  std::string t = text;
  MemoryBudget m;
  m.percent_of_ram = false;
  if (!t.empty()) {
    const char c = static_cast<char>(std::toupper(static_cast<unsigned char>(t.back())));
    if (c == '%') m.percent_of_ram = true;
    if (c == 'K') m.unit_power = 1;
    if (c == 'M') m.unit_power = 2;
    if (c == 'G') m.unit_power = 3;
    if (m.percent_of_ram || m.unit_power > 0) t.pop_back();
  }
  std::vector<double> v;
  try {
    v = parse_values(t, "--max-memory");
  } catch (const UsageError&) {
    v.clear();
  }
  if (v.size() != 1 || v[0] < 0 || (m.percent_of_ram && v[0] > 100))
    throw UsageError("--max-memory: expected a percentage of RAM (50%), bytes with K/M/G (6G), or 0; got '" +
                     text + "'");
  m.amount = v[0];
  return m;
}

void apply_memory_budget(VolumeReadOptions& read, const BuildParams& p) {
  const std::size_t budget = parse_memory_budget(p.max_memory).bytes();
  if (budget > 0 && read.max_bytes == 0) read.max_bytes = budget;
}

BuildOptions build_options(const BuildParams& p) {
  BuildOptions o;
  // --threshold replaces --rms, whose text is then not read.
  if (!p.rms.empty() && p.threshold <= 0) {
    std::string r = p.rms;
    const bool percent = r.back() == '%';
    if (percent) r.pop_back();
    const auto v = parse_values(r, "--rms");
    if (v.size() != 1 || v[0] <= 0) throw UsageError("--rms: expected one positive value, e.g. 0.5% or 2.0");
    o.rms = RmsTarget{v[0], percent};
  }
  o.threshold = p.threshold;
  o.max_vertices = p.max_vertices;
  o.max_level = p.max_level;
  o.start_level = p.start_level;
  o.norm = p.norm == "h1" ? Norm::kH1 : Norm::kL2;
  o.preconditioner = p.preconditioner == "auto"     ? Preconditioner::kAuto
                     : p.preconditioner == "bpx"    ? Preconditioner::kBpx
                     : p.preconditioner == "jacobi" ? Preconditioner::kJacobi
                                                    : Preconditioner::kNone;
  o.surface_tolerance = p.surface_tolerance;
  o.check_against_u = p.check_against_u;
  o.max_memory = parse_memory_budget(p.max_memory);
  if (!p.quiet) {
    // The table's header comes with the first row of either kind.
    auto header = std::make_shared<bool>(false);
    auto print_header = [header] {
      if (*header) return;
      *header = true;
      std::fprintf(stderr, "%4s %5s %10s %10s %12s %8s %8s %5s %8s\n", "iter", "level", "vertices",
                   "elements", "rms", "rms%", "psnr", "cg", "seconds");
    };
    o.surface_progress = [print_header](const SurfacePassStats& s) {
      print_header();
      std::fprintf(stderr,
                   "surface pass: %zu vertices, %zu elements, %zu near a surface, %zu refined, %.2f s\n",
                   s.vertices, s.elements, s.candidates, s.marked, s.seconds);
    };
    o.progress = [print_header](const IterationStats& s) {
      print_header();
      std::fprintf(stderr, "%4d %5d %10zu %10zu %12.5g %8.4f %8.2f %5d %8.2f\n", s.iteration, s.level,
                   s.vertices, s.elements, s.rms_error, s.rms_percent, s.psnr_db, s.cg_iterations, s.seconds);
    };
  }
  return o;
}

void warn_if_memory_limited(const Built& b, const std::string& source, const std::string& max_memory) {
  if (b.memory_limited())
    std::fprintf(
        stderr,
        "mlfe: warning: %s: refinement stopped at the memory budget (--max-memory %s, %.0f MiB for the "
        "build); the approximation is coarser than asked\n",
        source.c_str(), max_memory.c_str(), double(b.memory_budget_bytes) / 1048576.0);
}

Built build_from_grid(const ScalarGrid& grid, const BuildParams& p, const std::vector<double>& iso_values) {
  Built b = build(grid, build_options(p), iso_values);
  warn_if_memory_limited(b, grid.source, p.max_memory);
  return b;
}

AssetOptions asset_options(const AssetParams& p) {
  AssetOptions o;
  if (!p.iso.empty()) o.iso = parse_values(p.iso, "--iso");
  o.tolerance = p.tolerance;
  o.draco = !p.no_draco;
  o.quantize = p.quantize;
  o.lod = p.lod;
  o.decimate = p.decimate;
  o.simplify = p.simplify;
  o.simplifier = p.simplifier == "fast"      ? Simplifier::kFast
                 : p.simplifier == "bounded" ? Simplifier::kBounded
                 : p.simplifier == "meshopt" ? Simplifier::kMeshopt
                                             : Simplifier::kAuto;
  o.snap = p.snap;
  o.min_component = p.min_component;
  o.normals_toward_higher = p.normals_toward_higher;
  o.normals = p.normals == "gradient"  ? Normals::kGradient
              : p.normals == "surface" ? Normals::kSurface
                                       : Normals::kAuto;
  o.placement = p.placement == "input"     ? VertexPlacement::kInput
                : p.placement == "optimal" ? VertexPlacement::kOptimal
                                           : VertexPlacement::kAuto;
  o.z_scale = p.z_scale;
  o.level = p.level;
  return o;
}

void add_label_options(CLI::App* cmd, LabelParams& p) {
  p.labels = cmd->add_option("--labels", p.list,
                             "label map: one closed surface per structure (all but 0, or a list like 3,7-9); "
                             "put it after the input")
                 ->expected(0, 1);
  cmd->add_option("--label-table", p.table,
                  "names and colours: MRIcron .txt/.lut, ITK-SNAP, FreeSurfer LUT, Slicer .ctbl, JSON "
                  "(default: the file beside the volume with its stem)");
  cmd->add_option("--smooth-iterations", p.smooth, "with --labels: Taubin smoothing passes (default 20)");
  cmd->add_option("--max-offset", p.max_offset,
                  "with --labels: no vertex moves further from the voxels' interface, voxels (default 0.5)");
  // --simplify is the asset options' (added before); with --labels its default is LabelOptions'.
  p.simplify = cmd->get_option_no_throw("--simplify");
}

LabelOptions label_options(const LabelParams& p, const AssetParams& asset) {
  LabelOptions o;
  if (!p.list.empty()) o.labels = parse_label_list(p.list);
  o.table = p.table;
  o.min_component = asset.min_component;  // one --min-component for iso-surfaces and labels
  o.smoothing_iterations = p.smooth;
  o.max_offset = p.max_offset;
  if (p.simplify == nullptr || p.simplify->count() > 0) o.simplify = asset.simplify;
  o.tolerance = asset.tolerance;
  o.draco = !asset.no_draco;
  o.quantize = asset.quantize;
  o.warn = [](const std::string& w) { std::fprintf(stderr, "mlfe: warning: %s\n", w.c_str()); };
  return o;
}

}  // namespace mlfe::cli
