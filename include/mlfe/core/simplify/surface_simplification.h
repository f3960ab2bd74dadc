// Error-bounded simplification of triangle meshes (the iso-surfaces of `mlfe convert
// --simplify`): half-edge collapses ordered by quadric error, each refused unless every vertex
// of the input stays within a tolerance of the simplified surface. No I/O; TBB-parallel and
// deterministic whatever the thread count.
#pragma once
#include <mlfe/core/surface/triangle_mesh.h>

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace mlfe {

/// Where a collapse puts the vertex that survives it.
enum class Placement {
  kInputVertex,  ///< half-edge collapse: on the neighbour it merges into (every output vertex is an input
                 ///< vertex)
  kOptimal,      ///< at the minimum of the merged quadrics (Garland & Heckbert), kept near the input surface
};

struct SimplifyOptions {
  double tolerance = 0;                   ///< bound on the distance of input vertices, mesh units; > 0
  std::size_t min_triangles = 0;          ///< stop once the mesh has this many triangles or fewer
  double max_normal_turn_degrees = 45.0;  ///< a collapse may not turn a face normal further
  bool flip_edges = true;  ///< also flip edges toward valence 6 (smaller Draco files, fewer triangles)
  Placement placement = Placement::kInputVertex;
  /// true: the bound below is verified (Klein et al.); false: estimated from the quadrics, as
  /// meshoptimizer does (a collapse is taken while the merged quadric's area-weighted mean
  /// squared distance to its planes stays within tolerance²): several times faster, the topology
  /// checks unchanged, the bound no longer guaranteed.
  bool verify_bound = true;
  /// With an estimated bound, meshes of at least this many triangles start with the blocks of
  /// space (core/simplify/surface_simplification.cpp), each simplified on its own, cheapest
  /// collapse first, before the parallel passes (smaller ones take a second or less in the
  /// passes alone).
  std::size_t blocks_from = 100000;
};

struct SimplifyStats {
  std::size_t passes = 0;     ///< rounds of independent collapses
  std::size_t collapses = 0;  ///< vertices removed
  std::size_t flips = 0;      ///< valence-improving edge flips
};

/// What simplify_within shares with the simplifications of the neighbouring parts of one surface
/// (core/simplify/bricked_iso_surface.h): vertices held where the parts meet, and the bound's
/// points carried over from an earlier simplification, so that the bound stays measured
/// against the surface that one started from.
struct SimplifyCarry {
  /// In: empty, or one per input vertex; 1 where the vertex never moves and is never removed
  /// (a neighbour may still collapse onto it, the half-edge way, leaving it in place; flips
  /// may change its triangles but not flip its edges). Unlike a boundary vertex, which may
  /// slide along the boundary, it stays exactly as it is, and so do the boundary edges between
  /// two such vertices; no collapse or flip joins two of them by a new edge (the other part
  /// glued along them may have that edge).
  std::vector<std::uint8_t> locked;
  /// In (verified bound only): when `point_face` is not empty, the bound's points, in place of
  /// the input's vertices; each lies within the tolerance of the input triangle `point_face`
  /// names (one that has no repeated index). The reverse check of a moved survivor then looks
  /// at the input triangles around the collapse's own two vertices only.
  std::vector<std::array<float, 3>> points;
  /// In: see `points`. Out (verified bound): per point (the input's vertices when no points came
  /// in; an input vertex no triangle uses gets UINT32_MAX), the output triangle it lies within
  /// the tolerance of. Empty with an estimated bound, which keeps no points.
  std::vector<std::uint32_t> point_face;
  /// Out: per output vertex, the input vertex it is (the survivor of its collapses).
  std::vector<std::uint32_t> source;
};

/// Simplifies `mesh` by edge collapses, cheapest quadric error first (Garland & Heckbert 1997),
/// and edge flips that make valences more regular (under the same checks). With
/// Placement::kInputVertex a vertex moves onto a neighbour, so every output position is an
/// input position; with Placement::kOptimal the merged vertex goes to the quadric minimum
/// (or the cheapest point of the edge when that is ill-defined or far away; the half-edge
/// collapse when that fails the checks). On scanned surfaces at asset tolerances this removes
/// more triangles at the same bound and smooths the voxel noise (CT skull at 0.2 voxel: about
/// 30 % fewer, at a lower mean distance to the data's surface) for up to twice the time. On
/// clean smooth input at tight tolerances input vertices do better: they already lie on the
/// surface, and a moved vertex also moves the faces around it, whose points must stay bound.
///
/// Contract:
/// - Bound: every input vertex used by a triangle lies within `opts.tolerance` of the output
///   surface (one-sided Hausdorff distance from the input's vertices; each input vertex is
///   kept attached to a face that covers it, as in Klein, Liebich & Straßer 1996). So small
///   closed parts never vanish. The other direction is checked where it can go wrong: a
///   boundary vertex is only removed within the tolerance of the boundary edge that replaces
///   it, and (kOptimal) a moved vertex lies within the tolerance of an input triangle near it.
/// - Topology: collapses that would change it are refused (link condition), so a closed
///   2-manifold stays closed with the same genus, boundaries stay boundaries (boundary vertices
///   only move along boundary edges), and vertices on non-manifold edges or fans never move.
///   No collapse turns a face normal by more than `opts.max_normal_turn_degrees` or makes a
///   face degenerate. Orientation is kept. Boundary vertices never move (kOptimal too).
/// - Triangles with a repeated index are dropped first. Output vertices keep their input
///   normals (with kOptimal: the normal of the input vertex that survived, at its new place)
///   when the input has one per vertex (iso-surfaces: the data's gradient, more
///   faithful than normals averaged from the coarser triangles); without input normals they
///   are area-weighted from the output geometry. Output vertices and triangles keep their
///   input order (unused vertices dropped).
/// - Deterministic: the same input and options give identical output for any thread count.
/// - Throws mlfe::Error for a tolerance that is not positive and finite, an index out of range,
///   a non-finite position used by a triangle, or a normal count that is neither 0 nor one per
///   vertex.
/// - `carry` (may be null): see SimplifyCarry; throws mlfe::Error when its sizes do not fit the
///   mesh, when a point's triangle is out of range or degenerate, or for points with an
///   estimated bound.
TriangleMesh simplify_within(const TriangleMesh& mesh, const SimplifyOptions& opts,
                             SimplifyStats* stats = nullptr, SimplifyCarry* carry = nullptr);

/// Fast simplification with meshoptimizer's meshopt_simplify (A. Kapoulkine; quadric-ordered
/// edge collapses onto input vertices): collapses while meshoptimizer's own error estimate
/// stays within `tolerance` (mesh units), with boundary vertices locked. The estimate is not a
/// verified bound (simplify_within gives one): use it where throughput matters more, and
/// measure. Big surfaces are simplified in slabs in parallel, and the triangles around the
/// slabs' seams once more, so the estimate holds per pass. Contract: every output vertex is an
/// input vertex, kept with its normal (when the input has one per vertex) and in input order;
/// triangles with a repeated index are dropped first; the output does not depend on the thread
/// count. Throws mlfe::Error for a tolerance that is not positive and finite or an index out of
/// range.
TriangleMesh simplify_fast(const TriangleMesh& mesh, double tolerance);

}  // namespace mlfe
