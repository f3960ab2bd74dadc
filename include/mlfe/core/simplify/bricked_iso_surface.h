// Iso-surfaces extracted and simplified in bricks of the samples' lattice (issue 39): the brick
// pass, the weld and the seam pass behind `mlfe convert --bricks B`, and the pieces a
// distributed run sends to workers (brick_pass) and joins on the client (join_bricks).
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
// Weld. The parts are joined by the lattice place of each face vertex (LatticePlace: the edge
// it lies on), not by comparing floats; every other vertex belongs to one brick.
//
// Seam pass. Locked face vertices leave the surface dense along the brick faces. The strips
// there (the triangles within kSeamRings rings of a face vertex; a brick's own strips are its
// share of them, since only face vertices are in two bricks) are simplified once more, as one
// surface with the face vertices free and the strips' rim locked, down to what is left of the
// whole surface's budget (`ratio` of all extracted triangles), so the seams end as sparse as
// the rest.
//
// Why the bound holds across the seams. The verified bound (Klein et al., see
// surface_simplification.h) keeps every point of the surface a run started from attached to a
// face within the tolerance. A brick's last run reports where each of its points ended
// (SimplifyCarry::point_face); the seam pass takes the points attached to the strips' faces,
// with those faces, as its own points (SimplifyCarry::points) and keeps them within the same
// tolerance by the same rules, while every face outside the strips stays as the brick pass left
// it. So each point is measured against the surface its brick's last run started from, never
// against an intermediate seam-pass input: one tolerance, not two. An estimated last run keeps
// no points, and the seam pass estimates in the same way. The other direction (the output's
// distance to the extraction) is refitted outside the strips; a vertex the seam pass moves stays
// within the tolerance of the strips, so within twice it of the extraction.
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
  std::size_t face_vertices = 0;        ///< welded vertices on the shared sample planes
  std::size_t seam_triangles = 0;       ///< triangles of the strips the seam pass simplified
  std::size_t seam_output = 0;          ///< what the seam pass left of them
  std::size_t welded_triangles = 0;     ///< triangles after the weld, before the seam pass
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

/// The weld and the seam pass over the bricks' parts, in brick order (empty parts allowed):
/// one surface. Throws mlfe::Error when the parts do not fit together (a face vertex in one part
/// and not in its neighbour: parts of different volumes or options).
TriangleMesh join_bricks(std::vector<BrickPart> parts, const BrickedIsoOptions& o,
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
/// window per brick for every iso-value), simplified in bricks of `edge` cubes: brick_pass over
/// every brick (threads over bricks, at most as many windows in memory as threads run), then
/// join_bricks per iso-value; `stats` (may be null) receives one BrickStats per iso-value.
/// Vertex and triangle order are a function of the samples, `edge` and the options, not of the
/// thread count. Throws mlfe::Error as brick_layout, brick_pass and join_bricks do, and what
/// `read` or `progress` throws.
std::vector<TriangleMesh> bricked_iso_surfaces(const WindowReader& read,
                                               const std::array<std::int64_t, 3>& dims, std::int64_t edge,
                                               const std::vector<double>& isos, const BrickedIsoOptions& o,
                                               std::vector<BrickStats>* stats = nullptr,
                                               const BrickProgress& progress = {});

}  // namespace mlfe
