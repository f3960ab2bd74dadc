// mlfe render / convert --render end to end: files written, the same bytes with 1 and 2
// threads, levels and the reference, turntable frames, bad input (exit 2, no output).
#include <gtest/gtest.h>

#include <cstdlib>
#include <cstring>
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

// Bytes of a v2-v4 hierarchy file up to the end of its LEVL k section (docs/mlfeh-v3.md:
// 16-byte preamble, then sections of a 28-byte header with the stored size at offset 8).
std::string prefix_up_to_level(const std::string& file, int k) {
  std::size_t pos = 16;
  for (int section = 0; section < 2 + k; ++section) {  // HEAD, MESH, LEVL 1..k
    std::uint64_t stored = 0;
    std::memcpy(&stored, file.data() + pos + 8, 8);
    pos += 28 + stored;
    EXPECT_LE(pos, file.size());
  }
  return file.substr(0, pos);
}

TEST(Render, LevelReadsOnlyTheFilesPrefix) {
  // A v4 file (v3's sections), and a copy cut right after level 2 under the same name (the EXR records the
  // file name): --level 2 renders both to the same bytes, with 1 and 2 threads, so it reads
  // nothing past level 2. The whole file cannot be read from the cut copy.
  const std::string full = scratch() + "/h.mlfeh";
  ASSERT_EQ(run("build " + kSkull + " --max-vertices 3000 -o " + full + " --quiet").status, 0);
  fs::create_directories(scratch() + "/cut");
  const std::string cut = scratch() + "/cut/h.mlfeh";
  const std::string whole = bytes(full);
  ASSERT_EQ(whole.substr(8, 1), "\x04");
  const std::string head = prefix_up_to_level(whole, 2);
  ASSERT_LT(head.size(), whole.size());
  std::ofstream(cut, std::ios::binary) << head;
  const std::string opts = " --tf bone --size 48x40 --level 2 --quiet";
  const std::string a = scratch() + "/level2_full.exr", b = scratch() + "/level2_cut.exr",
                    c = scratch() + "/level2_cut_1.exr", d = scratch() + "/finest.exr";
  ASSERT_EQ(run("--threads 2 render " + full + " -o " + a + opts).status, 0);
  ASSERT_EQ(run("--threads 2 render " + cut + " -o " + b + opts).status, 0);
  ASSERT_EQ(run("--threads 1 render " + cut + " -o " + c + opts).status, 0);
  EXPECT_EQ(bytes(a), bytes(b));
  EXPECT_EQ(bytes(b), bytes(c));
  ASSERT_EQ(run("render " + full + " -o " + d + " --tf bone --size 48x40 --quiet").status, 0);
  EXPECT_NE(bytes(a), bytes(d));
  const RunResult r = run("render " + cut + " -o " + scratch() + "/never.exr --quiet");
  EXPECT_EQ(r.status, 2);
  EXPECT_NE(r.err.find("h.mlfeh"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(scratch() + "/never.exr"));
  // A level beyond the file's is a usage error naming the file's levels.
  EXPECT_EQ(run("render " + full + " -o " + scratch() + "/never.exr --level 40 --quiet").status, 1);
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
