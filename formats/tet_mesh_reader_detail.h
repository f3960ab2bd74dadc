// Helpers shared by the tetrahedral mesh readers (formats/vtu_reader.cpp, msh_reader.cpp).
// Not part of the public API.
#pragma once
#include <mlfe/formats/tet_mesh_reader.h>

#include <array>
#include <cctype>
#include <charconv>
#include <cstdint>
#include <string>
#include <system_error>

namespace mlfe::tet_mesh_detail {

/// The file name endings of the tetrahedral mesh formats, each a dot and the format's name.
inline constexpr std::array<const char*, 2> kTetMeshExtensions = {".vtu", ".msh"};

/// The mesh in the VTK XML UnstructuredGrid held in `data` (the whole file).
TetMesh read_vtu(const std::string& path, const std::string& data, const TetMeshReadOptions& options,
                 std::uint64_t memory_limit);
/// The mesh in the Gmsh MSH 2.2 / 4.1 file held in `data`.
TetMesh read_msh(const std::string& path, const std::string& data, const TetMeshReadOptions& options,
                 std::uint64_t memory_limit);

/// Throws "<path>: needs N bytes for WHAT but only M bytes of memory are available" when
/// `points` points and `tets` tetrahedra (with values and the reader's scratch) exceed `limit`.
void check_mesh_memory(const std::string& path, std::uint64_t points, std::uint64_t tets,
                       std::uint64_t limit);

/// The next whitespace-separated number of the text [p, end) into v, p moved past it; false
/// (p at the token) when there is none or the token is not entirely a number of type T.
template <class T>
bool next_number(const char*& p, const char* end, T& v) {
  while (p < end && std::isspace(static_cast<unsigned char>(*p))) ++p;
  if (p == end) return false;
  const auto r = std::from_chars(p, end, v);
  if (r.ec != std::errc() || (r.ptr < end && !std::isspace(static_cast<unsigned char>(*r.ptr)))) return false;
  p = r.ptr;
  return true;
}

}  // namespace mlfe::tet_mesh_detail
