#include <gtest/gtest.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/surface/triangle_mesh.h>
#include <mlfe/formats/asset_reader.h>
#include <mlfe/formats/draco_io.h>
#include <mlfe/formats/gltf_reader.h>
#include <mlfe/formats/gltf_writer.h>
#include <sys/wait.h>
#include <tbb/global_control.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <nlohmann/json.hpp>

#include "tests/test_meshes.h"

namespace mlfe {
namespace {

using nlohmann::json;
using test::icosphere;
using test::scratch_dir;

struct ValidatorResult {
  int status = -1;
  std::string output;
};

// Runs tools/validate_gltf.js; a missing node or validator gives a non-zero status (the test
// then fails with the instructions in the output).
ValidatorResult validate(const std::string& file) {
  const std::string cmd = "node " MLFE_SOURCE_DIR "/tools/validate_gltf.js '" + file + "' 2>&1";
  ValidatorResult r;
  FILE* pipe = ::popen(cmd.c_str(), "r");
  if (pipe == nullptr) {
    r.output = "cannot run: " + cmd;
    return r;
  }
  char buf[4096];
  std::size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, pipe)) > 0) r.output.append(buf, n);
  const int st = ::pclose(pipe);
  r.status = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
  if (r.status == 127 || r.status == 2)
    r.output += "\n(needs node and the gltf-validator npm package: run scripts/install_deps.sh)";
  return r;
}

struct Glb {
  json gltf;
  std::string bin;
};

Glb parse_glb(const std::string& bytes) {
  Glb g;
  auto u32 = [&](std::size_t at) {
    std::uint32_t v;
    std::memcpy(&v, bytes.data() + at, 4);
    return v;
  };
  EXPECT_GE(bytes.size(), 20u);
  if (bytes.size() < 20) return g;
  EXPECT_EQ(bytes.substr(0, 4), "glTF");
  EXPECT_EQ(u32(4), 2u);
  EXPECT_EQ(u32(8), bytes.size());
  const std::uint32_t json_len = u32(12);
  EXPECT_EQ(u32(16), 0x4E4F534Au);
  g.gltf = json::parse(bytes.substr(20, json_len));
  const std::size_t bin_at = 20 + json_len;
  if (bin_at + 8 <= bytes.size()) {
    EXPECT_EQ(u32(bin_at + 4), 0x004E4942u);
    g.bin = bytes.substr(bin_at + 8, u32(bin_at));
  }
  return g;
}

// Two nested spheres off-centre, the inner one translucent, the outer with two LODs.
std::vector<GltfSurface> two_surface_scene(bool with_lods = false) {
  GltfSurface skin;
  skin.iso_value = -300;
  skin.mesh = icosphere(3, 80.0f, {12.0f, -30.0f, 140.0f});
  skin.color = {0.9f, 0.75f, 0.65f, 0.4f};
  if (with_lods)
    skin.lods = {icosphere(2, 80.0f, {12.0f, -30.0f, 140.0f}), icosphere(1, 80.0f, {12.0f, -30.0f, 140.0f})};
  GltfSurface bone;
  bone.name = "bone";
  bone.iso_value = 400.5;
  bone.mesh = test::uv_sphere(12, 24, 30.0f, {20.0f, -10.0f, 150.0f});
  bone.color = {0.95f, 0.95f, 0.9f, 1.0f};
  return {skin, bone};
}

// The physical bounding box mapped to glTF: min/max of M*p over all vertices.
void expected_bounds(const std::vector<GltfSurface>& s, const std::string& space, std::array<double, 3>& lo,
                     std::array<double, 3>& hi) {
  const auto m = physical_to_gltf_matrix(space);
  lo.fill(1e300);
  hi.fill(-1e300);
  for (const auto& surface : s)
    for (const auto& p : surface.mesh.positions)
      for (int r = 0; r < 3; ++r) {
        const double v = m[3 * r] * p[0] + m[3 * r + 1] * p[1] + m[3 * r + 2] * p[2];
        lo[r] = std::min(lo[r], v);
        hi[r] = std::max(hi[r], v);
      }
}

enum class Mode { kDraco, kFloat, kQuantized };
const char* mode_name(Mode m) {
  return m == Mode::kDraco ? "draco" : m == Mode::kFloat ? "float" : "quantized";
}

GltfOptions options_for(Mode mode, const std::string& space = "RAS") {
  GltfOptions o;
  o.draco = mode == Mode::kDraco;
  o.quantize = mode == Mode::kQuantized;
  o.tolerance_mm = 0.05;
  o.space = space;
  o.extras = {{"source", "test volume"}, {"iso_count", 2}};
  return o;
}

class GltfValidation : public ::testing::TestWithParam<std::tuple<std::string, Mode>> {};

TEST_P(GltfValidation, PassesTheKhronosValidatorWithoutErrorsOrWarnings) {
  const auto [ext, mode] = GetParam();
  const std::string path = scratch_dir() + "/valid_" + mode_name(mode) + ext;
  write_gltf(path, two_surface_scene(/*with_lods=*/true), options_for(mode));
  const ValidatorResult r = validate(path);
  EXPECT_EQ(r.status, 0) << r.output;
}

INSTANTIATE_TEST_SUITE_P(Encodings, GltfValidation,
                         ::testing::Combine(::testing::Values(std::string(".glb"), std::string(".gltf")),
                                            ::testing::Values(Mode::kDraco, Mode::kFloat, Mode::kQuantized)),
                         [](const auto& info) {
                           return std::get<0>(info.param).substr(1) + "_" +
                                  mode_name(std::get<1>(info.param));
                         });

TEST(GltfValidator, RejectsAnInvalidAsset) {
  // Guards the validation tests above: the script must really report problems.
  const std::string path = scratch_dir() + "/invalid.gltf";
  std::ofstream(path)
      << R"({"asset":{"version":"2.0"},"accessors":[{"componentType":5126,"count":0,"type":"VEC3"}]})";
  EXPECT_NE(validate(path).status, 0);
}

class GltfBoundingBox : public ::testing::TestWithParam<std::tuple<Mode, std::string>> {};

TEST_P(GltfBoundingBox, AccessorMinMaxEqualsTheConvertedPhysicalBox) {
  const auto [mode, space] = GetParam();
  const auto scene = two_surface_scene();
  const std::string path = scratch_dir() + "/bbox_" + mode_name(mode) + "_" + space + ".glb";
  const GltfOptions opts = options_for(mode, space);
  write_gltf(path, scene, opts);
  const Glb glb = parse_glb(test::read_bytes(path));
  std::array<double, 3> lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
  for (const auto& mesh : glb.gltf["meshes"]) {
    const json& acc = glb.gltf["accessors"][mesh["primitives"][0]["attributes"]["POSITION"].get<int>()];
    for (int k = 0; k < 3; ++k) {
      double a = acc["min"][k].get<double>(), b = acc["max"][k].get<double>();
      if (mode == Mode::kQuantized) {  // undo the root node's dequantization transform
        const json& root = glb.gltf["nodes"][0];
        const double s = root["scale"][k].get<double>(), t = root["translation"][k].get<double>();
        a = t + s * std::max(a / 32767.0, -1.0);
        b = t + s * std::max(b / 32767.0, -1.0);
      }
      lo[k] = std::min(lo[k], a);
      hi[k] = std::max(hi[k], b);
    }
  }
  std::array<double, 3> elo, ehi;
  expected_bounds(scene, space, elo, ehi);
  const double tol = opts.tolerance_mm * 1e-3 * 1.001 + 1e-7;
  for (int k = 0; k < 3; ++k) {
    EXPECT_NEAR(lo[k], elo[k], tol) << "axis " << k;
    EXPECT_NEAR(hi[k], ehi[k], tol) << "axis " << k;
  }
}

INSTANTIATE_TEST_SUITE_P(Encodings, GltfBoundingBox,
                         ::testing::Combine(::testing::Values(Mode::kDraco, Mode::kFloat, Mode::kQuantized),
                                            ::testing::Values(std::string("RAS"), std::string("LPS"))),
                         [](const auto& info) {
                           return std::string(mode_name(std::get<0>(info.param))) + "_" +
                                  std::get<1>(info.param);
                         });

TEST(GltfDraco, PayloadDecodesToWhatTheAccessorsDeclare) {
  const auto scene = two_surface_scene();
  const std::string path = scratch_dir() + "/draco_payload.glb";
  const GltfOptions opts = options_for(Mode::kDraco);
  write_gltf(path, scene, opts);
  const Glb glb = parse_glb(test::read_bytes(path));
  const json& g = glb.gltf;
  EXPECT_EQ(g["extensionsUsed"], json::array({"KHR_draco_mesh_compression"}));
  EXPECT_EQ(g["extensionsRequired"], json::array({"KHR_draco_mesh_compression"}));
  const auto m = physical_to_gltf_matrix("RAS");
  ASSERT_EQ(g["meshes"].size(), 2u);
  for (std::size_t i = 0; i < 2; ++i) {
    SCOPED_TRACE("mesh " + std::to_string(i));
    const json& prim = g["meshes"][i]["primitives"][0];
    const json& ext = prim["extensions"]["KHR_draco_mesh_compression"];
    const json& view = g["bufferViews"][ext["bufferView"].get<int>()];
    const json& pos = g["accessors"][prim["attributes"]["POSITION"].get<int>()];
    const json& nrm = g["accessors"][prim["attributes"]["NORMAL"].get<int>()];
    const json& idx = g["accessors"][prim["indices"].get<int>()];
    for (const json* a : {&pos, &nrm, &idx}) EXPECT_FALSE(a->contains("bufferView"));
    const std::string bytes =
        glb.bin.substr(view.value("byteOffset", 0), view["byteLength"].get<std::size_t>());
    const TriangleMesh dec = decode_draco(bytes.data(), bytes.size(), "payload");
    EXPECT_EQ(pos["count"].get<std::size_t>(), dec.positions.size());
    EXPECT_EQ(nrm["count"].get<std::size_t>(), dec.normals.size());
    EXPECT_EQ(idx["count"].get<std::size_t>(), dec.triangles.size() * 3);
    EXPECT_EQ(idx["componentType"].get<int>(), dec.positions.size() <= 65535 ? 5123 : 5125);
    // The attribute ids must name the decoded attributes (we only have these two).
    EXPECT_NE(ext["attributes"]["POSITION"], ext["attributes"]["NORMAL"]);
    // Triangles: the converted input within the tolerance (in metres).
    TriangleMesh expected = scene[i].mesh;
    for (auto& p : expected.positions) {
      const std::array<float, 3> q = p;
      for (int r = 0; r < 3; ++r) p[r] = float(m[3 * r] * q[0] + m[3 * r + 1] * q[1] + m[3 * r + 2] * q[2]);
    }
    EXPECT_EQ(dec.triangle_count(), expected.triangle_count());
    EXPECT_EQ(test::unmatched_triangles(expected, dec, opts.tolerance_mm * 1e-3 * 1.001 + 1e-7), 0u);
  }
}

TEST(GltfWriter, WritesIdenticalBytesTwice) {
  for (const char* name : {"det.glb", "det.gltf"}) {
    for (Mode mode : {Mode::kDraco, Mode::kFloat}) {
      const std::string a = scratch_dir() + "/a_" + mode_name(mode) + name;
      const std::string b = scratch_dir() + "/b_" + mode_name(mode) + name;
      write_gltf(a, two_surface_scene(true), options_for(mode));
      write_gltf(b, two_surface_scene(true), options_for(mode));
      const std::string bytes = test::read_bytes(a);
      EXPECT_FALSE(bytes.empty());
      EXPECT_TRUE(bytes == test::read_bytes(b)) << name << " " << mode_name(mode);
    }
  }
}

TEST(GltfWriter, BadPathThrowsAndLeavesNoFile) {
  const std::string path = scratch_dir() + "/no/such/dir/scene.glb";
  EXPECT_THROW(write_gltf(path, two_surface_scene(), options_for(Mode::kDraco)), Error);
  EXPECT_FALSE(test::file_exists(path));
  EXPECT_THROW(write_gltf(scratch_dir() + "/scene.obj", two_surface_scene(), options_for(Mode::kDraco)),
               Error);
  EXPECT_FALSE(test::file_exists(scratch_dir() + "/scene.obj"));
  GltfOptions bad_space = options_for(Mode::kFloat, "RAI");
  EXPECT_THROW(write_gltf(scratch_dir() + "/space.glb", two_surface_scene(), bad_space), Error);
}

TEST(GltfWriter, RecordsFrameProvenanceNamesAndMaterials) {
  const std::string path = scratch_dir() + "/meta.glb";
  write_gltf(path, two_surface_scene(true), options_for(Mode::kDraco, "LPS"));
  const json g = parse_glb(test::read_bytes(path)).gltf;
  EXPECT_EQ(g["asset"]["version"], "2.0");
  EXPECT_EQ(g["asset"]["generator"], "mlfe");
  EXPECT_EQ(g["asset"]["extras"]["source"], "test volume");
  const auto m = physical_to_gltf_matrix("LPS");
  EXPECT_EQ(g["asset"]["extras"]["mlfe"]["physical_to_gltf"], json(std::vector<double>(m.begin(), m.end())));
  EXPECT_EQ(g["asset"]["extras"]["mlfe"]["input_space"], "LPS");

  // One scene with one node per surface; LODs hang off MSFT_lod, outside the scene.
  ASSERT_EQ(g["scenes"].size(), 1u);
  ASSERT_EQ(g["scenes"][0]["nodes"].size(), 2u);
  const json& skin = g["nodes"][g["scenes"][0]["nodes"][0].get<int>()];
  const json& bone = g["nodes"][g["scenes"][0]["nodes"][1].get<int>()];
  EXPECT_EQ(skin["name"], "iso -300");
  EXPECT_EQ(bone["name"], "iso 400.5");
  EXPECT_EQ(g["meshes"][bone["mesh"].get<int>()]["name"], "bone");
  const json lods = skin["extensions"]["MSFT_lod"]["ids"];
  ASSERT_EQ(lods.size(), 2u);
  EXPECT_EQ(g["nodes"][lods[0].get<int>()]["name"], "iso -300 lod 1");
  EXPECT_EQ(g["nodes"][lods[1].get<int>()]["name"], "iso -300 lod 2");

  const json& skin_mat =
      g["materials"][g["meshes"][skin["mesh"].get<int>()]["primitives"][0]["material"].get<int>()];
  EXPECT_EQ(skin_mat["alphaMode"], "BLEND");
  EXPECT_EQ(skin_mat["doubleSided"], true);
  EXPECT_NEAR(skin_mat["pbrMetallicRoughness"]["baseColorFactor"][3].get<double>(), 0.4, 1e-6);
  const json& bone_mat =
      g["materials"][g["meshes"][bone["mesh"].get<int>()]["primitives"][0]["material"].get<int>()];
  EXPECT_FALSE(bone_mat.contains("alphaMode"));
}

// Float output: every triangle's winding agrees with its vertex normals and the normals point
// away from the sphere centre, i.e. the frame change is a rotation applied to both.
TEST(GltfWriter, KeepsWindingNormalsAndOutwardOrientation) {
  for (const std::string space : {"RAS", "LPS"}) {
    GltfSurface s;
    s.iso_value = 1;
    s.mesh = icosphere(2, 50.0f, {10.0f, 20.0f, 30.0f});
    const std::string path = scratch_dir() + "/orient_" + space + ".glb";
    write_gltf(path, {s}, options_for(Mode::kFloat, space));
    const Glb glb = parse_glb(test::read_bytes(path));
    const json& prim = glb.gltf["meshes"][0]["primitives"][0];
    auto data = [&](int accessor) {
      const json& a = glb.gltf["accessors"][accessor];
      const json& v = glb.gltf["bufferViews"][a["bufferView"].get<int>()];
      return glb.bin.data() + v.value("byteOffset", 0);
    };
    const auto* pos = reinterpret_cast<const float*>(data(prim["attributes"]["POSITION"].get<int>()));
    const auto* nrm = reinterpret_cast<const float*>(data(prim["attributes"]["NORMAL"].get<int>()));
    const auto* idx = reinterpret_cast<const std::uint16_t*>(data(prim["indices"].get<int>()));
    const auto m = physical_to_gltf_matrix(space);
    double c[3];
    for (int r = 0; r < 3; ++r) c[r] = m[3 * r] * 10 + m[3 * r + 1] * 20 + m[3 * r + 2] * 30;
    for (std::size_t t = 0; t < s.mesh.triangle_count(); ++t) {
      const float* a = pos + 3 * idx[3 * t];
      const float* b = pos + 3 * idx[3 * t + 1];
      const float* d = pos + 3 * idx[3 * t + 2];
      const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]},
                   v[3] = {d[0] - a[0], d[1] - a[1], d[2] - a[2]};
      const double n[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
      const float* vn = nrm + 3 * idx[3 * t];
      ASSERT_GT(n[0] * vn[0] + n[1] * vn[1] + n[2] * vn[2], 0.0) << space << " triangle " << t;
      ASSERT_GT(vn[0] * (a[0] - c[0]) + vn[1] * (a[1] - c[1]) + vn[2] * (a[2] - c[2]), 0.0) << space;
      ASSERT_NEAR(std::sqrt(vn[0] * vn[0] + vn[1] * vn[1] + vn[2] * vn[2]), 1.0, 1e-6);
    }
  }
}

TEST(GltfFrame, MatricesAreScaledProperRotationsToYUp) {
  auto apply = [](const std::array<double, 9>& m, std::array<double, 3> p) {
    return std::array<double, 3>{m[0] * p[0] + m[1] * p[1] + m[2] * p[2],
                                 m[3] * p[0] + m[4] * p[1] + m[5] * p[2],
                                 m[6] * p[0] + m[7] * p[1] + m[8] * p[2]};
  };
  for (const std::string space : {"RAS", "LPS", ""}) {
    auto m = physical_to_gltf_matrix(space);
    for (auto& x : m) x *= 1000.0;
    const double det = m[0] * (m[4] * m[8] - m[5] * m[7]) - m[1] * (m[3] * m[8] - m[5] * m[6]) +
                       m[2] * (m[3] * m[7] - m[4] * m[6]);
    EXPECT_DOUBLE_EQ(det, 1.0) << space;
    // Superior is +Y, anterior +Z, patient's left +X (the asset's right is -X).
    const double sign = space == "LPS" ? -1.0 : 1.0;  // LPS flips the x and y axes of RAS
    EXPECT_EQ(apply(m, {0, 0, 1}), (std::array<double, 3>{0, 1, 0})) << space;
    EXPECT_EQ(apply(m, {0, sign, 0}), (std::array<double, 3>{0, 0, 1})) << space;
    EXPECT_EQ(apply(m, {-sign, 0, 0}), (std::array<double, 3>{1, 0, 0})) << space;
  }
  EXPECT_EQ(physical_to_gltf_matrix("")[0], -1e-3);
  EXPECT_THROW(physical_to_gltf_matrix("RAI"), Error);
}

TEST(GltfWriter, WritesSurfacesWithoutTrianglesAsEmptyNodes) {
  GltfSurface empty;
  empty.iso_value = 5;
  const std::string path = scratch_dir() + "/empty.glb";
  auto scene = two_surface_scene();
  scene.push_back(empty);
  write_gltf(path, scene, options_for(Mode::kDraco));
  const ValidatorResult r = validate(path);
  EXPECT_EQ(r.status, 0) << r.output;
  const json g = parse_glb(test::read_bytes(path)).gltf;
  EXPECT_EQ(g["meshes"].size(), 2u);
  EXPECT_EQ(g["nodes"].size(), 3u);
}

TEST(GltfWriter, WritesAValidEmptySceneWithoutUnusedExtensions) {
  const std::string path = scratch_dir() + "/no_surfaces.glb";
  write_gltf(path, {}, options_for(Mode::kDraco));
  const ValidatorResult r = validate(path);
  EXPECT_EQ(r.status, 0) << r.output;
  const json g = parse_glb(test::read_bytes(path)).gltf;
  EXPECT_FALSE(g.contains("extensionsRequired"));
  EXPECT_EQ(g["scenes"].size(), 1u);
}

// A level of 20480 triangles in pieces of at most 3000: the writing's own contract
// (GltfOptions::draco_piece_triangles), lowered so that a small mesh is cut.
struct Pieces {
  std::vector<GltfSurface> scene;
  GltfOptions whole = options_for(Mode::kDraco), cut = options_for(Mode::kDraco);
  Pieces() {
    GltfSurface s;
    s.iso_value = 7;
    s.mesh = icosphere(5, 60.0f, {10.0f, -20.0f, 130.0f});
    scene = {s};
    cut.draco_piece_triangles = 3000;
  }
  std::string write(const std::string& name, const GltfOptions& o, int threads) {
    const std::string path = scratch_dir() + "/" + name;
    const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, std::size_t(threads));
    write_gltf(path, scene, o);
    return path;
  }
};

TEST(GltfDracoPieces, ABigLevelIsCutIntoValidPiecesWithTheSameBytesAtAnyThreadCount) {
  Pieces p;
  const std::string one = p.write("pieces_1.glb", p.cut, 1), two = p.write("pieces_2.glb", p.cut, 2);
  EXPECT_TRUE(test::read_bytes(one) == test::read_bytes(two));
  const ValidatorResult r = validate(one);
  EXPECT_EQ(r.status, 0) << r.output;
  const json g = parse_glb(test::read_bytes(one)).gltf;
  ASSERT_EQ(g["meshes"].size(), 1u);
  const json& prims = g["meshes"][0]["primitives"];
  ASSERT_EQ(prims.size(), 7u);  // ceil(20480 / 3000)
  std::size_t triangles = 0;
  for (const json& prim : prims) {
    const std::size_t n = g["accessors"][prim["indices"].get<int>()]["count"].get<std::size_t>() / 3;
    EXPECT_LE(n, 3000u);
    EXPECT_GE(n, 20480u / 7);  // balanced
    triangles += n;
    EXPECT_EQ(prim["material"], 0);
  }
  EXPECT_EQ(triangles, 20480u);
  EXPECT_EQ(g["nodes"][0]["extras"]["triangles"], 20480);
}

TEST(GltfDracoPieces, ALevelOfAtMostOnePieceKeepsItsBytes) {
  Pieces p;
  GltfOptions exact = p.whole;
  exact.draco_piece_triangles = 20480;
  EXPECT_TRUE(test::read_bytes(p.write("one_piece.glb", exact, 2)) ==
              test::read_bytes(p.write("whole.glb", p.whole, 2)));
  exact.draco_piece_triangles = 0;
  EXPECT_THROW(p.write("no_piece.glb", exact, 2), Error);
}

TEST(GltfDracoPieces, PiecesReadBackAsOneWeldedSurfaceWithinTheQuantization) {
  Pieces p;
  const GltfAsset whole = read_gltf(p.write("read_whole.glb", p.whole, 2));
  const GltfAsset cut = read_gltf(p.write("read_cut.glb", p.cut, 2));
  ASSERT_EQ(whole.primitives.size(), 1u);
  ASSERT_EQ(cut.primitives.size(), 1u);
  EXPECT_EQ(cut.primitives[0].label, "node 0 'iso 7' mesh 'iso 7' primitive 0 (+6 joined)");
  EXPECT_EQ(cut.structure, whole.structure);  // the pieces are listed once
  const TriangleMesh& joined = cut.primitives[0].mesh_data;
  // Welded: the single encoding's vertex count (the sphere's own), closed, manifold.
  EXPECT_EQ(joined.positions.size(), whole.primitives[0].mesh_data.positions.size());
  EXPECT_EQ(joined.positions.size(), p.scene[0].mesh.positions.size());
  EXPECT_EQ(joined.normals.size(), joined.positions.size());
  const MeshTopology topo = mesh_topology(joined);
  EXPECT_TRUE(topo.welded_manifold());
  EXPECT_EQ(topo.boundary_edges, 0u);
  EXPECT_EQ(cut.primitives[0].quantization_step, whole.primitives[0].quantization_step);
  // Every triangle within the tolerance of the input's (metres).
  TriangleMesh expected = p.scene[0].mesh;
  const auto m = physical_to_gltf_matrix("RAS");
  for (auto& q : expected.positions) {
    const std::array<float, 3> x = q;
    for (int r = 0; r < 3; ++r) q[r] = float(m[3 * r] * x[0] + m[3 * r + 1] * x[1] + m[3 * r + 2] * x[2]);
  }
  EXPECT_EQ(joined.triangles.size(), expected.triangles.size());
  EXPECT_EQ(test::unmatched_triangles(expected, joined, p.cut.tolerance_mm * 1e-3 * 1.001 + 1e-7), 0u);
  // read_asset (Python's read_mesh) sees the same one surface.
  const AssetFile asset = read_asset(scratch_dir() + "/read_cut.glb");
  ASSERT_EQ(asset.surfaces.size(), 1u);
  EXPECT_EQ(asset.surfaces[0].mesh.positions.size(), joined.positions.size());
}

TEST(GltfReader, JoinsOnlyPrimitivesThatDifferInTheirDataAlone) {
  // The fourth piece given a material of its own is a surface of its own.
  Pieces p;
  const std::string path = p.write("two_materials.gltf", p.cut, 2);
  json g = json::parse(test::read_bytes(path));
  g["materials"].push_back(g["materials"][0]);
  g["meshes"][0]["primitives"][3]["material"] = 1;
  test::write_bytes(path, g.dump());
  const GltfAsset a = read_gltf(path);
  ASSERT_EQ(a.primitives.size(), 2u);
  EXPECT_EQ(a.primitives[1].primitive, 3);
  EXPECT_EQ(a.primitives[0].mesh_data.triangles.size() + a.primitives[1].mesh_data.triangles.size(), 20480u);
  EXPECT_EQ(a.structure["meshes"][0]["primitives"].size(), 2u);
}

}  // namespace
}  // namespace mlfe
