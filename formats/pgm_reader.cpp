#include <fmt/format.h>
#include <mlfe/formats/pgm_reader.h>
#include <mlfe/formats/raw_reader.h>

#include <cctype>

#include "formats/reader_helpers.h"

namespace mlfe {
using namespace volume_detail;

ScalarGrid read_pgm(const std::string& path, const VolumeReadOptions& opts) {
  const std::uint64_t fsize = regular_file_size(path);
  const std::string head = read_file_prefix(path, 4096);
  if (head.size() < 2 || head[0] != 'P' || head[1] != '5') fail(path, "not a binary PGM file (no P5 magic)");
  std::size_t pos = 2;
  // Header fields are separated by whitespace and may be interleaved with # comments.
  auto next_number = [&](const char* what) -> std::int64_t {
    for (;;) {
      while (pos < head.size() && std::isspace(static_cast<unsigned char>(head[pos]))) ++pos;
      if (pos < head.size() && head[pos] == '#') {
        while (pos < head.size() && head[pos] != '\n' && head[pos] != '\r') ++pos;
        continue;
      }
      break;
    }
    if (pos >= head.size()) fail(path, fmt::format("truncated PGM header (no {})", what));
    if (!std::isdigit(static_cast<unsigned char>(head[pos])))
      fail(path, fmt::format("bad PGM header: {} is not a number", what));
    std::int64_t v = 0;
    while (pos < head.size() && std::isdigit(static_cast<unsigned char>(head[pos]))) {
      v = v * 10 + (head[pos] - '0');
      if (v > INT32_MAX) fail(path, fmt::format("PGM {} is too large", what));
      ++pos;
    }
    return v;
  };
  const std::int64_t w = next_number("width");
  const std::int64_t h = next_number("height");
  const std::int64_t maxval = next_number("maxval");
  if (pos >= head.size() || !std::isspace(static_cast<unsigned char>(head[pos])))
    fail(path, "truncated PGM header (no whitespace after maxval)");
  ++pos;  // exactly one whitespace character before the data
  if (maxval < 1 || maxval > 65535) fail(path, fmt::format("PGM maxval {} is outside 1..65535", maxval));
  const ScalarType type = maxval < 256 ? ScalarType::U8 : ScalarType::U16;
  const std::array<std::int64_t, 3> dims{w, h, 1};
  const std::int64_t voxels = checked_voxel_count(path, dims);
  const std::uint64_t bytes = checked_bytes(path, voxels, static_cast<std::uint64_t>(scalar_type_size(type)));
  if (fsize - pos < bytes)
    fail(path, fmt::format("truncated: {} x {} PGM with maxval {} needs {} bytes of data, the file has {}", w,
                           h, maxval, bytes, fsize - pos));
  check_memory(path, checked_bytes(path, voxels, 4), opts, "the float32 grid");
  ScalarGrid grid;
  grid.dim = 2;
  grid.dims = dims;
  grid.source_type = type;
  allocate_values(grid);
  RegularFile in(path);
  in.seek(pos);
  read_raw_values(path, in, type, host_is_little_endian(), grid.values.data(), grid.values.size());
  if (fsize - pos > bytes) add_note(grid, "bytes after the first PGM image ignored");
  return grid;
}

}  // namespace mlfe
