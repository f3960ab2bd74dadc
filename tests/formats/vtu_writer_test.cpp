#include <gtest/gtest.h>
#include <mlfe/core/base/error.h>
#include <mlfe/formats/vtu_writer.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <regex>
#include <string>

#include "tests/test_paths.h"

namespace mlfe {
namespace {

namespace fs = std::filesystem;

fs::path temp_file(const std::string& name) { return fs::path(mlfe::test::scratch_dir("vtu_writer")) / name; }

std::string read_all(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

// A minimal reader for what write_vtu produces: parses the XML header with regexes, then the
// appended blocks (UInt64 byte count + data) at the offsets the XML names.
struct ParsedVtu {
  std::size_t points = 0, cells = 0;
  std::map<std::string, std::string> type_of;  // array name -> VTK type
  std::map<std::string, std::string> data_of;  // array name -> raw bytes
  std::map<std::string, int> components_of;

  template <class T>
  std::vector<T> get(const std::string& name) const {
    const std::string& s = data_of.at(name);
    std::vector<T> v(s.size() / sizeof(T));
    std::memcpy(v.data(), s.data(), v.size() * sizeof(T));
    return v;
  }
};

ParsedVtu parse_vtu(const std::string& file) {
  ParsedVtu out;
  const std::size_t underscore = file.find("<AppendedData encoding=\"raw\">");
  EXPECT_NE(underscore, std::string::npos);
  const std::size_t data_start = file.find('_', underscore) + 1;
  const std::string xml = file.substr(0, underscore);
  EXPECT_NE(xml.find("header_type=\"UInt64\""), std::string::npos);
  EXPECT_NE(xml.find("byte_order=\"LittleEndian\""), std::string::npos);
  std::smatch m;
  EXPECT_TRUE(std::regex_search(xml, m, std::regex(R"re(NumberOfPoints="(\d+)" NumberOfCells="(\d+)")re")));
  out.points = std::stoul(m[1]);
  out.cells = std::stoul(m[2]);
  const std::regex array(
      R"re(<DataArray type="(\w+)" Name="(\w+)"(?: NumberOfComponents="(\d+)")? format="appended" offset="(\d+)"/>)re");
  std::uint64_t expected_offset = 0;
  for (auto it = std::sregex_iterator(xml.begin(), xml.end(), array); it != std::sregex_iterator(); ++it) {
    const auto& a = *it;
    const std::uint64_t offset = std::stoull(a[4]);
    EXPECT_EQ(offset, expected_offset) << "blocks must be back to back in document order";
    std::uint64_t bytes = 0;
    EXPECT_LE(data_start + offset + 8, file.size());
    std::memcpy(&bytes, file.data() + data_start + offset, 8);
    EXPECT_LE(data_start + offset + 8 + bytes, file.size());
    out.type_of[a[2]] = a[1];
    out.components_of[a[2]] = a[3].matched ? std::stoi(a[3]) : 1;
    out.data_of[a[2]] = file.substr(data_start + offset + 8, bytes);
    expected_offset = offset + 8 + bytes;
  }
  const std::string tail = "\n  </AppendedData>\n</VTKFile>\n";
  EXPECT_EQ(file.size(), data_start + expected_offset + tail.size());
  EXPECT_EQ(file.substr(file.size() - tail.size()), tail);
  return out;
}

Hierarchy<3> refined_box() {
  Hierarchy<3> h = Hierarchy<3>::box({0, 0, 0}, {1, 2, 3});
  h.refine_uniform();
  std::vector<ElemId> marked;
  for (ElemId e : h.leaves())
    if (h.cell(e)[0] == VertexId(0)) marked.push_back(e);  // local refinement: adds greens
  h.refine(marked);
  return h;
}

TEST(VtuWriter, WritesCountsOffsetsTypesAndCellDataThatParseBack) {
  const Hierarchy<3> h = refined_box();
  const auto leaves = h.leaves();
  std::vector<double> u;
  for (const auto& p : h.points()) u.push_back(p[0] + 10 * p[1] + 100 * p[2]);
  const fs::path path = temp_file("leaves.vtu");
  write_vtu<3>(path.string(), h, leaves, &u, nullptr);
  const ParsedVtu v = parse_vtu(read_all(path));
  EXPECT_EQ(v.points, h.vertex_count());  // every vertex is used by some leaf
  EXPECT_EQ(v.cells, leaves.size());
  EXPECT_EQ(v.type_of.at("u"), "Float64");
  EXPECT_EQ(v.type_of.at("Points"), "Float64");
  EXPECT_EQ(v.components_of.at("Points"), 3);
  EXPECT_EQ(v.type_of.at("connectivity"), "Int64");
  EXPECT_EQ(v.type_of.at("level"), "UInt8");
  EXPECT_EQ(v.type_of.at("kind"), "UInt8");
  const auto points = v.get<double>("Points");
  const auto conn = v.get<std::int64_t>("connectivity");
  const auto offsets = v.get<std::int64_t>("offsets");
  const auto types = v.get<std::uint8_t>("types");
  const auto level = v.get<std::uint8_t>("level");
  const auto kind = v.get<std::uint8_t>("kind");
  const auto values = v.get<double>("u");
  ASSERT_EQ(points.size(), 3 * v.points);
  ASSERT_EQ(conn.size(), 4 * v.cells);
  ASSERT_EQ(offsets.size(), v.cells);
  ASSERT_EQ(types.size(), v.cells);
  ASSERT_EQ(level.size(), v.cells);
  ASSERT_EQ(kind.size(), v.cells);
  ASSERT_EQ(values.size(), v.points);
  bool green = false;
  for (std::size_t i = 0; i < v.cells; ++i) {
    EXPECT_EQ(offsets[i], static_cast<std::int64_t>(4 * (i + 1)));
    EXPECT_EQ(types[i], 10);
    EXPECT_EQ(level[i], h.level(leaves[i]));
    EXPECT_EQ(kind[i], static_cast<int>(h.kind(leaves[i])));
    green |= kind[i] == 2;
    for (int k = 0; k < 4; ++k) {
      // With all vertices used, compact ids equal VertexIds; the writer may swap two corners
      // so that every tetrahedron is positively oriented (issue #25).
      const std::int64_t c = conn[4 * i + k];
      const auto& cell = h.cell(leaves[i]);
      ASSERT_TRUE(std::any_of(cell.begin(), cell.end(),
                              [&](VertexId v) { return static_cast<std::int64_t>(v.value) == c; }));
      const auto& p = h.point(VertexId(static_cast<std::uint32_t>(c)));
      for (int a = 0; a < 3; ++a) EXPECT_EQ(points[3 * c + a], p[a]);
      EXPECT_EQ(values[c], u[c]);
    }
  }
  EXPECT_TRUE(green);
}

TEST(VtuWriter, WritesOnlyTheUsedVerticesOfALevelAndAppliesTheTransform) {
  const Hierarchy<3> h = refined_box();
  const auto coarse = h.level_elements(0);
  GridTransform t;
  t.spacing = {2, 2, 2};  // local_to_physical ignores spacing: local is already index .* spacing
  t.origin = {10, 20, 30};
  t.direction = {0, -1, 0, 1, 0, 0, 0, 0, 1};  // 90° about z
  const fs::path path = temp_file("coarse.vtu");
  write_vtu<3>(path.string(), h, coarse, nullptr, &t);
  const std::string file = read_all(path);
  const ParsedVtu v = parse_vtu(file);
  EXPECT_EQ(v.points, 8u);
  EXPECT_EQ(v.cells, 6u);
  EXPECT_EQ(v.data_of.count("u"), 0u);
  const auto points = v.get<double>("Points");
  for (int c = 0; c < 8; ++c) {
    const auto q =
        t.local_to_physical({h.point(VertexId(c))[0], h.point(VertexId(c))[1], h.point(VertexId(c))[2]});
    for (int a = 0; a < 3; ++a) EXPECT_DOUBLE_EQ(points[3 * c + a], q[a]);
  }
}

TEST(VtuWriter, Writes2DTrianglesWithZeroZ) {
  Hierarchy<2> h = Hierarchy<2>::box({0, 0}, {4, 3});
  h.refine_uniform();
  const fs::path path = temp_file("tri.vtu");
  write_vtu<2>(path.string(), h, h.leaves(), nullptr, nullptr);
  const ParsedVtu v = parse_vtu(read_all(path));
  EXPECT_EQ(v.cells, 8u);
  for (auto t : v.get<std::uint8_t>("types")) EXPECT_EQ(t, 5);
  const auto points = v.get<double>("Points");
  for (std::size_t i = 0; i < v.points; ++i) EXPECT_EQ(points[3 * i + 2], 0.0);
  EXPECT_EQ(v.get<std::int64_t>("offsets").back(), 24);
}

TEST(VtuWriter, IsDeterministicForEqualHierarchies) {
  const Hierarchy<3> h = refined_box();
  const fs::path a = temp_file("det_a.vtu"), b = temp_file("det_b.vtu");
  write_vtu<3>(a.string(), h, h.leaves(), nullptr, nullptr);
  write_vtu<3>(b.string(), refined_box(), h.leaves(), nullptr, nullptr);
  EXPECT_EQ(read_all(a), read_all(b));
}

TEST(VtuWriter, RejectsBadArgumentsWithoutLeavingAFile) {
  const Hierarchy<3> h = refined_box();
  const fs::path path = temp_file("bad.vtu");
  fs::remove(path);
  std::vector<double> short_values(h.vertex_count() - 1, 0.0);
  EXPECT_THROW(write_vtu<3>(path.string(), h, h.leaves(), &short_values, nullptr), Error);
  EXPECT_THROW(write_vtu<3>(path.string(), h, {ElemId(static_cast<std::uint32_t>(h.element_count()))},
                            nullptr, nullptr),
               Error);
  EXPECT_FALSE(fs::exists(path));
  EXPECT_THROW(write_vtu<3>((temp_file("no_such_dir") / "x.vtu").string(), h, h.leaves(), nullptr, nullptr),
               Error);
}

// VTK's own reader, when python3-vtk9 is installed (it is optional: a bench-only package).
TEST(VtuWriter, ReadsBackWithVtkWhenAvailable) {
  if (std::system("/usr/bin/python3 -c 'import vtk' > /dev/null 2>&1") != 0)
    GTEST_SKIP() << "python3-vtk9 not installed";
  const Hierarchy<3> h = refined_box();
  std::vector<double> u(h.vertex_count(), 1.5);
  const fs::path path = temp_file("vtk.vtu");
  write_vtu<3>(path.string(), h, h.leaves(), &u, nullptr);
  const std::string cmd =
      "/usr/bin/python3 -c \"import vtk,sys; r=vtk.vtkXMLUnstructuredGridReader(); r.SetFileName('" +
      path.string() + "'); r.Update(); g=r.GetOutput(); sys.exit(0 if g.GetNumberOfCells()==" +
      std::to_string(h.leaves().size()) + " and g.GetNumberOfPoints()==" + std::to_string(h.vertex_count()) +
      " and g.GetPointData().GetArray('u').GetValue(0)==1.5 "
      "else 1)\"";
  EXPECT_EQ(std::system(cmd.c_str()), 0) << cmd;
}

}  // namespace
}  // namespace mlfe
