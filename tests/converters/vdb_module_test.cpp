// OpenVDB is a module loaded on the first .vdb file (formats/vdb_module.h): commands that never
// see one must not pay for loading libopenvdb, and those that do must find the module.
#include <gtest/gtest.h>

#include <string>

#include "tests/test_paths.h"

namespace mlfe::test {
namespace {

// The dynamic loader's list of the objects it opened (LD_DEBUG=files) for `mlfe ARGS`.
std::string loaded_objects(const std::string& args, int& status) {
  const std::string dir = scratch_dir("vdb_module"), log = dir + "/ld.txt";
  const int rc = std::system(
      ("LD_DEBUG=files " + std::string(MLFE_BINARY) + " " + args + " > /dev/null 2> " + log).c_str());
  status = WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
  std::ifstream in(log, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

TEST(VdbModule, OtherFormatsDoNotLoadOpenVdb) {
  int status = -1;
  const std::string objects = loaded_objects("info " + test_data_path("mri_slice_256.nrrd"), status);
  EXPECT_EQ(status, 0);
  EXPECT_NE(objects.find("libmlfe_formats"), std::string::npos) << "LD_DEBUG gave no list";
  EXPECT_EQ(objects.find("libopenvdb"), std::string::npos);
  EXPECT_EQ(objects.find("libmlfe_openvdb"), std::string::npos);
}

TEST(VdbModule, AVdbFileLoadsTheModule) {
  int status = -1;
  const std::string objects = loaded_objects("info " + test_data_path("small_sphere.vdb"), status);
  EXPECT_EQ(status, 0);
  EXPECT_NE(objects.find("libmlfe_openvdb.so"), std::string::npos);
  EXPECT_NE(objects.find("libopenvdb"), std::string::npos);
}

}  // namespace
}  // namespace mlfe::test
