// formats/gltf_reader: geometry back from mlfe's own .glb/.gltf (Draco, plain, quantized), node
// transforms applied (a mirroring one flips the winding), and bad files end in mlfe::Error.
#include <gtest/gtest.h>
#include <mlfe/core/base/error.h>
#include <mlfe/formats/gltf_reader.h>
#include <mlfe/formats/gltf_writer.h>

#include <cmath>
#include <fstream>
#include <random>

#include "tests/test_meshes.h"

namespace mlfe {
namespace {

std::string tmp(const std::string& name) { return test::scratch_dir() + "/gltf_reader_" + name; }

TEST(GltfReader, ReadsEveryEncodingBackInMetres) {
  GltfSurface s;
  s.iso_value = 2;
  s.mesh = test::icosphere(2, 10.0f, {100.0f, 0.0f, 0.0f});  // millimetres, RAS
  int i = 0;
  for (const bool draco : {true, false})
    for (const bool quantize : {false, true}) {
      if (draco && quantize) continue;
      GltfOptions o;
      o.draco = draco;
      o.quantize = quantize;
      o.tolerance_mm = 0.01;
      const std::string path = tmp("enc" + std::to_string(i++) + ".glb");
      write_gltf(path, {s}, o);
      const GltfAsset a = read_gltf(path);
      ASSERT_EQ(a.primitives.size(), 1u);
      const TriangleMesh& m = a.primitives[0].mesh_data;
      EXPECT_EQ(m.triangle_count(), s.mesh.triangle_count());
      ASSERT_EQ(m.normals.size(), m.positions.size());
      // RAS x = 100 mm becomes glTF x = -0.1 m; every vertex 10 mm from the centre.
      for (const auto& p : m.positions) {
        const double r = std::sqrt((p[0] + 0.1) * (p[0] + 0.1) + p[1] * p[1] + p[2] * p[2]);
        EXPECT_NEAR(r, 0.01, 2e-5) << "draco " << draco << " quantize " << quantize;
      }
      // The compression extensions are encoding, not structure.
      EXPECT_FALSE(a.structure.contains("accessors"));
      EXPECT_FALSE(a.structure.dump().find("KHR_draco_mesh_compression") != std::string::npos);
      // Quantized files add a root node "mlfe dequantize" above the surface's node.
      EXPECT_EQ(a.structure["nodes"][quantize ? 1 : 0]["name"], "iso 2") << a.structure["nodes"].dump();
    }
}

TEST(GltfReader, AppliesNodeTransformsAndFlipsWindingForMirrors) {
  // One triangle in a hand-written .gltf, under a parent that translates and a child that
  // mirrors x.
  const std::string path = tmp("nodes.gltf");
  std::ofstream(path) << R"({"asset": {"version": "2.0"},
    "buffers": [{"byteLength": 42, "uri": "data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAAAAABAAIA"}],
    "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36}, {"buffer": 0, "byteOffset": 36, "byteLength": 6}],
    "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0,0,0], "max": [1,1,0]},
                  {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}],
    "meshes": [{"name": "tri", "primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
    "nodes": [{"name": "child", "mesh": 0, "scale": [-1, 1, 1]}, {"name": "parent", "children": [0], "translation": [5, 0, 0]}],
    "scenes": [{"nodes": [1]}], "scene": 0})";
  const GltfAsset a = read_gltf(path);
  ASSERT_EQ(a.primitives.size(), 1u);
  const TriangleMesh& m = a.primitives[0].mesh_data;
  ASSERT_EQ(m.positions.size(), 3u);
  EXPECT_FLOAT_EQ(m.positions[0][0], 5.0f);
  EXPECT_FLOAT_EQ(m.positions[1][0], 4.0f);  // (1, 0, 0) mirrored, then moved by 5
  EXPECT_FLOAT_EQ(m.positions[2][1], 1.0f);
  EXPECT_EQ(m.triangles[0], (std::array<std::uint32_t, 3>{0, 2, 1}));
  EXPECT_EQ(a.primitives[0].label, "node 0 'child' mesh 'tri' primitive 0");
  EXPECT_FALSE(a.structure["nodes"][0].contains("scale"));
}

TEST(GltfReader, TruncatedAndCorruptedFilesThrowError) {
  GltfSurface s;
  s.mesh = test::icosphere(1, 10.0f);
  const std::string good = tmp("good.glb");
  write_gltf(good, {s}, {});
  const std::string bytes = test::read_bytes(good);
  std::mt19937 rng(11);
  const std::string bad = tmp("bad.glb");
  int errors = 0, reads = 0;
  for (int trial = 0; trial < 300; ++trial) {
    std::string b = bytes;
    if (trial < 100) {
      b.resize(bytes.size() * std::size_t(trial) / 100);
    } else {
      for (int k = 0; k < 1 + trial % 4; ++k) b[rng() % b.size()] = char(rng());
    }
    std::ofstream(bad, std::ios::binary | std::ios::trunc).write(b.data(), std::streamsize(b.size()));
    try {
      read_gltf(bad);
      ++reads;
    } catch (const Error& e) {
      ++errors;
      EXPECT_NE(std::string(e.what()).find(bad), std::string::npos);
    }
  }
  EXPECT_GE(errors, 100);  // at least every truncation
  EXPECT_THROW(read_gltf(tmp("missing.glb")), Error);
}

}  // namespace
}  // namespace mlfe
