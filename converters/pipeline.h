// The volume → hierarchy → assets pipeline shared by `mlfe build`, `mlfe iso` and
// `mlfe convert`: option parsing, the adaptive build with progress and report, iso-surface
// extraction and writing by output extension.
#pragma once
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/approximation.h"
#include "core/scalar_grid.h"
#include "core/triangle_mesh.h"
#include "formats/hierarchy_io.h"
#include "formats/volume_reader.h"

namespace mlfe::cli {

struct BuildParams {
  /// Target RMS error: "0.5%" of the value range, or absolute. Empty: the default, which is
  /// 0.5% without iso-values and none with them (surface-driven refinement; see build_from_grid).
  std::string rms;
  double threshold = 0;  ///< the paper's per-element threshold (data units), 0: off
  std::size_t max_vertices = 0;
  int max_level = 20;
  int start_level = -1;
  std::string norm = "l2";             ///< "l2" or "h1"
  std::string preconditioner = "bpx";  ///< "bpx", "jacobi", "none"
  double surface_tolerance = 0.5;      ///< voxels, for iso-aware refinement
  bool check_against_u = false;        ///< surface-driven: refine where u misses the data's surfaces
  /// Surface-driven builds: false skips assembling and solving for u when no output needs it
  /// (the assets come from the data's interpolant); the build then reports no RMS error.
  bool solve_u = true;
  /// Memory budget of the build: "50%" of the machine's RAM (default), or bytes with an
  /// optional K/M/G suffix; "0": none. Refinement stops at it with a message.
  std::string max_memory = "50%";
  bool quiet = false;
};

/// The memory budget in bytes of a --max-memory text ("50%", "6G", "512M", "0"); throws
/// mlfe::Error on bad text.
std::size_t parse_memory_budget(const std::string& text);

/// Adds --rms, --threshold, --max-vertices, --max-level, --start-level, --norm,
/// --preconditioner, --surface-tolerance and --quiet.
void add_build_options(CLI::App* cmd, BuildParams& p);

/// The hierarchy and solution built from a grid (2D or 3D alternative set).
struct Built {
  int dim = 3;
  std::optional<Approximation<2>> a2;
  std::optional<Approximation<3>> a3;
  GridTransform transform;
  std::string space;
  double value_min = 0, value_max = 0;
  double seconds = 0;
  /// Built around the iso-surfaces (ApproximationOptions::surface_driven): the mesh certifies
  /// the data's interpolant there, so assets are extracted from it when the volume is at hand.
  bool surface_driven = false;
  const std::vector<IterationStats>& iterations() const { return dim == 2 ? a2->iterations : a3->iterations; }
  const std::string& stop_reason() const { return dim == 2 ? a2->stop_reason : a3->stop_reason; }
  std::size_t vertices() const {
    return dim == 2 ? a2->hierarchy.vertex_count() : a3->hierarchy.vertex_count();
  }
  std::size_t leaves() const {
    return dim == 2 ? a2->hierarchy.leaves().size() : a3->hierarchy.leaves().size();
  }
  int levels() const { return (dim == 2 ? a2->hierarchy.max_level() : a3->hierarchy.max_level()) + 1; }
};

/// Runs the adaptive approximation on `grid`. With iso values and no global target (--rms,
/// --threshold, --max-vertices), refinement is surface-driven (ApproximationOptions::
/// surface_driven); with one, the global target drives it and the iso values add iso-aware marks.
/// Throws mlfe::Error for unusable grids (fewer than 2 samples along an axis) or options.
Built build_from_grid(const ScalarGrid& grid, const BuildParams& p, const std::vector<double>& iso_values);

/// Loads a hierarchy file as a Built (values required).
Built built_from_file(const std::string& path);

/// Writes the hierarchy (.mlfeh) with provenance.
void write_built(const std::string& path, const Built& b, const nlohmann::json& provenance);

/// The JSON report of a build (input, dims, voxels, vertices, elements, levels, iterations,
/// errors, PSNR, value range, seconds, peak RSS, per-iteration rows).
nlohmann::json build_report(const std::string& input, const ScalarGrid* grid, const Built& b);

/// Checks before any work that `path` has one of `extensions` (lower case, with the dot) and
/// that its folder exists; throws mlfe::Error naming the path otherwise.
void check_output_path(const std::string& path, const std::vector<std::string>& extensions);

/// The output types of write_assets.
extern const std::vector<std::string> kAssetExtensions;

/// Writes JSON atomically.
void write_json(const std::string& path, const nlohmann::json& j);

/// Peak resident set size of this process in MiB.
double peak_rss_mb();

/// Parses "80,150" into numbers; throws mlfe::Error on bad input.
std::vector<double> parse_values(const std::string& text, const std::string& what);

struct AssetParams {
  std::string iso;       ///< comma-separated iso-values (3D)
  double tolerance = 0;  ///< mm; 0: a tenth of the smallest voxel spacing
  bool no_draco = false;
  bool quantize = false;
  int lod = 0;               ///< coarser levels to add to glTF
  std::size_t decimate = 0;  ///< triangle budget per surface (OpenMesh quadric decimation)
  /// Simplification tolerance in voxels (0: the raw extraction). The default keeps assets
  /// compact: chosen from bench/convert_bench.py (bench/RESULTS.md).
  double simplify = 0.3;
  /// "bounded" (simplify_within, error verified), "fast" (meshoptimizer, error estimated) or
  /// "auto" (bounded for surfaces of up to 200 000 extracted triangles, fast above).
  std::string simplifier = "auto";
  double snap = 1.0;  ///< move vertices onto the data's surface, at most this many voxels (0: off)
  bool normals_toward_higher = false;
  /// "gradient": the paper's normals (volume-weighted tetrahedron gradients of u, interpolated
  /// along the cut edge), kept through --simplify; "surface": area-weighted normals of the
  /// written triangles, so shading follows the asset's own silhouette and Draco predicts them
  /// from the geometry (files 20-45 % smaller); "auto": gradient for extracted surfaces,
  /// surface once --simplify or --decimate has made new triangles. --decimate (OpenMesh)
  /// moves vertices, so its output always has surface normals.
  std::string normals = "auto";
  /// --simplify's vertex placement: "input" (half-edge collapses: every vertex an extracted,
  /// snapped one), "optimal" (quadric minimum near the surface: fewer triangles at the same
  /// bound, smoother; up to twice the simplification time) or "auto" (optimal, but input
  /// with --normals gradient, whose normals hold only at extracted vertices).
  std::string placement = "auto";
  double z_scale = 1.0;  ///< 2D height fields: height per data unit
  int level = -1;        ///< extract on this level (-1 finest)
};
void add_asset_options(CLI::App* cmd, AssetParams& p);

/// Extracts the surfaces of `b` and writes them to `out` by extension (.glb .gltf .drc .ply
/// .obj .stl .off). `grid` is the volume `b` was built from, or nullptr (a hierarchy file):
/// with it, 3D surfaces are snapped onto the data's own iso-surface (AssetParams::snap).
/// Returns a JSON summary (triangles per surface, bytes, seconds).
nlohmann::json write_assets(const std::string& out, const Built& b, const AssetParams& p,
                            const nlohmann::json& provenance, const ScalarGrid* grid = nullptr);

}  // namespace mlfe::cli
