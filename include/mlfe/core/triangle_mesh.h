// An indexed triangle mesh: the output of iso-surface extraction, the input of the mesh
// writers in formats/. Flat parallel arrays; positions in the output frame's units
// (physical millimetres unless a writer converts), normals unit length (or empty).
#pragma once
#include <array>
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

}  // namespace mlfe
