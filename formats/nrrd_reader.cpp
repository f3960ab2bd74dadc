#include <fmt/format.h>
#include <mlfe/core/base/vec.h>
#include <mlfe/formats/nrrd_reader.h>
#include <mlfe/formats/raw_reader.h>
#include <teem/nrrd.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <mutex>
#include <sstream>
#include <string>
#include <vector>

#include "formats/reader_helpers.h"
#include "formats/volume_formats_detail.h"

namespace mlfe {
using namespace volume_detail;

namespace {

// biff keeps its messages in global state, so all Teem calls are serialised.
std::mutex& teem_mutex() {
  static std::mutex m;
  return m;
}

std::string biff_message() {
  char* err = biffGetDone(NRRD);
  if (!err) return "unknown Teem error";
  std::string all(err);
  std::free(err);
  // biff lists the outermost caller first; the last line is the root cause.
  std::string last;
  std::size_t start = 0;
  while (start < all.size()) {
    std::size_t end = all.find('\n', start);
    if (end == std::string::npos) end = all.size();
    std::string line = all.substr(start, end - start);
    if (!line.empty()) last = line;
    start = end + 1;
  }
  if (last.rfind("[nrrd] ", 0) == 0) last = last.substr(7);
  auto colon = last.find(": ");  // drop the Teem function name
  if (colon != std::string::npos && colon < 40 && last.find(' ') >= colon) last = last.substr(colon + 2);
  return last;
}

struct NrrdDeleter {
  void operator()(Nrrd* n) const { nrrdNuke(n); }
};
struct IoDeleter {
  void operator()(NrrdIoState* n) const { nrrdIoStateNix(n); }
};

std::optional<ScalarType> teem_type(int t) {
  switch (t) {
    case nrrdTypeChar:
      return ScalarType::I8;
    case nrrdTypeUChar:
      return ScalarType::U8;
    case nrrdTypeShort:
      return ScalarType::I16;
    case nrrdTypeUShort:
      return ScalarType::U16;
    case nrrdTypeInt:
      return ScalarType::I32;
    case nrrdTypeUInt:
      return ScalarType::U32;
    case nrrdTypeFloat:
      return ScalarType::F32;
    case nrrdTypeDouble:
      return ScalarType::F64;
    default:
      return std::nullopt;
  }
}

// Length of an attached header: up to and including the first empty line.
std::optional<std::uint64_t> attached_header_length(const std::string& path) {
  std::string head = read_file_prefix(path, 1 << 20);
  std::size_t a = head.find("\n\n");
  std::size_t b = head.find("\r\n\r\n");
  if (a == std::string::npos && b == std::string::npos) return std::nullopt;
  if (b != std::string::npos && (a == std::string::npos || b < a)) return b + 4;
  return a + 2;
}

// The files a "data file:" value names, resolved against the header's folder as Teem resolves
// them: one name, "LIST" (the names follow the header, one a line) or "FORMAT MIN MAX STEP
// [SUBDIM]" with one %d conversion. `rest` is the text after the header.
std::vector<std::string> detached_files(const std::string& path, const std::string& value,
                                        const std::string& rest) {
  std::vector<std::string> names;
  if (value == "LIST") {
    std::istringstream in(rest);
    for (std::string line; std::getline(in, line);)
      if (!line.empty()) names.push_back(line.back() == '\r' ? line.substr(0, line.size() - 1) : line);
  } else if (value.find('%') != std::string::npos) {
    std::istringstream in(value);
    std::string format;
    long long lo = 0, hi = 0, step = 0;
    in >> format >> lo >> hi >> step;
    const std::size_t pct = format.find('%');
    const std::size_t conv = format.find_first_not_of("0123456789", pct + 1);
    if (!in || step == 0 || conv == std::string::npos || format[conv] != 'd' ||
        format.find('%', conv) != std::string::npos || (hi - lo) / step < 0 || (hi - lo) / step > 100000)
      fail(path, "bad NRRD header: unsupported data file format \"" + value.substr(0, 100) + "\"");
    for (long long i = lo; step > 0 ? i <= hi : i >= hi; i += step)
      names.push_back(fmt::format("{}{:0{}}{}", format.substr(0, pct), i,
                                  std::atoi(format.substr(pct + 1, conv - pct - 1).c_str()),
                                  format.substr(conv + 1)));
  } else {
    names.push_back(value);
  }
  for (auto& n : names) n = sibling_path(path, n);
  return names;
}

// Teem 1.12 formats some parse errors, quoting the offending header line, into a fixed
// 1025-byte buffer with vsprintf; a long bad line overflows it and the process aborts
// (found by fuzzing). Field lines of valid headers are short, so long ones are refused
// here. Comments are never quoted by Teem and may be long. Detached data files are checked to
// be regular files here too: Teem opens them while it parses the header, and a FIFO hung it.
// Returns the detached data files (none for attached data).
std::vector<std::string> check_header_lines(const std::string& path) {
  const std::string head = read_file_prefix(path, 1 << 20);
  std::vector<std::string> data_files;
  std::size_t start = 0;
  int number = 0;
  while (start < head.size()) {
    // Teem ends a line at '\n', '\r' or "\r\n" (a lone '\r' inside what looks like a comment
    // starts a new, quoted line: found by fuzzing), so split the same way.
    std::size_t end = head.find_first_of("\r\n", start);
    if (end == std::string::npos) end = head.size();
    std::string line = head.substr(start, end - start);
    if (end + 1 < head.size() && head[end] == '\r' && head[end + 1] == '\n') ++end;
    ++number;
    if (line.empty()) break;  // end of the header
    for (const char* key : {"data file: ", "datafile: "})
      if (line.rfind(key, 0) == 0)
        for (const std::string& f :
             detached_files(path, line.substr(std::strlen(key)), head.substr(end + 1))) {
          regular_file_size(f);
          data_files.push_back(f);
        }
    if (line[0] != '#' && line.find(":=") == std::string::npos && line.size() > 400)
      fail(path, fmt::format("bad NRRD header: line {} is {} bytes long (field lines are at most 400)",
                             number, line.size()));
    // A "key:=value" line that Teem fails to parse is quoted into the same buffer (found by
    // fuzzing: binary data after a comment line), so those are capped below its size too.
    if (line[0] != '#' && line.size() > 900)
      fail(path, fmt::format("bad NRRD header: line {} is {} bytes long (key/value lines are at most 900)",
                             number, line.size()));
    // Teem stores an absent spacing as NaN, so a written "nan" or "inf" would silently become
    // the default spacing 1; a spacing that is written must be a number.
    if (line.rfind("spacings:", 0) == 0) {
      std::string lower = line;
      std::transform(lower.begin(), lower.end(), lower.begin(),
                     [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
      if (lower.find("nan") != std::string::npos || lower.find("inf") != std::string::npos)
        fail(path, "bad NRRD header: spacings must be finite numbers (" + line + ")");
    }
    start = end + 1;
  }
  return data_files;
}

// Compares the data the header promises with what the file holds before Teem allocates: Teem
// would allocate the full array first and only then find the data short. Compressed data is
// weighed by what it decodes to (bzip2, whose ratio has no useful bound, by decoding it once
// in bounded memory), text by the fewest characters a value can take.
void check_data_size(const std::string& path, const NrrdIoState& nio_ref, std::uint64_t bytes,
                     const std::array<std::int64_t, 3>& dims, ScalarType type) {
  const NrrdIoState* nio = &nio_ref;
  const bool attached = nio->dataFNArr->len == 0 && !nio->dataFNFormat;
  if (!attached && nio->dataFNArr->len != 1) return;  // several files: each is read in turn
  // Teem keeps the name as written and opens it relative to the header's folder.
  const std::string data_file = attached ? path : sibling_path(path, nio->dataFN[0]);
  RegularFile file(data_file);
  std::uint64_t start = 0;
  if (attached) {
    const auto hl = attached_header_length(path);
    start = hl ? *hl : file.size();
  }
  const std::uint64_t avail = file.size() > start ? file.size() - start : 0;
  const NrrdEncoding* encoding = nio->encoding;
  const auto truncated = [&](const std::string& held) {
    fail(data_file, fmt::format("truncated: {} x {} x {} {} voxels need {} bytes of data, {}", dims[0],
                                dims[1], dims[2], scalar_type_name(type), bytes, held));
  };
  const std::uint64_t voxels = bytes / static_cast<std::uint64_t>(scalar_type_size(type));
  if (encoding == nrrdEncodingRaw && nio->lineSkip == 0 && nio->byteSkip >= 0) {
    const auto skip = static_cast<std::uint64_t>(nio->byteSkip);
    const std::uint64_t left = avail > skip ? avail - skip : 0;
    if (left < bytes) truncated(fmt::format("the file has {}", left));
  } else if (encoding == nrrdEncodingGzip) {
    // Deflate expands at most 1032:1.
    constexpr std::uint64_t kMaxDeflateRatio = 1032;
    if (bytes / kMaxDeflateRatio > avail + 64)
      truncated(fmt::format("more than {} bytes of gzip data can hold", avail));
  } else if (encoding == nrrdEncodingBzip2) {
    file.seek(start);
    const std::uint64_t held =
        count_bytes(decoded_source(data_file, Compression::kBzip2, file_source(file)), bytes);
    if (held < bytes) truncated(fmt::format("the bzip2 data holds {}", held));
  } else if (encoding == nrrdEncodingAscii || encoding == nrrdEncodingHex) {
    // A value as text is at least a digit and a separator; a byte in hex is two digits.
    const std::uint64_t least = encoding == nrrdEncodingHex ? 2 * bytes : 2 * voxels - 1;
    if (avail < least)
      truncated(fmt::format("more than {} bytes of {} text can hold", avail, encoding->name));
  }
}

// The index-to-physical transform: space directions and origin when the header has a space
// (RAS/LPS named; LAS converted), else per-axis spacing and min.
void read_transform(const std::string& path, const Nrrd* nrrd, unsigned dim, ScalarGrid& grid) {
  GridTransform& t = grid.transform;
  const unsigned sdim = nrrd->spaceDim;
  if (sdim > 0) {
    if (sdim > 3) fail(path, fmt::format("space dimension {} is not supported (2 or 3)", sdim));
    std::array<std::array<double, 3>, 3> axes{};
    for (unsigned a = 0; a < dim; ++a) {
      for (unsigned r = 0; r < sdim; ++r) {
        double v = nrrd->axis[a].spaceDirection[r];
        if (!std::isfinite(v)) fail(path, fmt::format("axis {} has no space direction", a));
        axes[a][r] = v;
      }
    }
    if (dim == 2) {
      // A height field in 3D space: the unused third axis is the unit normal.
      const auto& u = axes[0];
      const auto& v = axes[1];
      const Vec3 n = cross(u, v);
      axes[2] = norm(n) > 0 ? normalized(n) : Vec3{0, 0, 1};
    }
    set_axes(path, t, axes);
    for (unsigned r = 0; r < sdim; ++r) {
      double o = nrrd->spaceOrigin[r];
      t.origin[r] = std::isfinite(o) ? o : 0.0;
    }
    switch (nrrd->space) {
      case nrrdSpaceRightAnteriorSuperior:
      case nrrdSpaceRightAnteriorSuperiorTime:
        grid.space = "RAS";
        break;
      case nrrdSpaceLeftPosteriorSuperior:
      case nrrdSpaceLeftPosteriorSuperiorTime:
      case nrrdSpaceScannerXYZ:
        grid.space = "LPS";
        break;
      case nrrdSpaceLeftAnteriorSuperior:
      case nrrdSpaceLeftAnteriorSuperiorTime:
        for (int c = 0; c < 3; ++c) t.direction[c] = -t.direction[c];
        t.origin[0] = -t.origin[0];
        grid.space = "RAS";
        add_note(grid, "space left-anterior-superior converted to RAS (x negated)");
        break;
      default:
        if (nrrd->space != nrrdSpaceUnknown)
          add_note(grid, fmt::format("space \"{}\" is not RAS/LPS; coordinates kept as they are",
                                     airEnumStr(nrrdSpace, nrrd->space)));
    }
  } else {
    for (unsigned a = 0; a < dim; ++a) {
      const NrrdAxisInfo& ax = nrrd->axis[a];
      double s = std::isfinite(ax.spacing) ? ax.spacing : 1.0;
      if (s == 0.0) fail(path, fmt::format("axis {} has zero spacing", a));
      double o = std::isfinite(ax.min) ? ax.min : 0.0;
      if (std::isfinite(ax.min) && ax.center == nrrdCenterCell) o += 0.5 * s;
      // A negative spacing means the axis runs backwards.
      t.spacing[a] = std::fabs(s);
      t.direction[a * 3 + a] = s < 0 ? -1.0 : 1.0;
      t.origin[a] = o;
    }
  }
}

// The header read without the data: the frame, the Teem type and axes, and where the voxels lie
// when read_raw_box can read them (in_boxes): raw or gzip data in one file, no skipped lines.
struct NrrdHeader {
  RawLayout layout;
  int teem_type = nrrdTypeUnknown;
  unsigned dim = 0;
  bool in_boxes = false;
};

void place_data(const std::string& path, const NrrdIoState& nio, NrrdHeader& h) {
  const bool attached = nio.dataFNArr->len == 0 && !nio.dataFNFormat;
  const bool gzip = nio.encoding == nrrdEncodingGzip;
  if ((!attached && (nio.dataFNArr->len != 1 || nio.dataFNFormat)) || nio.lineSkip != 0 ||
      (nio.encoding != nrrdEncodingRaw && !gzip) || nio.byteSkip < 0 || (gzip && nio.byteSkip != 0))
    return;
  RawLayout& l = h.layout;
  l.data_file = attached ? path : sibling_path(path, nio.dataFN[0]);
  std::uint64_t start = 0;
  if (attached) {
    const auto end = attached_header_length(path);
    // Teem also ends a line at a lone '\r': the header's end is certain only without any.
    if (!end || read_file_prefix(path, *end).find('\r') != std::string::npos) return;
    start = *end;
  }
  if (gzip) {
    l.packing = Compression::kGzip;
    l.packed_at = start;
  } else {
    l.offset = start + static_cast<std::uint64_t>(nio.byteSkip);
  }
  l.swap = scalar_type_size(l.frame.source_type) > 1 && nio.endian != airMyEndian();
  h.in_boxes = true;
}

NrrdHeader read_header(const std::string& path) {
  std::string magic = read_file_prefix(path, 8);
  if (magic.rfind("NRRD000", 0) != 0) fail(path, "not a NRRD file (no NRRD000x magic)");
  if (magic.size() < 8 || magic[7] < '1' || magic[7] > '5')
    fail(path, "unsupported NRRD version " + magic.substr(0, 8));

  check_header_lines(path);

  std::lock_guard<std::mutex> lock(teem_mutex());
  nrrdStateVerboseIO = 0;
  std::unique_ptr<Nrrd, NrrdDeleter> header(nrrdNew());
  std::unique_ptr<NrrdIoState, IoDeleter> nio(nrrdIoStateNew());
  nio->skipData = AIR_TRUE;
  if (nrrdLoad(header.get(), path.c_str(), nio.get())) fail(path, "bad NRRD header: " + biff_message());

  const unsigned dim = header->dim;
  if (dim != 2 && dim != 3)
    fail(path,
         fmt::format("NRRD has {} axes; only 2D height fields and 3D scalar volumes are supported", dim));
  auto type = teem_type(header->type);
  if (!type) fail(path, fmt::format("unsupported NRRD type {}", airEnumStr(nrrdType, header->type)));
  std::array<std::int64_t, 3> dims{1, 1, 1};
  for (unsigned a = 0; a < dim; ++a) {
    std::size_t s = header->axis[a].size;
    dims[a] = s > static_cast<std::size_t>(INT64_MAX) ? -1 : static_cast<std::int64_t>(s);
  }
  const std::int64_t voxels = checked_voxel_count(path, dims);
  const int esize = scalar_type_size(*type);
  const std::uint64_t bytes = checked_bytes(path, voxels, static_cast<std::uint64_t>(esize));
  check_data_size(path, *nio, bytes, dims, *type);

  NrrdHeader h;
  h.teem_type = header->type;
  h.dim = dim;
  ScalarGrid& grid = h.layout.frame;
  grid.dims = dims;
  grid.source_type = *type;
  read_transform(path, header.get(), dim, grid);
  const std::string encoding = nio->encoding ? nio->encoding->name : "";
  if (encoding != "raw") add_note(grid, "NRRD encoding " + encoding);
  place_data(path, *nio, h);
  return h;
}

}  // namespace

namespace volume_detail {

std::vector<std::string> nrrd_companions(const std::string& path) { return check_header_lines(path); }

}  // namespace volume_detail

std::optional<RawLayout> nrrd_layout(const std::string& path, const VolumeReadOptions&) {
  NrrdHeader h = read_header(path);
  if (!h.in_boxes) return std::nullopt;
  return std::move(h.layout);
}

ScalarGrid read_nrrd(const std::string& path, const VolumeReadOptions& opts) {
  NrrdHeader h = read_header(path);
  ScalarGrid& grid = h.layout.frame;
  check_memory_for_copy(path, h.layout, opts, "the NRRD data and the float32 grid");

  std::lock_guard<std::mutex> lock(teem_mutex());
  std::unique_ptr<Nrrd, NrrdDeleter> nrrd(nrrdNew());
  if (nrrdLoad(nrrd.get(), path.c_str(), nullptr)) fail(path, biff_message());
  if (nrrd->dim != h.dim || nrrd->type != h.teem_type || !nrrd->data)
    fail(path, "NRRD header changed between reads");
  for (unsigned a = 0; a < h.dim; ++a)
    if (static_cast<std::int64_t>(nrrd->axis[a].size) != grid.dims[a])
      fail(path, "NRRD header changed between reads");

  allocate_values(grid);
  convert_to_float(nrrd->data, grid.source_type, false, grid.values.data(), grid.values.size());
  return std::move(grid);
}

}  // namespace mlfe
