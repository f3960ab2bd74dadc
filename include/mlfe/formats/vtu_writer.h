// VTK XML UnstructuredGrid (.vtu) output of a set of hierarchy elements, for ParaView/VisIt.
//
// Layout (VTK file format version 1.0, byte_order LittleEndian, header_type UInt64):
//   one Piece; Points: Float64 × 3 (2D points get z = 0, then the transform);
//   Cells: connectivity and offsets Int64, types UInt8 (VTK_TRIANGLE = 5, VTK_TETRA = 10);
//   CellData "level" (UInt8) and "kind" (UInt8: 0 coarse, 1 red, 2 green);
//   PointData "u" (Float64) when values are given.
// All arrays are in one <AppendedData encoding="raw"> block, each preceded by its byte count as
// a UInt64, in the order the DataArray elements appear; the XML offsets point at those counts.
#pragma once
#include <mlfe/core/field/scalar_grid.h>
#include <mlfe/core/mesh/hierarchy.h>
#include <mlfe/core/mesh/ids.h>
#include <mlfe/formats/element_regions.h>

#include <string>
#include <vector>

namespace mlfe {

/// Writes the elements `elems` of `h` (usually h.leaves() or h.level_elements(k)) to `path`
/// atomically. Only the vertices the elements use are written, in increasing VertexId order,
/// so the bytes depend only on the arguments. `point_values` (may be null) holds one value per
/// vertex of h (size vertex_count); `transform` (may be null) maps local coordinates to
/// physical ones: p = transform->local_to_physical(local). `regions` (may be null) adds the
/// cell array `label` (Int32, one per element of `elems`). Throws mlfe::Error ("<path>: ...")
/// for an element id out of range, a wrong number of values, or a file that cannot be written.
template <int D>
void write_vtu(const std::string& path, const Hierarchy<D>& h, const std::vector<ElemId>& elems,
               const std::vector<double>* point_values, const GridTransform* transform,
               const ElementRegions* regions = nullptr);

extern template void write_vtu<2>(const std::string&, const Hierarchy<2>&, const std::vector<ElemId>&,
                                  const std::vector<double>*, const GridTransform*, const ElementRegions*);
extern template void write_vtu<3>(const std::string&, const Hierarchy<3>&, const std::vector<ElemId>&,
                                  const std::vector<double>*, const GridTransform*, const ElementRegions*);

}  // namespace mlfe
