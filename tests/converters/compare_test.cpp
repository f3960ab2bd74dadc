// formats/compare (mlfe compare's library): each kind detects a planted difference just over
// its tolerance and accepts one just under; Draco copies, reordered copies and glTF encodings
// compare equal; mirrored and millimetre meshes are reported with a reason that says so.
#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfOutputFile.h>
#include <ImfStringAttribute.h>
#include <gtest/gtest.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/mesh/hierarchy.h>
#include <mlfe/formats/asset_reader.h>
#include <mlfe/formats/asset_writer.h>
#include <mlfe/formats/draco_io.h>
#include <mlfe/formats/gltf_writer.h>
#include <mlfe/formats/hierarchy_io.h>
#include <mlfe/formats/openmesh_io.h>
#include <mlfe/pipeline/compare.h>
#include <png.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <numeric>
#include <random>

#include "tests/test_meshes.h"

namespace mlfe {
namespace {

std::string tmp(const std::string& name) { return test::scratch_dir() + "/compare_" + name; }

bool mentions(const CompareResult& r, const std::string& text) {
  return r.summary().find(text) != std::string::npos;
}

/// A sphere with a bump, so that no mirror maps it onto itself.
TriangleMesh lumpy_sphere() {
  TriangleMesh m = test::icosphere(3, 1.0f, {0.2f, 0.1f, 0.0f});
  for (std::size_t v = 0; v < m.positions.size(); ++v) {
    auto& p = m.positions[v];
    const float dx = p[0] - 0.9f, dy = p[1] - 0.5f;
    if (dx * dx + dy * dy < 0.4f) p[2] *= 1.4f;
  }
  m.normals.clear();
  compute_area_weighted_normals(m);
  return m;
}

// ---------------------------------------------------------------- meshes

TEST(CompareMeshes, VertexMovedJustOverToleranceIsReportedJustUnderIsAccepted) {
  const TriangleMesh a = test::icosphere(3, 1.0f);
  CompareOptions o;
  o.tolerance = 0.01;
  o.mean_tolerance = 0.01;
  for (const double factor : {0.95, 1.05}) {
    TriangleMesh b = a;
    const auto& p = a.positions[11];
    const double r = std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
    for (int k = 0; k < 3; ++k) b.positions[11][k] = float(p[k] * (r + factor * 0.01) / r);
    const CompareResult res = compare_meshes(a, b, o);
    EXPECT_EQ(res.equal(), factor < 1) << factor << "\n" << res.summary();
    if (factor > 1) {
      EXPECT_TRUE(mentions(res, "Hausdorff distance")) << res.summary();
    }
  }
}

TEST(CompareMeshes, CountToleranceInPercent) {
  const TriangleMesh a = test::icosphere(3, 1.0f);  // 1280 triangles, 642 vertices
  TriangleMesh b = a;
  // 10 duplicated vertices (unused): 1.56 % more vertices, same surface.
  for (int i = 0; i < 10; ++i) {
    b.positions.push_back(b.positions[i]);
    b.normals.push_back(b.normals[i]);
  }
  CompareOptions o;
  EXPECT_TRUE(mentions(compare_meshes(a, b, o), "vertex count"));
  o.count_tolerance_percent = 1.5;
  EXPECT_TRUE(mentions(compare_meshes(a, b, o), "vertex count"));
  o.count_tolerance_percent = 1.6;
  EXPECT_TRUE(compare_meshes(a, b, o).equal()) << compare_meshes(a, b, o).summary();
}

TEST(CompareMeshes, NormalsTurnedJustOverToleranceAreReported) {
  const TriangleMesh a = test::icosphere(3, 1.0f);
  CompareOptions o;
  o.normal_angle_deg = 3.0;
  for (const double deg : {2.9, 3.1}) {
    TriangleMesh b = a;
    // Tilt every normal by `deg` about an axis perpendicular to it.
    const double t = deg * M_PI / 180.0;
    for (auto& n : b.normals) {
      std::array<double, 3> axis{-n[1], n[0], 0.0};
      if (std::abs(n[2]) > 0.9) axis = {0.0, -n[2], n[1]};
      const double l = std::sqrt(axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]);
      for (auto& x : axis) x /= l;
      const std::array<double, 3> v{n[0], n[1], n[2]};
      const std::array<double, 3> c{axis[1] * v[2] - axis[2] * v[1], axis[2] * v[0] - axis[0] * v[2],
                                    axis[0] * v[1] - axis[1] * v[0]};
      for (int k = 0; k < 3; ++k) n[k] = float(std::cos(t) * v[k] + std::sin(t) * c[k]);
    }
    const CompareResult r = compare_meshes(a, b, o);
    EXPECT_EQ(r.equal(), deg < 3.0) << deg << "\n" << r.summary();
    if (deg > 3.0) {
      EXPECT_TRUE(mentions(r, "normals: mean angle")) << r.summary();
    }
  }
}

TEST(CompareMeshes, DracoCopyIsEqualWithinItsQuantization) {
  const TriangleMesh a = lumpy_sphere();
  const std::string ply = tmp("lumpy.ply"), drc = tmp("lumpy.drc");
  write_mesh_file(ply, a);
  DracoOptions d;
  d.tolerance = 0.001;
  write_draco_file(drc, a, d);
  CompareOptions o;
  o.tolerance = 0.001 * std::sqrt(3.0);  // per-coordinate rounding bound, as a distance
  const CompareResult r = compare_files(ply, drc, o);
  EXPECT_TRUE(r.equal()) << r.summary();
  EXPECT_EQ(r.kind, "mesh");
  EXPECT_GT(r.report["hausdorff"].get<double>(), 0.0);  // it did decode a quantized copy
  // A tolerance below Draco's rounding widens to the file's grid step (issue 42), and says so.
  o.tolerance = 0.0001;
  const CompareResult w = compare_files(ply, drc, o);
  EXPECT_TRUE(w.equal()) << w.summary();
  ASSERT_EQ(w.notes.size(), 1u);
  EXPECT_NE(w.notes[0].find("the Draco quantization step of ACTUAL"), std::string::npos) << w.notes[0];
}

TEST(CompareMeshes, VertexReorderedCopyIsEqual) {
  const TriangleMesh a = lumpy_sphere();
  TriangleMesh b;
  std::vector<std::uint32_t> perm(a.vertex_count());
  std::iota(perm.begin(), perm.end(), 0u);
  std::mt19937 rng(3);
  std::shuffle(perm.begin(), perm.end(), rng);
  b.positions.resize(a.vertex_count());
  b.normals.resize(a.vertex_count());
  for (std::size_t v = 0; v < perm.size(); ++v) {
    b.positions[perm[v]] = a.positions[v];
    b.normals[perm[v]] = a.normals[v];
  }
  for (std::size_t t = a.triangle_count(); t-- > 0;) {
    const auto& tri = a.triangles[t];
    b.triangles.push_back({perm[tri[1]], perm[tri[2]], perm[tri[0]]});  // rotated corners, same winding
  }
  const std::string obj = tmp("reordered.obj"), ply = tmp("original.ply");
  write_mesh_file(ply, a);
  write_mesh_file(obj, b);
  CompareOptions o;
  o.tolerance = 1e-6;
  const CompareResult r = compare_files(ply, obj, o);
  EXPECT_TRUE(r.equal()) << r.summary();
}

TEST(CompareMeshes, MirroredMeshIsReportedAsWrongHandedness) {
  const TriangleMesh a = lumpy_sphere();
  TriangleMesh b = a;
  for (auto& p : b.positions) p[0] = -p[0];
  for (auto& n : b.normals) n[0] = -n[0];
  CompareOptions o;
  o.tolerance = 0.001;
  const CompareResult r = compare_meshes(a, b, o);
  EXPECT_FALSE(r.equal());
  EXPECT_TRUE(mentions(r, "handedness")) << r.summary();
  EXPECT_TRUE(mentions(r, "mirrored along x")) << r.summary();
}

TEST(CompareMeshes, MillimetresInsteadOfMetresIsNamed) {
  const TriangleMesh a = lumpy_sphere();
  TriangleMesh b = a;
  for (auto& p : b.positions)
    for (auto& x : p) x *= 1000.0f;
  const CompareResult r = compare_meshes(a, b, {});
  EXPECT_FALSE(r.equal());
  EXPECT_TRUE(mentions(r, "1000 times the size of EXPECTED: millimetres instead of metres?")) << r.summary();
}

TEST(CompareMeshes, SameReportWithOneAndTwoThreads) {
  const TriangleMesh a = lumpy_sphere();
  TriangleMesh b = test::icosphere(4, 1.02f, {0.2f, 0.1f, 0.0f});
  std::string one, two;
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 1);
    one = compare_meshes(a, b, {}).report.dump();
  }
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 2);
    two = compare_meshes(a, b, {}).report.dump();
  }
  EXPECT_EQ(one, two);
}

// ---------------------------------------------------------------- glTF

GltfSurface surface_of(const TriangleMesh& m, double iso) {
  GltfSurface s;
  s.iso_value = iso;
  s.mesh = m;
  return s;
}

TEST(CompareGltf, DracoAndPlainEncodingsOfOneSceneAreEqual) {
  const TriangleMesh a = lumpy_sphere();  // "millimetres"
  GltfOptions draco, plain;
  draco.tolerance_mm = 0.001;
  plain.draco = false;
  const std::string g1 = tmp("draco.glb"), g2 = tmp("plain.gltf");
  write_gltf(g1, {surface_of(a, 1.0)}, draco);
  write_gltf(g2, {surface_of(a, 1.0)}, plain);
  CompareOptions o;
  o.tolerance = 0.001e-3 * std::sqrt(3.0);  // metres
  // The writer records its encoding in the provenance; the encoding is not meaning, so it is
  // not compared (issue #25), without any --ignore.
  const CompareResult r = compare_files(g2, g1, o);
  EXPECT_FALSE(mentions(r, "/asset/extras/mlfe/encoding")) << r.summary();
  EXPECT_EQ(r.kind, "gltf");
  EXPECT_TRUE(r.equal()) << r.summary();
  EXPECT_GT(r.report["primitives"][0]["hausdorff"].get<double>(), 0.0);  // Draco did quantize
}

TEST(CompareGltf, ASurfaceInDracoPiecesEqualsItInOnePrimitive) {
  const TriangleMesh a = lumpy_sphere();
  GltfOptions whole, cut;
  whole.tolerance_mm = cut.tolerance_mm = 0.001;
  cut.draco_piece_triangles = a.triangles.size() / 4;
  const std::string g1 = tmp("whole.glb"), g2 = tmp("pieces.glb");
  write_gltf(g1, {surface_of(a, 1.0)}, whole);
  write_gltf(g2, {surface_of(a, 1.0)}, cut);
  ASSERT_FALSE(test::read_bytes(g1) == test::read_bytes(g2));
  CompareOptions o;
  o.strict = true;
  const CompareResult r = compare_files(g1, g2, o);
  EXPECT_TRUE(r.equal()) << r.summary();
  EXPECT_EQ(r.report["primitives"].size(), 1u);
  EXPECT_LT(r.report["primitives"][0]["hausdorff"].get<double>(), 1e-12);  // the same grid points
}

/// lumpy_sphere with a sliver: vertex 0, a twin a few float steps from it (the same Draco grid
/// point, so after decoding the two coincide) and a tip of its own outside the sphere. Draco
/// makes such triangles out of an iso-surface's tiny ones; the tip lies on no other triangle.
TriangleMesh sphere_with_sliver() {
  TriangleMesh m = lumpy_sphere();
  const std::array<float, 3> x = m.positions[0], centre{0.2f, 0.1f, 0.0f};
  std::array<float, 3> twin = x, tip;
  for (int i = 0; i < 4; ++i) twin[0] = std::nextafter(twin[0], 2.0f);
  for (int k = 0; k < 3; ++k) tip[k] = centre[k] + 1.2f * (x[k] - centre[k]);
  const auto n = std::uint32_t(m.positions.size());
  m.positions.insert(m.positions.end(), {twin, tip});
  m.normals.insert(m.normals.end(), {m.normals[0], m.normals[0]});
  m.triangles.push_back({0, n, n + 1});
  return m;
}

TEST(CompareGltf, IdenticalDracoFilesAreEqualAndAMovedVertexIsNot) {
  TriangleMesh a = sphere_with_sliver();
  GltfOptions draco;
  draco.tolerance_mm = 0.001;
  const std::string g1 = tmp("sliver.glb"), g2 = tmp("sliver_copy.glb"), moved = tmp("sliver_moved.glb");
  write_gltf(g1, {surface_of(a, 1.0)}, draco);
  std::filesystem::copy_file(g1, g2, std::filesystem::copy_options::overwrite_existing);
  const CompareResult r = compare_files(g1, g2, {});
  EXPECT_TRUE(r.equal()) << r.summary();
  EXPECT_LT(r.report["primitives"][0]["hausdorff"].get<double>(), 1e-12);  // rounding of area samples

  // The sliver's tip 0.1 mm sideways: only triangles with coinciding corners are near it.
  a.positions.back()[2] += 0.1f;
  write_gltf(moved, {surface_of(a, 1.0)}, draco);
  CompareOptions o;
  o.tolerance = 1e-5;  // metres: ten Draco steps
  const CompareResult m = compare_files(g1, moved, o);
  EXPECT_TRUE(mentions(m, "primitive 0: Hausdorff distance")) << m.summary();
  EXPECT_GT(m.report["primitives"][0]["hausdorff"].get<double>(), 5e-5);
}

TEST(CompareGltf, MovedSurfaceAndChangedStructureAreReported) {
  const TriangleMesh a = lumpy_sphere();
  GltfOptions opt;
  opt.draco = false;
  const std::string e = tmp("e.glb"), under = tmp("under.glb"), over = tmp("over.glb"),
                    colour = tmp("colour.glb");
  write_gltf(e, {surface_of(a, 1.0)}, opt);
  CompareOptions o;
  o.tolerance = 1e-5;  // metres: 0.01 mm
  for (const double mm : {0.0095, 0.0105}) {
    TriangleMesh b = a;
    for (auto& p : b.positions) p[1] += float(mm);  // glTF: RAS y (anterior) becomes +Z
    write_gltf(mm < 0.01 ? under : over, {surface_of(b, 1.0)}, opt);
  }
  EXPECT_TRUE(compare_files(e, under, o).equal()) << compare_files(e, under, o).summary();
  const CompareResult r = compare_files(e, over, o);
  EXPECT_TRUE(mentions(r, "node 0 'iso 1' mesh 'iso 1' primitive 0: Hausdorff distance")) << r.summary();

  GltfSurface s = surface_of(a, 1.0);
  s.color = {0.8f, 0.2f, 0.2f, 1.0f};
  GltfOptions extras = opt;
  extras.extras = {{"note", "changed"}};
  write_gltf(colour, {s}, extras);
  const CompareResult c = compare_files(e, colour, o);
  EXPECT_TRUE(mentions(c, "structure /materials/0/pbrMetallicRoughness/baseColorFactor/1")) << c.summary();
  EXPECT_TRUE(mentions(c, "structure /asset/extras/note: only in ACTUAL")) << c.summary();
  o.ignore = {"/materials", "/asset/extras/note"};
  EXPECT_TRUE(compare_files(e, colour, o).equal()) << compare_files(e, colour, o).summary();
}

// ---------------------------------------------------------------- geometry, not provenance

TEST(CompareProvenance, InputToolAndTimingsAreNotesUnlessStrict) {
  const TriangleMesh a = lumpy_sphere();
  GltfOptions e_opt, a_opt;
  e_opt.draco = a_opt.draco = false;
  e_opt.extras = {{"input", "head.nii"}, {"tool", "mlfe 1"}, {"build", {{"seconds", 1.5}}}, {"iso", 80}};
  a_opt.extras = {
      {"input", "array"}, {"tool", "mlfe 1 (python)"}, {"build", {{"seconds", 2.5}}}, {"iso", 80}};
  a_opt.generator = "mlfe (python)";
  const std::string g1 = tmp("prov_file.glb"), g2 = tmp("prov_array.glb");
  write_gltf(g1, {surface_of(a, 1.0)}, e_opt);
  write_gltf(g2, {surface_of(a, 1.0)}, a_opt);
  const CompareResult r = compare_files(g1, g2, {});
  EXPECT_TRUE(r.equal()) << r.summary();
  ASSERT_EQ(r.notes.size(), 1u);
  EXPECT_EQ(r.notes[0],
            "structure: provenance not compared (/asset/extras/build/seconds, /asset/extras/input, "
            "/asset/extras/tool, /asset/generator; --strict compares it)");
  CompareOptions strict;
  strict.strict = true;
  const CompareResult s = compare_files(g1, g2, strict);
  EXPECT_EQ(s.differences.size(), 4u) << s.summary();
  EXPECT_TRUE(mentions(s, "structure /asset/extras/input: \"head.nii\" in EXPECTED, \"array\" in ACTUAL"))
      << s.summary();
  // What is not provenance still counts.
  a_opt.extras["iso"] = 81;
  write_gltf(g2, {surface_of(a, 1.0)}, a_opt);
  EXPECT_TRUE(
      mentions(compare_files(g1, g2, {}), "structure /asset/extras/iso: 80 in EXPECTED, 81 in ACTUAL"));
  EXPECT_TRUE(is_provenance("/levels/3/build_seconds"));
  EXPECT_TRUE(is_provenance("/timings/extract"));
  EXPECT_FALSE(is_provenance("/asset/extras/inputs"));
  EXPECT_FALSE(is_provenance("/seconds_left"));
}

TEST(CompareDraco, ToleranceWidensToTheFilesQuantizationStepAndSaysSo) {
  const TriangleMesh a = lumpy_sphere();  // "millimetres", about 2.4 across
  GltfOptions draco, plain;
  draco.tolerance_mm = 0.002;
  plain.draco = false;
  const std::string d = tmp("widen_draco.glb"), p = tmp("widen_plain.glb");
  write_gltf(d, {surface_of(a, 1.0)}, draco);
  write_gltf(p, {surface_of(a, 1.0)}, plain);
  CompareOptions o;
  o.tolerance = 1e-9;  // metres: far below Draco's grid
  const CompareResult r = compare_files(p, d, o);
  EXPECT_TRUE(r.equal()) << r.summary();
  const double step = r.report["primitives"][0]["quantization_step"][1].get<double>();
  EXPECT_GT(step, 0.0);
  EXPECT_LE(step, 2 * draco.tolerance_mm * 1e-3);
  EXPECT_EQ(r.report["primitives"][0]["tolerance"].get<double>(), step);
  ASSERT_EQ(r.notes.size(), 1u);
  EXPECT_NE(r.notes[0].find("tolerance 1e-09 widened to"), std::string::npos) << r.notes[0];
  EXPECT_NE(r.notes[0].find("the Draco quantization step of ACTUAL"), std::string::npos) << r.notes[0];
  // Without Draco on either side nothing widens: the plain file against itself moved by 3 steps.
  TriangleMesh moved = a;
  for (auto& q : moved.positions) q[0] += float(3e3 * step);
  const std::string m = tmp("widen_moved.glb");
  write_gltf(m, {surface_of(moved, 1.0)}, plain);
  o.tolerance = step;
  EXPECT_TRUE(mentions(compare_files(p, m, o), "Hausdorff distance")) << compare_files(p, m, o).summary();
  // The encoding is compared only in strict mode.
  CompareOptions strict;
  strict.strict = true;
  const CompareResult s = compare_files(p, d, strict);
  EXPECT_TRUE(mentions(s, "encoding /mlfe/encoding: \"float\" in EXPECTED, \"draco\" in ACTUAL"))
      << s.summary();
}

TEST(CompareDraco, ScaledAndMirroredCopiesStillDiffer) {
  const TriangleMesh a = lumpy_sphere();
  TriangleMesh scaled = a, mirrored = a;
  for (auto& q : scaled.positions)
    for (auto& x : q) x *= 1000.0f;
  for (auto& q : mirrored.positions) q[0] = 0.4f - q[0];
  mirrored.normals.clear();
  compute_area_weighted_normals(mirrored);
  const std::string d = tmp("copy_draco.drc"), sc = tmp("copy_scaled.ply"), mi = tmp("copy_mirrored.ply");
  DracoOptions o;
  o.tolerance = 0.002;
  write_draco_file(d, a, o);
  write_mesh_file(sc, scaled);
  write_mesh_file(mi, mirrored);
  const CompareResult s = compare_files(d, sc, {});
  EXPECT_TRUE(mentions(s, "times the size of EXPECTED: millimetres instead of metres?")) << s.summary();
  const CompareResult m = compare_files(d, mi, {});
  EXPECT_TRUE(mentions(m, "handedness")) << m.summary();
  EXPECT_TRUE(mentions(m, "mirrored along x")) << m.summary();
}

TEST(CompareAssets, GlbAndPlyOfOneAssetAreEqualInTheScanFrame) {
  GltfSurface s1 = surface_of(lumpy_sphere(), 1.0), s2 = surface_of(test::icosphere(2, 0.5f, {3, 0, 0}), 2.0);
  s1.node_name = "skull";
  s2.node_name = "brain";
  s1.node_extras = {{"label", 1}};
  s2.node_extras = {{"label", 2}};
  const std::string glb = tmp("asset.glb"), ply = tmp("asset.ply");
  write_asset({s1, s2}, glb, {false, false, 0.01, "LPS", {}});
  write_asset({s1, s2}, ply, {false, false, 0.01, "LPS", {}});
  CompareOptions o;
  o.tolerance = 1e-5;  // millimetres: float precision through glTF's metres
  const CompareResult r = compare_files(glb, ply, o);
  EXPECT_TRUE(r.equal()) << r.summary();
  EXPECT_EQ(r.report["frame"], "scan millimetres");
  EXPECT_EQ(r.report["surfaces_matched_by"], "all merged");
  // Surfaces by name, in any order: the read glTF against its structures reversed.
  AssetFile reversed = read_asset(glb);
  std::swap(reversed.surfaces[0], reversed.surfaces[1]);
  const CompareResult n = compare_assets(read_asset(glb), reversed, o);
  EXPECT_TRUE(n.equal()) << n.summary();
  EXPECT_EQ(n.report["surfaces_matched_by"], "name");
  EXPECT_EQ(n.report["frame"], "glTF metres");
  reversed.surfaces.pop_back();
  EXPECT_TRUE(
      mentions(compare_assets(read_asset(glb), reversed, o), "node 'skull' of EXPECTED is not in ACTUAL"));
  o.strict = true;
  EXPECT_TRUE(mentions(compare_files(glb, ply, o), "format: glb in EXPECTED, ply in ACTUAL"));
}

// ---------------------------------------------------------------- images

void write_exr(const std::string& path, int w, int h, const std::vector<std::string>& names,
               const std::vector<std::vector<float>>& data, const std::string& comment) {
  Imf::Header header(w, h);
  for (const auto& n : names) header.channels().insert(n, Imf::Channel(Imf::FLOAT));
  header.insert("comments", Imf::StringAttribute(comment));
  Imf::OutputFile file(path.c_str(), header);
  Imf::FrameBuffer fb;
  for (std::size_t c = 0; c < names.size(); ++c)
    fb.insert(names[c], Imf::Slice(Imf::FLOAT, (char*)data[c].data(), sizeof(float), sizeof(float) * w));
  file.setFrameBuffer(fb);
  file.writePixels(h);
}

TEST(CompareImages, ExrChannelDifferenceJustOverMaxAndPsnrAreReported) {
  const int w = 16, h = 8;
  std::vector<std::vector<float>> rgb(3, std::vector<float>(w * h));
  for (int c = 0; c < 3; ++c)
    for (int i = 0; i < w * h; ++i) rgb[c][i] = float(0.1 * c + 0.01 * (i % 17));
  const std::string e = tmp("e.exr");
  write_exr(e, w, h, {"R", "G", "B"}, rgb, "render");
  CompareOptions o;
  o.image_max = 0.01;
  for (const double delta : {0.0099, 0.0101}) {
    auto changed = rgb;
    changed[1][37] += float(delta);
    const std::string a = tmp(delta < 0.01 ? "under.exr" : "over.exr");
    write_exr(a, w, h, {"R", "G", "B"}, changed, "render");
    const CompareResult r = compare_files(e, a, o);
    EXPECT_EQ(r.equal(), delta < 0.01) << r.summary();
    if (delta > 0.01) {
      EXPECT_TRUE(mentions(r, "channel G: max difference")) << r.summary();
    }
    EXPECT_EQ(r.report["channels"]["R"]["max"].get<double>(), 0.0);
  }
  // PSNR: one changed pixel of 128, peak = the expected channel's max.
  CompareOptions p;
  p.min_psnr = 60;
  auto noisy = rgb;
  noisy[0][5] += 0.05f;
  const std::string n = tmp("noisy.exr");
  write_exr(n, w, h, {"R", "G", "B"}, noisy, "render");
  const CompareResult pr = compare_files(e, n, p);
  const double peak = *std::max_element(rgb[0].begin(), rgb[0].end());
  const double expected_psnr = 20 * std::log10(peak / std::sqrt(0.05 * 0.05 / (w * h)));
  EXPECT_NEAR(pr.report["channels"]["R"]["psnr_db"].get<double>(), expected_psnr, 0.01);
  EXPECT_EQ(pr.equal(), expected_psnr >= 60) << pr.summary();
  p.min_psnr = expected_psnr - 0.1;
  EXPECT_TRUE(compare_files(e, n, p).equal());
  p.min_psnr = expected_psnr + 0.1;
  EXPECT_TRUE(mentions(compare_files(e, n, p), "channel R: PSNR"));
}

TEST(CompareImages, ExrChannelNamesAndAttributesAreCompared) {
  const int w = 4, h = 4;
  std::vector<std::vector<float>> d(2, std::vector<float>(w * h, 0.5f));
  const std::string e = tmp("names_e.exr"), renamed = tmp("names_a.exr"), commented = tmp("names_c.exr");
  write_exr(e, w, h, {"Y", "Z"}, d, "one");
  write_exr(renamed, w, h, {"Y", "depth"}, d, "one");
  write_exr(commented, w, h, {"Y", "Z"}, d, "two");
  const CompareResult r = compare_files(e, renamed);
  EXPECT_TRUE(mentions(r, "channel Z: missing in ACTUAL")) << r.summary();
  EXPECT_TRUE(mentions(r, "channel depth: only in ACTUAL")) << r.summary();
  const CompareResult c = compare_files(e, commented);
  EXPECT_TRUE(mentions(c, "attribute comments: 'string: one' in EXPECTED, 'string: two' in ACTUAL"))
      << c.summary();
  EXPECT_TRUE(compare_files(e, e).equal());
}

void write_png(const std::string& path, int w, int h, const std::vector<std::uint8_t>& rgba) {
  png_image image;
  std::memset(&image, 0, sizeof image);
  image.version = PNG_IMAGE_VERSION;
  image.width = w;
  image.height = h;
  image.format = PNG_FORMAT_RGBA;
  ASSERT_TRUE(png_image_write_to_file(&image, path.c_str(), 0, rgba.data(), 0, nullptr)) << image.message;
}

TEST(CompareImages, PngDifferenceInUnitsOfFullScale) {
  const int w = 8, h = 8;
  std::vector<std::uint8_t> px(w * h * 4);
  for (std::size_t i = 0; i < px.size(); ++i) px[i] = std::uint8_t(i * 7 % 256);
  const std::string e = tmp("e.png"), a = tmp("a.png");
  write_png(e, w, h, px);
  px[4 * 9 + 2] += 3;  // blue of pixel 9 up by 3/255 = 0.01176
  write_png(a, w, h, px);
  CompareOptions o;
  o.image_max = 3.0 / 255 + 1e-6;
  EXPECT_TRUE(compare_files(e, a, o).equal()) << compare_files(e, a, o).summary();
  o.image_max = 3.0 / 255 - 1e-6;
  const CompareResult r = compare_files(e, a, o);
  EXPECT_TRUE(mentions(r, "channel B: max difference")) << r.summary();
  EXPECT_FALSE(mentions(r, "channel R"));
  EXPECT_FALSE(compare_files(e, a).equal());  // default: exact
}

// ---------------------------------------------------------------- volumes

void write_raw_volume(const std::string& path, const std::vector<float>& v, double spacing) {
  std::ofstream(path, std::ios::binary)
      .write(reinterpret_cast<const char*>(v.data()), std::streamsize(v.size() * 4));
  std::ofstream(path + ".json") << "{\"dims\": [4, 3, 2], \"spacing\": [" << spacing
                                << ", 1, 1], \"dtype\": \"float32\", \"endian\": \"little\"}";
}

TEST(CompareVolumes, VoxelDifferenceAndTransformAreReported) {
  std::vector<float> v(24);
  for (int i = 0; i < 24; ++i) v[i] = float(i);
  const std::string e = tmp("e.raw"), under = tmp("under.raw"), over = tmp("over.raw"),
                    spaced = tmp("spaced.raw");
  write_raw_volume(e, v, 0.5);
  auto w = v;
  w[13] += 0.49f;
  write_raw_volume(under, w, 0.5);
  w[13] = v[13] + 0.51f;
  write_raw_volume(over, w, 0.5);
  write_raw_volume(spaced, v, 0.6);
  CompareOptions o;
  o.value_max = 0.5;
  EXPECT_TRUE(compare_files(e, under, o).equal()) << compare_files(e, under, o).summary();
  const CompareResult r = compare_files(e, over, o);
  EXPECT_EQ(r.kind, "volume");
  EXPECT_TRUE(mentions(r, "voxels: max difference 0.51 > 0.5 (at index 13")) << r.summary();
  EXPECT_TRUE(
      mentions(compare_files(e, spaced, o), "transform spacing: (0.5 1 1) in EXPECTED, (0.6 1 1) in ACTUAL"));
  CompareOptions rms;
  rms.value_rms = 0.51 / std::sqrt(24.0) + 1e-4;
  EXPECT_TRUE(compare_files(e, over, rms).equal());
  rms.value_rms = 0.51 / std::sqrt(24.0) - 1e-4;
  EXPECT_TRUE(mentions(compare_files(e, over, rms), "voxels: RMS difference"));
}

TEST(CompareFiles, DifferentKindsAndUnreadableFiles) {
  const std::string exr = tmp("kind.exr"), ply = tmp("kind.ply");
  write_exr(exr, 2, 2, {"Y"}, {std::vector<float>(4, 1.0f)}, "");
  write_mesh_file(ply, test::icosphere(1, 1.0f));
  const CompareResult r = compare_files(exr, ply);
  EXPECT_EQ(r.kind, "mismatch");
  EXPECT_TRUE(mentions(r, "EXPECTED is a image, ACTUAL a mesh")) << r.summary();
  EXPECT_THROW(compare_files(ply, tmp("missing.ply")), Error);
  std::ofstream(tmp("broken.glb")) << "glTF\x02";
  EXPECT_THROW(compare_files(tmp("broken.glb"), tmp("broken.glb")), Error);
}

// ---------------------------------------------------------------- hierarchies

TEST(CompareHierarchies, ValuesPerLevelCountsAndMetadata) {
  Hierarchy<2> h = Hierarchy<2>::box({0.0, 0.0}, {1.0, 1.0});
  h.refine_uniform();
  h.refine_uniform();
  std::vector<double> u(h.vertex_count());
  for (std::size_t v = 0; v < u.size(); ++v) u[v] = h.points()[v][0] + 2 * h.points()[v][1];
  HierarchyFileInfo info;
  info.value_max = 3.0;
  info.metadata = {{"rms_error", 0.25}};
  const std::string e = tmp("e.mlfeh"), under = tmp("under.mlfeh"), over = tmp("over.mlfeh"),
                    finer = tmp("finer.mlfeh"), meta = tmp("meta.mlfeh");
  write_hierarchy<2>(e, h, u, info);
  // The last vertex is a level-2 midpoint.
  ASSERT_EQ(h.vertex_level(VertexId(std::uint32_t(u.size() - 1))), 2);
  auto w = u;
  w.back() += 0.0099;
  write_hierarchy<2>(under, h, w, info);
  w.back() = u.back() + 0.0101;
  write_hierarchy<2>(over, h, w, info);
  CompareOptions o;
  o.value_max = 0.01;
  EXPECT_TRUE(compare_files(e, under, o).equal()) << compare_files(e, under, o).summary();
  const CompareResult r = compare_files(e, over, o);
  EXPECT_EQ(r.kind, "hierarchy");
  EXPECT_TRUE(mentions(r, "values at level 2: max difference")) << r.summary();
  EXPECT_FALSE(mentions(r, "values at level 1"));

  Hierarchy<2> g = h;
  g.refine_uniform();
  write_hierarchy<2>(finer, g, std::vector<double>(g.vertex_count(), 0.0), info);
  EXPECT_TRUE(mentions(compare_files(e, finer, o), "levels: 3 levels in EXPECTED, 4 in ACTUAL"));

  HierarchyFileInfo info2 = info;
  info2.metadata["rms_error"] = 0.3;
  write_hierarchy<2>(meta, h, u, info2);
  EXPECT_TRUE(mentions(compare_files(e, meta, o), "metadata /rms_error: 0.25 in EXPECTED, 0.3 in ACTUAL"));
}

}  // namespace
}  // namespace mlfe
