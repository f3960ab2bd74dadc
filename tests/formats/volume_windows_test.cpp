// VolumeWindows reads NIfTI, NRRD and MetaImage files box by box (formats/volume_reader.h): each
// format and encoding, written here by its own library or by hand, gives in every window exactly
// the samples and the frame read_volume gives, and the whole reader's checks still hold when the
// data is found bad only while the boxes are read.
#include <gtest/gtest.h>
#include <mlfe/core/base/error.h>
#include <mlfe/formats/volume_reader.h>
#include <nifti2_io.h>
#include <teem/nrrd.h>
#include <zlib.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "tests/test_paths.h"

namespace mlfe {
namespace {

using Box = std::array<std::int64_t, 3>;
constexpr int kNx = 13, kNy = 11, kNz = 9;

std::string scratch() { return test::scratch_dir("windows"); }

// The stored value at (i, j, k): negative and positive, different along every axis.
double stored(int i, int j, int k) { return (i * 7 + j * 31 + k * 101) % 300 - 120; }

template <typename T>
std::vector<T> pattern() {
  std::vector<T> v;
  for (int k = 0; k < kNz; ++k)
    for (int j = 0; j < kNy; ++j)
      for (int i = 0; i < kNx; ++i) v.push_back(static_cast<T>(stored(i, j, k)));
  return v;
}

// The bytes of `values` with each value's bytes reversed when `big` (the host is little-endian).
template <typename T>
std::string bytes_of(const std::vector<T>& values, bool big) {
  std::string b(values.size() * sizeof(T), '\0');
  std::memcpy(b.data(), values.data(), b.size());
  if (big)
    for (std::size_t i = 0; i < b.size(); i += sizeof(T))
      std::reverse(b.begin() + i, b.begin() + i + sizeof(T));
  return b;
}

std::string zlib_of(const std::string& data) {
  uLongf n = compressBound(data.size());
  std::string z(n, '\0');
  EXPECT_EQ(compress2(reinterpret_cast<Bytef*>(z.data()), &n, reinterpret_cast<const Bytef*>(data.data()),
                      data.size(), 6),
            Z_OK);
  z.resize(n);
  return z;
}

void write_text(const std::string& path, const std::string& text) {
  test::write_file_bytes(path, std::vector<std::uint8_t>(text.begin(), text.end()));
}

// Every window of `path` equals read_volume's samples there, and the frame is read_volume's.
void expect_windows_match(const std::string& path, const VolumeReadOptions& opts = {}) {
  SCOPED_TRACE(path);
  const ScalarGrid whole = read_volume(path, opts);
  ASSERT_TRUE(reads_in_windows(path, opts));
  const VolumeWindows v(path, opts);
  EXPECT_TRUE(v.streamed());
  const ScalarGrid& f = v.frame();
  EXPECT_EQ(f.dims, whole.dims);
  EXPECT_EQ(f.dim, whole.dim);
  EXPECT_EQ(f.transform.spacing, whole.transform.spacing);
  EXPECT_EQ(f.transform.origin, whole.transform.origin);
  EXPECT_EQ(f.transform.direction, whole.transform.direction);
  EXPECT_EQ(f.space, whole.space);
  EXPECT_EQ(f.source_type, whole.source_type);
  EXPECT_EQ(f.format, whole.format);
  // The whole reader adds how many NaN voxels --nan-as replaced, which the frame cannot know.
  if (opts.nan_as)
    EXPECT_EQ(whole.notes.rfind(f.notes + "\n", 0), 0u) << whole.notes;
  else
    EXPECT_EQ(f.notes, whole.notes);
  const Box d = whole.dims, mid{d[0] / 2, d[1] / 2, d[2] / 2};
  // The whole box, an inner one, the last voxel, a slab of x-rows, a column.
  const std::vector<std::pair<Box, Box>> boxes = {
      {{0, 0, 0}, d},
      {{d[0] / 4, d[1] / 4, d[2] / 4}, {mid[0] + 1, mid[1] + 1, d[2]}},
      {{d[0] - 1, d[1] - 1, d[2] - 1}, d},
      {{0, mid[1], 0}, {d[0], mid[1] + 1, d[2]}},
      {mid, {mid[0] + 1, d[1], mid[2] + 1}}};
  for (const auto& [lo, hi] : boxes) {
    const ScalarGrid w = v.read(lo, hi);
    ASSERT_EQ(w.dims, (Box{hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]}));
    std::size_t n = 0;
    for (std::int64_t k = lo[2]; k < hi[2]; ++k)
      for (std::int64_t j = lo[1]; j < hi[1]; ++j)
        for (std::int64_t i = lo[0]; i < hi[0]; ++i, ++n)
          ASSERT_EQ(w.values[n], whole.at(i, j, k)) << i << "," << j << "," << k;
  }
}

// A NIfTI of the pattern as `datatype` (int16 or float32) with an oblique sform, written by
// libnifti: .nii, .nii.gz, .hdr (+ .img) or .hdr.gz (+ .img.gz).
void write_nifti(const std::string& path, int datatype, double slope, double inter, bool nifti2 = false) {
  std::int64_t dims[8] = {3, kNx, kNy, kNz, 1, 1, 1, 1};
  nifti_image* nim = nifti_make_new_nim(dims, datatype, 0);
  ASSERT_NE(nim, nullptr);
  const std::string data =
      datatype == DT_INT16 ? bytes_of(pattern<std::int16_t>(), false) : bytes_of(pattern<float>(), false);
  nim->data = std::malloc(data.size());
  std::memcpy(nim->data, data.data(), data.size());
  nim->scl_slope = slope;
  nim->scl_inter = inter;
  const double rows[4][4] = {{0, 0.75, 0, -20}, {-1.5, 0, 0, 30}, {0, 0, 2.5, 7.25}, {0, 0, 0, 1}};
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) nim->sto_xyz.m[r][c] = rows[r][c];
  nim->sform_code = NIFTI_XFORM_SCANNER_ANAT;
  if (nifti2) nim->nifti_type = NIFTI_FTYPE_NIFTI2_1;
  ASSERT_EQ(nifti_set_filenames(nim, path.c_str(), 0, 1), 0);
  nifti_image_write(nim);
  nifti_image_free(nim);
}

TEST(VolumeWindows, NiftiPlainGzippedAndPairsWithScaling) {
  const std::string dir = scratch() + "/";
  for (const char* name : {"a.nii", "b.nii.gz", "c.hdr", "d.hdr.gz"}) {
    write_nifti(dir + name, DT_INT16, 0.5, -3.25);
    expect_windows_match(dir + name);
  }
  write_nifti(dir + "e.nii.gz", DT_FLOAT32, 0, 0, true);
  expect_windows_match(dir + "e.nii.gz");
  VolumeReadOptions lps;
  lps.space = "lps";
  expect_windows_match(dir + "e.nii.gz", lps);
  // Big-endian int16 written by another tool.
  expect_windows_match(test::test_data_path("mri_small_bigendian.nii"));
}

// The pattern as int16 in NRRD, written by Teem with `encoding` (attached, or detached for .nhdr)
// in the given byte order.
void write_nrrd(const std::string& path, const NrrdEncoding* encoding, int endian) {
  std::vector<std::int16_t> values = pattern<std::int16_t>();
  Nrrd* n = nrrdNew();
  ASSERT_EQ(nrrdWrap_va(n, values.data(), nrrdTypeShort, 3, size_t(kNx), size_t(kNy), size_t(kNz)), 0);
  ASSERT_EQ(nrrdSpaceSet(n, nrrdSpaceLeftPosteriorSuperior), 0);
  const double dirs[3][NRRD_SPACE_DIM_MAX] = {{0, 0.5, 0}, {1.25, 0, 0}, {0, 0, -2}};
  nrrdAxisInfoSet_va(n, nrrdAxisInfoSpaceDirection, dirs[0], dirs[1], dirs[2]);
  const double origin[3] = {3, -4, 5.5};
  ASSERT_EQ(nrrdSpaceOriginSet(n, origin), 0);
  NrrdIoState* nio = nrrdIoStateNew();
  nio->encoding = encoding;
  nio->endian = endian;
  ASSERT_EQ(nrrdSave(path.c_str(), n, nio), 0) << biffGetDone(NRRD);
  nrrdIoStateNix(nio);
  nrrdNix(n);
}

TEST(VolumeWindows, NrrdRawAndGzipAttachedAndDetached) {
  const std::string dir = scratch() + "/";
  int k = 0;
  for (const NrrdEncoding* e : {nrrdEncodingRaw, nrrdEncodingGzip})
    for (const char* ext : {".nrrd", ".nhdr"})
      for (int endian : {airEndianLittle, airEndianBig}) {
        const std::string path = dir + "v" + std::to_string(k++) + ext;
        write_nrrd(path, e, endian);
        expect_windows_match(path);
      }
  // A header with a byte skip before raw data, written by hand.
  const std::string data = bytes_of(pattern<std::int16_t>(), true);
  std::string text =
      "NRRD0004\ntype: short\ndimension: 3\nsizes: 13 11 9\nendian: big\nencoding: raw\n"
      "byte skip: 5\nspacings: 0.5 0.25 2\n\nXXXXX" +
      data;
  write_text(dir + "skip.nrrd", text);
  expect_windows_match(dir + "skip.nrrd");
  // bzip2 cannot be read in boxes: the volume is read whole, its windows the same.
  write_nrrd(dir + "b.nrrd", nrrdEncodingBzip2, airEndianLittle);
  EXPECT_FALSE(reads_in_windows(dir + "b.nrrd", {}));
  EXPECT_FALSE(VolumeWindows(dir + "b.nrrd", {}).streamed());
}

std::string mha_header(bool msb, const std::string& compressed, const std::string& data_file) {
  return "ObjectType = Image\nNDims = 3\nDimSize = 13 11 9\nElementType = MET_SHORT\n"
         "ElementSpacing = 0.5 1.5 2\nOffset = 1 -2 3.5\nTransformMatrix = 0 1 0 -1 0 0 0 0 1\n"
         "ElementByteOrderMSB = " +
         std::string(msb ? "True" : "False") + "\n" + compressed + "ElementDataFile = " + data_file + "\n";
}

TEST(VolumeWindows, MetaImageLocalSeparateAndCompressed) {
  const std::string dir = scratch() + "/";
  for (bool msb : {false, true}) {
    const std::string data = bytes_of(pattern<std::int16_t>(), msb);
    const std::string tag = msb ? "big" : "little";
    write_text(dir + tag + ".mha", mha_header(msb, "", "LOCAL") + data);
    expect_windows_match(dir + tag + ".mha");
    write_text(dir + tag + ".raw", data);
    write_text(dir + tag + ".mhd", mha_header(msb, "", tag + ".raw"));
    expect_windows_match(dir + tag + ".mhd");
    const std::string z = zlib_of(data);
    write_text(dir + tag + "_z.mha", mha_header(msb, "CompressedData = True\n", "LOCAL") + z);
    expect_windows_match(dir + tag + "_z.mha");
    write_text(dir + tag + ".zraw", z);
    write_text(dir + tag + "_z.mhd", mha_header(msb, "CompressedData = True\n", tag + ".zraw"));
    expect_windows_match(dir + tag + "_z.mhd");
  }
  expect_windows_match(test::test_data_path("small_float_z.mhd"));
}

// Expects `read` to throw one line that starts with `file` and holds `part`.
template <class Read>
void expect_one_line(Read&& read, const std::string& file, const std::string& part) {
  try {
    read();
    ADD_FAILURE() << "no error for " << file;
  } catch (const Error& e) {
    const std::string m = e.what();
    EXPECT_EQ(m.find('\n'), std::string::npos) << m;
    EXPECT_EQ(m.rfind(file + ": ", 0), 0u) << m;
    EXPECT_NE(m.find(part), std::string::npos) << m;
  }
}

// Compressed data that is bad shows only while the boxes are read: the reads throw the whole
// reader's kind of line, at every read.
TEST(VolumeWindows, BadCompressedDataFailsEveryRead) {
  const std::string dir = scratch() + "/";
  write_nifti(dir + "full.nii.gz", DT_INT16, 1, 0);
  const std::vector<std::uint8_t> gz = test::read_file_bytes(dir + "full.nii.gz");
  test::write_file_bytes(dir + "cut.nii.gz",
                         std::vector<std::uint8_t>(gz.begin(), gz.begin() + gz.size() / 2));
  const VolumeWindows cut(dir + "cut.nii.gz", {});
  for (int round = 0; round < 2; ++round)
    expect_one_line([&] { cut.read({0, 0, 0}, {2, 2, 2}); }, dir + "cut.nii.gz", "truncated compressed data");

  const std::string data = bytes_of(pattern<std::int16_t>(), false);
  write_text(dir + "long.mha", mha_header(false, "CompressedData = True\n", "LOCAL") + zlib_of(data + "xx"));
  expect_one_line(
      [&] {
        VolumeWindows(dir + "long.mha", {}).read({0, 0, 0}, {1, 1, 1});
      },
      dir + "long.mha", "does not inflate to the 2574 bytes");
  std::string bad = zlib_of(data);
  bad[bad.size() / 2] ^= 0x55;
  write_text(dir + "bad.mha", mha_header(false, "CompressedData = True\n", "LOCAL") + bad);
  expect_one_line(
      [&] {
        VolumeWindows(dir + "bad.mha", {}).read({0, 0, 0}, {13, 11, 9});
      },
      dir + "bad.mha", "compressed data");
}

// NaN voxels in a box are refused with the volume's index, or replaced with --nan-as, as the
// whole reader does; scaling that overflows a float is refused.
TEST(VolumeWindows, NanAndScalingChecksHoldInBoxes) {
  const std::string dir = scratch() + "/";
  std::vector<float> values = pattern<float>();
  values[4 + kNx * (5 + kNy * 6)] = std::nanf("");
  const std::string data = bytes_of(values, false);
  write_text(
      dir + "nan.mha",
      "NDims = 3\nDimSize = 13 11 9\nElementType = MET_FLOAT\nCompressedData = True\nElementDataFile = "
      "LOCAL\n" +
          zlib_of(data));
  const VolumeWindows v(dir + "nan.mha", {});
  expect_one_line([&] { v.read({2, 2, 2}, {8, 8, 8}); }, dir + "nan.mha", "first at index 4,5,6");
  EXPECT_NO_THROW(v.read({0, 0, 0}, {4, 11, 9}));
  VolumeReadOptions nan_as;
  nan_as.nan_as = -7;
  expect_windows_match(dir + "nan.mha", nan_as);

  write_nifti(dir + "huge.nii", DT_INT16, 1e37, 0);
  expect_one_line(
      [&] {
        VolumeWindows(dir + "huge.nii", {}).read({0, 0, 0}, {13, 11, 9});
      },
      dir + "huge.nii", "overflows a float");
}

}  // namespace
}  // namespace mlfe
