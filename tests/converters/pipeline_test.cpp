// The pipeline library (include/mlfe/pipeline.h) without the command line: its defaults give the
// command line's bytes, extract() and write_assets() agree, the 2D/3D holder, and bad input
// throws mlfe::Error before any output is written.
#include <gtest/gtest.h>
#include <mlfe/core/base/error.h>
#include <mlfe/formats/hierarchy_io.h>
#include <mlfe/formats/volume_reader.h>
#include <mlfe/pipeline.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "tests/test_meshes.h"
#include "tests/test_paths.h"

namespace fs = std::filesystem;

namespace mlfe {
namespace {

using test::read_bytes;

const std::string kSkull = test::sample_path("ct_skull_64.nrrd");

std::string scratch() { return test::scratch_dir("pipeline"); }

std::string cli_convert(const std::string& args, const std::string& out) {
  const std::string cmd = std::string(MLFE_BINARY) + " convert " + kSkull + " " + args + " --quiet -o " +
                          out + " > /dev/null 2>&1";
  EXPECT_EQ(std::system(cmd.c_str()), 0) << cmd;
  return read_bytes(out);
}

TEST(Pipeline, DefaultsGiveTheGoldenFile) {
  ConvertOptions o;
  o.asset.iso = {2.5};
  o.build.max_vertices = 3000;
  o.asset.simplify = 0;
  const std::string out = scratch() + "/golden.ply";
  const ConvertResult r = convert(kSkull, out, o);
  EXPECT_EQ(read_bytes(out), read_bytes(test::golden_path("ct_skull_iso2.5_3000.ply")));
  EXPECT_EQ(r.built.dim(), 3);
  EXPECT_LE(r.built.vertices(), 3000u);
  EXPECT_EQ(r.asset["triangles"].get<std::size_t>(), r.asset["surfaces"][0]["triangles"].get<std::size_t>());
}

TEST(Pipeline, DefaultsAreTheCommandLines) {
  // Surface-driven build, simplified, snapped, Draco glTF with provenance: the same bytes.
  ConvertOptions o;
  o.asset.iso = {1.5, 3.0};
  const std::string api = scratch() + "/api.glb", cli = scratch() + "/cli.glb";
  convert(kSkull, api, o);
  EXPECT_TRUE(read_bytes(api) == cli_convert("--iso 1.5,3", cli)) << "defaults differ from mlfe convert's";
  // Global targets, typed: --rms 3% --max-vertices 6000 --norm h1 --normals gradient
  // --simplifier bounded.
  o.build.rms = RmsTarget{3.0, true};
  o.build.max_vertices = 6000;
  o.build.norm = Norm::kH1;
  o.asset.normals = Normals::kGradient;
  o.asset.simplifier = Simplifier::kBounded;
  convert(kSkull, api, o);
  EXPECT_TRUE(
      read_bytes(api) ==
      cli_convert(
          "--iso 1.5,3 --rms 3% --max-vertices 6000 --norm h1 --normals gradient --simplifier bounded", cli));
}

TEST(Pipeline, ExtractAgreesWithWriteAssetsAndKeepsTheVolumesSurfaces) {
  const ScalarGrid grid = read_volume(kSkull);
  BuildOptions bo;
  bo.max_vertices = 4000;
  std::size_t iterations = 0;
  bo.progress = [&](const IterationStats&) { ++iterations; };
  const Built b = build(grid, bo, {1.5, 3.0});
  EXPECT_EQ(iterations, b.iterations().size());
  EXPECT_FALSE(b.surface_driven);
  AssetOptions ao;
  ao.iso = {3.0, 1.5};  // sorted by extract
  const Surfaces s = extract(b, ao, &grid);
  ASSERT_EQ(s.surfaces.size(), 2u);
  EXPECT_EQ(s.iso_values, (std::vector<double>{1.5, 3.0}));
  EXPECT_TRUE(s.snapped);
  EXPECT_EQ(s.normals, Normals::kSurface);  // auto after simplification
  EXPECT_EQ(s.placement, VertexPlacement::kOptimal);
  const nlohmann::json summary = write_assets(scratch() + "/x.obj", b, ao, {}, &grid);
  for (int i = 0; i < 2; ++i)
    EXPECT_EQ(summary["surfaces"][i]["triangles"].get<std::size_t>(), s.surfaces[i].mesh.triangles.size());
  // Without the volume: no snapping, u's own surfaces.
  EXPECT_FALSE(extract(b, ao, nullptr).snapped);
}

TEST(Pipeline, OneHolderFor2DAnd3D) {
  const ScalarGrid dem = read_volume(test::sample_path("dem_jacksboro.nrrd"));
  BuildOptions o;
  o.rms = RmsTarget{2.0, true};
  const Built b = build(dem, o);
  EXPECT_EQ(b.dim(), 2);
  EXPECT_EQ(b.values().size(), b.vertices());
  EXPECT_EQ(b.get<2>().hierarchy.vertex_count(), b.vertices());
  EXPECT_LE(b.iterations().back().rms_percent, 2.0);
  AssetOptions ao;
  ao.simplify = 0;
  const Surfaces s = extract(b, ao);
  ASSERT_EQ(s.surfaces.size(), 1u);
  EXPECT_EQ(s.surfaces[0].mesh.positions.size(), b.vertices());
}

// Runs `f`, expecting an mlfe::Error whose message contains `part`.
template <class F>
void expect_error(F&& f, const std::string& part) {
  try {
    f();
    ADD_FAILURE() << "no mlfe::Error; expected one containing '" << part << "'";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(part), std::string::npos) << e.what();
  }
}

// Issue 42: the hierarchy file keeps the build's record; a record of the wrong shape names the file.
TEST(Pipeline, TheFileKeepsTheBuildRecord) {
  const ScalarGrid skull = read_volume(kSkull);
  BuildOptions o;
  o.max_vertices = 3000;
  const Built b = build(skull, o, {2.5});
  const std::string path = scratch() + "/record.mlfeh";
  write_built(path, b, {{"input", kSkull}});
  const Built loaded = built_from_file(path);
  EXPECT_FALSE(b.stop_reason().empty());
  EXPECT_EQ(build_record(loaded), build_record(b));
  EXPECT_EQ(loaded.stop_reason(), b.stop_reason());
  ASSERT_EQ(loaded.iterations().size(), b.iterations().size());
  EXPECT_EQ(loaded.iterations().back().l2_error, b.iterations().back().l2_error);
  EXPECT_EQ(build_record(b)["options"]["max_vertices"], 3000);

  HierarchyFileInfo info;
  info.transform = b.transform;
  info.value_min = b.value_min;
  info.value_max = b.value_max;
  info.metadata = {{"build", {{"stop_reason", 7}}}};
  write_hierarchy(path, b.get<3>().hierarchy, b.values(), info);
  expect_error([&] { built_from_file(path); }, "record.mlfeh: the build record in the metadata is malformed");
}

TEST(Pipeline, BadInputThrowsBeforeWriting) {
  const std::string out = scratch() + "/bad.glb";
  ScalarGrid flat;
  flat.dims = {1, 8, 8};
  flat.values.assign(64, 1.0f);
  flat.source = "flat";
  ConvertOptions o;
  o.asset.iso = {0.5};
  expect_error([&] { convert(flat, out, o); }, "flat: needs at least 2 samples along every axis");
  ScalarGrid short_grid = flat;
  short_grid.dims = {4, 4, 8};
  short_grid.values.resize(100);
  expect_error([&] { convert(short_grid, out, o); }, "100 values do not fill dims 4x4x8");
  expect_error([&] { convert(kSkull, out, ConvertOptions{}); }, "iso is required");
  expect_error([&] { convert(kSkull, scratch() + "/no/such/folder/x.glb", o); }, "does not exist");
  expect_error([&] { convert(kSkull, scratch() + "/x.xyz", o); }, "unknown output type '.xyz'");
  ConvertOptions bad = o;
  bad.build.max_level = 41;
  expect_error([&] { convert(kSkull, out, bad); }, "max_level: expected 0..40, got 41");
  bad = o;
  bad.build.rms = RmsTarget{-1, true};
  expect_error([&] { convert(kSkull, out, bad); }, "rms: expected one positive value");
  bad = o;
  bad.asset.lod = 9;
  expect_error([&] { convert(kSkull, out, bad); }, "lod");
  bad = o;
  bad.build.max_memory = MemoryBudget{150, true};
  expect_error([&] { convert(kSkull, out, bad); }, "150%");
  EXPECT_FALSE(fs::exists(out));
}

TEST(Pipeline, MemoryBudgetText) {
  EXPECT_EQ(MemoryBudget{}.text(), "50%");
  EXPECT_EQ((MemoryBudget{6, false, 3}.text()), "6G");
  EXPECT_EQ((MemoryBudget{512, false, 2}.bytes()), 512u << 20);
  EXPECT_EQ((MemoryBudget{0, false, 0}.bytes()), 0u);
}

}  // namespace
}  // namespace mlfe
