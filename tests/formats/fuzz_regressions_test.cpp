// Inputs the fuzzers once crashed on and the reader rows of the bad-input battery (issue 43:
// tiny files claiming huge data, singular frames), in tests/data/fuzz_regressions/: each must
// be refused with mlfe::Error naming the file — never a crash or an abort inside a library.
// The fuzz stage replays them as seeds under ASan + UBSan.
#include <gtest/gtest.h>
#include <mlfe/core/base/error.h>
#include <mlfe/formats/draco_io.h>
#include <mlfe/formats/volume_reader.h>

#include <filesystem>

namespace mlfe {
namespace {

TEST(FuzzRegressions, EveryRecordedCrashIsNowAnError) {
  const std::filesystem::path dir = std::filesystem::path(MLFE_SOURCE_DIR) / "tests/data/fuzz_regressions";
  int n = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    ++n;
    const std::string path = entry.path().string();
    try {
      read_volume(path);
      ADD_FAILURE() << path << " was accepted";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(entry.path().filename().string()), std::string::npos) << e.what();
    }
  }
  EXPECT_GE(n, 1);
}

TEST(FuzzRegressions, CorruptDracoPayloadsAreErrors) {
  const std::filesystem::path dir =
      std::filesystem::path(MLFE_SOURCE_DIR) / "tests/data/fuzz_regressions_draco";
  int n = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    ++n;
    EXPECT_THROW(read_draco_file(entry.path().string()), Error) << entry.path();
  }
  EXPECT_GE(n, 1);
}

}  // namespace
}  // namespace mlfe
