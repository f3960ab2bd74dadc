#include <mlfe/core/base/error.h>
#include <mlfe/core/base/vec.h>
#include <mlfe/formats/atomic_file.h>
#include <mlfe/formats/vtu_writer.h>

#include <cstdint>
#include <cstring>
#include <ostream>
#include <sstream>
#include <utility>

namespace mlfe {

// Arrays are written with memcpy and declared LittleEndian.
static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "vtu_writer assumes a little-endian host");

namespace {

struct Block {
  std::string xml_open;  // the DataArray element up to (not including) offset="..."
  const void* data;
  std::uint64_t bytes;
};

template <class T>
Block block(const std::string& head, const std::vector<T>& v) {
  return {head, v.data(), static_cast<std::uint64_t>(v.size() * sizeof(T))};
}

}  // namespace

template <int D>
void write_vtu(const std::string& path, const Hierarchy<D>& h, const std::vector<ElemId>& elems,
               const std::vector<double>* point_values, const GridTransform* transform,
               const ElementRegions* regions) {
  const std::size_t nv_all = h.vertex_count();
  if (point_values && point_values->size() != nv_all)
    throw Error(path + ": " + std::to_string(point_values->size()) + " point values for " +
                std::to_string(nv_all) + " vertices");
  for (ElemId e : elems)
    if (!e.valid() || e.value >= h.element_count())
      throw Error(path + ": element id " + std::to_string(e.value) + " out of range");
  if (regions && regions->label.size() != elems.size())
    throw Error(path + ": " + std::to_string(regions->label.size()) + " region labels for " +
                std::to_string(elems.size()) + " elements");

  // Compact the used vertices in VertexId order: deterministic and independent of elems' order.
  constexpr std::uint32_t kUnused = ~std::uint32_t(0);
  std::vector<std::uint32_t> new_index(nv_all, kUnused);
  for (ElemId e : elems)
    for (VertexId v : h.cell(e)) new_index[v.value] = 0;
  std::vector<double> points;
  std::vector<double> values;
  std::uint32_t n = 0;
  for (std::size_t v = 0; v < nv_all; ++v) {
    if (new_index[v] == kUnused) continue;
    new_index[v] = n++;
    std::array<double, 3> local{0.0, 0.0, 0.0};
    const auto& p = h.point(VertexId(static_cast<std::uint32_t>(v)));
    for (int i = 0; i < D; ++i) local[i] = p[i];
    const std::array<double, 3> q = transform ? transform->local_to_physical(local) : local;
    points.insert(points.end(), q.begin(), q.end());
    if (point_values) values.push_back((*point_values)[v]);
  }

  std::vector<std::int64_t> connectivity, offsets;
  std::vector<std::uint8_t> types, levels, kinds;
  connectivity.reserve(elems.size() * (D + 1));
  offsets.reserve(elems.size());
  for (ElemId e : elems) {
    const std::size_t first = connectivity.size();
    for (VertexId v : h.cell(e)) connectivity.push_back(new_index[v.value]);
    // VTK's tetrahedron has positive volume (vtkMeshQuality, ParaView's filters rely on it);
    // red-green refinement keeps no orientation, so order each one in the written frame, as the
    // .msh writer does (a direction matrix with a negative determinant mirrors it, too).
    if constexpr (D == 3) {
      const auto at = [&](int k) {
        const double* p = &points[3 * static_cast<std::size_t>(connectivity[first + k])];
        return Vec3{p[0], p[1], p[2]};
      };
      if (signed_volume6(at(0), at(1), at(2), at(3)) < 0)
        std::swap(connectivity[first + 2], connectivity[first + 3]);
    }
    offsets.push_back(static_cast<std::int64_t>(connectivity.size()));
    types.push_back(D == 2 ? 5 : 10);
    levels.push_back(static_cast<std::uint8_t>(h.level(e)));
    kinds.push_back(static_cast<std::uint8_t>(h.kind(e)));
  }

  // Regions: the cell array `label` (VTK has no region names; they go with the label table).
  std::vector<std::int32_t> labels;
  if (regions) labels.assign(regions->label.begin(), regions->label.end());
  std::vector<Block> point_data, cell_data, pts, cells;
  if (point_values)
    point_data.push_back(
        block(R"(<DataArray type="Float64" Name="u" NumberOfComponents="1" format="appended")", values));
  cell_data.push_back(
      block(R"(<DataArray type="UInt8" Name="level" NumberOfComponents="1" format="appended")", levels));
  cell_data.push_back(
      block(R"(<DataArray type="UInt8" Name="kind" NumberOfComponents="1" format="appended")", kinds));
  if (regions)
    cell_data.push_back(
        block(R"(<DataArray type="Int32" Name="label" NumberOfComponents="1" format="appended")", labels));
  pts.push_back(
      block(R"(<DataArray type="Float64" Name="Points" NumberOfComponents="3" format="appended")", points));
  cells.push_back(block(R"(<DataArray type="Int64" Name="connectivity" format="appended")", connectivity));
  cells.push_back(block(R"(<DataArray type="Int64" Name="offsets" format="appended")", offsets));
  cells.push_back(block(R"(<DataArray type="UInt8" Name="types" format="appended")", types));

  std::ostringstream xml;
  std::uint64_t offset = 0;
  std::vector<const Block*> order;
  auto section = [&](const char* open, const char* close, const std::vector<Block>& blocks) {
    xml << "      " << open << "\n";
    for (const Block& b : blocks) {
      xml << "        " << b.xml_open << " offset=\"" << offset << "\"/>\n";
      offset += 8 + b.bytes;
      order.push_back(&b);
    }
    xml << "      " << close << "\n";
  };
  xml << "<?xml version=\"1.0\"?>\n"
      << "<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" "
         "header_type=\"UInt64\">\n"
      << "  <UnstructuredGrid>\n"
      << "    <Piece NumberOfPoints=\"" << n << "\" NumberOfCells=\"" << elems.size() << "\">\n";
  section(point_values ? "<PointData Scalars=\"u\">" : "<PointData>", "</PointData>", point_data);
  section("<CellData Scalars=\"level\">", "</CellData>", cell_data);
  section("<Points>", "</Points>", pts);
  section("<Cells>", "</Cells>", cells);
  xml << "    </Piece>\n"
      << "  </UnstructuredGrid>\n"
      << "  <AppendedData encoding=\"raw\">\n"
      << "   _";
  const std::string head = xml.str();

  write_file_atomically(path, [&](std::ostream& out) {
    out.write(head.data(), static_cast<std::streamsize>(head.size()));
    for (const Block* b : order) {
      out.write(reinterpret_cast<const char*>(&b->bytes), 8);
      if (b->bytes) out.write(static_cast<const char*>(b->data), static_cast<std::streamsize>(b->bytes));
    }
    const char tail[] = "\n  </AppendedData>\n</VTKFile>\n";
    out.write(tail, sizeof(tail) - 1);
  });
}

template void write_vtu<2>(const std::string&, const Hierarchy<2>&, const std::vector<ElemId>&,
                           const std::vector<double>*, const GridTransform*, const ElementRegions*);
template void write_vtu<3>(const std::string&, const Hierarchy<3>&, const std::vector<ElemId>&,
                           const std::vector<double>*, const GridTransform*, const ElementRegions*);

}  // namespace mlfe
