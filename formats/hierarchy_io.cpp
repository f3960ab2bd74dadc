// .mlfeh reader and writer; the format is specified in hierarchy_io.h.
#include <mlfe/core/base/check.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/base/huge_pages.h>
#include <mlfe/formats/atomic_file.h>
#include <mlfe/formats/hierarchy_io.h>
#include <mlfe/formats/hierarchy_levels.h>
#include <mlfe/formats/safe_read.h>
#include <zlib.h>
#include <zstd.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <limits>
#include <optional>

#include "lattice_values.h"

namespace mlfe {

// The array sections are copied with memcpy; a big-endian host would need byte swapping.
static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "hierarchy_io assumes a little-endian host");

namespace {

constexpr char kMagic[8] = {'M', 'L', 'F', 'E', 'H', 'I', 'E', 'R'};
constexpr std::uint32_t kVersion = 1, kVersion2 = 2, kVersion3 = 3, kVersion4 = 4;
constexpr std::size_t kHeaderSize = 200;
constexpr std::uint32_t kFlagZstd = 1u, kFlagValues = 2u;
constexpr std::uint64_t kMaxSpace = 64;
constexpr int kMaxLatticeLevel = 24;  // sample_lattice(): at most 2^24 samples per axis
constexpr std::uint64_t kMaxMetadata = 16u << 20;
// Caps the allocation a small compressed file can demand.
constexpr std::uint64_t kMaxRatio = 1024, kRatioSlack = 4096;
// v2 sections: zstd's own limit (a 4-byte RLE block per 128 KiB block), since a level whose
// marks are all set and whose surpluses all round to 0 compresses far beyond 1024:1.
constexpr std::uint64_t kMaxSectionRatio = 32768;
// Elements or vertices per file byte the reader reserves for at most before the counts are
// verified (measured files hold about 11 elements per byte).
constexpr std::uint64_t kMaxReserveFactor = 256;
// v4: at most this many elements per file byte (plus the slack) in a file's HEAD.
constexpr std::uint64_t kMaxElementsPerByte = 4096, kElementSlack = 1u << 20;

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
  check_frame(path, info.transform.direction);
  if (!std::isfinite(info.value_min) || !std::isfinite(info.value_max) || info.value_min > info.value_max)
    throw Error(path + ": value range must be finite with min <= max");
  if (info.space.size() > kMaxSpace || !printable(info.space))
    throw Error(path + ": space must be at most 64 printable ASCII characters");
  if (!info.metadata.is_object()) throw Error(path + ": metadata must be a JSON object");
}

// The lattice fields of a v3 file (core/fem/sample_lattice.h): dims ≥ 2 on the used axes, 1 on the
// others, and L the smallest level with 2^L ≥ n − 1 on every axis.
void check_lattice(const std::string& path, int dim, const HierarchyFileInfo& info) {
  if (!std::isnan(info.sample_error_bound) &&
      !(info.sample_error_bound >= 0 && std::isfinite(info.sample_error_bound)))
    throw Error(path + ": sample error bound out of range");
  if (!info.on_lattice) return;
  std::int64_t longest = 1;
  for (int a = 0; a < 3; ++a) {
    const std::int64_t n = info.data_dims[a];
    if (a < dim ? (n < 2 || n > (std::int64_t(1) << kMaxLatticeLevel)) : n != 1)
      throw Error(path + ": lattice dims out of range (axis " + std::to_string(a) + ")");
    longest = std::max(longest, n - 1);
  }
  const int level = info.lattice_level;
  if (level < 0 || level > kMaxLatticeLevel || (std::int64_t(1) << level) < longest ||
      (level > 0 && (std::int64_t(1) << (level - 1)) >= longest))
    throw Error(path + ": lattice level " + std::to_string(level) + " does not fit the dims");
}

// T0 of a lattice file covers the cube [0, 2^L·spacing] on every axis.
template <int D>
void check_lattice_box(const std::string& path, const Hierarchy<D>& h, const HierarchyFileInfo& info) {
  if (!info.on_lattice) return;
  for (int a = 0; a < D; ++a) {
    double lo = std::numeric_limits<double>::infinity(), hi = -lo;
    for (std::uint32_t v = 0; v < h.vertex_count(); ++v)
      if (!h.vertex_parents(VertexId(v))[0].valid())
        lo = std::min(lo, h.point(VertexId(v))[a]), hi = std::max(hi, h.point(VertexId(v))[a]);
    const double w = std::ldexp(info.transform.spacing[a], info.lattice_level);
    if (!(std::fabs(lo) <= 1e-9 * w && std::fabs(hi - w) <= 1e-9 * w))
      throw Error(path + ": T0 is not the lattice's cube (axis " + std::to_string(a) + ")");
  }
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

// ---- version 2 (docs/mlfeh-v2.md) ----

constexpr std::uint32_t tag_of(const char (&s)[5]) {
  return std::uint32_t(std::uint8_t(s[0])) | std::uint32_t(std::uint8_t(s[1])) << 8 |
         std::uint32_t(std::uint8_t(s[2])) << 16 | std::uint32_t(std::uint8_t(s[3])) << 24;
}
constexpr std::uint32_t kTagHead = tag_of("HEAD"), kTagMesh = tag_of("MESH"), kTagLevel = tag_of("LEVL");
constexpr std::uint32_t kCodecRaw = 0, kCodecZstd = 1;
constexpr std::uint32_t kCodingNone = 0, kCodingQuantized = 1, kCodingExact = 2, kCodingInteger = 3;
constexpr std::size_t kPreambleSize = 16, kSectionHeaderSize = 28, kHeadFixedSize = 204;
constexpr int kMaxLevels = 60;

std::uint32_t norm_code(const std::string& norm) { return norm == "l2" ? 1 : norm == "h1" ? 2 : 0; }

template <int D>
typename PredictedValues<D>::Coding predicted_coding(const HierarchyFileInfo& info, double bound,
                                                     bool integer) {
  typename PredictedValues<D>::Coding c;
  c.integer = integer;
  c.bound = bound;
  c.on_lattice = info.on_lattice;
  c.lattice_level = info.lattice_level;
  c.spacing = info.transform.spacing;
  return c;
}

// Integer coding (v3): a vertex's code goes to the stream of its context, the bit width of
// |d_a − d_b| of its decoded parents (capped; 0 for T0): large surpluses come where the parents
// differ, so each stream holds codes of one magnitude and zstd's entropy stage codes them
// with their own statistics (−9 % on the brain MRI's lossless file, bench/RESULTS.md).
constexpr int kContexts = 7;
template <int D>
int integer_context(const Hierarchy<D>& h, const std::vector<double>& d, std::size_t v) {
  const auto& p = h.vertex_parents(VertexId(static_cast<std::uint32_t>(v)));
  if (!p[0].valid()) return 0;
  auto diff = static_cast<std::uint64_t>(
      std::llabs(static_cast<std::int64_t>(d[p[0].value]) - static_cast<std::int64_t>(d[p[1].value])));
  int c = 0;
  while (diff != 0 && c < kContexts - 1) diff >>= 1, ++c;
  return c;
}

void put_varint(Bytes& out, std::int64_t q) {
  std::uint64_t z = (static_cast<std::uint64_t>(q) << 1) ^ static_cast<std::uint64_t>(q >> 63);  // zigzag
  while (z >= 0x80) {
    out.push_back(static_cast<std::uint8_t>(z | 0x80));
    z >>= 7;
  }
  out.push_back(static_cast<std::uint8_t>(z));
}

// v4 level sections: form 0 holds range-coded marks and values (docs/mlfeh-v4.md), form 1 the
// marks and values as v3 stores them, form 2 form 0's layout with the values quantized against
// the chosen prediction.
constexpr std::uint32_t kFormCoded = 0, kFormPacked = 1, kFormResidual = 2;

// The v4 value streams of every step (T0 first) and the decoded values in d: levels quantized
// against the chosen prediction with `residual`, T0 always against 0 (it has no prediction).
template <int D>
std::vector<Bytes> predicted_streams(const Hierarchy<D>& h, const std::vector<std::size_t>& vertex_end,
                                     const std::vector<double>& u, const HierarchyFileInfo& info,
                                     const HierarchyWriteOptions& options, bool residual,
                                     std::vector<double>& d) {
  PredictedValues<D> pv(predicted_coding<D>(info, options.max_error, options.integer_values));
  d.assign(u.size(), 0.0);
  std::vector<Bytes> streams;
  for (std::size_t k = 0; k < vertex_end.size(); ++k)
    streams.push_back(pv.encode(h, static_cast<int>(k), k == 0 ? 0 : vertex_end[k - 1], vertex_end[k], u, d,
                                residual && k > 0));
  return streams;
}

// Whether the writer stores the levels in form 2 (options.residual_quantization where it
// applies: a v4 file of coding 1 or 3 with a bound).
bool residual_levels(const HierarchyWriteOptions& options, bool predicted) {
  return options.residual_quantization && predicted && options.max_error > 0;
}

// The marks of a level as bits, least significant first (v2, v3, v4 form 1).
void put_mark_bits(Bytes& out, const std::vector<std::uint8_t>& marks) {
  Bytes bits((marks.size() + 7) / 8, 0);
  for (std::size_t i = 0; i < marks.size(); ++i)
    if (marks[i]) bits[i / 8] |= static_cast<std::uint8_t>(1u << (i % 8));
  put_array(out, bits);
}

// Appends one section (header + payload) to `file`.
// The HEAD section's CRC starts from the preamble's (crc_seed), so the version and dimension
// are covered too.
void put_section(const std::string& path, Bytes& file, std::uint32_t tag, const Bytes& raw, bool compress,
                 int level, std::uint32_t crc_seed = 0) {
  Bytes packed;
  if (compress) {
    packed.resize(ZSTD_compressBound(raw.size()));
    const std::size_t n = ZSTD_compress(packed.data(), packed.size(), raw.data(), raw.size(), level);
    if (ZSTD_isError(n)) throw Error(path + ": zstd compression failed (" + ZSTD_getErrorName(n) + ")");
    packed.resize(n);
  }
  const Bytes& payload = compress ? packed : raw;
  const std::size_t at = file.size();
  put(file, tag);
  put(file, compress ? kCodecZstd : kCodecRaw);
  put(file, static_cast<std::uint64_t>(payload.size()));
  put(file, static_cast<std::uint64_t>(raw.size()));
  const std::uint32_t crc =
      crc32_of(payload.data(), payload.size(), crc32_of(file.data() + at, 24, crc_seed));
  put(file, crc);
  put_bytes(file, payload.data(), payload.size());
}

// The metadata as written (compact JSON; empty for none), checked against the format's limit.
std::string metadata_text(const std::string& path, const HierarchyFileInfo& info) {
  std::string meta = info.metadata.empty() ? std::string() : info.metadata.dump();
  if (meta.size() > kMaxMetadata) throw Error(path + ": metadata larger than 16 MiB");
  return meta;
}

// The checks of either write_hierarchy before anything is encoded; returns the metadata text.
template <int D>
std::string check_write(const std::string& path, const Hierarchy<D>& h, const std::vector<double>& values,
                        const HierarchyFileInfo& info, const HierarchyWriteOptions& options) {
  static_assert(sizeof(typename Hierarchy<D>::Point) == 8 * D &&
                    sizeof(typename Hierarchy<D>::Cell) == 4 * (D + 1) && sizeof(ElemId) == 4 &&
                    sizeof(ElemKind) == 1,
                "arrays are copied as raw bytes");
  check_info(path, info);
  check_lattice(path, D, info);
  check_lattice_box(path, h, info);
  if (options.version == 1 && (info.on_lattice || !std::isnan(info.sample_error_bound)))
    throw Error(path + ": the samples' lattice and a sample error bound need format version 3");
  if (options.version == 1 && options.integer_values)
    throw Error(path + ": integer values need format version 3");
  if (options.version < 1 || options.version > 4)
    throw Error(path + ": cannot write hierarchy file version " + std::to_string(options.version));
  if (!values.empty() && values.size() != h.vertex_count())
    throw Error(path + ": " + std::to_string(values.size()) + " values for " +
                std::to_string(h.vertex_count()) + " vertices");
  if (options.version == 1) {
    for (double v : values)
      if (std::isnan(v)) throw Error(path + ": values contain NaN");
    return metadata_text(path, info);
  }
  for (double v : values)
    if (!std::isfinite(v)) throw Error(path + ": values must be finite");
  if (!(options.max_error >= 0) || !std::isfinite(options.max_error))
    throw Error(path + ": max error must be finite and >= 0");
  if (h.max_level() > kMaxLevels) throw Error(path + ": more than 60 levels");
  const bool v3 = options.version >= 3;
  if (options.integer_values &&
      (!v3 || options.max_error != std::floor(options.max_error) || options.max_error >= 2147483648.0))
    throw Error(path + ": integer values need format version 3 and an integer bound below 2^31");
  if (!v3 && (info.on_lattice || !std::isnan(info.sample_error_bound)))
    throw Error(path + ": the samples' lattice and a sample error bound need format version 3");
  return metadata_text(path, info);
}

// h is in the canonical numbering `enc` describes; values (u) in its vertex order; meta from
// check_write.
template <int D>
void write_v2(const std::string& path, const Hierarchy<D>& h, const LevelDescription<D>& enc,
              const std::vector<double>& u, const HierarchyFileInfo& info, const std::string& meta,
              const HierarchyWriteOptions& options) {
  const bool v3 = options.version >= 3, v4 = options.version == 4;

  MLFE_CHECK(!enc.vertex_end.empty() && enc.vertex_end.back() == h.vertex_count() &&
             enc.coarse_cells.size() == h.coarse_count() && enc.marks.size() + 1 == enc.vertex_end.size());
  // Step 1: the values quantized in the canonical vertex order.
  const std::uint32_t coding = u.empty()                ? kCodingNone
                               : options.integer_values ? kCodingInteger
                               : options.max_error > 0  ? kCodingQuantized
                                                        : kCodingExact;
  std::vector<std::int64_t> codes;
  std::vector<double> decoded;  // integer coding: the contexts come from the decoded parents
  // v4: coding 1 and 3 also predicted on the lattice and range coded, one stream per step (the
  // same codes and decoded values).
  const bool predicted = v4 && (coding == kCodingQuantized || coding == kCodingInteger);
  const bool residual = residual_levels(options, predicted);
  std::vector<Bytes> streams;
  try {
    // Form 2 has no v3 form to fall back to (its decoded values are not v3's).
    if (coding == kCodingQuantized && !residual) quantize_hierarchical(h, u, options.max_error, &codes);
    if (coding == kCodingInteger && !residual)
      decoded = quantize_integer(h, u, static_cast<std::int64_t>(options.max_error), &codes);
    std::vector<double> d;
    if (predicted) streams = predicted_streams(h, enc.vertex_end, u, info, options, residual, d);
  } catch (const Error& e) {
    throw Error(path + ": " + e.what());
  }
  const auto put_values = [&](Bytes& out, std::size_t from, std::size_t to) {
    if (coding == kCodingInteger) {
      std::array<Bytes, kContexts> streams;
      for (std::size_t v = from; v < to; ++v) put_varint(streams[integer_context(h, decoded, v)], codes[v]);
      for (const Bytes& b : streams) put(out, static_cast<std::uint32_t>(b.size()));
      for (const Bytes& b : streams) put_array(out, b);
      return;
    }
    for (std::size_t v = from; v < to; ++v) {
      if (coding == kCodingQuantized || coding == kCodingInteger) put_varint(out, codes[v]);
      if (coding == kCodingExact) put(out, u[v]);
    }
  };

  Bytes file;
  put_bytes(file, kMagic, 8);
  put(file, v4 ? kVersion4 : v3 ? kVersion3 : kVersion2);
  put(file, static_cast<std::uint32_t>(D));

  // Step 2: HEAD.
  Bytes head;
  put(head, static_cast<std::uint64_t>(h.vertex_count()));
  put(head, static_cast<std::uint64_t>(h.element_count()));
  put(head, static_cast<std::uint32_t>(h.max_level()));
  put(head, coding);
  put(head, coding == kCodingQuantized || coding == kCodingInteger ? options.max_error : 0.0);
  for (double x : info.transform.spacing) put(head, x);
  for (double x : info.transform.origin) put(head, x);
  for (double x : info.transform.direction) put(head, x);
  put(head, info.value_min);
  put(head, info.value_max);
  put(head, info.rms_error);
  put(head, info.max_error);
  put(head, info.psnr_db);
  put(head, norm_code(info.norm));
  if (v3) {
    put(head, static_cast<std::uint32_t>(info.on_lattice ? 1 : 0));
    put(head, static_cast<std::uint32_t>(info.on_lattice ? info.lattice_level : 0));
    for (std::int64_t n : info.on_lattice ? info.data_dims : std::array<std::int64_t, 3>{1, 1, 1})
      put(head, static_cast<std::uint64_t>(n));
    put(head, info.sample_error_bound);
  }
  put(head, static_cast<std::uint32_t>(info.space.size()));
  put(head, static_cast<std::uint32_t>(meta.size()));
  put_bytes(head, info.space.data(), info.space.size());
  put_bytes(head, meta.data(), meta.size());
  put_section(path, file, kTagHead, head, false, 0, crc32_of(file.data(), kPreambleSize));

  // Step 3: MESH (T0 and its values).
  Bytes mesh;
  put(mesh, static_cast<std::uint32_t>(enc.coarse_points.size()));
  put(mesh, static_cast<std::uint32_t>(enc.coarse_cells.size()));
  put_array(mesh, enc.coarse_points);
  put_array(mesh, enc.coarse_cells);
  if (predicted)
    put_array(mesh, streams[0]);
  else
    put_values(mesh, 0, enc.vertex_end[0]);
  put_section(path, file, kTagMesh, mesh, options.compress, options.zstd_level);

  // Step 4: one LEVL per refinement step.
  for (std::size_t k = 1; k < enc.vertex_end.size(); ++k) {
    const auto& marks = enc.marks[k - 1];
    Bytes level;
    put(level, static_cast<std::uint32_t>(k));
    put(level, static_cast<std::uint32_t>(marks.size()));
    put(level, static_cast<std::uint32_t>(enc.vertex_end[k] - enc.vertex_end[k - 1]));
    Bytes coded = level;  // v4 form 0 or 2: range-coded marks and values, stored raw
    Bytes packed;
    if (!residual) {
      if (v4) put(level, kFormPacked);
      put_mark_bits(level, marks);
      put_values(level, enc.vertex_end[k - 1], enc.vertex_end[k]);
      put_section(path, packed, kTagLevel, level, options.compress, options.zstd_level);
    }
    if (predicted) {
      // The smaller form: range coding wins on scans, zstd on label maps' repeated patterns.
      put(coded, residual ? kFormResidual : kFormCoded);
      const Bytes marks_stream = encode_marks(marks);
      put(coded, static_cast<std::uint32_t>(marks_stream.size()));
      put_array(coded, marks_stream);
      put_array(coded, streams[k]);
      Bytes section;
      put_section(path, section, kTagLevel, coded, false, 0);
      if (residual || section.size() < packed.size()) packed.swap(section);
    }
    put_array(file, packed);
  }
  write_file_atomically(path, [&](std::ostream& out) {
    out.write(reinterpret_cast<const char*>(file.data()), static_cast<std::streamsize>(file.size()));
  });
}
}  // namespace

template <int D>
void write_hierarchy(const std::string& path, const Hierarchy<D>& h, const std::vector<double>& values,
                     const HierarchyFileInfo& info, const HierarchyWriteOptions& options) {
  const std::string meta = check_write(path, h, values, info, options);
  if (options.version >= 2) {
    LevelEncoding<D> enc;
    try {
      enc = encode_levels(h);
    } catch (const LevelRebuildError& e) {
      throw LevelRebuildError(path + ": " + e.what());
    }
    std::vector<double> u(values.empty() ? 0 : h.vertex_count());
    for (std::size_t v = 0; v < u.size(); ++v) u[v] = values[enc.to_original[v].value];
    write_v2(path, enc.rebuilt, enc, u, info, meta, options);
    return;
  }
  const std::size_t nv = h.vertex_count(), ne = h.element_count();
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
    const std::size_t n =
        ZSTD_compress(packed.data(), packed.size(), raw.data(), raw.size(), options.zstd_level);
    if (ZSTD_isError(n)) throw Error(path + ": zstd compression failed (" + ZSTD_getErrorName(n) + ")");
    packed.resize(n);
    Bytes().swap(raw);
  }
  const Bytes& section = options.compress ? packed : raw;

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
  put(head,
      static_cast<std::uint32_t>((options.compress ? kFlagZstd : 0u) | (has_values ? kFlagValues : 0u)));
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

template <int D>
void write_hierarchy(const std::string& path, const Hierarchy<D>& h, const LevelDescription<D>& levels,
                     const std::vector<double>& values, const HierarchyFileInfo& info,
                     const HierarchyWriteOptions& options) {
  const std::string meta = check_write(path, h, values, info, options);
  MLFE_CHECK(options.version >= 2);
  write_v2(path, h, levels, values, info, meta, options);
}

template <int D>
std::vector<double> residual_quantized_values(const Hierarchy<D>& h, const LevelDescription<D>& levels,
                                              const std::vector<double>& values,
                                              const HierarchyFileInfo& info,
                                              const HierarchyWriteOptions& options) {
  MLFE_CHECK(options.version == 4 && options.residual_quantization && options.max_error > 0 &&
             values.size() == h.vertex_count() && !levels.vertex_end.empty() &&
             levels.vertex_end.back() == h.vertex_count());
  std::vector<double> d;
  predicted_streams(h, levels.vertex_end, values, info, options, true, d);
  return d;
}

void write_hierarchy(const std::string& path, const HierarchyFile& file,
                     const HierarchyWriteOptions& options) {
  if (file.dim == 2 && std::holds_alternative<Hierarchy<2>>(file.hierarchy))
    write_hierarchy<2>(path, std::get<Hierarchy<2>>(file.hierarchy), file.values, file, options);
  else if (file.dim == 3 && std::holds_alternative<Hierarchy<3>>(file.hierarchy))
    write_hierarchy<3>(path, std::get<Hierarchy<3>>(file.hierarchy), file.values, file, options);
  else
    throw Error(path + ": HierarchyFile::dim does not match the hierarchy it holds");
}

namespace {
HierarchyFile read_v1(const std::string& path) {
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
    throw Error(path + ": unsupported hierarchy file version " + std::to_string(version) +
                " (this mlfe reads " + std::to_string(kVersion) + ")");
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
  if (nv >= VertexId::kInvalidValue)
    throw Error(path + ": vertex count " + std::to_string(nv) + " too large");
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
  if (!zstd && ss != rs)
    throw Error(path + ": stored size differs from the array size of an uncompressed file");
  // ls, lm are bounded above; ss is compared against the real file size before it is used, and
  // written so that the sum cannot overflow.
  const std::uint64_t fixed = kHeaderSize + ls + lm + 4;
  if (file_size < fixed || ss != file_size - fixed)
    throw Error(
        path + ": file size " + std::to_string(file_size) + " does not match the header (expected " +
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
  f.version = 1;
  f.file_levels = std::visit([](const auto& hh) { return hh.max_level(); }, f.hierarchy);
  f.sections.push_back({"header", -1, kHeaderSize + ls + lm, kHeaderSize + ls + lm});
  f.sections.push_back({"arrays", -1, ss + 4, rs});
  return f;
}
// ---- version 2 reader ----

// Reads the sections of a v2 file one after the other, each checked before it is used.
class SectionReader {
 public:
  SectionReader(const std::string& path, std::ifstream& in, std::uint64_t file_size)
      : path_(path), in_(in), size_(file_size), pos_(kPreambleSize) {}

  // crc_seed: the CRC of the preamble for HEAD, else 0.
  Bytes next(std::uint32_t tag, const std::string& name, HierarchyFile& f, int level,
             std::uint32_t crc_seed = 0) {
    if (size_ - pos_ < kSectionHeaderSize)
      throw Error(path_ + ": truncated file (" + name + " section missing)");
    std::uint8_t head[kSectionHeaderSize];
    read(head, kSectionHeaderSize);
    Cursor c(path_, head, kSectionHeaderSize);
    const auto got_tag = c.get<std::uint32_t>("section header");
    const auto codec = c.get<std::uint32_t>("section header");
    const auto stored = c.get<std::uint64_t>("section header");
    const auto raw = c.get<std::uint64_t>("section header");
    const auto stored_crc = c.get<std::uint32_t>("section header");
    if (got_tag != tag) throw Error(path_ + ": expected the " + name + " section, found another tag");
    if (codec != kCodecRaw && codec != kCodecZstd)
      throw Error(path_ + ": " + name + " section has unknown codec");
    if (stored > size_ - pos_) throw Error(path_ + ": truncated " + name + " section");
    if (codec == kCodecRaw && raw != stored) throw Error(path_ + ": " + name + " section sizes disagree");
    if (codec == kCodecZstd && raw > kMaxSectionRatio * stored + kRatioSlack)
      throw Error(path_ + ": implausible compression ratio in the " + name + " section");
    Bytes payload(static_cast<std::size_t>(stored));
    read(payload.data(), payload.size());
    if (crc32_of(payload.data(), payload.size(), crc32_of(head, 24, crc_seed)) != stored_crc)
      throw Error(path_ + ": checksum mismatch in the " + name + " section (file corrupted)");
    f.sections.push_back({name, level, kSectionHeaderSize + stored, raw});
    if (codec == kCodecRaw) return payload;
    if (ZSTD_getFrameContentSize(payload.data(), payload.size()) != raw)
      throw Error(path_ + ": " + name + " section decompresses to the wrong size");
    Bytes out(static_cast<std::size_t>(raw));
    const std::size_t n = ZSTD_decompress(out.data(), out.size(), payload.data(), payload.size());
    if (ZSTD_isError(n) || n != raw) throw Error(path_ + ": corrupt compressed " + name + " section");
    return out;
  }
  bool at_end() const { return pos_ == size_; }
  std::uint64_t file_size() const { return size_; }

 private:
  void read(std::uint8_t* p, std::size_t n) {
    in_.read(reinterpret_cast<char*>(p), static_cast<std::streamsize>(n));
    if (!in_) throw Error(path_ + ": read error");
    pos_ += n;
  }
  const std::string& path_;
  std::ifstream& in_;
  std::uint64_t size_, pos_;
};

std::int64_t get_varint(const std::string& path, Cursor& c, const char* what) {
  std::uint64_t z = 0;
  for (int shift = 0;; shift += 7) {
    if (shift > 63) throw Error(path + ": malformed value code in " + what);
    const auto b = c.get<std::uint8_t>(what);
    z |= static_cast<std::uint64_t>(b & 0x7f) << shift;
    if (!(b & 0x80)) break;
  }
  return static_cast<std::int64_t>(z >> 1) ^ -static_cast<std::int64_t>(z & 1);
}

struct HeadV2 {
  std::uint64_t nv = 0, ne = 0;
  std::uint32_t levels = 0, coding = 0, version = 2;
  double bound = 0;
  /// v4 with coding 1 or 3: values predicted on the lattice and range coded.
  bool predicted() const {
    return version == kVersion4 && (coding == kCodingQuantized || coding == kCodingInteger);
  }
};

// The rest of a section's payload: a v4 range-coded stream.
Bytes rest_of(Cursor& c, const char* what) { return c.get_array<std::uint8_t>(c.left(), what); }

// Decodes the values of vertices [from, to) of h: see docs/mlfeh-v2.md, "Values".
template <int D>
void get_values(const std::string& path, Cursor& c, const Hierarchy<D>& h, const HeadV2& head,
                std::size_t from, std::size_t to, std::vector<double>& d, const char* what) {
  if (head.coding == kCodingNone) return;
  d.resize(to);
  // Integer coding: one stream per context, each with its byte length first.
  std::array<Bytes, kContexts> stream_bytes;
  std::vector<Cursor> streams;
  streams.reserve(kContexts);
  if (head.coding == kCodingInteger) {
    std::array<std::uint32_t, kContexts> length;
    for (auto& n : length) n = c.get<std::uint32_t>(what);
    for (int k = 0; k < kContexts; ++k) {
      stream_bytes[k] = c.get_array<std::uint8_t>(length[k], what);
      streams.emplace_back(path, stream_bytes[k].data(), stream_bytes[k].size());
    }
  }
  for (std::size_t v = from; v < to; ++v) {
    if (head.coding == kCodingInteger) {
      // Decoded values stay integers below 2^52 in magnitude (checked), so the f64 values
      // are exact and the prediction's integer arithmetic cannot overflow.
      const auto& p = h.vertex_parents(VertexId(static_cast<std::uint32_t>(v)));
      const std::int64_t pred = p[0].valid() ? integer_prediction(static_cast<std::int64_t>(d[p[0].value]),
                                                                  static_cast<std::int64_t>(d[p[1].value]))
                                             : 0;
      const std::int64_t q = get_varint(path, streams[integer_context(h, d, v)], what);
      const auto step = static_cast<std::int64_t>(2 * head.bound + 1);
      constexpr std::int64_t kMax = std::int64_t(1) << 52;
      if (q > kMax / step || q < -kMax / step || std::llabs(pred + q * step) >= kMax)
        throw Error(path + ": value of a vertex in " + what + " is out of range");
      d[v] = static_cast<double>(pred + q * step);
      continue;
    }
    if (head.coding == kCodingExact) {
      d[v] = c.get<double>(what);
    } else {
      const auto& p = h.vertex_parents(VertexId(static_cast<std::uint32_t>(v)));
      const double pred = p[0].valid() ? 0.5 * (d[p[0].value] + d[p[1].value]) : 0.0;
      d[v] = pred + static_cast<double>(get_varint(path, c, what)) * (2 * head.bound);
    }
    if (!std::isfinite(d[v])) throw Error(path + ": value of a vertex in " + what + " is not finite");
  }
  for (const Cursor& sc : streams)
    if (sc.left() != 0) throw Error(path + ": trailing bytes in a value stream of " + std::string(what));
}

// The n marks of a level section: bits (v2, v3, v4 form 1) or a range-coded stream after its
// length (v4 form 0, `coded`).
std::vector<std::uint8_t> read_marks(const std::string& path, Cursor& c, bool coded, std::uint32_t n,
                                     const std::string& name) {
  if (coded) {
    const auto bytes = c.get<std::uint32_t>(name.c_str());
    const Bytes coded = c.get_array<std::uint8_t>(bytes, name.c_str());
    return decode_marks(path, name.c_str(), n, coded.data(), coded.size());
  }
  const Bytes bits = c.get_array<std::uint8_t>((std::size_t(n) + 7) / 8, name.c_str());
  if (n % 8 && (bits.back() >> (n % 8))) throw Error(path + ": " + name + " has marks past its candidates");
  std::vector<std::uint8_t> marks(n);
  for (std::size_t i = 0; i < n; ++i) marks[i] = (bits[i / 8] >> (i % 8)) & 1u;
  return marks;
}

template <int D>
void read_v2_body(const std::string& path, SectionReader& r, const HeadV2& head, int max_level,
                  HierarchyFile& f) {
  // Step 1: T0 and its values.
  const Bytes mesh = r.next(kTagMesh, "T0", f, 0);
  Cursor c(path, mesh.data(), mesh.size());
  const auto nv0 = c.get<std::uint32_t>("T0 counts");
  const auto ne0 = c.get<std::uint32_t>("T0 counts");
  if (nv0 > head.nv || ne0 == 0 || ne0 > head.ne) throw Error(path + ": T0 counts disagree with the header");
  typename Hierarchy<D>::Arrays a;
  a.points = c.get_array<typename Hierarchy<D>::Point>(nv0, "T0 points");
  a.cells = c.get_array<typename Hierarchy<D>::Cell>(ne0, "T0 cells");
  // The rebuild's arrays at their final size from the start (from_arrays keeps the capacity):
  // grown level by level, refine() would copy them at every level. The header's counts are
  // not trusted yet, so the reservation is bounded by what the file's size can describe.
  {
    const std::uint64_t cap = std::uint64_t(kMaxReserveFactor) * r.file_size() + 4096;
    const auto nv = static_cast<std::size_t>(std::min<std::uint64_t>(head.nv, cap));
    const auto ne = static_cast<std::size_t>(std::min<std::uint64_t>(head.ne, cap));
    a.points.reserve(nv);
    a.vertex_parents.reserve(nv);
    a.vertex_level.reserve(nv);
    a.cells.reserve(ne);
    a.parent.reserve(ne);
    a.first_child.reserve(ne);
    a.num_children.reserve(ne);
    a.level.reserve(ne);
    a.kind.reserve(ne);
    advise_huge_pages(a.points);
    advise_huge_pages(a.vertex_parents);
    advise_huge_pages(a.vertex_level);
    advise_huge_pages(a.cells);
    advise_huge_pages(a.parent);
    advise_huge_pages(a.first_child);
    advise_huge_pages(a.num_children);
    advise_huge_pages(a.level);
    advise_huge_pages(a.kind);
  }
  a.vertex_parents.assign(nv0, {VertexId::invalid(), VertexId::invalid()});
  a.vertex_level.assign(nv0, 0);
  a.parent.assign(ne0, ElemId::invalid());
  a.first_child.assign(ne0, ElemId::invalid());
  a.num_children.assign(ne0, 0);
  a.level.assign(ne0, 0);
  a.kind.assign(ne0, ElemKind::kCoarse);
  Hierarchy<D> h = Hierarchy<D>::from_arrays(std::move(a), path + ": invalid T0");
  // The edge → midpoint map at its final size too: grown by doubling, it rehashed every entry
  // ~13 times on the way to 225 000 vertices (9 % of reading H225k). Unlike the arrays'
  // reservation (address space only), sizing the map fills it, so a small file claiming a huge
  // count must not size it: at most 16 vertices per file byte (the measured files hold under 2;
  // beyond that the map just grows as before).
  {
    const std::uint64_t cap = 16 * r.file_size() + 4096;
    h.reserve(static_cast<std::size_t>(std::min<std::uint64_t>(head.nv, cap)), 0, true);
  }
  check_lattice_box(path, h, f);
  std::optional<PredictedValues<D>> pv;
  if (head.predicted()) {
    pv.emplace(predicted_coding<D>(f, head.bound, head.coding == kCodingInteger));
    f.values.resize(nv0);
    const Bytes stream = rest_of(c, "T0");
    pv->decode(path, "T0", h, 0, 0, nv0, stream.data(), stream.size(), f.values, false);
  } else {
    get_values(path, c, h, head, 0, nv0, f.values, "T0");
  }
  if (c.left() != 0) throw Error(path + ": trailing bytes in the T0 section");

  // Step 2: the levels, each rebuilt before its values are read (they need the parents).
  const int last = max_level < 0 ? static_cast<int>(head.levels) : std::min<int>(max_level, head.levels);
  for (int k = 1; k <= last; ++k) {
    const std::string name = "level " + std::to_string(k);
    const Bytes level = r.next(kTagLevel, name, f, k);
    Cursor lc(path, level.data(), level.size());
    const auto got_k = lc.get<std::uint32_t>(name.c_str());
    const auto n = lc.get<std::uint32_t>(name.c_str());
    const auto m = lc.get<std::uint32_t>(name.c_str());
    if (got_k != static_cast<std::uint32_t>(k)) throw Error(path + ": " + name + " section is out of order");
    const std::vector<ElemId> cand = refinement_candidates(h, k);
    if (n != cand.size())
      throw Error(path + ": " + name + " has " + std::to_string(n) + " marks for " +
                  std::to_string(cand.size()) + " candidate elements");
    if (h.vertex_count() + std::uint64_t(m) > head.nv)
      throw Error(path + ": " + name + " exceeds the vertex count");
    const std::uint32_t form = head.version == kVersion4 ? lc.get<std::uint32_t>(name.c_str()) : kFormPacked;
    if (form > kFormResidual || (form != kFormPacked && !pv) || (form == kFormResidual && !(head.bound > 0)))
      throw Error(path + ": " + name + " has an unknown form " + std::to_string(form));
    const bool coded = form != kFormPacked;
    const std::vector<std::uint8_t> marks = read_marks(path, lc, coded, n, name);
    const std::size_t before = h.vertex_count();
    apply_refinement_marks(h, cand, marks);
    if (h.vertex_count() - before != m || h.element_count() > head.ne)
      throw Error(path + ": " + name + " does not rebuild the stored counts");
    if (coded) {
      f.values.resize(h.vertex_count());
      const Bytes stream = rest_of(lc, name.c_str());
      pv->decode(path, name.c_str(), h, k, before, h.vertex_count(), stream.data(), stream.size(), f.values,
                 form == kFormResidual);
    } else {
      get_values(path, lc, h, head, before, h.vertex_count(), f.values, name.c_str());
      if (pv) pv->observe(h, k, before, h.vertex_count(), f.values);
    }
    if (lc.left() != 0) throw Error(path + ": trailing bytes in the " + name + " section");
  }
  if (max_level < 0 || max_level >= static_cast<int>(head.levels)) {
    if (h.vertex_count() != head.nv || h.element_count() != head.ne)
      throw Error(path + ": the rebuilt hierarchy does not have the stored counts");
    if (max_level < 0 && !r.at_end()) throw Error(path + ": trailing bytes after the last level");
  }
  f.hierarchy = std::move(h);
}

HierarchyFile read_v2(const std::string& path, std::ifstream& in, std::uint64_t file_size,
                      const std::uint8_t (&preamble)[kPreambleSize], int max_level) {
  std::uint32_t dim;
  std::memcpy(&dim, preamble + 12, 4);
  if (dim != 2 && dim != 3) throw Error(path + ": dimension " + std::to_string(dim) + " is not 2 or 3");
  std::uint32_t version;
  std::memcpy(&version, preamble + 8, 4);
  HierarchyFile f;
  f.version = static_cast<int>(version);
  f.dim = static_cast<int>(dim);
  f.sections.push_back({"preamble", -1, kPreambleSize, kPreambleSize});
  SectionReader r(path, in, file_size);
  const Bytes hb = r.next(kTagHead, "header", f, -1, crc32_of(preamble, kPreambleSize));
  Cursor c(path, hb.data(), hb.size());
  HeadV2 head;
  head.nv = c.get<std::uint64_t>("header");
  head.ne = c.get<std::uint64_t>("header");
  head.levels = c.get<std::uint32_t>("header");
  head.coding = c.get<std::uint32_t>("header");
  head.bound = c.get<double>("header");
  head.version = version;
  for (double& x : f.transform.spacing) x = c.get<double>("header");
  for (double& x : f.transform.origin) x = c.get<double>("header");
  for (double& x : f.transform.direction) x = c.get<double>("header");
  f.value_min = c.get<double>("header");
  f.value_max = c.get<double>("header");
  f.rms_error = c.get<double>("header");
  f.max_error = c.get<double>("header");
  f.psnr_db = c.get<double>("header");
  const auto norm = c.get<std::uint32_t>("header");
  if (version >= 3) {
    const auto lattice = c.get<std::uint32_t>("header");
    const auto level = c.get<std::uint32_t>("header");
    for (auto& n : f.data_dims)
      n = static_cast<std::int64_t>(
          std::min<std::uint64_t>(c.get<std::uint64_t>("header"), std::uint64_t(1) << 62));
    f.sample_error_bound = c.get<double>("header");
    if (lattice > 1) throw Error(path + ": unknown lattice flag " + std::to_string(lattice));
    f.on_lattice = lattice == 1;
    f.lattice_level = static_cast<int>(std::min<std::uint32_t>(level, 1000));
    if (!f.on_lattice && (level != 0 || f.data_dims != std::array<std::int64_t, 3>{1, 1, 1}))
      throw Error(path + ": lattice fields set without the lattice flag");
  }
  const auto ls = c.get<std::uint32_t>("header");
  const auto lm = c.get<std::uint32_t>("header");
  if (head.nv >= VertexId::kInvalidValue) throw Error(path + ": vertex count too large");
  if (head.ne == 0 || head.ne >= ElemId::kInvalidValue) throw Error(path + ": element count out of range");
  if (head.levels > kMaxLevels) throw Error(path + ": more than 60 levels");
  // A range-coded level describes its marks in as little as a bit per thousands of
  // candidates, so a small v4 file could claim and rebuild a huge hierarchy: its counts are
  // capped by its size (measured files hold under 40 elements per byte).
  if (version == kVersion4 && head.ne > kMaxElementsPerByte * file_size + kElementSlack)
    throw Error(path + ": element count implausible for the file size");
  if (head.coding > (version >= 3 ? kCodingInteger : kCodingExact))
    throw Error(path + ": unknown value coding " + std::to_string(head.coding));
  const bool bound_ok = head.coding == kCodingQuantized ? head.bound > 0 && std::isfinite(head.bound)
                        : head.coding == kCodingInteger ? head.bound >= 0 && head.bound < 2147483648.0 &&
                                                              head.bound == std::floor(head.bound)
                                                        : head.bound == 0;
  if (!bound_ok) throw Error(path + ": value bound does not fit the value coding");
  for (double e : {f.rms_error, f.max_error})
    if (!std::isnan(e) && !(e >= 0 && std::isfinite(e))) throw Error(path + ": error figures out of range");
  if (norm > 2) throw Error(path + ": unknown norm " + std::to_string(norm));
  if (ls > kMaxSpace) throw Error(path + ": space string longer than 64 bytes");
  if (lm > kMaxMetadata) throw Error(path + ": metadata longer than 16 MiB");
  if (c.left() != std::uint64_t(ls) + lm)
    throw Error(path + ": header section size does not match its strings");
  f.norm = norm == 1 ? "l2" : norm == 2 ? "h1" : "";
  const auto sp = c.get_array<char>(ls, "space");
  f.space.assign(sp.begin(), sp.end());
  if (!printable(f.space)) throw Error(path + ": space string is not printable ASCII");
  if (lm > 0) {
    const auto meta = c.get_array<char>(lm, "metadata");
    f.metadata = nlohmann::json::parse(meta.begin(), meta.end(), nullptr, /*allow_exceptions=*/false);
    if (!f.metadata.is_object()) throw Error(path + ": metadata is not a JSON object");
  }
  check_info(path, f);
  check_lattice(path, f.dim, f);
  f.file_levels = static_cast<int>(head.levels);
  f.value_bound = head.bound;
  f.integer_values = head.coding == kCodingInteger;
  if (dim == 2)
    read_v2_body<2>(path, r, head, max_level, f);
  else
    read_v2_body<3>(path, r, head, max_level, f);
  return f;
}

// T_max_level of a v1 file's hierarchy, with the values at its vertices.
template <int D>
void truncate_levels(const std::string& path, HierarchyFile& f, int max_level) {
  const Hierarchy<D>& h = std::get<Hierarchy<D>>(f.hierarchy);
  LevelEncoding<D> enc;
  try {
    enc = encode_levels(h, max_level);
  } catch (const Error& e) {
    throw Error(path + ": " + e.what());
  }
  if (!f.values.empty()) {
    std::vector<double> u(enc.rebuilt.vertex_count());
    for (std::size_t v = 0; v < u.size(); ++v) u[v] = f.values[enc.to_original[v].value];
    f.values = std::move(u);
  }
  f.hierarchy = std::move(enc.rebuilt);
}

}  // namespace

HierarchyFile read_hierarchy(const std::string& path, int max_level) {
  std::uint32_t version = 0;
  std::uint64_t file_size = 0;
  regular_file_size(path);
  {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw Error(path + ": cannot open file");
    in.seekg(0, std::ios::end);
    const std::streamoff size_signed = in.tellg();
    if (size_signed < 0) throw Error(path + ": cannot determine the file size");
    file_size = static_cast<std::uint64_t>(size_signed);
    in.seekg(0);
    std::uint8_t pre[kPreambleSize] = {};
    in.read(reinterpret_cast<char*>(pre),
            static_cast<std::streamsize>(std::min<std::uint64_t>(file_size, kPreambleSize)));
    if (file_size < 8 || std::memcmp(pre, kMagic, 8) != 0)
      throw Error(path + ": not an mlfe hierarchy file (bad magic)");
    if (file_size < 12) throw Error(path + ": truncated header");
    std::memcpy(&version, pre + 8, 4);
    if (version == kVersion2 || version == kVersion3 || version == kVersion4) {
      if (file_size < kPreambleSize) throw Error(path + ": truncated header");
      return read_v2(path, in, file_size, pre, max_level);
    }
  }
  if (version != kVersion)
    throw Error(path + ": unsupported hierarchy file version " + std::to_string(version) +
                " (this mlfe reads 1, 2, 3 and 4)");
  HierarchyFile f = read_v1(path);
  if (max_level >= 0 && max_level < f.file_levels) {
    if (f.dim == 2)
      truncate_levels<2>(path, f, max_level);
    else
      truncate_levels<3>(path, f, max_level);
  }
  return f;
}

template std::vector<double> residual_quantized_values<2>(const Hierarchy<2>&, const LevelDescription<2>&,
                                                          const std::vector<double>&,
                                                          const HierarchyFileInfo&,
                                                          const HierarchyWriteOptions&);
template std::vector<double> residual_quantized_values<3>(const Hierarchy<3>&, const LevelDescription<3>&,
                                                          const std::vector<double>&,
                                                          const HierarchyFileInfo&,
                                                          const HierarchyWriteOptions&);
template void write_hierarchy<2>(const std::string&, const Hierarchy<2>&, const std::vector<double>&,
                                 const HierarchyFileInfo&, const HierarchyWriteOptions&);
template void write_hierarchy<3>(const std::string&, const Hierarchy<3>&, const std::vector<double>&,
                                 const HierarchyFileInfo&, const HierarchyWriteOptions&);
template void write_hierarchy<2>(const std::string&, const Hierarchy<2>&, const LevelDescription<2>&,
                                 const std::vector<double>&, const HierarchyFileInfo&,
                                 const HierarchyWriteOptions&);
template void write_hierarchy<3>(const std::string&, const Hierarchy<3>&, const LevelDescription<3>&,
                                 const std::vector<double>&, const HierarchyFileInfo&,
                                 const HierarchyWriteOptions&);

bool is_hierarchy_file(const std::string& path) {
  try {
    const std::string magic = read_file_prefix(path, 8);
    return magic.size() == 8 && std::memcmp(magic.data(), kMagic, 8) == 0;
  } catch (const Error&) {
    return false;  // missing, or not a regular file: not one to read
  }
}

}  // namespace mlfe
