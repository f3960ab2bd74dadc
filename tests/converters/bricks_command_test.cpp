// `mlfe convert --bricks B` (core/simplify/bricked_iso_surface.h): the same bytes for any thread
// count, a surface as clean as the unbricked one and of about its size, and the option's
// refusals (no output written).
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

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
