// Where the tests find their inputs and put their outputs, in one place: the bundled samples
// (samples/, also the main job's inputs), the small test inputs (tests/data), the golden files
// (tests/golden), and a scratch folder per test binary, removed at exit.
#pragma once
#include <sys/wait.h>
#include <unistd.h>

#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

namespace mlfe::test {

/// A file of the bundled samples (samples/ct_skull_64.nrrd, samples/dem_jacksboro.nrrd).
inline std::string sample_path(const std::string& name) {
  return std::string(MLFE_SOURCE_DIR) + "/samples/" + name;
}
/// A file of tests/data.
inline std::string test_data_path(const std::string& name) {
  return std::string(MLFE_SOURCE_DIR) + "/tests/data/" + name;
}
/// A file of tests/golden.
inline std::string golden_path(const std::string& name) {
  return std::string(MLFE_SOURCE_DIR) + "/tests/golden/" + name;
}

/// A fresh scratch folder per test binary run, removed when the binary exits; with `sub`, a
/// folder of that name inside it (created on first use).
inline std::string scratch_dir(const std::string& sub = "") {
  struct Dir {
    std::filesystem::path path;
    Dir() : path(std::filesystem::temp_directory_path() / ("mlfe_test_" + std::to_string(::getpid()))) {
      std::filesystem::create_directories(path);
    }
    ~Dir() {
      std::error_code ec;
      std::filesystem::remove_all(path, ec);
    }
  };
  static const Dir dir;
  if (sub.empty()) return dir.path.string();
  const std::filesystem::path p = dir.path / sub;
  std::filesystem::create_directories(p);
  return p.string();
}

/// The bytes of a file (empty when it cannot be read), and a file written with exactly `b`.
inline std::vector<std::uint8_t> read_file_bytes(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::vector<std::uint8_t>(std::istreambuf_iterator<char>(in), {});
}
inline void write_file_bytes(const std::filesystem::path& p, const std::vector<std::uint8_t>& b) {
  std::ofstream out(p, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(b.data()), static_cast<std::streamsize>(b.size()));
}

#ifdef MLFE_BINARY
/// What the mlfe command line printed and returned.
struct CliResult {
  int status;  ///< exit status (-1 when it did not exit normally)
  std::string out, err;
};

/// Runs `mlfe ARGS` (the build's binary), capturing stdout and stderr.
inline CliResult run_mlfe(const std::string& args) {
  const std::string dir = scratch_dir("cli"), out = dir + "/out.txt", err = dir + "/err.txt";
  const int rc = std::system((std::string(MLFE_BINARY) + " " + args + " > " + out + " 2> " + err).c_str());
  const auto slurp = [](const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
  };
  return {WIFEXITED(rc) ? WEXITSTATUS(rc) : -1, slurp(out), slurp(err)};
}
#endif

}  // namespace mlfe::test
