#include <fmt/format.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/base/usage_error.h>
#include <mlfe/core/field/field.h>
#include <mlfe/core/field/noise_estimate.h>
#include <mlfe/core/simplify/bricked_iso_surface.h>
#include <mlfe/core/simplify/simplifier.h>
#include <mlfe/core/surface/iso_surface.h>
#include <mlfe/formats/asset_writer.h>
#include <mlfe/formats/atomic_file.h>
#include <mlfe/formats/brick_parts.h>
#include <mlfe/formats/file_names.h>
#include <mlfe/formats/gltf_writer.h>
#include <mlfe/formats/hierarchy_levels.h>
#include <mlfe/formats/input_files.h>
#include <mlfe/formats/openmesh_io.h>
#include <mlfe/formats/volume_reader.h>
#include <mlfe/pipeline.h>
#include <mlfe/version.h>
#include <sys/resource.h>
#include <tbb/parallel_for.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <limits>
#include <map>
#include <mutex>
#include <optional>
#include <utility>

#include "converters/progress_reporter.h"

namespace mlfe {

namespace fs = std::filesystem;

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

namespace pipeline {
namespace {

bool same_file(const std::string& a, const std::string& b) {
  // weakly_canonical keeps a relative path relative when nothing of it exists yet.
  std::error_code ea, eb;
  const fs::path ca = fs::weakly_canonical(fs::absolute(a, ea), ea);
  const fs::path cb = fs::weakly_canonical(fs::absolute(b, eb), eb);
  if (!ea && !eb && ca == cb) return true;
  std::error_code ec;
  return fs::equivalent(a, b, ec) && !ec;
}

}  // namespace

void check_distinct_files(const NamedFiles& inputs, const NamedFiles& outputs) {
  std::vector<std::pair<std::string, std::string>> read;  // what reads it, file
  for (const auto& [name, path] : inputs)
    if (!path.empty())
      for (const std::string& f : input_files(path))
        read.emplace_back(f == path ? name : name + " " + path + " reads it", f);
  std::vector<std::pair<std::string, std::string>> written;  // option, target
  for (const auto& [name, path] : outputs) {
    if (path.empty()) continue;
    const std::string target = output_target(path);
    for (const auto& [reader, in_path] : read)
      if (same_file(target, in_path))
        throw OptionError(option_ref(name) + ": " + path + " is also an input (" + reader +
                          "); it would be overwritten");
    for (const auto& [other, other_target] : written)
      if (same_file(target, other_target))
        throw OptionError(option_ref(name) + ": " + path + " is also the output " + option_ref(other) +
                          " (two outputs on one path)");
    written.emplace_back(name, target);
  }
}

}  // namespace pipeline

double peak_rss_mb() {
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  return ru.ru_maxrss / 1024.0;
}

std::size_t MemoryBudget::bytes() const {
  if (!(amount >= 0) || (percent_of_ram && amount > 100) || unit_power < 0 || unit_power > 3)
    throw Error(fmt::format("memory budget: expected a percentage of RAM (0..100) or bytes; got {}", text()));
  if (!percent_of_ram) return static_cast<std::size_t>(amount * std::pow(1024.0, unit_power));
  const double ram = double(sysconf(_SC_PHYS_PAGES)) * double(sysconf(_SC_PAGE_SIZE));
  return static_cast<std::size_t>(ram * amount / 100.0);
}

std::string MemoryBudget::text() const {
  static const char* const kUnits[] = {"", "K", "M", "G"};
  return fmt::format("{}{}", amount,
                     percent_of_ram                       ? "%"
                     : unit_power >= 0 && unit_power <= 3 ? kUnits[unit_power]
                                                          : "?");
}

namespace {

// The budget counts the vertices of the whole mesh, and the coarsest one (the box as 6
// tetrahedra or 2 triangles) already has its corners; a smaller budget cannot be kept.
void check_vertex_budget(const BuildOptions& p, int dim) {
  const std::size_t corners = dim == 2 ? 4 : 8;
  if (p.max_vertices > 0 && p.max_vertices < corners)
    throw pipeline::OptionError(fmt::format("{}: the coarsest {}D mesh has {} vertices; got {}",
                                            pipeline::option_ref("max_vertices"), dim, corners,
                                            p.max_vertices));
}

// Iso-values and no global target: the build refines for the surfaces alone (unless it is an
// error-bounded one, --max-error, which build() then makes global).
bool without_global_target(const BuildOptions& p, const std::vector<double>& isos) {
  return !isos.empty() && !p.rms && p.threshold <= 0 && p.max_vertices == 0;
}

// --surface: the samples' surfaces for a surface-driven build (which exists to carry the data's
// surfaces, and the samples give them exactly) with the volume at hand at the finest level; a
// global target (--rms, --max-vertices, ...) asks for the approximation's. extract() decides
// with the build, convert() before it (to skip the build).
// --surface samples asks for what only a volume's finest level has: refused before any work
// otherwise (an option that cannot apply, like a conflicting pair).
void check_surface_option(const AssetOptions& a, bool have_samples) {
  if (a.surface != SurfaceSource::kSamples) return;
  if (!have_samples)
    throw pipeline::OptionError(pipeline::option_ref("surface") +
                                " samples needs the volume's samples (a hierarchy file has none)");
  if (a.level >= 0)
    throw pipeline::OptionError(pipeline::option_ref("surface") + " samples extracts on the finest level; " +
                                pipeline::option_ref("level") + " asks for another");
}

// 3D surfaces are the iso-surfaces of the values asked for.
void require_iso(const std::vector<double>& iso) {
  if (iso.empty())
    throw pipeline::OptionInputError(pipeline::option_ref("iso") +
                                     " is required for 3D volumes (the values to extract, e.g. 80 and 150)");
}

bool surfaces_from_samples(const AssetOptions& a, bool have_samples, bool surface_driven) {
  return have_samples && a.level < 0 &&
         (a.surface == SurfaceSource::kSamples || (a.surface == SurfaceSource::kAuto && surface_driven));
}

// An iso-value the data never crosses gives an empty asset, which looks like success.
void check_iso_in_range(const std::vector<double>& isos, double lo, double hi, const std::string& source) {
  for (double v : isos)
    if (!(v > lo && v < hi))
      throw pipeline::OptionInputError(
          fmt::format("{}: {} {} is outside the data's range {:.6g} .. {:.6g} (no surface there)", source,
                      pipeline::option_ref("iso"), v, lo, hi));
}

// A grid build() and convert() can use (GridField relies on it), as the input they record.
FieldInput checked_grid_input(const ScalarGrid& grid) {
  if (grid.dim != 2 && grid.dim != 3)
    throw Error(fmt::format("{}: expected a 2D or 3D grid, got dim {}", grid.source, grid.dim));
  for (int a = 0; a < grid.dim; ++a)
    if (grid.dims[a] < 2)
      throw Error(fmt::format("{}: needs at least 2 samples along every axis (dims {}x{}x{})", grid.source,
                              grid.dims[0], grid.dims[1], grid.dims[2]));
  if (grid.values.size() != static_cast<std::size_t>(grid.voxel_count()) ||
      (grid.dim == 2 && grid.dims[2] != 1))
    throw Error(fmt::format("{}: {} values do not fill dims {}x{}x{}", grid.source, grid.values.size(),
                            grid.dims[0], grid.dims[1], grid.dims[2]));
  for (int a = 0; a < grid.dim; ++a)
    if (!(grid.transform.spacing[a] > 0) || !std::isfinite(grid.transform.spacing[a]))
      throw Error(fmt::format("{}: spacing must be positive (axis {}: {})", grid.source, a,
                              grid.transform.spacing[a]));
  // The volume and its min/max pyramid.
  return {grid.transform, grid.space, grid.source, double(grid.voxel_count()) * (sizeof(float) + 1.2)};
}

// Reports the share of the refinement done through `progress` from the approximation's own
// statistics: the RMS error toward the target on a log scale, the vertices toward the budget, the
// level toward max_level; surface passes by their count (each pass about halves what is left).
void add_fraction_progress(const Progress& progress, ApproximationOptions& o, double span) {
  const pipeline::detail::Reporter report(progress);
  report(0, "building");
  const auto first_error = std::make_shared<double>(0);
  const double target = o.target_rms;
  const std::size_t max_vertices = o.max_vertices;
  const int max_level = std::max(1, o.max_level);
  o.progress = [report, first_error, target, max_vertices, max_level, span,
                inner = std::move(o.progress)](const IterationStats& s) {
    if (inner) inner(s);
    double f = double(s.level) / max_level;
    if (max_vertices > 0) f = std::max(f, double(s.vertices) / double(max_vertices));
    if (target > 0 && s.rms_error > 0) {
      if (*first_error == 0) *first_error = std::max(s.rms_error, 1e-12 * span);
      const double e0 = *first_error;
      f = std::max(f,
                   e0 > target ? std::log(e0 / std::max(s.rms_error, target)) / std::log(e0 / target) : 1.0);
    }
    report(std::min(f, 0.99), "building");
  };
  const auto passes = std::make_shared<int>(0);
  o.surface_progress = [report, passes, inner = std::move(o.surface_progress)](const SurfacePassStats& s) {
    if (inner) inner(s);
    ++*passes;
    report(1.0 - std::pow(0.5, *passes), "building");
  };
}

}  // namespace

Built build(const ScalarGrid& grid, const BuildOptions& p, const std::vector<double>& iso_values) {
  const FieldInput input = checked_grid_input(grid);
  return build(GridField(grid), input, p, iso_values);
}

Built build(const Field& f, const FieldInput& input, const BuildOptions& p,
            const std::vector<double>& iso_values) {
  // RMS target of the default build relative to the noise (bench/RESULTS.md, noise).
  constexpr double kNoiseTargetFactor = 1.0;
  AssetOptions isos;  // the iso-values' rules are the assets'
  isos.iso = iso_values;
  pipeline::check_options(isos);
  pipeline::check_options(p);
  check_vertex_budget(p, f.dim());
  Built b;
  b.transform = input.transform;
  b.space = input.space;
  const auto range = f.range();
  b.value_min = range[0];
  b.value_max = range[1];
  check_iso_in_range(iso_values, range[0], range[1], input.source);
  const double span = range[1] > range[0] ? range[1] - range[0] : 1.0;

  ApproximationOptions o;
  // With surfaces to extract and no global target, refine for the surfaces alone.
  o.surface_driven = without_global_target(p, iso_values);
  if (p.threshold > 0) {
    o.threshold = p.threshold;
  } else if (!o.surface_driven) {
    const RmsTarget r = p.rms.value_or(RmsTarget{});
    o.target_rms = r.percent_of_range ? r.value / 100.0 * span : r.value;
    // The default does not store the noise: a scan's samples carry noise of deviation σ that
    // no approximation should chase, so the target is at least σ (bench/RESULTS.md, noise).
    if (const ScalarGrid* g = f.samples(); g && !p.rms) {
      b.noise_sigma = estimate_noise_sigma(*g);
      if (kNoiseTargetFactor * b.noise_sigma > o.target_rms) {
        o.target_rms = kNoiseTargetFactor * b.noise_sigma;
        b.target_from_noise = true;
      }
    }
    b.target_rms = o.target_rms;
  }
  o.max_vertices = p.max_vertices;
  o.max_level = p.max_level;
  o.start_level = p.start_level;
  o.h1 = p.norm == Norm::kH1;
  o.preconditioner = p.preconditioner;
  o.iso_values = iso_values;
  o.surface_tolerance = p.surface_tolerance;
  o.check_surfaces_against_u = p.check_against_u;
  o.solve = p.solve_u || p.check_against_u;
  o.max_sample_error = p.max_sample_error;
  if (o.max_sample_error >= 0) o.surface_driven = false;
  const std::size_t budget = p.max_memory.bytes();
  if (budget > 0) {
    // What the build may use: the budget less the input, with a fifth kept for extraction,
    // writing and the quantized file (a tenth let the whole-head T1 at --max-memory 400M
    // peak at 428 MiB).
    const double room = 0.8 * double(budget) - input.bytes;
    if (room < 8.0 * 1024 * 1024)
      throw pipeline::OptionInputError(
          fmt::format("{}: the volume alone ({:.0f} MiB) leaves no room under {} {} ({:.0f} MiB)",
                      input.source, input.bytes / 1048576.0, pipeline::option_ref("max_memory"),
                      p.max_memory.text(), double(budget) / 1048576.0));
    o.max_memory_bytes = static_cast<std::size_t>(room);
  }
  o.progress = p.progress;
  o.surface_progress = p.surface_progress;
  if (p.fraction_progress) add_fraction_progress(p.fraction_progress, o, span);
  b.memory_budget_bytes = o.max_memory_bytes;
  b.options = build_options_record(p, iso_values);
  const auto t0 = std::chrono::steady_clock::now();
  b.surface_driven = o.surface_driven;
  if (f.dim() == 2)
    b.approximation = approximate<2>(f, o);
  else
    b.approximation = approximate<3>(f, o);
  b.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (p.fraction_progress && !p.fraction_progress(1.0, "building")) throw Cancelled();
  return b;
}

FieldInput mesh_input(const TetMeshField& f, const TetMesh& mesh) {
  FieldInput in;
  in.transform.origin = f.origin();
  in.transform.spacing = {f.resolution(), f.resolution(), f.resolution()};
  in.source = mesh.source;
  // The field's copy: points, tetrahedra with their inverse matrices and buckets.
  in.bytes = double(mesh.points.size()) * 24 + double(f.tet_count()) * 200;
  return in;
}

Built build(const TetMesh& mesh, const BuildOptions& p, const std::vector<double>& iso_values) {
  const TetMeshField f(mesh);
  return build(f, mesh_input(f, mesh), p, iso_values);
}

template <int D>
void set_lattice_info(const Approximation<D>& a, HierarchyFileInfo& info) {
  info.on_lattice = a.on_lattice;
  info.lattice_level = a.on_lattice ? a.lattice.level : 0;
  info.data_dims = a.on_lattice ? a.lattice.dims : std::array<std::int64_t, 3>{1, 1, 1};
}

template <int D>
void set_lattice(const HierarchyFileInfo& info, Approximation<D>& a) {
  a.on_lattice = info.on_lattice;
  if (!info.on_lattice) return;
  a.lattice = sample_lattice(D, info.data_dims, info.transform.spacing, info.lattice_level);
  a.data_extent = a.lattice.data_extent();
}

template void set_lattice_info<2>(const Approximation<2>&, HierarchyFileInfo&);
template void set_lattice_info<3>(const Approximation<3>&, HierarchyFileInfo&);
template void set_lattice<2>(const HierarchyFileInfo&, Approximation<2>&);
template void set_lattice<3>(const HierarchyFileInfo&, Approximation<3>&);

Built built_from_file(const std::string& path, int max_level) {
  HierarchyFile hf = read_hierarchy(path, max_level);
  Built b;
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
    set_lattice(hf, a);
    b.approximation = std::move(a);
  } else {
    Approximation<3> a;
    a.hierarchy = std::get<Hierarchy<3>>(std::move(hf.hierarchy));
    a.values = std::move(hf.values);
    set_lattice(hf, a);
    b.approximation = std::move(a);
  }
  restore_build_record(path, hf.metadata, b);
  return b;
}

std::string write_built(const std::string& path, const Built& b, const nlohmann::json& provenance) {
  HierarchyFileInfo info;
  info.transform = b.transform;
  info.space = b.space;
  info.value_min = b.value_min;
  info.value_max = b.value_max;
  info.metadata = provenance;
  info.metadata["build"] = build_record(b);
  // v4 with exact values, so `iso` on the file extracts the surfaces convert extracted. The
  // writer verifies that the file rebuilds this hierarchy; if it ever did not, v1 (exact) is
  // written instead of a different hierarchy (v1 has no lattice: outputs of such a file are
  // not clipped to the data's box).
  HierarchyWriteOptions v4;
  v4.zstd_level = 19;
  v4.version = 4;
  std::string warning;
  b.visit([&](const auto& a) {
    HierarchyFileInfo li = info;
    set_lattice_info(a, li);
    try {
      write_hierarchy(path, a.hierarchy, a.values, li, v4);
    } catch (const LevelRebuildError& e) {
      warning = std::string(e.what()) + "; writing format version 1";
      write_hierarchy(path, a.hierarchy, a.values, info);
    }
  });
  return warning;
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
  const bool lattice = b.visit([](const auto& a) { return a.on_lattice; });
  r["errors_at"] = lattice ? "samples" : "continuous L2 over the domain";
  if (b.target_rms > 0) r["rms_target"] = b.target_rms;
  if (b.noise_sigma > 0 || b.target_from_noise) {
    r["noise_sigma"] = b.noise_sigma;
    r["rms_target_rule"] =
        b.target_from_noise ? "the estimated noise level (no --rms given)" : "--rms or its default";
  }
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
  const auto& passes = b.surface_passes();
  nlohmann::json sp = nlohmann::json::array();
  for (const auto& s : passes)
    sp.push_back({{"vertices", s.vertices},
                  {"elements", s.elements},
                  {"candidates", s.candidates},
                  {"marked", s.marked},
                  {"seconds", s.seconds}});
  r["surface_passes"] = sp;
  r["memory_limited"] = b.memory_limited();
  return r;
}

namespace {

// The voxel size tolerances are expressed in: the smallest spacing of the data's axes (mm).
double smallest_spacing(const GridTransform& t, int dim) {
  double s = 1e300;
  for (int a = 0; a < dim; ++a) s = std::min(s, t.spacing[a]);
  return s;
}

// Gradient normals hold at extracted vertices only, so they keep the vertices in place.
VertexPlacement resolved_placement(const AssetOptions& p) {
  return p.placement != VertexPlacement::kAuto ? p.placement
         : p.normals == Normals::kGradient     ? VertexPlacement::kInput
                                               : VertexPlacement::kOptimal;
}

SimplifierOptions simplifier_options(const AssetOptions& p, double voxel) {
  SimplifierOptions so;
  so.kind = p.simplifier;
  so.tolerance = p.simplify * voxel;
  so.placement =
      resolved_placement(p) == VertexPlacement::kOptimal ? Placement::kOptimal : Placement::kInputVertex;
  so.ratio = p.ratio;
  return so;
}

// Surface i of `count` iso-surfaces: its name, and its colour. Surfaces that enclose others are
// translucent so the inner ones stay visible: with normals toward lower values the innermost
// surface is the highest iso-value.
void style_iso_surface(GltfSurface& s, double iso, std::size_t i, std::size_t count, bool toward_higher) {
  s.iso_value = iso;
  s.name = fmt::format("iso {}", iso);
  const bool innermost = toward_higher ? i == 0 : i + 1 == count;
  static const std::array<std::array<float, 3>, 4> palette{
      {{0.93f, 0.87f, 0.75f}, {0.85f, 0.45f, 0.40f}, {0.45f, 0.60f, 0.85f}, {0.55f, 0.80f, 0.50f}}};
  const auto& c = palette[(count - 1 - i) % palette.size()];
  s.color = {c[0], c[1], c[2], innermost ? 1.0f : 0.35f};
}

// After extraction: decimation, and the normals the options resolve to (out.normals).
void finish_surfaces(Surfaces& out, const AssetOptions& p) {
  if (p.decimate > 0)
    for (auto& s : out.surfaces)
      if (s.mesh.triangles.size() > p.decimate) s.mesh = decimate_to(s.mesh, p.decimate);
  // decimate (OpenMesh) moves vertices, so only surface normals fit what it writes.
  out.normals = p.decimate > 0 || (p.normals == Normals::kAuto && p.simplify > 0) ? Normals::kSurface
                : p.normals == Normals::kAuto                                     ? Normals::kGradient
                                                                                  : p.normals;
  if (out.normals == Normals::kSurface)
    for (auto& s : out.surfaces) {
      compute_area_weighted_normals(s.mesh);
      for (auto& lod : s.lods) compute_area_weighted_normals(lod);
    }
}

}  // namespace

Surfaces extract(const Built& b, const AssetOptions& p, const ScalarGrid* grid) {
  pipeline::check_options(p);
  const auto t0 = std::chrono::steady_clock::now();
  Surfaces out;
  std::vector<GltfSurface>& surfaces = out.surfaces;
  std::vector<double>& isos = out.iso_values;
  // Surfaces extracted and simplified brick by brick (bricked_iso_surfaces), all at once.
  bool bricked = false;
  std::vector<TriangleMesh> bricked_meshes;
  std::vector<BrickStats> brick_stats;
  out.placement = resolved_placement(p);
  const SimplifierOptions so = simplifier_options(p, smallest_spacing(b.transform, b.dim()));
  const int dim = b.dim();
  if (dim == 3) {
    require_iso(p.iso);
    check_iso_in_range(p.iso, b.value_min, b.value_max, "the hierarchy");
    isos = p.iso;
    std::sort(isos.begin(), isos.end());
    const bool have_samples = grid && grid->dim == 3;
    check_surface_option(p, have_samples);
    out.source = surfaces_from_samples(p, have_samples, b.surface_driven) ? SurfaceSource::kSamples
                                                                          : SurfaceSource::kHierarchy;
    const bool from_samples = out.source == SurfaceSource::kSamples;
    if (p.bricks > 0 && !from_samples)
      throw pipeline::OptionError(
          pipeline::option_ref("bricks") +
          ": the bricks are the samples' lattice; surfaces from the hierarchy have none");
    if (p.bricks > 0 && p.min_component > 0)
      throw pipeline::OptionError(pipeline::option_ref("bricks") + ": " +
                                  pipeline::option_ref("min_component") +
                                  " needs the whole surface (a part may span bricks); use one or the other");
    bricked = p.bricks > 0 && p.simplify > 0;
    const Approximation<3>& a3 = b.get<3>();
    // Surface-driven builds refined until the data's interpolant on the mesh has the data's
    // surfaces (within the tolerance, small parts included); u, the L2 approximation, smooths
    // some of them away. With the volume at hand the asset takes the interpolant.
    // A build keeps them; a hierarchy read from a file (iso --volume) samples them again.
    std::vector<double> nodal_data;
    if (grid && grid->dim == 3 && b.surface_driven && !(from_samples && p.lod == 0)) {
      nodal_data = a3.data_values;
      sample_at_vertices(a3.hierarchy, GridField(*grid), nodal_data);
    }
    std::optional<IsoExtractor> x;
    if (!from_samples || p.lod > 0) x.emplace(a3.hierarchy, nodal_data.empty() ? a3.values : nodal_data);
    const int finest = a3.hierarchy.max_level();
    const int level = p.level < 0 ? finest : std::min(p.level, finest);
    std::optional<GridField> field;
    if (grid && grid->dim == 3 && p.snap > 0 && (!from_samples || p.lod > 0)) field.emplace(*grid);
    out.snapped = field.has_value();
    auto options = [&](int at) {
      IsoOptions o;
      o.normals_toward_higher = p.normals_toward_higher;
      o.level = at;
      o.min_component = p.min_component;
      o.clip = a3.on_lattice;
      o.clip_to = a3.data_extent;
      if (field) {
        o.snap_to = &*field;
        o.snap_distance = p.snap * smallest_spacing(b.transform, dim);
      }
      return o;
    };
    if (bricked) {
      // Every iso-value from one window per brick.
      BrickedIsoOptions bo;
      bo.normals_toward_higher = p.normals_toward_higher;
      bo.simplifier = so;
      bricked_meshes =
          bricked_iso_surfaces(grid_windows(*grid), grid->dims, p.bricks, isos, bo, &brick_stats);
    }
    for (std::size_t i = 0; i < isos.size(); ++i) {
      if (p.progress && !p.progress(0.5 * double(i) / double(isos.size()), "extracting")) throw Cancelled();
      GltfSurface s;
      style_iso_surface(s, isos[i], i, isos.size(), p.normals_toward_higher);
      Dropped dropped;
      IsoOptions o = options(level);
      o.dropped = &dropped;
      if (bricked) {
        s.mesh = std::move(bricked_meshes[i]);
        dropped.kept_parts = brick_stats[i].parts;
      } else {
        // On the samples the surface is the data's own: nothing to snap or clip.
        s.mesh = from_samples ? lattice_iso_surface(*grid, isos[i], o) : x->extract(isos[i], b.transform, o);
      }
      out.dropped.push_back(dropped);
      for (int k = 1; k <= p.lod && level - 2 * k >= 0; ++k)
        s.lods.push_back(x->extract(isos[i], b.transform, options(level - 2 * k)));
      surfaces.push_back(std::move(s));
    }
  } else {
    const Approximation<2>& a2 = b.get<2>();
    GltfSurface s;
    s.name = "height field";
    s.mesh = height_field_surface(a2.hierarchy, a2.values, b.transform, p.z_scale, p.level);
    s.color = {0.70f, 0.72f, 0.60f, 1.0f};
    surfaces.push_back(std::move(s));
  }
  out.extract_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (p.progress && !p.progress(0.5, "simplifying")) throw Cancelled();
  if (p.simplify > 0 && !bricked) {
    // Surfaces are independent: one task each, and each simplification is parallel inside.
    tbb::parallel_for(std::size_t(0), surfaces.size(), [&](std::size_t i) {
      auto& m = surfaces[i].mesh;
      if (!m.triangles.empty()) m = simplify(m, so);
    });
  }
  finish_surfaces(out, p);
  out.simplify_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() - out.extract_seconds;
  if (p.progress && !p.progress(1.0, "simplifying")) throw Cancelled();
  return out;
}

namespace {

// The extracted surfaces of a volume of `dim` dimensions (voxel: its smallest spacing) written
// to `out`, and write_assets' summary; `t0`: when the call began. The surfaces are given up to
// the writer, which releases each mesh as it writes it.
nlohmann::json write_surfaces(const std::string& out, Surfaces extracted, const AssetOptions& p,
                              const nlohmann::json& provenance, int dim, double voxel,
                              const std::string& space, std::chrono::steady_clock::time_point t0) {
  const double tol = p.tolerance > 0 ? p.tolerance : voxel / 10.0;
  const std::vector<GltfSurface>& surfaces = extracted.surfaces;

  nlohmann::json summary;
  nlohmann::json per = nlohmann::json::array();
  std::size_t total = 0;
  for (std::size_t i = 0; i < surfaces.size(); ++i) {
    const GltfSurface& s = surfaces[i];
    const MeshTopology topo = mesh_topology(s.mesh);
    per.push_back({{"iso", s.iso_value},
                   {"triangles", s.mesh.triangles.size()},
                   {"vertices", s.mesh.positions.size()},
                   {"topology",
                    {{"duplicate_vertices", topo.duplicate_vertices},
                     {"degenerate_triangles", topo.degenerate_triangles},
                     {"boundary_edges", topo.boundary_edges},
                     {"non_manifold_edges", topo.non_manifold_edges},
                     {"non_manifold_vertices", topo.non_manifold_vertices},
                     {"inconsistent_edges", topo.inconsistent_edges}}}});
    if (i < extracted.dropped.size()) {
      const Dropped& d = extracted.dropped[i];
      per.back()["parts"] = {{"kept", d.kept_parts},
                             {"dropped", d.parts},
                             {"dropped_triangles", d.triangles},
                             {"min_component_voxels", p.min_component}};
    }
    total += s.mesh.triangles.size();
  }
  // The glTF's asset.extras (the other formats have no place for them).
  nlohmann::json extras = provenance;
  extras["iso_values"] = extracted.iso_values;
  extras["snapped_to_data_voxels"] = extracted.snapped ? p.snap : 0.0;
  extras["simplify_voxels"] = p.simplify;
  if (p.simplify > 0) extras["simplifier"] = to_string(p.simplifier);
  if (p.simplify > 0 && dim == 3) extras["simplify_ratio"] = p.ratio;
  if (p.simplify > 0 && p.simplifier != Simplifier::kMeshopt)
    extras["placement"] = to_string(extracted.placement);
  extras["normals"] = to_string(extracted.normals);
  if (dim == 3) extras["surface"] = to_string(extracted.source);
  write_asset(std::move(extracted.surfaces), out, {p.draco, p.quantize, tol, space, extras});
  summary["output"] = out;
  if (dim == 3) summary["surface"] = to_string(extracted.source);
  summary["surfaces"] = per;
  summary["triangles"] = total;
  summary["bytes"] = written_file_size(out);
  summary["tolerance_mm"] = tol;
  summary["seconds"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  summary["stage_seconds"] = {
      {"extract", extracted.extract_seconds},
      {"simplify", extracted.simplify_seconds},
      {"write", summary["seconds"].get<double>() - extracted.extract_seconds - extracted.simplify_seconds}};
  return summary;
}

// Reads the windows of `v` for bricked_iso_surface, noting the values' range as they pass.
struct RangedWindows {
  const VolumeWindows& v;
  std::mutex mutex;
  float lo = std::numeric_limits<float>::infinity(), hi = -std::numeric_limits<float>::infinity();
  WindowReader reader() {
    return [this](const std::array<std::int64_t, 3>& a, const std::array<std::int64_t, 3>& b) {
      ScalarGrid w = v.read(a, b);
      const auto [mn, mx] = std::minmax_element(w.values.begin(), w.values.end());
      const std::lock_guard<std::mutex> lock(mutex);
      lo = std::min(lo, *mn);
      hi = std::max(hi, *mx);
      return w;
    };
  }
};

}  // namespace

nlohmann::json write_assets(const std::string& out, const Built& b, const AssetOptions& p,
                            const nlohmann::json& provenance, const ScalarGrid* grid) {
  const auto t0 = std::chrono::steady_clock::now();
  check_output_path(out, kAssetExtensions);
  // Extraction and simplification take most of the time, writing (Draco encoding) the rest.
  const pipeline::detail::Reporter report(p.progress);
  AssetOptions extract_options = p;
  extract_options.progress = report.share(0, 0.8).as_progress();
  Surfaces extracted = extract(b, extract_options, grid);
  report(0.8, "writing");
  nlohmann::json summary = write_surfaces(out, std::move(extracted), p, provenance, b.dim(),
                                          smallest_spacing(b.transform, b.dim()), b.space, t0);
  report.finish("writing");
  return summary;
}

namespace {

// What extract(const VolumeWindows&, ...) and the distributed pieces share: the checks, the
// simplifier's options and the surfaces' styles, before any brick.
struct BrickedSurfaces {
  Surfaces out;
  BrickedIsoOptions options;
  BrickLayout layout;
};

BrickedSurfaces start_bricked_surfaces(const VolumeWindows& v, const AssetOptions& p) {
  pipeline::check_options(p);
  const ScalarGrid& frame = v.frame();
  if (frame.dim != 3)
    throw pipeline::OptionError(pipeline::option_ref("bricks") + ": a 2D height field has no bricks");
  if (p.bricks <= 0 || p.simplify <= 0 || p.lod > 0 || p.level >= 0 ||
      p.surface == SurfaceSource::kHierarchy || p.min_component > 0)
    throw pipeline::OptionError(
        pipeline::option_ref("bricks") +
        ": a volume read in bricks gives simplified surfaces of its samples at the finest "
        "level, with no LODs and no part-size floor");
  require_iso(p.iso);
  BrickedSurfaces b;
  b.out.iso_values = p.iso;
  std::sort(b.out.iso_values.begin(), b.out.iso_values.end());
  b.out.source = SurfaceSource::kSamples;
  b.out.placement = resolved_placement(p);
  b.options.normals_toward_higher = p.normals_toward_higher;
  b.options.simplifier = simplifier_options(p, smallest_spacing(frame.transform, 3));
  b.layout = brick_layout(frame.dims, p.bricks);
  return b;
}

// The surfaces joined from the bricks' meshes (one per iso-value), once the data's range is
// known: an iso-value outside it is refused as the unbricked path refuses it, before anything
// is written.
void finish_bricked_surfaces(BrickedSurfaces& b, std::vector<TriangleMesh> meshes,
                             const std::vector<BrickStats>& stats, float lo, float hi, const VolumeWindows& v,
                             const AssetOptions& p) {
  check_iso_in_range(p.iso, lo, hi, v.frame().source);
  const std::size_t n = b.out.iso_values.size();
  for (std::size_t i = 0; i < n; ++i) {
    GltfSurface s;
    style_iso_surface(s, b.out.iso_values[i], i, n, p.normals_toward_higher);
    s.mesh = std::move(meshes[i]);
    Dropped kept;
    kept.kept_parts = stats[i].parts;
    b.out.dropped.push_back(kept);
    b.out.surfaces.push_back(std::move(s));
  }
  finish_surfaces(b.out, p);
}

}  // namespace

Surfaces extract(const VolumeWindows& v, const AssetOptions& p) {
  BrickedSurfaces b = start_bricked_surfaces(v, p);
  const auto t0 = std::chrono::steady_clock::now();
  RangedWindows windows{v};
  std::mutex progress_mutex;
  std::vector<BrickStats> stats;
  std::vector<TriangleMesh> meshes =
      bricked_iso_surfaces(windows.reader(), v.frame().dims, p.bricks, b.out.iso_values, b.options, &stats,
                           [&](std::size_t done, std::size_t total) {
                             const std::lock_guard<std::mutex> lock(progress_mutex);
                             if (p.progress && !p.progress(double(done) / double(total), "extracting"))
                               throw Cancelled();
                             return true;
                           });
  finish_bricked_surfaces(b, std::move(meshes), stats, windows.lo, windows.hi, v, p);
  b.out.extract_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return std::move(b.out);
}

nlohmann::json bricks_provenance(const std::string& input, const AssetOptions& o) {
  return {{"input", fs::path(input).filename().string()},
          {"tool", std::string("mlfe ") + MLFE_VERSION},
          {"refinement", "none: the samples' surfaces, read and simplified in bricks"},
          {"bricks", o.bricks}};
}

std::size_t brick_count(const VolumeWindows& v, const AssetOptions& o) {
  return start_bricked_surfaces(v, o).layout.bricks();
}

std::string brick_parts(const VolumeWindows& v, const AssetOptions& o, std::size_t brick) {
  const BrickedSurfaces b = start_bricked_surfaces(v, o);
  if (brick >= b.layout.bricks())
    throw Error(
        fmt::format("{}: brick {} is not one of its {} bricks", v.frame().source, brick, b.layout.bricks()));
  std::array<std::int64_t, 3> lo, hi;
  b.layout.window(brick, lo, hi);
  const ScalarGrid window = v.read(lo, hi);
  BrickParts parts;
  parts.brick = brick;
  const auto [mn, mx] = std::minmax_element(window.values.begin(), window.values.end());
  parts.lo = *mn;
  parts.hi = *mx;
  for (double iso : b.out.iso_values)
    parts.surfaces.push_back(brick_pass(window, b.layout, brick, iso, b.options));
  return encode_brick_parts(parts);
}

namespace {

// Decoded brick parts and join pieces, by what they cover, for join_tree; the samples' range
// over all of them.
struct HeldParts {
  std::map<std::size_t, std::vector<BrickPart>> bricks;
  std::map<std::pair<std::size_t, std::size_t>, std::vector<BrickPart>> joined;
  float lo = std::numeric_limits<float>::infinity(), hi = -std::numeric_limits<float>::infinity();
  std::atomic<std::size_t> taken{0};
  std::size_t held = 0;
};

// `parts` decoded (each string released once decoded), checked against the layout and the
// surfaces' count.
void decode_parts(HeldParts& h, std::vector<std::string>& parts, const BrickLayout& layout, std::size_t n) {
  for (std::string& bytes : parts) {
    BrickParts d = decode_brick_parts(bytes);
    std::string().swap(bytes);
    const bool joined = d.end_slab > d.first_slab;
    if (d.surfaces.size() != n || (joined ? d.end_slab > layout.slabs() : d.brick >= layout.bricks()))
      throw Error(fmt::format(
          "brick parts: parts of brick {} (slabs [{}, {})) with {} surfaces are not "
          "those of {} bricks in {} slabs with {} surfaces",
          d.brick, d.first_slab, d.end_slab, d.surfaces.size(), layout.bricks(), layout.slabs(), n));
    h.lo = std::min(h.lo, d.lo);
    h.hi = std::max(h.hi, d.hi);
    const bool fresh =
        joined ? h.joined.emplace(std::pair(d.first_slab, d.end_slab), std::move(d.surfaces)).second
               : h.bricks.emplace(d.brick, std::move(d.surfaces)).second;
    if (!fresh) throw Error("brick parts: the same brick or slabs given twice");
    ++h.held;
  }
}

// Where join_tree finds what `h` holds; a brick a slab needs and `h` has not is refused.
SlabSource held_source(HeldParts& h, const BrickLayout& layout, std::size_t n) {
  SlabSource s;
  s.joined = [&h](std::size_t first, std::size_t end) {
    const auto it = h.joined.find({first, end});
    if (it == h.joined.end()) return std::vector<BrickPart>{};
    ++h.taken;
    return std::move(it->second);
  };
  s.bricks = [&h, &layout, n](std::size_t slab) {
    std::vector<std::vector<BrickPart>> in(n);
    for (std::size_t b = slab * layout.slab_bricks(); b < (slab + 1) * layout.slab_bricks(); ++b) {
      const auto it = h.bricks.find(b);
      if (it == h.bricks.end()) throw Error(fmt::format("brick parts: brick {}'s parts are missing", b));
      ++h.taken;
      for (std::size_t i = 0; i < n; ++i) in[i].push_back(std::move(it->second[i]));
    }
    return in;
  };
  return s;
}

}  // namespace

std::string join_parts(const VolumeWindows& v, const AssetOptions& o, std::size_t first, std::size_t end,
                       std::vector<std::string> parts) {
  const BrickedSurfaces b = start_bricked_surfaces(v, o);
  const std::size_t n = b.out.iso_values.size();
  if (!(first < end && end <= b.layout.slabs()))
    throw Error(fmt::format("{}: slabs [{}, {}) are not among its {} slabs", v.frame().source, first, end,
                            b.layout.slabs()));
  HeldParts h;
  decode_parts(h, parts, b.layout, n);
  // Only the node's own inputs: its bricks (a slab) or its halves' pieces.
  SlabSource s = held_source(h, b.layout, n);
  std::vector<std::vector<BrickPart>> in(n);
  if (end == first + 1) {
    in = s.bricks(first);
  } else {
    const std::size_t split = slab_split(first, end);
    for (const auto& [a, z] : {std::pair(first, split), std::pair(split, end)}) {
      std::vector<BrickPart> half = s.joined(a, z);
      if (half.empty())
        throw Error(fmt::format("brick parts: the pieces of slabs [{}, {}) are missing", a, z));
      for (std::size_t i = 0; i < n; ++i) in[i].push_back(std::move(half[i]));
    }
  }
  if (h.taken != h.held) throw Error("brick parts: parts that are not the join's");
  BrickParts out;
  out.first_slab = first;
  out.end_slab = end;
  out.lo = h.lo;
  out.hi = h.hi;
  for (std::size_t i = 0; i < n; ++i)
    out.surfaces.push_back(join_slabs(std::move(in[i]), b.layout, first, end, b.options));
  return encode_brick_parts(out);
}

nlohmann::json write_bricks(const std::string& out, const VolumeWindows& v, const AssetOptions& o,
                            std::vector<std::string> parts, const nlohmann::json& provenance) {
  const auto t0 = std::chrono::steady_clock::now();
  check_output_path(out, kAssetExtensions);
  BrickedSurfaces b = start_bricked_surfaces(v, o);
  const std::size_t n = b.out.iso_values.size();
  HeldParts h;
  decode_parts(h, parts, b.layout, n);
  std::vector<BrickStats> stats;
  std::vector<TriangleMesh> meshes = join_tree(held_source(h, b.layout, n), b.layout, n, b.options, &stats);
  if (h.taken != h.held) throw Error("brick parts: parts that the join tree does not use");
  finish_bricked_surfaces(b, std::move(meshes), stats, h.lo, h.hi, v, o);
  b.out.extract_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return write_surfaces(out, std::move(b.out), o, provenance, 3, smallest_spacing(v.frame().transform, 3),
                        v.frame().space, t0);
}

std::int64_t auto_bricks(const std::array<std::int64_t, 3>& dims) {
  constexpr std::int64_t kFrom = std::int64_t(1) << 27, kEdge = 128;
  return dims[0] * dims[1] * dims[2] > kFrom ? kEdge : 0;
}

bool reads_in_bricks(const BuildOptions& b, const AssetOptions& a, bool whole_volume_outputs) {
  const bool surface_driven = without_global_target(b, a.iso) && b.max_sample_error < 0;
  return a.bricks > 0 && !whole_volume_outputs && a.simplify > 0 && a.lod == 0 && a.min_component == 0 &&
         surfaces_from_samples(a, true, surface_driven);
}

nlohmann::json write_assets(const std::string& out, const VolumeWindows& v, const AssetOptions& p,
                            const nlohmann::json& provenance) {
  const auto t0 = std::chrono::steady_clock::now();
  check_output_path(out, kAssetExtensions);
  const pipeline::detail::Reporter report(p.progress);
  AssetOptions extract_options = p;
  extract_options.progress = report.share(0, 0.9).as_progress();
  Surfaces extracted = extract(v, extract_options);
  report(0.9, "writing");
  nlohmann::json summary = write_surfaces(out, std::move(extracted), p, provenance, 3,
                                          smallest_spacing(v.frame().transform, 3), v.frame().space, t0);
  report.finish("writing");
  return summary;
}

namespace {

std::string rms_text(const RmsTarget& r) {
  return r.percent_of_range ? fmt::format("{}%", r.value) : fmt::format("{}", r.value);
}

}  // namespace

namespace {

// convert() on any input function; `grid` (may be null) is the voxel volume f interpolates,
// for snapping and the report's grid figures.
ConvertResult convert_field(const Field& f, const FieldInput& input, const ScalarGrid* grid,
                            const std::string& out, const ConvertOptions& c) {
  check_output_path(out, kAssetExtensions);
  if (!c.hierarchy.empty()) check_output_path(c.hierarchy, {".mlfeh"});
  if (!c.report.empty()) check_output_path(c.report, {});
  // u is solved for only when an output holds it (the hierarchy) or the caller keeps it.
  BuildOptions p = c.build;
  p.solve_u = !c.hierarchy.empty() || c.keep_u;
  // The build's share of the call; extraction, simplification and writing the rest.
  const pipeline::detail::Reporter report(c.progress);
  if (report) p.fraction_progress = report.share(0, 0.6).as_progress();
  std::vector<double> isos;
  if (f.dim() == 3) {
    require_iso(c.asset.iso);
    isos = c.asset.iso;
  }
  // Surfaces from the samples (extract()'s choice, made here before the build) need no hierarchy:
  // unless an output holds it (the file, u, LODs), the build stops at T0.
  const bool surface_driven = without_global_target(p, isos) && p.max_sample_error < 0;  // as build()
  if (f.dim() == 3) check_surface_option(c.asset, grid && grid->dim == 3);
  const bool from_samples = surfaces_from_samples(c.asset, grid && grid->dim == 3, surface_driven);
  const bool hierarchy_needed = !from_samples || !c.hierarchy.empty() || c.keep_u || c.asset.lod > 0;
  if (!hierarchy_needed) p.max_level = 0;  // c.build's own max_level was checked by convert()
  ConvertResult result;
  Built& b = result.built;
  b = build(f, input, p, isos);
  if (!hierarchy_needed)
    std::get<Approximation<3>>(b.approximation).stop_reason =
        "not refined: the surfaces come from the samples (--surface), no output holds the hierarchy";
  pipeline::detail::OutputGuard written;
  nlohmann::json prov = {{"input", fs::path(input.source).filename().string()},
                         {"tool", std::string("mlfe ") + MLFE_VERSION}};
  if (!b.iterations().empty()) {
    const auto& last = b.iterations().back();
    prov["rms_error"] = last.rms_error;
    prov["rms_error_percent"] = last.rms_percent;
    prov["psnr_db"] = last.psnr_db;
  }
  prov["vertices"] = b.vertices();
  // The effective target: the default RMS applies only without iso-values (surface-driven
  // refinement otherwise) or alongside another global target.
  prov["options"] = {{"rms", p.rms            ? rms_text(*p.rms)
                             : surface_driven ? "none (surface-driven)"
                                              : "0.5%"},
                     {"threshold", p.threshold},
                     {"max_vertices", p.max_vertices},
                     {"norm", p.norm == Norm::kH1 ? "h1" : "l2"},
                     {"surface_tolerance", p.surface_tolerance}};
  prov["refinement"] = b.surface_driven ? "surface-driven" : "global";
  if (c.provenance.is_object()) prov.merge_patch(c.provenance);
  if (!c.hierarchy.empty()) {
    report(0.6, "writing");
    if (std::string w = write_built(c.hierarchy, b, prov); !w.empty())
      result.warnings.push_back(c.hierarchy + ": " + w);
    written.add(c.hierarchy);
  }
  AssetOptions asset = c.asset;
  if (report) asset.progress = report.share(0.65, 1).as_progress();
  result.asset = write_assets(out, b, asset, prov, grid);
  written.add(out);
  result.report = build_report(input.source, grid, b);
  result.report["asset"] = result.asset;
  result.report["peak_rss_mb"] = peak_rss_mb();
  if (!c.report.empty()) write_json(c.report, result.report);
  written.release();
  return result;
}

// Before any work, so that convert_field's build at T0 (surfaces from the samples) refuses what
// a full build would.
void check_convert_options(const std::string& out, const ConvertOptions& c) {
  check_output_path(out, kAssetExtensions);
  pipeline::check_options(c.build);
  pipeline::check_options(c.asset);
}

}  // namespace

ConvertResult convert(const ScalarGrid& grid, const std::string& out, const ConvertOptions& c) {
  check_convert_options(out, c);
  const FieldInput input = checked_grid_input(grid);
  return convert_field(GridField(grid), input, &grid, out, c);
}

ConvertResult convert(const TetMesh& mesh, const std::string& out, const ConvertOptions& c) {
  check_convert_options(out, c);
  const TetMeshField f(mesh);
  return convert_field(f, mesh_input(f, mesh), nullptr, out, c);
}

ConvertResult convert(const std::string& input, const std::string& out, const ConvertOptions& options,
                      const VolumeReadOptions& read) {
  check_convert_options(out, options);
  pipeline::check_options(read);
  if (!options.hierarchy.empty()) check_output_path(options.hierarchy, {".mlfeh"});
  if (!options.report.empty()) check_output_path(options.report, {});
  if (!detect_tet_mesh_format(input).empty()) {
    return convert(read_tet_mesh(input, tet_mesh_read_options(read)), out, options);
  }
  return convert(read_volume(input, read), out, options);
}

}  // namespace mlfe
