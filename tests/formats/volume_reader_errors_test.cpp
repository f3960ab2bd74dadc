// Importers on bad input: every problem is one mlfe::Error line naming the file and the
// problem, never a crash, an abort or an exit from inside a library.
#include <dirent.h>
#include <gtest/gtest.h>
#include <mlfe/core/base/error.h>
#include <mlfe/formats/volume_reader.h>
#include <nifti2_io.h>
#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "tests/test_meshes.h"
#include "tests/test_paths.h"

namespace mlfe {
namespace {

using test::read_bytes;
using test::write_bytes;

const std::string kData = std::string(MLFE_SOURCE_DIR) + "/tests/data/";

std::string temp_dir() {
  std::string t = ::testing::TempDir() + "mlfe_bad_XXXXXX";
  std::vector<char> buf(t.begin(), t.end());
  buf.push_back('\0');
  if (!mkdtemp(buf.data())) throw std::runtime_error("mkdtemp failed");
  return std::string(buf.data()) + "/";
}

// Expects read_volume to throw one mlfe::Error line that names `file` (default: path) and
// contains every string in `parts`.
void expect_error(const std::string& path, const std::vector<std::string>& parts,
                  const VolumeReadOptions& opts = {}, std::string file = "") {
  if (file.empty()) file = path;
  try {
    ScalarGrid g = read_volume(path, opts);
    ADD_FAILURE() << "no error for " << path << " (read " << g.dims[0] << "x" << g.dims[1] << "x" << g.dims[2]
                  << ")";
  } catch (const Error& e) {
    const std::string m = e.what();
    EXPECT_EQ(m.find('\n'), std::string::npos) << m;
    EXPECT_EQ(m.rfind(file + ": ", 0), 0u) << "message does not start with the file name: " << m;
    for (const auto& p : parts)
      EXPECT_NE(m.find(p), std::string::npos) << "missing \"" << p << "\" in: " << m;
  }
}

std::string nrrd_header(const std::string& fields) { return "NRRD0004\n" + fields + "\n\n"; }

TEST(VolumeReaderErrors, MissingFileAndUnknownFormat) {
  const std::string dir = temp_dir();
  expect_error(dir + "nope.nrrd", {"cannot open"});
  write_bytes(dir + "empty.xyz", "");
  expect_error(dir + "empty.xyz", {"unrecognised volume format"});
  write_bytes(dir + "junk.xyz", "some text that is no volume");
  expect_error(dir + "junk.xyz", {"unrecognised volume format", "736f6d65"});
}

TEST(VolumeReaderErrors, WrongMagicForTheExtension) {
  const std::string dir = temp_dir();
  write_bytes(dir + "bad.nii", std::string(400, 'x'));
  expect_error(dir + "bad.nii", {"not a NIfTI"});
  write_bytes(dir + "bad.vdb", "definitely not a vdb file");
  expect_error(dir + "bad.vdb", {"not an OpenVDB file"});
  write_bytes(dir + "bad.nrrd", "NRRX0004\ntype: float\n");
  expect_error(dir + "bad.nrrd", {"not a NRRD"});
  write_bytes(dir + "bad.png", "\x89PNX....");
  expect_error(dir + "bad.png", {"not a PNG"});
  write_bytes(dir + "bad.pgm", "P6\n1 1\n255\nabc");
  expect_error(dir + "bad.pgm", {"not a binary PGM"});
}

TEST(VolumeReaderErrors, NrrdTruncatedDataIsRefusedBeforeTeemAllocates) {
  const std::string dir = temp_dir();
  std::string full = read_bytes(test::sample_path("ct_skull_64.nrrd"));
  write_bytes(dir + "cut.nrrd", full.substr(0, full.size() - 1000));
  expect_error(dir + "cut.nrrd", {"truncated", "1048576 bytes"});
}

TEST(VolumeReaderErrors, NrrdAbsurdDimsAreRefusedWithoutAllocating) {
  const std::string dir = temp_dir();
  write_bytes(
      dir + "huge.nrrd",
      nrrd_header("type: float\ndimension: 3\nsizes: 100000 100000 100000\nendian: little\nencoding: raw") +
          "abcd");
  // The file is far too short: that is found before the memory check.
  expect_error(dir + "huge.nrrd", {"truncated", "4000000000000000 bytes"});
  write_bytes(
      dir + "hugegz.nrrd",
      nrrd_header("type: float\ndimension: 3\nsizes: 100000 100000 100000\nendian: little\nencoding: gzip") +
          "abcd");
  // Refused from the gzip data's size alone (deflate's largest ratio), before any allocation.
  expect_error(dir + "hugegz.nrrd", {"4000000000000000 bytes of data", "gzip data can hold"});
  write_bytes(dir + "overflow.nrrd", nrrd_header("type: double\ndimension: 3\nsizes: 2000000000 2000000000 "
                                                 "2000000000\nendian: little\nencoding: raw") +
                                         "x");
  expect_error(dir + "overflow.nrrd", {"too large"});
  write_bytes(dir + "zero.nrrd", nrrd_header("type: float\ndimension: 3\nsizes: 4 0 4\nencoding: raw"));
  expect_error(dir + "zero.nrrd", {"bad NRRD header"});
  write_bytes(dir + "neg.nrrd", nrrd_header("type: float\ndimension: 3\nsizes: 4 -3 4\nencoding: raw"));
  expect_error(dir + "neg.nrrd", {"bad NRRD header"});
}

TEST(VolumeReaderErrors, MemoryLimitNamesBytesNeededAndAvailable) {
  VolumeReadOptions o;
  o.max_bytes = 1000;
  expect_error(test::sample_path("ct_skull_64.nrrd"),
               {"needs 2097152 bytes", "only 1000 bytes of memory are available"}, o);
  expect_error(kData + "ct_skull_64.raw", {"needs 1048576 bytes", "only 1000 bytes"}, o);
}

TEST(VolumeReaderErrors, NrrdUnsupportedTypeAndDimension) {
  const std::string dir = temp_dir();
  write_bytes(dir + "ll.nrrd",
              nrrd_header("type: long long\ndimension: 2\nsizes: 2 2\nendian: little\nencoding: raw") +
                  std::string(32, '\0'));
  expect_error(dir + "ll.nrrd", {"unsupported NRRD type"});
  write_bytes(dir + "4d.nrrd", nrrd_header("type: uchar\ndimension: 4\nsizes: 2 2 2 2\nencoding: raw") +
                                   std::string(16, '\0'));
  expect_error(dir + "4d.nrrd", {"4 axes"});
}

TEST(VolumeReaderErrors, NrrdCorruptGzip) {
  const std::string dir = temp_dir();
  write_bytes(dir + "z.nrrd", nrrd_header("type: float\ndimension: 2\nsizes: 8 8\nencoding: gzip") +
                                  std::string("\x1f\x8b\x08\x00garbagegarbagegarbage", 25));
  expect_error(dir + "z.nrrd", {});
}

TEST(VolumeReaderErrors, NanVoxelsNeedNanAs) {
  const std::string dir = temp_dir();
  std::vector<float> v(8, 1.0f);
  v[5] = std::numeric_limits<float>::quiet_NaN();
  v[6] = std::numeric_limits<float>::infinity();
  write_bytes(dir + "n.raw", std::string(reinterpret_cast<char*>(v.data()), v.size() * 4));
  write_bytes(dir + "n.raw.json", R"({"dims":[2,2,2],"dtype":"float32"})");
  expect_error(dir + "n.raw", {"2 voxels are NaN or infinite", "index 1,0,1", "--nan-as"});
  VolumeReadOptions o;
  o.nan_as = -3.0;
  ScalarGrid g = read_volume(dir + "n.raw", o);
  EXPECT_EQ(g.values[5], -3.0f);
  EXPECT_EQ(g.values[6], -3.0f);
  EXPECT_NE(g.notes.find("2 NaN/Inf voxels replaced"), std::string::npos);
}

TEST(VolumeReaderErrors, RawSizeMismatchAndSidecarProblems) {
  const std::string dir = temp_dir();
  write_bytes(dir + "a.raw", std::string(100, '\0'));
  write_bytes(dir + "a.raw.json", R"({"dims":[5,5,5],"dtype":"uint8"})");
  expect_error(dir + "a.raw", {"size mismatch", "need 125 bytes", "the file has 100"});
  write_bytes(dir + "a.raw.json", R"({"dims":[5,5,4],"dtype":"uint8","offset":1})");
  expect_error(dir + "a.raw", {"size mismatch", "need 101 bytes"});
  write_bytes(dir + "a.raw.json", R"({"dims":[5,5,4],"dtype":"uint8")");
  expect_error(dir + "a.raw", {"bad JSON"}, {}, dir + "a.raw.json");
  write_bytes(dir + "a.raw.json", R"({"dtype":"uint8"})");
  expect_error(dir + "a.raw", {"missing \"dims\""}, {}, dir + "a.raw.json");
  write_bytes(dir + "a.raw.json", R"({"dims":[5,5,4]})");
  expect_error(dir + "a.raw", {"missing \"dtype\""}, {}, dir + "a.raw.json");
  write_bytes(dir + "a.raw.json", R"({"dims":[5,5,4],"dtype":"complex64"})");
  expect_error(dir + "a.raw", {"unsupported dtype"}, {}, dir + "a.raw.json");
  write_bytes(dir + "a.raw.json", R"({"dims":[5,-5,4],"dtype":"uint8"})");
  expect_error(dir + "a.raw", {"not a positive integer"}, {}, dir + "a.raw.json");
  write_bytes(dir + "a.raw.json", R"({"dims":[5,5,4],"dtype":"uint8","spacing":[1,0,1]})");
  expect_error(dir + "a.raw", {"\"spacing\" entries must be positive"}, {}, dir + "a.raw.json");
  write_bytes(dir + "b.raw", std::string(10, '\0'));
  expect_error(dir + "b.raw", {"needs a sidecar", "--raw-dims"});
}

TEST(VolumeReaderErrors, NiftiTruncatedAndUnsupported) {
  const std::string dir = temp_dir();
  std::string full = read_bytes(kData + "mri_small_bigendian.nii");
  write_bytes(dir + "cut.nii", full.substr(0, full.size() / 2));
  expect_error(dir + "cut.nii", {"truncated"});
  write_bytes(dir + "hdr.nii", full.substr(0, 200));
  expect_error(dir + "hdr.nii", {"truncated NIfTI header"});
  // Truncated and corrupt gzip.
  std::string gz;
  {
    const std::string p = dir + "ok.nii.gz";
    gzFile f = gzopen(p.c_str(), "wb");
    gzwrite(f, full.data(), static_cast<unsigned>(full.size()));
    gzclose(f);
    gz = read_bytes(p);
  }
  write_bytes(dir + "cut.nii.gz", gz.substr(0, gz.size() * 2 / 3));
  expect_error(dir + "cut.nii.gz", {"truncated or unreadable"});
  std::string bad = gz;
  for (std::size_t i = 400; i < bad.size() - 20; i += 7) bad[i] = static_cast<char>(bad[i] ^ 0x5a);
  write_bytes(dir + "bad.nii.gz", bad);
  expect_error(dir + "bad.nii.gz", {});
  // Unsupported datatype (complex64 = 32) written by libnifti itself.
  int64_t dims[8] = {3, 2, 2, 2, 1, 1, 1, 1};
  nifti_image* nim = nifti_make_new_nim(dims, DT_COMPLEX64, 1);
  nifti_set_filenames(nim, (dir + "complex.nii").c_str(), 0, 1);
  nifti_image_write(nim);
  nifti_image_free(nim);
  expect_error(dir + "complex.nii", {"unsupported NIfTI datatype 32"});
}

TEST(VolumeReaderErrors, VdbWithoutScalarOrEmptyGrid) {
  openvdb::initialize();
  const std::string dir = temp_dir();
  auto v = openvdb::Vec3SGrid::create();
  v->setName("vel");
  v->tree().setValue(openvdb::Coord(0, 0, 0), openvdb::Vec3s(1, 0, 0));
  openvdb::io::File(dir + "vec.vdb").write({v});
  expect_error(dir + "vec.vdb", {"no scalar grid", "vel (vec3s)"});
  auto e = openvdb::FloatGrid::create(1.0f);
  e->setName("empty");
  openvdb::io::File(dir + "empty.vdb").write({e});
  expect_error(dir + "empty.vdb", {"grid 'empty' is empty"});
  VolumeReadOptions o;
  o.grid_name = "missing";
  expect_error(dir + "empty.vdb", {"no grid named 'missing'", "empty (float)"}, o);
  openvdb::io::File(dir + "none.vdb").write(openvdb::GridPtrVec{});
  expect_error(dir + "none.vdb", {"no grids"});
  std::string full = read_bytes(dir + "empty.vdb");
  write_bytes(dir + "cut.vdb", full.substr(0, full.size() / 2));
  expect_error(dir + "cut.vdb", {});
}

TEST(VolumeReaderErrors, VdbCorruptLengthFieldIsRefusedBeforeOpenVdbAllocates) {
  const std::string dir = temp_dir();
  std::string bytes = read_bytes(kData + "small_sphere.vdb");
  ASSERT_GT(bytes.size(), 0x80u);
  ASSERT_EQ(bytes.substr(0x45, 7), "surface");  // the first grid name, after its 4-byte length
  bytes[0x41] = '\x00';
  bytes[0x42] = '\x00';
  bytes[0x43] = '\x00';
  bytes[0x44] = '\xf0';  // length 0xf0000000: OpenVDB alone would allocate 4 GB
  write_bytes(dir + "len.vdb", bytes);
  expect_error(dir + "len.vdb", {"truncated or corrupt OpenVDB file", "grid name"});
  bytes = read_bytes(kData + "small_sphere.vdb");
  bytes[8] = '\x10';  // file version 16
  write_bytes(dir + "ver.vdb", bytes);
  expect_error(dir + "ver.vdb", {"unsupported OpenVDB file version 16"});
}

TEST(VolumeReaderErrors, MetaImageAndPgmHeaders) {
  const std::string dir = temp_dir();
  write_bytes(
      dir + "a.mha",
      "ObjectType = Image\nNDims = 3\nDimSize = 4 4\nElementType = MET_UCHAR\nElementDataFile = LOCAL\n");
  expect_error(dir + "a.mha", {"DimSize needs 3 numbers"});
  write_bytes(
      dir + "b.mha",
      "ObjectType = Image\nNDims = 2\nDimSize = 4 4\nElementType = MET_LONG_LONG\nElementDataFile = LOCAL\n");
  expect_error(dir + "b.mha", {"unsupported MetaImage ElementType MET_LONG_LONG"});
  write_bytes(
      dir + "c.mha",
      "ObjectType = Image\nNDims = 2\nDimSize = 4 4\nElementType = MET_UCHAR\nElementDataFile = LOCAL\nabc");
  expect_error(dir + "c.mha", {"truncated", "16 bytes"}, {}, dir + "c.mha");
  write_bytes(dir + "d.mha",
              "ObjectType = Image\nNDims = 2\nDimSize = 4 4\nElementType = MET_UCHAR\nCompressedData = True\n"
              "ElementDataFile = LOCAL\nxxxxxxxxxxxxxxxx");
  expect_error(dir + "d.mha", {"corrupt compressed data"});
  write_bytes(dir + "e.mha", "ObjectType = Image\nNDims = 2\nDimSize = 4 4\nElementType = MET_UCHAR\n");
  expect_error(dir + "e.mha", {"no ElementDataFile"});
  write_bytes(
      dir + "f.mhd",
      "ObjectType = Image\nNDims = 2\nDimSize = 4 4\nElementType = MET_UCHAR\nElementDataFile = gone.raw\n");
  expect_error(dir + "f.mhd", {"cannot open"}, {}, dir + "gone.raw");
  write_bytes(dir + "a.pgm", "P5\n4 4\n70000\n");
  expect_error(dir + "a.pgm", {"maxval 70000"});
  write_bytes(dir + "b.pgm", "P5\n4 4\n65535\nabc");
  expect_error(dir + "b.pgm", {"truncated", "32 bytes"});
  write_bytes(dir + "c.pgm", "P5\n4 0\n255\n");
  expect_error(dir + "c.pgm", {"invalid dimensions"});
}

// Every prefix of every sample must read or throw mlfe::Error; anything else (a crash, an
// abort, another exception type) fails the test binary.
TEST(VolumeReaderErrors, TruncatedPrefixesOfEverySampleReadOrThrow) {
  const std::string dir = temp_dir();
  std::vector<std::string> samples;
  DIR* d = opendir(kData.c_str());
  ASSERT_NE(d, nullptr);
  while (dirent* e = readdir(d)) {
    std::string n = e->d_name;
    if (n[0] == '.' || n.size() < 4 || !std::filesystem::is_regular_file(kData + n)) continue;
    std::string ext = n.substr(n.find_last_of('.') + 1);
    if (ext == "md" || ext == "json" || ext == "zraw") continue;  // companions are kept whole
    samples.push_back(n);
  }
  closedir(d);
  std::sort(samples.begin(), samples.end());
  ASSERT_GE(samples.size(), 8u);
  int errors = 0, reads = 0;
  for (const auto& name : samples) {
    const std::string full = read_bytes(kData + name);
    std::set<std::size_t> cuts;
    const std::size_t small = std::min<std::size_t>(full.size(), 4096);
    for (std::size_t n = 0; n <= small; n += (n < 400 ? 1 : 11)) cuts.insert(n);
    for (int q = 1; q < 64; ++q) cuts.insert(full.size() * q / 64);
    for (std::size_t back = 1; back <= 16 && back <= full.size(); ++back) cuts.insert(full.size() - back);
    // Companion files stay complete so that only the sample itself is cut.
    for (const char* comp : {".json"}) {
      std::string c = read_bytes(kData + name + comp);
      if (!c.empty()) write_bytes(dir + name + comp, c);
    }
    if (name == "small_float_z.mhd")
      write_bytes(dir + "small_float_z.zraw", read_bytes(kData + "small_float_z.zraw"));
    for (std::size_t n : cuts) {
      const std::string path = dir + name;
      write_bytes(path, full.substr(0, n));
      try {
        read_volume(path);
        ++reads;
      } catch (const Error& e) {
        ++errors;
        const std::string m = e.what();
        // The message names the sample or, for a cut .mhd, the data file it now names.
        ASSERT_EQ(m.rfind(dir, 0), 0u) << m;
        ASSERT_EQ(m.find('\n'), std::string::npos) << m;
      }
    }
  }
  EXPECT_GT(errors, 1000);
  EXPECT_GT(reads, 0);  // the whole-file cut of headerless formats, PGM trailing data, ...
}

}  // namespace
}  // namespace mlfe
