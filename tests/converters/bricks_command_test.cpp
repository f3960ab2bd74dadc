// `mlfe convert --bricks B` (core/simplify/bricked_iso_surface.h): the same bytes for any thread
// count, a surface as clean as the unbricked one and of about its size, and the option's
// refusals (no output written).
#include <gtest/gtest.h>
#include <mlfe/core/base/error.h>
#include <mlfe/formats/brick_parts.h>
#include <mlfe/formats/volume_reader.h>
#include <mlfe/formats/volume_writer.h>
#include <mlfe/pipeline.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "tests/test_meshes.h"
#include "tests/test_paths.h"

namespace mlfe {
namespace {

using nlohmann::json;

const std::string kSkull = test::sample_path("ct_skull_64.nrrd");

std::string scratch() { return test::scratch_dir("bricks"); }

// The report's first surface after `mlfe convert` of the CT sample with `extra`.
json convert(const std::string& extra, const std::string& out) {
  const std::string report = out + ".json";
  const test::CliResult r = test::run_mlfe("convert " + kSkull + " --iso 1.5 --surface samples --quiet " +
                                           extra + " -o " + out + " --report " + report);
  EXPECT_EQ(r.status, 0) << r.err;
  std::ifstream in(report);
  return json::parse(in)["asset"]["surfaces"][0];
}

TEST(BricksCommand, SameBytesAtOneTwoAndSevenThreads) {
  std::string first;
  for (int threads : {1, 2, 7}) {
    const std::string out = scratch() + "/t" + std::to_string(threads) + ".glb";
    convert("--bricks 16 --threads " + std::to_string(threads), out);
    const std::string bytes = test::read_bytes(out);
    if (threads == 1)
      first = bytes;
    else
      EXPECT_EQ(bytes, first) << threads << " threads";
  }
  EXPECT_FALSE(first.empty());
}

TEST(BricksCommand, AsCleanAsUnbrickedAndAboutItsSize) {
  const json whole = convert("", scratch() + "/whole.glb");
  for (const char* b : {"8", "16", "32"}) {
    const json bricked = convert(std::string("--bricks ") + b, scratch() + "/bricked" + b + ".glb");
    // The same welded manifold; the surface's cuts by the volume's faces (boundary edges) may
    // keep a few vertices more (where a brick face meets the volume's face they are held until
    // the seam pass).
    json t = bricked["topology"], w = whole["topology"];
    EXPECT_GT(t["boundary_edges"].get<int>(), 0);
    EXPECT_LE(t["boundary_edges"].get<double>(), 2 * w["boundary_edges"].get<double>());
    t.erase("boundary_edges");
    w.erase("boundary_edges");
    EXPECT_EQ(t, w) << "--bricks " << b;
    EXPECT_EQ(t["duplicate_vertices"], 0);
    EXPECT_EQ(t["non_manifold_edges"], 0);
    EXPECT_EQ(bricked["parts"], whole["parts"]);
    const double ratio = bricked["triangles"].get<double>() / whole["triangles"].get<double>();
    EXPECT_GT(ratio, 0.9);
    EXPECT_LT(ratio, 1.1);
  }
}

// A raw float32 volume (40 x 41 x 39, a ball of radius 13 off centre) with its sidecar; `nan_at`
// >= 0 puts a NaN at that voxel index.
std::string write_ball(const std::string& name, long nan_at = -1) {
  const std::string path = scratch() + "/" + name;
  std::ofstream out(path, std::ios::binary);
  long index = 0;
  for (int k = 0; k < 39; ++k)
    for (int j = 0; j < 41; ++j)
      for (int i = 0; i < 40; ++i, ++index) {
        float v = float(13.0 - std::hypot(i - 19.6, j - 20.2, k - 19.1));
        if (index == nan_at) v = std::nanf("");
        out.write(reinterpret_cast<const char*>(&v), sizeof v);
      }
  std::ofstream(path + ".json")
      << R"({"dims": [40, 41, 39], "dtype": "float32", "spacing": [0.5, 0.5, 0.7]})";
  return path;
}

// Without an output that needs the whole volume, the raw file is read window by window (the
// report says so) and the surface is the one the whole volume in memory gives.
TEST(BricksCommand, ReadsARawVolumeWindowByWindowWithTheSameSurface) {
  const std::string ball = write_ball("ball.raw");
  const std::string streamed = scratch() + "/streamed.ply", whole = scratch() + "/whole.ply";
  test::CliResult r = test::run_mlfe("convert " + ball + " --iso 0 --bricks 8 --quiet -o " + streamed +
                                     " --report " + streamed + ".json");
  ASSERT_EQ(r.status, 0) << r.err;
  std::ifstream in(streamed + ".json");
  const json report = json::parse(in);
  EXPECT_TRUE(report["read_in_windows"].get<bool>());
  EXPECT_GT(report["asset"]["triangles"].get<int>(), 100);
  r = test::run_mlfe("convert " + ball + " --iso 0 --bricks 8 --quiet -o " + whole + " --hierarchy " +
                     scratch() + "/whole.mlfeh");
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_EQ(test::read_bytes(streamed), test::read_bytes(whole));
}

// auto (the default) bricks a raw or OME-Zarr volume only above 2^27 samples: smaller ones keep
// the whole surface's bytes.
TEST(BricksCommand, AutoBricksOnlyBigVolumes) {
  EXPECT_EQ(auto_bricks({512, 512, 512}), 0);
  EXPECT_EQ(auto_bricks({512, 512, 513}), 128);
  EXPECT_EQ(auto_bricks({2048, 1024, 1024}), 128);
  const std::string ball = write_ball("auto.raw");
  const std::string by_default = scratch() + "/auto_default.ply", whole = scratch() + "/auto_whole.ply";
  ASSERT_EQ(test::run_mlfe("convert " + ball + " --iso 0 --quiet -o " + by_default).status, 0);
  ASSERT_EQ(test::run_mlfe("convert " + ball + " --iso 0 --bricks 0 --quiet -o " + whole).status, 0);
  EXPECT_EQ(test::read_bytes(by_default), test::read_bytes(whole));
}

// What is found only while reading the windows still stops the run with one line and no file.
TEST(BricksCommand, RefusesWhatTheWindowsShowWithNoOutput) {
  const std::string out = scratch() + "/late.glb";
  std::filesystem::remove(out);
  test::CliResult r = test::run_mlfe("convert " + write_ball("ball_nan.raw", 3 + 40 * (4 + 41 * 5)) +
                                     " --iso 0 --bricks 8 --quiet -o " + out);
  EXPECT_EQ(r.status, 2);
  EXPECT_NE(r.err.find("NaN or infinite (first at index 3,4,5)"), std::string::npos) << r.err;
  EXPECT_FALSE(std::filesystem::exists(out));
  r = test::run_mlfe("convert " + write_ball("ball.raw") + " --iso 20 --bricks 8 --quiet -o " + out);
  EXPECT_EQ(r.status, 2);
  EXPECT_NE(r.err.find("outside the data's range"), std::string::npos) << r.err;
  EXPECT_FALSE(std::filesystem::exists(out));
}

// The ball as float32 with dyadic spacing (exact in a NIfTI's float sform), in RAS: a raw file
// with its sidecar and the same volume written as .nii.gz.
std::pair<std::string, std::string> write_ball_raw_and_nifti(const std::string& name) {
  const std::string raw = write_ball(name + ".raw");
  std::ofstream(raw + ".json")
      << R"({"dims": [40, 41, 39], "dtype": "float32", "spacing": [0.5, 0.5, 0.75], "space": "RAS"})";
  write_volume(scratch() + "/" + name + ".nii.gz", read_volume(raw));
  return {raw, scratch() + "/" + name + ".nii.gz"};
}

// A .nii.gz read in bricks (inflated once into a temporary file) gives the bytes the same volume
// as raw gives, and says it was read in windows.
TEST(BricksCommand, GzippedNiftiInBricksGivesTheRawVolumesBytes) {
  const auto [raw, nii] = write_ball_raw_and_nifti("same");
  pipeline::ConvertFileOptions o;
  o.asset.iso = {0.0, 2.0};
  o.asset.bricks = 8;
  o.provenance = {{"input", "ball"}};
  const std::string from_raw = scratch() + "/same_raw.glb", from_nii = scratch() + "/same_nii.glb";
  pipeline::convert(raw, from_raw, o);
  o.report = from_nii + ".json";
  pipeline::convert(nii, from_nii, o);
  std::ifstream in(o.report);
  EXPECT_TRUE(json::parse(in)["read_in_windows"].get<bool>());
  EXPECT_EQ(test::read_bytes(from_nii), test::read_bytes(from_raw));
  EXPECT_GT(test::read_bytes(from_raw).size(), 1000u);
}

// auto bricks a NIfTI as it bricks raw: only above 2^27 samples, so a small one keeps the whole
// surface's bytes. A truncated .nii.gz, found out only while its bricks are read, still stops the
// run with one line, exit 2 and no output.
TEST(BricksCommand, SmallNiftiKeepsItsBytesAndATruncatedOneLeavesNoOutput) {
  const std::string nii = write_ball_raw_and_nifti("auto_nii").second;
  const std::string by_default = scratch() + "/nii_default.ply", whole = scratch() + "/nii_whole.ply";
  ASSERT_EQ(test::run_mlfe("convert " + nii + " --iso 0 --quiet -o " + by_default).status, 0);
  ASSERT_EQ(test::run_mlfe("convert " + nii + " --iso 0 --bricks 0 --quiet -o " + whole).status, 0);
  EXPECT_EQ(test::read_bytes(by_default), test::read_bytes(whole));

  const std::string gz = test::read_bytes(nii), cut = scratch() + "/cut.nii.gz";
  std::ofstream(cut, std::ios::binary) << gz.substr(0, gz.size() / 2);
  const std::string out = scratch() + "/cut.glb";
  const test::CliResult r = test::run_mlfe("convert " + cut + " --iso 0 --bricks 8 --quiet -o " + out);
  EXPECT_EQ(r.status, 2);
  EXPECT_EQ(r.err.rfind("mlfe: " + cut + ": truncated compressed data", 0), 0u) << r.err;
  EXPECT_EQ(r.err.find('\n'), r.err.size() - 1) << r.err;
  EXPECT_FALSE(std::filesystem::exists(out));
}

// Progress counts bricks: one report a brick in "extracting", in order; cancelling while the
// bricks are read throws Cancelled and leaves neither the asset nor the report.
TEST(BricksCommand, ProgressCountsBricksAndCancelLeavesNoOutput) {
  const std::string ball = write_ball("progress.raw");
  pipeline::ConvertFileOptions o;
  o.asset.iso = {0.0};
  o.asset.bricks = 8;
  std::vector<double> extracting;
  o.progress = [&](double f, const std::string& stage) {
    if (stage == "extracting") extracting.push_back(f);
    return true;
  };
  pipeline::convert(ball, scratch() + "/progress.glb", o);
  const std::size_t bricks = 5 * 5 * 5;
  EXPECT_GE(extracting.size(), bricks);
  EXPECT_TRUE(std::is_sorted(extracting.begin(), extracting.end()));
  const std::string out = scratch() + "/cancelled.glb";
  std::size_t seen = 0;
  o.report = out + ".json";
  o.progress = [&](double, const std::string& stage) { return stage != "extracting" || ++seen < bricks / 2; };
  EXPECT_THROW(pipeline::convert(ball, out, o), pipeline::Cancelled);
  // Bricks already in flight on other threads may still report.
  EXPECT_GE(seen, bricks / 2);
  EXPECT_LT(seen, bricks);
  EXPECT_FALSE(std::filesystem::exists(out));
  EXPECT_FALSE(std::filesystem::exists(o.report));
}

// The command line's bar (on a terminal) moves with the bricks while it reads them.
TEST(BricksCommand, TheBarMovesWithTheBricks) {
  const std::string ball = write_ball("bar.raw"), log = scratch() + "/bar.log";
  const std::string cmd = std::string(MLFE_BINARY) + " convert " + ball +
                          " --iso 0 --bricks 8 --threads 1 -o " + scratch() + "/bar.glb";
  // script(1) gives the command a terminal, so the bar is drawn.
  ASSERT_EQ(std::system(("script -qec '" + cmd + "' /dev/null > " + log + " 2>&1").c_str()), 0);
  const std::string text = test::read_bytes(log);
  std::set<int> percents;
  for (std::size_t at = text.find("% extracting"); at != std::string::npos;
       at = text.find("% extracting", at + 1))
    percents.insert(std::stoi(text.substr(at - 3, 3)));
  EXPECT_GE(percents.size(), 20u) << text;
}

// The pieces a distributed run sends apart (brick_parts on workers, write_bricks on the client)
// give the bytes of the one-process run; parts that are not the volume's bricks are refused.
TEST(BricksCommand, PiecesRunApartWriteTheSameAsset) {
  const VolumeWindows v(write_ball("pieces.raw"), {});
  AssetOptions o;
  o.iso = {0.0, 2.0};
  o.bricks = 8;
  const nlohmann::json prov = bricks_provenance("pieces.raw", o);
  const std::string whole = scratch() + "/pieces_whole.glb", apart = scratch() + "/pieces_apart.glb";
  write_assets(whole, v, o, prov);
  const std::size_t n = brick_count(v, o);
  EXPECT_EQ(n, 5u * 5u * 5u);  // 39 x 40 x 38 cubes
  std::vector<std::string> parts(n);
  for (std::size_t b = n; b-- > 0;) parts[b] = brick_parts(v, o, b);  // any order
  EXPECT_EQ(encode_brick_parts(decode_brick_parts(parts[7])), parts[7]);
  // The fuzzer's seed (tests/data/brick_parts_seed.mlfebrk) is the first part of a few kB.
  if (const char* seed = std::getenv("MLFE_WRITE_BRICK_SEED"))
    for (const std::string& p : parts)
      if (p.size() > 2000 && p.size() < 30000) {
        std::ofstream(seed, std::ios::binary) << p;
        break;
      }
  write_bricks(apart, v, o, parts, prov);
  EXPECT_EQ(test::read_bytes(apart), test::read_bytes(whole));
  // The join tree's nodes joined apart (join_parts, as mlfe.distributed's tasks), then the root's
  // halves written: the same bytes.
  const std::size_t slabs = 5, per = n / slabs;  // 38 cubes along z
  std::map<std::pair<std::size_t, std::size_t>, std::string> pieces;
  for (std::size_t s = slabs; s-- > 0;)
    pieces[{s, s + 1}] = join_parts(v, o, s, s + 1, {parts.begin() + s * per, parts.begin() + (s + 1) * per});
  for (const auto& [first, end] : {std::pair<std::size_t, std::size_t>(0, 2), {3, 5}, {2, 5}}) {
    const std::size_t split = slab_split(first, end);
    pieces[{first, end}] = join_parts(v, o, first, end, {pieces.at({first, split}), pieces.at({split, end})});
  }
  const std::string halves = scratch() + "/pieces_halves.glb";
  write_bricks(halves, v, o, {pieces.at({2, 5}), pieces.at({0, 2})}, prov);
  EXPECT_EQ(test::read_bytes(halves), test::read_bytes(whole));
  EXPECT_THROW(join_parts(v, o, 0, 2, {pieces.at({0, 1})}), Error);                       // a half missing
  EXPECT_THROW(join_parts(v, o, 0, 1, {parts.begin(), parts.begin() + per - 1}), Error);  // a brick missing

  const std::string refused = scratch() + "/pieces_refused.glb";
  const std::string fourth = parts[4];
  parts[4] = parts[3];  // brick 3 twice, brick 4 missing
  EXPECT_THROW(write_bricks(refused, v, o, parts, prov), Error);
  parts[4] = fourth;
  parts[3].pop_back();
  EXPECT_THROW(write_bricks(refused, v, o, parts, prov), Error);
  parts.pop_back();
  EXPECT_THROW(write_bricks(refused, v, o, parts, prov), Error);
  // A part the tree does not use (a slab also given joined).
  EXPECT_THROW(write_bricks(refused, v, o, {pieces.at({0, 2}), pieces.at({2, 5}), pieces.at({0, 1})}, prov),
               Error);
  EXPECT_THROW(brick_parts(v, o, n), Error);
  EXPECT_FALSE(std::filesystem::exists(refused));
}

TEST(BricksCommand, RefusesWhatCannotBeBricked) {
  for (const std::string extra :
       {"--surface samples --bricks 12", "--surface samples --bricks 1", "--surface hierarchy --bricks 16",
        "--surface samples --bricks 16 --simplifier meshopt"}) {
    const std::string out = scratch() + "/refused.glb";
    std::filesystem::remove(out);
    const test::CliResult r =
        test::run_mlfe("convert " + kSkull + " --iso 1.5 --quiet " + extra + " -o " + out);
    EXPECT_NE(r.status, 0) << extra;
    EXPECT_NE(r.err.find("bricks"), std::string::npos) << extra << ": " << r.err;
    EXPECT_FALSE(std::filesystem::exists(out)) << extra;
  }
}

}  // namespace
}  // namespace mlfe
