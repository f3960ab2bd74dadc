// OME-Zarr 0.4 / Zarr v2 reading (formats/zarr_reader.h): the metadata, then chunk by chunk.
#include <blosc.h>
#include <fmt/format.h>
#include <mlfe/core/base/error.h>
#include <mlfe/formats/safe_read.h>
#include <mlfe/formats/zarr_reader.h>
#include <tbb/parallel_for.h>
#include <zlib.h>
#include <zstd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <vector>

#include "formats/reader_helpers.h"

namespace mlfe {
namespace {

using namespace volume_detail;
namespace fs = std::filesystem;
using Json = nlohmann::json;

// Metadata files are small; a larger one is not metadata.
constexpr std::uint64_t kMaxMetadataBytes = 16u << 20;

Json read_json(const std::string& path) {
  const std::string text = read_regular_file(path, kMaxMetadataBytes, "Zarr metadata");
  Json j = Json::parse(text, nullptr, false);
  if (j.is_discarded()) fail(path, "not valid JSON");
  if (!j.is_object()) fail(path, "expected a JSON object");
  return j;
}

bool is_folder(const std::string& p) {
  std::error_code ec;
  return fs::is_directory(p, ec);
}

bool is_file(const std::string& p) {
  std::error_code ec;
  return fs::is_regular_file(p, ec);
}

// One Zarr v2 array (.zarray).
struct ArrayMeta {
  std::vector<std::int64_t> shape, chunks;
  ScalarType type = ScalarType::U8;
  int itemsize = 1;
  bool swap = false;
  std::string compressor;  // "" (none), "blosc", "zlib", "gzip", "zstd"
  std::optional<double> fill;
  char separator = '.';
};

std::vector<std::int64_t> int_list(const std::string& file, const Json& j, const char* key) {
  const auto it = j.find(key);
  if (it == j.end() || !it->is_array() || it->empty() || it->size() > 8)
    fail(file, fmt::format("\"{}\" must be a list of 1 to 8 integers", key));
  std::vector<std::int64_t> v;
  for (const Json& e : *it) {
    if (!e.is_number_integer() || e.get<std::int64_t>() < 1 ||
        e.get<std::int64_t>() > (std::int64_t(1) << 31))
      fail(file, fmt::format("\"{}\" must hold integers 1..2^31", key));
    v.push_back(e.get<std::int64_t>());
  }
  return v;
}

// "<u2", "|u1", ">f4", ...
void parse_dtype(const std::string& file, const Json& j, ArrayMeta& a) {
  const auto it = j.find("dtype");
  if (it == j.end() || !it->is_string()) fail(file, "\"dtype\" must be a string such as \"<u2\"");
  const std::string d = it->get<std::string>();
  static const std::pair<const char*, ScalarType> kTypes[] = {
      {"u1", ScalarType::U8},  {"i1", ScalarType::I8},  {"u2", ScalarType::U16}, {"i2", ScalarType::I16},
      {"u4", ScalarType::U32}, {"i4", ScalarType::I32}, {"f4", ScalarType::F32}, {"f8", ScalarType::F64}};
  if (d.size() == 3 && (d[0] == '<' || d[0] == '>' || d[0] == '|')) {
    for (const auto& [name, type] : kTypes) {
      if (d.compare(1, 2, name) != 0) continue;
      a.type = type;
      a.itemsize = scalar_type_size(type);
      const bool big = d[0] == '>';
      a.swap = a.itemsize > 1 && big == host_is_little_endian();
      return;
    }
  }
  fail(file,
       fmt::format("dtype \"{}\" is not supported (integers u1..i4, floats f4 and f8)", d.substr(0, 16)));
}

void parse_compressor(const std::string& file, const Json& j, ArrayMeta& a) {
  const auto it = j.find("compressor");
  if (it == j.end() || it->is_null()) return;
  if (!it->is_object() || !it->contains("id") || !(*it)["id"].is_string())
    fail(file, "\"compressor\" must be null or an object with an \"id\"");
  const std::string id = (*it)["id"].get<std::string>();
  if (id != "blosc" && id != "zlib" && id != "gzip" && id != "zstd")
    fail(file, fmt::format("compressor \"{}\" is not supported (blosc, zlib, gzip, zstd or none)",
                           id.substr(0, 32)));
  a.compressor = id;
}

std::optional<double> parse_fill(const std::string& file, const Json& f) {
  if (f.is_null()) return std::nullopt;
  if (f.is_number()) return f.get<double>();
  if (f.is_boolean()) return f.get<bool>() ? 1.0 : 0.0;
  if (f.is_string()) {
    const std::string s = f.get<std::string>();
    if (s == "NaN") return std::numeric_limits<double>::quiet_NaN();
    if (s == "Infinity") return std::numeric_limits<double>::infinity();
    if (s == "-Infinity") return -std::numeric_limits<double>::infinity();
  }
  fail(file, "\"fill_value\" must be a number, \"NaN\", \"Infinity\", \"-Infinity\" or null");
}

ArrayMeta parse_zarray(const std::string& file) {
  const Json j = read_json(file);
  if (!j.contains("zarr_format") || j["zarr_format"] != 2)
    fail(file, "only Zarr format 2 arrays are supported (\"zarr_format\": 2)");
  ArrayMeta a;
  a.shape = int_list(file, j, "shape");
  a.chunks = int_list(file, j, "chunks");
  if (a.chunks.size() != a.shape.size())
    fail(file, fmt::format("\"chunks\" has {} entries for a shape of {}", a.chunks.size(), a.shape.size()));
  parse_dtype(file, j, a);
  parse_compressor(file, j, a);
  if (j.contains("filters") && !j["filters"].is_null() && !(j["filters"].is_array() && j["filters"].empty()))
    fail(file, "\"filters\" are not supported");
  if (j.contains("order") && j["order"] != "C") fail(file, "only \"order\": \"C\" is supported");
  a.fill = parse_fill(file, j.contains("fill_value") ? j["fill_value"] : Json());
  if (j.contains("dimension_separator")) {
    const Json& s = j["dimension_separator"];
    if (s == ".")
      a.separator = '.';
    else if (s == "/")
      a.separator = '/';
    else
      fail(file, "\"dimension_separator\" must be \".\" or \"/\"");
  }
  std::int64_t chunk_values = 1;
  for (std::int64_t c : a.chunks) {
    chunk_values *= c;
    if (chunk_values > (std::int64_t(1) << 31))
      fail(file, "a chunk of more than 2^31 values is not supported");
  }
  return a;
}

// Millimetres per unit of an OME-NGFF space axis; nullopt when the unit is unknown.
std::optional<double> millimetres_per(const std::string& unit) {
  static const std::pair<const char*, double> kUnits[] = {
      {"millimeter", 1.0}, {"micrometer", 1e-3}, {"nanometer", 1e-6}, {"centimeter", 10.0},
      {"meter", 1e3},      {"angstrom", 1e-7},   {"picometer", 1e-9}, {"decimeter", 100.0}};
  for (const auto& [name, mm] : kUnits)
    if (unit == name) return mm;
  return std::nullopt;
}

// Scale and translation of a coordinateTransformations list (identity where absent).
void apply_transformations(const std::string& file, const Json& list, std::size_t rank,
                           std::vector<double>& scale, std::vector<double>& translation) {
  if (!list.is_array()) fail(file, "\"coordinateTransformations\" must be a list");
  for (const Json& t : list) {
    if (!t.is_object() || !t.contains("type")) fail(file, "a coordinate transformation without a \"type\"");
    const std::string type = t["type"].is_string() ? t["type"].get<std::string>() : "";
    const char* key = type == "scale" ? "scale" : type == "translation" ? "translation" : nullptr;
    if (!key) fail(file, "coordinate transformations must be \"scale\" or \"translation\"");
    if (!t.contains(key) || !t[key].is_array() || t[key].size() != rank)
      fail(file, fmt::format("\"{}\" must list {} numbers, one per axis", key, rank));
    for (std::size_t i = 0; i < rank; ++i) {
      if (!t[key][i].is_number() || !std::isfinite(t[key][i].get<double>()))
        fail(file, fmt::format("\"{}\" must hold finite numbers", key));
      const double v = t[key][i].get<double>();
      if (type == "scale") {
        if (!(v > 0)) fail(file, "scales must be positive");
        scale[i] *= v;
        translation[i] *= v;
      } else {
        translation[i] += v;
      }
    }
  }
}

struct Axis {
  std::string name, type, unit;
};

std::vector<Axis> parse_axes(const std::string& file, const Json& ms, std::size_t rank) {
  std::vector<Axis> axes;
  if (!ms.contains("axes")) {
    // Before 0.3 the axes were implicit: t, c, z, y, x, the last `rank` of them.
    static const char* kNames[] = {"t", "c", "z", "y", "x"};
    if (rank > 5) fail(file, "an image of more than 5 axes without \"axes\"");
    for (std::size_t i = 5 - rank; i < 5; ++i)
      axes.push_back({kNames[i], i < 2 ? (i == 0 ? "time" : "channel") : "space", ""});
    return axes;
  }
  if (!ms["axes"].is_array() || ms["axes"].size() != rank)
    fail(file, fmt::format("\"axes\" must list {} axes, one per array dimension", rank));
  for (const Json& a : ms["axes"]) {
    Axis axis;
    if (a.is_string()) {  // 0.3: names only
      axis.name = a.get<std::string>();
      axis.type = axis.name == "t" ? "time" : axis.name == "c" ? "channel" : "space";
    } else if (a.is_object() && a.contains("name") && a["name"].is_string()) {
      axis.name = a["name"].get<std::string>();
      if (a.contains("type") && a["type"].is_string()) axis.type = a["type"].get<std::string>();
      if (a.contains("unit") && a["unit"].is_string()) axis.unit = a["unit"].get<std::string>();
      if (axis.type.empty())
        axis.type = (axis.name == "x" || axis.name == "y" || axis.name == "z") ? "space" : "";
    } else {
      fail(file, "each axis must be a name or an object with a \"name\"");
    }
    axes.push_back(axis);
  }
  return axes;
}

}  // namespace

struct ZarrVolume::Impl {
  std::string store, level_dir;
  ArrayMeta array;
  std::size_t space_rank = 3;  // 2 or 3 space axes, the last ones
  std::array<std::int64_t, 3> dims{1, 1, 1};
  std::array<std::int64_t, 3> chunk{1, 1, 1};  // x, y, z
  GridTransform transform;
  int levels = 1;
  std::string notes;

  std::string chunk_file(const std::array<std::int64_t, 3>& c) const;
  void decode_chunk(const std::string& file, std::vector<unsigned char>& out) const;
};

namespace {

// Reads the multiscales of `store` (level `level`): the level's folder and its frame.
void open_multiscales(ZarrVolume::Impl& z, int level, std::vector<Axis>& axes, std::vector<double>& scale,
                      std::vector<double>& translation) {
  const std::string attrs_file = (fs::path(z.store) / ".zattrs").string();
  const Json attrs = read_json(attrs_file);
  if (!attrs.contains("multiscales") || !attrs["multiscales"].is_array() || attrs["multiscales"].empty())
    fail(attrs_file, "no \"multiscales\" (not an OME-Zarr image)");
  const Json& ms = attrs["multiscales"][0];
  if (!ms.is_object() || !ms.contains("datasets") || !ms["datasets"].is_array() || ms["datasets"].empty())
    fail(attrs_file, "the multiscale has no \"datasets\"");
  z.levels = static_cast<int>(ms["datasets"].size());
  if (level < 0 || level >= z.levels)
    fail(z.store, fmt::format("has levels 0..{}, not {}", z.levels - 1, level));
  const Json& ds = ms["datasets"][static_cast<std::size_t>(level)];
  if (!ds.is_object() || !ds.contains("path") || !ds["path"].is_string())
    fail(attrs_file, fmt::format("dataset {} has no \"path\"", level));
  const std::string rel = ds["path"].get<std::string>();
  if (rel.empty() || rel.find("..") != std::string::npos || rel.front() == '/')
    fail(attrs_file,
         fmt::format("dataset path \"{}\" must name a folder inside the image", rel.substr(0, 64)));
  z.level_dir = (fs::path(z.store) / rel).string();
  z.array = parse_zarray((fs::path(z.level_dir) / ".zarray").string());
  const std::size_t rank = z.array.shape.size();
  axes = parse_axes(attrs_file, ms, rank);
  scale.assign(rank, 1.0);
  translation.assign(rank, 0.0);
  if (ds.contains("coordinateTransformations"))
    apply_transformations(attrs_file, ds["coordinateTransformations"], rank, scale, translation);
  if (ms.contains("coordinateTransformations"))
    apply_transformations(attrs_file, ms["coordinateTransformations"], rank, scale, translation);
}

// The space axes (the last two or three), their sizes, chunks and frame in millimetres.
void take_space_axes(ZarrVolume::Impl& z, const std::vector<Axis>& axes, const std::vector<double>& scale,
                     const std::vector<double>& translation) {
  const std::size_t rank = z.array.shape.size();
  std::size_t n_space = 0;
  while (n_space < rank && axes[rank - 1 - n_space].type == "space") ++n_space;
  if (n_space < 2 || n_space > 3)
    fail(z.store, fmt::format("needs 2 or 3 space axes last (y, x or z, y, x); it has {}", n_space));
  for (std::size_t i = 0; i + n_space < rank; ++i) {
    if (axes[i].type == "space") fail(z.store, "space axes must come last");
    if (z.array.shape[i] != 1)
      fail(z.store, fmt::format("axis \"{}\" has {} entries; mlfe reads one scalar field (size 1)",
                                axes[i].name.substr(0, 16), z.array.shape[i]));
  }
  z.space_rank = n_space;
  for (std::size_t s = 0; s < n_space; ++s) {  // s = 0 is x, the last axis
    const std::size_t i = rank - 1 - s;
    z.dims[s] = z.array.shape[i];
    z.chunk[s] = z.array.chunks[i];
    double mm = 1.0;
    if (const auto m = millimetres_per(axes[i].unit)) {
      mm = *m;
      if (mm != 1.0)
        z.notes += fmt::format("axis {} in {}s: converted to millimetres\n", axes[i].name.substr(0, 16),
                               axes[i].unit);
    } else {
      z.notes += fmt::format("axis {} has {} unit; taken as millimetres\n", axes[i].name.substr(0, 16),
                             axes[i].unit.empty() ? "no" : "an unknown");
    }
    z.transform.spacing[s] = scale[i] * mm;
    z.transform.origin[s] = translation[i] * mm;
  }
}

}  // namespace

std::string ZarrVolume::Impl::chunk_file(const std::array<std::int64_t, 3>& c) const {
  // Indices in the array's axis order: non-space axes (size 1) at 0, then z, y, x.
  std::string key;
  const std::size_t rank = array.shape.size();
  for (std::size_t i = 0; i < rank; ++i) {
    const std::size_t from_last = rank - 1 - i;
    const std::int64_t index = from_last < space_rank ? c[from_last] : 0;
    if (i > 0) key += array.separator;
    key += std::to_string(index);
  }
  return (fs::path(level_dir) / key).string();
}

namespace {

void inflate_exact(const std::string& file, const std::string& src, unsigned char* dst, std::size_t n,
                   bool gzip) {
  z_stream zs{};
  if (inflateInit2(&zs, gzip ? 16 + MAX_WBITS : MAX_WBITS) != Z_OK) fail(file, "cannot start zlib");
  zs.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(src.data()));
  zs.avail_in = static_cast<uInt>(src.size());
  zs.next_out = dst;
  zs.avail_out = static_cast<uInt>(n);
  const int rc = inflate(&zs, Z_FINISH);
  const std::size_t produced = n - zs.avail_out;
  inflateEnd(&zs);
  if (rc != Z_STREAM_END || produced != n)
    fail(file, fmt::format("{} chunk does not decode to the chunk's {} bytes", gzip ? "gzip" : "zlib", n));
}

}  // namespace

void ZarrVolume::Impl::decode_chunk(const std::string& file, std::vector<unsigned char>& out) const {
  std::size_t n = static_cast<std::size_t>(array.itemsize);
  for (std::int64_t c : array.chunks) n *= static_cast<std::size_t>(c);
  out.resize(n);
  // A compressed chunk is never much larger than its values (blosc and zstd add a header; an
  // incompressible zlib stream adds 5 bytes per 16 KiB block).
  const std::uint64_t limit = n + n / 64 + 4096;
  const std::string src = read_regular_file(file, limit, "a Zarr chunk");
  if (array.compressor.empty()) {
    if (src.size() != n) fail(file, fmt::format("uncompressed chunk has {} bytes, not {}", src.size(), n));
    std::copy(src.begin(), src.end(), out.begin());
  } else if (array.compressor == "blosc") {
    std::size_t nbytes = 0, cbytes = 0, block = 0;
    if (src.size() < BLOSC_MIN_HEADER_LENGTH) fail(file, "truncated blosc chunk");
    blosc_cbuffer_sizes(src.data(), &nbytes, &cbytes, &block);
    if (nbytes != n || cbytes != src.size())
      fail(file, fmt::format("blosc chunk of {} bytes holding {}, not a chunk of {}", cbytes, nbytes, n));
    if (blosc_decompress_ctx(src.data(), out.data(), n, 1) != static_cast<int>(n))
      fail(file, "corrupt blosc chunk");
  } else if (array.compressor == "zstd") {
    const unsigned long long content = ZSTD_getFrameContentSize(src.data(), src.size());
    if (content != ZSTD_CONTENTSIZE_UNKNOWN && content != n)
      fail(file, fmt::format("zstd chunk holding {} bytes, not a chunk of {}", content, n));
    const std::size_t got = ZSTD_decompress(out.data(), n, src.data(), src.size());
    if (ZSTD_isError(got) || got != n)
      fail(file, fmt::format("zstd chunk does not decode to the chunk's {} bytes", n));
  } else {
    inflate_exact(file, src, out.data(), n, array.compressor == "gzip");
  }
}

ZarrVolume::ZarrVolume(const std::string& path, int level) : impl_(std::make_unique<Impl>()) {
  Impl& z = *impl_;
  z.store = path;
  if (!is_folder(path)) fail(path, "not a Zarr store (expected a folder with .zattrs or .zarray)");
  std::vector<Axis> axes;
  std::vector<double> scale, translation;
  if (is_file((fs::path(path) / ".zattrs").string()) && !is_file((fs::path(path) / ".zarray").string())) {
    open_multiscales(z, level, axes, scale, translation);
  } else {
    // A plain array: the last axes are z, y, x (or y, x) at unit spacing.
    if (level != 0) fail(path, fmt::format("is a single Zarr array (level 0), not level {}", level));
    z.level_dir = path;
    z.array = parse_zarray((fs::path(path) / ".zarray").string());
    const std::size_t rank = z.array.shape.size();
    axes.assign(rank, Axis{"", "", ""});
    static const char* kNames[] = {"x", "y", "z"};
    for (std::size_t s = 0; s < std::min<std::size_t>(3, rank); ++s)
      axes[rank - 1 - s] = {kNames[s], "space", ""};
    scale.assign(rank, 1.0);
    translation.assign(rank, 0.0);
    z.notes += "a plain Zarr array: unit spacing in millimetres\n";
  }
  take_space_axes(z, axes, scale, translation);
  checked_voxel_count(path, z.dims);
}

ZarrVolume::~ZarrVolume() = default;
ZarrVolume::ZarrVolume(ZarrVolume&&) noexcept = default;
ZarrVolume& ZarrVolume::operator=(ZarrVolume&&) noexcept = default;
const std::array<std::int64_t, 3>& ZarrVolume::dims() const { return impl_->dims; }
const GridTransform& ZarrVolume::transform() const { return impl_->transform; }
ScalarType ZarrVolume::type() const { return impl_->array.type; }
int ZarrVolume::levels() const { return impl_->levels; }
const std::string& ZarrVolume::notes() const { return impl_->notes; }

namespace {

// Decodes chunk `c` and writes its overlap with the box [lo, hi) into g.
void copy_chunk(const ZarrVolume::Impl& z, const std::array<std::int64_t, 3>& c,
                const std::array<std::int64_t, 3>& lo, const std::array<std::int64_t, 3>& hi, ScalarGrid& g) {
  std::array<std::int64_t, 3> from, to;  // the overlap, in level indices
  for (int a = 0; a < 3; ++a) {
    from[a] = std::max(lo[a], c[a] * z.chunk[a]);
    to[a] = std::min(hi[a], (c[a] + 1) * z.chunk[a]);
  }
  const std::string file = z.chunk_file(c);
  // Missing means "no such file"; anything else (a folder, no permission) is left to the read,
  // which names it.
  std::error_code ec;
  const bool present = fs::exists(file, ec) || ec;
  std::vector<unsigned char> bytes;
  if (present) {
    z.decode_chunk(file, bytes);
  } else if (!z.array.fill) {
    fail(file, "missing chunk, and the array has no fill_value");
  }
  const std::int64_t run = to[0] - from[0];
  for (std::int64_t k = from[2]; k < to[2]; ++k)
    for (std::int64_t j = from[1]; j < to[1]; ++j) {
      float* dst = g.values.data() + ((k - lo[2]) * g.dims[1] + (j - lo[1])) * g.dims[0] + (from[0] - lo[0]);
      if (!present) {
        std::fill(dst, dst + run, static_cast<float>(*z.array.fill));
        continue;
      }
      // Within the chunk: C order, x fastest; chunk-local indices.
      const std::int64_t ci = from[0] - c[0] * z.chunk[0], cj = j - c[1] * z.chunk[1],
                         ck = k - c[2] * z.chunk[2];
      const std::size_t at =
          static_cast<std::size_t>((ck * z.chunk[1] + cj) * z.chunk[0] + ci) * z.array.itemsize;
      convert_to_float(bytes.data() + at, z.array.type, z.array.swap, dst, static_cast<std::size_t>(run));
    }
}

}  // namespace

ScalarGrid ZarrVolume::read_box(const std::array<std::int64_t, 3>& lo, const std::array<std::int64_t, 3>& hi,
                                const VolumeReadOptions& opts) const {
  const Impl& z = *impl_;
  for (int a = 0; a < 3; ++a)
    if (lo[a] < 0 || hi[a] > z.dims[a] || lo[a] >= hi[a])
      fail(z.store, fmt::format("box [{}, {}) x [{}, {}) x [{}, {}) is not inside the {} x {} x {} level",
                                lo[0], hi[0], lo[1], hi[1], lo[2], hi[2], z.dims[0], z.dims[1], z.dims[2]));
  ScalarGrid g;
  g.dims = {hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]};
  g.dim = z.space_rank == 2 ? 2 : 3;
  g.source_type = z.array.type;
  g.transform = z.transform;
  for (int a = 0; a < 3; ++a) g.transform.origin[a] += z.transform.spacing[a] * static_cast<double>(lo[a]);
  check_memory(z.store, checked_bytes(z.store, checked_voxel_count(z.store, g.dims), sizeof(float)), opts,
               "the volume's values");
  allocate_values(g);
  // The chunks the box meets, in a fixed order; each writes its own part of the box.
  std::array<std::int64_t, 3> c0, c1;
  for (int a = 0; a < 3; ++a) {
    c0[a] = lo[a] / z.chunk[a];
    c1[a] = (hi[a] - 1) / z.chunk[a] + 1;
  }
  std::vector<std::array<std::int64_t, 3>> chunks;
  for (std::int64_t k = c0[2]; k < c1[2]; ++k)
    for (std::int64_t j = c0[1]; j < c1[1]; ++j)
      for (std::int64_t i = c0[0]; i < c1[0]; ++i) chunks.push_back({i, j, k});
  // A failing chunk's error is kept by the lowest chunk number, so the message does not depend on
  // the threads' timing.
  std::mutex bad_mutex;
  std::size_t bad_chunk = chunks.size();
  std::string bad_message;
  tbb::parallel_for(std::size_t(0), chunks.size(), [&](std::size_t n) {
    try {
      copy_chunk(z, chunks[n], lo, hi, g);
    } catch (const std::exception& e) {
      const std::lock_guard<std::mutex> lock(bad_mutex);
      if (n < bad_chunk) {
        bad_chunk = n;
        bad_message =
            dynamic_cast<const Error*>(&e) ? e.what() : z.store + ": out of memory while reading a chunk";
      }
    }
  });
  if (bad_chunk < chunks.size()) throw Error(bad_message);
  return g;
}

bool is_zarr_store(const std::string& path) {
  if (!is_folder(path)) return false;
  if (is_file((fs::path(path) / ".zarray").string())) return true;
  const std::string attrs = (fs::path(path) / ".zattrs").string();
  if (!is_file(attrs)) return false;
  try {
    return read_json(attrs).contains("multiscales");
  } catch (const Error&) {
    return true;  // a store with broken metadata: the reader names the problem
  }
}

ScalarGrid read_zarr(const std::string& path, const VolumeReadOptions& opts) {
  const ZarrVolume v(path, opts.zarr_level);
  ScalarGrid g = v.read_box({0, 0, 0}, v.dims(), opts);
  g.notes = v.notes();
  if (!g.notes.empty() && g.notes.back() == '\n') g.notes.pop_back();
  return g;
}

}  // namespace mlfe
