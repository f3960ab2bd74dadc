// formats/asset_reader: every format write_asset writes reads back, with and without Draco,
// within the encoding's quantization: names, colours, labels and LODs of glTF nodes, the Draco
// grid as the file states it, and the scan frame as the inverse of the glTF writer's.
#include <gtest/gtest.h>
#include <mlfe/core/base/error.h>
#include <mlfe/formats/asset_reader.h>
#include <mlfe/formats/asset_writer.h>
#include <mlfe/formats/draco_io.h>

#include <cmath>
#include <string>
#include <vector>

#include "tests/test_meshes.h"

namespace mlfe {
namespace {

std::string tmp(const std::string& name) { return test::scratch_dir() + "/asset_reader_" + name; }

/// Two structures in millimetres, as a label map's asset holds them: named, coloured, labelled.
std::vector<GltfSurface> two_structures() {
  GltfSurface a, b;
  a.mesh = test::icosphere(3, 20.0f, {10.0f, -5.0f, 30.0f});
  b.mesh = test::icosphere(2, 8.0f, {-25.0f, 12.0f, 4.0f});
  a.node_name = a.name = "skull";
  b.node_name = b.name = "ventricle";
  a.color = {0.9f, 0.85f, 0.7f, 1.0f};
  b.color = {0.2f, 0.4f, 0.9f, 0.5f};
  a.node_extras = {{"label", 3}};
  b.node_extras = {{"label", 7}};
  return {a, b};
}

/// Every triangle of `read` lies within `tol` per coordinate of a triangle of `written`, corner by
/// corner, and the counts agree.
void expect_same_triangles(const TriangleMesh& written, const TriangleMesh& read, double tol,
                           const std::string& what) {
  EXPECT_EQ(read.triangles.size(), written.triangles.size()) << what;
  EXPECT_EQ(test::unmatched_triangles(written, read, tol), 0u) << what;
}

TEST(AssetReader, EveryFormatReadsBackWithinItsEncoding) {
  const std::vector<GltfSurface> surfaces = two_structures();
  const double tolerance_mm = 0.05;
  struct Case {
    std::string name;
    bool draco, quantize;
  };
  const std::vector<Case> cases = {{"d.glb", true, false},  {"p.glb", false, false},  {"q.glb", false, true},
                                   {"d.gltf", true, false}, {"p.gltf", false, false}, {"m.drc", true, false},
                                   {"m.ply", false, false}, {"m.obj", false, false},  {"m.stl", false, false},
                                   {"m.off", false, false}};
  for (const Case& c : cases) {
    const std::string path = tmp(c.name);
    write_asset(surfaces, path, {c.draco, c.quantize, tolerance_mm, "RAS", {{"input", "head.nii"}}});
    AssetFile a = read_asset(path);
    EXPECT_EQ(a.format, c.name.substr(2)) << c.name;
    const bool gltf = a.format == "glb" || a.format == "gltf";
    ASSERT_EQ(a.gltf_frame, gltf) << c.name;
    to_scan_frame(a);
    EXPECT_FALSE(a.gltf_frame);
    // Float formats keep float precision (a little more through glTF's metres); STL and OBJ as well.
    const double tol = c.draco || c.quantize ? tolerance_mm * 1.001 : 1e-4;
    if (!gltf) {
      ASSERT_EQ(a.surfaces.size(), 1u) << c.name;
      expect_same_triangles(merged_mesh(surfaces), a.surfaces[0].mesh, tol, c.name);
      EXPECT_EQ(a.quantization_steps[0] > 0, c.draco) << c.name;
      continue;
    }
    ASSERT_EQ(a.surfaces.size(), 2u) << c.name;
    EXPECT_EQ(a.space, "RAS");
    EXPECT_EQ(a.extras, nlohmann::json({{"input", "head.nii"}})) << c.name;
    EXPECT_DOUBLE_EQ(a.tolerance_mm, tolerance_mm) << c.name;
    for (std::size_t s = 0; s < 2; ++s) {
      const GltfSurface &w = surfaces[s], &r = a.surfaces[s];
      EXPECT_EQ(r.node_name, w.node_name);
      EXPECT_EQ(r.name, w.name);
      EXPECT_EQ(r.node_extras, w.node_extras) << c.name;
      for (int k = 0; k < 4; ++k) EXPECT_NEAR(r.color[k], w.color[k], 1e-6);
      expect_same_triangles(w.mesh, r.mesh, tol, c.name + " " + w.name);
      ASSERT_EQ(r.mesh.normals.size(), r.mesh.positions.size());
      // Draco's grid step, in millimetres after to_scan_frame: at most twice the tolerance asked.
      EXPECT_EQ(a.quantization_steps[s] > 0, c.draco) << c.name;
      EXPECT_LE(a.quantization_steps[s], 2 * tolerance_mm * 1.001) << c.name;
    }
  }
}

TEST(AssetReader, DracoGridIsTheEncodersGrid) {
  const TriangleMesh m = test::icosphere(2, 5.0f, {1.0f, 2.0f, 3.0f});
  DracoOptions o;
  o.tolerance = 0.01;
  o.box_min = {-10.0f, -10.0f, -10.0f};
  o.box_range = 30.0f;
  const DracoEncoding e = encode_draco_verified(m, o);
  DracoQuantization q;
  const TriangleMesh d = decode_draco(e.bytes.data(), e.bytes.size(), "test", &q);
  EXPECT_EQ(q.bits, e.quantization_bits);
  EXPECT_EQ(q.min, o.box_min);
  EXPECT_EQ(q.range, o.box_range);
  EXPECT_DOUBLE_EQ(q.step(), 30.0 / double((1u << q.bits) - 1));
  EXPECT_EQ(d.positions, e.decoded.positions);
  EXPECT_EQ(DracoQuantization{}.step(), 0.0);
}

TEST(AssetReader, LodsEmptySurfacesAndIsoValuesComeBack) {
  GltfSurface iso, empty;
  iso.iso_value = 80.0;
  iso.mesh = test::icosphere(3, 20.0f);
  iso.lods = {test::icosphere(2, 20.0f), test::icosphere(1, 20.0f)};
  empty.iso_value = 150.0;
  for (const bool quantize : {false, true}) {
    const std::string path = tmp(quantize ? "lods_q.glb" : "lods.glb");
    write_asset({iso, empty}, path, {false, quantize, 0.01, "", {}});
    const AssetFile a = read_asset(path);
    // The quantized file's root node "mlfe dequantize" is a transform, not a surface.
    ASSERT_EQ(a.surfaces.size(), 2u) << path;
    EXPECT_EQ(a.surfaces[0].node_name, "iso 80");
    EXPECT_EQ(a.surfaces[0].iso_value, 80.0);
    EXPECT_TRUE(a.surfaces[0].node_extras.is_null());
    ASSERT_EQ(a.surfaces[0].lods.size(), 2u);
    EXPECT_EQ(a.surfaces[0].lods[1].triangles.size(), iso.lods[1].triangles.size());
    // In metres like the full level: the quantized levels are dequantized by the root as well.
    float radius = 0;
    for (const auto& p : a.surfaces[0].lods[1].positions)
      radius = std::max(radius, std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]));
    EXPECT_NEAR(radius, 0.020f, 1e-4f) << path;
    EXPECT_EQ(a.surfaces[1].iso_value, 150.0);
    EXPECT_TRUE(a.surfaces[1].mesh.triangles.empty());
    EXPECT_EQ(a.space, "");
  }
}

TEST(AssetReader, ScanFrameIsTheInverseOfTheWriters) {
  GltfSurface s;
  s.mesh = test::icosphere(2, 10.0f, {5.0f, -3.0f, 40.0f});
  for (const std::string space : {"RAS", "LPS"}) {
    const std::string path = tmp("frame_" + space + ".gltf");
    write_asset({s}, path, {false, false, 0.01, space, {}});
    AssetFile a = read_asset(path);
    EXPECT_EQ(a.space, space);
    EXPECT_EQ(a.physical_to_gltf, physical_to_gltf_matrix(space));
    // In glTF: metres, superior up (+Y).
    const auto& top = a.surfaces[0].mesh.positions;
    float y_max = -1e9f;
    for (const auto& p : top) y_max = std::max(y_max, p[1]);
    EXPECT_NEAR(y_max, 0.050f, 1e-6f) << space;
    to_scan_frame(a);
    const TriangleMesh& back = a.surfaces[0].mesh;
    ASSERT_EQ(back.positions.size(), s.mesh.positions.size());
    for (std::size_t v = 0; v < back.positions.size(); ++v)
      for (int k = 0; k < 3; ++k) {
        EXPECT_NEAR(back.positions[v][k], s.mesh.positions[v][k], 1e-4) << space;
        EXPECT_NEAR(back.normals[v][k], s.mesh.normals[v][k], 1e-5) << space;
      }
    EXPECT_EQ(back.triangles, s.mesh.triangles);
  }
}

TEST(AssetReader, OtherFilesAndDamagedRecordsThrowNamingTheFile) {
  const std::string text = tmp("notes.txt");
  test::write_bytes(text, "not a mesh");
  try {
    read_asset(text);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(std::string(e.what()),
              text + ": not a mesh file (expected .glb, .gltf, .drc, .ply, .obj, .stl or .off)");
  }
  // A physical_to_gltf record that cannot be inverted cannot give the scan frame.
  const std::string gltf = tmp("singular.gltf");
  write_asset(two_structures(), gltf, {false, false, 0.01, "RAS", {}});
  std::string json = test::read_bytes(gltf);
  const std::string record = "\"physical_to_gltf\"";
  const auto at = json.find(record);
  ASSERT_NE(at, std::string::npos);
  const auto open = json.find('[', at), close = json.find(']', at);
  json.replace(open, close - open + 1, "[0,0,0,0,0,0,0,0,0]");
  test::write_bytes(gltf, json);
  EXPECT_THROW(read_asset(gltf), Error);
}

}  // namespace
}  // namespace mlfe
