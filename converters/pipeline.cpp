#include "converters/pipeline.h"

#include <fmt/format.h>
#include <sys/resource.h>
#include <tbb/parallel_for.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <optional>
#include <sstream>

#include "core/error.h"
#include "core/field.h"
#include "core/iso_surface.h"
#include "core/surface_simplification.h"
#include "formats/atomic_file.h"
#include "formats/draco_io.h"
#include "formats/file_names.h"
#include "formats/gltf_writer.h"
#include "formats/hierarchy_levels.h"
#include "formats/openmesh_io.h"

namespace mlfe::cli {

namespace fs = std::filesystem;

const std::vector<std::string> kAssetExtensions = {".glb", ".gltf", ".drc", ".ply", ".obj", ".stl", ".off"};

void check_output_path(const std::string& path, const std::vector<std::string>& extensions) {
  const std::string ext = lower_extension(path);
  if (!extensions.empty() && std::find(extensions.begin(), extensions.end(), ext) == extensions.end()) {
    std::string list;
    for (const auto& e : extensions) list += (list.empty() ? "" : " ") + e;
    throw Error(fmt::format("{}: unknown output type '{}' (use {})", path, ext, list));
  }
  const fs::path parent = fs::path(path).parent_path();
  if (!parent.empty() && !fs::is_directory(parent))
    throw Error(fmt::format("{}: cannot create file: folder {} does not exist", path, parent.string()));
}

void add_build_options(CLI::App* cmd, BuildParams& p) {
  cmd->add_option("--rms", p.rms,
                  "target RMS error: a percentage of the value range (\"0.5%\") or an absolute value in data "
                  "units [default: 0.5% without --iso; with --iso, refinement follows the surfaces]");
  cmd->add_option(
         "--threshold", p.threshold,
         "the paper's rule: refine elements whose RMS error exceeds this (data units); replaces --rms")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--max-vertices", p.max_vertices, "vertex budget (never exceeded)");
  cmd->add_option("--max-level", p.max_level, "deepest refinement level")
      ->check(CLI::Range(0, 40))
      ->capture_default_str();
  cmd->add_option("--start-level", p.start_level,
                  "uniform levels before adapting (-1: until edges <= 16 voxels)")
      ->check(CLI::Range(-1, 12));
  cmd->add_option("--norm", p.norm, "l2 (the paper) or h1: (u,v) + s^2 (grad u, grad v), s = voxel spacing")
      ->check(CLI::IsMember({"l2", "h1"}))
      ->capture_default_str();
  cmd->add_option("--preconditioner", p.preconditioner, "CG preconditioner")
      ->check(CLI::IsMember({"bpx", "jacobi", "none"}))
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
         "extraction)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_option(
         "--simplifier", p.simplifier,
         "--simplify's algorithm: bounded (every extracted vertex verified within the tolerance of the "
         "result, topology kept; ~10 microseconds per triangle), fast (meshoptimizer: collapses while its "
         "error estimate stays within the tolerance; seconds for millions of triangles) or auto (bounded "
         "for surfaces of up to 200000 extracted triangles, fast above)")
      ->check(CLI::IsMember({"auto", "fast", "bounded"}))
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
      throw Error(fmt::format("{}: not a number: '{}'", what, item));
    }
  }
  return out;
}

double peak_rss_mb() {
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  return ru.ru_maxrss / 1024.0;
}

std::size_t parse_memory_budget(const std::string& text) {
  std::string t = text;
  double scale = 1;
  bool percent = false;
  if (!t.empty()) {
    const char c = static_cast<char>(std::toupper(static_cast<unsigned char>(t.back())));
    if (c == '%') percent = true;
    if (c == 'K') scale = 1024.0;
    if (c == 'M') scale = 1024.0 * 1024.0;
    if (c == 'G') scale = 1024.0 * 1024.0 * 1024.0;
    if (percent || scale > 1) t.pop_back();
  }
  std::vector<double> v;
  try {
    v = parse_values(t, "--max-memory");
  } catch (const Error&) {
    v.clear();
  }
  if (v.size() != 1 || v[0] < 0 || (percent && v[0] > 100))
    throw Error("--max-memory: expected a percentage of RAM (50%), bytes with K/M/G (6G), or 0; got '" +
                text + "'");
  if (!percent) return static_cast<std::size_t>(v[0] * scale);
  const double ram = double(sysconf(_SC_PHYS_PAGES)) * double(sysconf(_SC_PAGE_SIZE));
  return static_cast<std::size_t>(ram * v[0] / 100.0);
}

Built build_from_grid(const ScalarGrid& grid, const BuildParams& p, const std::vector<double>& iso_values) {
  for (int a = 0; a < grid.dim; ++a)
    if (grid.dims[a] < 2)
      throw Error(fmt::format("{}: needs at least 2 samples along every axis (dims {}x{}x{})", grid.source,
                              grid.dims[0], grid.dims[1], grid.dims[2]));
  Built b;
  b.dim = grid.dim;
  b.transform = grid.transform;
  b.space = grid.space;
  const auto range = grid.value_range();
  b.value_min = range[0];
  b.value_max = range[1];
  const double span = range[1] > range[0] ? double(range[1]) - double(range[0]) : 1.0;

  ApproximationOptions o;
  // With surfaces to extract and no global target, refine for the surfaces alone.
  o.surface_driven = !iso_values.empty() && p.rms.empty() && p.threshold <= 0 && p.max_vertices == 0;
  if (p.threshold > 0) {
    o.threshold = p.threshold;
  } else if (!o.surface_driven) {
    std::string r = p.rms.empty() ? "0.5%" : p.rms;
    const bool percent = !r.empty() && r.back() == '%';
    if (percent) r.pop_back();
    const auto v = parse_values(r, "--rms");
    if (v.size() != 1 || v[0] <= 0) throw Error("--rms: expected one positive value, e.g. 0.5% or 2.0");
    o.target_rms = percent ? v[0] / 100.0 * span : v[0];
  }
  o.max_vertices = p.max_vertices;
  o.max_level = p.max_level;
  o.start_level = p.start_level;
  o.h1 = p.norm == "h1";
  o.preconditioner = p.preconditioner == "bpx"      ? Preconditioner::kBpx
                     : p.preconditioner == "jacobi" ? Preconditioner::kJacobi
                                                    : Preconditioner::kNone;
  o.iso_values = iso_values;
  o.surface_tolerance = p.surface_tolerance;
  o.check_surfaces_against_u = p.check_against_u;
  o.solve = p.solve_u || p.check_against_u;
  const std::size_t budget = parse_memory_budget(p.max_memory);
  if (budget > 0) {
    // What the build may use: the budget less the volume (and its min/max pyramid), with a
    // tenth kept for extraction and writing.
    const double grid_bytes = double(grid.voxel_count()) * (sizeof(float) + 1.2);
    const double room = 0.9 * double(budget) - grid_bytes;
    if (room < 8.0 * 1024 * 1024)
      throw Error(
          fmt::format("{}: the volume alone ({:.0f} MiB) leaves no room under --max-memory {} ({:.0f} MiB)",
                      grid.source, grid_bytes / 1048576.0, p.max_memory, double(budget) / 1048576.0));
    o.max_memory_bytes = static_cast<std::size_t>(room);
  }
  if (!p.quiet) {
    std::fprintf(stderr, "%4s %5s %10s %10s %12s %8s %8s %5s %8s\n", "iter", "level", "vertices", "elements",
                 "rms", "rms%", "psnr", "cg", "seconds");
    o.surface_progress = [](const SurfacePassStats& s) {
      std::fprintf(stderr,
                   "surface pass: %zu vertices, %zu elements, %zu near a surface, %zu refined, %.2f s\n",
                   s.vertices, s.elements, s.candidates, s.marked, s.seconds);
    };
    o.progress = [](const IterationStats& s) {
      std::fprintf(stderr, "%4d %5d %10zu %10zu %12.5g %8.4f %8.2f %5d %8.2f\n", s.iteration, s.level,
                   s.vertices, s.elements, s.rms_error, s.rms_percent, s.psnr_db, s.cg_iterations, s.seconds);
    };
  }
  const auto t0 = std::chrono::steady_clock::now();
  GridField f(grid);
  b.surface_driven = o.surface_driven;
  if (grid.dim == 2)
    b.a2 = approximate<2>(f, o);
  else
    b.a3 = approximate<3>(f, o);
  b.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if ((grid.dim == 2 ? b.a2->memory_limited : b.a3->memory_limited))
    std::fprintf(
        stderr,
        "mlfe: warning: %s: refinement stopped at the memory budget (--max-memory %s, %.0f MiB for the "
        "build); the approximation is coarser than asked\n",
        grid.source.c_str(), p.max_memory.c_str(), double(o.max_memory_bytes) / 1048576.0);
  return b;
}

Built built_from_file(const std::string& path) {
  HierarchyFile hf = read_hierarchy(path);
  Built b;
  b.dim = hf.dim;
  b.transform = hf.transform;
  b.space = hf.space;
  b.value_min = hf.value_min;
  b.value_max = hf.value_max;
  if (hf.values.empty()) throw Error(path + ": the hierarchy stores no values (u) to extract from");
  b.surface_driven = hf.metadata.is_object() && hf.metadata.value("refinement", "") == "surface-driven";
  if (hf.dim == 2) {
    Approximation<2> a;
    a.hierarchy = std::get<Hierarchy<2>>(std::move(hf.hierarchy));
    a.values = std::move(hf.values);
    b.a2 = std::move(a);
  } else {
    Approximation<3> a;
    a.hierarchy = std::get<Hierarchy<3>>(std::move(hf.hierarchy));
    a.values = std::move(hf.values);
    b.a3 = std::move(a);
  }
  return b;
}

void write_built(const std::string& path, const Built& b, const nlohmann::json& provenance) {
  HierarchyFileInfo info;
  info.transform = b.transform;
  info.space = b.space;
  info.value_min = b.value_min;
  info.value_max = b.value_max;
  info.metadata = provenance;
  // v2 with exact values, so `iso` on the file extracts the surfaces convert extracted.
  const HierarchyWriteOptions v2{true, 19, 2, 0.0};
  const auto write = [&](const auto& a) {
    try {
      write_hierarchy(path, a.hierarchy, a.values, info, v2);
    } catch (const LevelRebuildError& e) {
      std::fprintf(stderr, "mlfe: warning: %s; writing format version 1\n", e.what());
      write_hierarchy(path, a.hierarchy, a.values, info);
    }
  };
  if (b.dim == 2)
    write(*b.a2);
  else
    write(*b.a3);
}

void write_json(const std::string& path, const nlohmann::json& j) {
  write_file_atomically(path, [&](std::ostream& os) { os << j.dump(2) << "\n"; });
}

nlohmann::json build_report(const std::string& input, const ScalarGrid* grid, const Built& b) {
  nlohmann::json r;
  r["input"] = input;
  if (grid) {
    r["dims"] = {grid->dims[0], grid->dims[1], grid->dims[2]};
    r["voxels"] = grid->voxel_count();
    r["spacing"] = grid->transform.spacing;
  }
  const auto& its = b.iterations();
  r["vertices"] = b.vertices();
  r["elements"] = b.leaves();
  r["levels"] = b.levels();
  r["iterations"] = its.size();
  if (its.empty()) {
    r["u"] = "not solved: the outputs need only the mesh and the data's interpolant";
  } else {
    r["rms_error"] = its.back().rms_error;
    r["rms_error_percent"] = its.back().rms_percent;
    r["l2_error"] = its.back().l2_error;
    r["psnr_db"] = its.back().psnr_db;
  }
  r["value_range"] = {b.value_min, b.value_max};
  r["stop_reason"] = b.stop_reason();
  r["seconds"] = b.seconds;
  r["peak_rss_mb"] = peak_rss_mb();
  nlohmann::json rows = nlohmann::json::array();
  for (const auto& s : its)
    rows.push_back({{"iteration", s.iteration},
                    {"level", s.level},
                    {"vertices", s.vertices},
                    {"elements", s.elements},
                    {"marked", s.marked},
                    {"rms_error", s.rms_error},
                    {"rms_error_percent", s.rms_percent},
                    {"psnr_db", s.psnr_db},
                    {"cg_iterations", s.cg_iterations},
                    {"assembly_seconds", s.assembly_seconds},
                    {"solve_seconds", s.solve_seconds},
                    {"estimate_seconds", s.estimate_seconds},
                    {"refine_seconds", s.refine_seconds},
                    {"seconds", s.seconds}});
  r["per_iteration"] = rows;
  const auto& passes = b.dim == 2 ? b.a2->surface_passes : b.a3->surface_passes;
  nlohmann::json sp = nlohmann::json::array();
  for (const auto& s : passes)
    sp.push_back({{"vertices", s.vertices},
                  {"elements", s.elements},
                  {"candidates", s.candidates},
                  {"marked", s.marked},
                  {"seconds", s.seconds}});
  r["surface_passes"] = sp;
  r["memory_limited"] = b.dim == 2 ? b.a2->memory_limited : b.a3->memory_limited;
  return r;
}

namespace {

TriangleMesh merge(const std::vector<GltfSurface>& surfaces) {
  TriangleMesh m;
  for (const auto& s : surfaces) {
    const TriangleMesh& p = s.mesh;
    const auto base = static_cast<std::uint32_t>(m.positions.size());
    m.positions.insert(m.positions.end(), p.positions.begin(), p.positions.end());
    m.normals.insert(m.normals.end(), p.normals.begin(), p.normals.end());
    for (auto t : p.triangles) m.triangles.push_back({t[0] + base, t[1] + base, t[2] + base});
  }
  return m;
}

// The voxel size tolerances are expressed in: the smallest spacing of the data's axes (mm).
double smallest_spacing(const GridTransform& t, int dim) {
  double s = 1e300;
  for (int a = 0; a < dim; ++a) s = std::min(s, t.spacing[a]);
  return s;
}

}  // namespace

nlohmann::json write_assets(const std::string& out, const Built& b, const AssetParams& p,
                            const nlohmann::json& provenance, const ScalarGrid* grid) {
  const auto t0 = std::chrono::steady_clock::now();
  check_output_path(out, kAssetExtensions);
  const std::string ext = lower_extension(out);
  const double tol = p.tolerance > 0 ? p.tolerance : smallest_spacing(b.transform, b.dim) / 10.0;

  std::vector<GltfSurface> surfaces;
  std::vector<double> isos;
  bool field_used = false;
  if (b.dim == 3) {
    if (p.iso.empty()) throw Error("--iso is required for 3D volumes (e.g. --iso 80,150)");
    isos = parse_values(p.iso, "--iso");
    std::sort(isos.begin(), isos.end());
    // Surface-driven builds refined until the data's interpolant on the mesh has the data's
    // surfaces (within the tolerance, small parts included); u, the L2 approximation, smooths
    // some of them away. With the volume at hand the asset takes the interpolant.
    // A build keeps them; a hierarchy read from a file (iso --volume) samples them again.
    std::vector<double> nodal_data;
    if (grid && grid->dim == 3 && b.surface_driven) {
      nodal_data = b.a3->data_values;
      sample_at_vertices(b.a3->hierarchy, GridField(*grid), nodal_data);
    }
    IsoExtractor x(b.a3->hierarchy, nodal_data.empty() ? b.a3->values : nodal_data);
    const int finest = b.a3->hierarchy.max_level();
    const int level = p.level < 0 ? finest : std::min(p.level, finest);
    std::optional<GridField> field;
    if (grid && grid->dim == 3 && p.snap > 0) field.emplace(*grid);
    field_used = field.has_value();
    auto options = [&](int at) {
      IsoOptions o;
      o.normals_toward_higher = p.normals_toward_higher;
      o.level = at;
      if (field) {
        o.snap_to = &*field;
        o.snap_distance = p.snap * smallest_spacing(b.transform, b.dim);
      }
      return o;
    };
    for (std::size_t i = 0; i < isos.size(); ++i) {
      GltfSurface s;
      s.iso_value = isos[i];
      s.name = fmt::format("iso {}", isos[i]);
      s.mesh = x.extract(isos[i], b.transform, options(level));
      for (int k = 1; k <= p.lod && level - 2 * k >= 0; ++k)
        s.lods.push_back(x.extract(isos[i], b.transform, options(level - 2 * k)));
      // Surfaces that enclose others are translucent so the inner ones stay visible: with
      // normals toward lower values the innermost surface is the highest iso-value.
      const bool innermost = p.normals_toward_higher ? i == 0 : i + 1 == isos.size();
      static const std::array<std::array<float, 3>, 4> palette{
          {{0.93f, 0.87f, 0.75f}, {0.85f, 0.45f, 0.40f}, {0.45f, 0.60f, 0.85f}, {0.55f, 0.80f, 0.50f}}};
      const auto& c = palette[(isos.size() - 1 - i) % palette.size()];
      s.color = {c[0], c[1], c[2], innermost ? 1.0f : 0.35f};
      surfaces.push_back(std::move(s));
    }
  } else {
    GltfSurface s;
    s.name = "height field";
    s.mesh = height_field_surface(b.a2->hierarchy, b.a2->values, b.transform, p.z_scale, p.level);
    s.color = {0.70f, 0.72f, 0.60f, 1.0f};
    surfaces.push_back(std::move(s));
  }
  const double extract_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  // Gradient normals hold at extracted vertices only, so they keep the vertices in place.
  const std::string placement = p.placement != "auto"     ? p.placement
                                : p.normals == "gradient" ? "input"
                                                          : "optimal";
  if (p.simplify > 0) {
    const double voxel = smallest_spacing(b.transform, b.dim);
    SimplifyOptions so;
    so.tolerance = p.simplify * voxel;
    so.placement = placement == "optimal" ? Placement::kOptimal : Placement::kInputVertex;
    // Surfaces are independent: one task each, and each simplification is parallel inside.
    // auto: the verified simplifier while it takes about a second or two (~10 µs per
    // triangle), meshoptimizer beyond; decided per surface from its size alone, so the bytes do
    // not depend on the thread count.
    constexpr std::size_t kBoundedUpTo = 200000;
    tbb::parallel_for(std::size_t(0), surfaces.size(), [&](std::size_t i) {
      auto& m = surfaces[i].mesh;
      if (m.triangles.empty()) return;
      const bool bounded =
          p.simplifier == "bounded" || (p.simplifier == "auto" && m.triangles.size() <= kBoundedUpTo);
      m = bounded ? simplify_within(m, so) : simplify_fast(m, so.tolerance);
    });
  }
  if (p.decimate > 0)
    for (auto& s : surfaces)
      if (s.mesh.triangles.size() > p.decimate) s.mesh = decimate_to(s.mesh, p.decimate);
  // --decimate (OpenMesh) moves vertices, so only surface normals fit what it writes.
  const std::string normals = p.decimate > 0 || (p.normals == "auto" && p.simplify > 0) ? "surface"
                              : p.normals == "auto"                                     ? "gradient"
                                                                                        : p.normals;
  if (normals == "surface")
    for (auto& s : surfaces) {
      compute_area_weighted_normals(s.mesh);
      for (auto& lod : s.lods) compute_area_weighted_normals(lod);
    }

  const double simplify_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() - extract_seconds;
  nlohmann::json summary;
  nlohmann::json per = nlohmann::json::array();
  std::size_t total = 0;
  for (const auto& s : surfaces) {
    per.push_back({{"iso", s.iso_value},
                   {"triangles", s.mesh.triangles.size()},
                   {"vertices", s.mesh.positions.size()}});
    total += s.mesh.triangles.size();
  }
  if (ext == ".glb" || ext == ".gltf") {
    GltfOptions o;
    o.draco = !p.no_draco;
    o.quantize = p.quantize;
    o.tolerance_mm = tol;
    o.space = b.space;
    o.extras = provenance;
    o.extras["tolerance_mm"] = tol;
    o.extras["iso_values"] = isos;
    o.extras["snapped_to_data_voxels"] = field_used ? p.snap : 0.0;
    o.extras["simplify_voxels"] = p.simplify;
    if (p.simplify > 0) o.extras["simplifier"] = p.simplifier;
    if (p.simplify > 0 && p.simplifier != "fast") o.extras["placement"] = placement;
    o.extras["normals"] = normals;
    write_gltf(out, surfaces, o);
  } else {
    // Single-mesh formats: all surfaces in one mesh.
    const TriangleMesh all = merge(surfaces);
    if (ext == ".drc") {
      DracoOptions o;
      o.tolerance = tol;
      write_draco_file(out, all, o);
    } else {
      write_mesh_file(out, all);
    }
  }
  summary["output"] = out;
  summary["surfaces"] = per;
  summary["triangles"] = total;
  summary["bytes"] = std::filesystem::file_size(out);
  summary["tolerance_mm"] = tol;
  summary["seconds"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  summary["stage_seconds"] = {{"extract", extract_seconds},
                              {"simplify", simplify_seconds},
                              {"write", summary["seconds"].get<double>() - extract_seconds - simplify_seconds}};
  return summary;
}

}  // namespace mlfe::cli
