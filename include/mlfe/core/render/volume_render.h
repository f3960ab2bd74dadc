// Direct volume rendering of the piecewise-linear approximation u by ray casting through the
// adaptive tetrahedral mesh, face to face: R. Grosso, C. Lürig, T. Ertl, "The Multilevel Finite
// Element Method for Adaptive Mesh Optimization and Visualization of Volume Data", IEEE
// Visualization 1997, Sec. 6. Sampling follows the mesh: one exactly integrated segment per
// tetrahedron crossed (core/render/transfer_function.h), so a coarse level gives a fast, exact image
// of a coarser function. Also a reference ray caster on the original voxels.
//
// Traversal (per ray):
//   1. clip the ray to the domain box (slab test); when rendering with empty-space skipping,
//      move its start to just before the first cell of a coarse grid that a visible element
//      overlaps (3D DDA; everything in front is transparent, so the image does not change);
//   2. find the entry tetrahedron by a short walk from the previous pixel's entry, else by
//      descending the hierarchy from T0 (the child containing a point just behind the entry
//      point along the ray);
//   3. step through face neighbours of the rendered triangulation T_k; the exit face is the
//      face plane the ray crosses first among those it leaves through (outward normal · d > 0),
//      never the face it came in by, so a ray through a vertex or along an edge walks the ring
//      of tetrahedra around it toward the direction of the ray instead of bouncing back;
//   4. empty space: a tetrahedron whose value range maps to zero opacity is walked without
//      evaluating u; when its largest ancestor with the same property (per-element ranges of
//      u, as for iso-surfaces) lies RenderOptions::skip_levels (5) or more levels above, that
//      ancestor is crossed in one step and the ray located again behind it (a location costs
//      several leaf steps);
//   5. a ray that leaves the mesh before the box exit (rounding) is located again, not lost;
//      a hard bound on steps (number of tetrahedra + 64) ends pathological walks, counted.
// The rendered elements are kept in the refinement tree's depth-first order (a subtree is a
// compact piece of space), so that the records a tile of rays reads lie close together in
// memory; an unstructured mesh's (no tree) in Z-order of their centroids.
// Unstructured meshes (RayEntry::kBoundaryFaces: T0 is a given mesh, e.g. a finite-element
// solution read from .vtu/.msh, which need not fill its box nor be convex): steps 2 and 5 go
// through the mesh's boundary faces instead, kept in a uniform bucket grid over the box. A ray
// enters at the first boundary face it crosses inward (a 3D DDA through the buckets, testing the
// faces listed there); when it leaves through a boundary face it looks for the next inward one
// behind it, so it re-enters a non-convex mesh (Bunyk, Kaufman & Silva 1997 do the same with
// per-pixel lists of projected boundary faces). The face test is watertight: the edge terms of
// a face are computed with the edge's lower vertex id first, so the two faces sharing an edge
// see the same number, and a ray through the edge hits at least one of them.
// Exit test: the parametric form of the face-crossing test (as in Bunyk et al.) with the
// entry-face exclusion as tie-break, not Plücker coordinates (Platis & Theoharis 2003).
#pragma once
#include <mlfe/core/base/default_init.h>
#include <mlfe/core/field/scalar_grid.h>
#include <mlfe/core/mesh/hierarchy.h>
#include <mlfe/core/render/transfer_function.h>

#include <array>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <type_traits>
#include <utility>
#include <vector>

namespace mlfe {

/// A pinhole or orthographic camera in the world (physical) frame. Image row 0 is the top;
/// the ray of pixel (x, y) goes through its centre (x + 0.5, y + 0.5).
struct Camera {
  bool perspective = false;
  std::array<double, 3> position{0, -1, 0};
  std::array<double, 3> target{0, 0, 0};
  std::array<double, 3> up{0, 0, 1};
  double fov_degrees = 30;                  ///< perspective: vertical field of view
  double ortho_height = 1;                  ///< orthographic: height of the view (world units)
  double near_clip = 0.01, far_clip = 100;  ///< for world_to_ndc only
  int width = 500, height = 500;

  /// Origin and unit direction of the ray through pixel (x, y), world frame.
  void ray(double x, double y, std::array<double, 3>& origin, std::array<double, 3>& dir) const;
  /// Row-major 4x4 matrices for column vectors. Camera space: x right, y up, the camera looks
  /// along −z (OpenGL). NDC: x, y, z in [−1, 1] with z = −1 at near_clip (OpenGL projection).
  std::array<double, 16> world_to_camera() const;
  std::array<double, 16> world_to_ndc() const;
};

/// A camera on a sphere around `center` looking at it, framing a ball of `radius`:
/// azimuth 0, elevation 0 looks along +y with +z up; azimuth turns about +z, elevation lifts
/// toward +z (degrees). Clip planes enclose the ball.
Camera orbit_camera(const std::array<double, 3>& center, double radius, double azimuth_deg,
                    double elevation_deg, bool perspective, int width, int height);

struct RenderOptions {
  RayAccumulator::Rule rule = RayAccumulator::Rule::kPreIntegrated;
  double stop_opacity = 0.99;  ///< early ray termination
  double z_opacity = 0.5;      ///< Z = distance where the accumulated opacity reaches this
  bool shading = false;        ///< scale colours by 0.35 + 0.65 |cos(gradient, ray)|
  bool skip_empty = true;      ///< cross transparent coarse elements in one step (mesh only)
  int skip_levels = 5;         ///< ... when they are at least this many levels above the leaf
  /// Mesh only: whether the step records (TetRenderMesh::StepRecord) are stored for reuse or
  /// computed at every step. Storing one costs what computing it does plus 128 bytes of fresh
  /// memory, so it pays only for elements crossed more than once: kAuto stores them when the
  /// rays of this image and of the `images` still expected from the mesh cross its elements
  /// at least twice on average (estimated from the rays that hit its box; records already
  /// stored are always used). Unstructured meshes (RayEntry::kBoundaryFaces) always store
  /// them. The image is the same bytes either way.
  enum class Records { kAuto, kStore, kCompute };
  Records records = Records::kAuto;
  int images = 1;  ///< images expected from the mesh, this one included (a turntable's frames)
};

/// Premultiplied linear RGBA (4 floats per pixel, row 0 at the top) and Z (distance along the
/// ray from its origin, world units; +infinity where the opacity never reaches z_opacity).
struct RenderImage {
  int width = 0, height = 0;
  std::vector<float> rgba;
  std::vector<float> z;
};

struct RenderStats {
  std::uint64_t rays = 0;             ///< rays that hit the domain box
  std::uint64_t segments = 0;         ///< tetrahedra (or reference samples) integrated
  std::uint64_t skips = 0;            ///< transparent coarse elements crossed in one step
  std::uint64_t relocations = 0;      ///< rays located again after leaving the mesh early
  std::uint64_t step_bound_hits = 0;  ///< rays ended by the step bound (should be 0)
  std::uint64_t reentries = 0;        ///< RayEntry::kBoundaryFaces: entries after the first
  bool records_stored = false;        ///< mesh only: the step records were stored (RenderOptions::records)
};

/// How a ray finds its entry element and where it goes when it leaves the mesh.
enum class RayEntry {
  /// T0 fills the box (a hierarchy built on a volume or a mesh's box): locate through the
  /// hierarchy; leaving the mesh before the box's far side is rounding, located again.
  kHierarchy,
  /// T0 is an arbitrary conforming mesh (Hierarchy::from_coarse of an unstructured mesh): enter
  /// and re-enter through its boundary faces (the file comment); no transparent ancestor is
  /// skipped (locating behind it would need the hierarchy to fill the box).
  kBoundaryFaces,
};

/// The triangulation T_k of a hierarchy prepared for ray casting: face neighbours of its
/// elements, u at every vertex on that level, and per-element value ranges of u (elements of
/// level ≤ k) for empty-space skipping. Holds references to h (and to `values` for the finest
/// level): both must outlive it.
class TetRenderMesh {
 public:
  /// values: u at every vertex of h (size checked); level −1 or ≥ h.max_level() is the leaf
  /// triangulation, smaller levels use the hierarchical basis (surpluses above k dropped).
  /// With `clip_to` (a hierarchy on the samples' lattice, sample_lattice.h), rays are clipped to
  /// the data's box [0, clip_to] instead of T0's padded cube.
  /// With RayEntry::kBoundaryFaces, throws mlfe::Error ("render: ...") when a face is shared
  /// by more than two of the rendered tetrahedra (not a conforming mesh).
  TetRenderMesh(const Hierarchy<3>& h, const std::vector<double>& values, int level = -1,
                const std::array<double, 3>* clip_to = nullptr, RayEntry entry = RayEntry::kHierarchy);
  ~TetRenderMesh();

  std::size_t size() const { return elems_.size(); }
  int level() const { return level_; }
  const Hierarchy<3>& hierarchy() const { return h_; }
  ElemId element(std::uint32_t r) const { return ElemId(elems_[r]); }
  /// Face neighbours of element r (render indices; −1 on the boundary), face f opposite local
  /// vertex f.
  std::array<std::int32_t, 4> neighbors(std::uint32_t r) const {
    std::array<std::int32_t, 4> nb;
    for (int f = 0; f < 4; ++f) {
      const std::uint32_t x = next_[r][f];
      nb[f] = x == kNoNeighbor ? -1 : std::int32_t(x >> 2);
    }
    return nb;
  }
  double value(VertexId v) const { return (*u_)[v.value]; }
  const std::array<double, 3>& box_lo() const { return lo_box_; }
  const std::array<double, 3>& box_hi() const { return hi_box_; }
  /// Conservative range of u over element e (level ≤ k): [lo, hi] as floats rounded outward.
  float range_lo(ElemId e) const { return lo_[e.value]; }
  float range_hi(ElemId e) const { return hi_[e.value]; }
  /// Render index of hierarchy element e, or −1 when e is not in T_k.
  std::int32_t render_index(ElemId e) const { return std::int32_t(render_of_[e.value]); }
  /// Render index of the element of T_k containing p + δ d (δ = 1e-7 × box diagonal), found by
  /// descending from T0; the best candidate (largest smallest barycentric) when none contains it.
  /// With a valid `hint` (any element of level ≤ k), the descent starts from the nearest
  /// ancestor of the hint that contains the point instead (the previous pixel's entry, the
  /// element just skipped): the same answer for points inside an element, fewer tests.
  std::uint32_t locate(const std::array<double, 3>& p, const std::array<double, 3>& d,
                       ElemId hint = ElemId::invalid()) const;
  /// Like locate(), by a visibility walk through face neighbours from element `start` of T_k
  /// (each step crosses the face whose barycentric coordinate of the point is most negative):
  /// cheap when the point is near `start` (the next pixel's entry). Falls back to locate() after
  /// 32 steps or at the mesh boundary.
  std::uint32_t walk_to(std::uint32_t start, const std::array<double, 3>& p,
                        const std::array<double, 3>& d) const;
  /// What a ray step needs of element r, precomputed once, in one record so that a step reads
  /// one place: the outward face planes n_f · x = h_f (face f opposite local vertex f; normals
  /// rounded to float, offsets in double through the face's lowest-id vertex, so the two
  /// elements sharing a face hold the same plane with opposite signs), u(x) = b + g · x, and
  /// the face neighbours, each as 4 × render index + the index of the shared face in the
  /// neighbour (kNoNeighbor on the boundary), so a step needs no search for its entry face.
  /// Aligned to cache lines: 120 bytes then touch two lines instead of three.
  /// Built on first use, a chunk of consecutive render indices at a time (thread-safe; the
  /// same bytes whichever thread builds them): a small image never pays for the records of the
  /// elements its rays do not cross, and no pass over all of them precedes the first ray.
  struct alignas(64) StepRecord {
    double h[4];
    double b;
    float n[3][4];  ///< n[a][f]: component a of face f's normal
    float g[3];
    std::uint32_t next[4];
  };
  static constexpr std::uint32_t kNoNeighbor = 0xFFFFFFFFu;
  const StepRecord& record(std::uint32_t r) const {
    const std::uint32_t chunk = r >> kChunkBits;
    if (!built_[chunk].load(std::memory_order_acquire)) build_chunk(chunk);
    return records_[r];
  }
  /// Element r's step record computed into `out`, the same bytes record(r) holds.
  void compute_record(std::uint32_t r, StepRecord& out) const;
  /// Builds every step record not built yet, in parallel (record() then only reads).
  void build_all_records() const;
  /// Step records built so far (chunks of consecutive render indices are built together).
  std::size_t records_built() const;
  /// Where record(r) is or will be, without building it (for prefetching).
  const StepRecord* record_address(std::uint32_t r) const { return records_.data() + r; }
  /// Where the ray o + t d, t in [t0, t1], may start for transfer function tf: a little before
  /// the first cell of a coarse grid over the box (about one cell per 8 elements) whose value
  /// range — the union of those of the elements overlapping it — is not transparent; t1 when
  /// there is none. Every element holding a point of the ray in front is transparent.
  double first_visible(const std::array<double, 3>& o, const std::array<double, 3>& d, double t0, double t1,
                       const CompiledTransferFunction& tf) const;
  /// Bytes the renderer adds on top of the hierarchy and its values (step records as far as
  /// built).
  std::size_t memory_bytes() const;

  RayEntry ray_entry() const { return entry_; }
  /// A boundary face the ray crosses: face `face` of element `tet` (render index) at t,
  /// `inward` when the ray enters the mesh there.
  struct BoundaryHit {
    std::uint32_t tet = 0;
    int face = 0;
    double t = 0;
    bool inward = false;
  };
  /// RayEntry::kBoundaryFaces only: the first boundary face the ray o + t d crosses with
  /// t in [t_min, t_max] (only inward ones with `inward_only`), smallest t first, then the
  /// lowest (4 × tet + face); never the faces given as `skip` (4 × tet + face, kNoNeighbor for
  /// none). t is where the ray meets the face's plane as the walk computes it (record()).
  bool boundary_hit(const std::array<double, 3>& o, const std::array<double, 3>& d, double t_min,
                    double t_max, bool inward_only, const std::uint32_t (&skip)[2], BoundaryHit& hit) const;
  /// Boundary faces of the rendered triangulation (0 with RayEntry::kHierarchy).
  std::size_t boundary_face_count() const;

 private:
  const Hierarchy<3>& h_;
  int level_;
  std::vector<double> coarse_values_;
  const std::vector<double>* u_;
  std::vector<std::uint32_t, DefaultInit<std::uint32_t>> elems_;  // element ids in render order
  // Records are built lazily in chunks of 2^kChunkBits (record()); the neighbours, which need
  // the whole mesh, are found up front (next_).
  static constexpr int kChunkBits = 9;
  mutable std::vector<StepRecord, DefaultInit<StepRecord>> records_;
  std::vector<std::array<std::uint32_t, 4>, DefaultInit<std::array<std::uint32_t, 4>>> next_;
  std::unique_ptr<std::atomic<bool>[]> built_;
  std::unique_ptr<std::once_flag[]> build_once_;
  void build_chunk(std::uint32_t chunk) const;
  std::size_t chunk_count() const { return (records_.size() >> kChunkBits) + 1; }
  std::vector<std::uint32_t, DefaultInit<std::uint32_t>> render_of_;
  std::vector<float, DefaultInit<float>> lo_, hi_;
  std::array<double, 3> lo_box_, hi_box_;
  double diag_ = 0;
  int grid_n_[3];
  std::array<double, 3> grid_cell_;
  std::vector<float> grid_lo_, grid_hi_;  // per cell of the range grid (empty: lo > hi)
  int grid_index(int a, double x) const;
  // The constructor's phases, in the order it calls them.
  void select_values(const std::vector<double>& values, int level);
  void order_elements();
  void reserve_records();
  void find_neighbors();
  void bound_domain(const std::array<double, 3>* clip_to);
  void build_range_grid();
  void build_boundary_grid();
  RayEntry entry_ = RayEntry::kHierarchy;
  struct BoundaryGrid;
  std::unique_ptr<BoundaryGrid> boundary_;
};

/// One piece of a traced ray: tetrahedron `tet` (render index; −1 for a skipped transparent
/// coarse element) from t0 to t1, with u at both ends and u's gradient there (local frame).
/// `empty`: the element is transparent for the skip transfer function (s0, s1 and gradient
/// are then not computed).
struct TraceSegment {
  std::int32_t tet;
  double t0, t1;
  double s0, s1;
  std::array<double, 3> gradient;
  bool empty;
};

struct TraceResult {
  bool hit = false;              ///< the ray met the domain box
  double t_near = 0, t_far = 0;  ///< its chord in the box
  std::uint64_t steps = 0, skips = 0, relocations = 0;
  std::uint64_t reentries = 0;  ///< RayEntry::kBoundaryFaces: entries after the first
  bool step_bound_hit = false;
};

/// Traces the ray origin + t·dir (local frame, t ≥ 0) through m, calling visit(segment) per
/// tetrahedron in ray order until it returns false or the ray leaves the box. With `skip`,
/// elements whose range it reports transparent (skip->transparent) are crossed in one step,
/// and the walk starts at first_visible() (the transparent elements in front are not visited).
/// `entry_hint` (may be null): in, an element to start the entry search from; out, the entry
/// element of this ray (for the next pixel).
TraceResult trace_ray(const TetRenderMesh& m, const std::array<double, 3>& origin,
                      const std::array<double, 3>& dir, const CompiledTransferFunction* skip,
                      const std::function<bool(const TraceSegment&)>& visit, ElemId* entry_hint = nullptr);

/// Renders u on m (in the hierarchy's local frame; `transform` maps it to the world frame the
/// camera lives in). Parallel over image tiles; the result does not depend on the thread count.
RenderImage render_mesh(const TetRenderMesh& m, const GridTransform& transform, const TransferFunction& tf,
                        const Camera& camera, const RenderOptions& options, RenderStats* stats = nullptr);

/// Reference: the trilinear interpolant of the voxels (3D grid, ≥ 2 samples per axis; throws
/// mlfe::Error otherwise),
/// sampled every half of the smallest spacing, each step integrated like a mesh segment
/// (linear between samples); no empty-space skipping (a full-grid ray caster).
RenderImage render_grid(const ScalarGrid& grid, const TransferFunction& tf, const Camera& camera,
                        const RenderOptions& options, RenderStats* stats = nullptr);

/// Local ↔ world for points and directions of an invertible transform.
std::array<double, 3> world_to_local_point(const GridTransform& t, const std::array<double, 3>& p);
std::array<double, 3> world_to_local_direction(const GridTransform& t, const std::array<double, 3>& d);

}  // namespace mlfe
