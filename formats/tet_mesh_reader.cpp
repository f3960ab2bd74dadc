// Tetrahedral mesh input (.vtu, .msh): format detection, the memory check both readers share,
// and the checks every mesh passes before the finite-element core sees it.
#include <fmt/format.h>
#include <mlfe/formats/tet_mesh_reader.h>
#include <mlfe/formats/zarr_reader.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstring>
#include <new>

#include "formats/reader_helpers.h"
#include "formats/tet_mesh_reader_detail.h"

namespace mlfe {

namespace tet_mesh_detail {

void check_mesh_memory(const std::string& path, std::uint64_t points, std::uint64_t tets,
                       std::uint64_t limit) {
  // Per point: coordinates, value, tag and index while reading, the field's local copy;
  // per tetrahedron: indices while reading and the field's ~160 bytes.
  constexpr std::uint64_t kPerPoint = 96, kPerTet = 224;
  constexpr std::uint64_t kMax = std::uint64_t(1) << 40;
  if (points > kMax || tets > kMax)
    volume_detail::fail(path, fmt::format("{} points, {} cells: too many", points, tets));
  volume_detail::check_memory(path, points * kPerPoint + tets * kPerTet, limit,
                              fmt::format("{} points and {} tetrahedra", points, tets));
}

}  // namespace tet_mesh_detail

std::string detect_tet_mesh_format(const std::string& path) {
  if (is_zarr_store(path)) return "";  // a folder of chunks, for the volume readers
  const std::string head = read_file_prefix(path, 512);
  if (head.compare(0, 11, "$MeshFormat") == 0) return "msh";
  if (head.find("<VTKFile") != std::string::npos && head.find("UnstructuredGrid") != std::string::npos)
    return "vtu";
  std::string lower = path;
  std::transform(lower.begin(), lower.end(), lower.begin(),
                 [](unsigned char c) { return char(std::tolower(c)); });
  for (const char* ext : tet_mesh_detail::kTetMeshExtensions) {
    const std::size_t n = std::strlen(ext);
    if (lower.size() >= n && lower.compare(lower.size() - n, n, ext) == 0) return ext + 1;
  }
  return "";
}

TetMeshReadOptions tet_mesh_read_options(const VolumeReadOptions& volume) {
  TetMeshReadOptions o;
  o.array_name = volume.grid_name;
  o.max_bytes = volume.max_bytes;
  return o;
}

TetMesh read_tet_mesh(const std::string& path, const TetMeshReadOptions& options) {
  const std::string format = detect_tet_mesh_format(path);
  if (format.empty()) volume_detail::fail(path, "not a tetrahedral mesh (.vtu or .msh)");
  const std::uint64_t limit = options.max_bytes ? options.max_bytes : default_memory_limit();
  TetMesh m;
  try {
    const std::string data = read_regular_file(path, limit, "the file");
    m = format == "vtu" ? tet_mesh_detail::read_vtu(path, data, options, limit)
                        : tet_mesh_detail::read_msh(path, data, options, limit);
  } catch (const Error&) {
    throw;
  } catch (const std::bad_alloc&) {
    volume_detail::fail(path, "out of memory while reading");
  } catch (const std::exception& e) {
    volume_detail::fail(path, e.what());
  }
  if (m.tets.empty()) volume_detail::fail(path, "no tetrahedra");
  const std::size_t np = m.points.size();
  for (std::size_t i = 0; i < np; ++i) {
    const auto& p = m.points[i];
    if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2]))
      volume_detail::fail(path, fmt::format("point {} has a coordinate that is not a finite number", i));
    if (!std::isfinite(m.values[i]))
      volume_detail::fail(path,
                          fmt::format("the value '{}' at point {} is not a finite number", m.value_name, i));
  }
  for (std::size_t t = 0; t < m.tets.size(); ++t)
    for (std::int32_t v : m.tets[t])
      if (v < 0 || std::size_t(v) >= np)
        volume_detail::fail(path, fmt::format("tetrahedron {} has point index {} out of range", t, v));
  m.source = path;
  return m;
}

}  // namespace mlfe
