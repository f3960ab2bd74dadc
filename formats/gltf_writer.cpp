#include <mlfe/formats/gltf_writer.h>

// Debian's libtinygltf-dev ships tinygltf as a compiled shared library (libtinygltf.so, linked
// through TinyGLTF::TinyGLTF), so this file only includes the declarations. Defining
// TINYGLTF_IMPLEMENTATION here as well would put a second, differently configured copy of every
// tinygltf symbol into the process (an ODR violation resolved by symbol interposition).
#include <fmt/format.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/base/vec.h>
#include <mlfe/formats/atomic_file.h>
#include <mlfe/formats/draco_io.h>
#include <mlfe/formats/file_names.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>
#include <tiny_gltf.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <utility>

namespace mlfe {
namespace {

enum class Encoding { kFloat, kDraco, kQuantized };

tinygltf::Value to_value(const nlohmann::json& j) {
  switch (j.type()) {
    case nlohmann::json::value_t::object: {
      tinygltf::Value::Object o;
      for (auto it = j.begin(); it != j.end(); ++it) o[it.key()] = to_value(it.value());
      return tinygltf::Value(std::move(o));
    }
    case nlohmann::json::value_t::array: {
      tinygltf::Value::Array a;
      for (const auto& e : j) a.push_back(to_value(e));
      return tinygltf::Value(std::move(a));
    }
    case nlohmann::json::value_t::string:
      return tinygltf::Value(j.get<std::string>());
    case nlohmann::json::value_t::boolean:
      return tinygltf::Value(j.get<bool>());
    case nlohmann::json::value_t::number_integer:
    case nlohmann::json::value_t::number_unsigned: {
      // tinygltf integers are 32-bit; larger ones keep their value as a double.
      const double d = j.get<double>();
      if (d >= std::numeric_limits<int>::min() && d <= std::numeric_limits<int>::max())
        return tinygltf::Value(j.get<int>());
      return tinygltf::Value(d);
    }
    case nlohmann::json::value_t::number_float:
      return tinygltf::Value(j.get<double>());
    default:
      return tinygltf::Value();
  }
}

// A surface level: its names and the mesh it is converted from (converted when it is written,
// so that only one level is held in glTF's frame at a time).
struct Level {
  std::string node_name;
  std::string mesh_name;
  int lod = 0;
  const TriangleMesh* source = nullptr;
  /// `source` when the caller gave the surfaces up: released once converted for writing.
  TriangleMesh* owned = nullptr;
};

// p (physical millimetres) in glTF's metres through the row-major matrix m.
std::array<float, 3> to_gltf(const std::array<float, 3>& p, const std::array<double, 9>& m) {
  std::array<float, 3> q;
  for (int r = 0; r < 3; ++r) q[r] = float(m[3 * r] * p[0] + m[3 * r + 1] * p[1] + m[3 * r + 2] * p[2]);
  return q;
}

// What convert refuses: normals that are not one per position, too many vertices, triangle
// indices out of range (non-finite positions are found as they are converted).
void check_level(const TriangleMesh& in, const std::string& path) {
  const std::size_t n = in.positions.size();
  if (!in.normals.empty() && in.normals.size() != n)
    throw Error(path + ": mesh has " + std::to_string(in.normals.size()) + " normals for " +
                std::to_string(n) + " positions");
  if (n > std::numeric_limits<std::uint32_t>::max()) throw Error(path + ": mesh too large");
}

void check_triangle(const std::array<std::uint32_t, 3>& t, std::size_t n, const std::string& path) {
  if (t[0] >= n || t[1] >= n || t[2] >= n) throw Error(path + ": triangle index out of range");
}

// `mesh` (consumed, converted in place so that a big surface is not held twice) in glTF metres
// with cleaned triangles and unit normals.
TriangleMesh convert(TriangleMesh mesh, const std::array<double, 9>& m, const std::string& path) {
  check_level(mesh, path);
  const std::size_t n = mesh.positions.size();
  for (auto& p : mesh.positions) {
    p = to_gltf(p, m);
    for (float c : p)
      if (!std::isfinite(c)) throw Error(path + ": non-finite vertex position");
  }
  // Degenerate triangles are invisible, and Draco drops them anyway; dropping them everywhere
  // keeps the three encodings describing the same triangles.
  std::size_t kept = 0;
  for (const auto& t : mesh.triangles) {
    check_triangle(t, n, path);
    const auto &a = mesh.positions[t[0]], &b = mesh.positions[t[1]], &c = mesh.positions[t[2]];
    if (a == b || b == c || a == c) continue;
    mesh.triangles[kept++] = t;
  }
  mesh.triangles.resize(kept);

  // The rotation part (1000*m) maps normals; it is orthonormal, so no inverse transpose needed.
  // Missing or zero normals fall back to the area-weighted normals of the converted triangles
  // (marked NaN until then).
  std::vector<std::array<float, 3>> rotated = std::move(mesh.normals);
  mesh.normals.clear();
  bool all_rotated = rotated.size() == n;
  for (auto& q : rotated) {
    std::array<double, 3> v;
    for (int r = 0; r < 3; ++r) v[r] = 1000.0 * (m[3 * r] * q[0] + m[3 * r + 1] * q[1] + m[3 * r + 2] * q[2]);
    const double len = norm(v);
    if (len > 1e-12 && std::isfinite(len)) {
      for (int k = 0; k < 3; ++k) q[k] = float(v[k] / len);
    } else {
      q[0] = std::numeric_limits<float>::quiet_NaN();
      all_rotated = false;
    }
  }
  if (all_rotated) {
    mesh.normals = std::move(rotated);
    return mesh;
  }
  compute_area_weighted_normals(mesh);
  for (std::size_t i = 0; i < rotated.size(); ++i)
    if (!std::isnan(rotated[i][0])) mesh.normals[i] = rotated[i];
  return mesh;
}

// Appends bytes to buffer 0 at a 4-byte aligned offset and returns a new bufferView index.
int add_buffer_view(tinygltf::Model& model, const void* data, std::size_t size, int target, int stride = 0) {
  auto& buf = model.buffers[0].data;
  buf.resize((buf.size() + 3) & ~std::size_t(3), 0);
  tinygltf::BufferView view;
  view.buffer = 0;
  view.byteOffset = buf.size();
  view.byteLength = size;
  view.target = target;
  view.byteStride = std::size_t(stride);
  const auto* bytes = static_cast<const unsigned char*>(data);
  buf.insert(buf.end(), bytes, bytes + size);
  model.bufferViews.push_back(view);
  return int(model.bufferViews.size() - 1);
}

int add_accessor(tinygltf::Model& model, int view, int component, int type, std::size_t count,
                 bool normalized, std::vector<double> min = {}, std::vector<double> max = {}) {
  tinygltf::Accessor a;
  a.bufferView = view;
  a.byteOffset = 0;
  a.componentType = component;
  a.type = type;
  a.count = count;
  a.normalized = normalized;
  a.minValues = std::move(min);
  a.maxValues = std::move(max);
  model.accessors.push_back(a);
  return int(model.accessors.size() - 1);
}

void bounds(const std::vector<std::array<float, 3>>& ps, std::vector<double>& lo, std::vector<double>& hi) {
  lo.assign(3, std::numeric_limits<double>::infinity());
  hi.assign(3, -std::numeric_limits<double>::infinity());
  for (const auto& p : ps)
    for (int k = 0; k < 3; ++k) {
      lo[k] = std::min(lo[k], double(p[k]));
      hi[k] = std::max(hi[k], double(p[k]));
    }
}

int index_component_for(std::size_t vertex_count) {
  // 65535 is the primitive-restart value for 16-bit indices, so it must not occur as an index.
  return vertex_count <= 65535 ? TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT
                               : TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT;
}

// The indices of an uncompressed primitive, in a view of their own.
int add_indices(tinygltf::Model& model, const TriangleMesh& mesh) {
  const int component = index_component_for(mesh.positions.size());
  const std::size_t count = mesh.triangles.size() * 3;
  int view = -1;
  if (component == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT) {
    std::vector<std::uint16_t> idx;
    idx.reserve(count);
    for (const auto& t : mesh.triangles)
      for (auto v : t) idx.push_back(std::uint16_t(v));
    view = add_buffer_view(model, idx.data(), idx.size() * 2, TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER);
  } else {
    view = add_buffer_view(model, mesh.triangles.data(), count * 4, TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER);
  }
  return add_accessor(model, view, component, TINYGLTF_TYPE_SCALAR, count, false);
}

// A verified Draco encoding reduced to what its glTF primitive needs.
struct DracoPiece {
  std::vector<char> bytes;
  int position_id = -1, normal_id = -1;  // Draco attribute unique ids
  std::size_t vertices = 0, triangles = 0;
  std::vector<double> lo, hi;  // decoded positions' bounds
};

constexpr std::uint32_t kNoVertex = std::numeric_limits<std::uint32_t>::max();

// A level's pieces: balanced runs of its triangles in triangle_spatial_order.
struct PieceCutter {
  const TriangleMesh& mesh;
  std::size_t count;
  std::vector<std::uint32_t> order;

  PieceCutter(const TriangleMesh& m, std::size_t pieces)
      : mesh(m), count(pieces), order(triangle_spatial_order(m)) {}

  // Piece k of `count` with its own vertices (in order of first use); `local` maps the mesh's
  // vertices to the piece's, all kNoVertex before and after.
  TriangleMesh piece(std::size_t k, std::vector<std::uint32_t>& local) const {
    const std::size_t total = order.size(), begin = total * k / count, end = total * (k + 1) / count;
    TriangleMesh piece;
    std::vector<std::uint32_t> global;  // piece vertex -> mesh vertex
    piece.triangles.reserve(end - begin);
    for (std::size_t i = begin; i < end; ++i) {
      std::array<std::uint32_t, 3> t = mesh.triangles[order[i]];
      for (auto& v : t) {
        if (local[v] == kNoVertex) {
          local[v] = std::uint32_t(global.size());
          global.push_back(v);
        }
        v = local[v];
      }
      piece.triangles.push_back(t);
    }
    piece.positions.resize(global.size());
    piece.normals.resize(global.size());
    for (std::size_t v = 0; v < global.size(); ++v) {
      piece.positions[v] = mesh.positions[global[v]];
      piece.normals[v] = mesh.normals[global[v]];
      local[global[v]] = kNoVertex;
    }
    return piece;
  }
};

// Scene-wide quantization box in glTF metres (cube; see DracoOptions).
struct SceneBox {
  std::array<float, 3> min{0, 0, 0};
  float range = 0;
};

struct Writer {
  const std::string& path;
  const GltfOptions& options;
  Encoding encoding;
  SceneBox box;
  tinygltf::Model model;

  // `piece` (in glTF's frame, consumed) Draco-compressed on the scene's grid and verified,
  // reduced to what its primitive needs. `what` names it in errors. Touches nothing shared, so
  // pieces may be encoded on several threads.
  DracoPiece encode_piece(const std::string& what, TriangleMesh&& piece) const {
    DracoOptions d;
    d.tolerance = options.tolerance_mm * 1e-3;
    d.box_min = box.min;
    d.box_range = box.range;
    DracoPiece out;
    try {
      DracoEncoding enc = encode_draco_verified(std::move(piece), d);
      out.bytes = std::move(enc.bytes);
      out.position_id = enc.position_unique_id;
      out.normal_id = enc.normal_unique_id;
      out.vertices = enc.decoded.positions.size();
      out.triangles = enc.decoded.triangles.size();
      bounds(enc.decoded.positions, out.lo, out.hi);
    } catch (const Error& e) {
      throw Error(path + ": " + what + ": " + e.what());
    }
    return out;
  }

  // The primitive of an encoded piece, its accessors describing the decoded data.
  tinygltf::Primitive draco_primitive(const DracoPiece& piece, int material) {
    tinygltf::Primitive prim;
    prim.material = material;
    prim.mode = TINYGLTF_MODE_TRIANGLES;
    const int view = add_buffer_view(model, piece.bytes.data(), piece.bytes.size(), 0);
    prim.attributes["POSITION"] = add_accessor(model, -1, TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3,
                                               piece.vertices, false, piece.lo, piece.hi);
    prim.attributes["NORMAL"] =
        add_accessor(model, -1, TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3, piece.vertices, false);
    prim.indices = add_accessor(model, -1, index_component_for(piece.vertices), TINYGLTF_TYPE_SCALAR,
                                piece.triangles * 3, false);
    tinygltf::Value::Object attributes;
    attributes["POSITION"] = tinygltf::Value(piece.position_id);
    attributes["NORMAL"] = tinygltf::Value(piece.normal_id);
    tinygltf::Value::Object ext;
    ext["bufferView"] = tinygltf::Value(view);
    ext["attributes"] = tinygltf::Value(std::move(attributes));
    prim.extensions["KHR_draco_mesh_compression"] = tinygltf::Value(std::move(ext));
    return prim;
  }

  // `mesh` (consumed) as Draco primitives of `out`: one, or pieces of at most
  // draco_piece_triangles (see GltfOptions). Pieces are cut and encoded in batches of one per
  // thread, so that at most that many pieces' encoders are alive; the bytes are added in order.
  void add_draco_primitives(tinygltf::Mesh& out, TriangleMesh&& mesh, int material) {
    const std::size_t total = mesh.triangles.size(), limit = options.draco_piece_triangles;
    if (total <= limit) {
      out.primitives.push_back(draco_primitive(encode_piece(out.name, std::move(mesh)), material));
      return;
    }
    const PieceCutter cutter(mesh, (total + limit - 1) / limit);
    // The threads TBB may run (the CLI's --threads sets this limit).
    const std::size_t batch = std::max<std::size_t>(
        1,
        std::min<std::size_t>(tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism),
                              std::size_t(tbb::this_task_arena::max_concurrency())));
    std::vector<std::uint32_t> local(mesh.positions.size(), kNoVertex);
    for (std::size_t first = 0; first < cutter.count; first += batch) {
      std::vector<TriangleMesh> pieces;
      for (std::size_t k = first; k < std::min(first + batch, cutter.count); ++k)
        pieces.push_back(cutter.piece(k, local));
      std::vector<DracoPiece> encoded(pieces.size());
      tbb::parallel_for(std::size_t(0), pieces.size(), [&](std::size_t i) {
        encoded[i] = encode_piece(fmt::format("{} piece {} of {}", out.name, first + i + 1, cutter.count),
                                  std::move(pieces[i]));
      });
      for (const DracoPiece& piece : encoded) out.primitives.push_back(draco_primitive(piece, material));
    }
  }

  // `mesh`: `level` in glTF's frame (consumed by the Draco encoder).
  int add_mesh(const Level& level, TriangleMesh&& mesh, int material) {
    tinygltf::Mesh m;
    m.name = level.mesh_name;
    if (encoding == Encoding::kDraco) {
      add_draco_primitives(m, std::move(mesh), material);
      model.meshes.push_back(m);
      return int(model.meshes.size() - 1);
    }
    tinygltf::Primitive prim;
    prim.material = material;
    prim.mode = TINYGLTF_MODE_TRIANGLES;
    if (encoding == Encoding::kQuantized) {
      // Normalized SHORT positions relative to the scene box; the root node's translation and
      // uniform scale map them back to metres (uniform, so normals need no correction).
      const double half = 0.5 * double(box.range);
      std::vector<std::int16_t> pos(4 * mesh.positions.size(), 0), nrm(4 * mesh.positions.size(), 0);
      std::vector<double> lo(3, 32767), hi(3, -32767);
      for (std::size_t i = 0; i < mesh.positions.size(); ++i)
        for (int k = 0; k < 3; ++k) {
          const double center = double(box.min[k]) + half;
          const double q = std::clamp(std::round((double(mesh.positions[i][k]) - center) / half * 32767.0),
                                      -32767.0, 32767.0);
          pos[4 * i + k] = std::int16_t(q);
          lo[k] = std::min(lo[k], q);
          hi[k] = std::max(hi[k], q);
          nrm[4 * i + k] =
              std::int16_t(std::round(std::clamp(double(mesh.normals[i][k]), -1.0, 1.0) * 32767.0));
        }
      // Vertex attribute strides must be multiples of 4: pad each SHORT VEC3 to 8 bytes.
      const int pos_view =
          add_buffer_view(model, pos.data(), pos.size() * 2, TINYGLTF_TARGET_ARRAY_BUFFER, 8);
      const int nrm_view =
          add_buffer_view(model, nrm.data(), nrm.size() * 2, TINYGLTF_TARGET_ARRAY_BUFFER, 8);
      prim.attributes["POSITION"] = add_accessor(model, pos_view, TINYGLTF_COMPONENT_TYPE_SHORT,
                                                 TINYGLTF_TYPE_VEC3, mesh.positions.size(), true, lo, hi);
      prim.attributes["NORMAL"] = add_accessor(model, nrm_view, TINYGLTF_COMPONENT_TYPE_SHORT,
                                               TINYGLTF_TYPE_VEC3, mesh.positions.size(), true);
      prim.indices = add_indices(model, mesh);
    } else {
      std::vector<double> lo, hi;
      bounds(mesh.positions, lo, hi);
      const int pos_view = add_buffer_view(model, mesh.positions.data(), mesh.positions.size() * 12,
                                           TINYGLTF_TARGET_ARRAY_BUFFER);
      const int nrm_view =
          add_buffer_view(model, mesh.normals.data(), mesh.normals.size() * 12, TINYGLTF_TARGET_ARRAY_BUFFER);
      prim.attributes["POSITION"] = add_accessor(model, pos_view, TINYGLTF_COMPONENT_TYPE_FLOAT,
                                                 TINYGLTF_TYPE_VEC3, mesh.positions.size(), false, lo, hi);
      prim.attributes["NORMAL"] = add_accessor(model, nrm_view, TINYGLTF_COMPONENT_TYPE_FLOAT,
                                               TINYGLTF_TYPE_VEC3, mesh.normals.size(), false);
      prim.indices = add_indices(model, mesh);
    }
    m.primitives.push_back(prim);
    model.meshes.push_back(m);
    return int(model.meshes.size() - 1);
  }
};

void add_extension(tinygltf::Model& model, const std::string& name, bool required) {
  model.extensionsUsed.push_back(name);
  if (required) model.extensionsRequired.push_back(name);
}

// Every surface and its coarser levels, named; `owned`: the same surfaces when the caller gave
// them up (Level::owned).
std::vector<std::vector<Level>> name_levels(const std::vector<GltfSurface>& surfaces,
                                            std::vector<GltfSurface>* owned) {
  std::vector<std::vector<Level>> levels(surfaces.size());
  for (std::size_t s = 0; s < surfaces.size(); ++s) {
    const GltfSurface& surface = surfaces[s];
    const std::string node_name =
        surface.node_name.empty() ? fmt::format("iso {}", surface.iso_value) : surface.node_name;
    const std::string mesh_name = surface.name.empty() ? node_name : surface.name;
    levels[s].push_back({node_name, mesh_name, 0, &surface.mesh, owned ? &(*owned)[s].mesh : nullptr});
    for (std::size_t k = 0; k < surface.lods.size(); ++k)
      levels[s].push_back({fmt::format("{} lod {}", node_name, k + 1),
                           fmt::format("{} lod {}", mesh_name, k + 1), int(k + 1), &surface.lods[k],
                           owned ? &(*owned)[s].lods[k] : nullptr});
  }
  return levels;
}

// The box of every vertex of every level in glTF's frame, which quantized positions share. Each
// level is checked and its positions converted on the fly (as convert would, without a copy of
// the level), which also checks every level before anything else.
void fit_shared_box(Writer& w, const std::vector<std::vector<Level>>& levels,
                    const std::array<double, 9>& m) {
  std::array<float, 3> lo{0, 0, 0}, hi{0, 0, 0};
  bool any = false;
  for (const auto& ls : levels)
    for (const auto& l : ls) {
      const TriangleMesh& mesh = *l.source;
      check_level(mesh, w.path);
      for (const auto& p : mesh.positions)
        for (float c : to_gltf(p, m))
          if (!std::isfinite(c)) throw Error(w.path + ": non-finite vertex position");
      for (const auto& t : mesh.triangles) {
        check_triangle(t, mesh.positions.size(), w.path);
        const std::array<std::array<float, 3>, 3> corners = {to_gltf(mesh.positions[t[0]], m),
                                                             to_gltf(mesh.positions[t[1]], m),
                                                             to_gltf(mesh.positions[t[2]], m)};
        if (corners[0] == corners[1] || corners[1] == corners[2] || corners[0] == corners[2]) continue;
        for (const auto& p : corners) {
          for (int k = 0; k < 3; ++k) {
            lo[k] = any ? std::min(lo[k], p[k]) : p[k];
            hi[k] = any ? std::max(hi[k], p[k]) : p[k];
          }
          any = true;
        }
      }
    }
  float range = 0;
  for (int k = 0; k < 3; ++k) range = std::max(range, hi[k] - lo[k]);
  w.box.min = lo;
  w.box.range = range > 0 ? range : 1.0f;
}

// The PBR material of a surface: its colour, translucent and double-sided when not opaque.
tinygltf::Material surface_material(const GltfSurface& surface, const std::string& name,
                                    const std::string& path) {
  tinygltf::Material mat;
  mat.name = name;
  const auto& c = surface.color;
  for (float x : c)
    if (!(x >= 0.0f && x <= 1.0f)) throw Error(path + ": surface color components must be in [0, 1]");
  // Via the shortest decimal form, so 0.9f is written as 0.9 rather than 0.8999999761581421.
  auto shortest = [](float x) { return std::stod(fmt::format("{}", x)); };
  mat.pbrMetallicRoughness.baseColorFactor = {shortest(c[0]), shortest(c[1]), shortest(c[2]), shortest(c[3])};
  mat.pbrMetallicRoughness.metallicFactor = 0.0;  // tissue is a dielectric
  mat.pbrMetallicRoughness.roughnessFactor = 0.6;
  if (c[3] < 1.0f) {
    mat.alphaMode = "BLEND";
    mat.doubleSided = true;  // inner structures must stay visible through the back faces
  }
  return mat;
}

// One node per level of a surface (extras: iso value or the surface's own, lod, triangles); the
// coarser ones referenced from the full one through MSFT_lod. Returns the full level's node.
int add_surface_nodes(Writer& w, const GltfSurface& surface, const std::vector<Level>& levels,
                      const std::array<double, 9>& m, int material, bool& any_lod) {
  tinygltf::Model& model = w.model;
  std::vector<int> lod_nodes;
  int main_node = -1;
  for (const Level& level : levels) {
    tinygltf::Node node;
    node.name = level.node_name;
    tinygltf::Value::Object extras;
    if (surface.node_extras.is_object())
      extras = to_value(surface.node_extras).Get<tinygltf::Value::Object>();
    else
      extras["iso_value"] = tinygltf::Value(surface.iso_value);
    extras["lod"] = tinygltf::Value(level.lod);
    TriangleMesh mesh =
        convert(level.owned ? std::exchange(*level.owned, TriangleMesh{}) : *level.source, m, w.path);
    extras["triangles"] = tinygltf::Value(int(std::min<std::size_t>(mesh.triangles.size(), INT32_MAX)));
    node.extras = tinygltf::Value(std::move(extras));
    if (!mesh.triangles.empty()) node.mesh = w.add_mesh(level, std::move(mesh), material);
    model.nodes.push_back(node);
    const int id = int(model.nodes.size() - 1);
    if (level.lod == 0)
      main_node = id;
    else
      lod_nodes.push_back(id);
  }
  if (!lod_nodes.empty()) {
    // MSFT_lod: coarser levels are referenced from the full-resolution node and are not part
    // of the scene, so viewers without LOD support show only the full surface.
    tinygltf::Value::Array ids;
    for (int id : lod_nodes) ids.push_back(tinygltf::Value(id));
    tinygltf::Value::Object lod_ext;
    lod_ext["ids"] = tinygltf::Value(std::move(ids));
    model.nodes[main_node].extensions["MSFT_lod"] = tinygltf::Value(std::move(lod_ext));
    any_lod = true;
  }
  return main_node;
}

}  // namespace

std::array<double, 9> physical_to_gltf_matrix(const std::string& space) {
  // Asset right = -X, up = +Y, front = +Z (glTF 2.0 spec, "Coordinate System and Units").
  if (space.empty() || space == "RAS") return {-1e-3, 0, 0, 0, 0, 1e-3, 0, 1e-3, 0};
  if (space == "LPS") return {1e-3, 0, 0, 0, 0, 1e-3, 0, -1e-3, 0};
  throw Error("glTF export: unknown anatomical space '" + space + "' (expected RAS, LPS or empty)");
}

namespace {

// write_gltf's body; `owned`: the same surfaces when the caller gave them up.
void write_gltf_of(const std::string& path, const std::vector<GltfSurface>& surfaces,
                   std::vector<GltfSurface>* owned, const GltfOptions& options) {
  const std::string ext = lower_extension(path);
  if (ext != ".glb" && ext != ".gltf") throw Error(path + ": glTF output needs a .glb or .gltf extension");
  const bool binary = ext == ".glb";
  std::array<double, 9> m;
  try {
    m = physical_to_gltf_matrix(options.space);
  } catch (const Error& e) {
    throw Error(path + ": " + e.what());
  }
  const Encoding encoding = options.draco      ? Encoding::kDraco
                            : options.quantize ? Encoding::kQuantized
                                               : Encoding::kFloat;
  if (encoding != Encoding::kFloat && !(options.tolerance_mm > 0 && std::isfinite(options.tolerance_mm)))
    throw Error(path + ": tolerance_mm must be positive for compressed or quantized glTF");
  if (encoding == Encoding::kDraco && options.draco_piece_triangles == 0)
    throw Error(path + ": draco_piece_triangles must be at least 1");

  const std::vector<std::vector<Level>> levels = name_levels(surfaces, owned);

  Writer w{path, options, encoding, {}, {}};
  fit_shared_box(w, levels, m);
  if (encoding == Encoding::kQuantized) {
    const double max_error = 0.5 * double(w.box.range) / 65534.0;
    if (max_error > options.tolerance_mm * 1e-3)
      throw Error(path + fmt::format(": 16-bit quantization error {} mm exceeds tolerance {} mm; use Draco",
                                     max_error * 1e3, options.tolerance_mm));
  }

  tinygltf::Model& model = w.model;
  model.asset.version = "2.0";
  model.asset.generator = options.generator;
  {
    nlohmann::json extras = options.extras.is_object() ? options.extras : nlohmann::json::object();
    if (!options.extras.is_object() && !options.extras.is_null()) extras["provenance"] = options.extras;
    extras["mlfe"] = {
        {"physical_to_gltf", std::vector<double>(m.begin(), m.end())},
        {"input_space", options.space},
        {"assumed_space", options.space.empty() ? "RAS" : options.space},
        {"encoding", encoding == Encoding::kDraco       ? "draco"
                     : encoding == Encoding::kQuantized ? "quantized"
                                                        : "float"},
        {"tolerance_mm", options.tolerance_mm},
    };
    model.asset.extras = to_value(extras);
  }
  model.buffers.resize(1);

  tinygltf::Scene scene;
  scene.name = "mlfe";
  int parent = -1;
  if (encoding == Encoding::kQuantized) {
    // Dequantization transform for every surface (normalized SHORT -> metres).
    tinygltf::Node root;
    root.name = "mlfe dequantize";
    const double half = 0.5 * double(w.box.range);
    root.translation = {double(w.box.min[0]) + half, double(w.box.min[1]) + half,
                        double(w.box.min[2]) + half};
    root.scale = {half, half, half};
    model.nodes.push_back(root);
    parent = 0;
    scene.nodes.push_back(0);
  }
  bool any_lod = false;
  for (std::size_t s = 0; s < surfaces.size(); ++s) {
    const tinygltf::Material mat = surface_material(surfaces[s], levels[s][0].mesh_name, path);
    model.materials.push_back(mat);
    const int material = int(model.materials.size() - 1);

    const int main_node = add_surface_nodes(w, surfaces[s], levels[s], m, material, any_lod);
    if (parent >= 0)
      model.nodes[parent].children.push_back(main_node);
    else
      scene.nodes.push_back(main_node);
  }
  // Only declared when a mesh uses them: a required extension that nothing uses is an error.
  if (!model.meshes.empty() && encoding == Encoding::kDraco)
    add_extension(model, "KHR_draco_mesh_compression", true);
  if (!model.meshes.empty() && encoding == Encoding::kQuantized)
    add_extension(model, "KHR_mesh_quantization", true);
  if (any_lod) add_extension(model, "MSFT_lod", false);
  model.scenes.push_back(scene);
  model.defaultScene = 0;
  if (model.buffers[0].data.empty()) model.buffers.clear();  // a buffer must not be empty

  write_file_atomically(path, [&](std::ostream& out) {
    tinygltf::TinyGLTF gltf;
    if (!gltf.WriteGltfSceneToStream(&model, out, /*prettyPrint=*/!binary, /*writeBinary=*/binary))
      throw Error(path + ": glTF serialization failed");
  });
}

}  // namespace

void write_gltf(const std::string& path, const std::vector<GltfSurface>& surfaces,
                const GltfOptions& options) {
  write_gltf_of(path, surfaces, nullptr, options);
}

void write_gltf(const std::string& path, std::vector<GltfSurface>&& surfaces, const GltfOptions& options) {
  write_gltf_of(path, surfaces, &surfaces, options);
}

}  // namespace mlfe
