// The volume → hierarchy → assets pipeline as a library (mlfe::pipeline), used by `mlfe build`,
// `mlfe iso`, `mlfe convert`, `mlfe render`, the Python module and asset pipelines that embed
// the converter: the adaptive build, iso-surface extraction, and writing by output extension.
// Options are typed; their defaults are the command line's. Bad input or options throw
// mlfe::Error with a one-line message; nothing is printed (progress goes to the callbacks).
#pragma once
#include <mlfe/core/approximation.h>
#include <mlfe/core/iso_surface.h>
#include <mlfe/core/scalar_grid.h>
#include <mlfe/core/tet_mesh_field.h>
#include <mlfe/core/triangle_mesh.h>
#include <mlfe/formats/gltf_writer.h>
#include <mlfe/formats/hierarchy_io.h>
#include <mlfe/formats/tet_mesh_reader.h>
#include <mlfe/formats/volume_reader.h>

#include <cstddef>
#include <cstdint>
#include <functional>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <variant>
#include <vector>

namespace mlfe {

enum class Norm { kL2, kH1 };

/// A target RMS error: a percentage of the data's value range or an absolute value in data units.
struct RmsTarget {
  double value = 0.5;
  bool percent_of_range = true;
};

/// A memory budget: a percentage of the machine's RAM, or bytes (written with a unit for
/// messages: 1024^unit_power bytes per unit, 0: bytes, 1: K, 2: M, 3: G). 0: no budget.
struct MemoryBudget {
  double amount = 50;
  bool percent_of_ram = true;
  int unit_power = 0;
  /// The budget in bytes (0: none).
  std::size_t bytes() const;
  /// "50%", "6G", "512M", "1000", as the command line spells it.
  std::string text() const;
};

struct BuildOptions {
  /// Target RMS error. Unset: 0.5% of the value range without iso-values; none with them
  /// (surface-driven refinement; see build()).
  std::optional<RmsTarget> rms;
  double threshold = 0;          ///< the paper's per-element threshold (data units), 0: off
  std::size_t max_vertices = 0;  ///< 0: no limit
  int max_level = 20;            ///< 0..40
  int start_level = -1;          ///< -1..12; -1: until edges <= 16 voxels
  Norm norm = Norm::kL2;
  Preconditioner preconditioner = Preconditioner::kAuto;
  double surface_tolerance = 0.5;  ///< voxels, for iso-aware refinement (> 0)
  bool check_against_u = false;    ///< surface-driven: refine where u misses the data's surfaces
  /// Surface-driven builds: false skips assembling and solving for u (values are then the
  /// data's interpolant, the assets' source anyway; iterations stay empty and no RMS error is
  /// reported). convert() sets it from its outputs.
  bool solve_u = true;
  /// ≥ 0: the error-bounded interpolating build (ApproximationOptions::max_sample_error, grids
  /// only): every sample within this of the hierarchy's interpolant; rms, threshold and the
  /// iso-values' refinement are then not used.
  double max_sample_error = -1;
  /// Refinement stops at this budget (Built::memory_limited); the default is half the RAM.
  MemoryBudget max_memory;
  /// Progress of the refine-solve iterations and of the surface passes; may be empty.
  std::function<void(const IterationStats&)> progress;
  std::function<void(const SurfacePassStats&)> surface_progress;
};

/// The hierarchy and solution built from a grid or read from a hierarchy file: one 2D or 3D
/// approximation with the grid's frame and value range.
struct Built {
  std::variant<Approximation<3>, Approximation<2>> approximation;
  GridTransform transform;
  std::string space;
  double value_min = 0, value_max = 0;
  double seconds = 0;
  /// Built around the iso-surfaces (ApproximationOptions::surface_driven): the mesh certifies
  /// the data's interpolant there, so assets are extracted from it when the volume is at hand.
  bool surface_driven = false;
  /// The memory the build was allowed (0: no budget); see memory_limited().
  std::size_t memory_budget_bytes = 0;
  /// The RMS target the build ran to (0: none), and for gridded input without --rms the
  /// estimated noise deviation of the samples (core/noise_estimate.h); target_from_noise when
  /// the noise, not --rms's default, set the target.
  double target_rms = 0;
  double noise_sigma = 0;
  bool target_from_noise = false;

  int dim() const { return std::holds_alternative<Approximation<2>>(approximation) ? 2 : 3; }
  template <int D>
  Approximation<D>& get() {
    return std::get<Approximation<D>>(approximation);
  }
  template <int D>
  const Approximation<D>& get() const {
    return std::get<Approximation<D>>(approximation);
  }
  /// Calls f(approximation) with the 2D or 3D alternative.
  template <class F>
  decltype(auto) visit(F&& f) const {
    return std::visit(std::forward<F>(f), approximation);
  }
  const std::vector<IterationStats>& iterations() const {
    return visit([](const auto& a) -> const std::vector<IterationStats>& { return a.iterations; });
  }
  const std::vector<SurfacePassStats>& surface_passes() const {
    return visit([](const auto& a) -> const std::vector<SurfacePassStats>& { return a.surface_passes; });
  }
  const std::string& stop_reason() const {
    return visit([](const auto& a) -> const std::string& { return a.stop_reason; });
  }
  /// Refinement stopped at the memory budget: the approximation is coarser than asked.
  bool memory_limited() const {
    return visit([](const auto& a) { return a.memory_limited; });
  }
  const std::vector<double>& values() const {
    return visit([](const auto& a) -> const std::vector<double>& { return a.values; });
  }
  std::size_t vertices() const {
    return visit([](const auto& a) { return a.hierarchy.vertex_count(); });
  }
  std::size_t leaves() const {
    return visit([](const auto& a) { return a.hierarchy.leaves().size(); });
  }
  int levels() const {
    return visit([](const auto& a) { return a.hierarchy.max_level() + 1; });
  }
};

/// Runs the adaptive approximation on `grid`. With iso values and no global target (rms,
/// threshold, max_vertices), refinement is surface-driven (ApproximationOptions::
/// surface_driven); with one, the global target drives it and the iso values add iso-aware marks.
/// Throws mlfe::Error for unusable grids (fewer than 2 samples along an axis, values that do not
/// fill the dims, non-positive spacing) or options out of range.
Built build(const ScalarGrid& grid, const BuildOptions& options, const std::vector<double>& iso_values = {});

/// What build() records about an input function besides the function itself.
struct FieldInput {
  GridTransform transform;  ///< the field's local frame → physical coordinates
  std::string space;        ///< "RAS", "LPS" or ""
  std::string source;       ///< the file (for messages)
  double bytes = 0;         ///< memory the input holds, counted against BuildOptions::max_memory
};

/// The same on any input function: the domain is [0, f.extent()], the value range f.range().
/// The grid overload checks its grid and calls this one.
Built build(const Field& f, const FieldInput& input, const BuildOptions& options,
            const std::vector<double>& iso_values = {});

/// The frame of a mesh input: origin at the field's box corner, spacing its resolution() on
/// every axis (tolerances "in voxels" are then in units of the mesh's fine edges).
FieldInput mesh_input(const TetMeshField& f, const TetMesh& mesh);

/// build() on a tetrahedral mesh's P1 interpolant (TetMeshField).
Built build(const TetMesh& mesh, const BuildOptions& options, const std::vector<double>& iso_values = {});

/// Loads a hierarchy file as a Built (values required). With max_level ≥ 0, only T_max_level
/// and its values (read_hierarchy: a v2/v3 file is read up to that level's section only).
Built built_from_file(const std::string& path, int max_level = -1);

/// The lattice fields of a hierarchy file (HierarchyFileInfo::on_lattice, lattice_level,
/// data_dims) from an approximation, and back: the approximation's on_lattice, lattice and
/// data_extent from a file's fields and frame (off the lattice: on_lattice false).
template <int D>
void set_lattice_info(const Approximation<D>& a, HierarchyFileInfo& info);
template <int D>
void set_lattice(const HierarchyFileInfo& info, Approximation<D>& a);

/// Writes the hierarchy (.mlfeh) with provenance.
void write_built(const std::string& path, const Built& b, const nlohmann::json& provenance);

/// The JSON report of a build (input, dims, voxels, vertices, elements, levels, iterations,
/// errors, PSNR, value range, seconds, peak RSS, per-iteration rows).
nlohmann::json build_report(const std::string& input, const ScalarGrid* grid, const Built& b);

enum class Simplifier { kAuto, kFast, kBounded, kMeshopt };
enum class VertexPlacement { kAuto, kInput, kOptimal };
enum class Normals { kAuto, kGradient, kSurface };

/// The command line's spelling of each option value ("auto", "fast", "input", "gradient", ...).
const char* to_string(Simplifier s);
const char* to_string(VertexPlacement p);
const char* to_string(Normals n);

struct AssetOptions {
  std::vector<double> iso;   ///< iso-values (3D volumes; required there)
  double tolerance = 0;      ///< mm for Draco/quantization; 0: a tenth of the smallest voxel spacing
  bool draco = true;         ///< glTF with KHR_draco_mesh_compression (else plain buffers)
  bool quantize = false;     ///< glTF without Draco: KHR_mesh_quantization
  int lod = 0;               ///< coarser levels to add to glTF (0..8)
  std::size_t decimate = 0;  ///< triangle budget per surface (OpenMesh quadric decimation), 0: off
  /// Simplification tolerance in voxels (0: the raw extraction). The default keeps assets
  /// compact (bench/convert_bench.py).
  double simplify = 0.3;
  /// kBounded: simplify_within, error verified; kFast: the same collapses and topology checks
  /// with the error estimated from the quadrics (SimplifyOptions::verify_bound false);
  /// kMeshopt: meshoptimizer (simplify_fast), error estimated, seconds for millions of
  /// triangles but it may pinch the surface (non-manifold spots, counted in the report); kAuto:
  /// bounded for surfaces of up to 200 000 extracted triangles, meshopt above.
  Simplifier simplifier = Simplifier::kAuto;
  double snap = 1.0;  ///< move vertices onto the data's surface, at most this many voxels (0: off)
  /// Drop connected parts of a 3D surface whose vertices lie in fewer than this many voxel
  /// cells (0: keep every part of the data's surface); Surfaces::dropped counts them.
  std::size_t min_component = 0;
  bool normals_toward_higher = false;
  /// kGradient: the paper's normals (volume-weighted tetrahedron gradients of u, interpolated
  /// along the cut edge), kept through simplification; kSurface: area-weighted normals of the
  /// written triangles, so shading follows the asset's own silhouette and Draco predicts them
  /// from the geometry; kAuto: gradient for extracted surfaces, surface once simplify or
  /// decimate has made new triangles. decimate moves vertices, so its output always has
  /// surface normals.
  Normals normals = Normals::kAuto;
  /// simplify's vertex placement: kInput (half-edge collapses: every vertex an extracted,
  /// snapped one), kOptimal (quadric minimum near the surface: fewer triangles at the same
  /// bound, smoother, slower) or kAuto (optimal, but input with gradient normals, which hold
  /// only at extracted vertices).
  VertexPlacement placement = VertexPlacement::kAuto;
  double z_scale = 1.0;  ///< 2D height fields: height per data unit
  int level = -1;        ///< extract on this level (-1 finest)
};

/// The surfaces of an extraction, ready to write, with the choices the options resolved to.
struct Surfaces {
  std::vector<GltfSurface> surfaces;  ///< one per iso-value, ascending (3D), or the height field
  std::vector<double> iso_values;     ///< ascending (empty in 2D)
  bool snapped = false;               ///< vertices were moved onto the volume's own surface
  std::vector<Dropped> dropped;       ///< per surface: what AssetOptions::min_component dropped
  VertexPlacement placement = VertexPlacement::kOptimal;  ///< kInput or kOptimal
  Normals normals = Normals::kGradient;                   ///< kGradient or kSurface
  double extract_seconds = 0, simplify_seconds = 0;       ///< extraction (and snapping); the rest
};

/// Extracts, simplifies and decimates the surfaces of `b`. `grid` is the volume `b` was built
/// from, or nullptr (a hierarchy file): with it, 3D surfaces are snapped onto the data's own
/// iso-surface (AssetOptions::snap). Throws mlfe::Error without iso-values for a 3D `b`.
Surfaces extract(const Built& b, const AssetOptions& o, const ScalarGrid* grid = nullptr);

/// Checks before any work that `path` has one of `extensions` (lower case, with the dot) and
/// that its folder exists; throws mlfe::Error naming the path otherwise.
void check_output_path(const std::string& path, const std::vector<std::string>& extensions);

/// The output types of write_assets.
extern const std::vector<std::string> kAssetExtensions;

/// Extracts the surfaces of `b` (extract()) and writes them to `out` by extension (.glb .gltf
/// .drc .ply .obj .stl .off; one merged mesh for the single-mesh formats), atomically.
/// `provenance` goes into the glTF's extras. Returns a JSON summary (triangles per surface,
/// bytes, seconds).
nlohmann::json write_assets(const std::string& out, const Built& b, const AssetOptions& o,
                            const nlohmann::json& provenance, const ScalarGrid* grid = nullptr);

struct ConvertOptions {
  BuildOptions build;
  AssetOptions asset;
  std::string hierarchy;  ///< also write the hierarchy here (.mlfeh); empty: no
  std::string report;     ///< also write the JSON report (build_report + "asset") here; empty: no
  /// Recorded in the asset's extras and the hierarchy's metadata, over the pipeline's own
  /// entries (input file name, tool, errors, options): e.g. {"options": {"rms": "2.0"}} keeps
  /// the spelling a caller was given.
  nlohmann::json provenance = nlohmann::json::object();
  /// Surface-driven builds solve for u only when an output holds it (the hierarchy); true also
  /// solves it for the caller (e.g. to render ConvertResult::built).
  bool keep_u = false;
};

struct ConvertResult {
  Built built;
  nlohmann::json asset;  ///< write_assets' summary
};

/// Volume in, asset out: build (surface-driven around asset.iso unless a global target is set),
/// then write_assets with the volume at hand, and the hierarchy and report when asked. All
/// output paths are checked before any work.
ConvertResult convert(const ScalarGrid& grid, const std::string& out, const ConvertOptions& options);
/// The same from a tetrahedral mesh with point values: assets from its P1 interpolant (no
/// snapping: that needs a voxel volume).
ConvertResult convert(const TetMesh& mesh, const std::string& out, const ConvertOptions& options);
/// The same from a volume file (any format read_volume reads) or a tetrahedral mesh file
/// (.vtu, .msh; read_tet_mesh with tet_mesh_read_options(read)).
ConvertResult convert(const std::string& input, const std::string& out, const ConvertOptions& options,
                      const VolumeReadOptions& read = {});

/// Options of convert_labels (`mlfe convert --labels`): a label map in, one closed, named,
/// coloured surface per structure out (core/label_surface.h).
struct LabelOptions {
  /// The structures to write; empty: every label present except the background 0. Labels not
  /// picked count as background, so the picked ones stay closed where they touched them.
  std::vector<std::uint16_t> labels;
  /// Label table (formats/label_table.h); must parse. Empty: the file beside the volume with its
  /// stem (find_label_table on the grid's source) when it parses as a table (else a warning),
  /// else label_N names and the fixed palette.
  std::string table;
  /// A table held in memory in the JSON table format (the one a label hierarchy stores), used
  /// when `table` is empty instead of a file beside the volume; `table_json_source` names it.
  std::string table_json, table_json_source;
  /// 6-connected pieces of a label with fewer voxels take their surroundings' label (0: keep
  /// every island).
  std::size_t min_component = 0;
  int smoothing_iterations = 20;  ///< Taubin λ|μ pairs (0: the extracted interfaces)
  double max_offset = 0.5;        ///< voxels: no vertex moves further from the extracted interface
  /// voxels: the RMS distance to the smoothed interfaces' planes that each merge of the quadric
  /// edge collapse may reach (0: none). 0.34 meets mean <= 0.15 and Hausdorff <= 1.5 voxels per
  /// structure on the JHU atlas with fewer triangles than the Slicer-like VTK pipeline
  /// (bench/RESULTS.md).
  double simplify = 0.34;
  bool draco = true;
  bool quantize = false;
  double tolerance = 0;  ///< mm for Draco/quantization; 0: a tenth of the smallest voxel spacing
  /// Called with each warning (table labels absent from the volume, picked labels absent).
  std::function<void(const std::string&)> warn;
};

/// Parses a label list "3,7-9" (ascending ranges, 0..65535); throws mlfe::Error on bad text.
std::vector<std::uint16_t> parse_label_list(const std::string& text);

/// A label map in, structures out: labels checked (integers 0..65535, else mlfe::Error before
/// any output), small pieces relabelled (min_component), multi-material marching tetrahedra on
/// the Kuhn triangulation of the samples, smoothing and simplification of the shared interface
/// complex, then one surface per structure, named and coloured from the table. .glb/.gltf: one
/// mesh and node per structure (node extras: label, voxels, volume_mm3); the single-mesh
/// formats (.drc .ply .obj .stl .off) need exactly one structure. Returns the summary (per
/// structure: label, name, voxels, volume_mm3, triangles, vertices, pieces, closed), written
/// atomically to `out`; `provenance` goes into the glTF's asset extras.
nlohmann::json convert_labels(const ScalarGrid& grid, const std::string& out, const LabelOptions& options,
                              const nlohmann::json& provenance = nlohmann::json::object());

/// Writes JSON atomically.
void write_json(const std::string& path, const nlohmann::json& j);

/// Peak resident set size of this process in MiB.
double peak_rss_mb();

}  // namespace mlfe
