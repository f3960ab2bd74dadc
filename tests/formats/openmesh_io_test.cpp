#include <gtest/gtest.h>
#include <mlfe/core/base/error.h>
#include <mlfe/formats/openmesh_io.h>

#include <algorithm>
#include <array>
#include <cmath>

#include "tests/test_meshes.h"

namespace mlfe {
namespace {

using test::icosphere;
using test::scratch_dir;
using test::unmatched_triangles;

class MeshFileRoundTrip : public ::testing::TestWithParam<std::string> {};

TEST_P(MeshFileRoundTrip, KeepsPositionsAndTriangleCount) {
  const TriangleMesh in = icosphere(3, 37.5f, {101.25f, -12.5f, 3.0f});
  const std::string path = scratch_dir() + "/roundtrip" + GetParam();
  write_mesh_file(path, in);
  const TriangleMesh out = read_mesh_file(path);
  EXPECT_EQ(out.triangle_count(), in.triangle_count());
  EXPECT_EQ(out.vertex_count(), in.vertex_count());
  // Binary formats store floats; text formats are written with 9 digits: both exact.
  EXPECT_EQ(unmatched_triangles(in, out, 0.0), 0u);
  if (GetParam() != ".stl") {  // STL has face normals only
    ASSERT_EQ(out.normals.size(), out.positions.size());
  }
}

TEST_P(MeshFileRoundTrip, WritesIdenticalBytesTwice) {
  const TriangleMesh in = icosphere(2, 5.0f);
  const std::string a = scratch_dir() + "/det_a" + GetParam(), b = scratch_dir() + "/det_b" + GetParam();
  write_mesh_file(a, in);
  write_mesh_file(b, in);
  const std::string bytes = test::read_bytes(a);
  EXPECT_FALSE(bytes.empty());
  EXPECT_EQ(bytes, test::read_bytes(b));
}

INSTANTIATE_TEST_SUITE_P(Formats, MeshFileRoundTrip, ::testing::Values(".ply", ".obj", ".off", ".stl"),
                         [](const auto& info) { return info.param.substr(1); });

TEST(MeshFile, PlyIsBinary) {
  const std::string path = scratch_dir() + "/binary.ply";
  write_mesh_file(path, icosphere(1, 1.0f));
  EXPECT_NE(test::read_bytes(path).find("format binary_little_endian"), std::string::npos);
}

TEST(MeshFile, UnknownExtensionOrMissingDirThrowsAndLeavesNoFile) {
  EXPECT_THROW(write_mesh_file(scratch_dir() + "/x.xyz", icosphere(1, 1.0f)), Error);
  EXPECT_FALSE(test::file_exists(scratch_dir() + "/x.xyz"));
  const std::string path = scratch_dir() + "/missing/dir/x.ply";
  EXPECT_THROW(write_mesh_file(path, icosphere(1, 1.0f)), Error);
  EXPECT_FALSE(test::file_exists(path));
  EXPECT_THROW(read_mesh_file(scratch_dir() + "/nothing.ply"), Error);
}

TEST(OpenMeshConversion, KeepsNonManifoldTriangles) {
  // Three triangles on one edge: OpenMesh refuses the third as a complex edge.
  TriangleMesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}};
  m.triangles = {{0, 1, 2}, {1, 0, 3}, {0, 1, 4}};
  const TriangleMesh back = from_openmesh(to_openmesh(m));
  EXPECT_EQ(back.triangle_count(), 3u);
  EXPECT_EQ(unmatched_triangles(m, back, 0.0), 0u);
}

TEST(OpenMeshConversion, RejectsIndicesOutOfRange) {
  TriangleMesh m = icosphere(0, 1.0f);
  m.triangles.push_back({0, 1, 12});
  EXPECT_THROW(to_openmesh(m), Error);
}

TEST(Decimation, ReachesTheTargetWithinOnePercent) {
  const TriangleMesh in = icosphere(5, 50.0f);  // 20480 triangles
  for (std::size_t target : {10000u, 2000u, 500u}) {
    const TriangleMesh out = decimate_to(in, target);
    EXPECT_NEAR(double(out.triangle_count()), double(target), 0.01 * target) << target;
    ASSERT_EQ(out.normals.size(), out.positions.size());
    // Still a closed genus-0 surface without leftover vertices (Euler: V - E + F = 2).
    EXPECT_EQ(out.vertex_count(), out.triangle_count() / 2 + 2);
    // Still a sphere: vertices stay near the surface and normals point outwards.
    for (std::size_t i = 0; i < out.positions.size(); ++i) {
      const auto& p = out.positions[i];
      const double r = std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
      ASSERT_NEAR(r, 50.0, 2.0);
      const auto& n = out.normals[i];
      ASSERT_GT((n[0] * p[0] + n[1] * p[1] + n[2] * p[2]) / r, 0.9);
    }
  }
}

TEST(Decimation, LeavesMeshesAtOrBelowTheTargetAlone) {
  const TriangleMesh in = icosphere(2, 1.0f);
  const TriangleMesh out = decimate_to(in, in.triangle_count());
  EXPECT_EQ(out.positions, in.positions);
  EXPECT_EQ(out.triangles, in.triangles);
}

}  // namespace
}  // namespace mlfe
