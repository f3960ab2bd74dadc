// Label maps (segmentations, atlases) to one closed surface per structure, with the surfaces of
// touching structures sharing their interface exactly: multi-material marching tetrahedra on
// the Kuhn (Freudenthal) triangulation of the samples' lattice, then smoothing and
// simplification of the whole interface complex at once, then a split per label.
//
// Labels are categories: nothing here interpolates a label value. Every lattice vertex carries
// its sample's label, and each label's region is cut out of every tetrahedron by interfaces
// through the midpoints of the edges whose ends differ, the centroids of faces with three
// labels and the centroid of a tetrahedron with three or four. Where a tetrahedron holds two
// labels that is plain marching tetrahedra on the label's indicator function at 1/2 (what a
// binary mask of the structure alone gives); where it holds more, the interfaces of the
// indicators are fanned to the centroids, where the junction curves run. This is right for
// categories: the result depends on the corner labels alone and treats every label alike, the
// pieces partition each tetrahedron (no gap, no overlap), and label 3 next to label 7 gives one
// 3|7 interface and no surface of 4, 5 or 6. The hierarchy of issue #23 (tetrahedra of level L
// = one-voxel Kuhn tetrahedra) refines exactly where a tetrahedron holds more than one label,
// so extraction takes the set of mixed one-voxel tetrahedra as its input: coarse elements
// inside structures hold no interface.
//
// Non-manifold configurations (four labels around a lattice edge, checkerboard faces and
// corners) do not arise: every two corners of a tetrahedron share one of its edges, so each
// label's corners in a tetrahedron are connected and its piece there is one disc (a triangle,
// a quad or a fan around the centroid). Where marching cubes would have to choose (a face or
// a cube whose equal labels touch only diagonally), the Kuhn diagonal, the same in every cube,
// has chosen: labels on it are connected, the others are cut off. Each label's surface is so,
// tetrahedron by tetrahedron, the level set at 1/2 of its indicator made linear on the
// tetrahedra (where one holds three or four labels, the fan has the same boundary on its faces
// and is a disc as well), and no sample holds 1/2: a closed 2-manifold, each edge in two
// triangles and each vertex one fan (tests/core/label_surface_test.cpp checks it on four
// labels around an edge and on 3D checkerboards of 2 and 8 labels).
//
// Every interface triangle is stored once, tagged with its two labels, over one vertex set, so
// two structures that touch have the same vertices and edges along their interface by
// construction; smoothing and simplification act on that shared complex and keep it so. The
// volume is padded with background (label 0) outside its box, so every structure is closed.
#pragma once
#include <mlfe/core/field/scalar_grid.h>
#include <mlfe/core/simplify/complex_decimator.h>
#include <mlfe/core/surface/triangle_mesh.h>

#include <array>
#include <cstddef>
#include <cstdint>
#include <map>
#include <vector>

namespace mlfe {

/// One label (0..65535; 0 is the background) per sample of a 3D lattice, x fastest.
struct LabelGrid {
  std::array<std::int64_t, 3> dims{0, 0, 0};
  std::vector<std::uint16_t> labels;
  GridTransform transform;

  /// The label at (i, j, k); 0 (background) outside the lattice, which closes every structure
  /// at the volume's box.
  std::uint16_t at(std::int64_t i, std::int64_t j, std::int64_t k) const {
    if (i < 0 || j < 0 || k < 0 || i >= dims[0] || j >= dims[1] || k >= dims[2]) return 0;
    return labels[static_cast<std::size_t>(i + dims[0] * (j + dims[1] * k))];
  }
};

/// The labels of a 3D scalar grid. Throws mlfe::Error (naming the first offending voxel) for
/// a 2D grid, a value that is not an integer, or a label below 0 or above 65535.
LabelGrid label_grid(const ScalarGrid& grid);

/// Voxel count per label present (background included), ascending by label.
std::map<std::uint16_t, std::size_t> label_counts(const LabelGrid& g);

/// Replaces every label not in `keep` by the background (0). Labels listed in `keep` that are
/// absent change nothing.
void keep_labels(LabelGrid& g, const std::vector<std::uint16_t>& keep);

/// What remove_small_components removed: connected pieces (6-connected voxels of one label)
/// per label.
struct ComponentRemoval {
  std::map<std::uint16_t, std::size_t> removed;  ///< label -> pieces removed
  std::size_t voxels = 0;                        ///< voxels relabelled
};

/// Relabels every 6-connected piece of a non-background label with fewer than `min_voxels`
/// voxels to the label most of its 6-neighbours outside the piece carry (the lowest such label
/// on ties; the background when it has none). Pieces are visited in lattice order, so the
/// result is deterministic.
ComponentRemoval remove_small_components(LabelGrid& g, std::size_t min_voxels);

/// One tetrahedron of the Kuhn triangulation of the lattice: the cube with lower corner
/// (i, j, k) (-1 .. dims-1: the padded lattice) is cut into 6 tetrahedra along its diagonal
/// from (i, j, k) to (i+1, j+1, k+1); `order` (0..5) picks the axis order of the monotone path
/// from the first corner to the last. Every cube is cut the same way, so the tetrahedra form a
/// conforming mesh: level L of the lattice hierarchy.
struct KuhnTet {
  std::int32_t i = 0, j = 0, k = 0;
  std::uint8_t order = 0;
};

/// The Kuhn tetrahedra of the padded lattice whose four corners carry more than one label, in
/// lattice order (z slowest). Parallel; the same list for any thread count.
std::vector<KuhnTet> mixed_kuhn_tets(const LabelGrid& g);

/// What extraction would make of a label lattice, counted without making it: the mixed
/// tetrahedra (mixed_kuhn_tets(g).size()) and the triangles extract_label_interfaces gives for
/// them. One pass over the labels, no allocation per tetrahedron, so a caller can refuse a
/// label map whose interfaces would not fit before building them.
struct InterfaceCount {
  std::size_t tetrahedra = 0;
  std::size_t triangles = 0;
};
InterfaceCount count_label_interfaces(const LabelGrid& g);

/// The interface complex: triangles between label regions over one shared vertex set (the
/// regions are the labels, InterfaceComplex::labels). Positions are in index coordinates
/// (voxels) of the lattice, so core/simplify's tolerances on it (simplify(), or
/// decimate_interface_complex()) are in voxels.
using LabelInterfaces = InterfaceComplex;

/// Multi-material marching tetrahedra on the given one-voxel Kuhn tetrahedra (mixed_kuhn_tets,
/// or the mixed leaves of a lattice hierarchy): per tetrahedron one triangle or quad through
/// the midpoints of its mixed edges where it holds two labels; where it holds three or four, a
/// fan around its centroid over the interface segments on its faces (across two-label faces
/// between edge midpoints, from edge midpoints to the centroid of three-label faces). Vertices are shared
/// through edge and face keys; the output is sequential and deterministic. Each label's triangles form a
/// closed, consistently oriented surface when `tets` holds every mixed tetrahedron.
LabelInterfaces extract_label_interfaces(const LabelGrid& g, const std::vector<KuhnTet>& tets);

struct LabelSmoothingOptions {
  /// Taubin λ|μ pairs (Taubin 1995: a low-pass filter that does not shrink). 0: no smoothing.
  int iterations = 20;
  double lambda = 0.5, mu = -0.53;
  /// No vertex moves further than this from where extraction put it (voxels): the surfaces stay
  /// within this bound of the labels' voxel boundary (the extracted interface), whatever the
  /// filter does to thin parts and single voxels.
  double max_offset = 0.5;
};

/// Smooths the complex in place. Vertices inside one interface (every edge between the same two
/// labels) move toward their neighbours; vertices on a junction curve (an edge where three or
/// more labels meet) move along the curve only; where curves meet, vertices stay. So interfaces
/// stay shared, junctions stay on the curves where the labels meet, and corners stay put.
/// Jacobi updates: the same result for any thread count.
void smooth_label_interfaces(LabelInterfaces& x, const LabelSmoothingOptions& options);

/// The closed surface of `label`: its triangles from the complex, oriented outward (normals
/// out of the structure), positions mapped to physical coordinates with `t` (windings
/// reversed when `t` mirrors), vertices in first-use order. Empty when the label has none.
TriangleMesh label_surface(const LabelInterfaces& x, std::uint16_t label, const GridTransform& t);

/// The labels that have triangles in `x`, ascending (the background excluded).
std::vector<std::uint16_t> labels_with_surfaces(const LabelInterfaces& x);

/// Checks that every oriented edge of `mesh` has exactly one reverse twin (closed and
/// consistently oriented, non-manifold edges counted in pairs); returns the number of edges
/// without one (0 for a closed surface).
std::size_t unmatched_edges(const TriangleMesh& mesh);

/// Connected pieces of a triangle mesh (triangles sharing a vertex).
std::size_t connected_pieces(const TriangleMesh& mesh);

}  // namespace mlfe
