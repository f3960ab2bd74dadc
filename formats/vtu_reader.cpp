// VTK XML UnstructuredGrid (.vtu) reader for tetrahedral meshes with point values, after the
// "VTK File Formats" document (XML formats: DataArray encodings, the binary header of UInt32 or
// UInt64 words, vtkZLibDataCompressor blocks, AppendedData). The XML is parsed with expat; raw
// appended data is not XML, so expat sees the document up to the AppendedData start tag only.
#include <expat.h>
#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cstring>
#include <limits>
#include <optional>
#include <type_traits>
#include <vector>

#include "formats/reader_helpers.h"
#include "formats/tet_mesh_reader_detail.h"

namespace mlfe::tet_mesh_detail {

using volume_detail::fail;

namespace {

struct Array {
  std::string section;  // PointData, Points, Cells, CellData, ...
  std::string name, type, format;
  int components = 1;
  std::optional<std::uint64_t> offset;
  std::string text;  // inline ascii / base64 content
};

struct Document {
  std::string file_type, byte_order = "LittleEndian", header_type = "UInt32", compressor;
  int pieces = 0;
  std::string points_text, cells_text;  // of the first Piece
  std::vector<Array> arrays;
  std::string appended_encoding;
  bool in_appended = false;
  std::vector<std::string> stack;
  int array_open = -1;  // index of the DataArray being read, -1 outside
  std::string error;
  XML_Parser parser = nullptr;
};

const char* attribute(const XML_Char** atts, const char* name) {
  for (int i = 0; atts[i]; i += 2)
    if (std::strcmp(atts[i], name) == 0) return atts[i + 1];
  return nullptr;
}

void stop(Document& d, const std::string& message) {
  if (d.error.empty()) d.error = message;
  XML_StopParser(d.parser, XML_FALSE);
}

void XMLCALL on_start(void* user, const XML_Char* name, const XML_Char** atts) {
  Document& d = *static_cast<Document*>(user);
  const std::string n = name;
  const std::string parent = d.stack.empty() ? "" : d.stack.back();
  d.stack.push_back(n);
  if (n == "VTKFile") {
    if (const char* t = attribute(atts, "type")) d.file_type = t;
    if (const char* b = attribute(atts, "byte_order")) d.byte_order = b;
    if (const char* h = attribute(atts, "header_type")) d.header_type = h;
    if (const char* c = attribute(atts, "compressor")) d.compressor = c;
  } else if (n == "Piece") {
    if (++d.pieces > 1) return stop(d, "more than one Piece (only single-piece files are read)");
    const char* p = attribute(atts, "NumberOfPoints");
    const char* c = attribute(atts, "NumberOfCells");
    if (!p || !c) return stop(d, "Piece without NumberOfPoints or NumberOfCells");
    d.points_text = p;
    d.cells_text = c;
  } else if (n == "AppendedData") {
    const char* e = attribute(atts, "encoding");
    d.appended_encoding = e ? e : "base64";
    d.in_appended = true;
  } else if (n == "DataArray") {
    if (d.pieces != 1) return;  // outside the Piece (e.g. FieldData)
    Array a;
    a.section = parent;
    if (const char* v = attribute(atts, "Name")) a.name = v;
    if (const char* v = attribute(atts, "type")) a.type = v;
    const char* f = attribute(atts, "format");
    a.format = f ? f : "ascii";
    if (const char* v = attribute(atts, "NumberOfComponents")) {
      int c = 0;
      const char* end = v + std::strlen(v);
      if (std::from_chars(v, end, c).ptr != end || c < 1 || c > 1024)
        return stop(d, fmt::format("DataArray {}: bad NumberOfComponents '{}'", a.name, v));
      a.components = c;
    }
    if (const char* v = attribute(atts, "offset")) {
      std::uint64_t o = 0;
      const char* end = v + std::strlen(v);
      if (std::from_chars(v, end, o).ptr != end)
        return stop(d, fmt::format("DataArray {}: bad offset '{}'", a.name, v));
      a.offset = o;
    }
    d.arrays.push_back(std::move(a));
    d.array_open = int(d.arrays.size()) - 1;
  }
}

void XMLCALL on_end(void* user, const XML_Char*) {
  Document& d = *static_cast<Document*>(user);
  if (!d.stack.empty()) {
    if (d.stack.back() == "DataArray") d.array_open = -1;
    d.stack.pop_back();
  }
}

void XMLCALL on_text(void* user, const XML_Char* s, int len) {
  Document& d = *static_cast<Document*>(user);
  if (d.array_open >= 0 && d.arrays[std::size_t(d.array_open)].format != "appended")
    d.arrays[std::size_t(d.array_open)].text.append(s, std::size_t(len));
}

std::uint64_t parse_count(const std::string& path, const std::string& text, const char* what) {
  std::uint64_t n = 0;
  const char* end = text.data() + text.size();
  if (text.empty() || std::from_chars(text.data(), end, n).ptr != end || n > (std::uint64_t(1) << 40))
    fail(path, fmt::format("bad {} '{}'", what, text.substr(0, 40)));
  return n;
}

int type_size(const std::string& t) {
  if (t == "Int8" || t == "UInt8") return 1;
  if (t == "Int16" || t == "UInt16") return 2;
  if (t == "Int32" || t == "UInt32" || t == "Float32") return 4;
  if (t == "Int64" || t == "UInt64" || t == "Float64") return 8;
  return 0;
}

// Base64 text without whitespace.
class Base64 {
 public:
  explicit Base64(std::string chars) : s_(std::move(chars)) {}
  std::size_t size() const { return s_.size(); }
  char at(std::size_t i) const { return s_[i]; }
  // Decodes the characters [from, from + count) (count a multiple of 4) into out.
  bool decode(std::size_t from, std::size_t count, std::vector<unsigned char>& out) const {
    if (count % 4 || from > s_.size() || count > s_.size() - from) return false;
    out.clear();
    out.reserve(count / 4 * 3);
    for (std::size_t i = from; i < from + count; i += 4) {
      int v[4];
      int pad = 0;
      for (int k = 0; k < 4; ++k) {
        const char c = s_[i + k];
        if (c == '=') {
          if (k < 2) return false;
          v[k] = 0;
          ++pad;
        } else {
          if (pad) return false;
          v[k] = sextet(c);
          if (v[k] < 0) return false;
        }
      }
      const std::uint32_t w = std::uint32_t(v[0]) << 18 | std::uint32_t(v[1]) << 12 |
                              std::uint32_t(v[2]) << 6 | std::uint32_t(v[3]);
      out.push_back(static_cast<unsigned char>(w >> 16));
      if (pad < 2) out.push_back(static_cast<unsigned char>(w >> 8));
      if (pad < 1) out.push_back(static_cast<unsigned char>(w));
    }
    return true;
  }

 private:
  static int sextet(char c) {
    if (c >= 'A' && c <= 'Z') return c - 'A';
    if (c >= 'a' && c <= 'z') return c - 'a' + 26;
    if (c >= '0' && c <= '9') return c - '0' + 52;
    if (c == '+') return 62;
    if (c == '/') return 63;
    return -1;
  }
  std::string s_;
};

std::string without_space(const char* p, const char* end) {
  std::string s;
  s.reserve(std::size_t(end - p));
  for (; p < end && *p != '<'; ++p)
    if (!std::isspace(static_cast<unsigned char>(*p))) s += *p;
  return s;
}

class Reader {
 public:
  Reader(const std::string& path, const std::string& data, const TetMeshReadOptions& options,
         std::uint64_t limit)
      : path_(path), data_(data), options_(options), limit_(limit) {}

  TetMesh read() {
    parse_xml();
    if (doc_.file_type != "UnstructuredGrid")
      fail(path_, fmt::format("a VTK XML '{}' file; only UnstructuredGrid (.vtu) is read",
                              doc_.file_type.substr(0, 40)));
    if (doc_.byte_order != "LittleEndian" && doc_.byte_order != "BigEndian")
      fail(path_, fmt::format("unknown byte_order '{}'", doc_.byte_order.substr(0, 40)));
    swap_ = (doc_.byte_order == "BigEndian") != !volume_detail::host_is_little_endian();
    if (doc_.header_type != "UInt32" && doc_.header_type != "UInt64")
      fail(path_, fmt::format("unknown header_type '{}' (UInt32 or UInt64)", doc_.header_type.substr(0, 40)));
    header_size_ = doc_.header_type == "UInt64" ? 8 : 4;
    if (!doc_.compressor.empty() && doc_.compressor != "vtkZLibDataCompressor")
      fail(path_, fmt::format("compressor {} is not supported (vtkZLibDataCompressor is)",
                              doc_.compressor.substr(0, 40)));
    if (doc_.pieces == 0) fail(path_, "no Piece");
    const std::uint64_t np = parse_count(path_, doc_.points_text, "NumberOfPoints");
    const std::uint64_t nc = parse_count(path_, doc_.cells_text, "NumberOfCells");
    check_mesh_memory(path_, np, nc, limit_);

    TetMesh m;
    const Array& pts = find("Points", "", 3, "the Points array");
    const std::vector<double> xyz = numbers<double>(pts, np * 3);
    m.points.resize(np);
    for (std::uint64_t i = 0; i < np; ++i) m.points[i] = {xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]};

    const std::vector<std::int64_t> types =
        numbers<std::int64_t>(find("Cells", "types", 1, "Cells/types"), nc);
    for (std::int64_t t : types)
      if (t != 10) fail(path_, fmt::format("only tetrahedra (VTK type 10) are supported, found type {}", t));
    const std::vector<std::int64_t> offsets =
        numbers<std::int64_t>(find("Cells", "offsets", 1, "Cells/offsets"), nc);
    for (std::uint64_t c = 0; c < nc; ++c)
      if (offsets[c] != std::int64_t(4 * (c + 1)))
        fail(path_,
             fmt::format("cell {}: offset {} where a tetrahedron ends at {}", c, offsets[c], 4 * (c + 1)));
    const std::vector<std::int64_t> conn =
        numbers<std::int64_t>(find("Cells", "connectivity", 1, "Cells/connectivity"), 4 * nc);
    m.tets.resize(nc);
    for (std::uint64_t c = 0; c < nc; ++c)
      for (int k = 0; k < 4; ++k) {
        const std::int64_t v = conn[4 * c + k];
        if (v < 0 || std::uint64_t(v) >= np)
          fail(path_, fmt::format("cell {} has point index {} out of range ({} points)", c, v, np));
        m.tets[c][k] = static_cast<std::int32_t>(v);
      }

    const Array* values = nullptr;
    for (const Array& a : doc_.arrays) {
      if (a.section != "PointData") continue;
      if (!options_.array_name.empty() ? a.name == options_.array_name : a.components == 1) {
        values = &a;
        break;
      }
    }
    if (!values)
      fail(path_, options_.array_name.empty()
                      ? std::string("no scalar (1-component) point-data array to read as the values")
                      : fmt::format("no point-data array named '{}'", options_.array_name));
    if (values->components != 1)
      fail(path_, fmt::format("point-data array '{}' has {} components; a scalar one is needed", values->name,
                              values->components));
    m.values = numbers<double>(*values, np);
    m.value_name = values->name;
    m.source = path_;
    return m;
  }

 private:
  void parse_xml() {
    std::string xml;
    const std::size_t tag = data_.find("<AppendedData");
    if (tag != std::string::npos) {
      const std::size_t close = data_.find('>', tag);
      if (close == std::string::npos) fail(path_, "truncated AppendedData tag");
      const bool empty = data_[close - 1] == '/';
      // expat never sees the end of the file, so its closing tags are checked here: a file cut
      // inside them may have lost appended bytes, too.
      std::size_t end = data_.find_last_not_of(" \t\r\n");
      const auto ends_with = [&](const char* t) {
        const std::size_t n = std::strlen(t);
        if (end == std::string::npos || end + 1 < n || data_.compare(end + 1 - n, n, t) != 0) return false;
        end = end + 1 - n == 0 ? std::string::npos : data_.find_last_not_of(" \t\r\n", end - n);
        return true;
      };
      if (!ends_with("</VTKFile>") || (!empty && !ends_with("</AppendedData>")))
        fail(path_, empty ? "truncated: the file does not end with </VTKFile>"
                          : "truncated: the file does not end with </AppendedData></VTKFile>");
      xml = data_.substr(0, close + 1) + (empty ? "</VTKFile>" : "</AppendedData></VTKFile>");
      const std::size_t mark = data_.find('_', close);
      if (mark != std::string::npos) appended_ = mark + 1;
    }
    const std::string& text = tag != std::string::npos ? xml : data_;
    XML_Parser p = XML_ParserCreate(nullptr);
    if (!p) fail(path_, "out of memory for the XML parser");
    doc_.parser = p;
    XML_SetUserData(p, &doc_);
    XML_SetElementHandler(p, on_start, on_end);
    XML_SetCharacterDataHandler(p, on_text);
    const XML_Status st =
        XML_Parse(p, text.data(), int(std::min<std::size_t>(text.size(), INT32_MAX)), XML_TRUE);
    std::string error;
    if (!doc_.error.empty())
      error = doc_.error;
    else if (st != XML_STATUS_OK || text.size() > INT32_MAX)
      error = fmt::format("XML error at line {}: {}", XML_GetCurrentLineNumber(p),
                          XML_ErrorString(XML_GetErrorCode(p)));
    XML_ParserFree(p);
    if (!error.empty()) fail(path_, error);
  }

  const Array& find(const char* section, const char* name, int components, const char* what) const {
    for (const Array& a : doc_.arrays)
      if (a.section == section && (!*name || a.name == name)) {
        if (a.components != components)
          fail(path_, fmt::format("{} has {} components, not {}", what, a.components, components));
        return a;
      }
    fail(path_, fmt::format("no {} array", what));
  }

  std::uint64_t word(const unsigned char* p) const {
    unsigned char b[8];
    std::memcpy(b, p, std::size_t(header_size_));
    if (swap_) std::reverse(b, b + header_size_);
    if (header_size_ == 4) {
      std::uint32_t v;
      std::memcpy(&v, b, 4);
      return v;
    }
    std::uint64_t v;
    std::memcpy(&v, b, 8);
    return v;
  }

  // The array's bytes, decompressed; `bytes` is the size the counts call for.
  std::vector<unsigned char> payload(const Array& a, std::uint64_t bytes) const {
    const std::string what = a.name.empty() ? std::string("DataArray") : "DataArray " + a.name;
    const bool appended = a.format == "appended";
    if (appended && !a.offset) fail(path_, what + ": appended without an offset");
    if (appended && !appended_) fail(path_, what + ": appended, but the file has no AppendedData");
    const bool raw = appended && doc_.appended_encoding == "raw";
    if (appended && !raw && doc_.appended_encoding != "base64")
      fail(path_, fmt::format("unknown AppendedData encoding '{}'", doc_.appended_encoding.substr(0, 40)));
    const bool compressed = !doc_.compressor.empty();
    const std::uint64_t hs = std::uint64_t(header_size_);
    std::vector<unsigned char> out;

    if (raw) {
      const std::uint64_t start = *appended_;
      if (*a.offset > data_.size() - start) fail(path_, what + ": offset past the end of the file");
      const unsigned char* p = reinterpret_cast<const unsigned char*>(data_.data()) + start + *a.offset;
      const std::uint64_t avail = data_.size() - start - *a.offset;
      if (!compressed) {
        if (avail < hs) fail(path_, what + ": truncated");
        const std::uint64_t n = word(p);
        if (n != bytes) fail(path_, fmt::format("{}: {} bytes where {} are expected", what, n, bytes));
        if (n > avail - hs) fail(path_, what + ": truncated");
        out.assign(p + hs, p + hs + n);
        return out;
      }
      if (avail < 3 * hs) fail(path_, what + ": truncated");
      const std::uint64_t nb = word(p);
      if (nb > (avail - 3 * hs) / hs) fail(path_, what + ": truncated block table");
      std::vector<unsigned char> header(p, p + (3 + nb) * hs);
      const std::uint64_t used = (3 + nb) * hs;
      inflate_blocks(what, header, p + used, avail - used, bytes, out);
      return out;
    }

    // Base64: inline text, or appended characters from the offset on.
    Base64 b64 = [&] {
      if (!appended) return Base64(without_space(a.text.data(), a.text.data() + a.text.size()));
      const std::uint64_t start = *appended_;
      if (*a.offset > data_.size() - start) fail(path_, what + ": offset past the end of the file");
      return Base64(without_space(data_.data() + start + *a.offset, data_.data() + data_.size()));
    }();
    // VTK encodes the header and the data separately, each padded; a header that is a multiple
    // of 3 bytes looks the same either way, otherwise padding ('=') at its end tells.
    std::vector<unsigned char> head;
    const std::uint64_t first = compressed ? 3 * hs : hs;
    if (!b64.decode(0, (first + 2) / 3 * 4, head) || head.size() < first)
      fail(path_, what + ": bad base64 data");
    std::uint64_t header_bytes = hs, data_bytes = 0;
    if (compressed) {
      const std::uint64_t nb = word(head.data());
      if (nb > b64.size() / hs) fail(path_, what + ": truncated block table");
      header_bytes = (3 + nb) * hs;
    }
    const std::uint64_t header_chars = (header_bytes + 2) / 3 * 4;
    if (header_chars > b64.size()) fail(path_, what + ": truncated");
    const bool separate = header_bytes % 3 != 0 && b64.at(std::size_t(header_chars - 1)) == '=';
    if (!b64.decode(0, header_chars, head) || head.size() < header_bytes)
      fail(path_, what + ": bad base64 data");
    if (compressed) {
      const std::uint64_t nb = word(head.data());
      for (std::uint64_t i = 0; i < nb; ++i) {
        const std::uint64_t c = word(head.data() + (3 + i) * hs);
        if (c > b64.size()) fail(path_, what + ": truncated");
        data_bytes += c;
      }
    } else {
      data_bytes = word(head.data());
      if (data_bytes != bytes)
        fail(path_, fmt::format("{}: {} bytes where {} are expected", what, data_bytes, bytes));
    }
    if (data_bytes > b64.size()) fail(path_, what + ": truncated");
    std::vector<unsigned char> body;
    if (separate) {
      if (!b64.decode(std::size_t(header_chars), std::size_t((data_bytes + 2) / 3 * 4), body) ||
          body.size() < data_bytes)
        fail(path_, what + ": bad or truncated base64 data");
    } else {
      if (!b64.decode(0, std::size_t((header_bytes + data_bytes + 2) / 3 * 4), body) ||
          body.size() < header_bytes + data_bytes)
        fail(path_, what + ": bad or truncated base64 data");
      body.erase(body.begin(), body.begin() + std::ptrdiff_t(header_bytes));
    }
    body.resize(std::size_t(data_bytes));
    if (!compressed) return body;
    head.resize(std::size_t(header_bytes));
    inflate_blocks(what, head, body.data(), body.size(), bytes, out);
    return out;
  }

  // vtkZLibDataCompressor: header [blocks, block size, last block size, compressed sizes...].
  void inflate_blocks(const std::string& what, const std::vector<unsigned char>& header,
                      const unsigned char* p, std::uint64_t avail, std::uint64_t bytes,
                      std::vector<unsigned char>& out) const {
    const std::uint64_t hs = std::uint64_t(header_size_);
    const std::uint64_t nb = word(header.data()), bs = word(header.data() + hs),
                        last = word(header.data() + 2 * hs);
    std::uint64_t total = 0;
    if (nb > 0) {
      const std::uint64_t tail = last ? last : bs;
      if (last > bs || (nb - 1) > bytes || (bs && nb - 1 > bytes / bs))
        fail(path_, what + ": inconsistent compressed block sizes");
      total = (nb - 1) * bs + tail;
    }
    if (total != bytes) fail(path_, fmt::format("{}: {} bytes where {} are expected", what, total, bytes));
    // Block by block, each inflated into memory that grows with its data: a header claiming
    // gigabytes over a few compressed bytes fails at its first block.
    std::uint64_t pos = 0;
    for (std::uint64_t b = 0; b < nb; ++b) {
      const std::uint64_t c = word(header.data() + (3 + b) * hs);
      const std::uint64_t want = b + 1 == nb && last ? last : bs;
      if (c > avail - pos) fail(path_, what + ": truncated compressed data");
      std::vector<unsigned char> block;
      try {
        block = inflate_exactly(path_, p + pos, std::size_t(c), want);
      } catch (const Error&) {
        fail(path_, fmt::format("{}: corrupt zlib block {}", what, b));
      }
      out.insert(out.end(), block.begin(), block.end());
      pos += c;
    }
  }

  // `count` values of the array as T (double for coordinates and values, int64 for cells).
  template <class T>
  std::vector<T> numbers(const Array& a, std::uint64_t count) const {
    const std::string what = a.name.empty() ? std::string("DataArray") : "DataArray " + a.name;
    const int size = type_size(a.type);
    if (!size) fail(path_, fmt::format("{}: unsupported type '{}'", what, a.type.substr(0, 40)));
    const bool is_float = a.type[0] == 'F';
    if (std::is_integral_v<T> && is_float) fail(path_, what + ": cell arrays must have an integer type");
    std::vector<T> out;
    if (a.format == "ascii") {
      if (count > a.text.size()) fail(path_, fmt::format("{}: fewer than {} values", what, count));
      out.resize(std::size_t(count));
      const char* p = a.text.data();
      const char* end = p + a.text.size();
      for (std::uint64_t i = 0; i < count; ++i) {
        bool ok;
        if constexpr (std::is_integral_v<T>) {
          ok = next_number(p, end, out[i]);
        } else if (is_float) {
          ok = next_number(p, end, out[i]);
        } else {
          std::int64_t v = 0;
          ok = next_number(p, end, v);
          out[i] = T(v);
        }
        if (!ok) fail(path_, fmt::format("{}: value {} is missing or not a number", what, i));
      }
      return out;
    }
    if (a.format != "binary" && a.format != "appended")
      fail(path_, fmt::format("{}: unknown format '{}'", what, a.format.substr(0, 40)));
    const std::vector<unsigned char> bytes = payload(a, count * std::uint64_t(size));
    out.resize(std::size_t(count));
    for (std::uint64_t i = 0; i < count; ++i) {
      unsigned char b[8];
      std::memcpy(b, bytes.data() + i * std::uint64_t(size), std::size_t(size));
      if (swap_) std::reverse(b, b + size);
      out[i] = convert<T>(a.type, b);
    }
    return out;
  }

  template <class T>
  static T convert(const std::string& t, const unsigned char* b) {
    const auto get = [b](auto v) {
      std::memcpy(&v, b, sizeof(v));
      return v;
    };
    if (t == "Float64") return T(get(double()));
    if (t == "Float32") return T(get(float()));
    if (t == "Int8") return T(get(std::int8_t()));
    if (t == "UInt8") return T(get(std::uint8_t()));
    if (t == "Int16") return T(get(std::int16_t()));
    if (t == "UInt16") return T(get(std::uint16_t()));
    if (t == "Int32") return T(get(std::int32_t()));
    if (t == "UInt32") return T(get(std::uint32_t()));
    if (t == "Int64") return T(get(std::int64_t()));
    const std::uint64_t u = get(std::uint64_t());
    if constexpr (std::is_integral_v<T>)  // beyond int64 is out of any index range anyway
      return u > std::uint64_t(std::numeric_limits<std::int64_t>::max()) ? T(-1) : T(u);
    else
      return T(u);
  }

  const std::string& path_;
  const std::string& data_;
  const TetMeshReadOptions& options_;
  std::uint64_t limit_;
  Document doc_;
  std::optional<std::uint64_t> appended_;
  bool swap_ = false;
  int header_size_ = 4;
};

}  // namespace

TetMesh read_vtu(const std::string& path, const std::string& data, const TetMeshReadOptions& options,
                 std::uint64_t memory_limit) {
  return Reader(path, data, options, memory_limit).read();
}

}  // namespace mlfe::tet_mesh_detail
