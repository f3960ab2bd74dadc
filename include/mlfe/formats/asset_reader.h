// Surfaces read back from every asset format write_asset writes (.glb/.gltf with or without
// Draco, .drc, .ply, .obj, .stl, .off), through the readers `compare` uses: read_gltf,
// read_draco_file and OpenMesh's read_mesh_file. The inverse of write_asset, for the Python
// module's read_mesh and for comparing files with meshes held in memory.
#pragma once
#include <mlfe/formats/gltf_writer.h>

#include <array>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace mlfe {

/// An asset file's surfaces as write_asset's input describes them, in the file's own frame.
struct AssetFile {
  /// The file's encoding: "glb", "gltf", "drc", "ply", "obj", "stl" or "off" (by its magic bytes
  /// first, its extension second).
  std::string format;
  /// True for glTF: positions in glTF's metres and axes as stored (+Y up, see gltf_writer.h);
  /// false: the scan's millimetres (what the other formats store, and what write_asset takes).
  bool gltf_frame = false;
  /// glTF: one surface per node of a triangle mesh (primitives merged; nodes that are another
  /// node's MSFT_lod level become its `lods`) and per mesh-less node mlfe wrote for an empty
  /// surface, in node order: node name, mesh name, the first primitive's material colour
  /// (glTF's default white without one), node extras without the writer's "lod" and
  /// "triangles" ({"iso_value": v} alone becomes iso_value). Other formats: one unnamed surface.
  std::vector<GltfSurface> surfaces;
  /// Per surface: the grid step of Draco's quantized positions in the positions' units (the
  /// largest of its primitives'), 0 when not Draco-compressed.
  std::vector<double> quantization_steps;
  /// glTF: the scan's anatomical space mlfe recorded (asset.extras.mlfe.input_space), else "".
  std::string space;
  /// glTF: the matrix from scan millimetres to glTF metres mlfe recorded
  /// (asset.extras.mlfe.physical_to_gltf), else physical_to_gltf_matrix(space).
  std::array<double, 9> physical_to_gltf = physical_to_gltf_matrix("");
  /// glTF: asset.extras (the provenance) without mlfe's frame record ("mlfe") and the
  /// tolerance write_asset adds; an empty object for the other formats.
  nlohmann::json extras = nlohmann::json::object();
  /// glTF: the Draco/quantization tolerance recorded in millimetres, else 0.
  double tolerance_mm = 0.0;
};

/// Reads `path` (see AssetFile). Throws mlfe::Error ("<path>: <problem>") for a file that is
/// not one of the asset formats and the readers' errors (unreadable, damaged, indices out of
/// range, a physical_to_gltf record that is not 9 finite numbers of an invertible matrix).
AssetFile read_asset(const std::string& path);

/// Moves a glTF-frame asset into the scan's millimetres: positions through the inverse of
/// physical_to_gltf (the inverse of what write_gltf does), normals rotated and renormalized,
/// triangles flipped if the matrix mirrors, quantization steps scaled. Frees `asset` of the glTF
/// frame (gltf_frame false); an asset already in the scan's frame is left as it is.
void to_scan_frame(AssetFile& asset);

}  // namespace mlfe
