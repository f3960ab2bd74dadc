// End-to-end tests of `mlfe convert / build / iso`: validator verdicts, physical placement,
// determinism across thread counts, golden files, and bad input (exit 2, one line, no output).
#include <gtest/gtest.h>
#include <mlfe/core/field/field.h>
#include <mlfe/formats/draco_io.h>
#include <mlfe/formats/gltf_writer.h>
#include <mlfe/formats/openmesh_io.h>
#include <mlfe/formats/volume_reader.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <string>

#include "tests/test_meshes.h"
#include "tests/test_paths.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace mlfe {
namespace {

using test::read_bytes;

const std::string kSkull = test::sample_path("ct_skull_64.nrrd");
const std::string kGolden = std::string(MLFE_SOURCE_DIR) + "/tests/golden";

struct RunResult {
  int status;
  std::string err;
};

std::string scratch() { return test::scratch_dir("cli"); }

RunResult run(const std::string& args) {
  const std::string errfile = scratch() + "/stderr.txt";
  const std::string cmd = std::string(MLFE_BINARY) + " " + args + " > /dev/null 2> " + errfile;
  const int rc = std::system(cmd.c_str());
  std::ifstream in(errfile);
  std::stringstream ss;
  ss << in.rdbuf();
  return {WIFEXITED(rc) ? WEXITSTATUS(rc) : -1, ss.str()};
}

bool validator_accepts(const std::string& path, std::string* report) {
  const std::string out = scratch() + "/validator.txt";
  const std::string cmd =
      "node " + std::string(MLFE_SOURCE_DIR) + "/tools/validate_gltf.js " + path + " > " + out + " 2>&1";
  const int rc = std::system(cmd.c_str());
  *report = read_bytes(out);
  return rc == 0;
}

struct Glb {
  json gltf;
  std::string bin;
};
Glb parse_glb(const std::string& b) {
  Glb g;
  EXPECT_GE(b.size(), 20u);
  EXPECT_EQ(b.substr(0, 4), "glTF");
  std::uint32_t json_len;
  std::memcpy(&json_len, b.data() + 12, 4);
  g.gltf = json::parse(b.substr(20, json_len));
  const std::size_t bin_at = 20 + json_len;
  if (bin_at + 8 <= b.size()) {
    std::uint32_t bin_len;
    std::memcpy(&bin_len, b.data() + bin_at, 4);
    g.bin = b.substr(bin_at + 8, bin_len);
  }
  return g;
}

// Bounding box of all POSITION accessors (metres, glTF frame).
std::array<double, 6> glb_bbox(const Glb& g) {
  std::array<double, 6> bb{1e30, 1e30, 1e30, -1e30, -1e30, -1e30};
  for (const auto& mesh : g.gltf["meshes"])
    for (const auto& prim : mesh["primitives"]) {
      const auto& acc = g.gltf["accessors"][prim["attributes"]["POSITION"].get<int>()];
      for (int k = 0; k < 3; ++k) {
        bb[k] = std::min(bb[k], acc["min"][k].get<double>());
        bb[3 + k] = std::max(bb[3 + k], acc["max"][k].get<double>());
      }
    }
  return bb;
}

TEST(Cli, HelpWorksForEveryCommand) {
  EXPECT_EQ(run("--help").status, 0);
  for (const char* c : {"info", "build", "iso", "convert", "refine", "render"})
    EXPECT_EQ(run(std::string(c) + " --help").status, 0) << c;
}

TEST(Convert, GlbPassesTheValidatorAndLandsWhereTheScanIs) {
  const std::string glb = scratch() + "/skull.glb", ply = scratch() + "/skull.ply";
  const std::string common = kSkull + " --iso 1.5 --max-vertices 8000 --quiet";
  ASSERT_EQ(run("convert " + common + " -o " + glb).status, 0);
  ASSERT_EQ(run("convert " + common + " -o " + ply).status, 0);
  std::string report;
  EXPECT_TRUE(validator_accepts(glb, &report)) << report;
  const json r = json::parse(report.substr(report.find('{')));
  EXPECT_EQ(r["numErrors"], 0);
  EXPECT_EQ(r["numWarnings"], 0);

  // The PLY is in physical millimetres (RAS): its box, converted to glTF metres, is the glb's.
  const TriangleMesh m = read_mesh_file(ply);
  std::array<double, 6> mm{1e30, 1e30, 1e30, -1e30, -1e30, -1e30};
  for (const auto& p : m.positions)
    for (int k = 0; k < 3; ++k) {
      mm[k] = std::min(mm[k], double(p[k]));
      mm[3 + k] = std::max(mm[3 + k], double(p[k]));
    }
  const auto bb = glb_bbox(parse_glb(read_bytes(glb)));
  const auto M = physical_to_gltf_matrix("RAS");
  for (int r2 = 0; r2 < 3; ++r2) {
    double lo = 0, hi = 0;
    for (int c = 0; c < 3; ++c) {
      const double a = M[3 * r2 + c] * mm[c], b = M[3 * r2 + c] * mm[3 + c];
      lo += std::min(a, b);
      hi += std::max(a, b);
    }
    EXPECT_NEAR(bb[r2], lo, 1e-3) << "axis " << r2;
    EXPECT_NEAR(bb[3 + r2], hi, 1e-3) << "axis " << r2;
  }
  // And the surface's box is the box of the voxels above the iso-value, in the scan's frame.
  const ScalarGrid g = read_volume(kSkull);
  std::array<double, 6> vb{1e30, 1e30, 1e30, -1e30, -1e30, -1e30};
  for (int k = 0; k < g.dims[2]; ++k)
    for (int j = 0; j < g.dims[1]; ++j)
      for (int i = 0; i < g.dims[0]; ++i)
        if (g.at(i, j, k) > 1.5) {
          const auto p = g.transform.index_to_physical(i, j, k);
          for (int a = 0; a < 3; ++a) {
            vb[a] = std::min(vb[a], p[a]);
            vb[3 + a] = std::max(vb[3 + a], p[a]);
          }
        }
  for (int a = 0; a < 6; ++a) EXPECT_NEAR(mm[a], vb[a], 1.5 * g.transform.spacing[a % 3]) << "bound " << a;
}

TEST(Convert, OutputIsByteIdenticalWhateverTheThreadCount) {
  const std::string h1 = scratch() + "/t1.mlfeh", h2 = scratch() + "/t2.mlfeh";
  const std::string args = " convert " + kSkull + " --iso 1.5,3 --max-vertices 6000 --quiet";
  ASSERT_EQ(run("--threads 1" + args + " -o " + scratch() + "/t1.glb --hierarchy " + h1).status, 0);
  ASSERT_EQ(run("--threads 2" + args + " -o " + scratch() + "/t2.glb --hierarchy " + h2).status, 0);
  EXPECT_EQ(read_bytes(scratch() + "/t1.glb"), read_bytes(scratch() + "/t2.glb"));
  EXPECT_EQ(read_bytes(h1), read_bytes(h2));
  for (const char* ext : {".drc", ".ply"}) {
    const std::string a = scratch() + "/t1" + ext, b = scratch() + "/t2" + ext;
    ASSERT_EQ(run("--threads 1 iso " + h1 + " --iso 1.5,3 --quiet -o " + a).status, 0);
    ASSERT_EQ(run("--threads 2 iso " + h2 + " --iso 1.5,3 --quiet -o " + b).status, 0);
    EXPECT_EQ(read_bytes(a), read_bytes(b)) << ext;
  }
}

TEST(Convert, HierarchyRoundTripGivesTheSameSurfaces) {
  const std::string h = scratch() + "/rt.mlfeh", a = scratch() + "/rt_a.ply", b = scratch() + "/rt_b.ply";
  ASSERT_EQ(
      run("convert " + kSkull + " --iso 3 --max-vertices 6000 --snap 0 --quiet -o " + a + " --hierarchy " + h)
          .status,
      0);
  ASSERT_EQ(run("iso " + h + " --iso 3 --quiet -o " + b).status, 0);
  EXPECT_EQ(read_bytes(a), read_bytes(b));
}

// A kept hierarchy plus its volume gives the same snapped surfaces as the one-shot convert;
// a volume that does not match the hierarchy is refused.
TEST(Convert, IsoOnAHierarchyWithItsVolumeSnapsLikeConvert) {
  const std::string h = scratch() + "/vol.mlfeh", a = scratch() + "/vol_a.ply", b = scratch() + "/vol_b.ply";
  ASSERT_EQ(
      run("convert " + kSkull + " --iso 3 --max-vertices 6000 --quiet -o " + a + " --hierarchy " + h).status,
      0);
  ASSERT_EQ(run("iso " + h + " --iso 3 --quiet --volume " + kSkull + " -o " + b).status, 0);
  EXPECT_EQ(read_bytes(a), read_bytes(b));
  const std::string other = std::string(MLFE_SOURCE_DIR) + "/tests/data/mri_small_bigendian.nii";
  const std::string c = scratch() + "/vol_c.ply";
  const RunResult r = run("iso " + h + " --iso 3 --quiet --volume " + other + " -o " + c);
  EXPECT_EQ(r.status, 2) << r.err;
  EXPECT_NE(r.err.find("mri_small_bigendian.nii"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(c));
  EXPECT_EQ(run("iso " + kSkull + " --iso 3 --quiet --volume " + kSkull + " -o " + c).status, 2);
  EXPECT_FALSE(fs::exists(c));
}

// Usage errors (unknown options, values out of range) exit with 1 as documented, --help and
// --version with 0, and write nothing.
TEST(Convert, UsageErrorsExitWith1) {
  const std::string out = scratch() + "/usage.glb";
  for (const std::string& args :
       {"convert " + kSkull + " --iso 3 --snap 100 -o " + out,
        "convert " + kSkull + " --iso 3 --simplify -1 -o " + out,
        "convert " + kSkull + " --iso 3 --surface samples --level 2 -o " + out,
        "convert " + kSkull + " --iso 3 --bogus -o " + out, std::string("frobnicate"), std::string()}) {
    const RunResult r = run(args);
    EXPECT_EQ(r.status, 1) << args << "\n" << r.err;
    EXPECT_FALSE(fs::exists(out)) << args;
  }
  EXPECT_EQ(run("--help").status, 0);
  EXPECT_EQ(run("--version").status, 0);
  EXPECT_EQ(run("convert --help").status, 0);
}

// By default the vertices sit on the scan's own iso-surface (trilinear f = iso), not on the
// approximation's; the triangles are the same.
TEST(Convert, SnapPutsTheAssetOnTheScansSurface) {
  const std::string a = scratch() + "/snap0.ply", b = scratch() + "/snap1.ply";
  const std::string common = "convert " + kSkull + " --iso 3 --max-vertices 6000 --simplify 0 --quiet -o ";
  ASSERT_EQ(run(common + a + " --snap 0").status, 0);
  ASSERT_EQ(run(common + b).status, 0);
  const TriangleMesh plain = read_mesh_file(a), snapped = read_mesh_file(b);
  ASSERT_EQ(plain.triangles, snapped.triangles);
  const ScalarGrid g = read_volume(kSkull);
  const GridField f(g);
  const auto& t = g.transform;
  auto misfit = [&](const TriangleMesh& m, std::size_t* on = nullptr) {  // mean |f - iso| at the vertices
    double sum = 0;
    for (const auto& p : m.positions) {
      // local = Rᵀ (p - origin); the direction matrix is orthonormal.
      const double d[3] = {p[0] - t.origin[0], p[1] - t.origin[1], p[2] - t.origin[2]};
      std::array<double, 3> local{};
      for (int r = 0; r < 3; ++r)
        local[r] = t.direction[r] * d[0] + t.direction[3 + r] * d[1] + t.direction[6 + r] * d[2];
      const double e = std::abs(f.value(local) - 3.0);
      sum += e;
      if (on && e < 1e-3) ++*on;
    }
    return sum / double(m.positions.size());
  };
  std::size_t on = 0;
  const double before = misfit(plain), after = misfit(snapped, &on);
  std::printf("mean |f - iso| at the vertices: %.4f without snapping, %.5f with (%zu of %zu on f = iso)\n",
              before, after, on, snapped.positions.size());
  // Vertices whose crossing is more than a voxel away (or whose move would flip a triangle)
  // stay on the approximation's surface: about 8 % here.
  EXPECT_GT(on, snapped.positions.size() * 85 / 100);
  EXPECT_LT(after, before / 5);
}

TEST(Convert, SimplifyShrinksTheAssetWithinItsTolerance) {
  const std::string full = scratch() + "/simp_full.ply", simp = scratch() + "/simp.ply",
                    glb = scratch() + "/simp.glb";
  const std::string common = kSkull + " --iso 3 --max-vertices 8000 --quiet";
  ASSERT_EQ(run("convert " + common + " --simplify 0 -o " + full).status, 0);
  ASSERT_EQ(run("convert " + common + " --simplify 0.3 --simplifier bounded -o " + simp).status, 0);
  ASSERT_EQ(run("convert " + common + " --simplify 0.3 --simplifier bounded -o " + glb).status, 0);
  const TriangleMesh a = read_mesh_file(full), b = read_mesh_file(simp);
  EXPECT_LT(b.triangle_count(), a.triangle_count() / 2);
  // Every vertex of the extracted surface (every 7th, brute force) stays within 0.3 of the
  // smallest voxel spacing of the simplified one.
  const ScalarGrid g = read_volume(kSkull);
  const double tol = 0.3 * std::min({g.transform.spacing[0], g.transform.spacing[1], g.transform.spacing[2]});
  const double worst = test::one_sided_hausdorff(a, b, 7);
  EXPECT_LE(worst, tol * 1.01);
  std::string report;
  EXPECT_TRUE(validator_accepts(glb, &report)) << report;

  // --normals gradient: the simplified surface keeps the paper's normals, each vertex has the
  // normal the extracted surface has at the same position (so --placement auto keeps the
  // vertices in place: the same positions as --placement input).
  const std::string grad = scratch() + "/simp_gradient.ply", pinned = scratch() + "/simp_pinned.ply";
  ASSERT_EQ(
      run("convert " + common + " --simplify 0.3 --simplifier bounded --normals gradient -o " + grad).status,
      0);
  ASSERT_EQ(
      run("convert " + common + " --simplify 0.3 --simplifier bounded --placement input -o " + pinned).status,
      0);
  const TriangleMesh kept = read_mesh_file(grad);
  ASSERT_EQ(kept.positions, read_mesh_file(pinned).positions);
  ASSERT_NE(kept.positions, b.positions);  // the default moves vertices (optimal placement)
  std::map<std::array<float, 3>, std::array<float, 3>> normal_at;
  for (std::size_t i = 0; i < a.positions.size(); ++i) normal_at[a.positions[i]] = a.normals[i];
  ASSERT_EQ(kept.normals.size(), kept.positions.size());
  for (std::size_t i = 0; i < kept.positions.size(); ++i) {
    const auto it = normal_at.find(kept.positions[i]);
    ASSERT_NE(it, normal_at.end());
    for (int k = 0; k < 3; ++k) ASSERT_NEAR(kept.normals[i][k], it->second[k], 1e-6);
  }
  // --normals surface, and the default after --simplify: area-weighted normals of the written
  // triangles instead.
  const std::string surf = scratch() + "/simp_surface.ply";
  ASSERT_EQ(
      run("convert " + common + " --simplify 0.3 --simplifier bounded --normals surface -o " + surf).status,
      0);
  EXPECT_EQ(read_bytes(surf), read_bytes(simp));
  ASSERT_EQ(run("convert " + common +
                " --simplify 0.3 --simplifier bounded --normals surface --placement input -o " + surf)
                .status,
            0);
  EXPECT_EQ(read_bytes(surf), read_bytes(pinned));
  const TriangleMesh c = read_mesh_file(surf);
  ASSERT_EQ(c.positions, kept.positions);
  TriangleMesh expected = c;
  compute_area_weighted_normals(expected);
  double differ = 0;
  for (std::size_t i = 0; i < c.normals.size(); ++i)
    for (int k = 0; k < 3; ++k) {
      ASSERT_NEAR(c.normals[i][k], expected.normals[i][k], 1e-5);
      differ = std::max(differ, double(std::abs(c.normals[i][k] - kept.normals[i][k])));
    }
  EXPECT_GT(differ, 0.05);  // the two kinds are really different
  // Without simplification the default is the paper's normals.
  const std::string full_grad = scratch() + "/full_gradient.ply";
  ASSERT_EQ(run("convert " + common + " --simplify 0 --normals gradient -o " + full_grad).status, 0);
  EXPECT_EQ(read_bytes(full_grad), read_bytes(full));
  EXPECT_EQ(run("convert " + common + " --simplify 0 --normals flat -o " + surf).status, 1);
}

// --placement optimal: vertices at the quadric minimum, kept within the tolerance of the
// extracted surface both ways; fewer triangles on the CT at the same tolerance; same bytes for
// any thread count; recorded in the asset.
TEST(Convert, OptimalPlacementIsSmallerAndStaysWithinTheToleranceBothWays) {
  const std::string full = scratch() + "/opt_full.ply", pinned = scratch() + "/opt_pinned.ply",
                    one = scratch() + "/opt1.ply", two = scratch() + "/opt2.ply",
                    glb = scratch() + "/opt.glb";
  const std::string common = kSkull + " --iso 1.5 --max-vertices 8000 --ratio 0 --quiet";  // the bound alone
  ASSERT_EQ(run("convert " + common + " --simplify 0 -o " + full).status, 0);
  ASSERT_EQ(
      run("convert " + common + " --simplify 0.3 --simplifier bounded --placement input -o " + pinned).status,
      0);
  ASSERT_EQ(run("--threads 1 convert " + common +
                " --simplify 0.3 --simplifier bounded --placement optimal -o " + one)
                .status,
            0);
  ASSERT_EQ(run("--threads 2 convert " + common +
                " --simplify 0.3 --simplifier bounded --placement optimal -o " + two)
                .status,
            0);
  EXPECT_EQ(read_bytes(one), read_bytes(two));
  const std::string dflt = scratch() + "/opt_default.ply";  // auto: optimal with surface normals
  ASSERT_EQ(run("convert " + common + " --simplify 0.3 --simplifier bounded -o " + dflt).status, 0);
  EXPECT_EQ(read_bytes(dflt), read_bytes(two));
  const TriangleMesh a = read_mesh_file(full), b = read_mesh_file(pinned), c = read_mesh_file(two);
  std::printf("triangles: %zu extracted, %zu input placement, %zu optimal placement\n", a.triangle_count(),
              b.triangle_count(), c.triangle_count());
  EXPECT_LT(c.triangle_count(), b.triangle_count() * 9 / 10);
  const ScalarGrid g = read_volume(kSkull);
  const double tol = 0.3 * std::min({g.transform.spacing[0], g.transform.spacing[1], g.transform.spacing[2]});
  EXPECT_LE(test::one_sided_hausdorff(a, c, 5), tol * 1.01);
  EXPECT_LE(test::one_sided_hausdorff(c, a), tol * 1.01);
  // Vertices really moved: most are no extracted vertex.
  const std::set<std::array<float, 3>> extracted(a.positions.begin(), a.positions.end());
  std::size_t moved = 0;
  for (const auto& p : c.positions) moved += !extracted.count(p);
  EXPECT_GT(moved, c.positions.size() / 2);
  ASSERT_EQ(
      run("convert " + common + " --simplify 0.3 --simplifier bounded --placement optimal -o " + glb).status,
      0);
  std::string report;
  EXPECT_TRUE(validator_accepts(glb, &report)) << report;
  EXPECT_EQ(parse_glb(read_bytes(glb)).gltf["asset"]["extras"]["placement"], "optimal");
  EXPECT_EQ(
      run("convert " + common + " --simplify 0.3 --simplifier bounded --placement best -o " + glb).status, 1);
}

// Several surfaces are simplified at once, each in a fresh process here: OpenMesh's global log
// streams, first touched concurrently by two surfaces, once crashed about one run in five
// (README's main command). Every run must succeed, and match the single-threaded output.
TEST(Convert, ConcurrentSimplificationIsStableAndDeterministic) {
  const std::string args = " convert " + kSkull +
                           " --iso 1,1.5,2,3 --max-vertices 3000 --simplify 0.3 --simplifier bounded --quiet";
  const std::string one = scratch() + "/cs1.ply";
  ASSERT_EQ(run("--threads 1" + args + " -o " + one).status, 0);
  for (int i = 0; i < 8; ++i) {
    const std::string two = scratch() + "/cs2.ply";
    ASSERT_EQ(run("--threads 2" + args + " -o " + two).status, 0) << "run " << i;
    ASSERT_EQ(read_bytes(two), read_bytes(one)) << "run " << i;
  }
}

// Golden files: tests/golden holds the expected outputs of small conversions. The PLY is
// compared byte for byte (the pipeline is deterministic); the glb's Draco geometry is decoded
// and compared semantically (counts, box, every vertex near the golden surface), since Draco
// reorders vertices. Regenerate with MLFE_UPDATE_GOLDEN=1 after an intended change.
// `mlfe convert ARGS -o X.ply` gives the bytes of tests/golden/NAME.
void expect_golden_ply(const std::string& args, const std::string& name) {
  const std::string ply = scratch() + "/" + name;
  ASSERT_EQ(run("convert " + args + " -o " + ply).status, 0);
  const std::string golden_ply = kGolden + "/" + name;
  if (std::getenv("MLFE_UPDATE_GOLDEN")) fs::copy_file(ply, golden_ply, fs::copy_options::overwrite_existing);
  ASSERT_TRUE(fs::exists(golden_ply)) << "missing golden file " << golden_ply;
  const std::string got = read_bytes(ply), want = read_bytes(golden_ply);
  // Not EXPECT_EQ on the strings: a failure would print megabytes of binary.
  std::size_t first_diff = 0;
  while (first_diff < std::min(got.size(), want.size()) && got[first_diff] == want[first_diff]) ++first_diff;
  EXPECT_TRUE(got == want) << name << " differs from the golden file: " << got.size() << " vs " << want.size()
                           << " bytes, first difference at byte " << first_diff << "; header now:\n"
                           << got.substr(0, got.find("end_header"));
}

TEST(Golden, SkullConversionMatchesCheckedInOutputs) {
  const std::string glb = scratch() + "/golden.glb";
  const std::string args = kSkull + " --iso 2.5 --max-vertices 3000 --simplify 0 --quiet";
  expect_golden_ply(args, "ct_skull_iso2.5_3000.ply");
  ASSERT_EQ(run("convert " + args + " -o " + glb).status, 0);
  const std::string golden_ply = kGolden + "/ct_skull_iso2.5_3000.ply";

  const TriangleMesh golden = read_mesh_file(golden_ply);
  const Glb g = parse_glb(read_bytes(glb));
  ASSERT_EQ(g.gltf["meshes"].size(), 1u);
  const auto& prim = g.gltf["meshes"][0]["primitives"][0];
  const auto& view =
      g.gltf["bufferViews"][prim["extensions"]["KHR_draco_mesh_compression"]["bufferView"].get<int>()];
  const std::string bytes = g.bin.substr(view.value("byteOffset", 0), view["byteLength"].get<std::size_t>());
  const TriangleMesh dec = decode_draco(bytes.data(), bytes.size(), "golden glb");
  EXPECT_EQ(dec.triangles.size(), golden.triangles.size());
  EXPECT_EQ(dec.positions.size(), golden.positions.size());
  // Every decoded vertex (metres, glTF frame) near a golden vertex: Hausdorff bound = the
  // Draco tolerance (a tenth of the smallest voxel spacing, 0.3651 mm).
  const auto M = physical_to_gltf_matrix("RAS");
  std::vector<std::array<double, 3>> gm;
  for (const auto& p : golden.positions) {
    std::array<double, 3> q{};
    for (int r = 0; r < 3; ++r) q[r] = M[3 * r] * p[0] + M[3 * r + 1] * p[1] + M[3 * r + 2] * p[2];
    gm.push_back(q);
  }
  std::sort(gm.begin(), gm.end());
  double worst = 0;
  for (const auto& p : dec.positions) {
    double best = 1e30;
    // Sorted by x: scan the window of x within the current best.
    auto it = std::lower_bound(gm.begin(), gm.end(), std::array<double, 3>{p[0] - 1e-3, -1e30, -1e30});
    for (; it != gm.end() && (*it)[0] <= p[0] + 1e-3; ++it) {
      const double d =
          std::sqrt((p[0] - (*it)[0]) * (p[0] - (*it)[0]) + (p[1] - (*it)[1]) * (p[1] - (*it)[1]) +
                    (p[2] - (*it)[2]) * (p[2] - (*it)[2]));
      best = std::min(best, d);
    }
    worst = std::max(worst, best);
  }
  EXPECT_LE(worst, 0.3651e-3 * std::sqrt(3.0))
      << "decoded Draco geometry too far from the golden surface (m)";
}

// The README's main job on a small budget: snapped, simplified (default placement) surfaces.
TEST(Golden, SimplifiedSkullAssetMatchesCheckedInPly) {
  expect_golden_ply(
      kSkull + " --iso 1.5,3 --max-vertices 8000 --simplify 0.2 --ratio 0 --simplifier bounded --quiet",
      "ct_skull_iso1.5_3_8000_simplify0.2.ply");
}

// --ratio: simplification stops at that fraction of the extracted triangles unless the bound
// binds first; 0 leaves the bound alone, which removes more.
TEST(Convert, RatioStopsTheSimplificationAtAFractionOfTheExtraction) {
  const std::string raw = scratch() + "/ratio_raw.ply", dflt = scratch() + "/ratio_default.ply",
                    quarter = scratch() + "/ratio_quarter.ply", bound = scratch() + "/ratio_bound.ply";
  const std::string common = "convert " + kSkull + " --iso 2.5 --quiet -o ";
  ASSERT_EQ(run(common + raw + " --simplify 0").status, 0);
  ASSERT_EQ(run(common + dflt).status, 0);
  ASSERT_EQ(run(common + quarter + " --ratio 0.25").status, 0);
  ASSERT_EQ(run(common + bound + " --ratio 0").status, 0);
  const std::size_t n = read_mesh_file(raw).triangle_count();
  const std::size_t d = read_mesh_file(dflt).triangle_count(), q = read_mesh_file(quarter).triangle_count(),
                    b = read_mesh_file(bound).triangle_count();
  std::printf("triangles: %zu extracted; ratio 0.1: %zu, 0.25: %zu, 0 (bound only): %zu\n", n, d, q, b);
  // A collapse removes two triangles (one on the volume's faces), and a pass may end one past
  // the floor.
  EXPECT_LE(d, n / 10 + 2);
  EXPECT_GE(d, n / 10 - 2);
  EXPECT_LE(q, n / 4 + 2);
  EXPECT_GE(q, n / 4 - 2);
  EXPECT_LT(b, d);
  EXPECT_EQ(run(common + dflt + " --ratio 1.5").status, 1);  // usage
}

// The default surface: marching cubes on the samples (no global target, the finest level), raw.
TEST(Golden, SkullSurfaceFromTheSamplesMatchesCheckedInPly) {
  expect_golden_ply(kSkull + " --iso 2.5 --simplify 0 --quiet", "ct_skull_iso2.5_samples.ply");
  expect_golden_ply(kSkull + " --iso 2.5 --simplify 0 --surface samples --max-vertices 3000 --quiet",
                    "ct_skull_iso2.5_samples.ply");
}

TEST(Convert, HeightFieldBecomesAValidTerrainAsset) {
  const std::string dem = test::sample_path("dem_jacksboro.nrrd");
  const std::string glb = scratch() + "/dem.glb", rep = scratch() + "/dem.json";
  ASSERT_EQ(
      run("convert " + dem + " --rms 1% --z-scale 0.00001 --quiet -o " + glb + " --report " + rep).status, 0);
  std::string report;
  EXPECT_TRUE(validator_accepts(glb, &report)) << report;
  const json r = json::parse(read_bytes(rep));
  EXPECT_LE(r["rms_error_percent"].get<double>(), 1.0);
  EXPECT_LT(r["vertices"].get<double>(), 403.0 * 344.0 / 4);

  // Simplified terrain (open surface: the rim stays within the tolerance too), both
  // placements: fewer triangles, the bound both ways, and a valid asset.
  const std::string full = scratch() + "/dem.ply";
  const std::string common = " convert " + dem + " --rms 1% --z-scale 0.00001 --quiet";
  ASSERT_EQ(run(common + " --simplify 0 -o " + full).status, 0);
  const TriangleMesh a = read_mesh_file(full);
  for (const std::string placement : {"input", "optimal"}) {
    const std::string ply = scratch() + "/dem_" + placement + ".ply", sglb = scratch() + "/dem_s.glb";
    ASSERT_EQ(
        run(common + " --simplify 0.5 --simplifier bounded --placement " + placement + " -o " + ply).status,
        0);
    ASSERT_EQ(
        run(common + " --simplify 0.5 --simplifier bounded --placement " + placement + " -o " + sglb).status,
        0);
    EXPECT_TRUE(validator_accepts(sglb, &report)) << report;
    const TriangleMesh b = read_mesh_file(ply);
    EXPECT_LT(b.triangle_count(), a.triangle_count() / 2) << placement;
    const ScalarGrid g = read_volume(dem);
    const double tol = 0.5 * std::min(g.transform.spacing[0], g.transform.spacing[1]);
    EXPECT_LE(test::one_sided_hausdorff(a, b, 3), tol * 1.01) << placement;
    EXPECT_LE(test::one_sided_hausdorff(b, a), tol * 1.01) << placement;
  }
}

TEST(Build, ReportHasTheDocumentedFields) {
  const std::string h = scratch() + "/b.mlfeh", rep = scratch() + "/b.json";
  ASSERT_EQ(run("build " + kSkull + " --rms 2% --quiet -o " + h + " --report " + rep).status, 0);
  const json r = json::parse(read_bytes(rep));
  for (const char* k :
       {"input", "dims", "voxels", "vertices", "elements", "levels", "iterations", "rms_error",
        "rms_error_percent", "psnr_db", "value_range", "seconds", "peak_rss_mb", "per_iteration"})
    EXPECT_TRUE(r.contains(k)) << k;
  EXPECT_LE(r["rms_error_percent"].get<double>(), 2.0);
  EXPECT_EQ(r["voxels"].get<long>(), 64 * 64 * 64);
  EXPECT_EQ(r["per_iteration"].size(), r["iterations"].get<std::size_t>());
}

TEST(BadInput, ExitsWithStatusTwoOneLineAndNoOutput) {
  // Truncated volume.
  const std::string bad = scratch() + "/truncated.nrrd";
  {
    const std::string b = read_bytes(kSkull);
    std::ofstream(bad, std::ios::binary) << b.substr(0, b.size() / 2);
  }
  struct Case {
    std::string args, out, must_mention;
  };
  const std::vector<Case> cases = {
      {"convert " + bad + " --iso 1 -o " + scratch() + "/x1.glb", scratch() + "/x1.glb", "truncated.nrrd"},
      {"convert " + kSkull + " --iso 1 -o " + scratch() + "/x2.xyz", scratch() + "/x2.xyz", "x2.xyz"},
      {"convert " + kSkull + " -o " + scratch() + "/x4.glb", scratch() + "/x4.glb", "--iso"},
      {"iso " + bad + " --iso 1 -o " + scratch() + "/x5.ply", scratch() + "/x5.ply", "truncated.nrrd"},
      {"convert " + kSkull + " --iso 1 -o /nonexistent/dir/x6.glb", "/nonexistent/dir/x6.glb", "x6.glb"},
      {"build " + std::string(MLFE_SOURCE_DIR) + "/README.md -o " + scratch() + "/x7.mlfeh",
       scratch() + "/x7.mlfeh", "README.md"},
  };
  for (const auto& c : cases) {
    const RunResult r = run(c.args);
    EXPECT_EQ(r.status, 2) << c.args << "\n" << r.err;
    EXPECT_NE(r.err.find(c.must_mention), std::string::npos) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << "not one line: " << r.err;
    EXPECT_FALSE(fs::exists(c.out)) << c.out;
  }
  // A bad option value is a usage error (1), like every other; still one line and no output.
  const RunResult r = run("convert " + kSkull + " --iso abc -o " + scratch() + "/x3.glb");
  EXPECT_EQ(r.status, 1) << r.err;
  EXPECT_NE(r.err.find("--iso"), std::string::npos) << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << "not one line: " << r.err;
  EXPECT_FALSE(fs::exists(scratch() + "/x3.glb"));
  // No temporaries left next to the outputs.
  for (const auto& e : fs::directory_iterator(scratch()))
    EXPECT_EQ(e.path().filename().string().rfind(".tmp-", 0), std::string::npos) << e.path();
}

// The iso-aware loop with a global target used to trickle in a few surface elements per full
// solve (the skull: 0.1-2 % more vertices per iteration); it now ends within two iterations of
// the first that adds less than 1 %, and says so.
TEST(Convert, IsoAwareRefinementDoesNotStall) {
  const std::string rep = scratch() + "/stall.json";
  ASSERT_EQ(run("convert " + kSkull + " --rms 1% --iso 1.5,3 --simplify 0 --quiet -o " + scratch() +
                "/stall.ply --report " + rep)
                .status,
            0);
  const json r = json::parse(read_bytes(rep));
  const auto& its = r["per_iteration"];
  std::size_t first_small = its.size();
  for (std::size_t i = 1; i < its.size(); ++i)
    if (its[i]["vertices"].get<double>() < 1.01 * its[i - 1]["vertices"].get<double>()) {
      first_small = i;
      break;
    }
  EXPECT_LE(its.size(), first_small + 2);
  // On the samples' lattice the loop may also meet its target before growth falls below 1 %.
  const std::string stop = r["stop_reason"].get<std::string>();
  EXPECT_TRUE(stop.find("stalled") != std::string::npos || stop == "target RMS error reached") << stop;
}

// Defaults at work: a big sphere and, 25 voxels away, a sphere two voxels across. The default
// convert (surface-driven, simplified) keeps the small part, writes fewer triangles than the
// raw extraction, and the same bytes with 1 and 2 threads.
TEST(Convert, DefaultConvertKeepsSmallPartsAndIsDeterministic) {
  const std::string vol = scratch() + "/spheres.raw";
  {
    std::vector<float> v(64 * 64 * 64);
    for (int k = 0; k < 64; ++k)
      for (int j = 0; j < 64; ++j)
        for (int i = 0; i < 64; ++i) {
          auto d = [&](double x, double y, double z) {
            return std::sqrt((i - x) * (i - x) + (j - y) * (j - y) + (k - z) * (k - z));
          };
          v[i + 64 * (j + 64 * k)] = float(std::max(20.0 - d(24, 24, 24), 1.0 - d(54, 54, 54)));
        }
    std::ofstream f(vol, std::ios::binary);
    f.write(reinterpret_cast<const char*>(v.data()), std::streamsize(v.size() * 4));
    std::ofstream j(vol + ".json");
    j << R"({"dims": [64, 64, 64], "spacing": [1, 1, 1], "dtype": "float32", "endian": "little"})";
  }
  const std::string a = scratch() + "/sph1.ply", b = scratch() + "/sph2.ply", raw = scratch() + "/sphraw.ply";
  ASSERT_EQ(run("--threads 1 convert " + vol + " --iso 0 --quiet -o " + a).status, 0);
  ASSERT_EQ(run("--threads 2 convert " + vol + " --iso 0 --quiet -o " + b).status, 0);
  ASSERT_EQ(run("convert " + vol + " --iso 0 --simplify 0 --quiet -o " + raw).status, 0);
  EXPECT_EQ(read_bytes(a), read_bytes(b));
  const TriangleMesh m = read_mesh_file(a), full = read_mesh_file(raw);
  EXPECT_LT(m.triangle_count(), full.triangle_count());
  int near_small = 0;
  for (const auto& p : m.positions) {
    const double d =
        std::sqrt((p[0] - 54) * (p[0] - 54) + (p[1] - 54) * (p[1] - 54) + (p[2] - 54) * (p[2] - 54));
    if (d < 1.6) ++near_small;
  }
  EXPECT_GE(near_small, 4);  // a closed little surface around (54, 54, 54)
}

// A surface-driven convert solves for u only when an output holds it: without --hierarchy the
// report has no iterations and no RMS error; with it, u is solved and stored. The asset comes
// from the data's interpolant either way, so its bytes do not change. By default that asset is
// the samples' own surface, so without --hierarchy nothing is refined at all.
TEST(Convert, SurfaceDrivenConvertSolvesOnlyWhenAnOutputNeedsU) {
  const std::string a = scratch() + "/nou.ply", b = scratch() + "/withu.ply", h = scratch() + "/withu.mlfeh";
  const std::string ra = scratch() + "/nou.json", rb = scratch() + "/withu.json";
  const std::string tets = " --surface hierarchy";
  ASSERT_EQ(run("convert " + kSkull + " --iso 1.5 --quiet -o " + a + " --report " + ra + tets).status, 0);
  ASSERT_EQ(
      run("convert " + kSkull + " --iso 1.5 --quiet -o " + b + " --report " + rb + " --hierarchy " + h + tets)
          .status,
      0);
  EXPECT_EQ(read_bytes(a), read_bytes(b));
  const json ja = json::parse(read_bytes(ra)), jb = json::parse(read_bytes(rb));
  EXPECT_EQ(ja["iterations"].get<int>(), 0);
  EXPECT_FALSE(ja.contains("rms_error"));
  EXPECT_TRUE(ja.contains("u"));
  EXPECT_GE(jb["iterations"].get<int>(), 1);
  EXPECT_GT(jb["rms_error"].get<double>(), 0);
  EXPECT_EQ(ja["vertices"], jb["vertices"]);  // the same mesh: the surface passes decide it
  const std::string c = scratch() + "/fromh.ply";
  ASSERT_EQ(run("iso " + h + " --iso 1.5 --quiet -o " + c).status, 0);  // the stored u extracts
  // From the samples (the default): the hierarchy only when an output holds it, the same asset.
  const std::string s1 = scratch() + "/samples1.ply", s2 = scratch() + "/samples2.ply",
                    rs = scratch() + "/samples.json";
  ASSERT_EQ(run("convert " + kSkull + " --iso 1.5 --quiet -o " + s1 + " --report " + rs).status, 0);
  ASSERT_EQ(run("convert " + kSkull + " --iso 1.5 --quiet -o " + s2 + " --hierarchy " + h).status, 0);
  EXPECT_EQ(read_bytes(s1), read_bytes(s2));
  const json js = json::parse(read_bytes(rs));
  EXPECT_EQ(js["vertices"].get<int>(), 8);
  EXPECT_NE(js["stop_reason"].get<std::string>().find("samples"), std::string::npos);
  EXPECT_EQ(js["asset"]["surface"].get<std::string>(), "samples");
  // A hierarchy file has no samples to take them from.
  const std::string none = scratch() + "/nosamples.ply";
  EXPECT_EQ(run("iso " + h + " --iso 1.5 --surface samples --quiet -o " + none).status, 1);
  EXPECT_FALSE(fs::exists(none));
}

// --max-memory: a build that would not fit stops refining with a message, and still writes.
TEST(Convert, MemoryBudgetStopsWithAMessage) {
  const std::string out = scratch() + "/mem.ply", rep = scratch() + "/mem.json";
  const RunResult r = run("convert " + kSkull + " --iso 1.5 --surface hierarchy --max-memory 12M -o " + out +
                          " --report " + rep);
  EXPECT_EQ(r.status, 0);
  EXPECT_NE(r.err.find("memory budget"), std::string::npos) << r.err;
  EXPECT_TRUE(json::parse(read_bytes(rep))["memory_limited"].get<bool>());
  EXPECT_EQ(run("convert " + kSkull + " --iso 1.5 --max-memory lots -o " + out).status, 1);  // usage
}

}  // namespace
}  // namespace mlfe
