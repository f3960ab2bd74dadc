#include <gtest/gtest.h>
#include <mlfe/core/base/error.h>
#include <mlfe/formats/draco_io.h>
#include <mlfe/formats/openmesh_io.h>

#include <cmath>
#include <cstdlib>
#include <random>

#include "tests/test_meshes.h"

namespace mlfe {
namespace {

using test::icosphere;
using test::scratch_dir;
using test::unmatched_triangles;

DracoOptions options_with_tolerance(double tol) {
  DracoOptions o;
  o.tolerance = tol;
  return o;
}

TEST(DracoQuantizationBits, AreTheSmallestThatMeetTheTolerance) {
  // 100 mm at 0.01 mm needs 2^b - 1 >= 5000 steps: b = 13.
  EXPECT_EQ(quantization_bits_for(0.01, 100.0), 13);
  EXPECT_GT(100.0 / ((1 << 12) - 1) / 2, 0.01);
  EXPECT_EQ(quantization_bits_for(1.0, 1.0), 8);     // lower clamp
  EXPECT_EQ(quantization_bits_for(1e-12, 1e3), 30);  // upper clamp
  EXPECT_EQ(quantization_bits_for(0.5, 0.0), 8);
  EXPECT_THROW(quantization_bits_for(0.0, 1.0), Error);
  EXPECT_THROW(quantization_bits_for(-1.0, 1.0), Error);
}

TEST(DracoRoundTrip, KeepsEveryTriangleWithinTheTolerance) {
  const TriangleMesh in = icosphere(3, 50.0f, {10.0f, -20.0f, 30.0f});
  for (double tol : {0.5, 0.01, 1e-4}) {
    SCOPED_TRACE("tolerance " + std::to_string(tol));
    const DracoEncoding enc = encode_draco_verified(in, options_with_tolerance(tol));
    const TriangleMesh out = decode_draco(enc.bytes.data(), enc.bytes.size(), "test");
    ASSERT_EQ(out.triangle_count(), in.triangle_count());
    ASSERT_EQ(out.normals.size(), out.positions.size());
    EXPECT_EQ(unmatched_triangles(in, out, tol * 1.0001 + 1e-5), 0u);
    // The tolerance is really used: the coarsest one must move vertices measurably.
    if (tol == 0.5) {
      EXPECT_GT(unmatched_triangles(in, out, 1e-3), 0u);
    }
    // Normals: 10 octahedral bits keep directions within about a degree.
    for (std::size_t i = 0; i < out.positions.size(); ++i) {
      const auto& p = out.positions[i];
      const auto& n = out.normals[i];
      const double r =
          std::sqrt((p[0] - 10) * (p[0] - 10) + (p[1] + 20) * (p[1] + 20) + (p[2] - 30) * (p[2] - 30));
      const double dot = (n[0] * (p[0] - 10) + n[1] * (p[1] + 20) + n[2] * (p[2] - 30)) / r;
      ASSERT_GT(dot, std::cos(2.0 * M_PI / 180.0)) << "vertex " << i;
    }
  }
}

TEST(DracoRoundTrip, CoarserToleranceGivesSmallerPayload) {
  const TriangleMesh in = icosphere(4, 80.0f);
  const auto fine = encode_draco(in, options_with_tolerance(0.001));
  const auto coarse = encode_draco(in, options_with_tolerance(0.1));
  EXPECT_LT(coarse.size(), fine.size());
}

TEST(DracoEncoding, IsDeterministic) {
  const TriangleMesh in = icosphere(3, 20.0f);
  EXPECT_EQ(encode_draco(in, options_with_tolerance(0.01)), encode_draco(in, options_with_tolerance(0.01)));
}

TEST(DracoEncoding, DropsOnlyDegenerateTriangles) {
  TriangleMesh in = icosphere(1, 10.0f);
  const std::size_t good = in.triangle_count();
  in.triangles.push_back({0, 0, 1});  // repeated index
  in.positions.push_back(in.positions[2]);
  in.normals.push_back(in.normals[2]);
  in.triangles.push_back({2, std::uint32_t(in.positions.size() - 1), 3});  // repeated position
  const DracoEncoding enc = encode_draco_verified(in, options_with_tolerance(0.01));
  EXPECT_EQ(enc.decoded.triangle_count(), good);
}

// Two halves of a wavy sheet meet at x = 10; with one shared box the decoded boundary vertices
// of both halves coincide exactly, with per-mesh boxes they do not.
TEST(DracoSharedBox, KeepsTheSeamBetweenSurfacesCrackFree) {
  auto sheet = [](float x0, float x1) {
    TriangleMesh m;
    const int nx = 17, ny = 23;
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) {
        const float x = x0 + (x1 - x0) * float(i) / float(nx - 1);
        const float y = -3.3f + 7.77f * float(j) / float(ny - 1);
        m.positions.push_back({x, y, 0.37f * std::sin(0.9f * x + 0.4f * y)});
      }
    for (int j = 0; j + 1 < ny; ++j)
      for (int i = 0; i + 1 < nx; ++i) {
        const std::uint32_t a = std::uint32_t(j * nx + i);
        m.triangles.push_back({a, a + 1, a + std::uint32_t(nx) + 1});
        m.triangles.push_back({a, a + std::uint32_t(nx) + 1, a + std::uint32_t(nx)});
      }
    return m;
  };
  const TriangleMesh left = sheet(-1.37f, 10.0f), right = sheet(10.0f, 23.91f);
  auto seam = [](const TriangleMesh& m) {
    std::vector<std::array<float, 3>> s;
    for (const auto& p : m.positions)
      if (std::fabs(p[0] - 10.0f) < 0.01f) s.push_back(p);
    std::sort(s.begin(), s.end());
    return s;
  };
  const double tol = 0.004;
  DracoOptions shared = options_with_tolerance(tol);
  shared.box_min = {-1.37f, -3.3f, -0.5f};
  shared.box_range = 23.91f + 1.37f;
  const auto l = seam(encode_draco_verified(left, shared).decoded);
  const auto r = seam(encode_draco_verified(right, shared).decoded);
  ASSERT_EQ(l.size(), 23u);
  EXPECT_EQ(l, r);
  const auto l_own = seam(encode_draco_verified(left, options_with_tolerance(tol)).decoded);
  const auto r_own = seam(encode_draco_verified(right, options_with_tolerance(tol)).decoded);
  EXPECT_NE(l_own, r_own) << "per-mesh boxes happened to agree: the shared-box check proves nothing";
}

TEST(DracoEncoding, RejectsPositionsOutsideTheSharedBox) {
  DracoOptions o = options_with_tolerance(0.01);
  o.box_min = {0, 0, 0};
  o.box_range = 5.0f;
  EXPECT_THROW(encode_draco(icosphere(1, 10.0f), o), Error);
}

TEST(DracoEncoding, RejectsBadMeshesAndOptions) {
  TriangleMesh m = icosphere(1, 10.0f);
  EXPECT_THROW(encode_draco(TriangleMesh{}, options_with_tolerance(0.01)), Error);
  EXPECT_THROW(encode_draco(m, options_with_tolerance(0.0)), Error);
  TriangleMesh bad_index = m;
  bad_index.triangles.push_back({0, 1, 999});
  EXPECT_THROW(encode_draco(bad_index, options_with_tolerance(0.01)), Error);
  TriangleMesh bad_normals = m;
  bad_normals.normals.pop_back();
  EXPECT_THROW(encode_draco(bad_normals, options_with_tolerance(0.01)), Error);
  TriangleMesh nan = m;
  nan.positions[3][1] = NAN;
  EXPECT_THROW(encode_draco(nan, options_with_tolerance(0.01)), Error);
}

TEST(DracoDecoding, ThrowsErrorOnTruncatedOrGarbageData) {
  const auto bytes = encode_draco(icosphere(2, 10.0f), options_with_tolerance(0.01));
  for (std::size_t n : {std::size_t(0), std::size_t(1), std::size_t(8), bytes.size() / 3, bytes.size() / 2})
    EXPECT_THROW(decode_draco(bytes.data(), n, "truncated"), Error) << n << " bytes";
  const std::string garbage = "this is not a draco file at all";
  EXPECT_THROW(decode_draco(garbage.data(), garbage.size(), "garbage"), Error);
  try {
    decode_draco(garbage.data(), garbage.size(), "x.drc");
  } catch (const Error& e) {
    EXPECT_EQ(std::string(e.what()).rfind("x.drc: ", 0), 0u) << e.what();
  }
}

TEST(DracoDecoding, SurvivesRandomCorruptionWithErrorOrValidMesh) {
  const auto bytes = encode_draco(icosphere(2, 10.0f), options_with_tolerance(0.01));
  std::mt19937 rng(42);
  int errors = 0;
  for (int trial = 0; trial < 300; ++trial) {
    auto copy = bytes;
    for (int k = 0; k < 3; ++k) copy[rng() % copy.size()] ^= char(1 << (rng() % 8));
    try {
      const TriangleMesh m = decode_draco(copy.data(), copy.size(), "corrupt");
      for (const auto& t : m.triangles)
        for (auto v : t) ASSERT_LT(v, m.positions.size());
    } catch (const Error&) {
      ++errors;
    }
  }
  EXPECT_GT(errors, 0);
}

TEST(DracoFile, RoundTripsAndAgreesWithTheDebianDracoDecoder) {
  const std::string drc = scratch_dir() + "/sphere.drc";
  const std::string ply = scratch_dir() + "/sphere_from_drc.ply";
  const TriangleMesh in = icosphere(3, 40.0f, {1.0f, 2.0f, 3.0f});
  write_draco_file(drc, in, options_with_tolerance(0.01));
  const TriangleMesh ours = read_draco_file(drc);
  EXPECT_EQ(ours.triangle_count(), in.triangle_count());
  EXPECT_EQ(unmatched_triangles(in, ours, 0.01 * 1.0001 + 1e-5), 0u);

  ASSERT_EQ(std::system("command -v draco_decoder > /dev/null"), 0)
      << "draco_decoder not found: install the Debian package draco (scripts/install_deps.sh)";
  const std::string cmd = "draco_decoder -i '" + drc + "' -o '" + ply + "' > /dev/null";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
  const TriangleMesh theirs = read_mesh_file(ply);
  EXPECT_EQ(theirs.triangle_count(), ours.triangle_count());
  EXPECT_EQ(unmatched_triangles(ours, theirs, 1e-5), 0u);
}

TEST(DracoFile, FailedWriteThrowsAndLeavesNoFile) {
  const std::string path = scratch_dir() + "/no/such/dir/x.drc";
  EXPECT_THROW(write_draco_file(path, icosphere(1, 1.0f), options_with_tolerance(0.01)), Error);
  EXPECT_FALSE(test::file_exists(path));
  EXPECT_THROW(read_draco_file(scratch_dir() + "/missing.drc"), Error);
}

}  // namespace
}  // namespace mlfe
