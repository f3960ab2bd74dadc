// formats/image_reader: EXR channels and attributes (data window not at the origin), PNG
// channel layout and scaling, and truncated files end in mlfe::Error.
#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfOutputFile.h>
#include <ImfStringAttribute.h>
#include <gtest/gtest.h>
#include <half.h>
#include <mlfe/core/base/error.h>
#include <mlfe/formats/image_reader.h>
#include <png.h>

#include <cstring>
#include <fstream>

#include "tests/test_meshes.h"

namespace mlfe {
namespace {

std::string tmp(const std::string& name) { return test::scratch_dir() + "/image_reader_" + name; }

TEST(ImageReader, ExrWithShiftedDataWindow) {
  const std::string path = tmp("window.exr");
  const Imath::Box2i display(Imath::V2i(0, 0), Imath::V2i(9, 9)), data(Imath::V2i(3, 2), Imath::V2i(6, 4));
  Imf::Header header(display, data);
  header.channels().insert("Z", Imf::Channel(Imf::FLOAT));
  header.channels().insert("A", Imf::Channel(Imf::HALF));
  header.insert("owner", Imf::StringAttribute("mlfe test"));
  std::vector<float> z(4 * 3);
  std::vector<Imath::half> a(4 * 3);
  for (int i = 0; i < 12; ++i) {
    z[i] = float(i);
    a[i] = 0.5f;
  }
  {
    Imf::OutputFile file(path.c_str(), header);
    Imf::FrameBuffer fb;
    const std::ptrdiff_t shift = 3 + 2 * 4;
    fb.insert("Z", Imf::Slice(Imf::FLOAT, (char*)(z.data() - shift), sizeof(float), 4 * sizeof(float)));
    fb.insert("A",
              Imf::Slice(Imf::HALF, (char*)(a.data() - shift), sizeof(Imath::half), 4 * sizeof(Imath::half)));
    file.setFrameBuffer(fb);
    file.writePixels(3);
  }
  const Image img = read_image(path);
  EXPECT_EQ(img.format, "exr");
  EXPECT_EQ(img.width, 4);
  EXPECT_EQ(img.height, 3);
  ASSERT_EQ(img.channels.size(), 2u);
  EXPECT_EQ(img.channels[0].name, "A");
  EXPECT_EQ(img.channels[0].type, "half");
  EXPECT_EQ(img.channels[0].values[5], 0.5f);
  EXPECT_EQ(img.channels[1].name, "Z");
  EXPECT_EQ(img.channels[1].values, z);
  EXPECT_EQ(img.attributes.at("owner"), "string: mlfe test");
  EXPECT_EQ(img.attributes.at("dataWindow"), "box2i: (3, 2) - (6, 4)");
  EXPECT_EQ(img.attributes.count("channels"), 0u);  // compared as channels, not as bytes

  // Every truncation is an error naming the file, never a crash.
  const std::string bytes = test::read_bytes(path), cut = tmp("cut.exr");
  for (std::size_t n = 0; n < bytes.size(); n += 7) {
    std::ofstream(cut, std::ios::binary | std::ios::trunc).write(bytes.data(), std::streamsize(n));
    EXPECT_THROW(read_image(cut), Error) << n;
  }
}

TEST(ImageReader, PngGreyAlphaScaledToUnitRange) {
  const std::string path = tmp("ga.png");
  png_image image;
  std::memset(&image, 0, sizeof image);
  image.version = PNG_IMAGE_VERSION;
  image.width = 2;
  image.height = 1;
  image.format = PNG_FORMAT_GA;
  const std::uint8_t px[4] = {0, 255, 51, 102};
  ASSERT_TRUE(png_image_write_to_file(&image, path.c_str(), 0, px, 0, nullptr));
  const Image img = read_image(path);
  ASSERT_EQ(img.channels.size(), 2u);
  EXPECT_EQ(img.channels[0].name, "Y");
  EXPECT_EQ(img.channels[1].name, "A");
  EXPECT_FLOAT_EQ(img.channels[0].values[1], 0.2f);
  EXPECT_FLOAT_EQ(img.channels[1].values[1], 0.4f);
  EXPECT_EQ(img.attributes.at("sample depth"), "8");
  const std::string bytes = test::read_bytes(path), cut = tmp("cut.png");
  // libpng needs the image data, not the closing 12-byte IEND chunk.
  for (std::size_t n = 0; n + 12 < bytes.size(); n += 5) {
    std::ofstream(cut, std::ios::binary | std::ios::trunc).write(bytes.data(), std::streamsize(n));
    EXPECT_THROW(read_image(cut), Error) << n;
  }
  EXPECT_THROW(read_image(tmp("nothing.png")), Error);
}

}  // namespace
}  // namespace mlfe
