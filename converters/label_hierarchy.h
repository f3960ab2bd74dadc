// Label maps stored as hierarchies (issue #24, item 5): `mlfe build --labels` writes the label
// map losslessly on the samples' lattice (integer surpluses at bound 0; leaves refined only where
// the labels are not the linear interpolant of their corners, that is where labels meet, so
// elements inside a structure stay coarse) and its label table, as the JSON table format of
// formats/label_table.h, under the metadata key "labels". Readers get the label of every sample
// back exactly (the decoded function at the samples) and the table without the file beside it.
#pragma once
#include <mlfe/core/labels/label_surface.h>
#include <mlfe/core/mesh/hierarchy.h>
#include <mlfe/formats/hierarchy_io.h>
#include <mlfe/formats/label_table.h>

#include <cstdint>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace mlfe::pipeline::detail {

/// The error-bounded build of a label map keeps every decoded sample within this of its label
/// (integer values stored exactly; the bound covers the interpolation's last bits), so rounding
/// recovers the labels.
constexpr double kLabelSampleBound = 0.25;

/// The table stored with a label map: every label present (the background excepted), with its
/// name and colour from `table` (label_N and the fixed palette where it has none), in the JSON
/// table format ({"labels": [{"value", "name", "color"}]}), ascending.
nlohmann::json stored_label_table(const LabelTable& table,
                                  const std::map<std::uint16_t, std::size_t>& counts);

/// The label table file a labelled call reads: `named`, else the one beside `volume`
/// (find_label_table), else "".
std::string label_table_file(const std::string& named, const std::string& volume);

/// The label table of a label map: the one named (`named`, which must parse), else the file
/// beside the volume with its stem (find_label_table) when it parses as a table (a report.json
/// of an earlier run, say, is not one: a warning is appended to `warnings`), else none.
LabelTable named_or_beside_table(const std::string& named, const std::string& volume,
                                 std::vector<std::string>& warnings);

/// The label metadata `mlfe build --labels` stores (pipeline::build): the labels of `grid`
/// checked (label_grid: bad input before any output) and the table from `label_table`, else the
/// one beside the volume when it parses (a warning appended to `warnings` when it does not).
nlohmann::json label_metadata(const ScalarGrid& grid, const std::string& label_table,
                              std::vector<std::string>& warnings);

/// Whether the file's metadata holds a stored label table (written by `mlfe build --labels`).
bool is_label_hierarchy(const HierarchyFile& f);

/// The label map of a label hierarchy: the decoded function at the data's samples rounded to
/// the nearest integer (each must be within kLabelSampleBound of one), checked to be labels
/// (label_grid's rules), with the file's frame; and its stored table. Throws
/// mlfe::Error naming `path` when the file is not a label hierarchy on the samples' lattice or
/// its values are not labels.
struct StoredLabelMap {
  ScalarGrid grid;
  LabelTable table;
};
StoredLabelMap read_stored_label_map(const HierarchyFile& f, const std::string& path);

/// The label of each leaf of a label hierarchy for a tetrahedral mesh with regions: the label
/// most of its corners carry (decoded values rounded to the nearest integer); on a tie, one of
/// the tied labels picked by the sum of the element's vertex ids modulo their number (no label
/// favoured, so region volumes are unbiased). Inside a structure every corner carries its label; a leaf that
/// straddles labels is at the finest level, one lattice cell, and goes to the majority of its corners'
/// samples.
template <int D>
std::vector<std::uint16_t> leaf_labels(const Hierarchy<D>& h, const std::vector<ElemId>& leaves,
                                       const std::vector<double>& values);

}  // namespace mlfe::pipeline::detail
