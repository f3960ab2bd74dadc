// `mlfe compare`: exit status 0 / 1 / 2, one reason per difference on stdout, the JSON report,
// and the skull's .glb golden file checked semantically (Draco reorders, so bytes cannot be).
#include <gtest/gtest.h>
#include <mlfe/formats/openmesh_io.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "tests/test_meshes.h"
#include "tests/test_paths.h"

namespace fs = std::filesystem;

namespace mlfe {
namespace {

const std::string kSkull = test::sample_path("ct_skull_64.nrrd");
const std::string kGolden = std::string(MLFE_SOURCE_DIR) + "/tests/golden";

struct CliRun {
  int status;
  std::string out, err;
};

CliRun mlfe_run(const std::string& args) {
  const std::string dir = test::scratch_dir();
  const std::string cmd =
      std::string(MLFE_BINARY) + " " + args + " > " + dir + "/out.txt 2> " + dir + "/err.txt";
  const int rc = std::system(cmd.c_str());
  return {WIFEXITED(rc) ? WEXITSTATUS(rc) : -1, test::read_bytes(dir + "/out.txt"),
          test::read_bytes(dir + "/err.txt")};
}

TEST(CompareCommand, ExitStatusZeroOneTwo) {
  const std::string dir = test::scratch_dir();
  const TriangleMesh a = test::icosphere(3, 1.0f);
  TriangleMesh b = a;
  for (auto& p : b.positions) p[2] += 0.02f;
  write_mesh_file(dir + "/a.ply", a);
  write_mesh_file(dir + "/a.obj", a);
  write_mesh_file(dir + "/b.ply", b);

  const CliRun same = mlfe_run("compare " + dir + "/a.ply " + dir + "/a.obj --tolerance 1e-6");
  EXPECT_EQ(same.status, 0) << same.out << same.err;
  EXPECT_EQ(same.out, "equal (mesh)\n");

  const CliRun moved =
      mlfe_run("compare " + dir + "/a.ply " + dir + "/b.ply --tolerance 0.01 --report " + dir + "/r.json");
  EXPECT_EQ(moved.status, 1) << moved.err;
  EXPECT_NE(moved.out.find("Hausdorff distance: 0.02"), std::string::npos) << moved.out;
  EXPECT_NE(moved.out.find("bounding box: corners differ by up to 0.02"), std::string::npos) << moved.out;
  const nlohmann::json report = nlohmann::json::parse(test::read_bytes(dir + "/r.json"));
  EXPECT_FALSE(report["equal"].get<bool>());
  EXPECT_NEAR(report["figures"]["hausdorff"].get<double>(), 0.02, 1e-6);
  EXPECT_EQ(mlfe_run("compare " + dir + "/a.ply " + dir + "/b.ply --tolerance 0.021").status, 0);

  const CliRun missing = mlfe_run("compare " + dir + "/a.ply " + dir + "/nothing.ply");
  EXPECT_EQ(missing.status, 2);
  EXPECT_NE(missing.err.find("nothing.ply"), std::string::npos) << missing.err;
  // Usage errors are 2 as well, so that 1 always means "different".
  EXPECT_EQ(mlfe_run("compare " + dir + "/a.ply").status, 2);
  EXPECT_EQ(mlfe_run("compare " + dir + "/a.ply " + dir + "/b.ply --count-tolerance lots").status, 2);
  // Other commands keep 1 for usage errors.
  EXPECT_EQ(mlfe_run("info").status, 1);
}

// The .glb of the golden PLY's conversion, compared by content: Draco's vertex order and the
// encoder's bytes may change, the asset must not. Tolerance: the Draco tolerance of this
// conversion (a tenth of the smallest voxel spacing, 0.3651 mm, per coordinate) as a distance in
// metres. The tool version in the provenance is not compared. Regenerate with
// MLFE_UPDATE_GOLDEN=1 after an intended change.
TEST(GoldenCompare, SkullGlbMatchesCheckedInGlb) {
  const std::string glb = test::scratch_dir() + "/skull.glb";
  const std::string golden = kGolden + "/ct_skull_iso2.5_3000.glb";
  const CliRun conv =
      mlfe_run("convert " + kSkull + " --iso 2.5 --max-vertices 3000 --simplify 0 --quiet -o " + glb);
  ASSERT_EQ(conv.status, 0) << conv.err;
  if (std::getenv("MLFE_UPDATE_GOLDEN")) fs::copy_file(glb, golden, fs::copy_options::overwrite_existing);
  ASSERT_TRUE(fs::exists(golden)) << "missing golden file " << golden;
  const std::string ignore = " --ignore /asset/extras/tool --ignore /asset/generator";
  const CliRun cmp = mlfe_run("compare " + golden + " " + glb + " --tolerance 6.33e-4" + ignore);
  EXPECT_EQ(cmp.status, 0) << cmp.out << cmp.err;
  // And it is not blind: another iso-value is reported as different.
  const std::string other = test::scratch_dir() + "/skull_other.glb";
  ASSERT_EQ(mlfe_run("convert " + kSkull + " --iso 3 --max-vertices 3000 --quiet -o " + other).status, 0);
  const CliRun diff = mlfe_run("compare " + golden + " " + other + " --tolerance 6.33e-4" + ignore);
  EXPECT_EQ(diff.status, 1) << diff.out;
}

// Issue 42: the golden .glb (Draco) against a --no-draco conversion of the same input, with no
// --ignore: equal, the tolerance widened to the golden file's quantization step (a note says
// so); --strict compares the encoding and the provenance and finds them different.
TEST(GoldenCompare, DracoGoldenEqualsItsNoDracoTwinUnlessStrict) {
  const std::string plain = test::scratch_dir() + "/skull_plain.glb";
  const std::string golden = kGolden + "/ct_skull_iso2.5_3000.glb";
  const CliRun conv = mlfe_run("convert " + kSkull +
                               " --iso 2.5 --max-vertices 3000 --simplify 0 --no-draco --quiet -o " + plain);
  ASSERT_EQ(conv.status, 0) << conv.err;
  const CliRun cmp = mlfe_run("compare " + golden + " " + plain);
  EXPECT_EQ(cmp.status, 0) << cmp.out << cmp.err;
  EXPECT_NE(cmp.out.find("note: node 0 'iso 2.5' mesh 'iso 2.5' primitive 0: tolerance"), std::string::npos)
      << cmp.out;
  EXPECT_NE(cmp.out.find("widened to"), std::string::npos) << cmp.out;
  const CliRun strict = mlfe_run("compare --strict " + golden + " " + plain);
  EXPECT_EQ(strict.status, 1) << strict.out << strict.err;
  EXPECT_NE(strict.out.find("encoding /mlfe/encoding: \"draco\" in EXPECTED, \"float\" in ACTUAL"),
            std::string::npos)
      << strict.out;
  // A .ply of the conversion is the same geometry in the scan's millimetres.
  const CliRun ply = mlfe_run("compare " + golden + " " + kGolden + "/ct_skull_iso2.5_3000.ply");
  EXPECT_EQ(ply.status, 0) << ply.out << ply.err;
}

}  // namespace
}  // namespace mlfe
