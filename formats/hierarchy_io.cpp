// .mlfeh reader and writer; the format is specified in hierarchy_io.h.
#include "formats/hierarchy_io.h"

#include <zlib.h>
#include <zstd.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <limits>

#include "core/error.h"
#include "formats/atomic_file.h"

namespace mlfe {

// The array sections are copied with memcpy; a big-endian host would need byte swapping.
static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "hierarchy_io assumes a little-endian host");

namespace {

constexpr char kMagic[8] = {'M', 'L', 'F', 'E', 'H', 'I', 'E', 'R'};
constexpr std::uint32_t kVersion = 1;
constexpr std::size_t kHeaderSize = 200;
constexpr std::uint32_t kFlagZstd = 1u, kFlagValues = 2u;
constexpr std::uint64_t kMaxSpace = 64;
constexpr std::uint64_t kMaxMetadata = 16u << 20;
// Caps the allocation a small compressed file can demand.
constexpr std::uint64_t kMaxRatio = 1024, kRatioSlack = 4096;

using Bytes = std::vector<std::uint8_t>;

void put_bytes(Bytes& out, const void* p, std::size_t n) {
  if (n == 0) return;
  const std::size_t at = out.size();
  out.resize(at + n);
  std::memcpy(out.data() + at, p, n);
}

template <class T>
void put(Bytes& out, const T& v) {
  put_bytes(out, &v, sizeof(T));
}

template <class T>
void put_array(Bytes& out, const std::vector<T>& v) {
  put_bytes(out, v.data(), v.size() * sizeof(T));
}

std::uint32_t crc32_of(const std::uint8_t* p, std::size_t n, std::uint32_t crc = 0) {
  uLong c = crc;
  while (n > 0) {
    const std::size_t chunk = std::min<std::size_t>(n, 1u << 30);
    c = ::crc32(c, p, static_cast<uInt>(chunk));
    p += chunk;
    n -= chunk;
  }
  return static_cast<std::uint32_t>(c);
}

// Raw size of the array section; counts are < 2^32, so this cannot overflow 64 bits.
std::uint64_t raw_section_size(int dim, std::uint64_t nv, std::uint64_t ne, bool values) {
  const std::uint64_t per_vertex = 8u * dim + 8 + 1 + (values ? 8 : 0);
  const std::uint64_t per_elem = 4u * (dim + 1) + 4 + 4 + 3;
  return nv * per_vertex + ne * per_elem;
}

bool printable(const std::string& s) {
  for (unsigned char c : s)
    if (c < 0x20 || c > 0x7e) return false;
  return true;
}

void check_info(const std::string& path, const HierarchyFileInfo& info) {
  for (int i = 0; i < 3; ++i)
    if (!std::isfinite(info.transform.spacing[i]) || !(info.transform.spacing[i] > 0) ||
        !std::isfinite(info.transform.origin[i]))
      throw Error(path + ": transform spacing must be positive and origin finite");
  for (double d : info.transform.direction)
    if (!std::isfinite(d)) throw Error(path + ": transform direction is not finite");
  if (!std::isfinite(info.value_min) || !std::isfinite(info.value_max) || info.value_min > info.value_max)
    throw Error(path + ": value range must be finite with min <= max");
  if (info.space.size() > kMaxSpace || !printable(info.space))
    throw Error(path + ": space must be at most 64 printable ASCII characters");
  if (!info.metadata.is_object()) throw Error(path + ": metadata must be a JSON object");
}

// Bounds-checked little-endian reader over a byte range.
class Cursor {
 public:
  Cursor(const std::string& path, const std::uint8_t* p, std::size_t n) : path_(path), p_(p), end_(p + n) {}
  template <class T>
  T get(const char* what) {
    T v;
    need(sizeof(T), what);
    std::memcpy(&v, p_, sizeof(T));
    p_ += sizeof(T);
    return v;
  }
  template <class T>
  std::vector<T> get_array(std::size_t count, const char* what) {
    need(count * sizeof(T), what);
    std::vector<T> v(count);
    if (count) std::memcpy(static_cast<void*>(v.data()), p_, count * sizeof(T));
    p_ += count * sizeof(T);
    return v;
  }
  std::size_t left() const { return static_cast<std::size_t>(end_ - p_); }

 private:
  void need(std::size_t n, const char* what) const {
    if (left() < n) throw Error(path_ + ": truncated " + what);
  }
  const std::string& path_;
  const std::uint8_t* p_;
  const std::uint8_t* end_;
};

template <int D>
Hierarchy<D> read_arrays(const std::string& path, Cursor& c, std::size_t nv, std::size_t ne, bool has_values,
                         std::vector<double>& values) {
  typename Hierarchy<D>::Arrays a;
  a.points = c.get_array<typename Hierarchy<D>::Point>(nv, "points");
  a.vertex_parents = c.get_array<std::array<VertexId, 2>>(nv, "vertex parents");
  a.vertex_level = c.get_array<std::uint8_t>(nv, "vertex levels");
  if (has_values) values = c.get_array<double>(nv, "values");
  a.cells = c.get_array<typename Hierarchy<D>::Cell>(ne, "cells");
  a.parent = c.get_array<ElemId>(ne, "parents");
  a.first_child = c.get_array<ElemId>(ne, "first children");
  a.num_children = c.get_array<std::uint8_t>(ne, "child counts");
  a.level = c.get_array<std::uint8_t>(ne, "levels");
  // Any byte is a valid ElemKind object (fixed underlying type); from_arrays rejects values > 2.
  a.kind = c.get_array<ElemKind>(ne, "kinds");
  return Hierarchy<D>::from_arrays(std::move(a), path + ": invalid hierarchy");
}

}  // namespace

template <int D>
void write_hierarchy(const std::string& path, const Hierarchy<D>& h, const std::vector<double>& values,
                     const HierarchyFileInfo& info, const HierarchyWriteOptions& options) {
  static_assert(sizeof(typename Hierarchy<D>::Point) == 8 * D && sizeof(typename Hierarchy<D>::Cell) == 4 * (D + 1) &&
                    sizeof(ElemId) == 4 && sizeof(ElemKind) == 1,
                "arrays are copied as raw bytes");
  check_info(path, info);
  const std::size_t nv = h.vertex_count(), ne = h.element_count();
  if (!values.empty() && values.size() != nv)
    throw Error(path + ": " + std::to_string(values.size()) + " values for " + std::to_string(nv) + " vertices");
  for (double v : values)
    if (std::isnan(v)) throw Error(path + ": values contain NaN");
  const bool has_values = !values.empty();

  Bytes raw;
  raw.reserve(raw_section_size(D, nv, ne, has_values));
  put_array(raw, h.points());
  put_array(raw, h.vertex_parents_array());
  put_array(raw, h.vertex_level_array());
  if (has_values) put_array(raw, values);
  put_array(raw, h.cells());
  put_array(raw, h.parent_array());
  put_array(raw, h.first_child_array());
  put_array(raw, h.num_children_array());
  put_array(raw, h.level_array());
  put_array(raw, h.kind_array());

  Bytes packed;
  if (options.compress) {
    packed.resize(ZSTD_compressBound(raw.size()));
    const std::size_t n = ZSTD_compress(packed.data(), packed.size(), raw.data(), raw.size(), options.zstd_level);
    if (ZSTD_isError(n)) throw Error(path + ": zstd compression failed (" + ZSTD_getErrorName(n) + ")");
    packed.resize(n);
    Bytes().swap(raw);
  }
  const Bytes& section = options.compress ? packed : raw;
  const std::string meta = info.metadata.empty() ? std::string() : info.metadata.dump();
  if (meta.size() > kMaxMetadata) throw Error(path + ": metadata larger than 16 MiB");

  Bytes head;
  head.reserve(kHeaderSize + info.space.size() + meta.size());
  put_bytes(head, kMagic, 8);
  put(head, kVersion);
  put(head, static_cast<std::uint32_t>(D));
  put(head, static_cast<std::uint64_t>(nv));
  put(head, static_cast<std::uint64_t>(ne));
  for (double x : info.transform.spacing) put(head, x);
  for (double x : info.transform.origin) put(head, x);
  for (double x : info.transform.direction) put(head, x);
  put(head, info.value_min);
  put(head, info.value_max);
  put(head, static_cast<std::uint32_t>((options.compress ? kFlagZstd : 0u) | (has_values ? kFlagValues : 0u)));
  put(head, static_cast<std::uint32_t>(info.space.size()));
  put(head, static_cast<std::uint64_t>(meta.size()));
  put(head, static_cast<std::uint64_t>(section.size()));
  put(head, raw_section_size(D, nv, ne, has_values));
  put_bytes(head, info.space.data(), info.space.size());
  put_bytes(head, meta.data(), meta.size());
  std::uint32_t crc = crc32_of(head.data(), head.size());
  crc = crc32_of(section.data(), section.size(), crc);

  write_file_atomically(path, [&](std::ostream& out) {
    out.write(reinterpret_cast<const char*>(head.data()), static_cast<std::streamsize>(head.size()));
    out.write(reinterpret_cast<const char*>(section.data()), static_cast<std::streamsize>(section.size()));
    out.write(reinterpret_cast<const char*>(&crc), 4);
  });
}

void write_hierarchy(const std::string& path, const HierarchyFile& file, const HierarchyWriteOptions& options) {
  if (file.dim == 2 && std::holds_alternative<Hierarchy<2>>(file.hierarchy))
    write_hierarchy<2>(path, std::get<Hierarchy<2>>(file.hierarchy), file.values, file, options);
  else if (file.dim == 3 && std::holds_alternative<Hierarchy<3>>(file.hierarchy))
    write_hierarchy<3>(path, std::get<Hierarchy<3>>(file.hierarchy), file.values, file, options);
  else
    throw Error(path + ": HierarchyFile::dim does not match the hierarchy it holds");
}

HierarchyFile read_hierarchy(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(path + ": cannot open file");
  in.seekg(0, std::ios::end);
  const std::streamoff file_size_signed = in.tellg();
  if (file_size_signed < 0) throw Error(path + ": cannot determine the file size");
  const auto file_size = static_cast<std::uint64_t>(file_size_signed);
  in.seekg(0);

  std::uint8_t head[kHeaderSize];
  const std::size_t head_n = static_cast<std::size_t>(std::min<std::uint64_t>(file_size, kHeaderSize));
  in.read(reinterpret_cast<char*>(head), static_cast<std::streamsize>(head_n));
  if (!in) throw Error(path + ": read error");
  if (head_n < 8 || std::memcmp(head, kMagic, 8) != 0)
    throw Error(path + ": not an mlfe hierarchy file (bad magic)");
  Cursor h(path, head, head_n);
  h.get<std::uint64_t>("magic");
  const auto version = h.get<std::uint32_t>("header");
  if (version != kVersion)
    throw Error(path + ": unsupported hierarchy file version " + std::to_string(version) + " (this mlfe reads " +
                std::to_string(kVersion) + ")");
  if (head_n < kHeaderSize) throw Error(path + ": truncated header");

  HierarchyFile f;
  const auto dim = h.get<std::uint32_t>("header");
  const auto nv = h.get<std::uint64_t>("header");
  const auto ne = h.get<std::uint64_t>("header");
  for (double& x : f.transform.spacing) x = h.get<double>("header");
  for (double& x : f.transform.origin) x = h.get<double>("header");
  for (double& x : f.transform.direction) x = h.get<double>("header");
  f.value_min = h.get<double>("header");
  f.value_max = h.get<double>("header");
  const auto flags = h.get<std::uint32_t>("header");
  const auto ls = h.get<std::uint32_t>("header");
  const auto lm = h.get<std::uint64_t>("header");
  const auto ss = h.get<std::uint64_t>("header");
  const auto rs = h.get<std::uint64_t>("header");

  if (dim != 2 && dim != 3) throw Error(path + ": dimension " + std::to_string(dim) + " is not 2 or 3");
  if (nv >= VertexId::kInvalidValue) throw Error(path + ": vertex count " + std::to_string(nv) + " too large");
  if (ne == 0 || ne >= ElemId::kInvalidValue)
    throw Error(path + ": element count " + std::to_string(ne) + " out of range");
  if (flags & ~(kFlagZstd | kFlagValues)) throw Error(path + ": unknown flags " + std::to_string(flags));
  if (ls > kMaxSpace) throw Error(path + ": space string longer than 64 bytes");
  if (lm > kMaxMetadata) throw Error(path + ": metadata longer than 16 MiB");
  const bool zstd = flags & kFlagZstd, has_values = flags & kFlagValues;
  const std::uint64_t expect_raw = raw_section_size(static_cast<int>(dim), nv, ne, has_values);
  if (rs != expect_raw)
    throw Error(path + ": array section size " + std::to_string(rs) + " does not match the counts (" +
                std::to_string(expect_raw) + ")");
  if (!zstd && ss != rs) throw Error(path + ": stored size differs from the array size of an uncompressed file");
  // ls, lm are bounded above; ss is compared against the real file size before it is used, and
  // written so that the sum cannot overflow.
  const std::uint64_t fixed = kHeaderSize + ls + lm + 4;
  if (file_size < fixed || ss != file_size - fixed)
    throw Error(path + ": file size " + std::to_string(file_size) + " does not match the header (expected " +
                (ss <= std::numeric_limits<std::uint64_t>::max() - fixed ? std::to_string(fixed + ss) : "overflow") +
                "; truncated?)");
  if (zstd && rs > kMaxRatio * ss + kRatioSlack) throw Error(path + ": implausible compression ratio");

  // Sizes are consistent with the file: reading the rest allocates at most the file size.
  Bytes rest(static_cast<std::size_t>(file_size - kHeaderSize));
  in.read(reinterpret_cast<char*>(rest.data()), static_cast<std::streamsize>(rest.size()));
  if (!in) throw Error(path + ": read error");
  std::uint32_t stored_crc;
  std::memcpy(&stored_crc, rest.data() + rest.size() - 4, 4);
  const std::uint32_t crc = crc32_of(rest.data(), rest.size() - 4, crc32_of(head, kHeaderSize));
  if (crc != stored_crc) throw Error(path + ": checksum mismatch (file corrupted)");

  f.space.assign(reinterpret_cast<const char*>(rest.data()), ls);
  if (!printable(f.space)) throw Error(path + ": space string is not printable ASCII");
  if (lm > 0) {
    const std::string meta(reinterpret_cast<const char*>(rest.data()) + ls, lm);
    f.metadata = nlohmann::json::parse(meta, nullptr, /*allow_exceptions=*/false);
    if (!f.metadata.is_object()) throw Error(path + ": metadata is not a JSON object");
  }
  check_info(path, f);

  const std::uint8_t* section = rest.data() + ls + lm;
  Bytes unpacked;
  if (zstd) {
    const unsigned long long content = ZSTD_getFrameContentSize(section, ss);
    if (content != rs) throw Error(path + ": compressed array section has the wrong size");
    unpacked.resize(static_cast<std::size_t>(rs));
    const std::size_t n = ZSTD_decompress(unpacked.data(), unpacked.size(), section, ss);
    if (ZSTD_isError(n) || n != rs) throw Error(path + ": corrupt compressed array section");
    Bytes().swap(rest);
    section = unpacked.data();
  }
  Cursor c(path, section, static_cast<std::size_t>(rs));
  f.dim = static_cast<int>(dim);
  if (dim == 2)
    f.hierarchy = read_arrays<2>(path, c, nv, ne, has_values, f.values);
  else
    f.hierarchy = read_arrays<3>(path, c, nv, ne, has_values, f.values);
  for (std::size_t i = 0; i < f.values.size(); ++i)
    if (std::isnan(f.values[i])) throw Error(path + ": value of vertex " + std::to_string(i) + " is NaN");
  return f;
}

template void write_hierarchy<2>(const std::string&, const Hierarchy<2>&, const std::vector<double>&,
                                 const HierarchyFileInfo&, const HierarchyWriteOptions&);
template void write_hierarchy<3>(const std::string&, const Hierarchy<3>&, const std::vector<double>&,
                                 const HierarchyFileInfo&, const HierarchyWriteOptions&);

bool is_hierarchy_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  char magic[8] = {};
  in.read(magic, 8);
  return in.gcount() == 8 && std::memcmp(magic, kMagic, 8) == 0;
}

}  // namespace mlfe
