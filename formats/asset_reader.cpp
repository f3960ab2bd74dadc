// read_asset: the asset formats mapped back to their readers, glTF nodes to surfaces.
#include <fmt/format.h>
#include <mlfe/core/base/error.h>
#include <mlfe/formats/asset_reader.h>
#include <mlfe/formats/draco_io.h>
#include <mlfe/formats/file_names.h>
#include <mlfe/formats/gltf_reader.h>
#include <mlfe/formats/openmesh_io.h>
#include <mlfe/formats/safe_read.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstring>
#include <map>
#include <set>

namespace mlfe {
namespace {

/// The asset format of `path`: magic bytes first (they cannot lie), the extension second.
std::string asset_format(const std::string& path) {
  const std::string head = read_file_prefix(path, 5);
  if (head.size() >= 4 && std::memcmp(head.data(), "glTF", 4) == 0) return "glb";
  if (head == "DRACO") return "drc";
  const std::string ext = lower_extension(path);
  for (const char* known : {".gltf", ".glb", ".drc", ".ply", ".obj", ".stl", ".off"})
    if (ext == known) return ext.substr(1);
  throw Error(path + ": not a mesh file (expected .glb, .gltf, .drc, .ply, .obj, .stl or .off)");
}

const nlohmann::json& member(const nlohmann::json& j, const char* key) {
  static const nlohmann::json null;
  return j.is_object() && j.contains(key) ? j.at(key) : null;
}

/// The nodes that are another node's MSFT_lod level, and each surface node's levels in order.
std::map<int, std::vector<int>> lod_levels(const nlohmann::json& nodes, std::set<int>& levels) {
  std::map<int, std::vector<int>> out;
  for (std::size_t i = 0; i < nodes.size(); ++i) {
    const nlohmann::json& ids = member(member(member(nodes[i], "extensions"), "MSFT_lod"), "ids");
    if (!ids.is_array()) continue;
    for (const auto& id : ids)
      if (id.is_number_integer() && id.get<std::int64_t>() >= 0 &&
          id.get<std::int64_t>() < std::int64_t(nodes.size()) && id.get<int>() != int(i)) {
        out[int(i)].push_back(id.get<int>());
        levels.insert(id.get<int>());
      }
  }
  return out;
}

/// The base colour of the first primitive's material of node `node`'s mesh (glTF's default
/// white without one).
std::array<float, 4> node_color(const nlohmann::json& structure, const nlohmann::json& node) {
  std::array<float, 4> color{1.0f, 1.0f, 1.0f, 1.0f};
  const nlohmann::json& mesh_index = member(node, "mesh");
  if (!mesh_index.is_number_integer()) return color;
  const nlohmann::json& meshes = member(structure, "meshes");
  const nlohmann::json& primitives = member(meshes.at(mesh_index.get<std::size_t>()), "primitives");
  if (!primitives.is_array() || primitives.empty()) return color;
  const nlohmann::json& material = member(primitives[0], "material");
  const nlohmann::json& materials = member(structure, "materials");
  if (!material.is_number_integer() || !materials.is_array() || material.get<std::int64_t>() < 0 ||
      material.get<std::size_t>() >= materials.size())
    return color;
  const nlohmann::json& factor =
      member(member(materials[material.get<std::size_t>()], "pbrMetallicRoughness"), "baseColorFactor");
  if (factor.is_array() && factor.size() == 4)
    for (std::size_t k = 0; k < 4; ++k)
      if (factor[k].is_number()) color[k] = factor[k].get<float>();
  return color;
}

/// Node extras as GltfSurface keeps them: without the writer's own "lod" and "triangles", an
/// iso value alone as iso_value.
void set_extras(const nlohmann::json& node, GltfSurface& s) {
  nlohmann::json extras = member(node, "extras");
  if (!extras.is_object()) return;
  extras.erase("lod");
  extras.erase("triangles");
  if (extras.size() == 1 && extras.contains("iso_value") && extras["iso_value"].is_number()) {
    s.iso_value = extras["iso_value"].get<double>();
    return;
  }
  if (!extras.empty()) s.node_extras = extras;
}

/// The merged triangle primitives of each node, and the largest Draco grid step among them.
struct NodeMeshes {
  std::map<int, std::vector<const TriangleMesh*>> parts;
  std::map<int, double> steps;
};

void add_gltf_surfaces(const GltfAsset& g, AssetFile& a) {
  NodeMeshes by_node;
  for (const GltfPrimitive& p : g.primitives) {
    by_node.parts[p.node].push_back(&p.mesh_data);
    by_node.steps[p.node] = std::max(by_node.steps[p.node], p.quantization_step);
  }
  const nlohmann::json& nodes = member(g.structure, "nodes");
  if (!nodes.is_array()) return;
  std::set<int> levels;
  const std::map<int, std::vector<int>> lods = lod_levels(nodes, levels);
  for (std::size_t i = 0; i < nodes.size(); ++i) {
    const nlohmann::json& node = nodes[i];
    const int id = int(i);
    const bool has_mesh = by_node.parts.count(id) > 0;
    // An empty surface is a mesh-less leaf carrying the writer's extras (lod 0, triangles 0).
    const nlohmann::json& extras = member(node, "extras");
    const bool empty_surface = !node.contains("mesh") && !node.contains("children") &&
                               member(extras, "lod") == 0 && member(extras, "triangles") == 0;
    if (levels.count(id) || !(has_mesh || empty_surface)) continue;
    GltfSurface s;
    s.node_name = member(node, "name").is_string() ? node["name"].get<std::string>() : "";
    const nlohmann::json& mesh_index = member(node, "mesh");
    const nlohmann::json& mesh_name =
        mesh_index.is_number_integer() ? member(g.structure["meshes"][mesh_index.get<std::size_t>()], "name")
                                       : nlohmann::json();
    s.name = mesh_name.is_string() ? mesh_name.get<std::string>() : s.node_name;
    s.color = node_color(g.structure, node);
    set_extras(node, s);
    if (has_mesh) s.mesh = merge_meshes(by_node.parts.at(id));
    const auto level_ids = lods.find(id);
    if (level_ids != lods.end())
      for (int level : level_ids->second)
        if (by_node.parts.count(level)) s.lods.push_back(merge_meshes(by_node.parts.at(level)));
    a.surfaces.push_back(std::move(s));
    a.quantization_steps.push_back(has_mesh ? by_node.steps.at(id) : 0.0);
  }
}

/// The frame record of asset.extras.mlfe (see write_gltf), checked.
void set_gltf_frame(const std::string& path, const GltfAsset& g, AssetFile& a) {
  a.gltf_frame = true;
  nlohmann::json extras = member(member(g.structure, "asset"), "extras");
  if (!extras.is_object()) return;
  const nlohmann::json mlfe = member(extras, "mlfe");
  extras.erase("mlfe");
  extras.erase("tolerance_mm");
  a.extras = extras;
  const nlohmann::json& space = member(mlfe, "input_space");
  if (space.is_string()) a.space = space.get<std::string>();
  try {
    a.physical_to_gltf = physical_to_gltf_matrix(a.space);
  } catch (const Error&) {
    a.space.clear();  // a space mlfe does not write: the matrix record decides
  }
  const nlohmann::json& matrix = member(mlfe, "physical_to_gltf");
  if (matrix.is_array()) {
    Eigen::Matrix3d m;
    if (matrix.size() != 9) throw Error(path + ": asset.extras.mlfe.physical_to_gltf is not 9 numbers");
    for (std::size_t k = 0; k < 9; ++k) {
      if (!matrix[k].is_number() || !std::isfinite(matrix[k].get<double>()))
        throw Error(path + ": asset.extras.mlfe.physical_to_gltf is not 9 finite numbers");
      a.physical_to_gltf[k] = matrix[k].get<double>();
      m(int(k / 3), int(k % 3)) = a.physical_to_gltf[k];
    }
    if (!(std::abs(m.determinant()) > 0))
      throw Error(path + ": asset.extras.mlfe.physical_to_gltf is not invertible");
  }
  const nlohmann::json& tolerance = member(member(g.encoding, "mlfe"), "tolerance_mm");
  if (tolerance.is_number() && tolerance.get<double>() > 0) a.tolerance_mm = tolerance.get<double>();
}

}  // namespace

AssetFile read_asset(const std::string& path) {
  AssetFile a;
  a.format = asset_format(path);
  if (a.format == "glb" || a.format == "gltf") {
    const GltfAsset g = read_gltf(path);
    set_gltf_frame(path, g, a);
    add_gltf_surfaces(g, a);
    return a;
  }
  DracoQuantization grid;
  GltfSurface s;
  s.mesh = a.format == "drc" ? read_draco_file(path, &grid) : read_mesh_file(path);
  a.surfaces.push_back(std::move(s));
  a.quantization_steps.push_back(grid.step());
  return a;
}

void to_scan_frame(AssetFile& asset) {
  if (!asset.gltf_frame) return;
  const Eigen::Matrix3d m =
      Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(asset.physical_to_gltf.data());
  std::array<double, 9> inverse;
  Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(inverse.data()) = m.inverse();
  for (GltfSurface& s : asset.surfaces) {
    transform_mesh(s.mesh, inverse);
    for (TriangleMesh& lod : s.lods) transform_mesh(lod, inverse);
  }
  // A grid step is a displacement: the inverse's largest stretch bounds it.
  const double stretch = Eigen::JacobiSVD<Eigen::Matrix3d>(m.inverse()).singularValues()(0);
  for (double& step : asset.quantization_steps) step *= stretch;
  asset.gltf_frame = false;
}

}  // namespace mlfe
