// Reading glTF 2.0 assets (.glb, .gltf) back into triangle meshes for comparison: the JSON is
// parsed with nlohmann::json, buffers come from the GLB BIN chunk, data: URIs or files next to
// the asset, Draco decodes KHR_draco_mesh_compression primitives, and node transforms are
// applied so positions are in the scene's frame (metres, +Y up for mlfe's assets).
#pragma once
#include <mlfe/core/surface/triangle_mesh.h>

#include <array>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace mlfe {

/// One triangle surface of one node, in world coordinates: a triangle primitive, or the pieces of
/// one surface joined (see GltfAsset::primitives).
struct GltfPrimitive {
  /// "node <i> '<node name>' mesh '<mesh name>' primitive <p>", " (+<k> joined)" added for pieces
  std::string label;
  int node = -1, mesh = -1;
  int primitive = -1;      ///< the (first) primitive's index in its mesh
  TriangleMesh mesh_data;  ///< positions and normals transformed by the node's world matrix
  /// The grid step of Draco-quantized positions (DracoQuantization::step) in world units (times
  /// the node's largest scale), the largest of joined pieces'; 0 when not Draco-compressed.
  double quantization_step = 0.0;
};

struct GltfAsset {
  /// Every triangle primitive of every node that has a mesh, in node order then primitive
  /// order (nodes outside the scene, such as MSFT_lod levels, included). Triangle primitives of
  /// one mesh that are equal but for their data (the same attribute names, material, extras and
  /// other extensions) are the pieces of one surface (write_gltf's Draco pieces of a big level,
  /// or an exporter's 16-bit index splits): they come as one, at the first one's place, merged
  /// and welded by weld_piece_borders (matching open edges of two pieces at identical decoded
  /// positions become one), so a surface reads the same however it was cut.
  std::vector<GltfPrimitive> primitives;
  /// The glTF JSON without what only encodes the data: buffers, bufferViews, accessors,
  /// images' and primitives' data references, node transforms (their effect is in the geometry),
  /// the pieces of one surface but the first (see `primitives`)
  /// and the compression extensions KHR_draco_mesh_compression, KHR_mesh_quantization and
  /// EXT_meshopt_compression (in extensionsUsed/Required too). What remains is the scene graph,
  /// names, materials, other extensions and extras.
  nlohmann::json structure;
  /// How the geometry is stored, the part of the JSON that `structure` leaves out but which is
  /// not data: {"extensions": the compression extensions used, sorted; "mlfe": asset.extras.mlfe's
  /// encoding and tolerance_mm when present}.
  nlohmann::json encoding;
};

/// Reads a .glb or .gltf file (by magic bytes: "glTF" is binary, anything else JSON).
/// Triangle primitives (mode 4) with float or (normalized) integer positions
/// (KHR_mesh_quantization) and optional normals are read; other modes are skipped (they stay
/// visible in `structure`). Throws mlfe::Error ("<path>: <problem>") for unreadable files, bad
/// JSON, buffers or accessors outside their data, indices out of range, sparse accessors,
/// buffer URIs that leave the asset's folder and Draco payloads that do not decode.
GltfAsset read_gltf(const std::string& path);

/// Moves `mesh` by x -> linear * x + translation (`linear` row-major, invertible): positions
/// mapped, normals through the inverse transpose and renormalized, and the winding flipped when
/// the map mirrors (det < 0), so triangles stay counter-clockwise seen from their normals' side.
/// How read_gltf applies node transforms, and read_asset's to_scan_frame.
void transform_mesh(TriangleMesh& mesh, const std::array<double, 9>& linear,
                    const std::array<double, 3>& translation = {0.0, 0.0, 0.0});

/// The files next to the asset at `path` that its buffer URIs name (data: URIs and the GLB BIN
/// chunk are not files), as read_gltf reads them. Throws mlfe::Error as read_gltf does for a
/// file that is not glTF or a URI that leaves the asset's folder.
std::vector<std::string> gltf_buffer_files(const std::string& path);

}  // namespace mlfe
