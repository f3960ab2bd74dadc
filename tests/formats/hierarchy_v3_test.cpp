// The .mlfeh version 3 file (docs/mlfeh-v3.md): the samples' lattice and the sample error
// bound read back as written, integer surpluses are lossless at bound 0 and within the bound
// otherwise, inconsistent lattices and values are refused, and every truncation or bit flip
// of a v3 file is rejected.
#include <gtest/gtest.h>
#include <mlfe/core/base/error.h>
#include <mlfe/formats/hierarchy_io.h>
#include <mlfe/formats/hierarchy_levels.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <random>
#include <string>

#include "tests/formats/lattice_hierarchies.h"
#include "tests/test_paths.h"

namespace mlfe {
namespace {

namespace fs = std::filesystem;
using Bytes = std::vector<std::uint8_t>;

fs::path temp_file(const std::string& name) { return fs::path(test::scratch_dir("hierarchy_v3")) / name; }

Bytes read_bytes(const fs::path& p) { return test::read_file_bytes(p); }
void write_bytes(const fs::path& p, const Bytes& b) { test::write_file_bytes(p, b); }

// Data 5 x 3 x 7 samples on a level-3 lattice.
Hierarchy<3> lattice_hierarchy(unsigned seed) { return test::random_lattice_hierarchy(3, 0.4, seed); }

HierarchyFileInfo lattice_info() { return test::lattice_file_info(3, {5, 3, 7}); }

std::vector<double> random_integers(std::size_t n, unsigned seed) {
  std::mt19937 rng(seed);
  std::vector<double> v(n);
  for (double& x : v) x = std::uniform_int_distribution<int>(-300, 300)(rng);
  return v;
}

HierarchyWriteOptions v3_options(double bound, bool integer) {
  HierarchyWriteOptions o;
  o.version = 3;
  o.max_error = bound;
  o.integer_values = integer;
  return o;
}

TEST(HierarchyFileV3, TheLatticeAndTheSampleBoundReadBack) {
  const Hierarchy<3> h = lattice_hierarchy(1);
  HierarchyFileInfo info = lattice_info();
  info.sample_error_bound = 0.25;
  const auto p = temp_file("lattice.mlfeh");
  write_hierarchy(p.string(), h, random_integers(h.vertex_count(), 2), info, v3_options(0.25, false));
  const HierarchyFile f = read_hierarchy(p.string());
  EXPECT_EQ(f.version, 3);
  EXPECT_TRUE(f.on_lattice);
  EXPECT_EQ(f.lattice_level, 3);
  EXPECT_EQ(f.data_dims, (std::array<std::int64_t, 3>{5, 3, 7}));
  EXPECT_EQ(f.sample_error_bound, 0.25);
  EXPECT_FALSE(f.integer_values);
  EXPECT_EQ(f.value_bound, 0.25);
  // Off the lattice, a v3 file says so.
  HierarchyFileInfo plain;
  plain.value_max = 1;
  write_hierarchy(p.string(), h, {}, plain, v3_options(0, false));
  const HierarchyFile g = read_hierarchy(p.string());
  EXPECT_FALSE(g.on_lattice);
  EXPECT_TRUE(std::isnan(g.sample_error_bound));
}

TEST(HierarchyFileV3, IntegerSurplusesAreLosslessAtBoundZero) {
  for (unsigned seed : {3u, 4u, 5u}) {
    const Hierarchy<3> h = lattice_hierarchy(seed);
    const std::vector<double> u = random_integers(h.vertex_count(), seed + 10);
    const auto p = temp_file("integer.mlfeh");
    write_hierarchy(p.string(), h, u, lattice_info(), v3_options(0, true));
    const HierarchyFile f = read_hierarchy(p.string());
    EXPECT_TRUE(f.integer_values);
    EXPECT_EQ(f.value_bound, 0);
    // Same hierarchy up to numbering: compare the values by position.
    const auto& r = std::get<Hierarchy<3>>(f.hierarchy);
    ASSERT_EQ(r.vertex_count(), h.vertex_count());
    std::map<std::array<double, 3>, double> want;
    for (std::uint32_t v = 0; v < h.vertex_count(); ++v) want[h.point(VertexId(v))] = u[v];
    for (std::uint32_t v = 0; v < r.vertex_count(); ++v)
      ASSERT_EQ(f.values[v], want.at(r.point(VertexId(v)))) << "seed " << seed << " vertex " << v;
  }
}

TEST(HierarchyFileV3, IntegerSurplusesStayWithinAnIntegerBound) {
  const Hierarchy<3> h = lattice_hierarchy(6);
  const std::vector<double> u = random_integers(h.vertex_count(), 7);
  for (std::int64_t bound : {1, 2, 7}) {
    const std::vector<double> d = quantize_integer(h, u, bound);
    double worst = 0;
    for (std::size_t v = 0; v < u.size(); ++v) {
      EXPECT_EQ(d[v], std::nearbyint(d[v]));
      worst = std::max(worst, std::fabs(d[v] - u[v]));
    }
    EXPECT_LE(worst, double(bound));
    EXPECT_GT(worst, 0);  // the bound is used, not ignored
    const auto p = temp_file("integer_bound.mlfeh");
    write_hierarchy(p.string(), h, u, lattice_info(), v3_options(double(bound), true));
    const HierarchyFile f = read_hierarchy(p.string());
    EXPECT_EQ(f.value_bound, double(bound));
    const auto& r = std::get<Hierarchy<3>>(f.hierarchy);
    std::map<std::array<double, 3>, double> want;
    for (std::uint32_t v = 0; v < h.vertex_count(); ++v) want[h.point(VertexId(v))] = d[v];
    for (std::uint32_t v = 0; v < r.vertex_count(); ++v)
      ASSERT_EQ(f.values[v], want.at(r.point(VertexId(v))));
  }
}

TEST(HierarchyFileV3, TheIntegerPredictionIsTheFloorOfTheMean) {
  for (std::int64_t a : {-7, -2, -1, 0, 1, 2, 9})
    for (std::int64_t b : {-5, -1, 0, 1, 4, 11})
      EXPECT_EQ(integer_prediction(a, b), static_cast<std::int64_t>(std::floor((a + b) / 2.0)))
          << a << " " << b;
}

TEST(HierarchyFileV3, InconsistentInputIsRefused) {
  const Hierarchy<3> h = lattice_hierarchy(8);
  const auto p = temp_file("refused.mlfeh");
  const auto values = random_integers(h.vertex_count(), 9);
  // A lattice level that does not fit the dims, or dims that do not fit T0's cube.
  HierarchyFileInfo bad = lattice_info();
  bad.lattice_level = 4;
  EXPECT_THROW(write_hierarchy(p.string(), h, values, bad, v3_options(0, true)), Error);
  bad = lattice_info();
  bad.data_dims = {17, 3, 7};
  EXPECT_THROW(write_hierarchy(p.string(), h, values, bad, v3_options(0, true)), Error);
  bad = lattice_info();
  bad.data_dims = {5, 3, 1};
  EXPECT_THROW(write_hierarchy(p.string(), h, values, bad, v3_options(0, true)), Error);
  // The lattice needs version 3; integer coding needs integers and an integer bound.
  HierarchyWriteOptions v2 = v3_options(0, false);
  v2.version = 2;
  EXPECT_THROW(write_hierarchy(p.string(), h, values, lattice_info(), v2), Error);
  std::vector<double> half = values;
  half[h.vertex_count() / 2] += 0.5;
  EXPECT_THROW(write_hierarchy(p.string(), h, half, lattice_info(), v3_options(0, true)), Error);
  EXPECT_THROW(write_hierarchy(p.string(), h, values, lattice_info(), v3_options(0.5, true)), Error);
  EXPECT_FALSE(fs::exists(p));
}

TEST(HierarchyFileV3, EveryTruncationAndBitFlipIsRejected) {
  const Hierarchy<3> h = lattice_hierarchy(10);
  HierarchyFileInfo info = lattice_info();
  info.sample_error_bound = 0;
  const auto p = temp_file("flips.mlfeh");
  write_hierarchy(p.string(), h, random_integers(h.vertex_count(), 11), info, v3_options(0, true));
  const Bytes good = read_bytes(p);
  const auto q = temp_file("flipped.mlfeh");
  for (std::size_t n = 0; n < good.size(); n += 1 + good.size() / 97) {
    write_bytes(q, Bytes(good.begin(), good.begin() + static_cast<std::ptrdiff_t>(n)));
    EXPECT_THROW(read_hierarchy(q.string()), Error) << "cut at " << n;
  }
  for (std::size_t i = 0; i < good.size(); i += 1 + good.size() / 211) {
    Bytes b = good;
    b[i] ^= 0x04;
    write_bytes(q, b);
    EXPECT_THROW(read_hierarchy(q.string()), Error) << "flip at " << i;
  }
}

// tests/data/small_lattice_v3.mlfeh (a seed of fuzz/run_fuzzers.sh) is a lossless v3 file of a
// 9 x 7 x 5 uint8 volume (`mlfe build vol.raw --max-error 0`): it reads, with its lattice.
TEST(HierarchyFileV3, TheFuzzSeedReads) {
  const HierarchyFile f = read_hierarchy(std::string(MLFE_SOURCE_DIR) + "/tests/data/small_lattice_v3.mlfeh");
  EXPECT_EQ(f.version, 3);
  EXPECT_TRUE(f.on_lattice);
  EXPECT_TRUE(f.integer_values);
  EXPECT_EQ(f.data_dims, (std::array<std::int64_t, 3>{9, 7, 5}));
  EXPECT_EQ(f.lattice_level, 3);
  EXPECT_EQ(f.sample_error_bound, 0);
}

}  // namespace
}  // namespace mlfe
