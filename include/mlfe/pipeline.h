// The volume → hierarchy → assets pipeline as a library (mlfe::pipeline), used by `mlfe build`,
// `mlfe iso`, `mlfe convert`, `mlfe render`, the Python module and asset pipelines that embed
// the converter: the adaptive build, iso-surface extraction, and writing by output extension.
// Options are typed; their defaults are the command line's. Bad input or options throw
// mlfe::Error with a one-line message; nothing is printed (progress goes to the callbacks).
#pragma once
#include <mlfe/core/base/error.h>
#include <mlfe/core/base/usage_error.h>
#include <mlfe/core/fem/approximation.h>
#include <mlfe/core/fem/hierarchy_resample.h>
#include <mlfe/core/field/scalar_grid.h>
#include <mlfe/core/field/tet_mesh_field.h>
#include <mlfe/core/render/volume_render.h>
#include <mlfe/core/simplify/simplifier.h>
#include <mlfe/core/surface/iso_surface.h>
#include <mlfe/core/surface/triangle_mesh.h>
#include <mlfe/formats/asset_writer.h>
#include <mlfe/formats/gltf_writer.h>
#include <mlfe/formats/hierarchy_io.h>
#include <mlfe/formats/tet_mesh_reader.h>
#include <mlfe/formats/volume_reader.h>
#include <mlfe/pipeline/compare.h>

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <utility>
#include <variant>
#include <vector>

namespace mlfe {

// ---- progress and cancel (of mlfe::build and every mlfe::pipeline call) ----

/// Called with the fraction of the call's work done, in [0, 1] and non-decreasing within one
/// call, and the stage it is in: "reading", "building", "extracting", "simplifying",
/// "rendering", "resampling", "writing". A call reports 0 when it starts and 1 when its outputs
/// are written. Returning false cancels: the call stops at its next report and throws Cancelled.
/// Called on the calling thread only, never concurrently; it may be empty.
using Progress = std::function<bool(double fraction, const std::string& stage)>;

/// Thrown by a call whose Progress returned false or whose CancelToken was cancelled; no output
/// file of the call exists afterwards. An mlfe::Error, so callers that catch mlfe::Error at the
/// top (the command line: "mlfe: cancelled", status 2) need nothing more. what(): "cancelled".
class Cancelled : public Error {
 public:
  Cancelled() : Error("cancelled") {}
};

/// A flag another thread may set to stop a call: pass token.progress() (or
/// token.progress(your_callback)) as the call's Progress. Copies share the flag.
class CancelToken {
 public:
  CancelToken() : flag_(std::make_shared<std::atomic<bool>>(false)) {}
  void cancel() const { flag_->store(true); }
  bool cancelled() const { return flag_->load(); }
  /// A Progress that returns false once cancel() was called, after forwarding to `inner`.
  Progress progress(Progress inner = {}) const;

 private:
  std::shared_ptr<std::atomic<bool>> flag_;
};

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
  /// The fraction of the refinement done, stage "building": by the RMS error reached toward the
  /// target (log scale), the vertices toward max_vertices or the levels toward max_level,
  /// whichever is furthest; surface passes by their count. Returning false throws Cancelled
  /// from build() (between passes). May be empty.
  Progress fraction_progress;
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
  /// estimated noise deviation of the samples (core/field/noise_estimate.h); target_from_noise when
  /// the noise, not --rms's default, set the target.
  double target_rms = 0;
  double noise_sigma = 0;
  bool target_from_noise = false;
  /// The options the build ran with (build_options_record), kept in the hierarchy file.
  nlohmann::json options = nlohmann::json::object();

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

/// Writes the hierarchy (.mlfeh) with provenance: format version 3 with exact values, or
/// version 1 when the level-by-level rebuild would not reproduce the hierarchy. Returns the
/// warning saying so ("" when version 3 was written); prints nothing.
std::string write_built(const std::string& path, const Built& b, const nlohmann::json& provenance);

/// The JSON report of a build (input, dims, voxels, vertices, elements, levels, iterations,
/// errors, PSNR, value range, seconds, peak RSS, per-iteration rows).
nlohmann::json build_report(const std::string& input, const ScalarGrid* grid, const Built& b);

/// The options of a build as its record keeps them: the option table's keywords (rms as "0.5%"
/// or a number in data units, norm and preconditioner by name, max_memory as given) and the
/// iso-values. Depends on the options only, not on the machine.
nlohmann::json build_options_record(const BuildOptions& options, const std::vector<double>& iso_values);

/// What a build did, as a hierarchy file keeps it in its metadata under "build": stop_reason,
/// surface_driven, memory_limited, rms_target, noise_sigma, target_from_noise, options, and the
/// per_iteration and surface_passes rows of build_report without their times (a file's bytes
/// depend on its input and options only, so `seconds` is not kept). Rows also hold l2_error
/// and cg_residual.
nlohmann::json build_record(const Built& b);

/// Puts the record in `metadata` (a hierarchy file's, read from `path`) back into `b`: after it
/// b's stop_reason(), iterations(), surface_passes(), memory_limited(), surface_driven, noise,
/// target and options are the build's, and build_report(b) its report but for the times.
/// Metadata without "build" leaves b as it is. Throws mlfe::Error naming `path` for a record of
/// the wrong shape.
void restore_build_record(const std::string& path, const nlohmann::json& metadata, Built& b);

enum class VertexPlacement { kAuto, kInput, kOptimal };
enum class Normals { kAuto, kGradient, kSurface };
enum class SurfaceSource { kAuto, kSamples, kHierarchy };

/// The command line's spelling of each option value ("auto", "fast", "input", "gradient", ...).
const char* to_string(Simplifier s);
const char* to_string(VertexPlacement p);
const char* to_string(Normals n);
const char* to_string(SurfaceSource s);

struct AssetOptions {
  std::vector<double> iso;   ///< iso-values (3D volumes; required there)
  double tolerance = 0;      ///< mm for Draco/quantization; 0: a tenth of the smallest voxel spacing
  bool draco = true;         ///< glTF with KHR_draco_mesh_compression (else plain buffers)
  bool quantize = false;     ///< glTF without Draco: KHR_mesh_quantization
  int lod = 0;               ///< coarser levels to add to glTF (0..8)
  std::size_t decimate = 0;  ///< triangle budget per surface (OpenMesh quadric decimation), 0: off
  /// Simplification tolerance in voxels (0: the raw extraction). The default keeps assets
  /// compact (bench/py/convert_bench.py).
  double simplify = 0.3;
  /// Simplification stops at this fraction of each extracted surface's triangles, or earlier
  /// where the `simplify` bound binds (0: the bound alone). The default gives assets of about a
  /// tenth of the marching-cubes triangles, as asset pipelines' ratio simplifiers do, with the
  /// error well inside the bound.
  double ratio = 0.1;
  /// Which simplifier (core/simplify/simplifier.h says what each kind does: kBounded verified,
  /// kFast and kMeshopt estimated, kAuto by size); kMeshopt's non-manifold spots are counted in
  /// the report.
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
  /// snapped one), kOptimal (quadric minimum near the surface, then the least-squares refit of
  /// every vertex to the extracted surface, core/surface/surface_fitting.h: fewer triangles at the same
  /// bound, closer to the data, smoother, slower) or kAuto (optimal, but input with gradient normals, which
  /// hold only at extracted vertices).
  VertexPlacement placement = VertexPlacement::kAuto;
  double z_scale = 1.0;  ///< 2D height fields: height per data unit
  int level = -1;        ///< extract on this level (-1 finest)
  /// Where 3D surfaces come from. kSamples: marching cubes on the samples' lattice
  /// (lattice_iso_surface: the data's own surface, the hierarchy's finest level without building
  /// it; needs the volume and the finest level); kHierarchy: marching tetrahedra on T_level
  /// (IsoExtractor, the paper's); kAuto: the samples when the volume is at hand and the finest
  /// level is asked, else the hierarchy. LODs always come from the hierarchy.
  SurfaceSource surface = SurfaceSource::kAuto;
  /// Extract and simplify 3D surfaces from the samples in bricks of this many samples per edge
  /// (a power of two; core/simplify/bricked_iso_surface.h): threads over bricks, the same output
  /// for any thread count. When no output needs the whole volume (see reads_in_bricks), convert
  /// reads it window by window and builds no hierarchy. 0: the whole surface at once. -1 (auto):
  /// convert() takes auto_bricks() for a file read_volume's windows read box by box
  /// (reads_in_windows: raw, NIfTI, NRRD raw or gzip, MetaImage, OME-Zarr); anything else takes 0.
  std::int64_t bricks = -1;
  /// extract(): stages "extracting" and "simplifying"; write_assets(): the same in its first
  /// 0.8, then "writing". Returning false throws Cancelled (nothing written). May be empty.
  Progress progress;
};

/// The surfaces of an extraction, ready to write, with the choices the options resolved to.
struct Surfaces {
  std::vector<GltfSurface> surfaces;  ///< one per iso-value, ascending (3D), or the height field
  std::vector<double> iso_values;     ///< ascending (empty in 2D)
  bool snapped = false;               ///< vertices were moved onto the volume's own surface
  SurfaceSource source = SurfaceSource::kHierarchy;  ///< kSamples or kHierarchy
  std::vector<Dropped> dropped;  ///< per surface: what AssetOptions::min_component dropped
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

/// Extracts the surfaces of `b` (extract()) and writes them to `out` with write_asset
/// (<mlfe/formats/asset_writer.h>: by extension, one of kAssetExtensions), atomically.
/// `provenance` goes into the glTF's extras. Returns a JSON summary (triangles per surface,
/// bytes, seconds).
nlohmann::json write_assets(const std::string& out, const Built& b, const AssetOptions& o,
                            const nlohmann::json& provenance, const ScalarGrid* grid = nullptr);

/// Extracts the iso-surfaces o.iso of the volume `v` in bricks of o.bricks samples
/// (core/simplify/bricked_iso_surface.h), reading it window by window: the volume is never
/// held whole when v.streamed(), and no hierarchy is built. The surfaces are the samples' (as
/// SurfaceSource::kSamples), simplified (o.simplify > 0), at the finest level, without LODs or a
/// part-size floor: other options throw pipeline::OptionError. An iso-value outside the data's
/// range throws pipeline::OptionInputError once the bricks have been read. o.progress counts
/// bricks ("extracting"); returning false throws Cancelled.
Surfaces extract(const VolumeWindows& v, const AssetOptions& o);

/// The pieces of a conversion read in bricks that can run apart (mlfe.distributed): the bricks'
/// passes on workers, the join and the writing on the client. extract(v, o) runs the same
/// pieces in one process, so write_bricks writes write_assets(out, v, o, provenance)'s bytes.
/// Each throws as extract(v, o) does for options it refuses.
/// The asset extras convert gives a volume `input` read in bricks (file name, tool, bricks).
nlohmann::json bricks_provenance(const std::string& input, const AssetOptions& o);
/// How many bricks `v` has for `o` (o.bricks samples per brick edge).
std::size_t brick_count(const VolumeWindows& v, const AssetOptions& o);
/// Brick `brick`'s passes, one per iso-value of `o`, read from `v` and encoded
/// (<mlfe/formats/brick_parts.h>). Throws mlfe::Error for a brick that is not one of `v`'s.
std::string brick_parts(const VolumeWindows& v, const AssetOptions& o, std::size_t brick);
/// The join of the slabs [first, end) of `v`'s bricks for `o` (join_slabs), encoded: `parts` are
/// the slab's bricks' brick_parts (end == first + 1) or the pieces of its halves (join_parts of
/// [first, slab_split) and [slab_split, end)). Throws mlfe::Error for parts that are not those.
std::string join_parts(const VolumeWindows& v, const AssetOptions& o, std::size_t first, std::size_t end,
                       std::vector<std::string> parts);
/// The asset joined from `parts` written to `out`, with write_assets' summary: `parts` are
/// brick_parts and join_parts (any order, each string released once read) that together hold
/// every node of the join tree, e.g. every brick's, or the two halves of the root. Throws
/// mlfe::Error for parts that are not those of `v`'s bricks, or some the tree does not use.
nlohmann::json write_bricks(const std::string& out, const VolumeWindows& v, const AssetOptions& o,
                            std::vector<std::string> parts, const nlohmann::json& provenance);

/// auto's brick edge for a volume of `dims` samples read window by window: 128 above 2^27 samples
/// (where the whole volume's surface and hierarchy would take gigabytes), else 0.
std::int64_t auto_bricks(const std::array<std::int64_t, 3>& dims);

/// True when convert() with these options reads the volume brick by brick (extract(const
/// VolumeWindows&, ...)): a.bricks set, the surfaces the samples' (AssetOptions::surface), simplified,
/// at the finest level, no LODs or part-size floor, and no output that holds the hierarchy or
/// needs the whole volume (`whole_volume_outputs`: a hierarchy file, an image, u kept).
bool reads_in_bricks(const BuildOptions& b, const AssetOptions& a, bool whole_volume_outputs);

/// write_assets for a volume read in bricks: extract(v, o), then the same file and summary.
nlohmann::json write_assets(const std::string& out, const VolumeWindows& v, const AssetOptions& o,
                            const nlohmann::json& provenance);

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
  /// The whole conversion: "building" (0..0.6), then the assets' stages and "writing".
  Progress progress;
};

struct ConvertResult {
  Built built;
  nlohmann::json asset;               ///< write_assets' summary
  nlohmann::json report;              ///< what ConvertOptions::report holds (written there or not)
  std::vector<std::string> warnings;  ///< e.g. the hierarchy written as version 1
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
/// coloured surface per structure out (core/labels/label_surface.h).
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
  /// What the conversion may use: the interfaces are counted before they are built, and a label
  /// map whose estimated peak (volume, labels and interfaces) is over the budget is refused with
  /// pipeline::OptionInputError instead of running out of memory. convert() passes its build's.
  MemoryBudget max_memory;
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

// ---------------------------------------------------------------------------------------------
// mlfe::pipeline: every command of the mlfe command line as one call, files in and files out,
// for C++ callers, the Python module and the command line itself (a thin layer that parses its
// text into these options and prints these results). Calls print nothing; what the command line
// prints is in the results. Bad input or options throw mlfe::Error (mlfe::UsageError for a bad
// option value) naming the file or the option; no output file of a failed or cancelled call
// exists afterwards (formats/atomic_file.h).
// ---------------------------------------------------------------------------------------------
namespace mlfe::pipeline {

// Progress, Cancelled and CancelToken are mlfe's (declared above with the build's options).
using mlfe::Cancelled;
using mlfe::CancelToken;
using mlfe::Progress;

// ---- the options by name: one table for the library, the command line and Python ----

/// Who names an option in a message.
enum class Spelling {
  kLibrary,      ///< the options struct's field: "max_level", "smoothing_iterations"
  kCommandLine,  ///< the flag: "--max-level", "--smooth-iterations"
  kPython,       ///< the keyword: "max_level", "smooth_iterations"
};

/// One option of the calls, its names and the values it takes: numbers in [min, max] (an end
/// left out with min_excluded / max_excluded; finite either way), an enum's names (choices),
/// or neither (the option has a parse function, or no values to check).
struct OptionSpec {
  const char* name;  ///< the library's: the field of the options struct
  const char* flag;  ///< the command line's
  double min = -std::numeric_limits<double>::infinity();
  double max = std::numeric_limits<double>::infinity();
  bool min_excluded = false, max_excluded = false;
  const char* keyword = nullptr;                    ///< Python's, when it differs from name
  std::vector<std::string> (*choices)() = nullptr;  ///< enum_name_list<E> of an enum option

  /// The option as `s` spells it.
  const char* spelled(Spelling s) const;
  /// What it takes, as messages and the command line's help say it: "0..40", "a finite value
  /// >= 0", "one of l2, h1"; "" for neither a range nor choices.
  std::string values() const;
};

/// Every option that has a range or choices or that a message names, once: the rows of its own
/// and those of the field tables (render_fields()). A new ranged option is a row here and a
/// check_option call where the library takes its value; a new render option is one row of
/// render_fields(), which the library checks and both front ends offer.
const std::vector<OptionSpec>& option_table();
/// The row of the library's `name`; a name the table lacks is a bug (CHECK).
const OptionSpec& option_spec(const std::string& name);
/// The row whose flag is `flag`, or nullptr.
const OptionSpec* option_by_flag(const std::string& flag);

/// `name` (a row of the table) marked in a message, so that each front end reads it in its own
/// spelling (OptionMessage); the library's what() shows `name`.
std::string option_ref(const std::string& name);

/// A message that names options (option_ref), in each front end's spelling.
class OptionMessage {
 public:
  std::string spelled(Spelling s) const;

 protected:
  explicit OptionMessage(std::string marked) : marked_(std::move(marked)) {}

 private:
  std::string marked_;
};

/// A bad option value, or options that cannot go together (a usage error).
class OptionError : public UsageError, public OptionMessage {
 public:
  explicit OptionError(const std::string& marked)
      : UsageError(spell_marked(marked, Spelling::kLibrary)), OptionMessage(marked) {}
  /// The message `marked` (option_ref) as `s` spells its options.
  static std::string spell_marked(const std::string& marked, Spelling s);
};

/// An mlfe::Error (bad input, not usage) whose message names options: an iso-value the data
/// never crosses, an option the input cannot take.
class OptionInputError : public Error, public OptionMessage {
 public:
  explicit OptionInputError(const std::string& marked)
      : Error(OptionError::spell_marked(marked, Spelling::kLibrary)), OptionMessage(marked) {}
};

/// The message of `e` as `s` spells options: OptionMessage's, else e.what().
std::string message(const std::exception& e, Spelling s);

/// (option, path) of a call's files: inputs named as messages name them ("input",
/// option_ref("label_table")), outputs by their row in option_table(); empty paths are skipped.
using NamedFiles = std::vector<std::pair<std::string, std::string>>;
/// Refuses before any work, with an OptionError naming the output: an output that is a file one
/// of `inputs` reads (input_files: the input itself, its sidecar, detached data, the other half
/// of a pair, buffer files), which the call would replace, and two outputs on one path. Files are
/// compared as a write would replace them: symbolic links followed, existing files also by
/// device and inode (hard links, other spellings). Every file-level call (convert, iso, build,
/// render, export_hierarchy, compare) checks its files so; Python's calls that read a volume by
/// name do too.
void check_distinct_files(const NamedFiles& inputs, const NamedFiles& outputs);

/// Throws OptionError naming `name` unless `value` is finite and in its row's range.
void check_option(const std::string& name, double value);
/// Throws OptionError naming `name` unless `text` is one of its row's choices (any case when
/// `ignore_case`).
void check_choice(const std::string& name, const std::string& text, bool ignore_case = false);

/// An enum member of the options struct O, by its names (enum_names).
template <class O>
struct EnumMember {
  std::function<void(O&, const std::string& text)> set;  ///< parse_enum, naming the option
  std::function<std::string(const O&)> get;              ///< enum_name
};

/// Where a field lives in its options struct O. Its type says how the front ends spell it: a
/// flag (bool), a number, text, "x,y,z" (three numbers, optional or not), "WxH" (an image size)
/// or an enum's name.
template <class O>
using OptionMember =
    std::variant<bool O::*, int O::*, double O::*, std::string O::*, std::array<double, 3> O::*,
                 std::optional<std::array<double, 3>> O::*, std::array<int, 2> O::*, EnumMember<O>>;

/// A row of option_table() that is a field of the options struct O, with what the front ends
/// need to offer it without code of their own: the command line adds one option per field and
/// Python reads one keyword per field, both by the member's type; a bool whose flag starts
/// with "--no-" is the flag that clears it. check_fields checks the values against the row.
template <class O>
struct OptionField {
  OptionSpec spec;
  std::string help;           ///< the command line's help (and Python's documentation)
  bool show_default = false;  ///< the help shows the default value
  OptionMember<O> member;
};

/// Sets a field that is spelled as text (text, "x,y,z", "WxH", an enum's name) from `text`
/// through the vocabulary's parse functions; throws OptionError naming it on bad text. Fields
/// of bool, int and double the front ends set typed (a bug otherwise: CHECK).
template <class O>
void set_option_text(const OptionField<O>& f, O& o, const std::string& text);
/// The field's value as its flag takes it ("0,0,0", "500x500", "ortho"; "" when unset).
template <class O>
std::string option_text(const OptionField<O>& f, const O& o);
/// Throws OptionError naming the first field of `fields` whose value in `o` is out of its
/// row's range (numbers; image sizes 1..16384).
template <class O>
void check_fields(const std::vector<OptionField<O>>& fields, const O& o);

// ---- the option vocabulary: one parse function per option type, for the CLI and Python ----
// `option` is the option's name in the table; each throws OptionError naming it on bad text.

/// "50%" (of the machine's RAM), bytes with an optional K/M/G suffix ("6G", "512m", "1000"),
/// or "0" (no budget).
MemoryBudget parse_memory_budget(const std::string& text, const std::string& option = "max_memory");
/// "0.5%" (of the value range) or an absolute value "2.0"; positive.
RmsTarget parse_rms(const std::string& text, const std::string& option = "rms");
/// "2%" or "2": a non-negative percentage.
double parse_percent(const std::string& text, const std::string& option);
/// "80,150": finite numbers, comma separated (empty text: none).
std::vector<double> parse_values(const std::string& text, const std::string& option);
/// "x,y,z": exactly three finite numbers.
std::array<double, 3> parse_vector3(const std::string& text, const std::string& option);
/// "WxH", 1..16384 each.
std::array<int, 2> parse_image_size(const std::string& text, const std::string& option = "size");

/// The projection of render's camera.
enum class Projection { kOrtho, kPerspective };

/// One name per value of every option enum (Norm, Preconditioner, Simplifier, VertexPlacement,
/// Normals, Projection, RayAccumulator::Rule), the command line's spelling ("l2", "bpx",
/// "meshopt", "optimal", "surface", "perspective", "preintegrated", ...): the one table the
/// command line, the Python module and the files' provenance use.
template <class E>
struct EnumName {
  E value;
  const char* name;
};
template <class E>
const std::vector<EnumName<E>>& enum_names();

/// The value named `text`; throws OptionError naming `option` and the choices otherwise.
template <class E>
E parse_enum(const std::string& text, const std::string& option);
/// The name of `value`.
template <class E>
const char* enum_name(E value);
/// Every name, in the table's order (for help texts and choices).
template <class E>
std::vector<std::string> enum_name_list();

// ---- info ----

struct InfoOptions {
  VolumeReadOptions read;
  bool labels = false;      ///< volumes: list the labels of a label map (label_grid)
  std::string label_table;  ///< with labels: names from this table (default: the one beside the volume)
};

struct LabelRow {
  std::uint32_t label = 0;
  std::string name;
  std::size_t voxels = 0;
  double volume_mm3 = 0;
};

struct LevelCounts {
  std::size_t vertices = 0, elements = 0, leaves = 0;  ///< of this level
};

/// What a volume or hierarchy file holds, without computing anything.
struct InfoResult {
  std::string file;
  bool hierarchy = false;  ///< a .mlfeh: the hierarchy fields below; else the volume fields
  double read_seconds = 0;
  std::vector<std::string> warnings;  ///< e.g. a label table beside the volume that does not parse
  int dim = 3;
  GridTransform transform;
  std::string space;
  // Volumes:
  std::string format;  ///< "nifti", "nrrd", "vdb", ...
  std::array<std::int64_t, 3> dims{1, 1, 1};
  std::uint64_t voxels = 0;
  std::string type;  ///< the stored scalar type ("uint8", "float32", ...)
  std::array<double, 2> range{0, 0};
  std::uint64_t memory_bytes = 0;  ///< as float32
  std::string notes;               ///< the reader's notes, one per line
  std::vector<std::string> grids;  ///< OpenVDB: the file's grids
  bool has_labels = false;         ///< InfoOptions::labels was set
  std::vector<LabelRow> labels;    ///< with InfoOptions::labels
  std::string label_table;         ///< the table the names came from ("" none)
  // Hierarchies (the file's header; HierarchyFile without the mesh and values):
  HierarchyFileInfo header;
  int version = 0;
  std::size_t vertices = 0, elements = 0, leaves = 0;
  int levels = 0;
  std::string value_coding;  ///< "none", "integer", "quantized", "exact"
  double value_bound = 0;
  bool integer_values = false;
  std::vector<LevelCounts> per_level;
  std::vector<HierarchySection> sections;

  /// What `mlfe info --json` prints.
  nlohmann::json to_json() const;
};

/// `mlfe info`: reads `file` (a volume, or a hierarchy by its magic) and describes it. Throws
/// mlfe::Error for unreadable files and, with options.labels, values that are not labels.
InfoResult info(const std::string& file, const InfoOptions& options = {});

// ---- build ----

struct BuildFileOptions {
  BuildOptions build;      ///< the build's options (its stats callbacks are called too)
  VolumeReadOptions read;  ///< read.max_bytes 0: build.max_memory's bytes
  /// ≥ 0: every sample of the decoded file within this of the input (data units; 0 on integer
  /// data: lossless), split between interpolation and quantization by quantization_share.
  /// < 0: the least-squares build of build.rms with values quantized to half its RMS error.
  double max_error = -1;
  /// [0, 1]. 1 (all of max_error on the values; leaves refined until they interpolate the
  /// samples exactly) gave the smallest files at equal maximum error and at equal PSNR on
  /// integer and real scans (bench/RESULTS.md, issue 44); less trades values' precision for
  /// coarser leaves.
  double quantization_share = 1;
  double psnr = 0;  ///< > 0: quantization error alone at this PSNR (dB over the range)
  /// A label map (segmentation, atlas): stored exactly (every decoded sample rounds to its
  /// label; refined where labels meet) with its label table in the file's metadata; excludes
  /// max_error and psnr.
  bool labels = false;
  std::string label_table;  ///< with labels: the table to store (empty: the one beside the volume)
  std::string report;       ///< also write the JSON report here; empty: no
  Progress progress;
};

/// The hierarchy file as written and its error figures, measured from exactly the values a
/// reader decodes.
struct HierarchyFileFigures {
  GridErrors errors;  ///< at the samples (voxels) or the mesh's points
  double bound = 0;   ///< every stored value within this (0: exact)
  double encode_seconds = 0;
  int version = 4;
  std::string coding;       ///< "quantized", "integer", "exact"
  double tolerance = 0;     ///< max_error: the interpolation's share
  std::uint64_t bytes = 0;  ///< the file's size
  double samples = 0;       ///< voxels or mesh points, for bits per sample
  bool on_voxels = true;    ///< errors at the voxels (else at the mesh's points)
};

struct BuildFileResult {
  /// The build, its hierarchy in the file's numbering (the canonical order of its levels, the
  /// same mesh; values renumbered with it) and without Approximation::leaf_errors.
  Built built;
  HierarchyFileFigures file;
  double max_error = -1;              ///< the bound asked for (< 0: none), verified when ≥ 0
  std::vector<std::string> warnings;  ///< e.g. a label table beside the volume not used
  std::vector<std::string> written;   ///< the hierarchy, then the report
};

/// `mlfe build`: a volume or a tetrahedral mesh with point values (.vtu, .msh) to a hierarchy
/// file (.mlfeh), values quantized (or bounded by max_error), with the JSON report when asked.
BuildFileResult build(const std::string& input, const std::string& output, const BuildFileOptions& options);

// ---- render ----

struct RenderFileOptions {
  std::string tf = "grey";  ///< a preset (transfer_function_presets()) or a ParaView .json
  double tf_unit = 0;       ///< opacity unit length (mm); 0: one voxel (presets), 1 (JSON)
  Projection camera = Projection::kOrtho;
  double azimuth = 0, elevation = 0;  ///< degrees: the orbit camera around the volume's centre
  /// Physical frame; position replaces the orbit, target (default: the centre) and up
  /// (default 0,0,1) need it.
  std::optional<std::array<double, 3>> position, target, up;
  std::array<int, 2> size{500, 500};
  int level = -1;          ///< render the approximation on this level (-1: finest)
  bool reference = false;  ///< ray-cast the original voxels instead (needs the volume)
  RayAccumulator::Rule integration = RayAccumulator::Rule::kPreIntegrated;
  bool shading = false;
  bool skip_empty = true;
  std::string png;  ///< also an sRGB PNG preview over `background`; empty: no
  int frames = 1;   ///< > 1: a turntable about +z, numbered files OUT_0000.exr, ...
  std::array<double, 3> background{0, 0, 0};
  double stop_opacity = 0.99;
  double z_opacity = 0.5;
  BuildOptions build;        ///< a volume input is built first (as mlfe build)
  VolumeReadOptions read;    ///< read.max_bytes 0: build.max_memory's bytes
  bool keep_images = false;  ///< keep every frame's image in the result (files are written anyway)
  Progress progress;
};

/// The render options the front ends offer (all but build, read, keep_images and progress), in
/// the command line's order: each field's row, help and member. A new one is its member above,
/// its row here (pipeline_vocabulary.cpp) and its use in the renderer.
const std::vector<OptionField<RenderFileOptions>>& render_fields();

struct RenderFrame {
  std::string exr, png;  ///< written files ("" when not written)
  int width = 0, height = 0;
  double seconds = 0;
  RenderStats stats;
  Camera camera;
  RenderImage image;  ///< with keep_images, or from render_images()
};

struct RenderResult {
  std::vector<RenderFrame> frames;
  std::size_t tetrahedra = 0;  ///< the render mesh (0 for the reference)
  int level = 0;
  std::size_t mesh_bytes = 0;        ///< what the renderer added, step records as far as built
  Built built;                       ///< what was rendered (the file's or the build's)
  std::vector<std::string> written;  ///< every file, in order
};

/// Renders `b` (or with options.reference the volume `grid`, then required) in memory: the
/// frames' images and statistics, no files. Throws mlfe::Error for a 2D `b` or bad options.
RenderResult render_images(const Built& b, const RenderFileOptions& options, const ScalarGrid* grid = nullptr,
                           const std::string& source = "");

/// The same, written to `output` (.exr, half RGBA premultiplied and float Z, with the camera
/// and the transfer function in the header) and options.png.
RenderResult render(const Built& b, const std::string& output, const RenderFileOptions& options,
                    const ScalarGrid* grid = nullptr, const std::string& source = "");

/// `mlfe render`: a hierarchy file, a volume built first, or a tetrahedral mesh with point
/// values (.vtu, .msh; read.grid_name names the array) rendered as it is, to `output`.
RenderResult render(const std::string& input, const std::string& output, const RenderFileOptions& options);

/// An unstructured tetrahedral mesh with point values (a finite-element solution) rendered
/// directly, no build: the mesh is T0 and the finest level, rays enter and re-enter it through
/// its boundary faces (RayEntry::kBoundaryFaces), so it need not be convex nor fill its box.
/// Physical frame = the mesh's coordinates; preset opacities per its fine edge length (10th
/// percentile) unless options.tf_unit; build and level options do not apply (level -1 or 0).
/// Tetrahedra of zero volume are left out. Throws mlfe::Error ("<mesh.source>: ...") for
/// values that do not match the points, bad indices, non-finite numbers, no tetrahedron of
/// positive volume, or a face shared by more than two tetrahedra (not a conforming mesh).
/// Result::built holds the one-level hierarchy.
RenderResult render(const TetMesh& mesh, const std::string& output, const RenderFileOptions& options);
RenderResult render_images(const TetMesh& mesh, const RenderFileOptions& options);

// ---- convert and iso ----

struct ConvertFileOptions {
  BuildOptions build;
  AssetOptions asset;
  VolumeReadOptions read;  ///< read.max_bytes 0: build.max_memory's bytes
  std::string hierarchy;   ///< also write the hierarchy here (.mlfeh); empty: no
  std::string report;      ///< also write the JSON report here; empty: no
  /// Also a ray-cast image (.exr) of the hierarchy built, with RenderFileOptions' defaults.
  std::string render;
  /// With render: also the image as an sRGB PNG (RenderFileOptions::png).
  std::string png;
  /// Also the preview page of the asset (.html, <mlfe/pipeline/preview.h>): the output must be
  /// glTF; the page shows the report's figures and the png when there is one.
  std::string preview;
  /// Set: a label map in, one surface per structure out (convert_labels) instead of
  /// iso-surfaces; asset.iso must then be empty, hierarchy and render too.
  std::optional<LabelOptions> labels;
  /// Over the pipeline's own entries in the asset's extras and the hierarchy's metadata.
  nlohmann::json provenance = nlohmann::json::object();
  Progress progress;
};

struct ConvertFileResult {
  Built built;                        ///< (labels: empty)
  nlohmann::json asset;               ///< write_assets' (or convert_labels') summary
  std::vector<std::string> warnings;  ///< label warnings, a version-1 hierarchy
  std::vector<std::string> written;   ///< the asset, then hierarchy, report, images, preview
  RenderResult render;                ///< with ConvertFileOptions::render (its built is empty)
};

/// `mlfe convert`: a volume or tetrahedral mesh file in, an asset out by extension (.glb .gltf
/// .drc .ply .obj .stl .off), and the hierarchy, report and image when asked. Output paths are
/// checked before any work.
ConvertFileResult convert(const std::string& input, const std::string& output,
                          const ConvertFileOptions& options);

/// The volume `input` opened (VolumeWindows, its header only where the format allows) when
/// convert(input, out, o) reads it in bricks (reads_in_bricks), else nullopt; auto's brick edge
/// (o.asset.bricks < 0) is resolved in `o` first, as convert resolves it: auto_bricks for a file
/// read box by box (reads_in_windows), 0 for anything else. mlfe.distributed splits that same conversion over
/// workers (brick_parts, write_bricks). Throws as VolumeWindows does for an unreadable input.
std::optional<VolumeWindows> open_in_bricks(const std::string& input, ConvertFileOptions& o);

struct IsoOptions {
  AssetOptions asset;
  BuildOptions build;      ///< a volume input is built first (as convert)
  VolumeReadOptions read;  ///< for a volume input or `volume`
  /// With a hierarchy input: the volume it was built from (same frame and box, else
  /// mlfe::Error), so surfaces snap onto it as in convert.
  std::string volume;
  std::string report;  ///< also write the JSON report here; empty: no
  Progress progress;
};

/// `mlfe iso`: iso-surfaces of a hierarchy file (or of a volume, as convert) written to `output`.
ConvertFileResult iso(const std::string& input, const std::string& output, const IsoOptions& options);

// ---- export ----

struct ExportOptions {
  int level = -1;  ///< use levels 0..level only (-1: all)
  Progress progress;
};

struct ExportResult {
  bool mesh = false;  ///< .vtu/.msh: the leaf mesh; else a voxel grid
  std::size_t elements = 0, vertices = 0;
  int level = 0;                              ///< the finest level used
  std::array<std::int64_t, 3> dims{1, 1, 1};  ///< grids
  double resample_seconds = 0;
  std::vector<std::string> written;  ///< the output (and a .raw's sidecar)
};

/// `mlfe export`: a hierarchy file's approximation on its voxel grid (.nii.gz .nii .nrrd .raw
/// .vdb) or its leaf mesh with values and levels (.vtu .msh), in the file's frame.
ExportResult export_hierarchy(const std::string& input, const std::string& output,
                              const ExportOptions& options = {});

// ---- option checks ----
// Each call checks its options with these before any work: every value in its row's range in
// option_table(), and the pairs that cannot go together. Each throws OptionError.

void check_options(const BuildOptions& o);
void check_options(const AssetOptions& o);
void check_options(const LabelOptions& o);
/// render_fields() and the pairs, with o.build (a volume input is built first) and o.read;
/// `level` against the hierarchy is render's own.
void check_options(const RenderFileOptions& o);
/// With o.build and o.read.
void check_options(const BuildFileOptions& o);
/// The raw data's type and byte order, the space's name, offsets and levels, nan_as finite.
void check_options(const VolumeReadOptions& o);
/// Every tolerance, angle and figure finite and >= 0 (compare_files and compare_meshes call it).
void check_options(const CompareOptions& o);

// ---- compare ----

/// `mlfe compare`: compare_files (<mlfe/pipeline/compare.h>), and the JSON report written to `report`
/// when given.
CompareResult compare(const std::string& expected, const std::string& actual,
                      const CompareOptions& options = {}, const std::string& report = "");

}  // namespace mlfe::pipeline
