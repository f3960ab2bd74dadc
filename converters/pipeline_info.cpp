// mlfe::pipeline::info (`mlfe info`): what a volume or hierarchy file holds and what reading it
// costs, without computing anything.
#include <mlfe/core/base/error.h>
#include <mlfe/core/labels/label_surface.h>
#include <mlfe/formats/hierarchy_io.h>
#include <mlfe/formats/label_table.h>
#include <mlfe/formats/vdb_reader.h>
#include <mlfe/pipeline.h>

#include <chrono>
#include <cmath>
#include <variant>

#include "converters/label_hierarchy.h"

namespace mlfe::pipeline {
namespace {

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// The rows of `lg`: value, name, voxels and volume in mm³, ascending.
void add_label_rows(const LabelGrid& lg, const GridTransform& t, const LabelTable& table, InfoResult& r) {
  const double voxel_mm3 = t.spacing[0] * t.spacing[1] * t.spacing[2];
  for (const auto& [l, n] : label_counts(lg))
    r.labels.push_back({static_cast<std::uint32_t>(l),
                        l == 0 && !table.entries.count(0) ? std::string("background") : table.name(l),
                        static_cast<std::size_t>(n), double(n) * voxel_mm3});
  r.label_table = table.source;
  r.has_labels = true;
}

// The labels of a label map: value, name, voxels and volume in mm³, ascending. Throws
// mlfe::Error for values that are not labels (label_grid).
void add_label_rows(const ScalarGrid& g, const std::string& table_path, InfoResult& r) {
  const LabelGrid lg = label_grid(g);
  add_label_rows(lg, g.transform, detail::named_or_beside_table(table_path, g.source, r.warnings), r);
}

void add_label_json(const InfoResult& r, nlohmann::json& j) {
  nlohmann::json rows = nlohmann::json::array();
  for (const auto& l : r.labels)
    rows.push_back(
        {{"label", l.label}, {"name", l.name}, {"voxels", l.voxels}, {"volume_mm3", l.volume_mm3}});
  j["labels"] = rows;
  j["label_table"] = r.label_table;
}

// Per level k: vertices, elements and leaves of level k.
template <int D>
std::vector<LevelCounts> level_counts(const Hierarchy<D>& h) {
  std::vector<LevelCounts> c(static_cast<std::size_t>(h.max_level()) + 1);
  for (std::uint32_t v = 0; v < h.vertex_count(); ++v) ++c[h.vertex_level(VertexId(v))].vertices;
  for (std::uint32_t e = 0; e < h.element_count(); ++e) {
    ++c[h.level(ElemId(e))].elements;
    if (h.is_leaf(ElemId(e))) ++c[h.level(ElemId(e))].leaves;
  }
  return c;
}

InfoResult hierarchy_info(const std::string& file, const InfoOptions& options) {
  const auto t0 = std::chrono::steady_clock::now();
  HierarchyFile f = read_hierarchy(file);
  InfoResult r;
  r.file = file;
  r.hierarchy = true;
  r.read_seconds = seconds_since(t0);
  r.per_level = std::visit([](const auto& h) { return level_counts(h); }, f.hierarchy);
  r.vertices = std::visit([](const auto& h) { return std::size_t(h.vertex_count()); }, f.hierarchy);
  r.elements = std::visit([](const auto& h) { return std::size_t(h.element_count()); }, f.hierarchy);
  r.leaves = std::visit([](const auto& h) { return h.leaves().size(); }, f.hierarchy);
  r.levels = f.file_levels + 1;
  r.version = f.version;
  r.dim = f.dim;
  r.value_coding = f.values.empty()    ? "none"
                   : f.integer_values  ? "integer"
                   : f.value_bound > 0 ? "quantized"
                                       : "exact";
  r.value_bound = f.value_bound;
  r.integer_values = f.integer_values;
  r.sections = f.sections;
  r.transform = f.transform;
  r.space = f.space;
  r.range = {f.value_min, f.value_max};
  r.header = static_cast<const HierarchyFileInfo&>(f);
  // A label hierarchy (mlfe build --labels): its labels decoded at the samples, named from the
  // stored table (or options.label_table).
  if (detail::is_label_hierarchy(f)) {
    detail::StoredLabelMap m = detail::read_stored_label_map(f, file);
    if (!options.label_table.empty()) m.table = read_label_table(options.label_table);
    add_label_rows(label_grid(m.grid), m.grid.transform, m.table, r);
  } else if (options.labels) {
    throw Error(file + ": not a label map (no stored label table; build it with mlfe build --labels)");
  }
  return r;
}

nlohmann::json number_or_null(double x) {
  return std::isnan(x) ? nlohmann::json(nullptr) : nlohmann::json(x);
}

nlohmann::json hierarchy_json(const InfoResult& r) {
  const HierarchyFileInfo& f = r.header;
  nlohmann::json j;
  j["file"] = r.file;
  j["format"] = "mlfeh";
  j["version"] = r.version;
  j["dim"] = r.dim;
  j["vertices"] = r.vertices;
  j["elements"] = r.elements;
  j["leaves"] = r.leaves;
  j["levels"] = r.levels;
  j["values"] = r.value_coding;
  j["value_bound"] = r.value_bound;
  j["on_lattice"] = f.on_lattice;
  if (f.on_lattice) {
    j["lattice_level"] = f.lattice_level;
    j["data_dims"] = f.data_dims;
  }
  j["sample_error_bound"] = number_or_null(f.sample_error_bound);
  j["range"] = {f.value_min, f.value_max};
  j["norm"] = f.norm;
  j["rms_error"] = number_or_null(f.rms_error);
  j["max_error"] = number_or_null(f.max_error);
  j["psnr_db"] = f.psnr_db > 0 && std::isinf(f.psnr_db) ? nlohmann::json("inf") : number_or_null(f.psnr_db);
  j["spacing"] = f.transform.spacing;
  j["origin"] = f.transform.origin;
  j["direction"] = f.transform.direction;
  j["space"] = f.space;
  j["metadata"] = f.metadata;
  for (std::size_t k = 0; k < r.per_level.size(); ++k)
    j["per_level"].push_back({{"level", k},
                              {"vertices", r.per_level[k].vertices},
                              {"elements", r.per_level[k].elements},
                              {"leaves", r.per_level[k].leaves}});
  for (const auto& s : r.sections)
    j["sections"].push_back({{"name", s.name}, {"file_bytes", s.file_bytes}, {"raw_bytes", s.raw_bytes}});
  j["read_seconds"] = r.read_seconds;
  if (r.has_labels) {
    add_label_json(r, j);
  }
  return j;
}

nlohmann::json volume_json(const InfoResult& r, bool labels) {
  const auto& t = r.transform;
  nlohmann::json j;
  j["file"] = r.file;
  j["format"] = r.format;
  j["dim"] = r.dim;
  j["dims"] = r.dims;
  j["type"] = r.type;
  j["spacing"] = t.spacing;
  j["origin"] = t.origin;
  j["direction"] = t.direction;
  j["space"] = r.space;
  j["range"] = {r.range[0], r.range[1]};
  j["memory_bytes"] = r.memory_bytes;
  j["read_seconds"] = r.read_seconds;
  j["notes"] = r.notes;
  if (!r.grids.empty()) j["grids"] = r.grids;
  if (labels) add_label_json(r, j);
  return j;
}

}  // namespace

nlohmann::json InfoResult::to_json() const {
  return hierarchy ? hierarchy_json(*this) : volume_json(*this, has_labels);
}

InfoResult info(const std::string& file, const InfoOptions& options) {
  check_options(options.read);
  if (is_hierarchy_file(file)) return hierarchy_info(file, options);
  const auto t0 = std::chrono::steady_clock::now();
  const ScalarGrid g = read_volume(file, options.read);
  InfoResult r;
  r.file = file;
  r.read_seconds = seconds_since(t0);
  r.format = g.format;
  r.dim = g.dim;
  r.dims = g.dims;
  r.voxels = static_cast<std::uint64_t>(g.voxel_count());
  r.type = scalar_type_name(g.source_type);
  r.transform = g.transform;
  r.space = g.space;
  const auto range = g.value_range();
  r.range = {range[0], range[1]};
  r.memory_bytes = r.voxels * sizeof(float);
  r.notes = g.notes;
  if (g.format == "vdb") r.grids = list_vdb_grids(file);
  if (options.labels) add_label_rows(g, options.label_table, r);
  return r;
}

}  // namespace mlfe::pipeline
