#include <fmt/format.h>
#include <mlfe/core/base/check.h>
#include <mlfe/formats/raw_reader.h>
#include <sys/stat.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <nlohmann/json.hpp>
#include <vector>

#include "formats/reader_helpers.h"
#include "formats/volume_formats_detail.h"

namespace mlfe {
using namespace volume_detail;

void read_raw_values(const std::string& path, RegularFile& in, ScalarType t, bool swap, float* dst,
                     std::size_t n) {
  const std::size_t esize = static_cast<std::size_t>(scalar_type_size(t));
  const std::size_t chunk = (std::size_t(1) << 20) / esize;
  std::vector<char> buf(std::min(n, chunk) * esize);
  for (std::size_t done = 0; done < n;) {
    std::size_t m = std::min(chunk, n - done);
    const std::size_t got = in.read(buf.data(), m * esize);
    if (got != m * esize)
      fail(path,
           fmt::format("truncated: voxel data ends after {} of {} bytes", done * esize + got, n * esize));
    convert_to_float(buf.data(), t, swap, dst + done, m);
    done += m;
  }
}

namespace {

// Whatever exists under a sidecar's name is the sidecar: reading it then refuses a FIFO or a
// device by name instead of waiting on it.
bool exists(const std::string& p) {
  struct stat st {};
  return ::stat(p.c_str(), &st) == 0;
}

std::string find_sidecar(const std::string& path) {
  if (exists(path + ".json")) return path + ".json";
  auto dot = path.find_last_of('.');
  auto slash = path.find_last_of('/');
  if (dot != std::string::npos && (slash == std::string::npos || dot > slash)) {
    std::string p = path.substr(0, dot) + ".json";
    if (exists(p)) return p;
  }
  return "";
}

template <std::size_t N>
std::array<double, N> number_array(const std::string& file, const nlohmann::json& j, const char* key,
                                   std::size_t min_count, std::size_t* count = nullptr) {
  const auto& v = j.at(key);
  if (!v.is_array() || v.size() < min_count || v.size() > N)
    fail(file, fmt::format("\"{}\" must be an array of {}{} numbers", key, min_count,
                           min_count == N ? "" : fmt::format(" to {}", N)));
  std::array<double, N> out{};
  for (std::size_t i = 0; i < v.size(); ++i) {
    if (!v[i].is_number()) fail(file, fmt::format("\"{}\"[{}] is not a number", key, i));
    out[i] = v[i].get<double>();
    if (!std::isfinite(out[i])) fail(file, fmt::format("\"{}\"[{}] is not finite", key, i));
  }
  if (count) *count = v.size();
  return out;
}

}  // namespace

namespace volume_detail {

std::vector<std::string> raw_companions(const std::string& path) {
  const std::string sidecar = find_sidecar(path);
  if (sidecar.empty()) return {};
  return {sidecar};
}

}  // namespace volume_detail

RawLayout raw_layout(const std::string& path, const VolumeReadOptions& opts) {
  const std::uint64_t fsize = regular_file_size(path);
  RawLayout layout;
  ScalarGrid& grid = layout.frame;
  std::array<std::int64_t, 3> dims{0, 0, 1};
  std::optional<ScalarType> type;
  std::string endian = "little";
  std::int64_t offset = 0;
  bool have_dims = false;

  std::string sidecar = find_sidecar(path);
  if (!sidecar.empty()) {
    std::string text = read_regular_file(sidecar, 1 << 20, "a raw sidecar");
    nlohmann::json j = nlohmann::json::parse(text, nullptr, false);
    if (j.is_discarded()) fail(sidecar, "bad JSON in raw sidecar");
    if (!j.is_object()) fail(sidecar, "raw sidecar must be a JSON object");
    if (!opts.raw_dims) {
      if (!j.contains("dims")) fail(sidecar, "raw sidecar is missing \"dims\"");
      std::size_t n = 0;
      auto d = number_array<3>(sidecar, j, "dims", 2, &n);
      for (int a = 0; a < 3; ++a) {
        if (a < int(n) && (d[a] != std::floor(d[a]) || d[a] < 1 || d[a] > 2147483647.0))
          fail(sidecar, fmt::format("\"dims\"[{}] = {} is not a positive integer", a, d[a]));
        dims[a] = a < int(n) ? static_cast<std::int64_t>(d[a]) : 1;
      }
      have_dims = true;
    }
    if (opts.raw_dtype.empty()) {
      if (!j.contains("dtype") && !j.contains("type")) fail(sidecar, "raw sidecar is missing \"dtype\"");
      const auto& t = j.contains("dtype") ? j["dtype"] : j["type"];
      if (!t.is_string()) fail(sidecar, "\"dtype\" must be a string");
      type = parse_scalar_type(t.get<std::string>());
      if (!type) fail(sidecar, "unsupported dtype \"" + t.get<std::string>() + "\" (uint8..float64)");
    }
    if (j.contains("endian")) {
      if (!j["endian"].is_string()) fail(sidecar, "\"endian\" must be \"little\" or \"big\"");
      endian = j["endian"].get<std::string>();
    }
    if (j.contains("spacing")) {
      std::size_t n = 0;
      auto s = number_array<3>(sidecar, j, "spacing", 2, &n);
      for (std::size_t a = 0; a < n; ++a) {
        if (!(s[a] > 0)) fail(sidecar, "\"spacing\" entries must be positive");
        grid.transform.spacing[a] = s[a];
      }
    }
    if (j.contains("origin")) {
      std::size_t n = 0;
      auto o = number_array<3>(sidecar, j, "origin", 2, &n);
      for (std::size_t a = 0; a < n; ++a) grid.transform.origin[a] = o[a];
    }
    if (j.contains("direction")) grid.transform.direction = number_array<9>(sidecar, j, "direction", 9);
    if (j.contains("offset")) {
      const auto& o = j["offset"];
      if (!o.is_number_integer() || o.get<std::int64_t>() < 0)
        fail(sidecar, "\"offset\" must be a non-negative integer");
      offset = o.get<std::int64_t>();
    }
    if (j.contains("space")) {
      if (!j["space"].is_string()) fail(sidecar, "\"space\" must be \"RAS\" or \"LPS\"");
      std::string s = j["space"].get<std::string>();
      for (auto& c : s) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
      if (s != "RAS" && s != "LPS" && !s.empty()) fail(sidecar, "\"space\" must be \"RAS\" or \"LPS\"");
      grid.space = s;
    }
  }
  if (opts.raw_dims) {
    dims = *opts.raw_dims;
    if (dims[2] == 0) dims[2] = 1;
    have_dims = true;
  }
  if (!opts.raw_dtype.empty()) {
    type = parse_scalar_type(opts.raw_dtype);
    if (!type) fail(path, "unsupported raw type \"" + opts.raw_dtype + "\" (uint8..float64)");
  }
  if (sidecar.empty()) {
    endian = opts.raw_endian.empty() ? "little" : opts.raw_endian;
    offset = opts.raw_offset;
  } else {
    // Flags given explicitly override the sidecar; the defaults do not.
    if (opts.raw_endian != "little") endian = opts.raw_endian;
    if (opts.raw_offset != 0) offset = opts.raw_offset;
  }
  if (opts.raw_spacing) grid.transform.spacing = *opts.raw_spacing;
  if (opts.raw_origin) grid.transform.origin = *opts.raw_origin;
  if (!have_dims || !type)
    fail(path, "headerless raw data needs a sidecar " + path + ".json or --raw-dims and --raw-type");
  if (endian != "little" && endian != "big")
    fail(path, "endian must be \"little\" or \"big\", not \"" + endian + "\"");
  if (offset < 0) fail(path, "negative raw offset");

  {
    // Sidecar directions need not be unit length; fold their lengths into the spacing.
    std::array<std::array<double, 3>, 3> axes{};
    for (int a = 0; a < 3; ++a)
      for (int r = 0; r < 3; ++r)
        axes[a][r] = grid.transform.direction[r * 3 + a] * grid.transform.spacing[a];
    if (grid.transform.spacing[0] > 0 && grid.transform.spacing[1] > 0 && grid.transform.spacing[2] > 0)
      set_axes(sidecar.empty() ? path : sidecar, grid.transform, axes);
  }
  const std::int64_t voxels = checked_voxel_count(path, dims);
  const int esize = scalar_type_size(*type);
  const std::uint64_t bytes = checked_bytes(path, voxels, static_cast<std::uint64_t>(esize));
  std::uint64_t expected = 0;
  if (__builtin_add_overflow(bytes, static_cast<std::uint64_t>(offset), &expected) || expected != fsize)
    fail(path,
         fmt::format(
             "size mismatch: {} x {} x {} {} voxels after a {}-byte offset need {} bytes, the file has {}",
             dims[0], dims[1], dims[2], scalar_type_name(*type), offset, bytes + offset, fsize));
  grid.dims = dims;
  grid.source_type = *type;
  if (!sidecar.empty()) add_note(grid, "geometry from sidecar " + sidecar);
  layout.data_file = path;
  layout.offset = static_cast<std::uint64_t>(offset);
  layout.swap = (endian == "big") == host_is_little_endian();
  return layout;
}

ScalarGrid read_raw(const std::string& path, const VolumeReadOptions& opts) {
  RawLayout layout = raw_layout(path, opts);
  ScalarGrid& grid = layout.frame;
  check_memory(path, checked_bytes(path, grid.voxel_count(), 4), opts, "the float32 grid");
  allocate_values(grid);
  RegularFile in(path);
  in.seek(layout.offset);
  read_raw_values(path, in, grid.source_type, layout.swap, grid.values.data(), grid.values.size());
  return std::move(layout.frame);
}

void read_raw_box(const RegularFile& data, const RawLayout& layout, const std::array<std::int64_t, 3>& lo,
                  const std::array<std::int64_t, 3>& hi, float* dst) {
  const auto& d = layout.frame.dims;
  for (int a = 0; a < 3; ++a) MLFE_CHECK(0 <= lo[a] && lo[a] < hi[a] && hi[a] <= d[a]);
  const std::uint64_t esize = std::uint64_t(scalar_type_size(layout.frame.source_type));
  const std::size_t row = std::size_t(hi[0] - lo[0]);
  std::vector<char> buf(row * esize);
  float* const first = dst;
  for (std::int64_t k = lo[2]; k < hi[2]; ++k)
    for (std::int64_t j = lo[1]; j < hi[1]; ++j) {
      const std::uint64_t at = layout.offset + esize * std::uint64_t(lo[0] + d[0] * (j + d[1] * k));
      if (data.read_at(at, buf.data(), buf.size()) != buf.size())
        fail(data.path(), "truncated: the voxel data ended while reading a box (the file shrank?)");
      convert_to_float(buf.data(), layout.frame.source_type, layout.swap, dst, row);
      dst += row;
    }
  scale_values(data.path(), layout, first, std::size_t(dst - first));
}

std::uint64_t stored_bytes(const std::string& path, const RawLayout& layout) {
  return checked_bytes(path, layout.frame.voxel_count(),
                       std::uint64_t(scalar_type_size(layout.frame.source_type)));
}

void check_memory_for_copy(const std::string& path, const RawLayout& layout, const VolumeReadOptions& opts,
                           const std::string& what) {
  std::uint64_t need = 0;
  if (__builtin_add_overflow(stored_bytes(path, layout), checked_bytes(path, layout.frame.voxel_count(), 4),
                             &need))
    need = UINT64_MAX;
  check_memory(path, need, opts, what);
}

std::unique_ptr<RegularFile> unpack_raw(const std::string& path, const RawLayout& layout) {
  MLFE_CHECK(layout.packing.has_value());
  const std::uint64_t bytes = stored_bytes(path, layout);
  std::uint64_t total = 0;
  if (__builtin_add_overflow(bytes, layout.offset, &total)) fail(path, "the voxel data's size overflows");
  RegularFile in(layout.data_file);
  in.seek(layout.packed_at);
  const ByteSource decoded = decoded_source(path, *layout.packing, file_source(in));
  std::unique_ptr<RegularFile> out = RegularFile::scratch(path);
  std::vector<unsigned char> buf(std::size_t(1) << 20);
  for (std::uint64_t done = 0; done < total;) {
    const std::size_t got =
        decoded(buf.data(), std::size_t(std::min<std::uint64_t>(buf.size(), total - done)));
    if (got == 0) fail(path, fmt::format("truncated compressed data ({} of {} bytes)", done, total));
    out->append(buf.data(), got);
    done += got;
  }
  unsigned char extra = 0;
  if (layout.packed_exactly && decoded(&extra, 1) != 0)
    fail(path, fmt::format("compressed data does not inflate to the {} bytes of the dimensions", bytes));
  return out;
}

void scale_values(const std::string& path, const RawLayout& layout, float* v, std::size_t n) {
  if (!layout.scaling) return;
  const auto [slope, inter] = *layout.scaling;
  for (std::size_t i = 0; i < n; ++i) {
    const double scaled = v[i] * slope + inter;
    // Beyond float's range the value would become infinite and be reported as bad data.
    if (std::isfinite(v[i]) && !(std::abs(scaled) <= std::numeric_limits<float>::max()))
      fail(path, fmt::format("scl_slope {:.7g} and scl_inter {:.7g} take the value {:g} to {:.7g}, which "
                             "overflows a float (+-{:.4g})",
                             slope, inter, v[i], scaled, std::numeric_limits<float>::max()));
    v[i] = static_cast<float>(scaled);
  }
}

}  // namespace mlfe
