#include <draco/attributes/attribute_quantization_transform.h>
#include <draco/compression/decode.h>
#include <draco/compression/encode.h>
#include <draco/compression/expert_encode.h>
#include <draco/mesh/mesh.h>
#include <mlfe/core/base/error.h>
#include <mlfe/formats/atomic_file.h>
#include <mlfe/formats/draco_io.h>
#include <mlfe/formats/safe_read.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <new>
#include <unordered_map>
#include <utility>

namespace mlfe {
namespace {

constexpr const char* kEncodeWhat = "Draco encoding";

bool finite3(const std::array<float, 3>& p) {
  return std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]);
}

void check_options(const DracoOptions& o) {
  if (!(o.tolerance > 0) || !std::isfinite(o.tolerance))
    throw Error(std::string(kEncodeWhat) + ": tolerance must be a positive number");
  if (o.normal_bits < 1 || o.normal_bits > 30)
    throw Error(std::string(kEncodeWhat) + ": normal_bits must be in [1, 30]");
  if (o.speed < 0 || o.speed > 10) throw Error(std::string(kEncodeWhat) + ": speed must be in [0, 10]");
  if (!std::isfinite(o.box_range) || !finite3(o.box_min))
    throw Error(std::string(kEncodeWhat) + ": quantization box is not finite");
}

// Validates the input and drops its degenerate triangles in place (see the header for why).
void clean(TriangleMesh& mesh) {
  const std::size_t n = mesh.positions.size();
  if (!mesh.normals.empty() && mesh.normals.size() != n)
    throw Error(std::string(kEncodeWhat) + ": " + std::to_string(mesh.normals.size()) + " normals for " +
                std::to_string(n) + " positions");
  for (const auto& p : mesh.positions)
    if (!finite3(p)) throw Error(std::string(kEncodeWhat) + ": non-finite vertex position");
  for (const auto& v : mesh.normals)
    if (!finite3(v)) throw Error(std::string(kEncodeWhat) + ": non-finite vertex normal");
  if (n > std::numeric_limits<std::int32_t>::max())
    throw Error(std::string(kEncodeWhat) + ": too many vertices");
  std::size_t kept = 0;
  for (const auto& t : mesh.triangles) {
    if (t[0] >= n || t[1] >= n || t[2] >= n)
      throw Error(std::string(kEncodeWhat) + ": triangle index out of range");
    const auto& a = mesh.positions[t[0]];
    const auto& b = mesh.positions[t[1]];
    const auto& c = mesh.positions[t[2]];
    if (a == b || b == c || a == c) continue;
    mesh.triangles[kept++] = t;
  }
  mesh.triangles.resize(kept);
}

// Positions within `tol` per coordinate (Chebyshev distance), the metric of quantization error.
bool near(const std::array<float, 3>& a, const std::array<float, 3>& b, double tol) {
  for (int k = 0; k < 3; ++k)
    if (std::fabs(double(a[k]) - double(b[k])) > tol) return false;
  return true;
}

// Checks that every decoded triangle matches an input triangle corner by corner (same cyclic
// order, i.e. same orientation) within `tol`. Vertex identities are lost in Draco, so the match
// goes through a uniform hash grid over input positions with cells of size `tol`.
void verify_decoded(const TriangleMesh& input, const TriangleMesh& decoded, double tol) {
  if (decoded.triangles.size() != input.triangles.size())
    throw Error(std::string(kEncodeWhat) + ": verification failed: decoded " +
                std::to_string(decoded.triangles.size()) + " triangles instead of " +
                std::to_string(input.triangles.size()));
  if (input.triangles.empty()) return;

  double max_abs = 0;
  for (const auto& p : input.positions)
    for (float c : p) max_abs = std::max(max_abs, double(std::fabs(c)));
  // Cells of 4*tol: a query box [d-tol, d+tol] touches 1.5 cells per axis on average, and a
  // cell rarely holds more than one vertex because tolerances are far below edge lengths.
  // The floor of 2^-50 of the extent keeps cell indices exact in a double.
  const double cell = std::max(4.0 * tol, max_abs / double(std::int64_t(1) << 50));
  auto cell_of = [&](double c) { return std::int64_t(std::floor(c / cell)); };
  auto key_of = [](std::int64_t x, std::int64_t y, std::int64_t z) {
    // Distinct cells may share a key; that only adds candidates, each checked exactly below.
    std::uint64_t h = std::uint64_t(x) * 0x9E3779B97F4A7C15ull;
    h ^= std::uint64_t(y) * 0xC2B2AE3D27D4EB4Full + (h << 6) + (h >> 2);
    h ^= std::uint64_t(z) * 0x165667B19E3779F9ull + (h << 6) + (h >> 2);
    return h;
  };

  // Incident triangles per input vertex (CSR).
  const std::size_t n = input.positions.size();
  std::vector<std::uint32_t> first(n + 1, 0);
  for (const auto& t : input.triangles)
    for (auto v : t) ++first[v + 1];
  for (std::size_t i = 0; i < n; ++i) first[i + 1] += first[i];
  std::vector<std::uint32_t> incident(first[n]);
  {
    std::vector<std::uint32_t> fill(first.begin(), first.end() - 1);
    for (std::uint32_t f = 0; f < input.triangles.size(); ++f)
      for (auto v : input.triangles[f]) incident[fill[v]++] = f;
  }
  // Grid of referenced vertices: (key, vertex) sorted by key, and key -> [begin, end).
  std::vector<std::pair<std::uint64_t, std::uint32_t>> cells;
  cells.reserve(n);
  for (std::uint32_t v = 0; v < n; ++v) {
    if (first[v] == first[v + 1]) continue;
    const auto& p = input.positions[v];
    cells.emplace_back(key_of(cell_of(p[0]), cell_of(p[1]), cell_of(p[2])), v);
  }
  std::sort(cells.begin(), cells.end());
  std::unordered_map<std::uint64_t, std::pair<std::uint32_t, std::uint32_t>> grid;
  grid.reserve(cells.size());
  for (std::uint32_t i = 0; i < cells.size();) {
    std::uint32_t j = i;
    while (j < cells.size() && cells[j].first == cells[i].first) ++j;
    grid.emplace(cells[i].first, std::make_pair(i, j));
    i = j;
  }

  for (std::size_t f = 0; f < decoded.triangles.size(); ++f) {
    const auto& dt = decoded.triangles[f];
    const auto& d0 = decoded.positions[dt[0]];
    const auto& d1 = decoded.positions[dt[1]];
    const auto& d2 = decoded.positions[dt[2]];
    std::int64_t lo[3], hi[3];
    for (int k = 0; k < 3; ++k) {
      lo[k] = cell_of(double(d0[k]) - tol);
      hi[k] = cell_of(double(d0[k]) + tol);
    }
    bool found = false;
    for (std::int64_t x = lo[0]; x <= hi[0] && !found; ++x)
      for (std::int64_t y = lo[1]; y <= hi[1] && !found; ++y)
        for (std::int64_t z = lo[2]; z <= hi[2] && !found; ++z) {
          auto it = grid.find(key_of(x, y, z));
          if (it == grid.end()) continue;
          for (std::uint32_t c = it->second.first; c < it->second.second && !found; ++c) {
            const std::uint32_t v = cells[c].second;
            if (!near(input.positions[v], d0, tol)) continue;
            for (std::uint32_t i = first[v]; i < first[v + 1] && !found; ++i) {
              const auto& t = input.triangles[incident[i]];
              const int k = t[0] == v ? 0 : t[1] == v ? 1 : 2;
              found = near(input.positions[t[(k + 1) % 3]], d1, tol) &&
                      near(input.positions[t[(k + 2) % 3]], d2, tol);
            }
          }
        }
    if (!found)
      throw Error(std::string(kEncodeWhat) + ": verification failed: decoded triangle " + std::to_string(f) +
                  " is not within tolerance " + std::to_string(tol) + " of any input triangle");
  }
}

}  // namespace

int quantization_bits_for(double tolerance, double box_range) {
  if (!(tolerance > 0) || !std::isfinite(tolerance) || !std::isfinite(box_range))
    throw Error("Draco quantization: tolerance must be positive and the box range finite");
  for (int bits = 8; bits <= 30; ++bits) {
    const double max_error = box_range / double((std::uint64_t(1) << bits) - 1) / 2.0;
    if (max_error <= tolerance) return bits;
  }
  return 30;
}

namespace {

// A Draco mesh holding `mesh`'s arrays, each released from `mesh` once copied (the encoder's
// own tables are several times the mesh: the mesh is not held beside them). Returns the
// attribute ids of the positions and normals (-1 without normals).
std::pair<int, int> move_into(TriangleMesh& mesh, draco::Mesh& dm) {
  const std::size_t n = mesh.positions.size();
  dm.set_num_points(static_cast<draco::PointIndex::ValueType>(n));
  auto add = [&](draco::GeometryAttribute::Type type, std::vector<std::array<float, 3>>& values) {
    draco::GeometryAttribute att;
    att.Init(type, nullptr, 3, draco::DT_FLOAT32, false, sizeof(float) * 3, 0);
    const int id = dm.AddAttribute(att, true, static_cast<draco::AttributeValueIndex::ValueType>(n));
    for (std::size_t i = 0; i < n; ++i)
      dm.attribute(id)->SetAttributeValue(draco::AttributeValueIndex(std::uint32_t(i)), values[i].data());
    std::vector<std::array<float, 3>>().swap(values);
    return id;
  };
  const int pos_id = add(draco::GeometryAttribute::POSITION, mesh.positions);
  const int nrm_id = mesh.normals.empty() ? -1 : add(draco::GeometryAttribute::NORMAL, mesh.normals);
  dm.SetNumFaces(mesh.triangles.size());
  for (std::size_t f = 0; f < mesh.triangles.size(); ++f) {
    const auto& t = mesh.triangles[f];
    dm.SetFace(draco::FaceIndex(std::uint32_t(f)),
               {draco::PointIndex(t[0]), draco::PointIndex(t[1]), draco::PointIndex(t[2])});
  }
  std::vector<std::array<std::uint32_t, 3>>().swap(mesh.triangles);
  return {pos_id, nrm_id};
}

// The positions and triangles that move_into took (what verify_decoded compares with).
TriangleMesh taken_back(const draco::Mesh& dm, int pos_id) {
  TriangleMesh m;
  const draco::PointAttribute& pos = *dm.attribute(pos_id);
  m.positions.resize(dm.num_points());
  for (std::uint32_t i = 0; i < m.positions.size(); ++i)
    pos.GetValue(draco::AttributeValueIndex(i), m.positions[i].data());
  m.triangles.resize(dm.num_faces());
  for (std::uint32_t f = 0; f < dm.num_faces(); ++f) {
    const auto& face = dm.face(draco::FaceIndex(f));
    m.triangles[f] = {face[0].value(), face[1].value(), face[2].value()};
  }
  return m;
}

}  // namespace

DracoEncoding encode_draco_verified(TriangleMesh&& mesh, const DracoOptions& options) {
  check_options(options);
  clean(mesh);
  if (mesh.triangles.empty())
    throw Error(std::string(kEncodeWhat) + ": the mesh has no (non-degenerate) triangles");

  // Quantization box: the caller's shared box, or this mesh's own bounding cube.
  std::array<float, 3> origin = options.box_min;
  float range = options.box_range;
  if (range > 0) {
    for (const auto& p : mesh.positions)
      for (int k = 0; k < 3; ++k) {
        // The same float subtraction Draco performs, so "inside" here means inside there.
        const float offset = p[k] - origin[k];
        if (!(offset >= 0.0f && offset <= range))
          throw Error(std::string(kEncodeWhat) + ": vertex position outside the quantization box");
      }
  } else {
    std::array<float, 3> hi = mesh.positions[0];
    origin = mesh.positions[0];
    for (const auto& p : mesh.positions)
      for (int k = 0; k < 3; ++k) {
        origin[k] = std::min(origin[k], p[k]);
        hi[k] = std::max(hi[k], p[k]);
      }
    range = 0;
    for (int k = 0; k < 3; ++k) range = std::max(range, hi[k] - origin[k]);
    if (!(range > 0)) range = 1.0f;  // cannot happen with a non-degenerate triangle; stay safe
  }
  const int bits = quantization_bits_for(options.tolerance, range);

  DracoEncoding result;
  TriangleMesh input;
  {
    draco::Mesh dm;
    const auto [pos_id, nrm_id] = move_into(mesh, dm);
    {
      draco::ExpertEncoder encoder(dm);
      encoder.SetAttributeExplicitQuantization(pos_id, bits, 3, origin.data(), range);
      if (nrm_id >= 0) encoder.SetAttributeQuantization(nrm_id, options.normal_bits);
      encoder.SetSpeedOptions(options.speed, options.speed);
      draco::EncoderBuffer buffer;
      const draco::Status status = encoder.EncodeToBuffer(&buffer);
      if (!status.ok()) throw Error(std::string(kEncodeWhat) + ": " + status.error_msg_string());
      result.bytes.assign(buffer.data(), buffer.data() + buffer.size());
    }
    result.position_unique_id = int(dm.attribute(pos_id)->unique_id());
    result.normal_unique_id = nrm_id >= 0 ? int(dm.attribute(nrm_id)->unique_id()) : -1;
    input = taken_back(dm, pos_id);
  }
  result.quantization_bits = bits;
  result.decoded = decode_draco(result.bytes.data(), result.bytes.size(), kEncodeWhat);

  // Slack for float arithmetic in Draco's (de)quantization: a few ulps of the coordinates.
  const double ulp_slack =
      8.0 * std::numeric_limits<float>::epsilon() *
      (double(range) + std::max({std::fabs(origin[0]), std::fabs(origin[1]), std::fabs(origin[2])}));
  verify_decoded(input, result.decoded, options.tolerance + ulp_slack);
  return result;
}

DracoEncoding encode_draco_verified(const TriangleMesh& mesh, const DracoOptions& options) {
  return encode_draco_verified(TriangleMesh(mesh), options);
}

std::vector<char> encode_draco(const TriangleMesh& mesh, const DracoOptions& options) {
  return encode_draco_verified(mesh, options).bytes;
}

double DracoQuantization::step() const {
  return bits > 0 ? double(range) / double((std::uint64_t(1) << bits) - 1) : 0.0;
}

TriangleMesh decode_draco(const char* data, std::size_t size, const std::string& what,
                          DracoQuantization* quantization) {
  if (data == nullptr || size == 0) throw Error(what + ": empty Draco data");
  draco::DecoderBuffer buffer;
  buffer.Init(data, size);
  auto type = draco::Decoder::GetEncodedGeometryType(&buffer);
  if (!type.ok()) throw Error(what + ": not Draco data (" + type.status().error_msg_string() + ")");
  if (type.value() != draco::TRIANGULAR_MESH) throw Error(what + ": Draco data is not a triangle mesh");
  draco::Decoder decoder;
  // Quantized positions come back as the encoder's integers with their grid, which a plain decode
  // forgets; Draco's own inverse transform below then gives the floats a plain decode gives.
  decoder.SetSkipAttributeTransform(draco::GeometryAttribute::POSITION);
  // Draco sizes its buffers from counts in the data: a corrupt count can ask for gigabytes
  // (found by fuzzing), which surfaces here as bad_alloc.
  auto decode = [&] {
    try {
      return decoder.DecodeMeshFromBuffer(&buffer);
    } catch (const std::bad_alloc&) {
      throw Error(what + ": corrupt Draco data (declared sizes exceed the memory available)");
    }
  };
  auto decoded = decode();
  if (!decoded.ok()) throw Error(what + ": corrupt Draco data (" + decoded.status().error_msg_string() + ")");
  const draco::Mesh& dm = *decoded.value();

  const std::size_t n = dm.num_points();
  // Reads one attribute per point (values from `values`, indexed through `att`'s point map),
  // refusing maps that point outside the value array (corrupt input must not make us read out
  // of bounds).
  auto read_vec3 = [&](const draco::PointAttribute* att, const draco::PointAttribute* values,
                       const char* name) {
    std::vector<std::array<float, 3>> out(n);
    if (values->num_components() != 3)
      throw Error(what + ": Draco " + name + " attribute is not 3-component");
    // Only numeric types: Draco's converter reads DT_BOOL bytes as C++ bool, which is undefined
    // for bytes other than 0/1 (found by fuzzing).
    switch (values->data_type()) {
      case draco::DT_INT8:
      case draco::DT_UINT8:
      case draco::DT_INT16:
      case draco::DT_UINT16:
      case draco::DT_INT32:
      case draco::DT_UINT32:
      case draco::DT_FLOAT32:
      case draco::DT_FLOAT64:
        break;
      default:
        throw Error(what + ": corrupt Draco data (" + name + " attribute has a non-numeric type)");
    }
    if (!att->is_mapping_identity() && att->indices_map_size() < n)
      throw Error(what + ": corrupt Draco data (" + name + " map too short)");
    for (std::size_t i = 0; i < n; ++i) {
      const draco::AttributeValueIndex avi = att->mapped_index(draco::PointIndex(std::uint32_t(i)));
      if (avi.value() >= values->size() || !values->ConvertValue<float>(avi, 3, out[i].data()))
        throw Error(what + ": corrupt Draco data (" + name + " index out of range)");
      if (!finite3(out[i])) throw Error(what + ": corrupt Draco data (non-finite " + name + ")");
    }
    return out;
  };

  const draco::PointAttribute* pos = dm.GetNamedAttribute(draco::GeometryAttribute::POSITION);
  if (pos == nullptr) throw Error(what + ": Draco mesh has no positions");
  draco::AttributeQuantizationTransform grid;
  draco::PointAttribute dequantized;
  const draco::PointAttribute* position_values = pos;
  if (pos->GetAttributeTransformData() != nullptr) {
    // The inverse transform reads size() x 3 packed 32-bit integers: checked before it runs.
    const bool packed = pos->num_components() == 3 && pos->byte_offset() == 0 && pos->byte_stride() == 12 &&
                        (pos->data_type() == draco::DT_INT32 || pos->data_type() == draco::DT_UINT32) &&
                        pos->buffer() != nullptr && pos->buffer()->data_size() / 12 >= pos->size();
    if (!packed || !grid.InitFromAttribute(*pos) || grid.quantization_bits() < 1 ||
        grid.quantization_bits() > 30)
      throw Error(what + ": corrupt Draco data (bad POSITION quantization)");
    dequantized.Init(draco::GeometryAttribute::POSITION, 3, draco::DT_FLOAT32, false, pos->size());
    if (!grid.InverseTransformAttribute(*pos, &dequantized))
      throw Error(what + ": corrupt Draco data (bad POSITION quantization)");
    position_values = &dequantized;
  }
  TriangleMesh mesh;
  mesh.positions = read_vec3(pos, position_values, "POSITION");
  if (const draco::PointAttribute* nrm = dm.GetNamedAttribute(draco::GeometryAttribute::NORMAL)) {
    if (nrm->num_components() == 3) mesh.normals = read_vec3(nrm, nrm, "NORMAL");
  }
  mesh.triangles.resize(dm.num_faces());
  for (std::uint32_t f = 0; f < dm.num_faces(); ++f) {
    const auto& face = dm.face(draco::FaceIndex(f));
    for (int k = 0; k < 3; ++k) {
      if (face[k].value() >= n) throw Error(what + ": corrupt Draco data (face index out of range)");
      mesh.triangles[f][k] = face[k].value();
    }
  }
  if (quantization != nullptr) {
    *quantization = {};
    if (position_values != pos) {
      quantization->bits = grid.quantization_bits();
      quantization->min = {grid.min_value(0), grid.min_value(1), grid.min_value(2)};
      quantization->range = grid.range();
    }
  }
  return mesh;
}

void write_draco_file(const std::string& path, TriangleMesh mesh, const DracoOptions& options) {
  std::vector<char> bytes;
  try {
    bytes = encode_draco_verified(std::move(mesh), options).bytes;
  } catch (const Error& e) {
    throw Error(path + ": " + e.what());
  }
  write_file_atomically(path,
                        [&](std::ostream& out) { out.write(bytes.data(), std::streamsize(bytes.size())); });
}

TriangleMesh read_draco_file(const std::string& path, DracoQuantization* quantization) {
  const std::string bytes = read_regular_file(path, UINT64_MAX, "the file");
  return decode_draco(bytes.data(), bytes.size(), path, quantization);
}

}  // namespace mlfe
