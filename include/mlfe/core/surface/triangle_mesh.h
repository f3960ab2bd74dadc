// An indexed triangle mesh: the output of iso-surface extraction, the input of the mesh
// writers in formats/. Flat parallel arrays; positions in the output frame's units
// (physical millimetres unless a writer converts), normals unit length (or empty).
#pragma once
#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace mlfe {

struct TriangleMesh {
  std::vector<std::array<float, 3>> positions;
  std::vector<std::array<float, 3>> normals;            ///< empty, or one per position
  std::vector<std::array<std::uint32_t, 3>> triangles;  ///< counter-clockwise seen from the normal side

  std::size_t vertex_count() const { return positions.size(); }
  std::size_t triangle_count() const { return triangles.size(); }
};

/// Area-weighted vertex normals from the geometry (unit length; (0, 0, 1) for a vertex whose
/// triangles have no area). Replaces `mesh.normals`. Throws mlfe::Error for
/// triangle indices out of range.
void compute_area_weighted_normals(TriangleMesh& mesh);

/// The parts in one mesh, in order: positions appended, each part's triangles shifted by the
/// vertices before it. Normals are kept when every vertex has one and dropped otherwise, so the
/// result is a valid TriangleMesh even when only some parts carry normals. Throws mlfe::Error
/// when the vertices do not fit 32-bit indices. (CHECKs that no part is null.)
TriangleMesh merge_meshes(const std::vector<const TriangleMesh*>& parts);

/// Joins the pieces of one surface cut along its edges, given as merge_meshes of the pieces
/// (`piece_triangles`: each piece's triangle count, in order; CHECKed to sum to the triangles).
/// An open edge a→b of one piece (no triangle of the mesh traverses b→a) and an open edge
/// b'→a' of another piece at the same exact positions are one edge cut in two: a' is welded
/// into a and b' into b (into the earlier vertex). Nothing else is welded, so distinct vertices
/// that share a position (on the surface's own boundary, or inside a piece) stay distinct.
/// Vertices keep their order, less the welded ones; normals follow their vertices (the
/// earlier's is kept). read_gltf joins Draco pieces so. Throws mlfe::Error for triangle indices
/// out of range.
void weld_piece_borders(TriangleMesh& mesh, const std::vector<std::size_t>& piece_triangles);

/// The same surface with its vertices in Morton (Z-curve) order of their positions on a 1024³
/// grid over the bounding box (ties in input order) and its triangles ordered by their first
/// vertex in that order (ties in input order); each triangle keeps its corners' cyclic order,
/// so orientation is kept, and normals follow their vertices. Neighbouring vertices then lie
/// near each other in memory: algorithms that walk one-rings in random order (the verified
/// simplification) run faster. A function of the mesh alone. Throws mlfe::Error for triangle
/// indices out of range. `new_to_old` (may be null) receives, per output vertex, its input vertex.
TriangleMesh spatially_ordered(const TriangleMesh& mesh, std::vector<std::uint32_t>* new_to_old = nullptr);

/// The triangles' indices in Morton (Z-curve) order of their centroids on a 1024³ grid over the
/// positions' bounding box, ties in index order: consecutive runs of it are compact pieces of the
/// surface (how write_gltf cuts a big surface into Draco primitives). A function of the mesh
/// alone, the same at any thread count. Throws mlfe::Error for triangle indices out of range or
/// more than 2^32 triangles.
std::vector<std::uint32_t> triangle_spatial_order(const TriangleMesh& mesh);

/// What makes an indexed triangle mesh one welded, manifold surface, counted (for tests and
/// reports). Vertices are first welded by exact position, since a writer or viewer sees a seam
/// wherever two vertices share a position but not their triangles.
struct MeshTopology {
  std::size_t duplicate_vertices = 0;     ///< vertices at the exact position of an earlier one
  std::size_t degenerate_triangles = 0;   ///< triangles with two corners at one position
  std::size_t boundary_edges = 0;         ///< welded edges in exactly one triangle
  std::size_t non_manifold_edges = 0;     ///< welded edges in three or more triangles
  std::size_t non_manifold_vertices = 0;  ///< welded vertices whose triangles are not one fan
  /// Welded edges in two triangles that traverse it in the same direction (orientation flips).
  std::size_t inconsistent_edges = 0;
  /// Boundary edges that do not lie on the faces of the box given to mesh_topology.
  std::size_t boundary_edges_off_box = 0;

  bool welded_manifold() const {
    return duplicate_vertices == 0 && degenerate_triangles == 0 && non_manifold_edges == 0 &&
           non_manifold_vertices == 0 && inconsistent_edges == 0;
  }
};

/// Counts the MeshTopology figures of `mesh`. With box_min/box_max (mesh units), a boundary edge
/// whose two ends lie within box_tolerance of one common face of the box counts as on the box
/// (a surface cut by the volume's faces); every other one counts in boundary_edges_off_box.
/// Throws mlfe::Error for triangle indices out of range.
MeshTopology mesh_topology(const TriangleMesh& mesh, const std::array<double, 3>* box_min = nullptr,
                           const std::array<double, 3>* box_max = nullptr, double box_tolerance = 0);

/// By index (no welding): 1 for every vertex where `triangles` is not an oriented 2-manifold
/// (an end of an edge in three or more triangles, or in two that traverse it the same way; a
/// vertex whose triangles form more than one fan), 0 elsewhere; triangles with a repeated
/// index are ignored. Throws mlfe::Error for an index >= vertex_count.
std::vector<std::uint8_t> non_manifold_vertices(const std::vector<std::array<std::uint32_t, 3>>& triangles,
                                                std::size_t vertex_count);

}  // namespace mlfe
