// Importers: round trips through each library's own writer, and the shared real files.
#include <gtest/gtest.h>
#include <mlfe/core/base/error.h>
#include <mlfe/formats/volume_reader.h>
#include <nifti2_io.h>
#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/LevelSetSphere.h>
#include <teem/nrrd.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include "tests/test_paths.h"

namespace mlfe {
namespace {

const std::string kData = std::string(MLFE_SOURCE_DIR) + "/tests/data/";
const std::string kShared = std::string(MLFE_SHARED_DATA_DIR) + "/";

std::string temp_dir() {
  std::string t = ::testing::TempDir() + "mlfe_reader_XXXXXX";
  std::vector<char> buf(t.begin(), t.end());
  buf.push_back('\0');
  if (!mkdtemp(buf.data())) throw std::runtime_error("mkdtemp failed");
  return std::string(buf.data()) + "/";
}

bool exists(const std::string& p) { return std::ifstream(p).good(); }

// The expected value of the synthetic test pattern.
float pattern(int i, int j, int k) { return float((i * 7 + j * 3 + k * 11) % 50 - 10); }

void expect_point(const ScalarGrid& g, double i, double j, double k, const std::array<double, 3>& want,
                  double tol = 1e-5) {
  auto p = g.transform.index_to_physical(i, j, k);
  EXPECT_NEAR(p[0], want[0], tol) << "at " << i << "," << j << "," << k;
  EXPECT_NEAR(p[1], want[1], tol) << "at " << i << "," << j << "," << k;
  EXPECT_NEAR(p[2], want[2], tol) << "at " << i << "," << j << "," << k;
}

// ---- NRRD (Teem writer) ----

struct NrrdCase {
  int type;
  const NrrdEncoding* encoding;
  const char* name;
};

void write_nrrd(const std::string& path, const void* data, int type, size_t nx, size_t ny, size_t nz,
                const double dirs[3][NRRD_SPACE_DIM_MAX], const double origin[3], int space,
                const NrrdEncoding* enc) {
  Nrrd* n = nrrdNew();
  ASSERT_EQ(nrrdWrap_va(n, const_cast<void*>(data), type, 3, nx, ny, nz), 0);
  ASSERT_EQ(nrrdSpaceSet(n, space), 0);
  nrrdAxisInfoSet_va(n, nrrdAxisInfoSpaceDirection, dirs[0], dirs[1], dirs[2]);
  ASSERT_EQ(nrrdSpaceOriginSet(n, origin), 0);
  NrrdIoState* nio = nrrdIoStateNew();
  nio->encoding = enc;
  ASSERT_EQ(nrrdSave(path.c_str(), n, nio), 0) << biffGetDone(NRRD);
  nrrdIoStateNix(nio);
  nrrdNix(n);
}

TEST(NrrdReader, RoundTripThroughTeemKeepsVoxelsAndObliqueTransform) {
  const std::string dir = temp_dir();
  const int nx = 6, ny = 5, nz = 4;
  std::vector<short> s(nx * ny * nz);
  std::vector<float> f(nx * ny * nz);
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) {
        s[i + nx * (j + ny * k)] = short(pattern(i, j, k));
        f[i + nx * (j + ny * k)] = pattern(i, j, k) * 0.5f;
      }
  // A rotation about z by 30 degrees with anisotropic spacing 0.5, 0.7, 1.2.
  const double c = std::cos(M_PI / 6), sn = std::sin(M_PI / 6);
  const double dirs[3][NRRD_SPACE_DIM_MAX] = {{0.5 * c, 0.5 * sn, 0}, {-0.7 * sn, 0.7 * c, 0}, {0, 0, 1.2}};
  const double origin[3] = {-10, 20.5, 3};
  for (const NrrdEncoding* enc : {nrrdEncodingRaw, nrrdEncodingGzip}) {
    for (int type : {int(nrrdTypeShort), int(nrrdTypeFloat)}) {
      const std::string path = dir + "rt_" + enc->name + "_" + std::to_string(type) + ".nrrd";
      write_nrrd(path, type == nrrdTypeShort ? static_cast<const void*>(s.data()) : f.data(), type, nx, ny,
                 nz, dirs, origin, nrrdSpaceLeftPosteriorSuperior, enc);
      ScalarGrid g = read_volume(path);
      SCOPED_TRACE(path);
      EXPECT_EQ(g.format, "nrrd");
      EXPECT_EQ(g.dim, 3);
      EXPECT_EQ(g.dims, (std::array<std::int64_t, 3>{nx, ny, nz}));
      EXPECT_EQ(g.source_type, type == nrrdTypeShort ? ScalarType::I16 : ScalarType::F32);
      EXPECT_EQ(g.space, "LPS");
      for (int k = 0; k < nz; ++k)
        for (int j = 0; j < ny; ++j)
          for (int i = 0; i < nx; ++i)
            ASSERT_EQ(g.at(i, j, k), type == nrrdTypeShort ? pattern(i, j, k) : pattern(i, j, k) * 0.5f);
      EXPECT_NEAR(g.transform.spacing[0], 0.5, 1e-12);
      EXPECT_NEAR(g.transform.spacing[1], 0.7, 1e-12);
      EXPECT_NEAR(g.transform.spacing[2], 1.2, 1e-12);
      for (int i : {0, 5})
        for (int j : {0, 4})
          for (int k : {0, 3})
            expect_point(g, i, j, k,
                         {origin[0] + i * dirs[0][0] + j * dirs[1][0] + k * dirs[2][0],
                          origin[1] + i * dirs[0][1] + j * dirs[1][1] + k * dirs[2][1],
                          origin[2] + i * dirs[0][2] + j * dirs[1][2] + k * dirs[2][2]});
      // Asking for RAS negates x and y of every physical point.
      VolumeReadOptions ras;
      ras.space = "ras";
      ScalarGrid r = read_volume(path, ras);
      EXPECT_EQ(r.space, "RAS");
      auto p = g.transform.index_to_physical(2, 3, 1);
      expect_point(r, 2, 3, 1, {-p[0], -p[1], p[2]});
    }
  }
}

TEST(NrrdReader, CtSkullMatchesRawSidecarVoxelForVoxel) {
  ScalarGrid n = read_volume(test::sample_path("ct_skull_64.nrrd"));
  ScalarGrid r = read_volume(kData + "ct_skull_64.raw");
  EXPECT_EQ(n.format, "nrrd");
  EXPECT_EQ(r.format, "raw");
  EXPECT_EQ(n.dims, (std::array<std::int64_t, 3>{64, 64, 64}));
  EXPECT_EQ(r.dims, n.dims);
  EXPECT_EQ(n.source_type, ScalarType::F32);
  EXPECT_EQ(r.source_type, ScalarType::F32);
  ASSERT_EQ(n.values.size(), r.values.size());
  for (std::size_t i = 0; i < n.values.size(); ++i) ASSERT_EQ(n.values[i], r.values[i]) << i;
  for (const ScalarGrid* g : {&n, &r}) {
    EXPECT_NEAR(g->transform.spacing[0], 3.943, 1e-3);
    EXPECT_NEAR(g->transform.spacing[1], 3.943, 1e-3);
    EXPECT_NEAR(g->transform.spacing[2], 3.651, 1e-3);
  }
  auto range = n.value_range();
  EXPECT_GE(range[0], 0.0f);
  EXPECT_NEAR(range[1], 5.43, 0.01);
}

TEST(NrrdReader, JacksboroDemIsA2dInt16HeightField) {
  ScalarGrid g = read_volume(test::sample_path("dem_jacksboro.nrrd"));
  EXPECT_EQ(g.dim, 2);
  EXPECT_EQ(g.dims, (std::array<std::int64_t, 3>{403, 344, 1}));
  EXPECT_EQ(g.source_type, ScalarType::I16);
  EXPECT_NEAR(g.transform.spacing[0], 0.000833333, 1e-8);
  EXPECT_NEAR(g.transform.origin[0], -84.41375, 1e-9);
  EXPECT_NEAR(g.transform.origin[1], 36.73291666666667, 1e-9);
  auto range = g.value_range();
  // Elevations near Jacksboro, Tennessee: a few hundred metres.
  EXPECT_GT(range[0], 0.0f);
  EXPECT_LT(range[1], 2000.0f);
  EXPECT_GT(range[1], range[0] + 50.0f);
}

TEST(NrrdReader, BigEndianUint16SliceReadsInRange) {
  ScalarGrid g = read_volume(kData + "mri_slice_256.nrrd");
  EXPECT_EQ(g.dim, 2);
  EXPECT_EQ(g.dims, (std::array<std::int64_t, 3>{256, 256, 1}));
  EXPECT_EQ(g.source_type, ScalarType::U16);
  auto range = g.value_range();
  EXPECT_EQ(range[0], 0.0f);
  EXPECT_EQ(range[1], 215.0f);  // byte-swapped values would exceed 255
}

// ---- NIfTI (libnifti2 writer) ----

void write_nifti(const std::string& path, int datatype, bool nifti2, double slope, double inter) {
  int64_t dims[8] = {3, 6, 5, 4, 1, 1, 1, 1};
  nifti_image* nim = nifti_make_new_nim(dims, datatype, 1);
  ASSERT_NE(nim, nullptr);
  for (int k = 0; k < 4; ++k)
    for (int j = 0; j < 5; ++j)
      for (int i = 0; i < 6; ++i) {
        const int idx = i + 6 * (j + 5 * k);
        if (datatype == DT_INT16)
          static_cast<short*>(nim->data)[idx] = short(pattern(i, j, k));
        else
          static_cast<double*>(nim->data)[idx] = pattern(i, j, k) * 0.125;
      }
  nim->scl_slope = slope;
  nim->scl_inter = inter;
  // sform: a rotation about x by 90 degrees with spacing 2, 3, 4 and an offset.
  nifti_dmat44 m{};
  const double rows[4][4] = {{2, 0, 0, -50}, {0, 0, -4, 30}, {0, 3, 0, 7.5}, {0, 0, 0, 1}};
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) m.m[r][c] = rows[r][c];
  nim->sform_code = NIFTI_XFORM_SCANNER_ANAT;
  nim->sto_xyz = m;
  // A different qform, which must lose against the sform.
  nim->qform_code = NIFTI_XFORM_SCANNER_ANAT;
  nim->quatern_b = nim->quatern_c = nim->quatern_d = 0;
  nim->qoffset_x = nim->qoffset_y = nim->qoffset_z = 99;
  nim->pixdim[1] = 2;
  nim->pixdim[2] = 3;
  nim->pixdim[3] = 4;
  if (nifti2) nim->nifti_type = NIFTI_FTYPE_NIFTI2_1;
  ASSERT_EQ(nifti_set_filenames(nim, path.c_str(), 0, 1), 0);
  nifti_image_write(nim);
  nifti_image_free(nim);
  ASSERT_TRUE(exists(path)) << path;
}

TEST(NiftiReader, RoundTripThroughLibnifti2AppliesScalingAndPrefersSform) {
  const std::string dir = temp_dir();
  struct Case {
    std::string name;
    int datatype;
    bool nifti2;
  };
  for (const Case& c : {Case{"a.nii", DT_INT16, false}, Case{"b.nii.gz", DT_INT16, false},
                        Case{"c.nii", DT_FLOAT64, true}, Case{"d.hdr", DT_INT16, false}}) {
    const std::string path = dir + c.name;
    SCOPED_TRACE(path);
    write_nifti(path, c.datatype, c.nifti2, 2.0, -1.0);
    ScalarGrid g = read_volume(path);
    EXPECT_EQ(g.format, "nifti");
    EXPECT_EQ(g.dims, (std::array<std::int64_t, 3>{6, 5, 4}));
    EXPECT_EQ(g.source_type, c.datatype == DT_INT16 ? ScalarType::I16 : ScalarType::F64);
    EXPECT_EQ(g.space, "RAS");
    for (int k = 0; k < 4; ++k)
      for (int j = 0; j < 5; ++j)
        for (int i = 0; i < 6; ++i) {
          const double stored = c.datatype == DT_INT16 ? pattern(i, j, k) : pattern(i, j, k) * 0.125;
          ASSERT_FLOAT_EQ(g.at(i, j, k), float(stored * 2.0 - 1.0)) << i << "," << j << "," << k;
        }
    EXPECT_NEAR(g.transform.spacing[0], 2, 1e-6);
    EXPECT_NEAR(g.transform.spacing[1], 3, 1e-6);
    EXPECT_NEAR(g.transform.spacing[2], 4, 1e-6);
    for (int i : {0, 5})
      for (int j : {0, 4})
        for (int k : {0, 3}) expect_point(g, i, j, k, {2.0 * i - 50, -4.0 * k + 30, 3.0 * j + 7.5}, 1e-4);
  }
}

TEST(NiftiReader, BigEndianFileMatchesLibniftiAndHasExpectedDims) {
  const std::string path = kData + "mri_small_bigendian.nii";
  ScalarGrid g = read_volume(path);
  EXPECT_EQ(g.dims, (std::array<std::int64_t, 3>{33, 41, 25}));
  nifti_set_debug_level(0);
  std::unique_ptr<nifti_image, void (*)(nifti_image*)> nim(nifti_image_read(path.c_str(), 1),
                                                           nifti_image_free);
  ASSERT_NE(nim, nullptr);
  ASSERT_EQ(nim->nvox, 33 * 41 * 25);
  ASSERT_EQ(nim->byteorder, 2);  // MSB_FIRST (defined only inside libnifti)
  double slope = (nim->scl_slope != 0 && std::isfinite(nim->scl_slope)) ? nim->scl_slope : 1.0;
  double inter = nim->scl_slope != 0 ? nim->scl_inter : 0.0;
  for (std::int64_t i = 0; i < nim->nvox; ++i) {
    double v = 0;
    switch (nim->datatype) {
      case DT_INT16:
        v = static_cast<short*>(nim->data)[i];
        break;
      case DT_UINT8:
        v = static_cast<unsigned char*>(nim->data)[i];
        break;
      case DT_FLOAT32:
        v = static_cast<float*>(nim->data)[i];
        break;
      case DT_INT32:
        v = static_cast<int*>(nim->data)[i];
        break;
      default:
        FAIL() << "unexpected datatype " << nim->datatype;
    }
    ASSERT_FLOAT_EQ(g.values[i], float(v * slope + inter)) << i;
  }
  // The range found by decoding the big-endian int16 voxels independently (Python struct);
  // reading them little-endian would give a different range.
  auto range = g.value_range();
  EXPECT_EQ(range[0], -610.0f);
  EXPECT_EQ(range[1], 30393.0f);
}

TEST(NiftiReader, Colin27GzippedBrainHasItsDims) {
  const std::string path = kShared + "mri_colin27_brain.nii.gz";
  if (!exists(path)) GTEST_SKIP() << path << " is absent";
  ScalarGrid g = read_volume(path);
  EXPECT_EQ(g.dims, (std::array<std::int64_t, 3>{181, 217, 181}));
  EXPECT_EQ(g.source_type, ScalarType::U8);
  EXPECT_EQ(g.space, "RAS");
  EXPECT_NEAR(g.transform.spacing[0], 1.0, 1e-4);
  auto range = g.value_range();
  EXPECT_EQ(range[0], 0.0f);
  EXPECT_GT(range[1], 50.0f);
  EXPECT_LE(range[1], 255.0f);
}

// ---- OpenVDB ----

openvdb::math::Transform::Ptr oblique_vdb_transform() {
  auto xf = openvdb::math::Transform::createLinearTransform(0.5);
  xf->postRotate(0.3, openvdb::math::Z_AXIS);
  xf->postTranslate(openvdb::Vec3d(1.0, -2.0, 3.5));
  return xf;
}

TEST(VdbReader, RoundTripThroughOpenVdbUsesActiveBoxAndLinearTransform) {
  openvdb::initialize();
  const std::string path = temp_dir() + "box.vdb";
  auto grid = openvdb::FloatGrid::create(-7.0f);
  grid->setName("density");
  grid->setTransform(oblique_vdb_transform());
  auto acc = grid->getAccessor();
  const openvdb::Coord lo(-3, 2, 10);
  for (int k = 0; k < 4; ++k)
    for (int j = 0; j < 5; ++j)
      for (int i = 0; i < 6; ++i) {
        // Leave one voxel inside the box inactive: it must read as the background.
        if (i == 2 && j == 2 && k == 2) continue;
        acc.setValue(lo.offsetBy(i, j, k), pattern(i, j, k));
      }
  auto other = openvdb::Int32Grid::create(0);
  other->setName("labels");
  other->tree().setValue(openvdb::Coord(0, 0, 0), 4);
  openvdb::io::File(path).write({other, grid});

  VolumeReadOptions opts;
  opts.grid_name = "density";
  ScalarGrid g = read_volume(path, opts);
  EXPECT_EQ(g.format, "vdb");
  EXPECT_EQ(g.dims, (std::array<std::int64_t, 3>{6, 5, 4}));
  EXPECT_EQ(g.source_type, ScalarType::F32);
  for (int k = 0; k < 4; ++k)
    for (int j = 0; j < 5; ++j)
      for (int i = 0; i < 6; ++i)
        ASSERT_EQ(g.at(i, j, k), (i == 2 && j == 2 && k == 2) ? -7.0f : pattern(i, j, k));
  auto xf = oblique_vdb_transform();
  for (int i : {0, 5})
    for (int j : {0, 4})
      for (int k : {0, 3}) {
        auto w = xf->indexToWorld(lo.offsetBy(i, j, k));
        expect_point(g, i, j, k, {w.x(), w.y(), w.z()});
      }
  EXPECT_NEAR(g.transform.spacing[0], 0.5, 1e-12);

  // By name, the int32 grid is converted with a note.
  opts.grid_name = "labels";
  ScalarGrid labels = read_volume(path, opts);
  EXPECT_EQ(labels.dims, (std::array<std::int64_t, 3>{1, 1, 1})) << labels.notes;
  EXPECT_EQ(labels.values[0], 4.0f);
  EXPECT_EQ(labels.source_type, ScalarType::I32);
  EXPECT_NE(labels.notes.find("int32"), std::string::npos);

  // Without a name: the first scalar grid in the file's order (OpenVDB decides the order).
  openvdb::io::File f(path);
  f.open(false);
  const std::string first_name = (*f.readAllGridMetadata())[0]->getName();
  ScalarGrid first = read_volume(path);
  EXPECT_NE(first.notes.find("grid '" + first_name + "'"), std::string::npos) << first.notes;
}

TEST(VdbReader, LevelSetSphereKeepsSignInsideAndOut) {
  openvdb::initialize();
  const std::string path = temp_dir() + "sphere.vdb";
  auto ls =
      openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(2.0f, openvdb::Vec3f(0, 0, 0), 0.25f, 3.0f);
  ls->setName("surface");
  openvdb::io::File(path).write({ls});
  ScalarGrid g = read_volume(path);
  const float bg = ls->background();
  // The centre is deep inside (inactive interior), which must read as -background.
  auto idx = ls->transform().worldToIndexCellCentered(openvdb::Vec3d(0, 0, 0));
  auto bb = ls->evalActiveVoxelBoundingBox();
  auto rel = idx - bb.min();
  EXPECT_FLOAT_EQ(g.at(rel.x(), rel.y(), rel.z()), -bg);
  // A corner of the box is outside the sphere.
  EXPECT_GT(g.at(0, 0, 0), 0.0f);
  EXPECT_NE(g.notes.find("level set"), std::string::npos);
  // Voxel near the surface: about the signed distance in world units.
  auto p = g.transform.index_to_physical(0, rel.y(), rel.z());
  EXPECT_NEAR(g.at(0, rel.y(), rel.z()), std::min(float(std::abs(p[0]) - 2.0), bg), 0.26);
}

TEST(VdbReader, VectorGridNeedsVecMagnitude) {
  openvdb::initialize();
  const std::string path = temp_dir() + "vel.vdb";
  auto v = openvdb::Vec3SGrid::create();
  v->setName("velocity");
  v->tree().setValue(openvdb::Coord(1, 1, 1), openvdb::Vec3s(3, 4, 0));
  v->tree().setValue(openvdb::Coord(2, 1, 1), openvdb::Vec3s(0, 0, 2));
  openvdb::io::File(path).write({v});
  try {
    read_volume(path);
    FAIL() << "expected mlfe::Error";
  } catch (const Error& e) {
    std::string m = e.what();
    EXPECT_NE(m.find(path), std::string::npos) << m;
    EXPECT_NE(m.find("--vec-magnitude"), std::string::npos) << m;
  }
  VolumeReadOptions opts;
  opts.vec_magnitude = true;
  ScalarGrid g = read_volume(path, opts);
  EXPECT_EQ(g.dims, (std::array<std::int64_t, 3>{2, 1, 1}));
  EXPECT_FLOAT_EQ(g.values[0], 5.0f);
  EXPECT_FLOAT_EQ(g.values[1], 2.0f);
}

// ---- raw, MetaImage, PGM, PNG ----

TEST(RawReader, FlagsReadHeaderlessDataWithOffsetAndBigEndian) {
  const std::string path = temp_dir() + "data.bin";
  {
    std::ofstream out(path, std::ios::binary);
    out.write("HDR!", 4);
    for (int k = 0; k < 3; ++k)
      for (int j = 0; j < 4; ++j)
        for (int i = 0; i < 5; ++i) {
          short v = short(pattern(i, j, k));
          unsigned char b[2] = {static_cast<unsigned char>((v >> 8) & 0xff),
                                static_cast<unsigned char>(v & 0xff)};
          out.write(reinterpret_cast<char*>(b), 2);
        }
  }
  VolumeReadOptions o;
  o.raw_dims = std::array<std::int64_t, 3>{5, 4, 3};
  o.raw_dtype = "int16";
  o.raw_endian = "big";
  o.raw_offset = 4;
  o.raw_spacing = std::array<double, 3>{0.5, 0.5, 2};
  o.raw_origin = std::array<double, 3>{1, 2, 3};
  ScalarGrid g = read_volume(path, o);
  EXPECT_EQ(g.format, "raw");
  for (int k = 0; k < 3; ++k)
    for (int j = 0; j < 4; ++j)
      for (int i = 0; i < 5; ++i) ASSERT_EQ(g.at(i, j, k), pattern(i, j, k));
  expect_point(g, 4, 3, 2, {1 + 2.0, 2 + 1.5, 3 + 4.0});
}

TEST(MetaImageReader, LocalShortDataWithTransformMatrix) {
  ScalarGrid g = read_volume(kData + "small_short.mha");
  EXPECT_EQ(g.format, "metaimage");
  EXPECT_EQ(g.dims, (std::array<std::int64_t, 3>{5, 4, 3}));
  EXPECT_EQ(g.source_type, ScalarType::I16);
  EXPECT_EQ(g.space, "LPS");
  for (int k = 0; k < 3; ++k)
    for (int j = 0; j < 4; ++j)
      for (int i = 0; i < 5; ++i) ASSERT_EQ(g.at(i, j, k), pattern(i, j, k));
  // Axis i points along +y, axis j along -x (TransformMatrix 0 1 0 -1 0 0 0 0 1).
  expect_point(g, 1, 0, 0, {10, -20 + 0.5, 5.5});
  expect_point(g, 0, 1, 0, {10 - 1.5, -20, 5.5});
  expect_point(g, 0, 0, 1, {10, -20, 5.5 + 2});
}

TEST(MetaImageReader, CompressedBigEndianFloatInSeparateFile) {
  ScalarGrid g = read_volume(kData + "small_float_z.mhd");
  EXPECT_EQ(g.source_type, ScalarType::F32);
  for (int k = 0; k < 3; ++k)
    for (int j = 0; j < 4; ++j)
      for (int i = 0; i < 5; ++i) ASSERT_EQ(g.at(i, j, k), pattern(i, j, k) * 0.25f);
}

TEST(PgmReader, SixteenBitBigEndianHeightField) {
  ScalarGrid g = read_volume(kData + "small_16bit.pgm");
  EXPECT_EQ(g.format, "pgm");
  EXPECT_EQ(g.dim, 2);
  EXPECT_EQ(g.dims, (std::array<std::int64_t, 3>{7, 5, 1}));
  EXPECT_EQ(g.source_type, ScalarType::U16);
  for (int y = 0; y < 5; ++y)
    for (int x = 0; x < 7; ++x) ASSERT_EQ(g.at(x, y, 0), float((x * 1000 + y * 9000) % 65536));
}

TEST(PngReader, SixteenBitGreyMatchesThePgm) {
  ScalarGrid png = read_volume(kData + "small_16bit.png");
  ScalarGrid pgm = read_volume(kData + "small_16bit.pgm");
  EXPECT_EQ(png.format, "png");
  EXPECT_EQ(png.source_type, ScalarType::U16);
  EXPECT_EQ(png.dims, pgm.dims);
  EXPECT_EQ(png.values, pgm.values);
}

TEST(VolumeFormat, DetectedByMagicBeforeExtension) {
  const std::string dir = temp_dir();
  // A NRRD under a misleading name is still a NRRD.
  std::ifstream in(kData + "mri_slice_256.nrrd", std::ios::binary);
  std::ofstream(dir + "slice.png", std::ios::binary) << in.rdbuf();
  EXPECT_EQ(detect_volume_format(dir + "slice.png"), "nrrd");
  EXPECT_EQ(detect_volume_format(kData + "ct_skull_64.raw"), "raw");
  EXPECT_EQ(detect_volume_format(kData + "mri_small_bigendian.nii"), "nifti");
  EXPECT_EQ(detect_volume_format(kData + "small_short.mha"), "metaimage");
  EXPECT_EQ(detect_volume_format(kData + "small_16bit.pgm"), "pgm");
  std::ofstream(dir + "unknown.xyz") << "hello";
  EXPECT_EQ(detect_volume_format(dir + "unknown.xyz"), "");
}

}  // namespace
}  // namespace mlfe
