#include <ImfBoxAttribute.h>
#include <ImfChannelList.h>
#include <ImfCompressionAttribute.h>
#include <ImfDoubleAttribute.h>
#include <ImfFloatAttribute.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>
#include <ImfIntAttribute.h>
#include <ImfLineOrderAttribute.h>
#include <ImfStdIO.h>
#include <ImfStringAttribute.h>
#include <ImfVecAttribute.h>
#include <fmt/format.h>
#include <mlfe/core/base/error.h>
#include <mlfe/formats/image_reader.h>
#include <mlfe/formats/png_reader.h>
#include <mlfe/formats/safe_read.h>
#include <png.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <vector>

namespace mlfe {
namespace {

[[noreturn]] void fail(const std::string& path, const std::string& problem) {
  throw Error(path + ": " + problem);
}

bool is_exr_magic(const std::string& head) {
  return head.size() >= 4 && std::memcmp(head.data(), "\x76\x2f\x31\x01", 4) == 0;
}
bool is_png_magic(const std::string& head) {
  return head.size() >= 8 && std::memcmp(head.data(), "\x89PNG\r\n\x1a\n", 8) == 0;
}

/// A readable value for the common attribute types; the serialized bytes for the others, so
/// that any change is still seen.
std::string attribute_text(const Imf::Attribute& a) {
  using namespace Imf;
  if (auto* s = dynamic_cast<const StringAttribute*>(&a)) return s->value();
  if (auto* i = dynamic_cast<const IntAttribute*>(&a)) return std::to_string(i->value());
  if (auto* f = dynamic_cast<const FloatAttribute*>(&a)) return fmt::format("{}", f->value());
  if (auto* d = dynamic_cast<const DoubleAttribute*>(&a)) return fmt::format("{}", d->value());
  if (auto* b = dynamic_cast<const Box2iAttribute*>(&a))
    return fmt::format("({}, {}) - ({}, {})", b->value().min.x, b->value().min.y, b->value().max.x,
                       b->value().max.y);
  if (auto* v = dynamic_cast<const V2fAttribute*>(&a))
    return fmt::format("({}, {})", v->value().x, v->value().y);
  if (auto* v = dynamic_cast<const V2iAttribute*>(&a))
    return fmt::format("({}, {})", v->value().x, v->value().y);
  if (auto* c = dynamic_cast<const CompressionAttribute*>(&a)) return std::to_string(int(c->value()));
  if (auto* l = dynamic_cast<const LineOrderAttribute*>(&a)) return std::to_string(int(l->value()));
  StdOSStream os;
  a.writeValueTo(os, 2);
  std::string hex;
  for (unsigned char ch : os.str()) hex += fmt::format("{:02x}", ch);
  return "bytes " + hex;
}

// OpenEXR sizes attribute buffers from the header's own size fields before it reads them, so a
// corrupt size makes it ask for gigabytes. Every attribute of a single-part header must lie in
// the file: name\0 type\0 int32 size, value; the list ends with an empty name.
void check_exr_header(const std::string& path) {
  const std::string b = read_regular_file(path, UINT64_MAX, "the file");
  const auto fail = [&](const std::string& what) {
    throw Error(path + ": not a valid EXR file (" + what + ")");
  };
  if (b.size() < 8) fail("truncated");
  if (static_cast<unsigned char>(b[4]) != 2) fail("unsupported version");
  const unsigned flags = static_cast<unsigned char>(b[5]);
  if (flags & 0x10) return;  // multi-part: headers are checked by OpenEXR's multi-part reader
  // Names and types are at most 31 bytes (255 with the long-names flag), as OpenEXR reads them.
  const std::size_t max_name = (flags & 0x04) ? 255 : 31;
  std::size_t at = 8;
  const auto read_string = [&]() {
    const std::size_t start = at;
    while (at < b.size() && b[at] != 0) ++at;
    if (at >= b.size()) fail("header runs past the end of the file");
    if (at - start > max_name) fail("a header name is too long");
    ++at;
    return at - start - 1;
  };
  for (int n = 0;; ++n) {
    if (n > 10000) fail("too many header attributes");
    if (read_string() == 0) return;  // end of the attribute list
    read_string();                   // type
    if (at + 4 > b.size()) fail("header runs past the end of the file");
    std::int32_t size = 0;
    std::memcpy(&size, &b[at], 4);  // little-endian, as EXR is; this machine's order too
    at += 4;
    if (size < 0 || std::size_t(size) > b.size() - at) fail("a header attribute is larger than the file");
    at += std::size_t(size);
  }
}

Image read_exr(const std::string& path) {
  Image img;
  img.format = "exr";
  check_exr_header(path);
  try {
    Imf::InputFile file(path.c_str());
    const Imf::Header& header = file.header();
    const Imath::Box2i dw = header.dataWindow();
    const long long w = (long long)dw.max.x - dw.min.x + 1, h = (long long)dw.max.y - dw.min.y + 1;
    if (w <= 0 || h <= 0 || w * h > (1LL << 31)) fail(path, "unsupported data window");
    img.width = int(w);
    img.height = int(h);
    for (auto it = header.begin(); it != header.end(); ++it) {
      if (std::strcmp(it.name(), "channels") == 0) continue;
      img.attributes[it.name()] =
          std::string(it.attribute().typeName()) + ": " + attribute_text(it.attribute());
    }
    Imf::FrameBuffer fb;
    for (auto it = header.channels().begin(); it != header.channels().end(); ++it) {
      ImageChannel ch;
      ch.name = it.name();
      const Imf::PixelType t = it.channel().type;
      ch.type = t == Imf::HALF ? "half" : t == Imf::FLOAT ? "float" : "uint";
      if (it.channel().xSampling != 1 || it.channel().ySampling != 1)
        fail(path, "channel " + ch.name + " is subsampled (not supported)");
      ch.values.assign(std::size_t(w * h), 0.0f);
      img.channels.push_back(std::move(ch));
    }
    for (auto& ch : img.channels) {
      // Slices are addressed with absolute pixel coordinates; shift the base by the window origin.
      char* base = reinterpret_cast<char*>(ch.values.data()) -
                   (std::ptrdiff_t(dw.min.x) + std::ptrdiff_t(dw.min.y) * std::ptrdiff_t(w)) * sizeof(float);
      fb.insert(ch.name.c_str(), Imf::Slice(Imf::FLOAT, base, sizeof(float), sizeof(float) * std::size_t(w)));
    }
    file.setFrameBuffer(fb);
    file.readPixels(dw.min.y, dw.max.y);
  } catch (const Error&) {
    throw;
  } catch (const std::exception& e) {
    std::string what = e.what();
    std::replace(what.begin(), what.end(), '\n', ' ');
    fail(path, "bad OpenEXR file: " + what);
  }
  return img;
}

Image read_png_image(const std::string& path) {
  Image img;
  img.format = "png";
  check_png_chunks(path, read_regular_file(path, UINT64_MAX, "the file"));
  png_image image;
  std::memset(&image, 0, sizeof image);
  image.version = PNG_IMAGE_VERSION;
  if (!png_image_begin_read_from_file(&image, path.c_str()))
    fail(path, std::string("bad PNG: ") + image.message);
  struct Guard {
    png_image* img;
    ~Guard() { png_image_free(img); }
  } guard{&image};
  // Colour-mapped files are expanded; the channel layout and depth otherwise stay the file's.
  image.format &= ~PNG_FORMAT_FLAG_COLORMAP;
  const bool sixteen = (image.format & PNG_FORMAT_FLAG_LINEAR) != 0;
  const bool colour = (image.format & PNG_FORMAT_FLAG_COLOR) != 0;
  const bool alpha = (image.format & PNG_FORMAT_FLAG_ALPHA) != 0;
  const int nc = int(PNG_IMAGE_SAMPLE_CHANNELS(image.format));
  const std::size_t pixels = std::size_t(image.width) * image.height;
  if (pixels > (std::size_t(1) << 31)) fail(path, "image too large");
  std::vector<unsigned char> buffer(PNG_IMAGE_SIZE(image));
  if (!png_image_finish_read(&image, nullptr, buffer.data(), 0, nullptr))
    fail(path, std::string("bad PNG: ") + image.message);
  img.width = int(image.width);
  img.height = int(image.height);
  std::vector<std::string> names =
      colour ? std::vector<std::string>{"R", "G", "B"} : std::vector<std::string>{"Y"};
  if (alpha) names.push_back("A");
  for (int c = 0; c < nc; ++c) {
    ImageChannel ch;
    ch.name = names[c];
    ch.type = sixteen ? "uint16" : "uint8";
    ch.values.resize(pixels);
    for (std::size_t i = 0; i < pixels; ++i) {
      if (sixteen) {
        std::uint16_t v;
        std::memcpy(&v, buffer.data() + 2 * (i * nc + c), 2);
        ch.values[i] = float(v / 65535.0);
      } else {
        ch.values[i] = float(buffer[i * nc + c] / 255.0);
      }
    }
    img.channels.push_back(std::move(ch));
  }
  img.attributes["sample depth"] = sixteen ? "16" : "8";
  img.attributes["colour"] = colour ? "RGB" : "grey";
  img.attributes["alpha"] = alpha ? "yes" : "no";
  return img;
}

}  // namespace

bool is_image_file(const std::string& path) {
  const std::string head = read_file_prefix(path, 8);
  return is_exr_magic(head) || is_png_magic(head);
}

Image read_image(const std::string& path) {
  const std::string head = read_file_prefix(path, 8);
  if (is_exr_magic(head)) return read_exr(path);
  if (is_png_magic(head)) return read_png_image(path);
  fail(path, "not an OpenEXR or PNG image");
}

}  // namespace mlfe
