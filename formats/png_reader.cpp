#include <fmt/format.h>
#include <mlfe/formats/png_reader.h>
#include <png.h>

#include <cstdint>
#include <cstring>
#include <vector>

#include "formats/reader_helpers.h"

namespace mlfe {
using namespace volume_detail;

namespace {

// The pixels IHDR declares, at their bit depth: a lower bound of what the image data inflates
// to, interlaced or not (rows add filter bytes and padding on top).
void check_png_data_size(const std::string& path, const std::string& ihdr, const std::string& idat) {
  if (ihdr.size() != 13) return;  // libpng names the bad header
  const auto* h = reinterpret_cast<const unsigned char*>(ihdr.data());
  const auto be32 = [](const unsigned char* q) {
    return (std::uint64_t(q[0]) << 24) | (std::uint64_t(q[1]) << 16) | (std::uint64_t(q[2]) << 8) | q[3];
  };
  static constexpr int kChannels[7] = {1, 0, 3, 1, 2, 0, 4};  // by colour type
  const int channels = h[9] < 7 ? kChannels[h[9]] : 0;
  const unsigned __int128 bits = static_cast<unsigned __int128>(be32(h) * be32(h + 4)) * h[8] * channels;
  const std::uint64_t need = bits / 8 > UINT64_MAX ? UINT64_MAX : static_cast<std::uint64_t>(bits / 8);
  const std::uint64_t held =
      count_bytes(decoded_source(path, Compression::kZlib, memory_source(idat.data(), idat.size())), need);
  if (held < need)
    fail(path,
         fmt::format("truncated PNG: {} x {} pixels need {} bytes of image data, the IDAT chunks hold {}",
                     be32(h), be32(h + 4), need, held));
}

}  // namespace

void check_png_chunks(const std::string& path, const std::string& bytes) {
  if (bytes.size() < 8 || std::memcmp(bytes.data(), "\x89PNG\r\n\x1a\n", 8) != 0)
    fail(path, "not a PNG file (wrong signature)");
  std::size_t at = 8;
  std::string idat, ihdr;
  while (true) {
    if (bytes.size() - at < 12) fail(path, "truncated PNG (no IEND chunk)");
    const auto* p = reinterpret_cast<const unsigned char*>(bytes.data() + at);
    const std::uint64_t length = (std::uint64_t(p[0]) << 24) | (p[1] << 16) | (p[2] << 8) | p[3];
    if (length > bytes.size() - at - 12) fail(path, "truncated PNG (a chunk runs past the end)");
    const bool end = std::memcmp(p + 4, "IEND", 4) == 0;
    if (std::memcmp(p + 4, "IDAT", 4) == 0) idat.append(bytes, at + 8, std::size_t(length));
    if (std::memcmp(p + 4, "IHDR", 4) == 0 && ihdr.empty()) ihdr = bytes.substr(at + 8, std::size_t(length));
    at += 12 + std::size_t(length);
    if (end) break;
  }
  if (at != bytes.size()) fail(path, fmt::format("{} bytes after the PNG's IEND chunk", bytes.size() - at));
  check_png_data_size(path, ihdr, idat);
}

ScalarGrid read_png(const std::string& path, const VolumeReadOptions& opts) {
  const std::string data = read_regular_file(path, memory_limit(opts), "the file");
  check_png_chunks(path, data);
  // The simplified libpng API keeps its setjmp handling inside libpng; errors come back as
  // a return value and image.message.
  png_image image;
  std::memset(&image, 0, sizeof image);
  image.version = PNG_IMAGE_VERSION;
  if (!png_image_begin_read_from_memory(&image, data.data(), data.size()))
    fail(path, std::string("bad PNG: ") + image.message);
  struct Guard {
    png_image* img;
    ~Guard() { png_image_free(img); }
  } guard{&image};
  const bool sixteen = (image.format & PNG_FORMAT_FLAG_LINEAR) != 0;
  const bool colour = (image.format & PNG_FORMAT_FLAG_COLOR) != 0;
  const std::array<std::int64_t, 3> dims{image.width, image.height, 1};
  const std::int64_t voxels = checked_voxel_count(path, dims);
  const std::uint64_t pixel_bytes = checked_bytes(path, voxels, sixteen ? 2 : 1);
  std::uint64_t need = 0;
  if (__builtin_add_overflow(pixel_bytes, checked_bytes(path, voxels, 4), &need)) need = UINT64_MAX;
  check_memory(path, need, opts, "the PNG pixels and the float32 grid");

  ScalarGrid grid;
  grid.dim = 2;
  grid.dims = dims;
  grid.source_type = sixteen ? ScalarType::U16 : ScalarType::U8;
  // 16-bit PNG data is linear in libpng's model, so LINEAR_Y leaves grey values unchanged;
  // 8-bit grey is read as it is stored.
  image.format = sixteen ? PNG_FORMAT_LINEAR_Y : PNG_FORMAT_GRAY;
  std::vector<unsigned char> pixels(static_cast<std::size_t>(pixel_bytes));
  if (!png_image_finish_read(&image, nullptr, pixels.data(), 0, nullptr))
    fail(path, std::string("bad PNG data: ") + image.message);
  allocate_values(grid);
  convert_to_float(pixels.data(), grid.source_type, false, grid.values.data(), grid.values.size());
  if (colour) add_note(grid, "colour PNG converted to grey by libpng");
  return grid;
}

}  // namespace mlfe
