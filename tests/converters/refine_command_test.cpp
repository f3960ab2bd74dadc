// mlfe refine, run as a separate process.
#include <gtest/gtest.h>
#include <mlfe/core/base/error.h>
#include <mlfe/formats/hierarchy_io.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <regex>
#include <string>

#include "tests/test_paths.h"

namespace mlfe {
namespace {

namespace fs = std::filesystem;

fs::path temp_dir() { return mlfe::test::scratch_dir("refine_command"); }

std::string read_all(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

struct RunResult {
  int status = -1;
  std::string err;
};

RunResult run_mlfe(const std::string& args) {
  const fs::path err = temp_dir() / "stderr.txt";
  const std::string cmd = std::string(MLFE_BINARY) + " " + args + " 2> " + err.string() + " > /dev/null";
  const int raw = std::system(cmd.c_str());
  RunResult r;
  r.status = WIFEXITED(raw) ? WEXITSTATUS(raw) : -1;
  r.err = read_all(err);
  return r;
}

std::size_t vtu_cells(const fs::path& p) {
  const std::string s = read_all(p);
  std::smatch m;
  if (!std::regex_search(s, m, std::regex(R"re(NumberOfCells="(\d+)")re"))) return 0;
  return std::stoul(m[1]);
}

TEST(RefineCommand, WritesALeafMeshAndAHierarchyThatAgree) {
  const fs::path vtu = temp_dir() / "point.vtu", mlfeh = temp_dir() / "point.mlfeh";
  const RunResult r =
      run_mlfe("refine --dim 3 --box 0,0,0,2,1,1 --toward point --at 0.3,0.4,0.5 --levels 5 -o " +
               vtu.string() + " --hierarchy " + mlfeh.string());
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_TRUE(std::regex_search(
      r.err, std::regex(R"(refine: 3D, 5 levels, \d+ vertices, \d+ leaf elements, min dihedral)")))
      << r.err;
  const HierarchyFile f = read_hierarchy(mlfeh.string());
  ASSERT_EQ(f.dim, 3);
  const auto& h = std::get<Hierarchy<3>>(f.hierarchy);
  EXPECT_EQ(h.max_level(), 5);
  EXPECT_EQ(vtu_cells(vtu), h.leaves().size());
  // Local: far fewer leaves than uniform refinement (6 * 8^5), the far corner stays coarser
  // (the red-green grading lets levels fall by about one per element layer).
  EXPECT_LT(h.leaves().size(), 6u * 32768 / 10);
  for (ElemId e : h.leaves()) {
    for (VertexId v : h.cell(e)) {
      if (h.point(v) == Hierarchy<3>::Point{2, 1, 1}) {
        EXPECT_LE(h.level(e), 3);
      }
    }
  }
}

class RefineCommandTargets : public ::testing::TestWithParam<std::string> {};

TEST_P(RefineCommandTargets, SucceedAndWriteANonEmptyMesh) {
  const fs::path vtu = temp_dir() / "target.vtu";
  fs::remove(vtu);
  const RunResult r = run_mlfe("refine " + GetParam() + " --levels 4 -o " + vtu.string());
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_GT(vtu_cells(vtu), 50u);
}

INSTANTIATE_TEST_SUITE_P(
    All, RefineCommandTargets,
    ::testing::Values("--dim 2 --box 0,0,1,1 --toward point --at 0.3,0.3",
                      "--dim 2 --box 0,0,1,1 --toward plane --at 0.5,0.5 --normal 1,1",
                      "--dim 2 --box 0,0,1,1 --toward sphere --at 0.5,0.5 --radius 0.3",
                      "--dim 3 --box -1,-1,-1,1,1,1 --toward point --at 0,0,0",
                      "--dim 3 --box -1,-1,-1,1,1,1 --toward plane --at 0,0,0.1 --normal 0,0,1",
                      "--dim 3 --box -1,-1,-1,1,1,1 --toward sphere --at 0,0,0 --radius 0.5"));

TEST(RefineCommand, SphereRefinementFollowsTheSurfaceNotTheInside) {
  const fs::path vtu = temp_dir() / "sphere.vtu", mlfeh = temp_dir() / "sphere.mlfeh";
  const RunResult r =
      run_mlfe("refine --dim 2 --box -1,-1,1,1 --toward sphere --at 0,0 --radius 0.7 --levels 8 -o " +
               vtu.string() + " --hierarchy " + mlfeh.string());
  ASSERT_EQ(r.status, 0) << r.err;
  const auto f = read_hierarchy(mlfeh.string());
  const auto& h = std::get<Hierarchy<2>>(f.hierarchy);
  int centre_level = -1;
  for (ElemId e : h.leaves())
    for (VertexId v : h.cell(e))
      if (h.point(v) == Hierarchy<2>::Point{0, 0}) centre_level = std::max(centre_level, h.level(e));
  EXPECT_GE(centre_level, 0);
  EXPECT_GE(h.max_level(), 8);
  EXPECT_LE(centre_level, h.max_level() - 3) << "the centre is far from the surface";
}

struct BadCase {
  std::string args;
  std::string message;
};

class RefineCommandBadArguments : public ::testing::TestWithParam<BadCase> {};

// Bad option values are usage errors (exit 1), as for every command.
TEST_P(RefineCommandBadArguments, ExitWith1AndWriteNothing) {
  const fs::path vtu = temp_dir() / "bad.vtu", mlfeh = temp_dir() / "bad.mlfeh";
  fs::remove(vtu);
  fs::remove(mlfeh);
  const RunResult r =
      run_mlfe("refine " + GetParam().args + " -o " + vtu.string() + " --hierarchy " + mlfeh.string());
  EXPECT_EQ(r.status, 1) << r.err;
  EXPECT_NE(r.err.find("mlfe: " + GetParam().message), std::string::npos) << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << "one line: " << r.err;
  EXPECT_FALSE(fs::exists(vtu));
  EXPECT_FALSE(fs::exists(mlfeh));
}

INSTANTIATE_TEST_SUITE_P(
    All, RefineCommandBadArguments,
    ::testing::Values(
        BadCase{"--dim 4 --box 0,0,1,1 --toward point --at 0,0 --levels 2",
                "--dim: '4' is not an integer in [2, 3]"},
        BadCase{"--dim 3 --box 0,0,0,1,1 --toward point --at 0,0,0 --levels 2", "--box: expected 6"},
        BadCase{"--dim 2 --box 0,0,1,x --toward point --at 0,0 --levels 2",
                "--box: 'x' is not a finite number"},
        BadCase{"--dim 2 --box 1,0,0,1 --toward point --at 0,0 --levels 2", "--box: the lower corner"},
        BadCase{"--dim 2 --box 0,0,1,1 --toward cube --at 0,0 --levels 2", "--toward: 'cube'"},
        BadCase{"--dim 2 --box 0,0,1,1 --toward plane --at 0,0 --levels 2", "--normal is required"},
        BadCase{"--dim 2 --box 0,0,1,1 --toward plane --at 0,0 --normal 0,0 --levels 2",
                "--normal must not be zero"},
        BadCase{"--dim 2 --box 0,0,1,1 --toward sphere --at 0,0 --levels 2", "--radius is required"},
        BadCase{"--dim 2 --box 0,0,1,1 --toward sphere --at 0,0 --radius -1 --levels 2",
                "--radius must be positive"},
        BadCase{"--dim 2 --box 0,0,1,1 --toward point --at 0,0 --radius 1 --levels 2",
                "--radius is only used"},
        BadCase{"--dim 2 --box 0,0,1,1 --toward point --at 0,0,0 --levels 2", "--at: expected 2"},
        BadCase{"--dim 2 --box 0,0,1,1 --toward point --at 0,0 --levels 99", "--levels: '99'"},
        BadCase{"--dim 2 --box 0,0,1,1 --toward point --at 0,0 --levels two", "--levels: 'two'"}));

TEST(RefineCommand, UnwritableOutputExitsWith2AndLeavesNoHierarchy) {
  const fs::path mlfeh = temp_dir() / "orphan.mlfeh";
  fs::remove(mlfeh);
  const RunResult r =
      run_mlfe("refine --dim 2 --box 0,0,1,1 --toward point --at 0.5,0.5 --levels 2 -o " +
               (temp_dir() / "no_such_dir" / "x.vtu").string() + " --hierarchy " + mlfeh.string());
  EXPECT_EQ(r.status, 2) << r.err;
  EXPECT_FALSE(fs::exists(mlfeh));
}

}  // namespace
}  // namespace mlfe
