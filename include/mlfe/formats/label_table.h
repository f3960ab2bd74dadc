// Label tables: the names and colours of the structures of a label map (segmentation, atlas),
// read from the formats their tools write.
//
// - MRIcron: a text file of "value name" lines (tab or space separated, extra columns ignored)
//   and/or a 768-byte palette (.lut: 256 red bytes, then 256 green, then 256 blue) for labels
//   0..255. A .txt with a .lut of the same stem beside it takes its colours from the .lut.
// - ITK-SNAP label description file: `IDX R G B A VIS MSH "LABEL"` lines (A in [0, 1]).
// - FreeSurfer colour LUT (FreeSurferColorLUT.txt and its kind): `value name R G B A` lines,
//   A unused (FreeSurfer writes 0 and draws opaque).
// - 3D Slicer colour table (.ctbl, or .txt with Slicer's "# Color table file" header):
//   `value name R G B A` lines, A in 0..255.
// - JSON (.json): {"labels": [{"value": 3, "name": "Genu of corpus callosum",
//   "color": [255, 0, 0]}, ...]}; "color" optional, 3 or 4 integers 0..255 (sRGB, alpha last).
//
// '#' starts a comment line in the text formats; blank lines are skipped. Colours are sRGB
// bytes as the tools write them. Labels are 0..65535 and listed once.
#pragma once
#include <array>
#include <cstdint>
#include <map>
#include <string>

namespace mlfe {

struct LabelEntry {
  std::string name;                                ///< empty: label_N
  std::array<std::uint8_t, 4> rgba{0, 0, 0, 255};  ///< sRGB bytes, alpha last
  bool has_color = false;
};

struct LabelTable {
  std::map<std::uint16_t, LabelEntry> entries;
  std::string format;  ///< "mricron", "mricron-lut", "itksnap", "freesurfer", "slicer", "json"; "" none
  std::string source;  ///< the file(s) read

  /// The table's name of `label`, or "label_N" when it has none.
  std::string name(std::uint16_t label) const;
  /// The table's colour of `label` (sRGB bytes), or default_label_color(label).
  std::array<std::uint8_t, 3> color(std::uint16_t label) const;
};

/// A fixed palette of distinct colours for labels without a table colour (sRGB bytes): hues
/// by the golden angle, alternating in saturation and value, the same for a label everywhere.
std::array<std::uint8_t, 3> default_label_color(std::uint16_t label);

/// Parses a label table held in memory; `file_name` (its extension and name) decides between
/// formats where the content does not (".json", ".lut", ".ctbl"; FreeSurfer and Slicer by
/// header). Throws mlfe::Error ("<file_name>: line N: <problem>") for anything that does not
/// parse: unknown layout, a label that is not an integer 0..65535, a colour component outside
/// 0..255, a label listed twice, no entries at all.
LabelTable parse_label_table(const std::string& bytes, const std::string& file_name);

/// Reads the table at `path` (parse_label_table), and for an MRIcron .txt the colours of the
/// .lut of the same stem beside it. Throws mlfe::Error for unreadable or bad files.
LabelTable read_label_table(const std::string& path);

/// The .lut of the same stem beside the table at `table_path`, where an MRIcron table's colours
/// are; "" when there is none.
std::string mricron_colours_file(const std::string& table_path);

/// The table beside a volume: the first existing file of the volume's stem (its name without a
/// scan ending of scan_extensions(), ".nii.gz" whole, or else its last extension) with extension
/// .json, .ctbl, .txt, .label or .lut; "" when none.
std::string find_label_table(const std::string& volume_path);

}  // namespace mlfe
