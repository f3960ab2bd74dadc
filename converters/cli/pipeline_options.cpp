#include "converters/cli/pipeline_options.h"

#include <fmt/format.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/base/usage_error.h>
#include <signal.h>
#include <unistd.h>

#include <atomic>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <sstream>

namespace mlfe::cli {

void add_build_options(CLI::App* cmd, BuildParams& p) {
  cmd->add_option("--rms", p.rms,
                  "target RMS error: a percentage of the value range (\"0.5%\") or an absolute value in data "
                  "units [default: 0.5% without --iso; with --iso, refinement follows the surfaces]");
  cmd->add_option(
      "--threshold", p.threshold,
      "the paper's rule: refine elements whose RMS error exceeds this (data units); replaces --rms");
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
  cmd->add_option("--max-level", p.max_level, "deepest refinement level")->capture_default_str();
  cmd->add_option("--start-level", p.start_level,
                  "uniform levels before adapting (-1: until edges <= 16 voxels)");
  cmd->add_option("--norm", p.norm, "l2 (the paper) or h1: (u,v) + s^2 (grad u, grad v), s = voxel spacing")
      ->capture_default_str();
  cmd->add_option("--preconditioner", p.preconditioner,
                  "CG preconditioner (auto: Jacobi for least squares at the samples, else BPX)")
      ->capture_default_str();
  cmd->add_option("--surface-tolerance", p.surface_tolerance,
                  "with iso-values: refine until surfaces are within this many voxels")
      ->capture_default_str();
  cmd->add_flag(
      "--check-u", p.check_against_u,
      "surface-driven builds: after the first solve, refine where u's surfaces miss the data's and solve "
      "again (more vertices; u then follows small parts too)");
  cmd->add_option(
         "--max-memory", p.max_memory,
         "memory budget of the build: a percentage of RAM (\"50%\"), bytes with K/M/G, or 0 for none; "
         "refinement stops there with a message (with --labels: a label map whose interfaces would not "
         "fit is refused before they are built)")
      ->capture_default_str();
  cmd->add_flag("--quiet", p.quiet, "no progress on stderr");
}

void add_asset_options(CLI::App* cmd, AssetParams& p) {
  cmd->add_option("--iso", p.iso, "iso-values, comma separated (3D volumes)");
  cmd->add_option("--tolerance", p.tolerance,
                  "position tolerance in mm for Draco/quantization (default: voxel/10)");
  cmd->add_flag("--no-draco", p.no_draco, "glTF with plain float buffers");
  cmd->add_flag("--quantize", p.quantize, "glTF with KHR_mesh_quantization (with --no-draco)");
  cmd->add_option("--lod", p.lod, "add this many coarser levels from the hierarchy (glTF)");
  cmd->add_option("--decimate", p.decimate,
                  "reduce every surface to this many triangles (OpenMesh quadric decimater)");
  cmd->add_option(
         "--simplify", p.simplify,
         "simplify every surface while it stays within this many voxels of the extracted one (0: the raw "
         "extraction; with --labels: the RMS distance to the smoothed interfaces each merge may reach, "
         "default 0.34)")
      ->capture_default_str();
  cmd->add_option("--ratio", p.ratio,
                  "--simplify stops at this fraction of each extracted surface's triangles, or earlier where "
                  "its bound binds (0: the bound alone; iso-surfaces)")
      ->capture_default_str();
  cmd->add_option(
         "--simplifier", p.simplifier,
         "--simplify's algorithm: bounded (every extracted vertex verified within the tolerance of the "
         "result, topology kept; ~10 microseconds per triangle), fast (the same collapses and topology "
         "checks, the error estimated from quadrics; about twice as fast), meshopt (meshoptimizer, error "
         "estimated, seconds for millions of triangles, but it may pinch the surface: non-manifold edges, "
         "counted in the report) or auto (bounded up to 200000 extracted triangles; above, fast to half "
         "the tolerance and then bounded, or fast all the way with --ratio below 0.05)")
      ->capture_default_str();
  cmd->add_option("--placement", p.placement,
                  "--simplify's vertex placement: input (every vertex stays an extracted one), optimal "
                  "(quadric minimum near the surface, then every vertex refit to the extracted surface by "
                  "least squares: "
                  "fewer triangles at the same tolerance, closer to the data) or auto "
                  "(optimal, input with --normals gradient)")
      ->capture_default_str();
  cmd->add_option(
         "--snap", p.snap,
         "surfaces from the hierarchy: move their vertices onto the volume's own iso-surface, at most this "
         "many voxels along the approximation's gradient (0: keep the approximation's surface; needs the "
         "volume; surfaces from the samples are on it already)")
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
      ->capture_default_str();
  cmd->add_option("--z-scale", p.z_scale, "2D height fields: height per data unit")->capture_default_str();
  cmd->add_option("--level", p.level, "extract on this hierarchy level (-1: finest)");
  cmd->add_option("--surface", p.surface,
                  "3D surfaces from: samples (marching cubes on the volume's samples, the hierarchy's finest "
                  "level without building it), hierarchy (marching tetrahedra on the hierarchy's level, the "
                  "paper's) or auto (samples when the volume is at hand and the finest level is asked)")
      ->capture_default_str();
  cmd->add_option(
         "--bricks", p.bricks,
         "extract and simplify surfaces from the samples in bricks of this many samples per edge, a power "
         "of two (e.g. 64): threads work on bricks, the seams are simplified after; raw, NIfTI, NRRD (raw, "
         "gzip), MetaImage and OME-Zarr volumes are then read brick by brick. 0: the whole surface at once; "
         "-1 (auto): 128 for such a volume of more than 2^27 samples, else 0")
      ->capture_default_str();
}

namespace {

// Ctrl-C: the first one asks the running call to stop at its next progress report (it then
// throws Cancelled and leaves no output); the handler resets itself, so a second one ends the
// process at once.
std::atomic<bool> interrupted{false};
void on_interrupt(int) { interrupted.store(true); }

void install_interrupt_handler() {
  struct sigaction sa {};
  sa.sa_handler = on_interrupt;
  sigemptyset(&sa.sa_mask);
  sa.sa_flags = SA_RESETHAND;
  sigaction(SIGINT, &sa, nullptr);
}

// One progress display per process: the bar's state, so status lines can clear it.
struct Display {
  bool bar_shown = false;
  std::string stage;
  int percent = -1;
};
Display& display() {
  static Display d;
  return d;
}

}  // namespace

void status_line(const std::string& text) {
  if (display().bar_shown) {
    std::fputs("\r\033[K", stderr);
    display().bar_shown = false;
    display().percent = -1;
  }
  std::fprintf(stderr, "%s\n", text.c_str());
}

pipeline::Progress progress_display(const std::string& command, bool quiet) {
  install_interrupt_handler();
  if (quiet) return [](double, const std::string&) { return !interrupted.load(); };
  display() = Display{};
  if (isatty(fileno(stderr))) {
    return [command](double fraction, const std::string& stage) {
      Display& d = display();
      const int percent = static_cast<int>(std::floor(100 * fraction));
      if (percent == d.percent && stage == d.stage) return !interrupted.load();
      d.percent = percent;
      d.stage = stage;
      constexpr int kWidth = 30;
      const int filled = std::min(kWidth, percent * kWidth / 100);
      std::fprintf(stderr, "\r\033[K%s [%s%s] %3d%% %s", command.c_str(), std::string(filled, '#').c_str(),
                   std::string(kWidth - filled, '.').c_str(), percent, stage.c_str());
      if (percent >= 100 && stage == "writing") {  // done: the summary lines follow
        std::fputs("\r\033[K", stderr);
        d.bar_shown = false;
      } else {
        d.bar_shown = true;
      }
      std::fflush(stderr);
      return !interrupted.load();
    };
  }
  return [command](double fraction, const std::string& stage) {
    Display& d = display();
    if (stage == d.stage) return !interrupted.load();
    d.stage = stage;
    // The long tail of a command, after its input was read and checked: a bad input still
    // fails with its one-line error (reading, extracting), and the build prints its own table.
    if ((stage == "rendering" || stage == "resampling" || stage == "writing") && fraction < 1)
      std::fprintf(stderr, "%s: %s\n", command.c_str(), stage.c_str());
    return !interrupted.load();
  };
}

void print_warnings(const std::vector<std::string>& warnings) {
  for (const auto& w : warnings) status_line("mlfe: warning: " + w);
}

BuildOptions build_options(const BuildParams& p) {
  BuildOptions o;
  // --threshold replaces --rms, whose text is then not read.
  if (!p.rms.empty() && p.threshold <= 0) o.rms = pipeline::parse_rms(p.rms, "rms");
  o.threshold = p.threshold;
  o.max_vertices = p.max_vertices;
  o.max_level = p.max_level;
  o.start_level = p.start_level;
  o.norm = pipeline::parse_enum<Norm>(p.norm, "norm");
  o.preconditioner = pipeline::parse_enum<Preconditioner>(p.preconditioner, "preconditioner");
  o.surface_tolerance = p.surface_tolerance;
  o.check_against_u = p.check_against_u;
  o.max_memory = parse_memory_budget(p.max_memory);
  if (!p.quiet) {
    // The table's header comes with its first row (surface passes have lines of their own).
    auto header = std::make_shared<bool>(false);
    o.surface_progress = [](const SurfacePassStats& s) {
      status_line(
          fmt::format("surface pass: {} vertices, {} elements, {} near a surface, {} refined, {:.2f} s",
                      s.vertices, s.elements, s.candidates, s.marked, s.seconds));
    };
    o.progress = [header](const IterationStats& s) {
      if (!*header) {
        *header = true;
        status_line(fmt::format("{:>4} {:>5} {:>10} {:>10} {:>12} {:>8} {:>8} {:>5} {:>8}", "iter", "level",
                                "vertices", "elements", "rms", "rms%", "psnr", "cg", "seconds"));
      }
      char row[160];
      std::snprintf(row, sizeof row, "%4d %5d %10zu %10zu %12.5g %8.4f %8.2f %5d %8.2f", s.iteration, s.level,
                    s.vertices, s.elements, s.rms_error, s.rms_percent, s.psnr_db, s.cg_iterations,
                    s.seconds);
      status_line(row);
    };
  }
  return o;
}

void warn_if_memory_limited(const Built& b, const std::string& source, const std::string& max_memory) {
  if (b.memory_limited())
    status_line(
        fmt::format("mlfe: warning: {}: refinement stopped at the memory budget (--max-memory {}, {:.0f} "
                    "MiB for the build); the approximation is coarser than asked",
                    source, max_memory, double(b.memory_budget_bytes) / 1048576.0));
}

AssetOptions asset_options(const AssetParams& p) {
  AssetOptions o;
  if (!p.iso.empty()) o.iso = parse_values(p.iso, "iso");
  o.tolerance = p.tolerance;
  o.draco = !p.no_draco;
  o.quantize = p.quantize;
  o.lod = p.lod;
  o.decimate = p.decimate;
  o.simplify = p.simplify;
  o.ratio = p.ratio;
  o.simplifier = pipeline::parse_enum<Simplifier>(p.simplifier, "simplifier");
  o.snap = p.snap;
  o.min_component = p.min_component;
  o.normals_toward_higher = p.normals_toward_higher;
  o.normals = pipeline::parse_enum<Normals>(p.normals, "normals");
  o.placement = pipeline::parse_enum<VertexPlacement>(p.placement, "placement");
  o.z_scale = p.z_scale;
  o.level = p.level;
  o.surface = pipeline::parse_enum<SurfaceSource>(p.surface, "surface");
  o.bricks = p.bricks;
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
  o.warn = [](const std::string& w) { status_line("mlfe: warning: " + w); };
  return o;
}

}  // namespace mlfe::cli
