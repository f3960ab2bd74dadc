// `mlfe build` writes the compact v3 hierarchy file; `mlfe info` reports it; bad files exit 2.
#include <gtest/gtest.h>
#include <mlfe/formats/hierarchy_io.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "tests/test_meshes.h"
#include "tests/test_paths.h"

namespace fs = std::filesystem;

namespace mlfe {
namespace {

const std::string kSkull = test::sample_path("ct_skull_64.nrrd");

using RunResult = test::CliResult;
using test::read_bytes;

std::string scratch() { return test::scratch_dir("hfile"); }
RunResult run(const std::string& args) { return test::run_mlfe(args); }

TEST(HierarchyFileCommand, BuildWritesAFileWithinTheBoundAndFarBelowTheInput) {
  const std::string h = scratch() + "/skull.mlfeh", rep = scratch() + "/skull.json";
  const RunResult r = run("build " + kSkull + " -o " + h + " --report " + rep + " --psnr 50");
  ASSERT_EQ(r.status, 0) << r.err;
  const HierarchyFile f = read_hierarchy(h);
  EXPECT_EQ(f.version, 4);
  EXPECT_TRUE(f.on_lattice);
  EXPECT_TRUE(std::isnan(f.sample_error_bound));  // a least-squares build promises no bound
  const auto report = nlohmann::json::parse(read_bytes(rep));
  EXPECT_EQ(f.value_bound, report["file"]["value_bound"].get<double>());
  // The input is 1 MiB of float32; the target is ≤ 1/10 of gzip -9 of it.
  EXPECT_LT(fs::file_size(h), fs::file_size(kSkull) / 20);
  EXPECT_EQ(report["file"]["bytes"].get<double>(), static_cast<double>(fs::file_size(h)));
  EXPECT_EQ(report["file"]["rms_error"].get<double>(), f.rms_error);
  EXPECT_EQ(report["file"]["max_error"].get<double>(), f.max_error);
  // The file's figures and the build's are both at the samples; the quantization adds a little.
  EXPECT_GE(f.rms_error, 0.99 * report["rms_error"].get<double>());
  EXPECT_LT(f.rms_error, 1.5 * report["rms_error"].get<double>());
  EXPECT_GE(f.max_error, f.rms_error);
  EXPECT_EQ(f.norm, "l2");
}

TEST(HierarchyFileCommand, BuildPrintsItsSummaryUnlessQuiet) {
  const std::string h = scratch() + "/quiet.mlfeh";
  const RunResult loud = run("build " + kSkull + " -o " + h + " --max-vertices 3000");
  ASSERT_EQ(loud.status, 0) << loud.err;
  EXPECT_NE(loud.err.find("mlfe build: file"), std::string::npos) << loud.err;
  const RunResult quiet = run("build " + kSkull + " -o " + h + " --max-vertices 3000 --quiet");
  ASSERT_EQ(quiet.status, 0) << quiet.err;
  EXPECT_EQ(quiet.err, "");
  EXPECT_EQ(quiet.out, h + "\n");  // stdout still names the file written, for scripts
}

TEST(HierarchyFileCommand, InfoPrintsLevelsErrorsAndSections) {
  const std::string h = scratch() + "/info.mlfeh";
  ASSERT_EQ(run("build " + kSkull + " -o " + h + " --psnr 50").status, 0);
  const RunResult r = run("info " + h + " --json");
  ASSERT_EQ(r.status, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["version"], 4);
  EXPECT_EQ(j["values"], "quantized");
  EXPECT_EQ(j["on_lattice"], true);
  EXPECT_EQ(j["data_dims"], nlohmann::json::array({64, 64, 64}));
  const int levels = j["levels"];
  ASSERT_GE(levels, 3);
  EXPECT_EQ(j["per_level"].size(), static_cast<std::size_t>(levels));
  std::uint64_t bytes = 0;
  for (const auto& s : j["sections"]) bytes += s["file_bytes"].get<std::uint64_t>();
  EXPECT_EQ(bytes, fs::file_size(h));
  EXPECT_EQ(j["sections"].size(), static_cast<std::size_t>(levels) + 2);  // preamble, header, T0, levels 1..L
  const RunResult t = run("info " + h);
  EXPECT_NE(t.out.find("level 1"), std::string::npos) << t.out;
  EXPECT_NE(t.out.find("PSNR"), std::string::npos) << t.out;
  EXPECT_NE(t.out.find("lattice:   level 6"), std::string::npos) << t.out;
}

TEST(HierarchyFileCommand, ACorruptFileExitsWithStatus2AndNamesIt) {
  const std::string h = scratch() + "/corrupt.mlfeh";
  ASSERT_EQ(run("build " + kSkull + " -o " + h + " --max-vertices 3000").status, 0);
  const std::string good = read_bytes(h);
  std::string bytes = good;
  bytes[bytes.size() / 2] ^= 0x10;
  std::ofstream(h, std::ios::binary | std::ios::trunc) << bytes;
  const RunResult r = run("info " + h);
  EXPECT_EQ(r.status, 2);
  EXPECT_NE(r.err.find(h + ": checksum mismatch"), std::string::npos) << r.err;
  std::ofstream(h, std::ios::binary | std::ios::trunc) << good.substr(0, good.size() - 7);
  const RunResult t = run("iso " + h + " --iso 3 -o " + scratch() + "/x.ply");
  EXPECT_EQ(t.status, 2);
  EXPECT_NE(t.err.find("truncated"), std::string::npos) << t.err;
  EXPECT_FALSE(fs::exists(scratch() + "/x.ply"));
}

}  // namespace
}  // namespace mlfe
