// Gmsh MSH reader for tetrahedral meshes with point values, after the Gmsh reference manual's
// "MSH file format" (version 4.1) and "Legacy formats" (version 2.2): ASCII and binary (the
// binary forms write an integer 1 after $MeshFormat so the byte order can be checked).
#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <cstring>
#include <type_traits>
#include <vector>

#include "formats/reader_helpers.h"
#include "formats/tet_mesh_reader_detail.h"

namespace mlfe::tet_mesh_detail {

using volume_detail::fail;

namespace {

// Nodes per element of the Gmsh element types 1..19; 0: unknown. Volume types besides the
// 4-node tetrahedron (4) are rejected, lower-dimensional ones skipped.
constexpr int kNodesPerType[20] = {0, 2, 3, 4, 4, 8, 6, 5, 3, 6, 9, 10, 27, 18, 14, 1, 8, 20, 15, 13};
bool is_volume_type(int t) { return t == 4 || (t >= 5 && t <= 7) || (t >= 11 && t <= 14) || t >= 17; }

class Cursor {
 public:
  Cursor(const std::string& path, const std::string& data)
      : path_(path), p_(data.data()), begin_(data.data()), end_(data.data() + data.size()) {}

  std::size_t remaining() const { return std::size_t(end_ - p_); }
  bool at_end() {
    skip_space();
    return p_ == end_;
  }
  void skip_space() {
    while (p_ < end_ && std::isspace(static_cast<unsigned char>(*p_))) ++p_;
  }
  // The rest of the current line (without \r\n); the cursor moves past it.
  std::string line() {
    const char* e = static_cast<const char*>(std::memchr(p_, '\n', remaining()));
    if (!e) e = end_;
    std::string s(p_, e);
    p_ = e < end_ ? e + 1 : e;
    while (!s.empty() && (s.back() == '\r' || s.back() == ' ' || s.back() == '\t')) s.pop_back();
    return s;
  }
  // The next non-empty line.
  std::string next_line() {
    skip_space();
    return line();
  }
  template <class T>
  T number(const char* what) {
    T v{};
    if (!next_number(p_, end_, v))
      fail(path_, fmt::format("{}: expected a number at byte {}", what, offset()));
    return v;
  }
  template <class T>
  T binary(const char* what) {
    if (remaining() < sizeof(T)) fail(path_, fmt::format("{}: truncated at byte {}", what, offset()));
    T v;
    std::memcpy(&v, p_, sizeof(T));
    p_ += sizeof(T);
    return v;
  }
  // A count read as text (binary: as T), no larger than what the remaining bytes can hold at
  // `min_bytes` bytes per item.
  template <class T>
  std::uint64_t count(bool bin, std::size_t min_bytes, const char* what) {
    std::uint64_t n;
    if (bin) {
      const T v = binary<T>(what);
      if constexpr (std::is_signed_v<T>)
        if (v < 0) fail(path_, fmt::format("{}: negative count {}", what, v));
      n = std::uint64_t(v);
    } else {
      const long long v = number<long long>(what);
      if (v < 0) fail(path_, fmt::format("{}: negative count {}", what, v));
      n = std::uint64_t(v);
    }
    if (n > remaining() / min_bytes)
      fail(path_, fmt::format("{}: {} entries cannot fit in the {} bytes left (truncated file?)", what, n,
                              remaining()));
    return n;
  }
  void expect_end(const std::string& section) {
    const std::string l = next_line();
    if (l != "$End" + section)
      fail(path_, fmt::format("expected $End{} at byte {}, found '{}'", section, offset(), l.substr(0, 40)));
  }
  void skip_section(const std::string& section) {
    const std::string end = "$End" + section;
    const char* e = std::search(p_, end_, end.begin(), end.end());
    if (e == end_) fail(path_, fmt::format("section ${} has no {}", section, end));
    p_ = e;
    line();
  }
  std::size_t offset() const { return std::size_t(p_ - begin_); }

 private:
  const std::string& path_;
  const char* p_;
  const char* begin_;
  const char* end_;
};

struct Msh {
  std::vector<std::uint64_t> node_tags;
  std::vector<std::array<double, 3>> xyz;
  std::vector<std::array<std::uint64_t, 4>> tets;
  std::vector<std::pair<std::uint64_t, double>> data;
  std::string data_name;
  bool have_data = false;
};

class Reader {
 public:
  Reader(const std::string& path, const std::string& data, const TetMeshReadOptions& options,
         std::uint64_t limit)
      : path_(path), c_(path, data), options_(options), limit_(limit) {}

  TetMesh read() {
    header();
    bool nodes = false, elements = false;
    while (!c_.at_end()) {
      const std::string l = c_.next_line();
      if (l.empty() || l[0] != '$')
        fail(path_, fmt::format("expected a section ($Name), found '{}'", l.substr(0, 40)));
      const std::string name = l.substr(1);
      if (name == "Nodes") {
        if (nodes) fail(path_, "more than one $Nodes section");
        v4_ ? nodes_v4() : nodes_v2();
        nodes = true;
      } else if (name == "Elements") {
        if (elements) fail(path_, "more than one $Elements section");
        v4_ ? elements_v4() : elements_v2();
        elements = true;
      } else if (name == "NodeData" && !m_.have_data) {
        if (!node_data()) continue;  // another view: skipped with its $EndNodeData
      } else {
        c_.skip_section(name);
        continue;
      }
      c_.expect_end(name);
    }
    if (!nodes) fail(path_, "no $Nodes section");
    if (!elements) fail(path_, "no $Elements section");
    if (!m_.have_data)
      fail(path_, options_.array_name.empty()
                      ? std::string("no scalar $NodeData (point values)")
                      : fmt::format("no scalar $NodeData named '{}'", options_.array_name));
    return assemble();
  }

 private:
  void header() {
    if (c_.next_line() != "$MeshFormat") fail(path_, "not a Gmsh mesh (no $MeshFormat)");
    const std::string l = c_.line();
    char version[16] = {0};
    int type = -1, size = -1;
    if (std::sscanf(l.c_str(), "%15s %d %d", version, &type, &size) != 3)
      fail(path_, fmt::format("bad $MeshFormat line '{}'", l.substr(0, 40)));
    const std::string v = version;
    if (v == "4.1")
      v4_ = true;
    else if (v != "2.2" && v != "2.1" && v != "2")
      fail(path_, fmt::format("MSH version {} is not supported (2.2 or 4.1)", v));
    if (type != 0 && type != 1) fail(path_, fmt::format("bad file type {} in $MeshFormat", type));
    if (size != 8) fail(path_, fmt::format("data size {} is not supported (8-byte doubles)", size));
    binary_ = type == 1;
    if (binary_) {
      const int one = c_.binary<int>("$MeshFormat");
      if (one != 1) fail(path_, "binary MSH in the other byte order (only little endian is read)");
    }
    c_.expect_end("MeshFormat");
  }

  void add_node(std::uint64_t tag, double x, double y, double z) {
    m_.node_tags.push_back(tag);
    m_.xyz.push_back({x, y, z});
  }

  void reserve_nodes(std::uint64_t n) {
    check_mesh_memory(path_, n, 0, limit_);
    m_.node_tags.reserve(std::size_t(n));
    m_.xyz.reserve(std::size_t(n));
  }

  void nodes_v2() {
    const std::uint64_t n = c_.count<std::uint64_t>(false, binary_ ? 28 : 8, "$Nodes");
    reserve_nodes(n);
    if (binary_) c_.line();
    for (std::uint64_t i = 0; i < n; ++i) {
      if (binary_) {
        const int tag = c_.binary<int>("$Nodes");
        const double x = c_.binary<double>("$Nodes"), y = c_.binary<double>("$Nodes"),
                     z = c_.binary<double>("$Nodes");
        if (tag < 0) fail(path_, fmt::format("negative node tag {}", tag));
        add_node(std::uint64_t(tag), x, y, z);
      } else {
        const auto tag = c_.number<std::uint64_t>("$Nodes");
        const double x = c_.number<double>("$Nodes"), y = c_.number<double>("$Nodes"),
                     z = c_.number<double>("$Nodes");
        add_node(tag, x, y, z);
      }
    }
  }

  void nodes_v4() {
    const std::uint64_t blocks = c_.count<std::uint64_t>(binary_, binary_ ? 20 : 8, "$Nodes");
    const std::uint64_t n = c_.count<std::uint64_t>(binary_, binary_ ? 32 : 8, "$Nodes");
    binary_ ? c_.binary<std::uint64_t>("$Nodes") : c_.number<std::uint64_t>("$Nodes");  // min tag
    binary_ ? c_.binary<std::uint64_t>("$Nodes") : c_.number<std::uint64_t>("$Nodes");  // max tag
    reserve_nodes(n);
    std::uint64_t total = 0;
    for (std::uint64_t b = 0; b < blocks; ++b) {
      int dim, parametric;
      if (binary_) {
        dim = c_.binary<int>("$Nodes");
        c_.binary<int>("$Nodes");
        parametric = c_.binary<int>("$Nodes");
      } else {
        dim = c_.number<int>("$Nodes");
        c_.number<int>("$Nodes");
        parametric = c_.number<int>("$Nodes");
      }
      if (dim < 0 || dim > 3 || parametric < 0 || parametric > 1)
        fail(path_, fmt::format("$Nodes: bad entity block (dimension {}, parametric {})", dim, parametric));
      const int per_node = 3 + (parametric ? dim : 0);
      const std::uint64_t k =
          c_.count<std::uint64_t>(binary_, binary_ ? std::size_t(8 + 8 * per_node) : 8, "$Nodes");
      if (k > n - total) fail(path_, fmt::format("$Nodes: blocks hold more than the {} nodes announced", n));
      total += k;
      std::vector<std::uint64_t> tags(static_cast<std::size_t>(k));
      for (auto& t : tags)
        t = binary_ ? c_.binary<std::uint64_t>("$Nodes") : c_.number<std::uint64_t>("$Nodes");
      for (std::uint64_t i = 0; i < k; ++i) {
        double v[6];
        for (int j = 0; j < per_node; ++j)
          v[j] = binary_ ? c_.binary<double>("$Nodes") : c_.number<double>("$Nodes");
        add_node(tags[i], v[0], v[1], v[2]);
      }
    }
    if (total != n) fail(path_, fmt::format("$Nodes: {} nodes announced, {} in the blocks", n, total));
  }

  void element(int type, const std::uint64_t* nodes, std::size_t count) {
    if (type < 1 || type > 19 || !kNodesPerType[type])
      fail(path_, fmt::format("unknown element type {}", type));
    if (type != 4 && is_volume_type(type))
      fail(path_, fmt::format("only 4-node tetrahedra (element type 4) are supported, found type {}", type));
    if (type != 4) return;
    if (count != 4) fail(path_, "a tetrahedron without 4 nodes");
    if (m_.tets.size() == m_.tets.capacity())
      check_mesh_memory(path_, m_.node_tags.size(), 2 * m_.tets.size() + 1, limit_);
    m_.tets.push_back({nodes[0], nodes[1], nodes[2], nodes[3]});
  }

  void elements_v2() {
    const std::uint64_t n = c_.count<std::uint64_t>(false, binary_ ? 16 : 8, "$Elements");
    if (binary_) {
      c_.line();
      std::uint64_t done = 0;
      while (done < n) {
        const int type = c_.binary<int>("$Elements");
        const int count = c_.binary<int>("$Elements");
        const int ntags = c_.binary<int>("$Elements");
        if (type < 1 || type > 19 || !kNodesPerType[type])
          fail(path_, fmt::format("unknown element type {}", type));
        if (count <= 0 || ntags < 0 || ntags > 1000 || std::uint64_t(count) > n - done)
          fail(path_, fmt::format("$Elements: bad block header (count {}, tags {})", count, ntags));
        const int nn = kNodesPerType[type];
        if (std::uint64_t(count) * std::uint64_t(1 + ntags + nn) * 4 > c_.remaining())
          fail(path_, "$Elements: truncated");
        for (int e = 0; e < count; ++e) {
          c_.binary<int>("$Elements");
          for (int t = 0; t < ntags; ++t) c_.binary<int>("$Elements");
          std::uint64_t nodes[27];
          for (int k = 0; k < nn; ++k) {
            const int v = c_.binary<int>("$Elements");
            nodes[k] = v < 0 ? ~std::uint64_t(0) : std::uint64_t(v);
          }
          element(type, nodes, std::size_t(nn));
        }
        done += std::uint64_t(count);
      }
      return;
    }
    for (std::uint64_t e = 0; e < n; ++e) {
      c_.number<std::uint64_t>("$Elements");
      const int type = c_.number<int>("$Elements");
      const int ntags = c_.number<int>("$Elements");
      if (ntags < 0 || ntags > 1000) fail(path_, fmt::format("$Elements: bad tag count {}", ntags));
      for (int t = 0; t < ntags; ++t) c_.number<long long>("$Elements");
      if (type < 1 || type > 19 || !kNodesPerType[type])
        fail(path_, fmt::format("unknown element type {}", type));
      const int nn = kNodesPerType[type];
      std::uint64_t nodes[27];
      for (int k = 0; k < nn; ++k) nodes[k] = c_.number<std::uint64_t>("$Elements");
      element(type, nodes, std::size_t(nn));
    }
  }

  void elements_v4() {
    const std::uint64_t blocks = c_.count<std::uint64_t>(binary_, binary_ ? 20 : 8, "$Elements");
    const std::uint64_t n = c_.count<std::uint64_t>(binary_, binary_ ? 16 : 4, "$Elements");
    binary_ ? c_.binary<std::uint64_t>("$Elements") : c_.number<std::uint64_t>("$Elements");
    binary_ ? c_.binary<std::uint64_t>("$Elements") : c_.number<std::uint64_t>("$Elements");
    std::uint64_t total = 0;
    for (std::uint64_t b = 0; b < blocks; ++b) {
      int type;
      if (binary_) {
        c_.binary<int>("$Elements");
        c_.binary<int>("$Elements");
        type = c_.binary<int>("$Elements");
      } else {
        c_.number<int>("$Elements");
        c_.number<int>("$Elements");
        type = c_.number<int>("$Elements");
      }
      if (type < 1 || type > 19 || !kNodesPerType[type])
        fail(path_, fmt::format("unknown element type {}", type));
      const int nn = kNodesPerType[type];
      const std::uint64_t k = c_.count<std::uint64_t>(
          binary_, binary_ ? std::size_t(8 * (1 + nn)) : std::size_t(2 * (1 + nn)), "$Elements");
      if (k > n - total)
        fail(path_, fmt::format("$Elements: blocks hold more than the {} elements announced", n));
      total += k;
      for (std::uint64_t e = 0; e < k; ++e) {
        binary_ ? c_.binary<std::uint64_t>("$Elements") : c_.number<std::uint64_t>("$Elements");
        std::uint64_t nodes[27];
        for (int j = 0; j < nn; ++j)
          nodes[j] = binary_ ? c_.binary<std::uint64_t>("$Elements") : c_.number<std::uint64_t>("$Elements");
        element(type, nodes, std::size_t(nn));
      }
    }
    if (total != n) fail(path_, fmt::format("$Elements: {} elements announced, {} in the blocks", n, total));
  }

  // False when the view is not the one asked for (skipped up to and with its end).
  bool node_data() {
    // String tags (the first is the view's name), real tags, integer tags (time step,
    // components, entries[, partition]), then the entries; the same in 2.2 and 4.1.
    const std::uint64_t ns = c_.count<std::uint64_t>(false, 2, "$NodeData");
    c_.line();
    std::string name;
    for (std::uint64_t i = 0; i < ns; ++i) {
      std::string s = c_.line();
      if (s.size() >= 2 && s.front() == '"' && s.back() == '"') s = s.substr(1, s.size() - 2);
      if (i == 0) name = s;
    }
    const std::uint64_t nr = c_.count<std::uint64_t>(false, 2, "$NodeData");
    for (std::uint64_t i = 0; i < nr; ++i) c_.number<double>("$NodeData");
    const std::uint64_t ni = c_.count<std::uint64_t>(false, 2, "$NodeData");
    if (ni < 3) fail(path_, "$NodeData: fewer than 3 integer tags");
    long long ints[3];
    for (std::uint64_t i = 0; i < ni; ++i) {
      const long long v = c_.number<long long>("$NodeData");
      if (i < 3) ints[i] = v;
    }
    const long long components = ints[1], entries = ints[2];
    const bool wanted = components == 1 && (options_.array_name.empty() || name == options_.array_name);
    if (!wanted || components < 1 || components > 9 || entries < 0) {
      c_.skip_section("NodeData");
      return false;
    }
    if (std::uint64_t(entries) > c_.remaining() / (binary_ ? 12 : 4))
      fail(path_,
           fmt::format("$NodeData: {} entries cannot fit in the bytes left (truncated file?)", entries));
    check_mesh_memory(path_, std::uint64_t(entries), 0, limit_);
    m_.data.reserve(std::size_t(entries));
    if (binary_) c_.line();
    for (long long i = 0; i < entries; ++i) {
      if (binary_) {
        const int tag = c_.binary<int>("$NodeData");
        const double v = c_.binary<double>("$NodeData");
        m_.data.emplace_back(tag < 0 ? ~std::uint64_t(0) : std::uint64_t(tag), v);
      } else {
        const auto tag = c_.number<std::uint64_t>("$NodeData");
        m_.data.emplace_back(tag, c_.number<double>("$NodeData"));
      }
    }
    m_.data_name = name;
    m_.have_data = true;
    return true;
  }

  TetMesh assemble() {
    // Node tags → node indices by sorting (tags may be sparse).
    std::vector<std::uint32_t> order(m_.node_tags.size());
    if (m_.node_tags.size() >= std::size_t(INT32_MAX)) fail(path_, "too many nodes");
    for (std::size_t i = 0; i < order.size(); ++i) order[i] = std::uint32_t(i);
    std::sort(order.begin(), order.end(),
              [&](std::uint32_t a, std::uint32_t b) { return m_.node_tags[a] < m_.node_tags[b]; });
    for (std::size_t i = 1; i < order.size(); ++i)
      if (m_.node_tags[order[i]] == m_.node_tags[order[i - 1]])
        fail(path_, fmt::format("node tag {} appears twice", m_.node_tags[order[i]]));
    const auto index_of = [&](std::uint64_t tag) -> std::int64_t {
      const auto it = std::lower_bound(order.begin(), order.end(), tag,
                                       [&](std::uint32_t a, std::uint64_t t) { return m_.node_tags[a] < t; });
      return it != order.end() && m_.node_tags[*it] == tag ? std::int64_t(*it) : -1;
    };
    // The points are the nodes the tetrahedra use, in node order.
    constexpr std::int32_t kUnused = -1;
    std::vector<std::int32_t> point(m_.node_tags.size(), kUnused);
    std::vector<std::array<std::int64_t, 4>> tets(m_.tets.size());
    for (std::size_t t = 0; t < m_.tets.size(); ++t)
      for (int k = 0; k < 4; ++k) {
        const std::int64_t i = index_of(m_.tets[t][k]);
        if (i < 0)
          fail(path_, fmt::format("tetrahedron {} refers to node tag {}, which is not in $Nodes", t,
                                  std::int64_t(m_.tets[t][k])));
        tets[t][k] = i;
        point[std::size_t(i)] = 0;
      }
    TetMesh m;
    for (std::size_t i = 0; i < point.size(); ++i)
      if (point[i] != kUnused) {
        point[i] = std::int32_t(m.points.size());
        m.points.push_back(m_.xyz[i]);
      }
    m.tets.resize(tets.size());
    for (std::size_t t = 0; t < tets.size(); ++t)
      for (int k = 0; k < 4; ++k) m.tets[t][k] = point[std::size_t(tets[t][k])];
    std::vector<char> have(m.points.size(), 0);
    m.values.assign(m.points.size(), 0.0);
    for (const auto& [tag, v] : m_.data) {
      const std::int64_t i = index_of(tag);
      if (i < 0) fail(path_, fmt::format("$NodeData: node tag {} is not in $Nodes", std::int64_t(tag)));
      if (point[std::size_t(i)] == kUnused) continue;
      m.values[std::size_t(point[std::size_t(i)])] = v;
      have[std::size_t(point[std::size_t(i)])] = 1;
    }
    for (std::size_t i = 0; i < point.size(); ++i)
      if (point[i] != kUnused && !have[std::size_t(point[i])])
        fail(path_,
             fmt::format("$NodeData '{}' has no value for node tag {}", m_.data_name, m_.node_tags[i]));
    m.value_name = m_.data_name;
    m.source = path_;
    return m;
  }

  const std::string& path_;
  Cursor c_;
  const TetMeshReadOptions& options_;
  std::uint64_t limit_;
  Msh m_;
  bool v4_ = false, binary_ = false;
};

}  // namespace

TetMesh read_msh(const std::string& path, const std::string& data, const TetMeshReadOptions& options,
                 std::uint64_t memory_limit) {
  return Reader(path, data, options, memory_limit).read();
}

}  // namespace mlfe::tet_mesh_detail
