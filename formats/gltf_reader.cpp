#include <mlfe/formats/gltf_reader.h>

// Not through tinygltf's loader: in this process its symbols resolve to the copy bundled in
// libdraco.so (a different version than the libtinygltf-dev headers), and that loader crashed
// on damaged .glb files (GltfReader.TruncatedAndCorruptedFilesThrowError). The JSON is parsed
// with nlohmann::json and every index and byte range is checked here instead.
#include <fmt/format.h>
#include <mlfe/core/base/error.h>
#include <mlfe/formats/draco_io.h>
#include <mlfe/formats/safe_read.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>

namespace mlfe {
namespace {

constexpr const char* kEncodingExtensions[] = {"KHR_draco_mesh_compression", "KHR_mesh_quantization",
                                               "EXT_meshopt_compression"};

[[noreturn]] void fail(const std::string& path, const std::string& problem) {
  throw Error(path + ": " + problem);
}

bool is_glb(const std::string& bytes) {
  return bytes.size() >= 4 && std::memcmp(bytes.data(), "glTF", 4) == 0;
}

/// The JSON chunk of a GLB, or the whole file for .gltf.
nlohmann::json parse_json(const std::string& path, const std::string& bytes) {
  std::string text = bytes;
  if (is_glb(bytes)) {
    if (bytes.size() < 20) fail(path, "truncated GLB header");
    // The header's total length must be the file's: a cut or padded file is not the asset written.
    std::uint32_t version = 0, total = 0;
    std::memcpy(&version, bytes.data() + 4, 4);
    std::memcpy(&total, bytes.data() + 8, 4);
    if (version != 2) fail(path, "GLB version " + std::to_string(version) + " (expected 2)");
    if (total != bytes.size())
      fail(path, "GLB header says " + std::to_string(total) + " bytes, the file has " +
                     std::to_string(bytes.size()));
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

/// A primitive without what only encodes its data: attribute names stay (which data a primitive
/// has), their accessor numbers, the indices and the compression extensions go.
nlohmann::json stripped_primitive(nlohmann::json p) {
  if (!p.is_object()) return p;
  if (p.contains("attributes") && p["attributes"].is_object()) {
    nlohmann::json names = nlohmann::json::array();
    for (auto it = p["attributes"].begin(); it != p["attributes"].end(); ++it) names.push_back(it.key());
    p["attributes"] = names;
  }
  p.erase("indices");
  if (p.contains("extensions") && p["extensions"].is_object()) {
    for (const char* e : kEncodingExtensions) p["extensions"].erase(e);
    if (p["extensions"].empty()) p.erase("extensions");
  }
  return p;
}

bool is_triangles(const nlohmann::json& p) {
  return p.is_object() && (!p.contains("mode") || p["mode"] == 4);
}

/// A mesh's primitives in groups, in order of their first primitive: triangle primitives that
/// are equal once stripped (the same attributes, material, extras and other extensions) are the
/// pieces of one surface, cut for an encoder's or an index type's sake (mlfe's Draco pieces,
/// exporters' 65535-vertex splits); every other primitive is a group of its own.
std::vector<std::vector<std::size_t>> surface_groups(const nlohmann::json& primitives) {
  std::vector<std::vector<std::size_t>> groups;
  std::vector<nlohmann::json> keys;
  for (std::size_t p = 0; p < primitives.size(); ++p) {
    const nlohmann::json key = stripped_primitive(primitives[p]);
    std::size_t g = is_triangles(key) ? 0 : groups.size();
    while (g < groups.size() && !(is_triangles(keys[g]) && keys[g] == key)) ++g;
    if (g == groups.size()) {
      groups.emplace_back();
      keys.push_back(key);
    }
    groups[g].push_back(p);
  }
  return groups;
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
  // The pieces of one surface (see surface_groups) are listed once.
  if (j.contains("meshes") && j["meshes"].is_array())
    for (auto& m : j["meshes"])
      if (m.is_object() && m.contains("primitives") && m["primitives"].is_array()) {
        nlohmann::json kept = nlohmann::json::array();
        for (const auto& group : surface_groups(m["primitives"]))
          kept.push_back(stripped_primitive(m["primitives"][group[0]]));
        m["primitives"] = kept;
      }
  if (j.contains("images") && j["images"].is_array())
    for (auto& im : j["images"])
      if (im.is_object()) {
        im.erase("bufferView");
        im.erase("uri");
      }
  // mlfe's own record of the encoding (draco, quantized or float, and its tolerance) says how the
  // geometry is stored, like the extensions above; the geometry comparison measures its effect.
  if (j.contains("asset") && j["asset"].is_object() && j["asset"].contains("extras") &&
      j["asset"]["extras"].is_object() && j["asset"]["extras"].contains("mlfe") &&
      j["asset"]["extras"]["mlfe"].is_object())
    for (const char* key : {"encoding", "tolerance_mm"}) j["asset"]["extras"]["mlfe"].erase(key);
  return j;
}

nlohmann::json encoding_of(const nlohmann::json& j) {
  nlohmann::json out = {{"extensions", nlohmann::json::array()}};
  if (j.contains("extensionsUsed") && j["extensionsUsed"].is_array())
    for (const auto& e : j["extensionsUsed"])
      if (e.is_string() && is_encoding_extension(e.get<std::string>())) out["extensions"].push_back(e);
  std::sort(out["extensions"].begin(), out["extensions"].end());
  const nlohmann::json::json_pointer record("/asset/extras/mlfe");
  if (j.contains(record) && j[record].is_object())
    for (const char* key : {"encoding", "tolerance_mm"})
      if (j[record].contains(key)) out["mlfe"][key] = j[record][key];
  return out;
}

Eigen::Matrix4d local_matrix(const nlohmann::json& n) {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  if (n.contains("matrix")) {
    const auto matrix = n.at("matrix").get<std::vector<double>>();
    if (matrix.size() != 16) throw Error("node matrix must have 16 numbers");
    for (int c = 0; c < 4; ++c)
      for (int r = 0; r < 4; ++r) m(r, c) = matrix[c * 4 + r];  // glTF is column-major
    return m;
  }
  auto vec = [&](const char* key, std::size_t n_expected) {
    std::vector<double> v = n.contains(key) ? n.at(key).get<std::vector<double>>() : std::vector<double>{};
    if (!v.empty() && v.size() != n_expected) throw Error(std::string("node ") + key + " has the wrong size");
    return v;
  };
  const auto t = vec("translation", 3), r = vec("rotation", 4), sc = vec("scale", 3);
  Eigen::Affine3d a = Eigen::Affine3d::Identity();
  if (!t.empty()) a.translate(Eigen::Vector3d(t[0], t[1], t[2]));
  if (!r.empty()) a.rotate(Eigen::Quaterniond(r[3], r[0], r[1], r[2]).normalized());
  if (!sc.empty()) a.scale(Eigen::Vector3d(sc[0], sc[1], sc[2]));
  return a.matrix();
}

std::string base64_decode(const std::string& in, const std::string& path) {
  auto value = [&](char c) -> int {
    if (c >= 'A' && c <= 'Z') return c - 'A';
    if (c >= 'a' && c <= 'z') return c - 'a' + 26;
    if (c >= '0' && c <= '9') return c - '0' + 52;
    if (c == '+' || c == '-') return 62;
    if (c == '/' || c == '_') return 63;
    return -1;
  };
  std::string out;
  out.reserve(in.size() / 4 * 3);
  unsigned bits = 0;
  int count = 0;
  for (char c : in) {
    if (c == '=') break;
    const int v = value(c);
    if (v < 0) fail(path, "bad base64 data in a buffer URI");
    bits = (bits << 6) | unsigned(v);
    if ((count += 6) >= 8) {
      count -= 8;
      out.push_back(char((bits >> count) & 0xff));
    }
  }
  return out;
}

/// The file a buffer URI (not a data: URI) names: only a file next to the asset is read.
std::string buffer_file(const std::string& path, const std::string& uri) {
  if (uri.find("..") != std::string::npos || uri.find(':') != std::string::npos || uri.empty() ||
      uri[0] == '/')
    fail(path, "buffer URI '" + uri + "' is not a file next to the asset");
  const std::string dir = path.find('/') == std::string::npos ? "." : path.substr(0, path.rfind('/'));
  return dir + "/" + uri;
}

/// The bytes of every buffer: the GLB's BIN chunk, a data: URI or a file next to `path`.
std::vector<std::string> load_buffers(const std::string& path, const std::string& bytes,
                                      const nlohmann::json& j) {
  std::vector<std::string> buffers;
  if (!j.contains("buffers")) return buffers;
  std::string bin;
  if (is_glb(bytes) && bytes.size() >= 20) {
    std::uint32_t json_length = 0;
    std::memcpy(&json_length, bytes.data() + 12, 4);
    const std::size_t at = 20 + std::size_t(json_length);
    if (at + 8 <= bytes.size()) {
      std::uint32_t length = 0, type = 0;
      std::memcpy(&length, bytes.data() + at, 4);
      std::memcpy(&type, bytes.data() + at + 4, 4);
      if (type != 0x004E4942u || length > bytes.size() - at - 8) fail(path, "bad GLB BIN chunk");
      bin = bytes.substr(at + 8, length);
    }
  }
  for (const auto& b : j.at("buffers")) {
    const auto length = b.at("byteLength").get<std::uint64_t>();
    const std::string which = fmt::format("buffer {}", buffers.size());
    std::string data;
    if (!b.contains("uri")) {
      if (!buffers.empty() || !is_glb(bytes))
        fail(path, "a buffer without uri that is not the GLB BIN chunk");
      // The BIN chunk is padded to 4 bytes (glTF 2.0, 4.4.3.3), so it may be up to 3 bytes longer.
      if (bin.size() < length || bin.size() - length > 3)
        fail(path, fmt::format("{} says {} bytes (byteLength), the GLB BIN chunk has {}", which, length,
                               bin.size()));
      data = bin;
    } else {
      const auto uri = b.at("uri").get<std::string>();
      if (uri.rfind("data:", 0) == 0) {
        const auto comma = uri.find(";base64,");
        if (comma == std::string::npos) fail(path, "buffer data URI is not base64");
        data = base64_decode(uri.substr(comma + 8), path);
      } else {
        // Weighed before it is read: a byteLength that is not the file's size is a damaged asset.
        RegularFile file(buffer_file(path, uri));
        if (file.size() != length)
          fail(path, fmt::format("{} says {} bytes (byteLength), its file {} has {}", which, length, uri,
                                 file.size()));
        data.resize(static_cast<std::size_t>(length));
        data.resize(file.read(data.data(), data.size()));
      }
      if (data.size() != length)
        fail(path, fmt::format("{} says {} bytes (byteLength), its data has {}", which, length, data.size()));
    }
    buffers.push_back(std::move(data));
  }
  return buffers;
}

/// The bytes of buffer view `v` as [begin, begin + length) of its buffer, bounds-checked.
struct ViewBytes {
  const unsigned char* data;
  std::size_t length, stride;
};
ViewBytes view_bytes(const std::string& path, const nlohmann::json& j,
                     const std::vector<std::string>& buffers, std::int64_t v, const std::string& what) {
  if (!j.contains("bufferViews") || v < 0 || v >= std::int64_t(j.at("bufferViews").size()))
    fail(path, what + ": bufferView index out of range");
  const auto& view = j.at("bufferViews").at(std::size_t(v));
  const auto b = view.at("buffer").get<std::int64_t>();
  if (b < 0 || b >= std::int64_t(buffers.size())) fail(path, what + ": buffer index out of range");
  const auto offset = view.value("byteOffset", std::uint64_t(0));
  const auto length = view.at("byteLength").get<std::uint64_t>();
  const std::string& buffer = buffers[std::size_t(b)];
  if (offset > buffer.size() || length > buffer.size() - offset)
    fail(path, what + ": bufferView outside its buffer");
  return {reinterpret_cast<const unsigned char*>(buffer.data()) + offset, std::size_t(length),
          std::size_t(view.value("byteStride", std::uint64_t(0)))};
}

/// Element `i`, component `c` of an accessor as a double (normalized integers mapped as the
/// glTF specification says).
class AccessorView {
 public:
  AccessorView(const std::string& path, const nlohmann::json& j, const std::vector<std::string>& buffers,
               std::int64_t index, const std::string& what) {
    if (!j.contains("accessors") || index < 0 || index >= std::int64_t(j.at("accessors").size()))
      fail(path, what + ": accessor index out of range");
    const auto& acc = j.at("accessors").at(std::size_t(index));
    if (acc.contains("sparse")) fail(path, what + ": sparse accessors are not supported");
    if (!acc.contains("bufferView")) fail(path, what + ": accessor has no bufferView");
    const ViewBytes view = view_bytes(path, j, buffers, acc.at("bufferView").get<std::int64_t>(), what);
    component_type_ = acc.at("componentType").get<int>();
    normalized_ = acc.value("normalized", false);
    const std::string type = acc.at("type").get<std::string>();
    components_ = type == "SCALAR" ? 1 : type == "VEC2" ? 2 : type == "VEC3" ? 3 : type == "VEC4" ? 4 : 0;
    switch (component_type_) {
      case 5120:
      case 5121:
        size_ = 1;
        break;
      case 5122:
      case 5123:
        size_ = 2;
        break;
      case 5125:
      case 5126:
        size_ = 4;
        break;
      default:
        size_ = 0;
    }
    if (components_ == 0 || size_ == 0) fail(path, what + ": unsupported accessor type");
    count_ = acc.at("count").get<std::uint64_t>();
    stride_ = view.stride > 0 ? view.stride : std::size_t(components_ * size_);
    const auto offset = acc.value("byteOffset", std::uint64_t(0));
    const std::size_t element = std::size_t(components_ * size_);
    if (count_ > 0 && (offset > view.length || (count_ - 1) > (view.length - offset) / stride_ ||
                       (count_ - 1) * stride_ + element > view.length - offset))
      fail(path, what + ": accessor reaches outside its bufferView");
    data_ = view.data + offset;
  }
  std::size_t count() const { return count_; }
  int components() const { return components_; }
  bool integer_indices() const {
    return component_type_ == 5121 || component_type_ == 5123 || component_type_ == 5125;
  }
  double get(std::size_t i, int c) const {
    const unsigned char* p = data_ + i * stride_ + std::size_t(c) * std::size_t(size_);
    switch (component_type_) {
      case 5126:
        return load<float>(p);
      case 5120:
        return normalized_ ? std::max(load<std::int8_t>(p) / 127.0, -1.0) : load<std::int8_t>(p);
      case 5121:
        return normalized_ ? load<std::uint8_t>(p) / 255.0 : load<std::uint8_t>(p);
      case 5122:
        return normalized_ ? std::max(load<std::int16_t>(p) / 32767.0, -1.0) : load<std::int16_t>(p);
      case 5123:
        return normalized_ ? load<std::uint16_t>(p) / 65535.0 : load<std::uint16_t>(p);
      default:
        return load<std::uint32_t>(p);
    }
  }

 private:
  template <class T>
  static T load(const unsigned char* p) {
    T v;
    std::memcpy(&v, p, sizeof v);
    return v;
  }
  const unsigned char* data_ = nullptr;
  int component_type_ = 0, components_ = 0, size_ = 0;
  bool normalized_ = false;
  std::size_t count_ = 0, stride_ = 0;
};

/// The primitive's geometry in the mesh's own frame; `draco` receives the grid of Draco's
/// positions (bits 0 for other encodings).
TriangleMesh primitive_mesh(const std::string& path, const nlohmann::json& j,
                            const std::vector<std::string>& buffers, const nlohmann::json& prim,
                            const std::string& label, DracoQuantization& draco) {
  draco = {};
  if (prim.contains("extensions") && prim.at("extensions").contains("KHR_draco_mesh_compression")) {
    const auto& ext = prim.at("extensions").at("KHR_draco_mesh_compression");
    const ViewBytes view = view_bytes(path, j, buffers, ext.at("bufferView").get<std::int64_t>(), label);
    return decode_draco(reinterpret_cast<const char*>(view.data), view.length, path + ": " + label, &draco);
  }
  TriangleMesh m;
  const auto& attributes = prim.at("attributes");
  if (!attributes.contains("POSITION")) fail(path, label + ": primitive without POSITION");
  const AccessorView positions(path, j, buffers, attributes.at("POSITION").get<std::int64_t>(),
                               label + " POSITION");
  if (positions.components() != 3) fail(path, label + ": POSITION is not VEC3");
  m.positions.resize(positions.count());
  for (std::size_t i = 0; i < positions.count(); ++i)
    for (int c = 0; c < 3; ++c) m.positions[i][c] = float(positions.get(i, c));
  if (attributes.contains("NORMAL")) {
    const AccessorView normals(path, j, buffers, attributes.at("NORMAL").get<std::int64_t>(),
                               label + " NORMAL");
    if (normals.components() != 3 || normals.count() != positions.count())
      fail(path, label + ": NORMAL does not match POSITION");
    m.normals.resize(normals.count());
    for (std::size_t i = 0; i < normals.count(); ++i)
      for (int c = 0; c < 3; ++c) m.normals[i][c] = float(normals.get(i, c));
  }
  std::vector<std::uint32_t> index;
  if (prim.contains("indices")) {
    const AccessorView indices(path, j, buffers, prim.at("indices").get<std::int64_t>(), label + " indices");
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

/// The surface of one group of primitives (see surface_groups) in the mesh's own frame: one
/// primitive as it is, pieces merged and welded along their borders (their shared vertices
/// decode to one position on a shared Draco grid). `step` receives the largest Draco grid step.
TriangleMesh surface_mesh(const std::string& path, const nlohmann::json& j,
                          const std::vector<std::string>& buffers, const nlohmann::json& primitives,
                          const std::vector<std::size_t>& group, const std::string& label, double& step) {
  std::vector<TriangleMesh> pieces;
  step = 0;
  for (std::size_t p : group) {
    DracoQuantization draco;
    const std::string what = group.size() > 1 ? fmt::format("{} piece {}", label, p) : label;
    pieces.push_back(primitive_mesh(path, j, buffers, primitives.at(p), what, draco));
    step = std::max(step, draco.step());
  }
  if (pieces.size() == 1) return std::move(pieces[0]);
  std::vector<const TriangleMesh*> parts;
  std::vector<std::size_t> piece_triangles;
  for (const auto& piece : pieces) {
    parts.push_back(&piece);
    piece_triangles.push_back(piece.triangles.size());
  }
  TriangleMesh joined = merge_meshes(parts);
  pieces.clear();
  weld_piece_borders(joined, piece_triangles);
  return joined;
}

}  // namespace

void transform_mesh(TriangleMesh& m, const std::array<double, 9>& linear_rows,
                    const std::array<double, 3>& translation) {
  const Eigen::Matrix3d linear =
      Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(linear_rows.data());
  const Eigen::Matrix3d normal_matrix = linear.inverse().transpose();
  const Eigen::Vector3d shift(translation[0], translation[1], translation[2]);
  for (auto& p : m.positions) {
    const Eigen::Vector3d q = linear * Eigen::Vector3d(p[0], p[1], p[2]) + shift;
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

std::vector<std::string> gltf_buffer_files(const std::string& path) {
  const nlohmann::json j = parse_json(path, read_regular_file(path, UINT64_MAX, "the file"));
  std::vector<std::string> files;
  if (!j.contains("buffers") || !j.at("buffers").is_array()) return files;
  for (const auto& b : j.at("buffers"))
    if (b.is_object() && b.contains("uri") && b.at("uri").is_string()) {
      const auto uri = b.at("uri").get<std::string>();
      if (uri.rfind("data:", 0) != 0) files.push_back(buffer_file(path, uri));
    }
  return files;
}

GltfAsset read_gltf(const std::string& path) {
  const std::string bytes = read_regular_file(path, UINT64_MAX, "the file");
  GltfAsset asset;
  try {
    const nlohmann::json j = parse_json(path, bytes);
    asset.structure = strip_encoding(j);
    asset.encoding = encoding_of(j);
    // Step 1: buffers (BIN chunk, data: URIs, files next to the asset). The JSON is read here
    // directly: every index and range is checked, so a damaged file cannot make us read
    // outside its buffers.
    const std::vector<std::string> buffers = load_buffers(path, bytes, j);

    // Step 2: world matrices through the parent links (children may come before parents).
    const nlohmann::json no_nodes = nlohmann::json::array();
    const nlohmann::json& nodes = j.contains("nodes") ? j.at("nodes") : no_nodes;
    const std::size_t nn = nodes.size();
    std::vector<std::int64_t> parent(nn, -1);
    for (std::size_t i = 0; i < nn; ++i)
      if (nodes.at(i).contains("children"))
        for (const auto& child : nodes.at(i).at("children")) {
          const auto c = child.get<std::int64_t>();
          if (c < 0 || std::size_t(c) >= nn || parent[std::size_t(c)] != -1)
            fail(path, "node graph is not a forest");
          parent[std::size_t(c)] = std::int64_t(i);
        }
    // An MSFT_lod level stands in for the node that lists it, under that node's parent (the
    // quantized encoding's dequantizing root, for one).
    for (std::size_t i = 0; i < nn; ++i) {
      const nlohmann::json& node = nodes.at(i);
      if (!node.contains("extensions") || !node.at("extensions").contains("MSFT_lod")) continue;
      for (const auto& id : node.at("extensions").at("MSFT_lod").value("ids", nlohmann::json::array())) {
        const auto level = id.get<std::int64_t>();
        if (level < 0 || std::size_t(level) >= nn || std::size_t(level) == i)
          fail(path, fmt::format("node {}: MSFT_lod id out of range", i));
        if (parent[std::size_t(level)] == -1) parent[std::size_t(level)] = parent[i];
      }
    }
    std::vector<Eigen::Matrix4d> world(nn);
    for (std::size_t i = 0; i < nn; ++i) {
      Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
      std::size_t depth = 0;
      for (std::int64_t n = std::int64_t(i); n >= 0; n = parent[std::size_t(n)]) {
        if (++depth > nn) fail(path, "node graph has a cycle");
        m = local_matrix(nodes.at(std::size_t(n))) * m;
      }
      world[i] = m;
    }

    // Step 3: every triangle primitive of every node with a mesh, in world coordinates.
    for (std::size_t i = 0; i < nn; ++i) {
      const auto& node = nodes.at(i);
      if (!node.contains("mesh")) continue;
      const auto mi = node.at("mesh").get<std::int64_t>();
      if (!j.contains("meshes") || mi < 0 || mi >= std::int64_t(j.at("meshes").size()))
        fail(path, fmt::format("node {}: mesh index out of range", i));
      const auto& mesh = j.at("meshes").at(std::size_t(mi));
      const auto& primitives = mesh.at("primitives");
      for (const auto& group : surface_groups(primitives)) {
        const std::size_t p = group[0];
        if (primitives.at(p).value("mode", 4) != 4) continue;  // points and lines have no surface
        GltfPrimitive prim;
        prim.node = int(i);
        prim.mesh = int(mi);
        prim.primitive = int(p);
        prim.label = fmt::format("node {} '{}' mesh '{}' primitive {}", i, node.value("name", std::string()),
                                 mesh.value("name", std::string()), p);
        if (group.size() > 1) prim.label += fmt::format(" (+{} joined)", group.size() - 1);
        prim.mesh_data =
            surface_mesh(path, j, buffers, primitives, group, prim.label, prim.quantization_step);
        std::array<double, 9> rows;
        for (int k = 0; k < 9; ++k) rows[std::size_t(k)] = world[i](k / 3, k % 3);
        transform_mesh(prim.mesh_data, rows, {world[i](0, 3), world[i](1, 3), world[i](2, 3)});
        // A grid step is a displacement: the largest stretch of the node's linear part bounds it.
        const Eigen::Matrix3d linear = world[i].topLeftCorner<3, 3>();
        prim.quantization_step *= Eigen::JacobiSVD<Eigen::Matrix3d>(linear).singularValues()(0);
        asset.primitives.push_back(std::move(prim));
      }
    }
  } catch (const nlohmann::json::exception& e) {
    fail(path, std::string("bad glTF JSON: ") + e.what());
  } catch (const Error& e) {
    // Errors from helpers that do not know the path get it here.
    const std::string what = e.what();
    if (what.rfind(path + ": ", 0) == 0) throw;
    fail(path, what);
  }
  return asset;
}

}  // namespace mlfe
