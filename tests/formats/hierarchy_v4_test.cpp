// The .mlfeh version 4 file (docs/mlfeh-v4.md): it decodes exactly the values of version 3 (so
// every value stays within the bound, and integers at bound 0 are lossless) over random
// hierarchies, values and bounds, with the range-coded form in use; every level prefix
// decodes; the bytes do not depend on the thread count; and corrupt files whose checksums were
// repaired (so the decoders themselves see the damage) give mlfe::Error or a valid read, never
// a crash. Form 2 (values quantized against the chosen prediction) keeps every value within the
// bound and the same properties.
#include <gtest/gtest.h>
#include <mlfe/core/base/error.h>
#include <mlfe/formats/hierarchy_io.h>
#include <tbb/task_arena.h>
#include <zlib.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <map>
#include <random>
#include <string>

#include "tests/formats/lattice_hierarchies.h"
#include "tests/test_paths.h"

namespace mlfe {
namespace {

namespace fs = std::filesystem;
using Bytes = std::vector<std::uint8_t>;

fs::path temp_file(const std::string& name) { return fs::path(test::scratch_dir("hierarchy_v4")) / name; }

// Data 13 x 16 x 9 samples on a level-4 lattice.
Hierarchy<3> lattice_hierarchy(unsigned seed) { return test::random_lattice_hierarchy(4, 0.7, seed); }

HierarchyFileInfo lattice_info() { return test::lattice_file_info(4, {13, 16, 9}); }

// A smooth field plus noise of `noise` (integers when asked), so the lattice prediction helps.
std::vector<double> field(const Hierarchy<3>& h, unsigned seed, double noise, bool integer) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> n(0, noise);
  std::vector<double> v(h.vertex_count());
  for (std::uint32_t i = 0; i < v.size(); ++i) {
    const auto& p = h.point(VertexId(i));
    v[i] = 200 * std::sin(0.3 * p[0]) * std::cos(0.1 * p[1]) + 3 * p[2] + n(rng);
    if (integer) v[i] = std::nearbyint(v[i]);
  }
  return v;
}

HierarchyWriteOptions options(int version, double bound, bool integer) {
  HierarchyWriteOptions o;
  o.version = version;
  o.max_error = bound;
  o.integer_values = integer;
  return o;
}

// The decoded values by vertex position.
std::map<std::array<double, 3>, double> by_point(const HierarchyFile& f) {
  const auto& h = std::get<Hierarchy<3>>(f.hierarchy);
  std::map<std::array<double, 3>, double> m;
  for (std::uint32_t v = 0; v < h.vertex_count(); ++v) m[h.point(VertexId(v))] = f.values[v];
  return m;
}

// The level sections' forms (docs/mlfeh-v4.md: u32 form after k, n, m of a raw LEVL payload;
// a zstd-compressed section is form 1).
std::vector<std::uint32_t> level_forms(const Bytes& file) {
  std::vector<std::uint32_t> forms;
  for (std::size_t pos = 16; pos + 28 <= file.size();) {
    std::uint32_t tag, codec, form = 1;
    std::uint64_t stored;
    std::memcpy(&tag, &file[pos], 4);
    std::memcpy(&codec, &file[pos + 4], 4);
    std::memcpy(&stored, &file[pos + 8], 8);
    if (tag == 0x4C56454Cu && codec == 0) std::memcpy(&form, &file[pos + 28 + 12], 4);  // "LEVL"
    if (tag == 0x4C56454Cu) forms.push_back(form);
    pos += 28 + stored;
  }
  return forms;
}

// Recomputes every section's CRC-32 (the HEAD's seeded with the preamble's), as far as the
// sizes allow.
void repair_crcs(Bytes& b) {
  for (std::size_t pos = 16; pos + 28 <= b.size();) {
    std::uint64_t stored;
    std::memcpy(&stored, &b[pos + 8], 8);
    if (stored > b.size() - pos - 28) return;
    uLong c = pos == 16 ? ::crc32(0, b.data(), 16) : 0;
    c = ::crc32(c, &b[pos], 24);
    c = ::crc32(c, &b[pos + 28], static_cast<uInt>(stored));
    const auto crc = static_cast<std::uint32_t>(c);
    std::memcpy(&b[pos + 24], &crc, 4);
    pos += 28 + stored;
  }
}

// Property: over random hierarchies, values (real and integer) and bounds, version 4 decodes
// exactly version 3's values, each within the bound of the written value (integers at bound 0:
// the values themselves), with range-coded level sections among them.
TEST(HierarchyFileV4, DecodesVersion3sValuesWithinTheBound) {
  std::mt19937 rng(44);
  int coded = 0;
  for (unsigned seed = 1; seed <= 6; ++seed) {
    const Hierarchy<3> h = lattice_hierarchy(seed);
    for (bool integer : {true, false}) {
      const double noise = std::uniform_real_distribution<double>(0.5, 8)(rng);
      const std::vector<double> u = field(h, seed + 100, noise, integer);
      const double bound = integer ? double(std::uniform_int_distribution<int>(0, 6)(rng))
                                   : std::uniform_real_distribution<double>(0.01, 5)(rng);
      const auto p3 = temp_file("v3.mlfeh"), p4 = temp_file("v4.mlfeh");
      write_hierarchy(p3.string(), h, u, lattice_info(), options(3, bound, integer));
      write_hierarchy(p4.string(), h, u, lattice_info(), options(4, bound, integer));
      const HierarchyFile f3 = read_hierarchy(p3.string()), f4 = read_hierarchy(p4.string());
      EXPECT_EQ(f4.version, 4);
      EXPECT_EQ(f4.values, f3.values) << "seed " << seed << " integer " << integer << " bound " << bound;
      const auto got = by_point(f4);
      for (std::uint32_t v = 0; v < h.vertex_count(); ++v) {
        const double d = got.at(h.point(VertexId(v)));
        ASSERT_LE(std::fabs(d - u[v]), bound * (1 + 1e-12)) << "seed " << seed << " vertex " << v;
        if (integer) {
          ASSERT_EQ(d, std::nearbyint(d));
        }
      }
      for (std::uint32_t form : level_forms(test::read_file_bytes(p4))) coded += form == 0;
    }
  }
  EXPECT_GT(coded, 0);  // the range-coded form was exercised, not only v3's
}

// Form 2 (HierarchyWriteOptions::residual_quantization), property over random hierarchies,
// values (real and integer) and bounds > 0: every level is stored in form 2, the reader decodes
// exactly residual_quantized_values(), each within the bound (integers stay integers), every
// level prefix decodes to the same values of its vertices, and the file is smaller than form 0's
// on these smooth fields at wide bounds.
TEST(HierarchyFileV4, ResidualFormDecodesItsValuesWithinTheBound) {
  std::mt19937 rng(45);
  for (unsigned seed = 1; seed <= 6; ++seed) {
    for (bool integer : {true, false}) {
      Hierarchy<3> h = lattice_hierarchy(seed + 20);
      std::vector<double> u =
          field(h, seed + 200, std::uniform_real_distribution<double>(0.5, 8)(rng), integer);
      const LevelDescription<3> levels = renumber_canonically(h, {&u});
      const double bound = integer ? double(std::uniform_int_distribution<int>(1, 9)(rng))
                                   : std::uniform_real_distribution<double>(0.01, 9)(rng);
      HierarchyWriteOptions o = options(4, bound, integer);
      o.residual_quantization = true;
      const std::vector<double> d = residual_quantized_values(h, levels, u, lattice_info(), o);
      const auto p2 = temp_file("form2.mlfeh"), p0 = temp_file("form0.mlfeh");
      write_hierarchy(p2.string(), h, levels, u, lattice_info(), o);
      write_hierarchy(p0.string(), h, levels, u, lattice_info(), options(4, bound, integer));
      const HierarchyFile f = read_hierarchy(p2.string());
      const std::string what = "seed " + std::to_string(seed) + " integer " + std::to_string(integer) +
                               " bound " + std::to_string(bound);
      EXPECT_EQ(f.values, d) << what;
      for (std::uint32_t v = 0; v < h.vertex_count(); ++v) {
        ASSERT_LE(std::fabs(d[v] - u[v]), bound * (1 + 1e-12)) << what << " vertex " << v;
        if (integer) {
          ASSERT_EQ(d[v], std::nearbyint(d[v])) << what;
        }
      }
      for (std::uint32_t form : level_forms(test::read_file_bytes(p2))) EXPECT_EQ(form, 2u) << what;
      for (int k = 0; k < f.file_levels; ++k) {
        const HierarchyFile fk = read_hierarchy(p2.string(), k);
        ASSERT_LE(fk.values.size(), d.size());
        for (std::size_t v = 0; v < fk.values.size(); ++v)
          ASSERT_EQ(fk.values[v], d[v]) << what << " level " << k;
      }
      if (bound >= 4) {
        EXPECT_LT(fs::file_size(p2), fs::file_size(p0)) << what;
      }
    }
  }
}

TEST(HierarchyFileV4, EveryLevelPrefixDecodes) {
  const Hierarchy<3> h = lattice_hierarchy(7);
  const auto p = temp_file("prefix.mlfeh");
  write_hierarchy(p.string(), h, field(h, 8, 2, true), lattice_info(), options(4, 0, true));
  const HierarchyFile full = read_hierarchy(p.string());
  for (int k = 0; k <= full.file_levels; ++k) {
    const HierarchyFile f = read_hierarchy(p.string(), k);
    const auto& hk = std::get<Hierarchy<3>>(f.hierarchy);
    ASSERT_EQ(f.values.size(), hk.vertex_count());
    EXPECT_EQ(hk.max_level(), k);
    for (std::size_t v = 0; v < f.values.size(); ++v) ASSERT_EQ(f.values[v], full.values[v]) << k;
  }
}

TEST(HierarchyFileV4, TheBytesDoNotDependOnTheThreads) {
  const Hierarchy<3> h = lattice_hierarchy(9);
  const std::vector<double> u = field(h, 10, 3, false);
  for (bool residual : {false, true}) {
    HierarchyWriteOptions o = options(4, 0.7, false);
    o.residual_quantization = residual;
    Bytes one, two;
    for (int threads : {1, 2}) {
      const auto p = temp_file("threads.mlfeh");
      tbb::task_arena(threads).execute([&] { write_hierarchy(p.string(), h, u, lattice_info(), o); });
      (threads == 1 ? one : two) = test::read_file_bytes(p);
    }
    EXPECT_EQ(one, two) << residual;
  }
}

// Truncations, bit flips and lying counts with the CRCs repaired: the range decoders, the marks
// and the counts are checked themselves (under ASan in CI: no overflow, no unbounded allocation).
// Forms 0 and 2.
TEST(HierarchyFileV4, DamageBehindRepairedChecksumsIsRejectedOrReadsSafely) {
  const Hierarchy<3> h = lattice_hierarchy(11);
  const auto p = temp_file("good.mlfeh"), q = temp_file("bad.mlfeh");
  for (bool residual : {false, true}) {
    HierarchyWriteOptions o = options(4, 1, true);
    o.residual_quantization = residual;
    write_hierarchy(p.string(), h, field(h, 12, 2, true), lattice_info(), o);
    const Bytes good = test::read_file_bytes(p);
    for (std::size_t n = 16; n < good.size(); n += 1 + good.size() / 151) {
      Bytes b(good.begin(), good.begin() + static_cast<std::ptrdiff_t>(n));
      repair_crcs(b);
      test::write_file_bytes(q, b);
      EXPECT_THROW(read_hierarchy(q.string()), Error) << "cut at " << n;
    }
    int rejected = 0;
    for (std::size_t i = 16; i < good.size(); i += 1 + good.size() / 397) {
      for (std::uint8_t mask : {0x01, 0x40, 0xFF}) {
        Bytes b = good;
        b[i] ^= mask;
        repair_crcs(b);
        test::write_file_bytes(q, b);
        try {
          read_hierarchy(q.string());
        } catch (const Error&) {
          ++rejected;
        }
      }
    }
    EXPECT_GT(rejected, 0);
  }
}

// tests/data/small_lattice_v4.mlfeh (a seed of fuzz/run_fuzzers.sh) is small_lattice_v3.mlfeh
// written again as version 4 (bench/cpp/mlfeh_recode_bench.cpp): the same values.
TEST(HierarchyFileV4, TheFuzzSeedReadsAsItsVersion3) {
  const std::string dir = std::string(MLFE_SOURCE_DIR) + "/tests/data/";
  const HierarchyFile f4 = read_hierarchy(dir + "small_lattice_v4.mlfeh");
  const HierarchyFile f3 = read_hierarchy(dir + "small_lattice_v3.mlfeh");
  EXPECT_EQ(f4.version, 4);
  EXPECT_EQ(f4.values, f3.values);
  EXPECT_EQ(f4.data_dims, f3.data_dims);
}

// tests/data/small_lattice_v4_form2.mlfeh (a seed of fuzz/run_fuzzers.sh for the form-2 decoder)
// is an error-bounded build (--max-error 3) of small_lattice_v3.mlfeh's 9 x 7 x 5 samples: it
// reads, with its levels in form 2 and its bound.
TEST(HierarchyFileV4, TheForm2FuzzSeedReads) {
  const std::string path = std::string(MLFE_SOURCE_DIR) + "/tests/data/small_lattice_v4_form2.mlfeh";
  const HierarchyFile f = read_hierarchy(path);
  EXPECT_EQ(f.version, 4);
  EXPECT_TRUE(f.integer_values);
  EXPECT_EQ(f.sample_error_bound, 3);
  EXPECT_EQ(f.data_dims, (std::array<std::int64_t, 3>{9, 7, 5}));
  const std::vector<std::uint32_t> forms = level_forms(test::read_file_bytes(path));
  ASSERT_FALSE(forms.empty());
  for (std::uint32_t form : forms) EXPECT_EQ(form, 2u);
}

}  // namespace
}  // namespace mlfe
