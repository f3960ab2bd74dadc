// Decimation of an interface complex: the triangles between several regions of space over one
// shared vertex set (core/labels' label interfaces), simplified all at once so that two regions
// that touch keep the same vertices and edges along their interface. No I/O; TBB-parallel and
// deterministic whatever the thread count.
#pragma once
#include <mlfe/core/base/vec.h>

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace mlfe {

/// Triangles between regions over one shared vertex set: every interface triangle once, tagged
/// with the two regions it separates, so the surfaces of two regions that touch share their
/// vertices and edges by construction.
struct InterfaceComplex {
  std::vector<Vec3> positions;
  std::vector<std::array<std::uint32_t, 3>> triangles;
  /// Per triangle its regions (labels) {a, b}, a < b; the triangle is counter-clockwise seen
  /// from b, so its normal points out of a.
  std::vector<std::array<std::uint16_t, 2>> labels;
};

/// Simplifies the complex by quadric edge collapse (Garland & Heckbert 1997) over all its
/// interfaces at once, cheap merges first, each merged vertex placed where the summed
/// quadrics (area-weighted planes of the triangles it absorbed) are least. A merge is made only
/// when that RMS distance to the absorbed planes stays within `tolerance` (position units) and
/// the result stays near its input both ways: every input vertex lies within 1.5 `tolerance` of
/// the triangles of the vertex that absorbed it (re-checked for every input vertex whose reason
/// to be near a merge moves: the merged vertex's and its neighbours', so this holds for the
/// result), and each new triangle's corners, edge midpoints and centroid lie within 1.5
/// `tolerance` + a fifth of the input's mean edge length of an input vertex (one absorbed by the
/// merged vertex or its neighbours, so of the input surface there). A mean over planes lets a
/// vertex slide along a crease or a thin rim, or a triangle cut across a fold, at no cost, voxels away from
/// the input. Constraints keep the complex a partition: a vertex inside one interface merges with a neighbour
/// in the same interface or moves onto a junction-curve neighbour; a vertex on a junction curve (where three
/// or more regions meet) merges only along its curve, placed on the segment; where curves meet, and at
/// non-manifold points of an interface, vertices stay. Merging vertices never opens a closed surface; the
/// link condition (the ends' common neighbours are exactly the edge's apexes), a no-flip test on every moved
/// triangle, at least a tetrahedron per closed piece and three vertices per junction loop keep every region's
/// surface closed, consistently oriented and its islands present, and the interfaces shared. The cheap merges
/// (within a fifth of the tolerance) go first inside fixed blocks of 16³ position units, in parallel, away
/// from the blocks' borders; then the two halves below and above the vertices' median height, at once,
/// cheapest first up to the tolerance, away from the other half; then the whole complex (the seam). Parts do
/// not interact and each part's pass is sequential in itself, so the same result for any thread count.
/// Vertices end numbered in first use by the kept triangles, which keep their order. Returns the number of
/// vertices removed. Throws mlfe::Error unless `tolerance` is positive and finite.
std::size_t decimate_interface_complex(InterfaceComplex& x, double tolerance);

}  // namespace mlfe
