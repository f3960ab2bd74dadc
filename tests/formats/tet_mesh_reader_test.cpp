#include <gtest/gtest.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/mesh/hierarchy.h>
#include <mlfe/formats/msh_writer.h>
#include <mlfe/formats/tet_mesh_reader.h>
#include <mlfe/formats/vtu_writer.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>

#include "tests/test_meshes.h"
#include "tests/test_paths.h"
#include "tests/tet_meshes.h"

namespace mlfe {
namespace {

using test::read_bytes;
using test::write_bytes;

namespace fs = std::filesystem;
using V3 = std::array<double, 3>;

std::string scratch(const std::string& name) { return test::scratch_dir("tet_mesh_reader") + "/" + name; }

double f(const V3& p) { return 0.25 + p[0] * p[0] - 2 * p[1] + std::sin(p[2]); }

// A hierarchy refined twice over [0,1]x[0,2]x[0,1], its values, and the frame it is written in.
struct Written {
  Hierarchy<3> h = Hierarchy<3>::box({0, 0, 0}, {1, 2, 1});
  std::vector<double> values;
  GridTransform t;
  Written() {
    h.refine_uniform();
    h.refine_uniform();
    t.origin = {10, -5, 3};
    for (std::size_t v = 0; v < h.vertex_count(); ++v) {
      const auto& p = h.point(VertexId(std::uint32_t(v)));
      values.push_back(f(t.local_to_physical({p[0], p[1], p[2]})));
    }
  }
};

// The mesh read back is the written one: points (in vertex order), the same vertex set per
// tetrahedron, the values.
void expect_same(const Written& w, const TetMesh& m) {
  const auto leaves = w.h.leaves();
  ASSERT_EQ(m.points.size(), w.h.vertex_count());
  ASSERT_EQ(m.tets.size(), leaves.size());
  for (std::size_t v = 0; v < m.points.size(); ++v) {
    const auto& p = w.h.point(VertexId(std::uint32_t(v)));
    const V3 q = w.t.local_to_physical({p[0], p[1], p[2]});
    for (int a = 0; a < 3; ++a) ASSERT_NEAR(m.points[v][a], q[a], 1e-6);  // Float32 copies too
    ASSERT_NEAR(m.values[v], w.values[v], 1e-6 * (1 + std::abs(w.values[v])));
  }
  for (std::size_t e = 0; e < leaves.size(); ++e) {
    std::array<std::int32_t, 4> a = m.tets[e], b;
    for (int k = 0; k < 4; ++k) b[k] = std::int32_t(w.h.cell(leaves[e])[k].value);
    std::sort(a.begin(), a.end());
    std::sort(b.begin(), b.end());
    ASSERT_EQ(a, b) << "tetrahedron " << e;
  }
}

void expect_error(const std::string& path, const std::string& part, const TetMeshReadOptions& options = {}) {
  try {
    read_tet_mesh(path, options);
    FAIL() << path << " was accepted";
  } catch (const Error& e) {
    const std::string msg = e.what();
    EXPECT_EQ(msg.rfind(path + ": ", 0), 0u) << msg;
    EXPECT_NE(msg.find(part), std::string::npos) << msg;
    EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
  }
}

TEST(TetMeshReader, ReadsWhatTheVtuWriterWrites) {
  const Written w;
  const std::string p = scratch("round.vtu");
  write_vtu(p, w.h, w.h.leaves(), &w.values, &w.t);
  EXPECT_EQ(detect_tet_mesh_format(p), "vtu");
  const TetMesh m = read_tet_mesh(p);
  expect_same(w, m);
  EXPECT_EQ(m.value_name, "u");
  EXPECT_EQ(m.source, p);
}

TEST(TetMeshReader, ReadsWhatTheMshWriterWrites) {
  const Written w;
  const std::string p = scratch("round.msh");
  write_msh(p, w.h, w.h.leaves(), &w.values, &w.t);
  EXPECT_EQ(detect_tet_mesh_format(p), "msh");
  expect_same(w, read_tet_mesh(p));
}

// The formats VTK's own writer produces (python3-vtk9, a bench/test-only package).
TEST(TetMeshReader, ReadsEveryEncodingVtkWrites) {
  if (std::system("/usr/bin/python3 -c 'import vtk' > /dev/null 2>&1") != 0)
    GTEST_SKIP() << "python3-vtk9 not installed";
  const Written w;
  const std::string src = scratch("vtk_src.vtu"), dir = test::scratch_dir("tet_mesh_reader/vtk");
  write_vtu(src, w.h, w.h.leaves(), &w.values, &w.t);
  const std::string list = scratch("variants.txt");
  const std::string cmd = "/usr/bin/python3 " + std::string(MLFE_SOURCE_DIR) +
                          "/tests/formats/write_vtu_variants.py " + src + " " + dir + " > " + list;
  ASSERT_EQ(std::system(cmd.c_str()), 0);
  std::istringstream files(read_bytes(list));
  int n = 0;
  for (std::string file; std::getline(files, file); ++n) {
    SCOPED_TRACE(file);
    const TetMesh m = read_tet_mesh(file);  // default: the first scalar array, "u" ("vec" has 3)
    EXPECT_EQ(m.value_name, "u");
    expect_same(w, m);
    TetMeshReadOptions o;
    o.array_name = "u32";
    const TetMesh m32 = read_tet_mesh(file, o);
    for (std::size_t i = 0; i < m.values.size(); ++i) ASSERT_EQ(m32.values[i], double(float(m.values[i])));
    o.array_name = "vec";
    expect_error(file, "has 3 components", o);
  }
  EXPECT_EQ(n, 13);  // ascii + 3 encodings x 2 compressions x 2 header types
}

// A small mesh written by hand in the MSH variants the writer does not produce: 2.2 ASCII and
// binary, 4.1 binary, with points, lines and triangles to skip and sparse node tags.
std::string msh(const std::string& version, bool binary, const TetMesh& m) {
  std::string s = "$MeshFormat\n" + version + (binary ? " 1 8\n" : " 0 8\n");
  const auto raw = [&](auto v) { s.append(reinterpret_cast<const char*>(&v), sizeof(v)); };
  if (binary) {
    raw(int(1));
    s += "\n";
  }
  s += "$EndMeshFormat\n$PhysicalNames\n1\n3 1 \"vol\"\n$EndPhysicalNames\n";
  const std::size_t n = m.points.size(), t = m.tets.size();
  const auto tag = [](std::size_t i) { return 3 * i + 7; };  // sparse
  const auto num = [](double v) {
    char b[40];
    std::snprintf(b, sizeof b, "%.17g", v);
    return std::string(b);
  };
  s += "$Nodes\n";
  if (version == "2.2") {
    s += std::to_string(n) + "\n";
    for (std::size_t i = 0; i < n; ++i) {
      if (binary) {
        raw(int(tag(i)));
        for (double c : m.points[i]) raw(c);
      } else {
        s += std::to_string(tag(i)) + " " + num(m.points[i][0]) + " " + num(m.points[i][1]) + " " +
             num(m.points[i][2]) + "\n";
      }
    }
    if (binary) s += "\n";
    s += "$EndNodes\n$Elements\n" + std::to_string(t + 2) + "\n";
    if (binary) {
      for (int h : {15, 1, 2}) raw(h);  // one point element, 2 tags
      for (int v : {1, 0, 0, int(tag(0))}) raw(v);
      for (int h : {1, 1, 2}) raw(h);  // one line
      for (int v : {2, 0, 0, int(tag(0)), int(tag(1))}) raw(v);
      for (int h : {4, int(t), 2}) raw(h);
      for (std::size_t e = 0; e < t; ++e) {
        for (int v : {int(e + 3), 1, 1}) raw(v);
        for (int k = 0; k < 4; ++k) raw(int(tag(m.tets[e][k])));
      }
      s += "\n";
    } else {
      s += "1 15 2 0 0 " + std::to_string(tag(0)) + "\n";
      s += "2 1 2 0 0 " + std::to_string(tag(0)) + " " + std::to_string(tag(1)) + "\n";
      for (std::size_t e = 0; e < t; ++e) {
        s += std::to_string(e + 3) + " 4 2 1 1";
        for (int k = 0; k < 4; ++k) s += " " + std::to_string(tag(m.tets[e][k]));
        s += "\n";
      }
    }
    s += "$EndElements\n";
  } else {  // 4.1 binary: one node block, a triangle block and a tetrahedron block
    raw(std::size_t(1));
    raw(std::size_t(n));
    raw(std::size_t(tag(0)));
    raw(std::size_t(tag(n - 1)));
    for (int v : {3, 1, 0}) raw(v);
    raw(std::size_t(n));
    for (std::size_t i = 0; i < n; ++i) raw(std::size_t(tag(i)));
    for (std::size_t i = 0; i < n; ++i)
      for (double c : m.points[i]) raw(c);
    s += "\n$EndNodes\n$Elements\n";
    raw(std::size_t(2));
    raw(std::size_t(t + 1));
    raw(std::size_t(1));
    raw(std::size_t(t + 1));
    for (int v : {2, 1, 2}) raw(v);
    raw(std::size_t(1));
    for (std::size_t v : {std::size_t(1), tag(0), tag(1), tag(2)}) raw(v);
    for (int v : {3, 1, 4}) raw(v);
    raw(std::size_t(t));
    for (std::size_t e = 0; e < t; ++e) {
      raw(std::size_t(e + 2));
      for (int k = 0; k < 4; ++k) raw(std::size_t(tag(m.tets[e][k])));
    }
    s += "\n$EndElements\n";
  }
  // A 3-component view first (skipped), then the scalar one.
  for (int comps : {3, 1}) {
    s += "$NodeData\n1\n\"" + std::string(comps == 3 ? "velocity" : "temperature") + "\"\n1\n0.0\n3\n0\n" +
         std::to_string(comps) + "\n" + std::to_string(n) + "\n";
    for (std::size_t i = 0; i < n; ++i) {
      if (binary) {
        raw(int(tag(i)));
        for (int c = 0; c < comps; ++c) raw(m.values[i] + c);
      } else {
        s += std::to_string(tag(i));
        for (int c = 0; c < comps; ++c) s += " " + num(m.values[i] + c);
        s += "\n";
      }
    }
    if (binary) s += "\n";
    s += "$EndNodeData\n";
  }
  return s;
}

TEST(TetMeshReader, ReadsMsh22AsciiAndBinaryAndMsh41Binary) {
  const TetMesh m = test::kuhn_mesh(2, f);
  for (const auto& [version, binary] :
       {std::pair{"2.2", false}, std::pair{"2.2", true}, std::pair{"4.1", true}}) {
    const std::string p = scratch(std::string("hand_") + version + (binary ? "_bin" : "_ascii") + ".msh");
    write_bytes(p, msh(version, binary, m));
    SCOPED_TRACE(p);
    const TetMesh r = read_tet_mesh(p);
    EXPECT_EQ(r.value_name, "temperature");
    ASSERT_EQ(r.points.size(), m.points.size());
    ASSERT_EQ(r.tets, m.tets);
    EXPECT_EQ(r.points, m.points);
    EXPECT_EQ(r.values, m.values);
  }
}

TEST(TetMeshReader, ReadsTheBundledSeeds) {
  for (const char* name : {"small_tets_zlib_base64.vtu", "small_tets_raw.vtu", "small_tets_bin22.msh"}) {
    SCOPED_TRACE(name);
    const TetMesh m = read_tet_mesh(test::test_data_path(name));
    EXPECT_EQ(m.value_name, "u");
    EXPECT_EQ(m.tets.size(), 42u);  // 7 cubes of 6
    // .msh input keeps the nodes the tetrahedra use: not the far corner of the cube left out.
    EXPECT_EQ(m.points.size(), std::string(name).find(".msh") != std::string::npos ? 26u : 27u);
    for (std::size_t i = 0; i < m.points.size(); ++i) {
      const V3& p = m.points[i];
      EXPECT_NEAR(m.values[i], p[0] * p[0] - p[1] + 0.5 * p[2], 1e-12);
    }
    const TetMeshField f(m);
    EXPECT_TRUE(f.inside({0.25, 0.75, 0.75}));
    EXPECT_FALSE(f.inside({0.75, 0.75, 0.75}));  // the cube left out
  }
}

TEST(TetMeshReader, RejectsTruncatedFilesWithOneLineNamingTheFile) {
  const Written w;
  const std::string vtu = scratch("whole.vtu"), msh41 = scratch("whole.msh");
  write_vtu(vtu, w.h, w.h.leaves(), &w.values, &w.t);
  write_msh(msh41, w.h, w.h.leaves(), &w.values, &w.t);
  const TetMesh small = test::kuhn_mesh(2, f);
  const std::string bin22 = scratch("whole22.msh");
  write_bytes(bin22, msh("2.2", true, small));
  for (const std::string& whole : {vtu, msh41, bin22}) {
    const std::string bytes = read_bytes(whole);
    const std::string cut = scratch("cut" + fs::path(whole).extension().string());
    for (int i = 1; i < 40; ++i) {
      const std::size_t at = bytes.size() * std::size_t(i) / 40;
      // The .vtu's tail after the appended data is only closing tags the reader does not need.
      if (whole == vtu && at > bytes.size() - 40) continue;
      write_bytes(cut, bytes.substr(0, at));
      SCOPED_TRACE(whole + " cut at " + std::to_string(at));
      EXPECT_THROW(read_tet_mesh(cut), Error);
      try {
        read_tet_mesh(cut);
      } catch (const Error& e) {
        EXPECT_EQ(std::string(e.what()).rfind(cut + ": ", 0), 0u) << e.what();
      }
    }
  }
}

TEST(TetMeshReader, RejectsBadIndicesCellTypesAndValues) {
  const TetMesh m = test::kuhn_mesh(1, f);
  const auto ascii_vtu = [&](const std::string& conn, const std::string& types, const std::string& values) {
    std::string s =
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"1.0\">\n<UnstructuredGrid>\n"
        "<Piece NumberOfPoints=\"8\" NumberOfCells=\"6\">\n<PointData>\n"
        "<DataArray type=\"Float64\" Name=\"u\" format=\"ascii\">" +
        values +
        "</DataArray>\n</PointData>\n<Points>\n<DataArray type=\"Float64\" NumberOfComponents=\"3\" "
        "format=\"ascii\">";
    for (const auto& p : m.points)
      s += std::to_string(p[0]) + " " + std::to_string(p[1]) + " " + std::to_string(p[2]) + " ";
    s += "</DataArray>\n</Points>\n<Cells>\n<DataArray type=\"Int32\" Name=\"connectivity\" "
         "format=\"ascii\">" +
         conn +
         "</DataArray>\n<DataArray type=\"Int32\" Name=\"offsets\" format=\"ascii\">4 8 12 16 20 "
         "24</DataArray>\n"
         "<DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">" +
         types + "</DataArray>\n</Cells>\n</Piece>\n</UnstructuredGrid>\n</VTKFile>\n";
    return s;
  };
  std::string conn, values;
  for (const auto& t : m.tets)
    for (int v : t) conn += std::to_string(v) + " ";
  for (double v : m.values) values += std::to_string(v) + " ";
  const std::string good = scratch("good.vtu");
  write_bytes(good, ascii_vtu(conn, "10 10 10 10 10 10", values));
  EXPECT_EQ(read_tet_mesh(good).tets, m.tets);

  const std::string bad = scratch("bad.vtu");
  write_bytes(bad, ascii_vtu("99 " + conn.substr(2), "10 10 10 10 10 10", values));
  expect_error(bad, "point index 99 out of range");
  write_bytes(bad, ascii_vtu(conn, "10 10 12 10 10 10", values));
  expect_error(bad, "only tetrahedra (VTK type 10) are supported, found type 12");
  write_bytes(bad, ascii_vtu(conn, "10 10 10 10 10 10", "nan " + values.substr(values.find(' ') + 1)));
  expect_error(bad, "not a finite number");
  write_bytes(bad, ascii_vtu(conn, "10 10 10 10 10 10", "1 2 3"));
  expect_error(bad, "DataArray u: fewer than 8 values");
  write_bytes(bad, ascii_vtu(conn, "10 10 10 10 10 10", "1 2 3 4 5 6 7 x"));
  expect_error(bad, "DataArray u: value 7 is missing or not a number");
  write_bytes(bad, ascii_vtu(conn, "10 10 10 10 10 10", values).substr(0, 300));
  expect_error(bad, "XML error");

  // MSH: a hexahedron, a node that does not exist, no values.
  const std::string bm = scratch("bad.msh");
  const std::string head =
      "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n4\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n$EndNodes\n";
  const std::string data = "$NodeData\n1\n\"u\"\n1\n0\n3\n0\n1\n4\n1 1\n2 2\n3 3\n4 4\n$EndNodeData\n";
  write_bytes(bm, head + "$Elements\n1\n1 5 0 1 2 3 4 1 2 3 4\n$EndElements\n" + data);
  expect_error(bm, "only 4-node tetrahedra (element type 4) are supported, found type 5");
  write_bytes(bm, head + "$Elements\n1\n1 4 0 1 2 3 9\n$EndElements\n" + data);
  expect_error(bm, "node tag 9");
  write_bytes(bm, head + "$Elements\n1\n1 4 0 1 2 3 4\n$EndElements\n");
  expect_error(bm, "no scalar $NodeData");
  write_bytes(bm, head + "$Elements\n1\n1 4 0 1 2 3 4\n$EndElements\n" + data);
  EXPECT_EQ(read_tet_mesh(bm).values, (std::vector<double>{1, 2, 3, 4}));
  write_bytes(bm, "$MeshFormat\n3.0 0 8\n$EndMeshFormat\n");
  expect_error(bm, "MSH version 3.0 is not supported");
  // Counts far beyond the file.
  write_bytes(bm, "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n99999999999\n1 0 0 0\n$EndNodes\n");
  expect_error(bm, "cannot fit");
}

}  // namespace
}  // namespace mlfe
