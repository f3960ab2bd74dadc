// Internal to mlfe::core: what the two iso-surface extractors (marching tetrahedra on the
// hierarchy, marching cubes on the samples' lattice) share.
#pragma once
#include <mlfe/core/surface/iso_surface.h>
#include <mlfe/core/surface/triangle_mesh.h>

#include <array>
#include <cstddef>
#include <vector>

namespace mlfe::detail {

/// Drops the connected parts of `mesh` (triangles joined through shared vertices) whose vertices
/// (`local`, the grid-aligned local frame) lie in fewer than `min_cells` voxel cells of the
/// lattice with this `spacing`, and the vertices only they used (from `local` and `grad` too,
/// which run parallel to the vertices). Parts and order are a function of the mesh alone.
Dropped drop_small_parts(TriangleMesh& mesh, std::vector<std::array<double, 3>>& local,
                         std::vector<std::array<double, 3>>& grad, const std::array<double, 3>& spacing,
                         std::size_t min_cells);

/// Fills mesh.positions and mesh.normals from `local` (the grid-aligned local frame) and `grad`
/// (gradients there), mapped through `transform`: unit normals toward lower values, or higher
/// with normals_toward_higher (a zero gradient gives +z). A reflecting transform (det < 0)
/// reverses every triangle, so counter-clockwise still faces the normals' side.
void to_physical(TriangleMesh& mesh, const std::vector<std::array<double, 3>>& local,
                 const std::vector<std::array<double, 3>>& grad, const GridTransform& transform,
                 bool normals_toward_higher);

}  // namespace mlfe::detail
