// Surfaces written as one asset file, the format chosen by the file's extension: the one place
// that maps the asset extensions to the glTF, Draco and OpenMesh writers, for the convert and
// label pipelines and the Python module alike.
#pragma once
#include <mlfe/core/surface/triangle_mesh.h>
#include <mlfe/formats/gltf_writer.h>

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace mlfe {

/// The extensions write_asset accepts (lower case, with the dot): .glb .gltf .drc .ply .obj .stl .off.
extern const std::vector<std::string> kAssetExtensions;

/// Callers brace-initialize it in this order ({draco, quantize, tolerance_mm, space, extras}):
/// new fields go at the end.
struct AssetWriteOptions {
  bool draco = true;           ///< glTF only: KHR_draco_mesh_compression (GltfOptions::draco)
  bool quantize = false;       ///< glTF only: KHR_mesh_quantization without Draco
  double tolerance_mm = 0.01;  ///< max position error per coordinate of Draco/quantization, mm; > 0
  std::string space;           ///< glTF only: "RAS", "LPS" or "" of the positions (GltfOptions::space)
  nlohmann::json extras = nlohmann::json::object();  ///< glTF only: provenance for asset.extras
};

/// All surfaces in one mesh (merge_meshes of their meshes, in order; their LODs left out): what
/// the single-mesh formats store.
TriangleMesh merged_mesh(const std::vector<GltfSurface>& surfaces);

/// Writes `surfaces` (physical millimetres) to `path` by its extension, case-insensitive:
/// .glb/.gltf through write_gltf, one node per surface (with its LODs), asset.extras being
/// options.extras plus "tolerance_mm"; .drc the Draco encoding of merged_mesh(surfaces) within
/// tolerance_mm; .ply/.obj/.stl/.off write_mesh_file of merged_mesh(surfaces) (no compression,
/// tolerance unused). The file appears atomically; same inputs give the same bytes. Throws
/// mlfe::Error ("<path>: ...") for an extension not in kAssetExtensions, and the writers' errors
/// (bad meshes, tolerance_mm <= 0 with compression, I/O).
void write_asset(const std::vector<GltfSurface>& surfaces, const std::string& path,
                 const AssetWriteOptions& options);

/// The same, giving the surfaces up: their meshes are released as they are written (the same
/// bytes; `surfaces` is left unspecified).
void write_asset(std::vector<GltfSurface>&& surfaces, const std::string& path,
                 const AssetWriteOptions& options);

}  // namespace mlfe
