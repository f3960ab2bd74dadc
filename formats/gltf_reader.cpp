#include "formats/gltf_reader.h"

// Declarations only: Debian's libtinygltf-dev is a compiled library (see gltf_writer.cpp).
#include <fmt/format.h>
#include <tiny_gltf.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <sstream>

#include "core/error.h"
#include "formats/draco_io.h"

namespace mlfe {
namespace {

constexpr const char* kEncodingExtensions[] = {"KHR_draco_mesh_compression", "KHR_mesh_quantization",
                                               "EXT_meshopt_compression"};

[[noreturn]] void fail(const std::string& path, const std::string& problem) {
  throw Error(path + ": " + problem);
}

std::string read_all(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) fail(path, "cannot open file");
  std::stringstream ss;
  ss << in.rdbuf();
  if (in.bad()) fail(path, "read error");
  return ss.str();
}

bool is_glb(const std::string& bytes) {
  return bytes.size() >= 4 && std::memcmp(bytes.data(), "glTF", 4) == 0;
}

/// The JSON chunk of a GLB, or the whole file for .gltf.
nlohmann::json parse_json(const std::string& path, const std::string& bytes) {
  std::string text = bytes;
  if (is_glb(bytes)) {
    if (bytes.size() < 20) fail(path, "truncated GLB header");
    std::uint32_t chunk_length = 0, chunk_type = 0;
    std::memcpy(&chunk_length, bytes.data() + 12, 4);
    std::memcpy(&chunk_type, bytes.data() + 16, 4);
    if (chunk_type != 0x4E4F534Au || chunk_length > bytes.size() - 20) fail(path, "bad GLB JSON chunk");
    text = bytes.substr(20, chunk_length);
  }
  nlohmann::json j = nlohmann::json::parse(text, nullptr, false);
  if (j.is_discarded() || !j.is_object()) fail(path, "glTF JSON does not parse");
  return j;
}

bool is_encoding_extension(const std::string& name) {
  return std::find(std::begin(kEncodingExtensions), std::end(kEncodingExtensions), name) !=
         std::end(kEncodingExtensions);
}

/// Removes the data-encoding parts described in GltfAsset::structure.
nlohmann::json strip_encoding(nlohmann::json j) {
  for (const char* key : {"buffers", "bufferViews", "accessors"}) j.erase(key);
  for (const char* list : {"extensionsUsed", "extensionsRequired"}) {
    if (!j.contains(list) || !j[list].is_array()) continue;
    nlohmann::json kept = nlohmann::json::array();
    for (const auto& e : j[list])
      if (!e.is_string() || !is_encoding_extension(e.get<std::string>())) kept.push_back(e);
    std::sort(kept.begin(), kept.end());
    if (kept.empty())
      j.erase(list);
    else
      j[list] = kept;
  }
  if (j.contains("nodes") && j["nodes"].is_array())
    for (auto& n : j["nodes"])
      if (n.is_object())
        for (const char* key : {"matrix", "translation", "rotation", "scale"}) n.erase(key);
  if (j.contains("meshes") && j["meshes"].is_array())
    for (auto& m : j["meshes"])
      if (m.is_object() && m.contains("primitives") && m["primitives"].is_array())
        for (auto& p : m["primitives"]) {
          if (!p.is_object()) continue;
          // Attribute names stay (which data a primitive has); their accessor numbers go.
          if (p.contains("attributes") && p["attributes"].is_object()) {
            nlohmann::json names = nlohmann::json::array();
            for (auto it = p["attributes"].begin(); it != p["attributes"].end(); ++it)
              names.push_back(it.key());
            p["attributes"] = names;
          }
          p.erase("indices");
          if (p.contains("extensions") && p["extensions"].is_object()) {
            for (const char* e : kEncodingExtensions) p["extensions"].erase(e);
            if (p["extensions"].empty()) p.erase("extensions");
          }
        }
  if (j.contains("images") && j["images"].is_array())
    for (auto& im : j["images"])
      if (im.is_object()) {
        im.erase("bufferView");
        im.erase("uri");
      }
  return j;
}

Eigen::Matrix4d local_matrix(const tinygltf::Node& n) {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  if (n.matrix.size() == 16) {
    for (int c = 0; c < 4; ++c)
      for (int r = 0; r < 4; ++r) m(r, c) = n.matrix[c * 4 + r];  // glTF is column-major
    return m;
  }
  Eigen::Affine3d t = Eigen::Affine3d::Identity();
  if (n.translation.size() == 3)
    t.translate(Eigen::Vector3d(n.translation[0], n.translation[1], n.translation[2]));
  if (n.rotation.size() == 4)
    t.rotate(Eigen::Quaterniond(n.rotation[3], n.rotation[0], n.rotation[1], n.rotation[2]).normalized());
  if (n.scale.size() == 3) t.scale(Eigen::Vector3d(n.scale[0], n.scale[1], n.scale[2]));
  return t.matrix();
}

/// Element `i`, component `c` of an accessor as a double (normalized integers mapped as the
/// glTF specification says).
class AccessorView {
 public:
  AccessorView(const std::string& path, const tinygltf::Model& model, int index, const std::string& what) {
    if (index < 0 || index >= int(model.accessors.size())) fail(path, what + ": accessor index out of range");
    acc_ = &model.accessors[index];
    if (acc_->sparse.isSparse) fail(path, what + ": sparse accessors are not supported");
    if (acc_->bufferView < 0 || acc_->bufferView >= int(model.bufferViews.size()))
      fail(path, what + ": accessor has no buffer view");
    const auto& view = model.bufferViews[acc_->bufferView];
    if (view.buffer < 0 || view.buffer >= int(model.buffers.size())) fail(path, what + ": bad buffer index");
    const auto& buffer = model.buffers[view.buffer].data;
    components_ = tinygltf::GetNumComponentsInType(acc_->type);
    size_ = tinygltf::GetComponentSizeInBytes(acc_->componentType);
    if (components_ <= 0 || size_ <= 0) fail(path, what + ": bad accessor type");
    stride_ = view.byteStride > 0 ? view.byteStride : std::size_t(components_ * size_);
    const std::size_t begin = view.byteOffset + acc_->byteOffset;
    const std::size_t need = acc_->count == 0 ? 0 : (acc_->count - 1) * stride_ + components_ * size_;
    if (view.byteOffset + view.byteLength > buffer.size() || acc_->byteOffset + need > view.byteLength)
      fail(path, what + ": accessor reaches outside its buffer");
    data_ = buffer.data() + begin;
  }
  std::size_t count() const { return acc_->count; }
  int components() const { return components_; }
  double get(std::size_t i, int c) const {
    const unsigned char* p = data_ + i * stride_ + std::size_t(c) * size_;
    const bool norm = acc_->normalized;
    switch (acc_->componentType) {
      case TINYGLTF_COMPONENT_TYPE_FLOAT:
        return load<float>(p);
      case TINYGLTF_COMPONENT_TYPE_BYTE:
        return norm ? std::max(load<std::int8_t>(p) / 127.0, -1.0) : load<std::int8_t>(p);
      case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
        return norm ? load<std::uint8_t>(p) / 255.0 : load<std::uint8_t>(p);
      case TINYGLTF_COMPONENT_TYPE_SHORT:
        return norm ? std::max(load<std::int16_t>(p) / 32767.0, -1.0) : load<std::int16_t>(p);
      case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT:
        return norm ? load<std::uint16_t>(p) / 65535.0 : load<std::uint16_t>(p);
      case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT:
        return load<std::uint32_t>(p);
      default:
        return load<double>(p);
    }
  }
  bool integer_indices() const {
    return acc_->componentType == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE ||
           acc_->componentType == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT ||
           acc_->componentType == TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT;
  }

 private:
  template <class T>
  static T load(const unsigned char* p) {
    T v;
    std::memcpy(&v, p, sizeof v);
    return v;
  }
  const tinygltf::Accessor* acc_ = nullptr;
  const unsigned char* data_ = nullptr;
  int components_ = 0, size_ = 0;
  std::size_t stride_ = 0;
};

/// The primitive's geometry in the mesh's own frame.
TriangleMesh primitive_mesh(const std::string& path, const tinygltf::Model& model,
                            const tinygltf::Primitive& prim, const std::string& label) {
  const auto draco = prim.extensions.find("KHR_draco_mesh_compression");
  if (draco != prim.extensions.end()) {
    const tinygltf::Value& view_index = draco->second.Get("bufferView");
    if (!view_index.IsInt()) fail(path, label + ": KHR_draco_mesh_compression without bufferView");
    const int v = view_index.Get<int>();
    if (v < 0 || v >= int(model.bufferViews.size())) fail(path, label + ": Draco bufferView out of range");
    const auto& view = model.bufferViews[v];
    if (view.buffer < 0 || view.buffer >= int(model.buffers.size()) ||
        view.byteOffset + view.byteLength > model.buffers[view.buffer].data.size())
      fail(path, label + ": Draco bufferView outside its buffer");
    return decode_draco(
        reinterpret_cast<const char*>(model.buffers[view.buffer].data.data()) + view.byteOffset,
        view.byteLength, path + ": " + label);
  }
  TriangleMesh m;
  const auto pos = prim.attributes.find("POSITION");
  if (pos == prim.attributes.end()) fail(path, label + ": primitive without POSITION");
  const AccessorView positions(path, model, pos->second, label + " POSITION");
  if (positions.components() != 3) fail(path, label + ": POSITION is not VEC3");
  m.positions.resize(positions.count());
  for (std::size_t i = 0; i < positions.count(); ++i)
    for (int c = 0; c < 3; ++c) m.positions[i][c] = float(positions.get(i, c));
  const auto nrm = prim.attributes.find("NORMAL");
  if (nrm != prim.attributes.end()) {
    const AccessorView normals(path, model, nrm->second, label + " NORMAL");
    if (normals.components() != 3 || normals.count() != positions.count())
      fail(path, label + ": NORMAL does not match POSITION");
    m.normals.resize(normals.count());
    for (std::size_t i = 0; i < normals.count(); ++i)
      for (int c = 0; c < 3; ++c) m.normals[i][c] = float(normals.get(i, c));
  }
  std::vector<std::uint32_t> index;
  if (prim.indices >= 0) {
    const AccessorView indices(path, model, prim.indices, label + " indices");
    if (indices.components() != 1 || !indices.integer_indices()) fail(path, label + ": bad index accessor");
    index.resize(indices.count());
    for (std::size_t i = 0; i < indices.count(); ++i) index[i] = std::uint32_t(indices.get(i, 0));
  } else {
    index.resize(positions.count());
    for (std::size_t i = 0; i < index.size(); ++i) index[i] = std::uint32_t(i);
  }
  if (index.size() % 3 != 0) fail(path, label + ": index count is not a multiple of 3");
  m.triangles.resize(index.size() / 3);
  for (std::size_t t = 0; t < m.triangles.size(); ++t)
    for (int c = 0; c < 3; ++c) {
      if (index[3 * t + c] >= m.positions.size()) fail(path, label + ": vertex index out of range");
      m.triangles[t][c] = index[3 * t + c];
    }
  return m;
}

void transform_mesh(TriangleMesh& m, const Eigen::Matrix4d& world) {
  const Eigen::Matrix3d linear = world.topLeftCorner<3, 3>();
  const Eigen::Matrix3d normal_matrix = linear.inverse().transpose();
  for (auto& p : m.positions) {
    const Eigen::Vector3d q = linear * Eigen::Vector3d(p[0], p[1], p[2]) + world.topRightCorner<3, 1>();
    p = {float(q[0]), float(q[1]), float(q[2])};
  }
  for (auto& n : m.normals) {
    Eigen::Vector3d q = normal_matrix * Eigen::Vector3d(n[0], n[1], n[2]);
    if (q.norm() > 0) q.normalize();
    n = {float(q[0]), float(q[1]), float(q[2])};
  }
  // A mirroring node transform turns the front face around (glTF 2.0, 3.7.4 "Meshes"); flipping
  // the winding keeps "counter-clockwise from outside" true in world coordinates.
  if (linear.determinant() < 0)
    for (auto& t : m.triangles) std::swap(t[1], t[2]);
}

}  // namespace

GltfAsset read_gltf(const std::string& path) {
  const std::string bytes = read_all(path);
  GltfAsset asset;
  asset.structure = strip_encoding(parse_json(path, bytes));

  // Step 1: buffers and accessors through tinygltf; images are not decoded (only geometry and
  // the JSON matter here).
  tinygltf::Model model;
  tinygltf::TinyGLTF loader;
  loader.SetImageLoader([](tinygltf::Image*, const int, std::string*, std::string*, int, int,
                           const unsigned char*, int, void*) { return true; },
                        nullptr);
  std::string err, warn;
  const std::string dir = path.find('/') == std::string::npos ? "." : path.substr(0, path.rfind('/'));
  const bool ok = is_glb(bytes)
                      ? loader.LoadBinaryFromMemory(&model, &err, &warn,
                                                    reinterpret_cast<const unsigned char*>(bytes.data()),
                                                    static_cast<unsigned>(bytes.size()), dir)
                      : loader.LoadASCIIFromString(&model, &err, &warn, bytes.data(),
                                                   static_cast<unsigned>(bytes.size()), dir);
  if (!ok) {
    std::replace(err.begin(), err.end(), '\n', ' ');
    fail(path, "not a readable glTF file: " + err);
  }

  // Step 2: world matrices through the parent links (children may come before parents).
  const std::size_t nn = model.nodes.size();
  std::vector<int> parent(nn, -1);
  for (std::size_t i = 0; i < nn; ++i)
    for (int c : model.nodes[i].children) {
      if (c < 0 || std::size_t(c) >= nn || parent[c] != -1) fail(path, "node graph is not a forest");
      parent[c] = int(i);
    }
  std::vector<Eigen::Matrix4d> world(nn);
  for (std::size_t i = 0; i < nn; ++i) {
    Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
    std::size_t depth = 0;
    for (int n = int(i); n >= 0; n = parent[n]) {
      if (++depth > nn) fail(path, "node graph has a cycle");
      m = local_matrix(model.nodes[n]) * m;
    }
    world[i] = m;
  }

  // Step 3: every triangle primitive of every node with a mesh, in world coordinates.
  for (std::size_t i = 0; i < nn; ++i) {
    const int mi = model.nodes[i].mesh;
    if (mi < 0) continue;
    if (mi >= int(model.meshes.size())) fail(path, fmt::format("node {}: mesh index out of range", i));
    const auto& mesh = model.meshes[mi];
    for (std::size_t p = 0; p < mesh.primitives.size(); ++p) {
      if (mesh.primitives[p].mode != TINYGLTF_MODE_TRIANGLES && mesh.primitives[p].mode != -1) continue;
      GltfPrimitive prim;
      prim.node = int(i);
      prim.mesh = mi;
      prim.primitive = int(p);
      prim.label = fmt::format("node {} '{}' mesh '{}' primitive {}", i, model.nodes[i].name, mesh.name, p);
      prim.mesh_data = primitive_mesh(path, model, mesh.primitives[p], prim.label);
      transform_mesh(prim.mesh_data, world[i]);
      asset.primitives.push_back(std::move(prim));
    }
  }
  return asset;
}

}  // namespace mlfe
