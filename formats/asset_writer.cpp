// write_asset: the asset extensions mapped to the glTF, Draco and OpenMesh writers.
#include <mlfe/core/base/error.h>
#include <mlfe/formats/asset_writer.h>
#include <mlfe/formats/draco_io.h>
#include <mlfe/formats/file_names.h>
#include <mlfe/formats/openmesh_io.h>

#include <algorithm>
#include <utility>

namespace mlfe {

const std::vector<std::string> kAssetExtensions = {".glb", ".gltf", ".drc", ".ply", ".obj", ".stl", ".off"};

TriangleMesh merged_mesh(const std::vector<GltfSurface>& surfaces) {
  std::vector<const TriangleMesh*> parts;
  parts.reserve(surfaces.size());
  for (const auto& s : surfaces) parts.push_back(&s.mesh);
  return merge_meshes(parts);
}

namespace {

// merged_mesh(surfaces), the one surface of `owned` taken rather than copied (what merge_meshes
// keeps of a single part: its arrays, normals only when every vertex has one).
TriangleMesh merged_mesh(const std::vector<GltfSurface>& surfaces, std::vector<GltfSurface>* owned) {
  if (!owned || owned->size() != 1) return merged_mesh(surfaces);
  TriangleMesh mesh = std::move((*owned)[0].mesh);
  if (mesh.normals.size() != mesh.positions.size()) mesh.normals.clear();
  return mesh;
}

// write_asset's body; `owned`: the same surfaces when the caller gave them up.
void write_asset_of(const std::vector<GltfSurface>& surfaces, std::vector<GltfSurface>* owned,
                    const std::string& path, const AssetWriteOptions& options) {
  const std::string ext = lower_extension(path);
  if (std::find(kAssetExtensions.begin(), kAssetExtensions.end(), ext) == kAssetExtensions.end())
    throw Error(path + ": not an asset type (expected .glb, .gltf, .drc, .ply, .obj, .stl or .off)");
  if (ext == ".glb" || ext == ".gltf") {
    GltfOptions o;
    o.draco = options.draco;
    o.quantize = options.quantize;
    o.tolerance_mm = options.tolerance_mm;
    o.space = options.space;
    o.extras = options.extras;
    o.extras["tolerance_mm"] = options.tolerance_mm;
    if (owned)
      write_gltf(path, std::move(*owned), o);
    else
      write_gltf(path, surfaces, o);
    return;
  }
  TriangleMesh merged = merged_mesh(surfaces, owned);
  if (owned) std::vector<GltfSurface>().swap(*owned);
  if (ext == ".drc") {
    DracoOptions o;
    o.tolerance = options.tolerance_mm;
    write_draco_file(path, std::move(merged), o);
  } else {
    write_mesh_file(path, merged);
  }
}

}  // namespace

void write_asset(const std::vector<GltfSurface>& surfaces, const std::string& path,
                 const AssetWriteOptions& options) {
  write_asset_of(surfaces, nullptr, path, options);
}

void write_asset(std::vector<GltfSurface>&& surfaces, const std::string& path,
                 const AssetWriteOptions& options) {
  write_asset_of(surfaces, &surfaces, path, options);
}

}  // namespace mlfe
