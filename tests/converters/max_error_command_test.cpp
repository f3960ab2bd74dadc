// `mlfe build --max-error E` (issue #23, item 3): the decoded file is within E of the input at
// every sample; E = 0 on integer data is lossless through `mlfe export`; the v3 file knows the
// data's grid (export dims, the lattice of `iso` and `render`); the bytes do not depend on the
// thread count.
#include <gtest/gtest.h>
#include <mlfe/formats/hierarchy_io.h>
#include <mlfe/formats/volume_reader.h>
#include <mlfe/pipeline.h>

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>
#include <string>
#include <vector>

#include "tests/test_meshes.h"
#include "tests/test_paths.h"

namespace fs = std::filesystem;

namespace mlfe {
namespace {

using RunResult = test::CliResult;
using test::read_bytes;

std::string scratch() { return test::scratch_dir("max_error"); }
RunResult run(const std::string& args) { return test::run_mlfe(args); }

// A random volume as raw + JSON sidecar: a smooth blob plus noise, so some regions refine and
// some do not. `dtype` is "uint8", "int16" or "float32".
template <class T>
std::string write_volume(const std::string& name, const std::array<int, 3>& dims,
                         const std::array<double, 3>& spacing, const std::string& dtype, unsigned seed,
                         double noise, double lo, double hi) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> n01(0, 1);
  std::vector<T> v(static_cast<std::size_t>(dims[0]) * dims[1] * dims[2]);
  std::size_t i = 0;
  for (int z = 0; z < dims[2]; ++z)
    for (int y = 0; y < dims[1]; ++y)
      for (int x = 0; x < dims[0]; ++x, ++i) {
        const double r2 =
            std::pow(x - 0.4 * dims[0], 2) + std::pow(y - 0.6 * dims[1], 2) + std::pow(z - 0.5 * dims[2], 2);
        double s = lo + (hi - lo) * (0.5 + 0.4 * std::exp(-r2 / 20.0)) + noise * n01(rng);
        s = std::min(hi, std::max(lo, s));
        v[i] = static_cast<T>(std::is_integral<T>::value ? std::nearbyint(s) : s);
      }
  const std::string raw = scratch() + "/" + name + ".raw";
  std::ofstream(raw, std::ios::binary)
      .write(reinterpret_cast<const char*>(v.data()), static_cast<std::streamsize>(v.size() * sizeof(T)));
  std::ofstream(raw + ".json") << "{\"dims\":[" << dims[0] << "," << dims[1] << "," << dims[2]
                               << "],\"dtype\":\"" << dtype << "\",\"spacing\":[" << spacing[0] << ","
                               << spacing[1] << "," << spacing[2] << "],\"endian\":\"little\"}";
  return raw;
}

// Builds with --max-error E (and `options`), exports to a grid and returns the largest
// difference to the input at any sample (also checking the dims and the file's recorded bound).
double round_trip_max_error(const std::string& input, double e, const std::string& tag,
                            const std::string& options = "") {
  const std::string h = scratch() + "/" + tag + ".mlfeh", out = scratch() + "/" + tag + "_out.raw",
                    rep = scratch() + "/" + tag + ".json";
  const RunResult r = run("build " + input + " -o " + h + " --quiet --report " + rep + " --max-error " +
                          std::to_string(e) + " " + options);
  EXPECT_EQ(r.status, 0) << r.err;
  const RunResult x = run("export " + h + " -o " + out);
  EXPECT_EQ(x.status, 0) << x.err;
  const ScalarGrid src = read_volume(input), got = read_volume(out);
  EXPECT_EQ(got.dims, src.dims) << tag;
  if (got.values.size() != src.values.size()) return INFINITY;
  double worst = 0;
  for (std::size_t i = 0; i < src.values.size(); ++i)
    worst = std::max(worst, std::fabs(double(got.values[i]) - double(src.values[i])));
  const HierarchyFile f = read_hierarchy(h);
  EXPECT_EQ(f.version, 4);
  EXPECT_TRUE(f.on_lattice);
  EXPECT_EQ(f.data_dims, src.dims);
  EXPECT_DOUBLE_EQ(f.sample_error_bound, std::stod(std::to_string(e)));
  const auto report = nlohmann::json::parse(read_bytes(rep));
  EXPECT_TRUE(report["file"]["max_error_bound"]["verified"].get<bool>()) << report.dump(2);
  EXPECT_NE(report["file"]["errors_at"].get<std::string>().find("samples"), std::string::npos);
  EXPECT_LE(report["file"]["max_error"].get<double>(), e);
  return worst;
}

TEST(MaxErrorCommand, ZeroIsLosslessOnIntegerVolumes) {
  const std::string u8 =
      write_volume<std::uint8_t>("u8", {13, 9, 7}, {0.7, 1.3, 2.1}, "uint8", 1, 40, 0, 255);
  const std::string i16 =
      write_volume<std::int16_t>("i16", {11, 17, 5}, {1.0, 0.45, 3.0}, "int16", 2, 900, -30000, 30000);
  const std::string flat = write_volume<std::uint8_t>("flat", {9, 5, 15}, {1, 1, 1}, "uint8", 3, 0, 0, 255);
  for (const auto& in : {u8, i16, flat}) {
    EXPECT_EQ(round_trip_max_error(in, 0, fs::path(in).stem().string() + "_lossless"), 0.0) << in;
    const HierarchyFile f =
        read_hierarchy(scratch() + "/" + fs::path(in).stem().string() + "_lossless.mlfeh");
    EXPECT_TRUE(f.integer_values);
    EXPECT_EQ(f.value_bound, 0);
  }
}

// Mostly zeros (a label map's background) at 0.8 mm: the barycentric weights of a sample on a
// vertex are then not exactly 0 and 1, which left 1e-14 beside the zeros before the decoded
// samples of integer builds were rounded.
TEST(MaxErrorCommand, ZeroIsLosslessBesideZerosAtNonIntegerSpacing) {
  const std::array<int, 3> dims{19, 14, 11};
  std::vector<std::uint8_t> v(static_cast<std::size_t>(dims[0]) * dims[1] * dims[2], 0);
  std::size_t i = 0;
  for (int z = 0; z < dims[2]; ++z)
    for (int y = 0; y < dims[1]; ++y)
      for (int x = 0; x < dims[0]; ++x, ++i)
        v[i] = (x - 9) * (x - 9) + (y - 6) * (y - 6) + (z - 5) * (z - 5) < 16 ? 7 : (x > 14 && y < 4 ? 3 : 0);
  const std::string raw = scratch() + "/zeros08.raw";
  std::ofstream(raw, std::ios::binary)
      .write(reinterpret_cast<const char*>(v.data()), std::streamsize(v.size()));
  std::ofstream(raw + ".json") << "{\"dims\":[19,14,11],\"dtype\":\"uint8\",\"spacing\":[0.8,0.8,0.8],"
                                  "\"endian\":\"little\"}";
  EXPECT_EQ(round_trip_max_error(raw, 0, "zeros08_lossless"), 0.0);
}

TEST(MaxErrorCommand, EverySampleWithinTheBound) {
  // Property test: random float volumes (odd dims, anisotropic spacing) and several bounds.
  unsigned seed = 10;
  for (const auto& dims : {std::array<int, 3>{15, 11, 9}, std::array<int, 3>{7, 19, 13}}) {
    const std::string f32 = write_volume<float>("f32_" + std::to_string(seed), dims, {0.9, 1.7, 1.1},
                                                "float32", seed, 3.0, -50, 150);
    double previous_bytes = INFINITY;
    for (double e : {0.05, 0.5, 2.0, 10.0}) {
      const std::string tag = "f32_" + std::to_string(seed) + "_" + std::to_string(int(e * 100));
      const double worst = round_trip_max_error(f32, e, tag);
      EXPECT_LE(worst, e) << tag;
      EXPECT_GT(worst, 0.05 * e) << tag;  // lossy: the bound is spent, not ignored
      const double bytes = double(fs::file_size(scratch() + "/" + tag + ".mlfeh"));
      EXPECT_LT(bytes, previous_bytes) << tag;  // a looser bound gives a smaller file
      previous_bytes = bytes;
    }
    ++seed;
  }
  // Integer data with an integer bound keeps integer values within it.
  const std::string u8 =
      write_volume<std::uint8_t>("u8b", {13, 9, 7}, {0.7, 1.3, 2.1}, "uint8", 4, 40, 0, 255);
  for (double e : {1.0, 3.0}) {
    const double worst = round_trip_max_error(u8, e, "u8b_" + std::to_string(int(e)));
    EXPECT_LE(worst, e);
    if (e == 3.0) {
      EXPECT_GT(worst, 0);
    }
  }
}

// Property test on integer data: random uint8 and int16 volumes, integer and fractional bounds,
// the quantization share at both ends of its range. Every sample stays within E; at share 1 the
// values take the whole bound, so each integer E gives its own file (no staircase where E = 3
// stored E = 2's), and a fractional E spends its fraction on interpolation.
TEST(MaxErrorCommand, IntegerDataWithinEveryBoundAndShare) {
  const std::string u8 =
      write_volume<std::uint8_t>("u8s", {15, 11, 9}, {0.7, 1.3, 2.1}, "uint8", 7, 12, 0, 255);
  const std::string i16 =
      write_volume<std::int16_t>("i16s", {9, 13, 7}, {1.0, 0.45, 3.0}, "int16", 8, 60, -3000, 3000);
  for (const auto& in : {u8, i16})
    for (const char* share : {"0", "0.5", "1"}) {
      double previous_bytes = INFINITY;
      for (double e : {1.0, 2.0, 2.5, 3.0, 4.0, 7.75}) {
        const std::string tag =
            fs::path(in).stem().string() + "_" + share + "_" + std::to_string(int(e * 100));
        const double worst = round_trip_max_error(in, e, tag, std::string("--quantization-share ") + share);
        EXPECT_LE(worst, e) << tag;
        const double bytes = double(fs::file_size(scratch() + "/" + tag + ".mlfeh"));
        // (Share 0 stores the values losslessly whatever E: its files differ by the bound's
        // digits in the metadata.)
        if (std::string(share) != "0") {
          EXPECT_LE(bytes, previous_bytes) << tag;
        }
        if (std::string(share) == "1" && e == std::floor(e)) {
          EXPECT_EQ(worst, e) << tag;  // the bound is spent on the values
          EXPECT_LT(bytes, previous_bytes) << tag;
        }
        previous_bytes = bytes;
      }
    }
}

TEST(MaxErrorCommand, ExportWritesTheDataGridNotTheLatticeCube) {
  const std::string skull = test::sample_path("ct_skull_64.nrrd");
  const std::string h = scratch() + "/skull.mlfeh", out = scratch() + "/skull_out.nrrd";
  ASSERT_EQ(run("build " + skull + " -o " + h + " --quiet --max-vertices 3000").status, 0);
  ASSERT_EQ(run("export " + h + " -o " + out).status, 0);
  const ScalarGrid src = read_volume(skull), got = read_volume(out);
  EXPECT_EQ(got.dims, src.dims);
  const HierarchyFile f = read_hierarchy(h);
  EXPECT_EQ(f.version, 4);
  EXPECT_TRUE(f.on_lattice);
  EXPECT_EQ(f.lattice_level, 6);  // 63 sample steps: T0 is 64 wide
  // Reading it back gives the approximation on the lattice, which iso and render clip with.
  const Built b = built_from_file(h);
  const auto& a = b.get<3>();
  EXPECT_TRUE(a.on_lattice);
  EXPECT_EQ(a.lattice.width, 64);
  for (int k = 0; k < 3; ++k) EXPECT_DOUBLE_EQ(a.data_extent[k], 63 * src.transform.spacing[k]);
}

TEST(MaxErrorCommand, SameBytesWithOneAndTwoThreads) {
  const std::string u8 = write_volume<std::uint8_t>("thr", {21, 15, 11}, {1, 1.5, 2}, "uint8", 5, 30, 0, 255);
  const std::string f32 = write_volume<float>("thrf", {17, 13, 9}, {1, 1, 1}, "float32", 6, 2, 0, 100);
  for (const std::string& args :
       {u8 + " --max-error 0", u8 + " --max-error 2", f32 + " --max-error 0.5", f32}) {
    const std::string a = scratch() + "/t1.mlfeh", b = scratch() + "/t2.mlfeh";
    ASSERT_EQ(run("--threads 1 build " + args + " -o " + a + " --quiet").status, 0) << args;
    ASSERT_EQ(run("--threads 2 build " + args + " -o " + b + " --quiet").status, 0) << args;
    EXPECT_EQ(read_bytes(a), read_bytes(b)) << args;
  }
}

TEST(MaxErrorCommand, MeshInputIsRefused) {
  const RunResult r = run("build " + test::test_data_path("small_tets_raw.vtu") + " -o " + scratch() +
                          "/m.mlfeh --max-error 1");
  EXPECT_EQ(r.status, 2);
  EXPECT_FALSE(fs::exists(scratch() + "/m.mlfeh"));
}

}  // namespace
}  // namespace mlfe
