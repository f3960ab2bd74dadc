#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfIO.h>
#include <ImfOutputFile.h>
#include <ImfStandardAttributes.h>
#include <ImfStringAttribute.h>
#include <half.h>
#include <mlfe/core/base/check.h>
#include <mlfe/core/base/error.h>
#include <mlfe/formats/atomic_file.h>
#include <mlfe/formats/exr_writer.h>
#include <png.h>

#include <algorithm>
#include <cmath>

namespace mlfe {

namespace {

// OpenEXR on the shared writer's stream, whose state that writer checks: OutputFile writes its
// line offset table in its destructor, where a failed write is swallowed.
class ExrStream : public Imf::OStream {
 public:
  ExrStream(std::ostream& out, const std::string& name) : Imf::OStream(name.c_str()), out_(out) {}
  void write(const char c[], int n) override {
    out_.write(c, n);
    if (!out_) throw std::runtime_error("write failed (disk full?)");
  }
  uint64_t tellp() override { return static_cast<uint64_t>(out_.tellp()); }
  void seekp(uint64_t pos) override { out_.seekp(static_cast<std::streamoff>(pos)); }

 private:
  std::ostream& out_;
};

// Imath multiplies row vectors (p' = p · M): the transpose of the column-vector matrix.
Imath::M44f to_imath(const std::array<double, 16>& m) {
  Imath::M44f out;
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) out[j][i] = float(m[4 * i + j]);
  return out;
}

std::uint8_t srgb8(double linear) {
  const double c = std::clamp(linear, 0.0, 1.0);
  const double s = c <= 0.0031308 ? 12.92 * c : 1.055 * std::pow(c, 1.0 / 2.4) - 0.055;
  return std::uint8_t(std::lround(s * 255.0));
}

}  // namespace

void write_exr(const std::string& path, const RenderImage& img, const ExrAttributes& attributes) {
  const int w = img.width, h = img.height;
  if (w <= 0 || h <= 0 || img.rgba.size() != std::size_t(w) * h * 4 || img.z.size() != std::size_t(w) * h)
    throw Error(path + ": the image's size and its RGBA/Z arrays do not match");
  std::vector<half> channels[4];
  for (auto& c : channels) c.resize(std::size_t(w) * h);
  for (std::size_t i = 0; i < std::size_t(w) * h; ++i)
    for (int c = 0; c < 4; ++c) channels[c][i] = half(img.rgba[4 * i + c]);

  Imf::Header header(w, h);
  header.compression() = Imf::ZIP_COMPRESSION;
  const char* names[4] = {"R", "G", "B", "A"};
  for (const char* n : names) header.channels().insert(n, Imf::Channel(Imf::HALF));
  header.channels().insert("Z", Imf::Channel(Imf::FLOAT));
  Imf::addWorldToCamera(header, to_imath(attributes.world_to_camera));
  Imf::addWorldToNDC(header, to_imath(attributes.world_to_ndc));
  for (const auto& [key, value] : attributes.strings) header.insert(key, Imf::StringAttribute(value));

  Imf::FrameBuffer fb;
  for (int c = 0; c < 4; ++c)
    fb.insert(names[c], Imf::Slice(Imf::HALF, reinterpret_cast<char*>(channels[c].data()), sizeof(half),
                                   sizeof(half) * std::size_t(w)));
  fb.insert("Z", Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(const_cast<float*>(img.z.data())),
                            sizeof(float), sizeof(float) * std::size_t(w)));
  write_file_atomically(path, [&](std::ostream& out) {
    try {
      ExrStream stream(out, path);
      Imf::OutputFile file(stream, header, 1);  // one thread: identical bytes whatever the machine
      file.setFrameBuffer(fb);
      file.writePixels(h);
    } catch (const std::exception& e) {
      throw Error(path + ": cannot write EXR: " + e.what());
    }
  });
}

void write_png_preview(const std::string& path, const RenderImage& img,
                       const std::array<double, 3>& background) {
  const int w = img.width, h = img.height;
  if (w <= 0 || h <= 0 || img.rgba.size() != std::size_t(w) * h * 4)
    throw Error(path + ": the image's size and its RGBA array do not match");
  std::vector<std::uint8_t> rgb(std::size_t(w) * h * 3);
  for (std::size_t i = 0; i < std::size_t(w) * h; ++i) {
    const double a = img.rgba[4 * i + 3];
    for (int c = 0; c < 3; ++c) rgb[3 * i + c] = srgb8(img.rgba[4 * i + c] + (1.0 - a) * background[c]);
  }
  png_image image{};
  image.version = PNG_IMAGE_VERSION;
  image.width = std::uint32_t(w);
  image.height = std::uint32_t(h);
  image.format = PNG_FORMAT_RGB;
  png_alloc_size_t size = 0;
  if (!png_image_write_get_memory_size(image, size, 0, rgb.data(), 0, nullptr))
    throw Error(path + ": cannot encode PNG: " + image.message);
  std::vector<std::uint8_t> bytes(size);
  if (!png_image_write_to_memory(&image, bytes.data(), &size, 0, rgb.data(), 0, nullptr))
    throw Error(path + ": cannot encode PNG: " + image.message);
  write_file_atomically(path, [&](std::ostream& out) {
    out.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(size));
  });
}

}  // namespace mlfe
