// Iso-surfaces of the piecewise-linear approximation u by marching tetrahedra on the
// hierarchy (Grosso, Lürig & Ertl, IEEE Vis 1997, Sec. 5): u is linear on every tetrahedron,
// so each tetrahedron cut by the iso-value contributes one triangle or one quadrilateral (two
// triangles); vertex normals are the volume-weighted average of the per-tetrahedron gradients
// at the mesh vertices (the paper), interpolated along the cut edge.
//
// Output-sensitive: an IsoExtractor keeps, for every element, the range of u over its subtree,
// so whole subtrees that cannot contain the iso-value are skipped.
//
// Guarantees: one output vertex per cut mesh edge (welded, indexed; a cut exactly at a mesh
// vertex becomes that vertex, shared by all edges through it); no degenerate (index-repeating)
// triangles; each triangle oriented so that its normal points toward lower values of u (or
// higher, by option); vertex and triangle order are a deterministic function of the input.
#pragma once
#include <mlfe/core/field/field.h>
#include <mlfe/core/field/scalar_grid.h>
#include <mlfe/core/mesh/hierarchy.h>
#include <mlfe/core/surface/triangle_mesh.h>

#include <array>
#include <cstdint>
#include <vector>

namespace mlfe {

struct IsoOptions {
  bool normals_toward_higher = false;  ///< default: normals point toward lower values
  int level = -1;                      ///< extract on T_level (coarser, via the hierarchical
                                       ///< basis); -1: the finest (leaf) triangulation
  /// When set (the input f the hierarchy approximates, in the hierarchy's local frame; it must
  /// outlive the call): every vertex moves along u's gradient onto the data's own surface
  /// f = iso, the nearest crossing within `snap_distance` (local units) on either side, so the
  /// asset carries the scan's surface instead of the approximation's, at the same triangles.
  /// A vertex with no crossing in reach, or whose move would leave the domain or flip one of
  /// its triangles, stays where u put it. Normals stay the paper's (gradients of u).
  /// Cost: up to 8 * snap_distance / resolution samples of f per vertex (a reach beyond the
  /// domain's diagonal is cut to it).
  const Field* snap_to = nullptr;
  double snap_distance = 0;
  /// When set, the surface is clipped to the box [0, clip_to] of the local frame: a hierarchy
  /// on the samples' lattice (sample_lattice.h) covers a padded cube, and only the data's box
  /// is the data. Triangles wholly outside are dropped, those across a face cut along it (the
  /// cut points welded: one per cut surface edge and face).
  bool clip = false;
  std::array<double, 3> clip_to{0, 0, 0};
  /// Drops the connected parts of the surface (triangles joined through shared vertices) whose
  /// vertices lie in fewer than this many voxel cells of the transform's sample lattice (a
  /// speck of noise around one sample touches up to 8); 0 keeps every part.
  std::size_t min_component = 0;
  /// When set, receives what min_component dropped.
  struct Dropped* dropped = nullptr;
};

/// What IsoOptions::min_component dropped from one extraction.
struct Dropped {
  std::size_t parts = 0;       ///< connected parts dropped
  std::size_t triangles = 0;   ///< their triangles
  std::size_t kept_parts = 0;  ///< connected parts kept
};

class IsoExtractor {
 public:
  /// values: u at every vertex of h (mlfe::Error otherwise). Both must outlive the extractor.
  IsoExtractor(const Hierarchy<3>& h, const std::vector<double>& values);

  /// The iso-surface u = iso on T_level (values on coarser levels come from the hierarchical
  /// basis: surpluses of finer vertices dropped). Positions are mapped to the physical frame
  /// with `transform` (normals rotated with it). Elements never visited: see the header note.
  TriangleMesh extract(double iso, const GridTransform& transform, const IsoOptions& opts = {}) const;

  /// Elements visited by the last extract() (for tests of output sensitivity).
  std::size_t visited_elements() const { return visited_; }

 private:
  const Hierarchy<3>& h_;
  const std::vector<double>& values_;
  std::vector<float> lo_, hi_;  // subtree range of u per element (rounded outward)
  mutable std::size_t visited_ = 0;
};

/// Where a vertex of lattice_iso_surface lies on the samples' lattice: on the edge from sample
/// `at` to its neighbour along `axis` (0, 1, 2), or, with axis 3, inside the cube whose lowest
/// corner is `at` (the centre of a loop no fan could triangulate).
struct LatticePlace {
  std::array<std::int32_t, 3> at{0, 0, 0};
  int axis = 0;
};

/// The iso-surface of the samples themselves (their trilinear interpolant), by marching cubes on
/// the grid's lattice: the finest level of a hierarchy on the samples' lattice, without building
/// it (core/surface/lattice_iso_surface.cpp). One vertex per lattice edge the iso-value crosses (a sample
/// is above when its value > iso; a crossing at a sample moves 1/1024 of the edge off it), so
/// the surface is welded, closed where the data's surface is (boundary edges only at the
/// volume's faces), consistently oriented, and every vertex's triangles form one fan. Positions
/// and normals (the samples' central-difference gradients, interpolated along the edge) are
/// mapped through grid.transform. Of `opts`, only normals_toward_higher, min_component and
/// dropped apply. Vertex and triangle order are a function of the grid alone. grid.dim must be 3.
/// `places` (may be null) receives each output vertex's LatticePlace.
TriangleMesh lattice_iso_surface(const ScalarGrid& grid, double iso, const IsoOptions& opts = {},
                                 std::vector<LatticePlace>* places = nullptr);

/// The part of lattice_iso_surface of a bigger grid that the samples [lo, hi) of `window` span
/// (the cubes between them), where `window` holds the bigger grid's samples from lattice
/// coordinate `window_at` on and has its transform. Positions, normals and places are the bigger
/// grid's, to the bit, when `window` also holds the samples next to [lo, hi) that the bigger grid
/// has (the gradients' central differences read them): so parts extracted from neighbouring
/// windows meet exactly. Vertex and triangle order are a function of the samples in [lo, hi).
/// lo < hi <= window.dims per axis (CHECK).
TriangleMesh lattice_iso_surface(const ScalarGrid& window, const std::array<std::int64_t, 3>& window_at,
                                 const std::array<std::int64_t, 3>& lo, const std::array<std::int64_t, 3>& hi,
                                 double iso, const IsoOptions& opts = {},
                                 std::vector<LatticePlace>* places = nullptr);

/// A 2D height field as a surface: the leaf triangles (or T_level) lifted to z = z_scale·u,
/// mapped through the transform's x/y part (z added along the third axis of the direction),
/// normals from the lifted triangles, area-weighted. For DEMs and images.
TriangleMesh height_field_surface(const Hierarchy<2>& h, const std::vector<double>& values,
                                  const GridTransform& transform, double z_scale, int level = -1);

}  // namespace mlfe
