// EXR output as other tools see it (exrheader from the openexr package, and OpenEXR's reader),
// the PNG preview, and ParaView transfer-function files.
#include <ImfArray.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>
#include <ImfMatrixAttribute.h>
#include <gtest/gtest.h>
#include <mlfe/core/base/error.h>
#include <mlfe/formats/exr_writer.h>
#include <mlfe/formats/transfer_function_io.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>

#include "tests/test_paths.h"

namespace fs = std::filesystem;

namespace mlfe {
namespace {

std::string temp(const std::string& name) { return test::scratch_dir("exr_writer") + "/" + name; }

std::string command_output(const std::string& cmd) {
  std::string out;
  FILE* p = ::popen(cmd.c_str(), "r");
  if (!p) return out;
  char buf[4096];
  std::size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, p)) > 0) out.append(buf, n);
  ::pclose(p);
  return out;
}

RenderImage small_image() {
  RenderImage img;
  img.width = 5;
  img.height = 3;
  for (int i = 0; i < 15; ++i) {
    const float a = i / 14.0f;
    img.rgba.insert(img.rgba.end(), {0.5f * a, 0.25f * a, 0.125f * a, a});
    img.z.push_back(i == 0 ? std::numeric_limits<float>::infinity() : 10.0f + i);
  }
  return img;
}

TEST(ExrWriter, ExrheaderListsHalfRgbaFloatZAndTheAttributes) {
  const RenderImage img = small_image();
  ExrAttributes attr;
  const Camera cam = orbit_camera({1, 2, 3}, 4, 30, 20, true, 5, 3);
  attr.world_to_camera = cam.world_to_camera();
  attr.world_to_ndc = cam.world_to_ndc();
  attr.strings = {{"mlfe/transferFunction", "{\"name\":\"bone\"}"}, {"mlfe/source", "skull.nrrd"}};
  const std::string path = temp("a.exr");
  write_exr(path, img, attr);
  const std::string h = command_output("exrheader " + path);
  for (const char* ch : {"A", "B", "G", "R"})
    EXPECT_NE(h.find(std::string("    ") + ch + ", 16-bit floating-point"), std::string::npos) << h;
  EXPECT_NE(h.find("    Z, 32-bit floating-point"), std::string::npos) << h;
  EXPECT_NE(h.find("worldToCamera (type m44f)"), std::string::npos) << h;
  EXPECT_NE(h.find("worldToNDC (type m44f)"), std::string::npos) << h;
  EXPECT_NE(h.find("mlfe/source (type string): \"skull.nrrd\""), std::string::npos) << h;
  EXPECT_NE(h.find("mlfe/transferFunction (type string)"), std::string::npos) << h;

  // Pixels as OpenEXR reads them back: half RGBA, float Z (inf kept).
  Imf::InputFile in(path.c_str());
  Imf::Array2D<float> a(3, 5), z(3, 5);
  Imf::FrameBuffer fb;
  fb.insert("A", Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(&a[0][0]), sizeof(float), 5 * sizeof(float)));
  fb.insert("Z", Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(&z[0][0]), sizeof(float), 5 * sizeof(float)));
  in.setFrameBuffer(fb);
  in.readPixels(0, 2);
  EXPECT_NEAR(a[1][2], 7 / 14.0, 1e-3);
  EXPECT_EQ(z[2][4], 24.0f);
  EXPECT_TRUE(std::isinf(z[0][0]));
  // camera = world_to_camera · p: the target lies straight ahead (−z).
  const auto& m = in.header().typedAttribute<Imf::M44fAttribute>("worldToCamera").value();
  const Imath::V3f t = Imath::V3f(1, 2, 3) * m;
  EXPECT_NEAR(t.x, 0, 1e-4);
  EXPECT_NEAR(t.y, 0, 1e-4);
  EXPECT_LT(t.z, 0);
  fs::remove(path);
}

TEST(ExrWriter, UnwritablePathThrowsAndLeavesNothing) {
  EXPECT_THROW(write_exr("/nonexistent-dir/x.exr", small_image(), {}), Error);
}

TEST(PngPreview, CompositesOverTheBackgroundInSrgb) {
  const std::string path = temp("p.png");
  write_png_preview(path, small_image(), {1, 1, 1});
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  const std::string b = ss.str();
  ASSERT_GT(b.size(), 33u);
  EXPECT_EQ(b.substr(1, 3), "PNG");
  EXPECT_EQ(b.substr(12, 4), "IHDR");
  auto be32 = [&](std::size_t o) {
    return (unsigned(std::uint8_t(b[o])) << 24) | (unsigned(std::uint8_t(b[o + 1])) << 16) |
           (unsigned(std::uint8_t(b[o + 2])) << 8) | unsigned(std::uint8_t(b[o + 3]));
  };
  EXPECT_EQ(be32(16), 5u);
  EXPECT_EQ(be32(20), 3u);
  EXPECT_EQ(b[24], 8);  // bit depth
  EXPECT_EQ(b[25], 2);  // RGB
  fs::remove(path);
}

TEST(ParaViewTransferFunction, ReadsRgbAndOpacityPoints) {
  const std::string path = temp("tf.json");
  std::ofstream(path)
      << R"([{"ColorSpace":"Diverging","Name":"Cool to Warm","RGBPoints":[0,0.23,0.3,0.75,100,0.7,0.01,0.15],
    "Points":[0,0,0.5,0,50,0.2,0.5,0,100,1,0.5,0]}])";
  const TransferFunction tf = read_paraview_transfer_function(path, 2.0);
  EXPECT_EQ(tf.name, "Cool to Warm");
  ASSERT_EQ(tf.color.size(), 2u);
  EXPECT_DOUBLE_EQ(tf.color[1][1], 0.7);
  ASSERT_EQ(tf.opacity.size(), 3u);
  EXPECT_DOUBLE_EQ(tf.opacity[1][0], 50);
  EXPECT_DOUBLE_EQ(tf.opacity[1][1], 0.2);
  EXPECT_EQ(tf.unit_length, 2.0);

  std::ofstream(path) << R"({"RGBPoints":[0,0,0,0],"Points":[0,0,0.3,0]})";
  EXPECT_THROW(read_paraview_transfer_function(path), Error);
  std::ofstream(path) << R"({"RGBPoints":[0,0,0],"Points":[0,0,0.5,0]})";
  EXPECT_THROW(read_paraview_transfer_function(path), Error);
  std::ofstream(path) << "not json";
  EXPECT_THROW(read_paraview_transfer_function(path), Error);
  fs::remove(path);
}

TEST(ParaViewTransferFunction, RecordIsCompactJsonWithSortedKeys) {
  TransferFunction tf;
  tf.name = "bone";
  tf.color = {{0, 0.5, 0.25, 0}, {10, 1, 1, 1}};
  tf.opacity = {{0, 0}, {10, 0.5}};
  tf.unit_length = 2;
  EXPECT_EQ(transfer_function_record(tf),
            R"({"RGBPoints":[[0.0,0.5,0.25,0.0],[10.0,1.0,1.0,1.0]],"name":"bone",)"
            R"("opacityPoints":[[0.0,0.0],[10.0,0.5]],"opacityUnitLength":2.0})");
}

}  // namespace
}  // namespace mlfe
