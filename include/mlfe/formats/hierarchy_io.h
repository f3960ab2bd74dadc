// The mlfe hierarchy file (.mlfeh): a complete red-green hierarchy with per-vertex values, so
// that an approximation can be stored once and re-read for iso-surfacing, rendering or further
// refinement without solving again.
//
// ---- Format, version 1 (all integers and floats little-endian; f64 = IEEE 754 binary64) ----
//
//   offset size  field
//        0    8  magic "MLFEHIER"
//        8    4  u32 version = 1
//       12    4  u32 dim: 2 (triangles) or 3 (tetrahedra)
//       16    8  u64 vertex count nv   (< 2^32 - 1)
//       24    8  u64 element count ne  (1 .. 2^32 - 2)
//       32   24  f64[3] spacing        (GridTransform: physical = origin + direction·local,
//       56   24  f64[3] origin          local = index .* spacing; all finite, spacing > 0)
//       80   72  f64[9] direction, row-major
//      152    8  f64 value_min
//      160    8  f64 value_max         (finite, value_min <= value_max)
//      168    4  u32 flags: bit 0 = array section is one zstd frame; bit 1 = values present;
//                other bits must be 0
//      172    4  u32 space length ls   (<= 64; printable ASCII, e.g. "RAS", "LPS" or empty)
//      176    8  u64 metadata length lm (<= 16 MiB; UTF-8 JSON object, or 0 for {})
//      184    8  u64 stored size of the array section ss (bytes in this file)
//      192    8  u64 raw size of the array section rs (must equal the size implied by nv, ne,
//                dim and flags bit 1; if compressed, rs <= 1024 * ss + 4096)
//      200   ls  space
//         lm  metadata JSON
//         ss  array section (raw, or zstd-compressed when flags bit 0)
//          4  u32 CRC-32 (zlib polynomial) of every byte before it
//   The file ends right after the CRC: its size is exactly 204 + ls + lm + ss.
//
//   Array section (raw), arrays back to back in this order, no padding:
//     points          nv·dim f64   local frame (grid index .* spacing)
//     vertex_parents  nv·2   u32   edge endpoints of a midpoint vertex, p0 < p1 < vertex;
//                                   0xFFFFFFFF twice for vertices of T0
//     vertex_level    nv     u8
//     values          nv     f64   only when flags bit 1: u at each vertex (no NaN)
//     cells           ne·(dim+1) u32   vertex ids, vertex order as in the hierarchy
//     parent          ne     u32   0xFFFFFFFF for coarse elements
//     first_child     ne     u32   0xFFFFFFFF for leaves
//     num_children    ne     u8
//     level           ne     u8
//     kind            ne     u8    0 coarse, 1 red, 2 green
//   The arrays are those of mlfe::Hierarchy (core/mesh/hierarchy.h); the edge map is not stored, it
//   is rebuilt from vertex_parents. Readers validate everything (Hierarchy::from_arrays).
//
// Versioning: a reader rejects versions it does not know; any change to the layout above
// increments the version.
// ---- Format, version 2 (docs/mlfeh-v2.md is the full specification) ----
//
// A 16-byte preamble (magic, u32 version = 2, u32 dim), then sections, each with a 28-byte
// header (u32 tag, u32 codec, u64 stored size, u64 raw size, u32 CRC-32 of the header's first
// 24 bytes and the payload): HEAD (frame, value range, coding, error figures, provenance),
// MESH (T0 and its values), then one LEVL per level k = 1 .. L: the refinement marks over the
// canonical candidates (formats/hierarchy_levels.h) and the values of the vertices that step
// adds, as hierarchical-basis codes quantized against the decoded coarser level (or exact
// f64). Any prefix of complete levels is a valid, coarser file content.
//
// ---- Format, version 3 (docs/mlfeh-v3.md) ----
//
// Version 2's layout with a longer HEAD: whether the hierarchy is on the samples' lattice
// (core/fem/sample_lattice.h), the lattice level L and the data's samples per axis (so readers
// know the data's grid and box inside T0's padded cube), and the error bound at the samples
// of an error-bounded build; and one more value coding, integer surpluses (lossless for
// integer data at bound 0).
//
// ---- Format, version 4 (docs/mlfeh-v4.md) ----
//
// Version 3 with each level section in the smaller of two forms: v3's, or the marks and the
// values range coded (formats/range_coder.h), the values' quantized surpluses coded against a
// higher-order prediction on the samples' lattice (formats/lattice_values.h). The decoded
// values are v3's.
//
#pragma once
#include <mlfe/core/field/scalar_grid.h>
#include <mlfe/core/mesh/hierarchy.h>
#include <mlfe/formats/hierarchy_levels.h>

#include <array>
#include <cstdint>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>
#include <variant>
#include <vector>

namespace mlfe {

/// Everything in a hierarchy file besides the hierarchy and its values.
struct HierarchyFileInfo {
  GridTransform transform;  ///< local frame → physical
  std::string space;        ///< "RAS", "LPS" or "" (at most 64 printable ASCII characters)
  double value_min = 0.0;   ///< value range of the source data
  double value_max = 0.0;
  nlohmann::json metadata = nlohmann::json::object();  ///< provenance (must be an object)
  // Error figures of the stored approximation against its source, in data units (v2 only;
  // NaN: not known). `norm` is the build's norm: "l2", "h1" or "" (not known).
  std::string norm;
  double rms_error = std::numeric_limits<double>::quiet_NaN();
  double max_error = std::numeric_limits<double>::quiet_NaN();
  double psnr_db = std::numeric_limits<double>::quiet_NaN();
  /// v3: the hierarchy is on the samples' lattice: T0 is the cube 2^lattice_level samples
  /// wide (local frame [0, 2^L·spacing]) and data_dims are the data's samples per axis (1 on
  /// unused axes), its box [0, (n − 1)·spacing]. Earlier versions: false.
  bool on_lattice = false;
  int lattice_level = 0;
  std::array<std::int64_t, 3> data_dims{1, 1, 1};
  /// v3: every sample of the data is within this of the stored function as decoded (an
  /// error-bounded build, `mlfe build --max-error`); NaN: no such bound.
  double sample_error_bound = std::numeric_limits<double>::quiet_NaN();
};

/// One section of a file as read: name ("header", "preamble", "T0", "level k", "arrays"),
/// bytes in the file (with its section header) and after decompression.
struct HierarchySection {
  std::string name;
  int level = -1;  ///< refinement step of a level section, else −1
  std::uint64_t file_bytes = 0;
  std::uint64_t raw_bytes = 0;
};

struct HierarchyFile : HierarchyFileInfo {
  int dim = 3;  ///< 2 or 3: which alternative `hierarchy` holds
  std::variant<Hierarchy<2>, Hierarchy<3>> hierarchy;
  std::vector<double> values;  ///< u per vertex, or empty when the file stores none
  int version = 1;             ///< format version of the file read
  int file_levels = 0;         ///< max element level the file holds (v1: of its hierarchy)
  /// v2/v3 with quantized values: every value is within this bound of the writer's (0: exact
  /// values or none).
  double value_bound = 0;
  /// v3: the values are stored as integer surpluses (integer values; lossless when
  /// value_bound is 0).
  bool integer_values = false;
  std::vector<HierarchySection> sections;  ///< what was read, in file order
};

struct HierarchyWriteOptions {
  bool compress = true;  ///< zstd-compress the array section (v1) or the sections (v2)
  int zstd_level = 3;
  /// 1 keeps the ids and exact values; 2 is the compact progressive file; 3 adds the lattice
  /// and the integer coding (docs/mlfeh-v3.md); 4 range codes levels (docs/mlfeh-v4.md).
  int version = 1;
  /// v2/v3: quantize values so every decoded vertex value is within this bound (data units) of
  /// the given one; 0 stores them exactly (f64, or integers with integer_values).
  double max_error = 0;
  /// v3: the values are integers (else mlfe::Error), stored as integer surpluses; max_error
  /// must then be an integer (0: lossless).
  bool integer_values = false;
  /// v4 with max_error > 0 (coding 1 or 3): each level's values quantized against the
  /// prediction its range coder chose rather than against the mean of the parents (level form 2,
  /// docs/mlfeh-v4.md): other decoded values than v3's, each still within max_error, at fewer
  /// bytes where the bound is wide. residual_quantized_values() gives them.
  bool residual_quantization = false;
};

/// Version 2 throws LevelRebuildError (formats/hierarchy_levels.h) for a hierarchy its
/// level-by-level rebuild does not reproduce; callers may write version 1 instead.
/// Writes `h` and its per-vertex `values` (size vertex_count, or empty for none; no NaN) to
/// `path` atomically, in the format above. The bytes depend only on the arguments (not on the
/// thread count or the time). Throws mlfe::Error ("<path>: <problem>") on invalid arguments
/// (values size, NaN, bad info) or when the file cannot be written; nothing is left behind then.
template <int D>
void write_hierarchy(const std::string& path, const Hierarchy<D>& h, const std::vector<double>& values,
                     const HierarchyFileInfo& info, const HierarchyWriteOptions& options = {});

/// The same file for a hierarchy already in its levels' canonical numbering
/// (renumber_canonically in hierarchy_levels.h): `levels` is its description and `values` are
/// in h's vertex order, so the writer does not rebuild h beside itself (a second hierarchy at
/// its peak). Format version 2 or 3; the bytes are those the overload above writes for the
/// hierarchy before renumbering and its values.
template <int D>
void write_hierarchy(const std::string& path, const Hierarchy<D>& h, const LevelDescription<D>& levels,
                     const std::vector<double>& values, const HierarchyFileInfo& info,
                     const HierarchyWriteOptions& options);

/// The values a reader decodes from the file write_hierarchy(path, h, levels, values, info,
/// options) writes with options.residual_quantization (version 4, max_error > 0): every one
/// within options.max_error of `values`. Throws mlfe::Error as the writer does.
template <int D>
std::vector<double> residual_quantized_values(const Hierarchy<D>& h, const LevelDescription<D>& levels,
                                              const std::vector<double>& values,
                                              const HierarchyFileInfo& info,
                                              const HierarchyWriteOptions& options);

/// Writes a HierarchyFile (dispatches on the variant; `dim` must match it).
void write_hierarchy(const std::string& path, const HierarchyFile& file,
                     const HierarchyWriteOptions& options = {});

/// Reads and fully validates a hierarchy file (v1 to v4). Checks, in order: magic, version, the
/// header fields, the section sizes against the file size (before allocating anything large),
/// the CRCs, the decompressed sizes, every array (v1: Hierarchy::from_arrays; v2: T0, marks and
/// counts as the rebuild proceeds) and the values (finite). Throws mlfe::Error with a one-line
/// "<path>: <problem>" message on any violation; never crashes or aborts on a malformed file.
///
/// With max_level ≥ 0, returns T_max_level (elements of level ≤ max_level) and the values at
/// its vertices, which are those of the level-max_level hierarchical-basis approximation; a v2
/// reader then reads only the sections up to that level (a file cut after them reads). A v2
/// file's hierarchy is the writer's up to element and vertex numbering.
HierarchyFile read_hierarchy(const std::string& path, int max_level = -1);

/// True when `path` starts with the hierarchy file's magic (nothing else is checked; an
/// unreadable or short file gives false).
bool is_hierarchy_file(const std::string& path);

extern template std::vector<double> residual_quantized_values<2>(const Hierarchy<2>&,
                                                                 const LevelDescription<2>&,
                                                                 const std::vector<double>&,
                                                                 const HierarchyFileInfo&,
                                                                 const HierarchyWriteOptions&);
extern template std::vector<double> residual_quantized_values<3>(const Hierarchy<3>&,
                                                                 const LevelDescription<3>&,
                                                                 const std::vector<double>&,
                                                                 const HierarchyFileInfo&,
                                                                 const HierarchyWriteOptions&);
extern template void write_hierarchy<2>(const std::string&, const Hierarchy<2>&, const std::vector<double>&,
                                        const HierarchyFileInfo&, const HierarchyWriteOptions&);
extern template void write_hierarchy<3>(const std::string&, const Hierarchy<3>&, const std::vector<double>&,
                                        const HierarchyFileInfo&, const HierarchyWriteOptions&);
extern template void write_hierarchy<2>(const std::string&, const Hierarchy<2>&, const LevelDescription<2>&,
                                        const std::vector<double>&, const HierarchyFileInfo&,
                                        const HierarchyWriteOptions&);
extern template void write_hierarchy<3>(const std::string&, const Hierarchy<3>&, const LevelDescription<3>&,
                                        const std::vector<double>&, const HierarchyFileInfo&,
                                        const HierarchyWriteOptions&);

}  // namespace mlfe
