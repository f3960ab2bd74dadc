// Simplification of a lattice iso-surface in bricks of the samples' lattice (issue 39, step 1):
// the brick pass, the weld and the seam pass behind `mlfe convert --bricks B`.
//
// Bricks. The cubes of the samples' lattice are cut into bricks of B x B x B cubes (B a power of
// two, the last brick along an axis shorter); neighbouring bricks share the sample plane
// between them. The bricks are fixed by the lattice and B, never by the thread count, so the
// output is the same for any count. A vertex of lattice_iso_surface lies on a lattice edge (or
// inside one cube), and every triangle inside one cube, so each triangle belongs to exactly one
// brick; the vertices on edges in a shared sample plane ("face vertices") are the only ones
// two or more bricks use, and the same lattice edge gives them the same position and normal in
// each: the bricks' surfaces meet exactly, and are joined by the edge a vertex lies on
// (LatticePlace), not by comparing floats.
//
// Brick pass. Each brick's triangles are simplified on their own (threads over bricks, each
// simplification parallel inside), by the same runs of simplify_within that simplify() would
// make for the whole surface (simplify_stages(), decided by the whole surface's triangle count,
// each brick stopping at `ratio` of its own triangles), with the face vertices hard-locked
// (SimplifyCarry::locked). The Simplifier alone would not do: it lets a boundary vertex slide
// along a boundary edge (collapse onto its neighbour there), and the two bricks would slide
// differently. Locked, a face vertex neither moves nor vanishes (its neighbours may still
// collapse onto it, leaving it in place), so the boundary polylines of neighbouring bricks stay
// identical and the weld stays exact.
//
// Seam pass. Locked face vertices leave the surface dense along the brick faces. The strips
// there (the triangles around the face vertices, kSeamRings rings deep) are simplified once
// more, as one surface with the face vertices free and the strips' own rim locked, down to what
// is left of the whole surface's triangle budget (`ratio` of all its triangles), so the seams
// end as sparse as the rest.
//
// Why the bound holds across the seams. The verified bound (Klein et al., see
// surface_simplification.h) keeps every point of the surface a run started from attached to a
// face within the tolerance. The brick pass's last run reports where each of its points ended
// (SimplifyCarry::point_face); the seam pass takes the points attached to the strips' faces,
// with those faces, as its own points (SimplifyCarry::points) and keeps them within the same
// tolerance by the same rules, while every face outside the strips stays as the brick pass left
// it. So each point is measured against the surface the last run started from (the extraction
// itself, or, for kAuto on big surfaces, the estimated first stage's output, exactly as in
// simplify()), never against an intermediate seam-pass input: the bound is simplify()'s, not
// twice it. An estimated last run (kFast; kAuto below a 5 % ratio) keeps no points, and the
// seam pass estimates in the same way. With Placement::kOptimal the welded result is refitted
// to the whole extraction, as simplify() does.
//
// Brick size: 64 samples on a 1 mm head (181 x 217 x 181) gives 36 bricks of about 45 000
// extracted triangles each: enough bricks to balance two threads (the strips the seam pass takes
// again were 90 000 of the 199 000 welded triangles before face vertices took collapses). Measured there
// (iso 99.5, defaults, one loaded run): 32 keeps the mean distance but raises the worst one at the seams
// (Hausdorff 2.1 voxels against flying edges, 1.5 unbricked); 64 and 128 stay at 1.4-1.45 with the mean 3 %
// above the unbricked one. One thread is still 1.1-1.3x slower than the whole surface's simplification (which
// has its own blocks and parallel passes); the gain is to come from bricks read and simplified without the
// whole volume (issue 39's later steps).
#pragma once
#include <mlfe/core/simplify/simplifier.h>
#include <mlfe/core/surface/iso_surface.h>
#include <mlfe/core/surface/triangle_mesh.h>

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace mlfe {

/// What the brick pass and the seam pass did (for reports and tests).
struct BrickStats {
  std::size_t bricks = 0;            ///< bricks with triangles
  std::size_t face_vertices = 0;     ///< extracted vertices the bricks share
  std::size_t seam_triangles = 0;    ///< triangles of the strips the seam pass simplified
  std::size_t seam_output = 0;       ///< what the seam pass left of them
  std::size_t welded_triangles = 0;  ///< triangles after the weld, before the seam pass
};

/// `mesh`, lattice_iso_surface's output on a grid of `dims` samples with `places` its vertices'
/// LatticePlace, simplified in bricks of `brick` cubes per edge as the header describes, within
/// `o.tolerance` by `o.kind`'s rules, down to about `o.ratio` of its triangles. Topology as
/// simplify_within keeps it (a closed manifold extraction stays closed and manifold, with its
/// genus and parts). Vertex and triangle order are a function of the inputs and `brick`, not of
/// the thread count. Throws mlfe::Error for a brick edge that is not a power of two of at least
/// 2, for Simplifier::kMeshopt (it cannot lock vertices), for `places` not one per vertex or a
/// place outside `dims`, and as simplify_within does.
TriangleMesh simplify_in_bricks(const TriangleMesh& mesh, const std::vector<LatticePlace>& places,
                                const std::array<std::int64_t, 3>& dims, const SimplifierOptions& o,
                                std::int64_t brick, BrickStats* stats = nullptr);

}  // namespace mlfe
