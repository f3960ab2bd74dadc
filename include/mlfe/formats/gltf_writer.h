// glTF 2.0 export of iso-surfaces (.glb, or .gltf with the buffer embedded as base64).
//
// Frame: input positions are physical millimetres in the volume's anatomical space; glTF is
// metres, +Y up, +Z front, right-handed, and the asset's right side points to -X. Superior
// maps to +Y and anterior to +Z, so a viewer shows the patient upright, facing the camera.
// The matrix used is recorded in asset.extras.mlfe.physical_to_gltf.
#pragma once
#include <mlfe/core/surface/triangle_mesh.h>

#include <array>
#include <cstddef>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace mlfe {

struct GltfSurface {
  std::string name;  ///< mesh name; empty gives "iso <iso_value>"
  double iso_value = 0.0;
  TriangleMesh mesh;  ///< physical millimetres in GltfOptions::space; normals optional
  std::array<float, 4> color{0.8f, 0.8f, 0.8f, 1.0f};  ///< linear RGBA in [0,1]; alpha < 1 => BLEND
  std::vector<TriangleMesh> lods;  ///< coarser levels, finest first; written as extra nodes
  std::string node_name;           ///< empty gives "iso <iso_value>"
  /// Node extras (an object, e.g. a structure's label value) written instead of iso_value;
  /// null: {"iso_value": iso_value}. lod and triangles are added either way.
  nlohmann::json node_extras;
};

struct GltfOptions {
  bool draco = true;           ///< KHR_draco_mesh_compression (required extension)
  bool quantize = false;       ///< KHR_mesh_quantization for uncompressed output (ignored with draco)
  double tolerance_mm = 0.01;  ///< max position error per coordinate from Draco/quantization, mm
  std::string space;           ///< "RAS", "LPS" or "" (unknown, treated as RAS) of the input positions
  nlohmann::json extras = nlohmann::json::object();  ///< provenance, copied into asset.extras
  std::string generator = "mlfe";                    ///< asset.generator
  /// Draco only: the most triangles one primitive holds. Draco's encoder needs about 5 times the
  /// mesh it encodes, so a bigger surface level is cut into ceil(T / draco_piece_triangles)
  /// primitives of its mesh, balanced runs of triangle_spatial_order (compact pieces; a function
  /// of the mesh, so the bytes do not depend on the thread count), encoded one at a time: the
  /// writing costs the converted level plus one piece's encoding. All pieces share the scene's
  /// quantization grid, so a vertex on a border between pieces decodes to the same position in
  /// each, and read_gltf joins the pieces back into one welded surface. Levels of at most this
  /// many triangles stay one primitive (their bytes are what they were before pieces). >= 1.
  std::size_t draco_piece_triangles = std::size_t(1) << 20;
};

/// Writes one scene with one node, mesh and material per surface, to `path` (.glb binary or
/// .gltf JSON with an embedded data-URI buffer, chosen by the extension, case-insensitive).
/// Positions are converted with physical_to_gltf_matrix(options.space); normals are rotated,
/// renormalized and computed from the triangles when a surface has none. Surfaces without
/// triangles become nodes without a mesh; triangles with two equal corners are dropped.
/// Node names are "iso <iso_value>" (node extras: iso_value, lod, triangles) unless a surface
/// names its node (GltfSurface::node_name, node_extras). LOD k (from 1)
/// is a node "iso <v> lod <k>" referenced by MSFT_lod (optional extension) from the surface
/// node and kept out of the scene, so viewers without LOD support show only the full surface.
/// Draco: every primitive is compressed on one scene-wide quantization grid (crack-free between
/// surfaces and between the pieces of a big level, see draco_piece_triangles), verified by
/// decoding; accessors describe the decoded data. quantize: positions
/// and normals as normalized SHORT under a root node "mlfe dequantize" whose uniform scale and
/// translation restore metres; throws if 16 bits cannot meet tolerance_mm.
/// The file appears atomically; same inputs give byte-identical files.
/// Throws mlfe::Error ("<path>: <problem>") for an unknown extension or space, non-finite
/// or out-of-range mesh data, tolerance_mm <= 0 with compression, draco_piece_triangles 0 with
/// Draco, encoder failures and I/O errors.
void write_gltf(const std::string& path, const std::vector<GltfSurface>& surfaces,
                const GltfOptions& options);

/// The same, giving the surfaces up: each mesh is released once converted for writing, so a big
/// surface is not held beside its encoding (the same bytes; `surfaces` is left unspecified).
void write_gltf(const std::string& path, std::vector<GltfSurface>&& surfaces, const GltfOptions& options);

/// Row-major 3x3 matrix M with gltf_metres = M * physical_mm for input space "RAS" (also "")
/// or "LPS": RAS -> 0.001*(-x, z, y), LPS -> 0.001*(x, z, -y). 1000*M is a proper rotation
/// (det +1), so triangle winding and normals stay valid. Throws mlfe::Error for other spaces.
std::array<double, 9> physical_to_gltf_matrix(const std::string& space);

}  // namespace mlfe
