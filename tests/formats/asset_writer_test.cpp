// write_asset: glTF keeps one node per surface, the single-mesh formats hold merged_mesh.
#include <gtest/gtest.h>
#include <mlfe/core/base/error.h>
#include <mlfe/formats/asset_writer.h>
#include <mlfe/formats/draco_io.h>
#include <mlfe/formats/gltf_reader.h>
#include <mlfe/formats/openmesh_io.h>

#include <string>
#include <vector>

#include "tests/test_meshes.h"

namespace mlfe {
namespace {

using test::icosphere;
using test::scratch_dir;

std::vector<GltfSurface> two_spheres() {
  std::vector<GltfSurface> s(2);
  s[0].iso_value = 1;
  s[0].mesh = icosphere(1, 10.0f);
  s[1].iso_value = 2;
  s[1].mesh = icosphere(2, 5.0f, {30, 0, 0});
  return s;
}

TEST(WriteAsset, GltfHasOneNodePerSurfaceAndTheTolerance) {
  const auto surfaces = two_spheres();
  const std::string path = scratch_dir() + "/two.glb";
  AssetWriteOptions o;
  o.tolerance_mm = 0.05;
  o.extras = {{"input", "test"}};
  write_asset(surfaces, path, o);
  const GltfAsset a = read_gltf(path);
  ASSERT_EQ(a.primitives.size(), 2u);
  EXPECT_EQ(a.primitives[1].mesh_data.triangles.size(), surfaces[1].mesh.triangles.size());
  const auto& extras = a.structure["asset"]["extras"];
  EXPECT_EQ(extras["input"], "test");
  EXPECT_EQ(extras["tolerance_mm"], 0.05);
}

TEST(WriteAsset, SingleMeshFormatsHoldTheMergedMesh) {
  const auto surfaces = two_spheres();
  const TriangleMesh merged = merged_mesh(surfaces);
  EXPECT_EQ(merged.triangles.size(), surfaces[0].mesh.triangles.size() + surfaces[1].mesh.triangles.size());
  const std::string ply = scratch_dir() + "/two.PLY";
  write_asset(surfaces, ply, AssetWriteOptions());
  const TriangleMesh from_ply = read_mesh_file(ply);
  EXPECT_EQ(from_ply.vertex_count(), merged.vertex_count());
  EXPECT_EQ(test::unmatched_triangles(merged, from_ply, 0.0), 0u);
  const std::string drc = scratch_dir() + "/two.drc";
  AssetWriteOptions o;
  o.tolerance_mm = 0.01;
  write_asset(surfaces, drc, o);
  const TriangleMesh from_drc = read_draco_file(drc);
  EXPECT_EQ(from_drc.triangle_count(), merged.triangle_count());
  EXPECT_EQ(test::unmatched_triangles(merged, from_drc, 0.02), 0u);  // 0.01 plus float rounding
}

TEST(WriteAsset, RefusesOtherExtensions) {
  const std::string path = scratch_dir() + "/two.vtu";
  try {
    write_asset(two_spheres(), path, AssetWriteOptions());
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(std::string(e.what()).rfind(path + ": ", 0), 0u) << e.what();
  }
  EXPECT_FALSE(test::file_exists(path));
}

}  // namespace
}  // namespace mlfe
