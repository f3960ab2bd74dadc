// Reading tetrahedral meshes with point values (finite-element solutions) as mlfe's input
// function: VTK XML UnstructuredGrid (.vtu) and Gmsh MSH 2.2 / 4.1 (.msh).
//
// .vtu (VTK file format 0.1 / 1.0, parsed with expat): one Piece; DataArray format "ascii",
// "binary" (base64, header UInt32 or UInt64 per header_type, optionally compressed with
// vtkZLibDataCompressor) or "appended" (AppendedData encoding "raw" or "base64"); any VTK
// scalar type; either byte order. Cells must all be VTK_TETRA (10).
// .msh: formats 2.2 and 4.1, ASCII and binary (little endian); 4-node tetrahedra (type 4) are
// the mesh, points, lines, triangles and quadrangles are skipped, other volume elements are an
// error; the point values are the first scalar $NodeData view (by node tag).
//
// Like read_volume, every reader validates before it allocates (counts against the file size
// and the memory limit) and reports any bad, truncated or unsupported input as mlfe::Error with
// one line "<file>: <problem>".
#pragma once
#include <mlfe/core/field/tet_mesh_field.h>
#include <mlfe/formats/volume_read_options.h>

#include <cstddef>
#include <string>

namespace mlfe {

struct TetMeshReadOptions {
  /// The point-data array (.vtu) or $NodeData view (.msh) to read; empty: the first scalar one.
  std::string array_name;
  /// Upper bound in bytes for what reading may allocate; 0: default_memory_limit().
  std::size_t max_bytes = 0;
};

/// The mesh options a volume command's options stand for: grid_name names the point-data array
/// (.vtu) or $NodeData view (.msh), and max_bytes is the same memory limit.
TetMeshReadOptions tet_mesh_read_options(const VolumeReadOptions& volume);

/// Reads the mesh and point values at `path` (format by magic, then extension). Indices are
/// checked against the points, coordinates and values must be finite. Throws mlfe::Error.
TetMesh read_tet_mesh(const std::string& path, const TetMeshReadOptions& options = {});

/// "vtu" or "msh" when `path` is a tetrahedral mesh file read_tet_mesh reads (by its first bytes,
/// else its extension), "" otherwise. Throws mlfe::Error when an existing file cannot be read.
std::string detect_tet_mesh_format(const std::string& path);

}  // namespace mlfe
