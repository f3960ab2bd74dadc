// meshopt_update: the meshoptimizer 1.2 peer of bench/py/convert_bench.py. Debian ships
// libmeshoptimizer 0.18, which lacks meshopt_simplifyWithUpdate (1.0+), so this tool is built
// apart from the CMake project, against a pinned meshoptimizer source tree, by
// scripts/build_bench_peers.sh; it depends on nothing of mlfe (hence its own small PLY code).
//
//   meshopt_update IN.ply TARGET_TRIANGLES OUT.ply [--error E] [--prune]
//
// meshopt_simplifyWithUpdate on the positions alone (no attributes, no locks): the collapses
// move the kept vertices to their quadric-optimal places, which 1.x's meshopt_simplify does not.
// --error is the relative error limit (fraction of the mesh extent); by default FLT_MAX, so the
// triangle count decides, as in iso_tools_bench's meshopt mode. gltfpack's default is 1e-2.
// --prune adds meshopt_SimplifyPrune (drops small disconnected components). Unused vertices are
// dropped afterwards with meshopt_optimizeVertexFetch, inside the timed span (as a user must
// before writing an asset). Prints one JSON line: counts, seconds, the resulting error.
//
// IN.ply: binary little-endian or ASCII, vertex x y z (float or double, other properties
// skipped), faces as a list of vertex indices (triangles; larger polygons are fanned).
// OUT.ply: binary little-endian, float x y z, uchar/int face lists.
#include <meshoptimizer.h>

#include <cfloat>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace {

struct Mesh {
  std::vector<float> positions;   // x y z per vertex
  std::vector<unsigned> indices;  // 3 per triangle
};

struct Property {
  std::string name, type, count_type;  // count_type: non-empty for lists
};

struct Element {
  std::string name;
  std::size_t count = 0;
  std::vector<Property> props;
};

int type_size(const std::string& t, const std::string& file) {
  if (t == "char" || t == "uchar" || t == "int8" || t == "uint8") return 1;
  if (t == "short" || t == "ushort" || t == "int16" || t == "uint16") return 2;
  if (t == "int" || t == "uint" || t == "float" || t == "int32" || t == "uint32" || t == "float32") return 4;
  if (t == "double" || t == "float64") return 8;
  throw std::runtime_error(file + ": unknown PLY type " + t);
}

// One scalar of type t from a binary little-endian stream (the host is little-endian: x86/ARM).
double read_binary(std::istream& in, const std::string& t, const std::string& file) {
  unsigned char b[8] = {};
  const int n = type_size(t, file);
  if (!in.read(reinterpret_cast<char*>(b), n)) throw std::runtime_error(file + ": truncated PLY data");
  auto as = [&](auto v) {
    std::memcpy(&v, b, sizeof v);
    return double(v);
  };
  if (t == "char" || t == "int8") return as(std::int8_t());
  if (t == "uchar" || t == "uint8") return as(std::uint8_t());
  if (t == "short" || t == "int16") return as(std::int16_t());
  if (t == "ushort" || t == "uint16") return as(std::uint16_t());
  if (t == "int" || t == "int32") return as(std::int32_t());
  if (t == "uint" || t == "uint32") return as(std::uint32_t());
  if (t == "float" || t == "float32") return as(float());
  return as(double());
}

std::vector<Element> read_header(std::istream& in, const std::string& file, bool& binary) {
  std::string line;
  if (!std::getline(in, line) || line.rfind("ply", 0) != 0)
    throw std::runtime_error(file + ": not a PLY file");
  std::vector<Element> elements;
  while (std::getline(in, line)) {
    std::istringstream ls(line);
    std::string word;
    ls >> word;
    if (word == "format") {
      ls >> word;
      if (word != "ascii" && word != "binary_little_endian")
        throw std::runtime_error(file + ": PLY format " + word + " is not supported");
      binary = word != "ascii";
    } else if (word == "element") {
      elements.emplace_back();
      ls >> elements.back().name >> elements.back().count;
    } else if (word == "property") {
      if (elements.empty()) throw std::runtime_error(file + ": PLY property before any element");
      Property p;
      ls >> p.type;
      if (p.type == "list") ls >> p.count_type >> p.type;
      ls >> p.name;
      elements.back().props.push_back(p);
    } else if (word == "end_header") {
      return elements;
    }
  }
  throw std::runtime_error(file + ": PLY header without end_header");
}

Mesh read_ply(const std::string& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) throw std::runtime_error(file + ": cannot open");
  bool binary = false;
  const std::vector<Element> elements = read_header(in, file, binary);
  auto value = [&](const std::string& t) {
    if (binary) return read_binary(in, t, file);
    double v = 0;
    if (!(in >> v)) throw std::runtime_error(file + ": truncated PLY data");
    return v;
  };
  Mesh m;
  for (const Element& e : elements) {
    for (std::size_t i = 0; i < e.count; ++i) {
      std::vector<unsigned> face;
      for (const Property& p : e.props) {
        if (p.count_type.empty()) {
          const double v = value(p.type);
          if (e.name == "vertex" && (p.name == "x" || p.name == "y" || p.name == "z"))
            m.positions.push_back(float(v));
          continue;
        }
        const std::size_t n = std::size_t(value(p.count_type));
        for (std::size_t k = 0; k < n; ++k) face.push_back(unsigned(value(p.type)));
        if (e.name == "face" && (p.name == "vertex_indices" || p.name == "vertex_index"))
          for (std::size_t k = 2; k < face.size(); ++k)
            m.indices.insert(m.indices.end(), {face[0], face[k - 1], face[k]});
        face.clear();
      }
    }
  }
  const std::size_t nv = m.positions.size() / 3;
  if (m.positions.size() % 3 != 0 || nv == 0)
    throw std::runtime_error(file + ": PLY vertices need x, y and z");
  for (unsigned i : m.indices)
    if (i >= nv) throw std::runtime_error(file + ": PLY face index out of range");
  return m;
}

void write_ply(const std::string& file, const Mesh& m) {
  std::ofstream out(file, std::ios::binary);
  const std::size_t nt = m.indices.size() / 3;
  out << "ply\nformat binary_little_endian 1.0\nelement vertex " << m.positions.size() / 3
      << "\nproperty float x\nproperty float y\nproperty float z\nelement face " << nt
      << "\nproperty list uchar int vertex_indices\nend_header\n";
  out.write(reinterpret_cast<const char*>(m.positions.data()),
            std::streamsize(m.positions.size() * sizeof(float)));
  for (std::size_t t = 0; t < nt; ++t) {
    const unsigned char three = 3;
    out.write(reinterpret_cast<const char*>(&three), 1);
    out.write(reinterpret_cast<const char*>(&m.indices[3 * t]), 3 * sizeof(unsigned));
  }
  if (!out) throw std::runtime_error(file + ": write failed");
}

int usage() {
  std::fprintf(stderr, "usage: meshopt_update IN.ply TARGET_TRIANGLES OUT.ply [--error E] [--prune]\n");
  return 1;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 4) return usage();
  float target_error = FLT_MAX;
  unsigned options = 0;
  for (int i = 4; i < argc; ++i) {
    if (std::strcmp(argv[i], "--error") == 0 && i + 1 < argc)
      target_error = std::strtof(argv[++i], nullptr);
    else if (std::strcmp(argv[i], "--prune") == 0)
      options |= meshopt_SimplifyPrune;
    else
      return usage();
  }
  try {
    using Clock = std::chrono::steady_clock;
    const auto r0 = Clock::now();
    Mesh m = read_ply(argv[1]);
    const double read_seconds = std::chrono::duration<double>(Clock::now() - r0).count();
    const std::size_t in_triangles = m.indices.size() / 3, nv = m.positions.size() / 3;
    const std::size_t target = std::strtoull(argv[2], nullptr, 10);
    // meshopt_simplifyScale is taken before the update moves the vertices: the extent the
    // relative error refers to.
    const float scale = meshopt_simplifyScale(m.positions.data(), nv, 3 * sizeof(float));
    const auto t0 = Clock::now();
    float err = 0;
    m.indices.resize(meshopt_simplifyWithUpdate(m.indices.data(), m.indices.size(), m.positions.data(), nv,
                                                3 * sizeof(float), nullptr, 0, nullptr, 0, nullptr,
                                                target * 3, target_error, options, &err));
    Mesh out;
    out.positions.resize(m.positions.size());
    out.positions.resize(3 * meshopt_optimizeVertexFetch(out.positions.data(), m.indices.data(),
                                                         m.indices.size(), m.positions.data(), nv,
                                                         3 * sizeof(float)));
    out.indices = std::move(m.indices);
    const double seconds = std::chrono::duration<double>(Clock::now() - t0).count();
    write_ply(argv[3], out);
    std::printf(
        "{\"method\": \"meshopt_simplifyWithUpdate\", \"meshoptimizer_version\": %d, \"target_error\": %g, "
        "\"prune\": %s, \"input_triangles\": %zu, \"target_triangles\": %zu, \"read_seconds\": %.6f, "
        "\"simplify_seconds\": %.6f, \"relative_error\": %g, \"absolute_error\": %g, \"vertices\": %zu, "
        "\"triangles\": %zu}\n",
        MESHOPTIMIZER_VERSION, double(target_error), options ? "true" : "false", in_triangles, target,
        read_seconds, seconds, double(err), double(err * scale), out.positions.size() / 3,
        out.indices.size() / 3);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "meshopt_update: %s\n", e.what());
    return 2;
  }
  return 0;
}
