// Label table readers (formats: label_table.h). One tokenizer for the text formats; the layout
// of the first data line decides the format and every later line must follow it.
#include <mlfe/core/base/error.h>
#include <mlfe/formats/file_names.h>
#include <mlfe/formats/label_table.h>
#include <mlfe/formats/safe_read.h>
#include <mlfe/formats/volume_formats.h>

#include <charconv>
#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <sstream>
#include <vector>

namespace fs = std::filesystem;

namespace mlfe {

namespace {

constexpr std::size_t kMaxTableBytes = 64u << 20;

bool parse_int(const std::string& s, long long& v) {
  const auto r = std::from_chars(s.data(), s.data() + s.size(), v);
  return r.ec == std::errc() && r.ptr == s.data() + s.size();
}

// Splits a line at blanks; a double-quoted token keeps its blanks (ITK-SNAP names).
// Returns false for an unterminated quote.
bool tokens(const std::string& line, std::vector<std::string>& out, bool& quoted) {
  out.clear();
  quoted = false;
  std::size_t i = 0;
  while (i < line.size()) {
    if (line[i] == ' ' || line[i] == '\t' || line[i] == '\r') {
      ++i;
      continue;
    }
    if (line[i] == '"') {
      const std::size_t end = line.find('"', i + 1);
      if (end == std::string::npos) return false;
      out.push_back(line.substr(i + 1, end - i - 1));
      quoted = true;
      i = end + 1;
      continue;
    }
    std::size_t j = i;
    while (j < line.size() && line[j] != ' ' && line[j] != '\t' && line[j] != '\r') ++j;
    out.push_back(line.substr(i, j - i));
    i = j;
  }
  return true;
}

class TableBuilder {
 public:
  explicit TableBuilder(const std::string& source) { table_.source = source; }
  [[noreturn]] void fail(std::size_t line, const std::string& what) const {
    throw Error(table_.source + (line ? ": line " + std::to_string(line) : std::string()) + ": " + what);
  }
  std::uint16_t label(std::size_t line, const std::string& text) const {
    long long v = 0;
    if (!parse_int(text, v)) fail(line, "label value '" + text.substr(0, 40) + "' is not an integer");
    if (v < 0 || v > 65535) fail(line, "label value " + text + " outside 0..65535");
    return static_cast<std::uint16_t>(v);
  }
  std::uint8_t component(std::size_t line, const std::string& text) const {
    long long v = 0;
    if (!parse_int(text, v) || v < 0 || v > 255)
      fail(line, "colour component '" + text.substr(0, 40) + "' is not an integer 0..255");
    return static_cast<std::uint8_t>(v);
  }
  void add(std::size_t line, std::uint16_t value, LabelEntry e) {
    if (!table_.entries.emplace(value, std::move(e)).second)
      fail(line, "label " + std::to_string(value) + " listed twice");
  }
  LabelTable done(const std::string& format) {
    if (table_.entries.empty()) fail(0, "no labels in the table");
    table_.format = format;
    return std::move(table_);
  }

 private:
  LabelTable table_;
};

LabelTable parse_json(const std::string& bytes, const std::string& source) {
  TableBuilder b(source);
  const nlohmann::json j = nlohmann::json::parse(bytes, nullptr, false);
  if (j.is_discarded()) b.fail(0, "not valid JSON");
  if (!j.is_object() || !j.contains("labels") || !j["labels"].is_array())
    b.fail(0, "expected {\"labels\": [{\"value\": N, \"name\": \"...\", \"color\": [r, g, b]}, ...]}");
  std::size_t index = 0;
  for (const auto& e : j["labels"]) {
    const std::string where = "labels[" + std::to_string(index++) + "]";
    if (!e.is_object() || !e.contains("value") || !e["value"].is_number_integer())
      b.fail(0, where + ": needs an integer \"value\"");
    const auto v = e["value"].get<long long>();
    if (v < 0 || v > 65535) b.fail(0, where + ": value " + std::to_string(v) + " outside 0..65535");
    LabelEntry entry;
    if (e.contains("name")) {
      if (!e["name"].is_string()) b.fail(0, where + ": \"name\" must be a string");
      entry.name = e["name"].get<std::string>();
    }
    if (e.contains("color")) {
      const auto& c = e["color"];
      if (!c.is_array() || (c.size() != 3 && c.size() != 4))
        b.fail(0, where + ": \"color\" must be 3 or 4 integers 0..255");
      for (std::size_t k = 0; k < c.size(); ++k) {
        if (!c[k].is_number_integer() || c[k].get<long long>() < 0 || c[k].get<long long>() > 255)
          b.fail(0, where + ": \"color\" must be 3 or 4 integers 0..255");
        entry.rgba[k] = static_cast<std::uint8_t>(c[k].get<long long>());
      }
      entry.has_color = true;
    }
    try {
      b.add(0, static_cast<std::uint16_t>(v), std::move(entry));
    } catch (const Error&) {
      b.fail(0, where + ": label " + std::to_string(v) + " listed twice");
    }
  }
  return b.done("json");
}

LabelTable parse_lut(const std::string& bytes, const std::string& source) {
  TableBuilder b(source);
  if (bytes.size() != 768)
    b.fail(0, "an MRIcron .lut holds 768 bytes (256 red, green, blue), not " + std::to_string(bytes.size()));
  for (int l = 0; l < 256; ++l) {
    LabelEntry e;
    for (int c = 0; c < 3; ++c) e.rgba[c] = static_cast<std::uint8_t>(bytes[std::size_t(c * 256 + l)]);
    e.has_color = true;
    b.add(0, static_cast<std::uint16_t>(l), std::move(e));
  }
  return b.done("mricron-lut");
}

enum class Layout { kUnknown, kItkSnap, kSixColumn, kValueName };

LabelTable parse_text(const std::string& bytes, const std::string& source, const std::string& file_name) {
  TableBuilder b(source);
  if (bytes.find('\0') != std::string::npos) b.fail(0, "not a text label table (binary data)");
  const std::string ext = lower_extension(file_name);
  Layout layout = Layout::kUnknown;
  bool slicer = ext == ".ctbl";
  std::vector<std::string> tok;
  std::size_t line_no = 0;
  std::istringstream in(bytes);
  std::string line;
  while (std::getline(in, line)) {
    ++line_no;
    std::size_t first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos) continue;
    if (line[first] == '#') {
      if (line.find("Color table file") != std::string::npos) slicer = true;
      continue;
    }
    bool quoted = false;
    if (!tokens(line, tok, quoted)) b.fail(line_no, "unterminated quoted name");
    // Step 1: the first data line decides the layout.
    bool colours = tok.size() == 6;
    for (std::size_t c = 2; colours && c < 6; ++c) {
      long long v = 0;
      colours = parse_int(tok[c], v);
    }
    const Layout here = quoted ? Layout::kItkSnap : colours ? Layout::kSixColumn : Layout::kValueName;
    if (layout == Layout::kUnknown) layout = here;
    if (here != layout && !(layout == Layout::kValueName && here == Layout::kSixColumn))
      b.fail(line_no, "line does not follow the table's layout");
    // Step 2: the entry.
    LabelEntry e;
    std::uint16_t value = 0;
    switch (layout) {
      case Layout::kItkSnap: {
        // IDX R G B A VIS MSH "LABEL"
        if (tok.size() != 8 || !quoted)
          b.fail(line_no, "expected an ITK-SNAP line: IDX R G B A VIS MSH \"LABEL\"");
        value = b.label(line_no, tok[0]);
        for (int c = 0; c < 3; ++c) e.rgba[c] = b.component(line_no, tok[1 + c]);
        char* end = nullptr;
        const double a = std::strtod(tok[4].c_str(), &end);
        if (end != tok[4].c_str() + tok[4].size() || !(a >= 0 && a <= 1))
          b.fail(line_no, "ITK-SNAP opacity '" + tok[4].substr(0, 40) + "' is not a number in [0, 1]");
        e.rgba[3] = static_cast<std::uint8_t>(std::lround(a * 255));
        e.name = tok[7];
        e.has_color = true;
        break;
      }
      case Layout::kSixColumn:
        // value name R G B A (FreeSurfer, Slicer)
        if (tok.size() != 6) b.fail(line_no, "expected 'value name R G B A'");
        value = b.label(line_no, tok[0]);
        e.name = tok[1];
        for (int c = 0; c < 3; ++c) e.rgba[c] = b.component(line_no, tok[2 + c]);
        e.rgba[3] = slicer ? b.component(line_no, tok[5]) : (b.component(line_no, tok[5]), 255);
        e.has_color = true;
        break;
      case Layout::kValueName:
        // value name [ignored columns] (MRIcron)
        if (tok.size() < 2) b.fail(line_no, "expected 'value name'");
        value = b.label(line_no, tok[0]);
        e.name = tok[1];
        break;
      case Layout::kUnknown:
        break;
    }
    b.add(line_no, value, std::move(e));
  }
  return b.done(layout == Layout::kItkSnap     ? "itksnap"
                : layout == Layout::kSixColumn ? (slicer ? "slicer" : "freesurfer")
                                               : "mricron");
}

// The name without its scan ending (the table's compound ".nii.gz" whole) or its last extension.
std::string volume_stem(const std::string& path) {
  std::string name = fs::path(path).filename().string();
  std::string lower = name;
  for (auto& c : lower) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  for (const std::string& e : scan_extensions()) {
    if (lower.size() > e.size() && lower.compare(lower.size() - e.size(), e.size(), e) == 0)
      return name.substr(0, name.size() - e.size());
  }
  const auto dot = name.rfind('.');
  return dot == std::string::npos || dot == 0 ? name : name.substr(0, dot);
}

}  // namespace

std::string LabelTable::name(std::uint16_t label) const {
  const auto it = entries.find(label);
  return it != entries.end() && !it->second.name.empty() ? it->second.name : "label_" + std::to_string(label);
}

std::array<std::uint8_t, 3> LabelTable::color(std::uint16_t label) const {
  const auto it = entries.find(label);
  if (it != entries.end() && it->second.has_color)
    return {it->second.rgba[0], it->second.rgba[1], it->second.rgba[2]};
  return default_label_color(label);
}

std::array<std::uint8_t, 3> default_label_color(std::uint16_t label) {
  // Golden-angle hues never repeat; two saturation/value rows keep neighbours apart.
  const double h = std::fmod(double(label) * 0.6180339887498949, 1.0) * 6.0;
  const double s = label % 2 ? 0.65 : 0.45, v = label % 3 ? 0.92 : 0.75;
  const int sector = static_cast<int>(h) % 6;
  const double f = h - std::floor(h);
  const double p = v * (1 - s), q = v * (1 - s * f), t = v * (1 - s * (1 - f));
  double r = v, g = t, b = p;
  switch (sector) {
    case 1:
      r = q, g = v, b = p;
      break;
    case 2:
      r = p, g = v, b = t;
      break;
    case 3:
      r = p, g = q, b = v;
      break;
    case 4:
      r = t, g = p, b = v;
      break;
    case 5:
      r = v, g = p, b = q;
      break;
    default:
      break;
  }
  auto byte = [](double x) { return static_cast<std::uint8_t>(std::lround(x * 255)); };
  return {byte(r), byte(g), byte(b)};
}

LabelTable parse_label_table(const std::string& bytes, const std::string& file_name) {
  const std::string ext = lower_extension(file_name);
  if (ext == ".json") return parse_json(bytes, file_name);
  if (ext == ".lut") return parse_lut(bytes, file_name);
  return parse_text(bytes, file_name, file_name);
}

LabelTable read_label_table(const std::string& path) {
  LabelTable t = parse_label_table(read_regular_file(path, kMaxTableBytes, "a label table"), path);
  if (t.format != "mricron") return t;
  const std::string lut = mricron_colours_file(path);
  if (lut.empty()) return t;
  const LabelTable colours = parse_label_table(read_regular_file(lut, kMaxTableBytes, "a label table"), lut);
  for (auto& [value, e] : t.entries) {
    const auto it = colours.entries.find(value);
    if (it != colours.entries.end()) {
      e.rgba = it->second.rgba;
      e.has_color = true;
    }
  }
  t.source += " + " + lut;
  return t;
}

std::string mricron_colours_file(const std::string& table_path) {
  // MRIcron keeps colours in a .lut beside the names.
  const fs::path lut = fs::path(table_path).replace_extension(".lut");
  std::error_code ec;
  return fs::exists(lut, ec) ? lut.string() : "";
}

std::string find_label_table(const std::string& volume_path) {
  const fs::path dir = fs::path(volume_path).parent_path();
  const std::string stem = volume_stem(volume_path);
  for (const char* ext : {".json", ".ctbl", ".txt", ".label", ".lut"}) {
    const fs::path p = dir / (stem + ext);
    std::error_code ec;
    if (fs::is_regular_file(p, ec)) return p.string();
  }
  return "";
}

}  // namespace mlfe
