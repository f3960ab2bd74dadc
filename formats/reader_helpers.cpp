// The helpers every reader shares (formats/reader_helpers.h) and the default memory limit
// (<mlfe/formats/volume_read_options.h>).
#include "formats/reader_helpers.h"

#include <fmt/format.h>
#include <mlfe/core/base/vec.h>
#include <sys/stat.h>

#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>

namespace mlfe {

std::size_t default_memory_limit() {
  std::ifstream in("/proc/meminfo");
  std::string key;
  std::uint64_t kb = 0;
  std::string unit;
  while (in >> key >> kb >> unit) {
    if (key == "MemAvailable:") return static_cast<std::size_t>(kb * 1024);
  }
  return std::size_t(16) << 30;
}

std::optional<ScalarType> parse_scalar_type(const std::string& name) {
  std::string n;
  for (char c : name) n += static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (n == "uint8" || n == "u8" || n == "uchar" || n == "unsigned char") return ScalarType::U8;
  if (n == "int8" || n == "i8" || n == "char" || n == "signed char") return ScalarType::I8;
  if (n == "uint16" || n == "u16" || n == "ushort") return ScalarType::U16;
  if (n == "int16" || n == "i16" || n == "short") return ScalarType::I16;
  if (n == "uint32" || n == "u32" || n == "uint") return ScalarType::U32;
  if (n == "int32" || n == "i32" || n == "int") return ScalarType::I32;
  if (n == "float32" || n == "f32" || n == "float") return ScalarType::F32;
  if (n == "float64" || n == "f64" || n == "double") return ScalarType::F64;
  return std::nullopt;
}

namespace volume_detail {

void fail(const std::string& path, const std::string& problem) {
  // Library messages may span lines or quote garbage read from a corrupt file (OpenVDB quotes
  // whole strings); the contract is one short line.
  constexpr std::size_t kMaxLength = 400;
  std::string one;
  for (char c : problem) {
    const unsigned char u = static_cast<unsigned char>(c);
    if (c == '\n' || c == '\r') {
      if (!one.empty() && one.back() != ' ') one += "; ";
    } else if (u < 0x20 || u == 0x7f) {
      if (!one.empty() && one.back() != ' ') one += ' ';
    } else if (c == ' ' && !one.empty() && one.back() == ' ') {
      continue;
    } else {
      one += c;
    }
    if (one.size() > kMaxLength) {
      one += "...";
      break;
    }
  }
  while (!one.empty() && (one.back() == ' ' || one.back() == ';')) one.pop_back();
  throw Error(path + ": " + one);
}

bool host_is_little_endian() {
  const std::uint16_t one = 1;
  unsigned char b;
  std::memcpy(&b, &one, 1);
  return b == 1;
}

std::int64_t checked_voxel_count(const std::string& path, const std::array<std::int64_t, 3>& dims) {
  constexpr std::int64_t kMaxDim = std::numeric_limits<std::int32_t>::max();
  for (int a = 0; a < 3; ++a) {
    if (dims[a] < 1 || dims[a] > kMaxDim)
      fail(path, fmt::format("invalid dimensions {} x {} x {} (each must be 1..{})", dims[0], dims[1],
                             dims[2], kMaxDim));
  }
  std::int64_t n = 0;
  // 2^60 voxels of 8 bytes still fit a signed 64-bit byte count.
  constexpr std::int64_t kMaxVoxels = std::int64_t(1) << 59;
  if (__builtin_mul_overflow(dims[0], dims[1], &n) || __builtin_mul_overflow(n, dims[2], &n) ||
      n > kMaxVoxels)
    fail(path, fmt::format("dimensions {} x {} x {} are too large", dims[0], dims[1], dims[2]));
  return n;
}

std::uint64_t checked_bytes(const std::string& path, std::int64_t voxels, std::uint64_t element_size) {
  std::uint64_t b = 0;
  if (voxels < 0 || __builtin_mul_overflow(static_cast<std::uint64_t>(voxels), element_size, &b))
    fail(path, fmt::format("{} voxels of {} bytes overflow a 64-bit size", voxels, element_size));
  return b;
}

std::uint64_t memory_limit(const VolumeReadOptions& opts) {
  return opts.max_bytes ? opts.max_bytes : default_memory_limit();
}

void check_memory(const std::string& path, std::uint64_t bytes, std::uint64_t limit,
                  const std::string& what) {
  if (bytes > limit)
    fail(path,
         fmt::format("needs {} bytes for {} but only {} bytes of memory are available", bytes, what, limit));
}

void check_memory(const std::string& path, std::uint64_t bytes, const VolumeReadOptions& opts,
                  const std::string& what) {
  check_memory(path, bytes, memory_limit(opts), what);
}

namespace {
template <typename T>
void convert_typed(const unsigned char* src, bool swap, float* dst, std::size_t n) {
  unsigned char tmp[sizeof(T)];
  for (std::size_t i = 0; i < n; ++i) {
    const unsigned char* p = src + i * sizeof(T);
    if (swap) {
      for (std::size_t b = 0; b < sizeof(T); ++b) tmp[b] = p[sizeof(T) - 1 - b];
      p = tmp;
    }
    T v;
    std::memcpy(&v, p, sizeof(T));
    dst[i] = static_cast<float>(v);
  }
}
}  // namespace

void convert_to_float(const void* src, ScalarType t, bool swap, float* dst, std::size_t n) {
  auto s = static_cast<const unsigned char*>(src);
  switch (t) {
    case ScalarType::U8:
      convert_typed<std::uint8_t>(s, false, dst, n);
      break;
    case ScalarType::I8:
      convert_typed<std::int8_t>(s, false, dst, n);
      break;
    case ScalarType::U16:
      convert_typed<std::uint16_t>(s, swap, dst, n);
      break;
    case ScalarType::I16:
      convert_typed<std::int16_t>(s, swap, dst, n);
      break;
    case ScalarType::U32:
      convert_typed<std::uint32_t>(s, swap, dst, n);
      break;
    case ScalarType::I32:
      convert_typed<std::int32_t>(s, swap, dst, n);
      break;
    case ScalarType::F32:
      convert_typed<float>(s, swap, dst, n);
      break;
    case ScalarType::F64:
      convert_typed<double>(s, swap, dst, n);
      break;
  }
}

void set_axes(const std::string& path, GridTransform& t, const std::array<std::array<double, 3>, 3>& axes) {
  for (int a = 0; a < 3; ++a) {
    const auto& v = axes[a];
    const double len = norm(v);
    if (!std::isfinite(len) || len <= 0.0)
      fail(path,
           fmt::format("axis {} has a zero or non-finite physical step ({}, {}, {})", a, v[0], v[1], v[2]));
    t.spacing[a] = len;
    for (int r = 0; r < 3; ++r) t.direction[r * 3 + a] = v[r] / len;
  }
}

void allocate_values(ScalarGrid& grid) {
  grid.values.assign(static_cast<std::size_t>(grid.voxel_count()), 0.0f);
}

void add_note(ScalarGrid& grid, const std::string& note) {
  if (!grid.notes.empty()) grid.notes += '\n';
  grid.notes += note;
}

std::string sibling_path(const std::string& base, const std::string& name) {
  if (!name.empty() && name[0] == '/') return name;
  auto slash = base.find_last_of('/');
  return slash == std::string::npos ? name : base.substr(0, slash + 1) + name;
}

}  // namespace volume_detail

}  // namespace mlfe
