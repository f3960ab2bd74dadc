// Iso-surfaces extracted and simplified in bricks of the samples' lattice (issue 39): the brick
// pass, the weld and the seam pass behind `mlfe convert --bricks B`, and the pieces a
// distributed run sends to workers (brick_pass, join_slabs) and joins on the client (join_tree).
//
// Bricks. The cubes of the samples' lattice are cut into bricks of B x B x B cubes (B a power of
// two, the last brick along an axis shorter); neighbouring bricks share the sample plane
// between them. The bricks are fixed by the lattice and B, never by the thread or worker count,
// so the output is the same for any count. A brick's pass reads only its samples and one more
// on each side (a window: the extraction's gradients are central differences), so the volume
// need never be in memory at once: a WindowReader may read it from a file box by box.
//
// Brick pass. The brick's part of lattice_iso_surface is extracted from its window with the
// whole grid's lattice coordinates, so a vertex on a lattice edge in a shared sample plane (a
// "face vertex") gets the same position and normal, to the bit, in every brick that has it. It
// is simplified by simplify()'s runs for a big surface (kAuto: estimated, then verified), each
// stopping at `ratio` of the brick's triangles, with the face vertices hard-locked
// (SimplifyCarry::locked): a locked vertex neither moves nor vanishes, so the boundary polylines
// of neighbouring bricks stay identical. With Placement::kOptimal the triangles outside the
// strips (below) are then refitted to the brick's extraction, as simplify() ends; the strips
// keep their shape for the seam pass. What the join needs is kept: the simplified mesh, the face
// vertices' lattice places, and the bound's points attached to the strips.
//
// Joins by slabs. The bricks with the same z index form a slab. The parts are joined over a
// tree of slabs fixed by the layout alone: a leaf joins one slab's bricks, a node joins the
// pieces of its two halves (slabs [first, split) and [split, end), slab_split). Each join welds
// its pieces by the lattice place of each face vertex (LatticePlace: the edge it lies on), not by
// comparing floats; every other vertex belongs to one piece. The face vertices whose bricks all
// lie in the join are closed by it; those on the join's bottom or top sample plane, shared with
// slabs outside, stay open: locked, and kept with their places for a later join. So a leaf closes
// its slab's faces along x and y, a node the sample plane between its halves, and the root
// (every slab) the rest: each shared face is closed by exactly one join. Joins of disjoint slabs
// are independent, so threads (and Dask tasks) run them at once, and each simplifies only its own
// strips; a join's piece is the joined surface with the open vertices, so what is held is the
// slabs in work and the pieces joined so far (about the output), never every strip at once. The
// bytes are a function of the tree, hence of the lattice and B, not of the thread or worker
// count.
//
// Seam pass (per join). Locked face vertices leave the surface dense along the brick faces. The
// strips there (the triangles within kSeamRings rings of a closing vertex) are simplified once
// more, as one surface with the closing vertices free and the strips' rim and the open vertices
// locked, down to what is left of the join's budget (`ratio` of its extracted triangles), so the
// seams end as sparse as the rest. A vertex the seam pass may move has all its triangles in the
// strips, so nothing outside the join, and nothing of its surface outside the strips, changes.
//
// Why the bound holds across the seams. The verified bound (Klein et al., see
// surface_simplification.h) keeps every point of the surface a run started from attached to a
// face within the tolerance. A brick's last run reports where each of its points ended
// (SimplifyCarry::point_face); a brick keeps the points attached to its strips (within
// kSeamRings rings of any face vertex), and a join's piece the points attached to the triangles
// within kSeamRings rings of its open vertices: that covers every triangle a later join can take
// into its strips (a later strip's triangles in this piece lie within those rings, as every
// vertex they touch in two pieces is open in both). Each join's seam pass takes the points
// attached to its strips, with those faces, as its own points (SimplifyCarry::points) and keeps
// them within the same tolerance by the same rules, while every face outside the strips stays as
// it was. So each point is measured against the surface its brick's last run started from, never
// against an intermediate join's input: one tolerance, not one per join. An estimated last run
// keeps no points, and the seam passes estimate in the same way. The other direction (the
// output's distance to the extraction) is refitted outside the strips; a vertex a seam pass
// moves stays within the tolerance of the strips, so within twice it of the extraction.
//
// Brick size: 64 samples on a 1 mm head (181 x 217 x 181) gives 36 bricks of about 45 000
// extracted triangles each, enough to balance two threads; 32 raised the worst distance at the
// seams (bench/RESULTS.md).
#pragma once
#include <mlfe/core/field/scalar_grid.h>
#include <mlfe/core/simplify/simplifier.h>
#include <mlfe/core/surface/iso_surface.h>
#include <mlfe/core/surface/triangle_mesh.h>

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <vector>

namespace mlfe {

/// What the brick pass and the seam pass did (for reports and tests).
struct BrickStats {
  std::size_t bricks = 0;               ///< bricks with triangles
  std::size_t extracted_triangles = 0;  ///< the whole extraction's, summed over the bricks
  std::size_t face_vertices = 0;        ///< welded vertices on the shared sample planes (closed)
  std::size_t seam_triangles = 0;       ///< triangles of the strips the seam passes simplified
  std::size_t seam_output = 0;          ///< what the seam passes left of them
  std::size_t welded_triangles = 0;     ///< triangles the bricks' passes left
  std::size_t parts = 0;                ///< connected parts of the result (as extracted)
};

/// The bricks of a grid of `dims` samples with `edge` cubes per brick edge: brick (a, b, c) spans
/// the samples [edge * a, min(edge * (a + 1), dims - 1)] per axis (bricks share their face
/// samples), numbered x fastest.
struct BrickLayout {
  std::array<std::int64_t, 3> dims{0, 0, 0}, count{0, 0, 0};
  std::int64_t edge = 0;
  std::size_t bricks() const { return std::size_t(count[0] * count[1] * count[2]); }
  /// Brick `b`'s samples [lo, hi) (hi exclusive).
  void samples(std::size_t b, std::array<std::int64_t, 3>& lo, std::array<std::int64_t, 3>& hi) const;
  /// Slabs: the bricks with the same z index, count[0] * count[1] consecutive bricks each.
  std::size_t slabs() const { return std::size_t(count[2]); }
  std::size_t slab_bricks() const { return std::size_t(count[0] * count[1]); }
  /// The samples [lo, hi) a brick's pass reads: its own and one more on every side the grid
  /// has (the extraction's gradients are central differences).
  void window(std::size_t b, std::array<std::int64_t, 3>& lo, std::array<std::int64_t, 3>& hi) const;
};

/// The bricks of `dims` (each >= 2) with `edge` cubes per edge. Throws mlfe::Error for an edge
/// that is not a power of two of at least 2.
BrickLayout brick_layout(const std::array<std::int64_t, 3>& dims, std::int64_t edge);

/// One brick after the brick pass: what the join needs of it, and nothing of the volume.
struct BrickPart {
  std::size_t extracted_triangles = 0;  ///< the brick's extraction before simplification
  TriangleMesh mesh;                    ///< simplified, its face vertices where extracted
  /// The vertices of `mesh` on a sample plane the brick shares with a neighbour, ascending, and
  /// their lattice places (the weld joins by them); only these carry a place, so the parts of a
  /// big volume held for the join stay small.
  std::vector<std::uint32_t> face_vertex;
  std::vector<LatticePlace> face_place;
  /// The bound's points attached to the triangles the seam pass takes again (verified bound).
  std::vector<std::array<float, 3>> points;
  std::vector<std::uint32_t> point_face;
};

/// What a bricked extraction does besides the simplifier's options.
struct BrickedIsoOptions {
  bool normals_toward_higher = false;
  SimplifierOptions simplifier;  ///< kAuto, kFast or kBounded (kMeshopt cannot lock vertices)
};

/// The brick pass of brick `b` of `layout` for the iso-value `iso`: `window` holds the samples
/// layout.window(b) (with the whole grid's transform), the brick's part of lattice_iso_surface
/// is extracted from it and simplified as the header says. Deterministic; parallel inside.
/// Throws mlfe::Error for a window of the wrong size and as simplify_within does.
BrickPart brick_pass(const ScalarGrid& window, const BrickLayout& layout, std::size_t b, double iso,
                     const BrickedIsoOptions& o);

/// The join tree's split of the slabs [first, end) (end > first + 1): its halves are [first,
/// split) and [split, end).
std::size_t slab_split(std::size_t first, std::size_t end);

/// The join of the slabs [first, end) of `layout` (the header's "Joins by slabs"): `pieces` are
/// slab `first`'s bricks' parts in brick order (empty parts allowed) when end == first + 1, else
/// the pieces of its halves (slab_split). The result's face vertices are those shared with
/// slabs outside [first, end); for every slab it is the whole surface. Deterministic; parallel
/// inside. `stats` (may be null) receives this join's (bricks, face vertices closed, seams).
/// Throws mlfe::Error for pieces that do not fit together (a closing face vertex in one piece
/// only, a shared vertex placed differently: parts of different volumes or options) or are not
/// the join's.
BrickPart join_slabs(std::vector<BrickPart> pieces, const BrickLayout& layout, std::size_t first,
                     std::size_t end, const BrickedIsoOptions& o, BrickStats* stats = nullptr);

/// Where join_tree finds the pieces of a node.
struct SlabSource {
  /// May be empty. The pieces (one per surface) of the slabs [first, end) already joined, or
  /// none (the node is then joined here).
  std::function<std::vector<BrickPart>(std::size_t first, std::size_t end)> joined;
  /// Per surface, the bricks' parts of one slab in brick order, for a slab `joined` has not;
  /// called at most once per slab, from any thread.
  std::function<std::vector<std::vector<BrickPart>>(std::size_t slab)> bricks;
};

/// The `surfaces` surfaces joined over the slab tree of `layout` from `source`, threads running
/// disjoint subtrees at once; `stats` (may be null) receives per surface the sums over the joins
/// run here, with the whole extraction's triangles and the result's connected parts. The
/// result is join_slabs's at the root, whichever nodes `source` held. Throws as join_slabs does
/// and what `source` throws.
std::vector<TriangleMesh> join_tree(const SlabSource& source, const BrickLayout& layout, std::size_t surfaces,
                                    const BrickedIsoOptions& o, std::vector<BrickStats>* stats = nullptr);

/// join_tree over every brick's part of one surface, in brick order: one surface. Throws
/// mlfe::Error as join_slabs does, and for a count that is not the layout's.
TriangleMesh join_bricks(std::vector<BrickPart> parts, const BrickLayout& layout, const BrickedIsoOptions& o,
                         BrickStats* stats = nullptr);

/// Reads the samples [lo, hi) of the whole grid as a grid with the whole grid's transform. May be
/// called from several threads at once.
using WindowReader =
    std::function<ScalarGrid(const std::array<std::int64_t, 3>& lo, const std::array<std::int64_t, 3>& hi)>;

/// A WindowReader over a grid in memory (3D; it must outlive the reader).
WindowReader grid_windows(const ScalarGrid& grid);

/// Called after each brick with the bricks done and their count; returning false stops the run
/// (the caller's Cancelled is thrown from it or mlfe::Error "cancelled").
using BrickProgress = std::function<bool(std::size_t done, std::size_t total)>;

/// The iso-surfaces `isos` of a grid of `dims` samples, read brick by brick through `read` (one
/// window per brick for every iso-value), simplified in bricks of `edge` cubes: join_tree over
/// the bricks' passes, a slab's bricks passed when its leaf is joined (threads over bricks and
/// subtrees, at most as many windows in memory as threads run); `stats` (may be null) receives
/// one BrickStats per iso-value.
/// Vertex and triangle order are a function of the samples, `edge` and the options, not of the
/// thread count. Throws mlfe::Error as brick_layout, brick_pass and join_bricks do, and what
/// `read` or `progress` throws.
std::vector<TriangleMesh> bricked_iso_surfaces(const WindowReader& read,
                                               const std::array<std::int64_t, 3>& dims, std::int64_t edge,
                                               const std::vector<double>& isos, const BrickedIsoOptions& o,
                                               std::vector<BrickStats>* stats = nullptr,
                                               const BrickProgress& progress = {});

}  // namespace mlfe
