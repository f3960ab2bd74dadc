#include <gtest/gtest.h>
#include <mlfe/core/base/error.h>
#include <mlfe/formats/hierarchy_io.h>
#include <zlib.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <string>

#include "tests/core/test_hierarchies.h"
#include "tests/test_paths.h"

namespace mlfe {
namespace {

namespace fs = std::filesystem;
using Bytes = std::vector<std::uint8_t>;

// Red and green elements at several levels: refine toward the corner at the origin.
template <int D>
Hierarchy<D> adapted(int rounds) {
  typename Hierarchy<D>::Point lo, hi;
  lo.fill(0.0);
  hi.fill(1.0);
  hi[1] = 2.0;
  return test::refine_toward_origin(Hierarchy<D>::box(lo, hi), rounds);
}

template <int D>
std::vector<double> values_of(const Hierarchy<D>& h) {
  std::vector<double> u;
  for (const auto& p : h.points()) u.push_back(std::sin(3 * p[0]) + p[1] * p[1]);
  return u;
}

HierarchyFileInfo sample_info() {
  HierarchyFileInfo info;
  info.transform.spacing = {0.5, 0.75, 2.0};
  info.transform.origin = {-10.0, 4.0, 1.5};
  info.transform.direction = {0, 1, 0, -1, 0, 0, 0, 0, 1};
  info.space = "LPS";
  info.value_min = -1.0;
  info.value_max = 5.0;
  info.metadata = {{"source", "test"}, {"levels", 3}};
  return info;
}

fs::path temp_file(const std::string& name) { return fs::path(test::scratch_dir("hierarchy_io")) / name; }

Bytes read_bytes(const fs::path& p) { return test::read_file_bytes(p); }
void write_bytes(const fs::path& p, const Bytes& b) { test::write_file_bytes(p, b); }

// Recomputes the trailing CRC so that a deliberate corruption reaches the later checks.
void fix_crc(Bytes& b) {
  const std::uint32_t crc = static_cast<std::uint32_t>(::crc32(0, b.data(), static_cast<uInt>(b.size() - 4)));
  std::memcpy(b.data() + b.size() - 4, &crc, 4);
}

std::string read_error(const fs::path& p) {
  try {
    read_hierarchy(p.string());
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

template <int D>
void expect_round_trip(bool compress) {
  const Hierarchy<D> h = adapted<D>(3);
  const std::vector<double> u = values_of(h);
  const HierarchyFileInfo info = sample_info();
  const fs::path a = temp_file("a" + std::to_string(D) + std::to_string(compress) + ".mlfeh");
  const fs::path b = temp_file("b" + std::to_string(D) + std::to_string(compress) + ".mlfeh");
  write_hierarchy<D>(a.string(), h, u, info, {compress, 3});
  const HierarchyFile f = read_hierarchy(a.string());
  ASSERT_EQ(f.dim, D);
  const auto& g = std::get<Hierarchy<D>>(f.hierarchy);
  test::expect_same_hierarchy(g, h);
  EXPECT_EQ(f.values, u);
  EXPECT_EQ(f.transform.spacing, info.transform.spacing);
  EXPECT_EQ(f.transform.origin, info.transform.origin);
  EXPECT_EQ(f.transform.direction, info.transform.direction);
  EXPECT_EQ(f.space, info.space);
  EXPECT_EQ(f.value_min, info.value_min);
  EXPECT_EQ(f.value_max, info.value_max);
  EXPECT_EQ(f.metadata, info.metadata);
  write_hierarchy(b.string(), f, {compress, 3});
  EXPECT_EQ(read_bytes(a), read_bytes(b)) << "re-writing what was read must give the same bytes";
}

TEST(HierarchyFileRoundTrip, ReproducesArraysAndBytesIn2D) { expect_round_trip<2>(false); }
TEST(HierarchyFileRoundTrip, ReproducesArraysAndBytesIn3D) { expect_round_trip<3>(false); }
TEST(HierarchyFileRoundTrip, ReproducesArraysAndBytesWithZstdIn2D) { expect_round_trip<2>(true); }
TEST(HierarchyFileRoundTrip, ReproducesArraysAndBytesWithZstdIn3D) { expect_round_trip<3>(true); }

TEST(HierarchyFileRoundTrip, KeepsAbsentValuesAbsentAndEmptyMetadataAnObject) {
  const auto h = adapted<3>(2);
  const fs::path p = temp_file("novalues.mlfeh");
  write_hierarchy<3>(p.string(), h, {}, HierarchyFileInfo{});
  const HierarchyFile f = read_hierarchy(p.string());
  EXPECT_TRUE(f.values.empty());
  EXPECT_TRUE(f.metadata.is_object());
  EXPECT_TRUE(f.metadata.empty());
}

TEST(HierarchyFileWrite, CompressionMakesTheFileSmaller) {
  const auto h = adapted<3>(4);
  const fs::path raw = temp_file("raw.mlfeh"), zst = temp_file("zst.mlfeh");
  write_hierarchy<3>(raw.string(), h, values_of(h), sample_info(), {false, 3});
  write_hierarchy<3>(zst.string(), h, values_of(h), sample_info(), {true, 3});
  EXPECT_LT(fs::file_size(zst), fs::file_size(raw) * 3 / 4);
}

TEST(HierarchyFileWrite, RejectsNaNValuesAndWrongValueCountsWithoutLeavingAFile) {
  const auto h = adapted<2>(1);
  const fs::path p = temp_file("bad_values.mlfeh");
  fs::remove(p);
  auto u = values_of(h);
  u[3] = std::nan("");
  EXPECT_THROW(write_hierarchy<2>(p.string(), h, u, sample_info()), Error);
  u.pop_back();
  EXPECT_THROW(write_hierarchy<2>(p.string(), h, u, sample_info()), Error);
  HierarchyFileInfo bad = sample_info();
  bad.space = "bad\nspace";
  EXPECT_THROW(write_hierarchy<2>(p.string(), h, {}, bad), Error);
  EXPECT_FALSE(fs::exists(p));
}

TEST(HierarchyFileRead, NamesABadMagic) {
  const auto h = adapted<2>(1);
  const fs::path p = temp_file("magic.mlfeh");
  write_hierarchy<2>(p.string(), h, {}, sample_info());
  Bytes b = read_bytes(p);
  b[3] = 'X';
  write_bytes(p, b);
  const std::string msg = read_error(p);
  EXPECT_EQ(msg, p.string() + ": not an mlfe hierarchy file (bad magic)");
}

TEST(HierarchyFileRead, NamesAnUnsupportedVersion) {
  const auto h = adapted<2>(1);
  const fs::path p = temp_file("version.mlfeh");
  write_hierarchy<2>(p.string(), h, {}, sample_info());
  Bytes b = read_bytes(p);
  b[8] = 5;
  write_bytes(p, b);
  EXPECT_EQ(read_error(p),
            p.string() + ": unsupported hierarchy file version 5 (this mlfe reads 1, 2, 3 and 4)");
}

TEST(HierarchyFileRead, RejectsHugeCountsAgainstTheFileSizeBeforeAllocating) {
  const auto h = adapted<3>(1);
  const fs::path p = temp_file("huge.mlfeh");
  write_hierarchy<3>(p.string(), h, {}, sample_info(), {false, 3});
  Bytes b = read_bytes(p);
  // nv = 2^32 - 2 with a consistent raw size: only the file-size check can catch it.
  const std::uint64_t nv = 0xFFFFFFFEull;
  std::uint64_t ne = 0;
  std::memcpy(&ne, b.data() + 24, 8);
  const std::uint64_t rs = nv * (24 + 8 + 1) + ne * (16 + 11);
  std::memcpy(b.data() + 16, &nv, 8);
  std::memcpy(b.data() + 184, &rs, 8);
  std::memcpy(b.data() + 192, &rs, 8);
  write_bytes(p, b);
  EXPECT_NE(read_error(p).find("does not match the header"), std::string::npos) << read_error(p);
}

TEST(HierarchyFileRead, RejectsEveryTruncatedPrefix) {
  for (bool compress : {false, true}) {
    const auto h = adapted<2>(2);
    const fs::path p = temp_file("full.mlfeh"), q = temp_file("prefix.mlfeh");
    write_hierarchy<2>(p.string(), h, values_of(h), sample_info(), {compress, 3});
    const Bytes b = read_bytes(p);
    for (std::size_t n = 0; n < b.size(); ++n) {
      write_bytes(q, Bytes(b.begin(), b.begin() + static_cast<std::ptrdiff_t>(n)));
      EXPECT_NE(read_error(q), "") << "prefix of " << n << " of " << b.size() << " bytes was accepted";
    }
  }
}

TEST(HierarchyFileRead, RejectsRandomByteCorruptionByChecksum) {
  const auto h = adapted<3>(2);
  const fs::path p = temp_file("clean.mlfeh"), q = temp_file("corrupt.mlfeh");
  write_hierarchy<3>(p.string(), h, values_of(h), sample_info(), {true, 3});
  const Bytes b = read_bytes(p);
  std::mt19937 rng(7);
  for (int trial = 0; trial < 300; ++trial) {
    Bytes c = b;
    const std::size_t at = rng() % c.size();
    c[at] ^= static_cast<std::uint8_t>(1 + rng() % 255);
    write_bytes(q, c);
    EXPECT_NE(read_error(q), "") << "corruption at byte " << at << " was accepted";
  }
}

// With the CRC recomputed, corruption reaches the structural validation (from_arrays): the
// reader must then either throw mlfe::Error or return a hierarchy that passed validation.
TEST(HierarchyFileRead, SurvivesCorruptionBehindAValidChecksum) {
  const auto h = adapted<3>(2);
  const fs::path p = temp_file("clean_raw.mlfeh"), q = temp_file("corrupt_raw.mlfeh");
  write_hierarchy<3>(p.string(), h, values_of(h), sample_info(), {false, 3});
  const Bytes b = read_bytes(p);
  std::mt19937 rng(11);
  int rejected = 0;
  for (int trial = 0; trial < 2000; ++trial) {
    Bytes c = b;
    for (int k = 0; k < 1 + trial % 3; ++k)
      c[rng() % (c.size() - 4)] ^= static_cast<std::uint8_t>(1 + rng() % 255);
    fix_crc(c);
    write_bytes(q, c);
    try {
      const HierarchyFile f = read_hierarchy(q.string());
      const auto& g = std::get<Hierarchy<3>>(f.hierarchy);
      EXPECT_EQ(g.vertex_count(), f.values.size());
      (void)g.leaves();
    } catch (const Error&) {
      ++rejected;
    }
  }
  EXPECT_GT(rejected, 1000) << "most corruptions must be detected";
}

TEST(HierarchyFileRead, RejectsNaNValuesBehindAValidChecksum) {
  const auto h = adapted<2>(1);
  const fs::path p = temp_file("nan.mlfeh");
  write_hierarchy<2>(p.string(), h, values_of(h), sample_info(), {false, 3});
  Bytes b = read_bytes(p);
  const std::size_t nv = h.vertex_count();
  // Array section: after the 200-byte header, the space ("LPS") and the metadata JSON; the
  // values follow points (2 f64), parents (2 u32) and levels (u8) of every vertex.
  const std::size_t values_at = 200 + 3 + sample_info().metadata.dump().size() + nv * (16 + 8 + 1);
  const double nan = std::nan("");
  std::memcpy(b.data() + values_at + 8 * 2, &nan, 8);
  fix_crc(b);
  write_bytes(p, b);
  EXPECT_EQ(read_error(p), p.string() + ": value of vertex 2 is NaN");
}

TEST(HierarchyFileRead, RejectsAMissingFile) {
  EXPECT_NE(read_error(temp_file("does_not_exist.mlfeh")).find("cannot open"), std::string::npos);
}

}  // namespace
}  // namespace mlfe
