// Triangle meshes through OpenMesh: conversion, the classic mesh file formats (.ply, .obj,
// .off, .stl) and quadric decimation for coarser levels of detail.
#pragma once
// OpenMesh registers its readers/writers only when MeshIO.hh is seen before a mesh kernel.
#include <mlfe/core/surface/triangle_mesh.h>

#include <OpenMesh/Core/IO/MeshIO.hh>
#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>
#include <cstddef>
#include <string>

namespace mlfe {

/// OpenMesh's default triangle mesh: float points and normals.
using OpenMeshTriMesh = OpenMesh::TriMesh_ArrayKernelT<>;

/// Converts to OpenMesh. Vertex normals are requested and copied when `mesh` has them.
/// Triangles with repeated indices are dropped; a triangle OpenMesh refuses because it would
/// make the mesh non-manifold gets its own copies of its three vertices, so no triangle is lost.
/// Throws mlfe::Error for indices out of range or a normal count that is neither 0 nor one per
/// position.
OpenMeshTriMesh to_openmesh(const TriangleMesh& mesh);

/// Converts back, skipping deleted elements. Normals are copied when the mesh has vertex
/// normals, else left empty.
TriangleMesh from_openmesh(const OpenMeshTriMesh& mesh);

/// Writes `mesh` (units unchanged) by extension, case-insensitive: .ply (binary little-endian,
/// with normals), .obj (with vn), .off (NOFF when normals exist), .stl (binary; per-face normals
/// computed from the geometry). Coordinates keep full float precision in text formats. Same
/// input gives byte-identical files. The file appears atomically. Throws mlfe::Error
/// ("<path>: ...") for other extensions, bad meshes (see to_openmesh) and I/O failures.
void write_mesh_file(const std::string& path, const TriangleMesh& mesh);

/// Reads any format OpenMesh knows (by extension), with vertex normals when the file has them.
/// Throws mlfe::Error ("<path>: ...") when the file is missing or unreadable.
TriangleMesh read_mesh_file(const std::string& path);

/// Quadric-error decimation (OpenMesh Decimater + ModQuadric without an error bound, plus
/// ModNormalFlipping refusing collapses that turn a face normal by more than 60 degrees) down
/// to `target_triangles`. Collapses remove two triangles each, so the result is target or
/// target-1, or more when topology or the normal limit blocks further collapses (tiny or
/// very jagged meshes); callers that need a hard bound must check triangle_count().
/// A mesh already at or below the target is returned unchanged. Otherwise normals are recomputed
/// (area-weighted) from the decimated geometry. Throws mlfe::Error like to_openmesh.
TriangleMesh decimate_to(const TriangleMesh& mesh, std::size_t target_triangles);

}  // namespace mlfe
