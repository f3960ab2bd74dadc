#include <fmt/format.h>
#include <mlfe/formats/metaimage_reader.h>
#include <mlfe/formats/raw_reader.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstring>
#include <fstream>
#include <functional>
#include <map>
#include <sstream>
#include <vector>

#include "formats/reader_helpers.h"
#include "formats/volume_formats_detail.h"

namespace mlfe {
using namespace volume_detail;

namespace {

std::string trim(const std::string& s) {
  std::size_t b = 0, e = s.size();
  while (b < e && std::isspace(static_cast<unsigned char>(s[b]))) ++b;
  while (e > b && std::isspace(static_cast<unsigned char>(s[e - 1]))) --e;
  return s.substr(b, e - b);
}

std::string lower(std::string s) {
  for (auto& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

std::vector<double> numbers(const std::string& path, const std::string& key, const std::string& value,
                            std::size_t count) {
  std::vector<double> v;
  const char* p = value.c_str();
  while (*p) {
    while (*p && std::isspace(static_cast<unsigned char>(*p))) ++p;
    if (!*p) break;
    char* end = nullptr;
    double d = std::strtod(p, &end);
    if (end == p || !std::isfinite(d))
      fail(path, fmt::format("MetaImage {} has a bad number in \"{}\"", key, value));
    v.push_back(d);
    p = end;
  }
  if (v.size() != count)
    fail(path, fmt::format("MetaImage {} needs {} numbers, has {}", key, count, v.size()));
  return v;
}

bool truthy(const std::string& v) {
  std::string l = lower(v);
  return l == "true" || l == "1" || l == "yes";
}

std::optional<ScalarType> met_type(const std::string& t) {
  if (t == "MET_UCHAR") return ScalarType::U8;
  if (t == "MET_CHAR") return ScalarType::I8;
  if (t == "MET_USHORT") return ScalarType::U16;
  if (t == "MET_SHORT") return ScalarType::I16;
  if (t == "MET_UINT") return ScalarType::U32;
  if (t == "MET_INT") return ScalarType::I32;
  if (t == "MET_FLOAT") return ScalarType::F32;
  if (t == "MET_DOUBLE") return ScalarType::F64;
  return std::nullopt;
}

// A header entry, nullptr when absent.
using Header = std::function<const std::string*(const char* key)>;

// The header: "Key = Value" lines, ended by ElementDataFile; `header_end` is where the data of
// a LOCAL file starts.
std::map<std::string, std::string> read_header(const std::string& path, std::istream& in,
                                               std::uint64_t& header_end) {
  std::map<std::string, std::string> h;
  std::string line;
  bool ended = false;
  for (int n = 0; n < 1000 && std::getline(in, line); ++n) {
    if (line.size() > 65536) fail(path, "MetaImage header line is too long");
    auto eq = line.find('=');
    if (eq == std::string::npos) {
      if (trim(line).empty()) continue;
      fail(path, fmt::format("bad MetaImage header line {}: no '='", n + 1));
    }
    std::string key = trim(line.substr(0, eq));
    h[key] = trim(line.substr(eq + 1));
    if (key == "ElementDataFile") {
      ended = true;
      header_end = static_cast<std::uint64_t>(in.tellg());
      break;
    }
  }
  if (!ended) fail(path, "not a MetaImage header or truncated (no ElementDataFile line)");
  return h;
}

// Spacing, origin and the direction of each index axis (ITK's names and their synonyms).
void read_transform(const std::string& path, const Header& get, int ndims, GridTransform& t) {
  const std::string* sp = get("ElementSpacing");
  if (!sp) sp = get("ElementSize");
  if (sp) {
    auto s = numbers(path, "ElementSpacing", *sp, static_cast<std::size_t>(ndims));
    for (int a = 0; a < ndims; ++a) t.spacing[a] = s[a];
  }
  for (const char* key : {"Offset", "Origin", "Position"}) {
    if (auto o = get(key)) {
      auto v = numbers(path, key, *o, static_cast<std::size_t>(ndims));
      for (int a = 0; a < ndims; ++a) t.origin[a] = v[a];
      break;
    }
  }
  for (const char* key : {"TransformMatrix", "Rotation", "Orientation"}) {
    if (auto m = get(key)) {
      auto v = numbers(path, key, *m, static_cast<std::size_t>(ndims * ndims));
      // ITK writes the direction of index axis a as the a-th group of NDims numbers.
      std::array<std::array<double, 3>, 3> axes{};
      axes[2] = {0, 0, 1};
      for (int a = 0; a < ndims; ++a)
        for (int r = 0; r < ndims; ++r) axes[a][r] = v[a * ndims + r] * t.spacing[a];
      if (ndims == 2) axes[2][2] = t.spacing[2];
      if (t.spacing[0] > 0 && t.spacing[1] > 0 && t.spacing[2] > 0) set_axes(path, t, axes);
      break;
    }
  }
}

// The file that holds the data: `path` itself for ElementDataFile LOCAL, else the one file it
// names beside the header.
std::string data_file_of(const std::string& path, const std::string& edf) {
  if (edf == "LOCAL" || edf == "Local" || edf == "local") return path;
  if (edf.empty() || edf.rfind("LIST", 0) == 0 || edf.find('%') != std::string::npos)
    fail(path, "MetaImage ElementDataFile \"" + edf + "\" is not supported (LOCAL or one file)");
  return sibling_path(path, edf);
}

// The header of the MetaImage at `path` and where its LOCAL data starts.
std::map<std::string, std::string> read_header(const std::string& path, std::uint64_t& header_end) {
  regular_file_size(path);
  std::ifstream in(path, std::ios::binary);
  if (!in) fail(path, "cannot open");
  return read_header(path, in, header_end);
}

}  // namespace

namespace volume_detail {

std::vector<std::string> metaimage_companions(const std::string& path) {
  std::uint64_t header_end = 0;
  const std::map<std::string, std::string> h = read_header(path, header_end);
  const std::string data_file = data_file_of(path, h.at("ElementDataFile"));
  if (data_file == path) return {};
  return {data_file};
}

}  // namespace volume_detail

RawLayout metaimage_layout(const std::string& path, const VolumeReadOptions&) {
  std::uint64_t header_end = 0;
  const std::map<std::string, std::string> h = read_header(path, header_end);
  const Header get = [&h](const char* key) -> const std::string* {
    auto it = h.find(key);
    return it == h.end() ? nullptr : &it->second;
  };
  if (auto ot = get("ObjectType"); ot && *ot != "Image")
    fail(path, "MetaImage ObjectType is " + *ot + ", not Image");
  const std::string* nd = get("NDims");
  if (!nd) fail(path, "MetaImage header has no NDims");
  const int ndims = nd->size() == 1 && (*nd)[0] >= '1' && (*nd)[0] <= '9' ? (*nd)[0] - '0' : -1;
  if (ndims != 2 && ndims != 3) fail(path, "MetaImage NDims must be 2 or 3, not " + *nd);
  const std::string* ds = get("DimSize");
  if (!ds) fail(path, "MetaImage header has no DimSize");
  auto dv = numbers(path, "DimSize", *ds, static_cast<std::size_t>(ndims));
  std::array<std::int64_t, 3> dims{1, 1, 1};
  for (int a = 0; a < ndims; ++a) {
    if (dv[a] != std::floor(dv[a]) || dv[a] < 1 || dv[a] > 2147483647.0)
      fail(path, fmt::format("MetaImage DimSize {} is not a positive integer", dv[a]));
    dims[a] = static_cast<std::int64_t>(dv[a]);
  }
  const std::int64_t voxels = checked_voxel_count(path, dims);
  const std::string* et = get("ElementType");
  if (!et) fail(path, "MetaImage header has no ElementType");
  auto type = met_type(*et);
  if (!type) fail(path, "unsupported MetaImage ElementType " + *et);
  if (auto ch = get("ElementNumberOfChannels"); ch && trim(*ch) != "1")
    fail(path, "MetaImage with " + *ch + " channels is not supported (scalar images only)");
  bool msb = false;
  if (auto b = get("ElementByteOrderMSB")) msb = truthy(*b);
  if (auto b = get("BinaryDataByteOrderMSB")) msb = truthy(*b);
  if (auto b = get("BinaryData"); b && !truthy(*b))
    fail(path, "ASCII MetaImage data (BinaryData = False) is not supported");
  const bool compressed = get("CompressedData") && truthy(*get("CompressedData"));

  RawLayout layout;
  ScalarGrid& grid = layout.frame;
  GridTransform& t = grid.transform;
  read_transform(path, get, ndims, t);
  grid.space = "LPS";

  // Data location.
  const std::string data_file = data_file_of(path, *get("ElementDataFile"));
  std::uint64_t offset = data_file == path ? header_end : 0;
  const std::uint64_t dsize = regular_file_size(data_file);
  const int esize = scalar_type_size(*type);
  const std::uint64_t bytes = checked_bytes(path, voxels, static_cast<std::uint64_t>(esize));
  if (auto hs = get("HeaderSize")) {
    char* end = nullptr;
    long long v = std::strtoll(hs->c_str(), &end, 10);
    if (end == hs->c_str() || v < -1) fail(path, "bad MetaImage HeaderSize " + *hs);
    if (v == -1) {
      if (compressed) fail(path, "HeaderSize = -1 cannot be used with compressed data");
      if (dsize < bytes)
        fail(data_file, fmt::format("truncated: needs {} bytes of data, the file has {}", bytes, dsize));
      offset = dsize - bytes;
    } else if (data_file != path) {
      offset = static_cast<std::uint64_t>(v);
    } else if (__builtin_add_overflow(offset, static_cast<std::uint64_t>(v), &offset)) {
      fail(path, "bad MetaImage HeaderSize");
    }
  }
  const std::uint64_t avail = dsize > offset ? dsize - offset : 0;
  grid.dims = dims;
  grid.source_type = *type;
  layout.data_file = data_file;
  layout.swap = msb == host_is_little_endian();
  if (!compressed) {
    if (avail < bytes)
      fail(data_file, fmt::format("truncated: {} x {} x {} {} voxels need {} bytes of data, the file has {}",
                                  dims[0], dims[1], dims[2], *et, bytes, avail));
    layout.offset = offset;
    return layout;
  }
  // Compressed: a zlib stream that must inflate to exactly `bytes`.
  layout.packing = Compression::kZlib;
  layout.packed_at = offset;
  layout.packed_exactly = true;
  add_note(grid, "zlib-compressed MetaImage");
  return layout;
}

ScalarGrid read_metaimage(const std::string& path, const VolumeReadOptions& opts) {
  RawLayout layout = metaimage_layout(path, opts);
  ScalarGrid& grid = layout.frame;
  const std::uint64_t bytes = stored_bytes(path, layout);
  std::uint64_t need = checked_bytes(path, grid.voxel_count(), 4);
  if (!layout.packing) {
    check_memory(path, need, opts, "the float32 grid");
    allocate_values(grid);
    RegularFile din(layout.data_file);
    din.seek(layout.offset);
    read_raw_values(layout.data_file, din, grid.source_type, layout.swap, grid.values.data(),
                    grid.values.size());
    return std::move(grid);
  }
  RegularFile din(layout.data_file);
  const std::uint64_t avail = din.size() > layout.packed_at ? din.size() - layout.packed_at : 0;
  if (__builtin_add_overflow(need, bytes, &need) || __builtin_add_overflow(need, avail, &need))
    need = UINT64_MAX;
  check_memory(path, need, opts, "the compressed data, the voxels and the float32 grid");
  std::string packed(static_cast<std::size_t>(avail), '\0');
  din.seek(layout.packed_at);
  if (din.read(packed.data(), packed.size()) != avail) fail(layout.data_file, "read error");
  const std::vector<unsigned char> raw = inflate_exactly(path, packed.data(), packed.size(), bytes);
  allocate_values(grid);
  convert_to_float(raw.data(), grid.source_type, layout.swap, grid.values.data(), grid.values.size());
  return std::move(grid);
}

}  // namespace mlfe
