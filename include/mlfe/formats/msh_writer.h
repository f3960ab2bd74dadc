// Gmsh MSH 4.1 ASCII output of a set of hierarchy elements with per-vertex values and
// per-element levels, for Gmsh and the finite-element tools that read its format.
//
// Layout: $MeshFormat "4.1 0 8"; $Entities with one entity of dimension D (tag 1, the bounding
// box of the written points); $Nodes as one block, tags 1..n for the used vertices in
// increasing VertexId order, physical coordinates; $Elements as one block of type 4
// (4-node tetrahedron) or 2 (3-node triangle), tags 1..m in the given order, vertices
// ordered so a tetrahedron has positive volume (Gmsh's reference orientation);
// $NodeData "u" (when values are given) and $ElementData "level".
// With regions (ElementRegions): $PhysicalNames names one physical group per label present
// (tag = the label; the background 0: tag 65536, named "background" unless the table names it),
// $Entities holds one entity of dimension D per group (ascending label, its own box), and
// $Elements one block per entity; element tags run 1..m in block order.
#pragma once
#include <mlfe/core/field/scalar_grid.h>
#include <mlfe/core/mesh/hierarchy.h>
#include <mlfe/core/mesh/ids.h>
#include <mlfe/formats/element_regions.h>

#include <string>
#include <vector>

namespace mlfe {

/// Writes the elements `elems` of `h` to `path` atomically. `point_values` (may be null) holds
/// one value per vertex of h; `transform` (may be null) maps local coordinates to physical ones.
/// `regions` (may be null): one label per element of `elems` and the groups' names. The bytes
/// depend only on the arguments. Throws mlfe::Error ("<path>: ...") for an element id
/// out of range, a wrong number of values or a file that cannot be written.
template <int D>
void write_msh(const std::string& path, const Hierarchy<D>& h, const std::vector<ElemId>& elems,
               const std::vector<double>* point_values, const GridTransform* transform,
               const ElementRegions* regions = nullptr);

extern template void write_msh<2>(const std::string&, const Hierarchy<2>&, const std::vector<ElemId>&,
                                  const std::vector<double>*, const GridTransform*, const ElementRegions*);
extern template void write_msh<3>(const std::string&, const Hierarchy<3>&, const std::vector<ElemId>&,
                                  const std::vector<double>*, const GridTransform*, const ElementRegions*);

}  // namespace mlfe
