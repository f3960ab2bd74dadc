// mlfe render / convert --render end to end: files written, the same bytes with 1 and 2
// threads, levels and the reference, turntable frames, bad input (exit 2, no output).
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "tests/test_paths.h"

namespace fs = std::filesystem;

namespace mlfe {
namespace {

const std::string kSkull = test::sample_path("ct_skull_64.nrrd");
const std::string kSmall = std::string(MLFE_SOURCE_DIR) + "/tests/data/small_skull.mlfeh";

std::string scratch() { return test::scratch_dir("render"); }

struct RunResult {
  int status;
  std::string err;
};

RunResult run(const std::string& args) {
  const std::string errfile = scratch() + "/stderr.txt";
  const int rc = std::system((std::string(MLFE_BINARY) + " " + args + " > /dev/null 2> " + errfile).c_str());
  std::ifstream in(errfile);
  std::stringstream ss;
  ss << in.rdbuf();
  return {WIFEXITED(rc) ? WEXITSTATUS(rc) : -1, ss.str()};
}

std::string bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

TEST(Render, HierarchyToExrAndPngSameBytesWithOneAndTwoThreads) {
  const std::string a = scratch() + "/a.exr", b = scratch() + "/b.exr", png = scratch() + "/a.png";
  const std::string opts =
      " --tf bone --size 96x64 --camera perspective --azimuth 30 --elevation 20 --shading";
  ASSERT_EQ(run("--threads 1 render " + kSmall + " -o " + a + " --png " + png + opts).status, 0);
  ASSERT_EQ(run("--threads 2 render " + kSmall + " -o " + b + opts).status, 0);
  EXPECT_GT(fs::file_size(a), 1000u);
  EXPECT_GT(fs::file_size(png), 100u);
  EXPECT_EQ(bytes(a), bytes(b));
  // A coarser level is a different image.
  const std::string c = scratch() + "/c.exr";
  ASSERT_EQ(run("render " + kSmall + " -o " + c + " --level 1" + opts).status, 0);
  EXPECT_NE(bytes(a), bytes(c));
}

TEST(Render, VolumeReferenceTurntableAndConvert) {
  const std::string ref = scratch() + "/ref.exr";
  ASSERT_EQ(run("render " + kSkull + " --reference -o " + ref + " --size 48x48 --quiet").status, 0);
  EXPECT_TRUE(fs::exists(ref));
  const std::string turn = scratch() + "/turn.exr";
  ASSERT_EQ(run("render " + kSmall + " -o " + turn + " --frames 3 --size 32x32").status, 0);
  for (const char* n : {"turn_0000.exr", "turn_0001.exr", "turn_0002.exr"})
    EXPECT_TRUE(fs::exists(scratch() + "/" + n)) << n;
  EXPECT_NE(bytes(scratch() + "/turn_0000.exr"), bytes(scratch() + "/turn_0001.exr"));
  const std::string glb = scratch() + "/s.glb", img = scratch() + "/s.exr";
  ASSERT_EQ(
      run("convert " + kSkull + " --iso 3 --max-vertices 3000 -o " + glb + " --render " + img + " --quiet")
          .status,
      0);
  EXPECT_TRUE(fs::exists(img));
}

TEST(Render, BadInputExitsTwoWithoutOutput) {
  const std::string out = scratch() + "/bad.exr";
  RunResult r = run("render " + kSmall + " --reference -o " + out);
  EXPECT_EQ(r.status, 2);
  EXPECT_NE(r.err.find("--reference"), std::string::npos) << r.err;
  const std::string tf = scratch() + "/bad_tf.json";
  std::ofstream(tf) << "{\"RGBPoints\": [0, 1, 1]}";
  r = run("render " + kSmall + " --tf " + tf + " -o " + out);
  EXPECT_EQ(r.status, 2);
  EXPECT_NE(r.err.find("bad_tf.json"), std::string::npos) << r.err;
  r = run("render " + kSmall + " --tf nope -o " + out);
  EXPECT_EQ(r.status, 2);
  // Bad option values are usage errors (1).
  r = run("render " + kSmall + " --size 10 -o " + out);
  EXPECT_EQ(r.status, 1);
  r = run("render " + kSmall + " --position 0,0,100 --target 0,0,0 --up 0,0,1 -o " + out);
  EXPECT_EQ(r.status, 1);
  EXPECT_NE(r.err.find("--up"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(out));
  for (const auto& e : fs::directory_iterator(scratch()))
    EXPECT_EQ(e.path().string().find(".tmp-"), std::string::npos) << e.path();
}

}  // namespace
}  // namespace mlfe
