// mlfe info FILE: what a volume file holds and what reading it costs, without computing
// anything; for a hierarchy file (.mlfeh), its levels, counts, error figures and bytes per
// section.
#include <fmt/format.h>
#include <mlfe/core/error.h>
#include <mlfe/core/label_surface.h>
#include <mlfe/formats/hierarchy_io.h>
#include <mlfe/formats/label_table.h>
#include <mlfe/formats/vdb_reader.h>
#include <mlfe/formats/volume_reader.h>

#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <variant>

#include "converters/commands.h"
#include "converters/label_hierarchy.h"
#include "converters/volume_options.h"

namespace mlfe::cli {
namespace {

struct InfoArgs {
  std::string file;
  VolumeReadOptions read;
  bool json = false;
  bool labels = false;      ///< list the labels of a label map
  std::string label_table;  ///< names from this table (default: the one beside the volume)
};

// The labels of a label map: value, name, voxels and volume in mm³, ascending. Throws
// mlfe::Error for values that are not labels (label_grid).
nlohmann::json label_rows(const ScalarGrid& g, const LabelTable& table) {
  const LabelGrid lg = label_grid(g);
  const double voxel_mm3 = g.transform.spacing[0] * g.transform.spacing[1] * g.transform.spacing[2];
  nlohmann::json rows = nlohmann::json::array();
  for (const auto& [l, n] : label_counts(lg))
    rows.push_back({{"label", l},
                    {"name", l == 0 && !table.entries.count(0) ? std::string("background") : table.name(l)},
                    {"voxels", n},
                    {"volume_mm3", double(n) * voxel_mm3}});
  return {{"table", table.source}, {"rows", rows}};
}

nlohmann::json label_rows(const ScalarGrid& g, const std::string& table_path) {
  LabelTable table;
  if (!table_path.empty()) {
    table = read_label_table(table_path);
  } else if (const std::string found = find_label_table(g.source); !found.empty()) {
    // Beside the volume, only a file that parses as a table is one (not an earlier report).
    try {
      table = read_label_table(found);
    } catch (const Error& e) {
      std::fprintf(stderr, "mlfe: warning: %s (found beside the volume; not used)\n", e.what());
    }
  }
  return label_rows(g, table);
}

void print_label_rows(const nlohmann::json& l) {
  fmt::print("labels:    {} (table: {})\n", l["rows"].size(),
             l["table"].get<std::string>().empty() ? "none" : l["table"].get<std::string>());
  fmt::print("{:>8} {:>12} {:>14}  {}\n", "label", "voxels", "mm3", "name");
  for (const auto& r : l["rows"])
    fmt::print("{:>8} {:>12} {:>14.2f}  {}\n", r["label"].get<int>(), r["voxels"].get<std::size_t>(),
               r["volume_mm3"].get<double>(), r["name"].get<std::string>());
}

// Per level k: vertices of level k, elements of level k, leaves of level k.
template <int D>
std::vector<std::array<std::size_t, 3>> level_counts(const Hierarchy<D>& h) {
  std::vector<std::array<std::size_t, 3>> c(static_cast<std::size_t>(h.max_level()) + 1, {0, 0, 0});
  for (std::uint32_t v = 0; v < h.vertex_count(); ++v) ++c[h.vertex_level(VertexId(v))][0];
  for (std::uint32_t e = 0; e < h.element_count(); ++e) {
    ++c[h.level(ElemId(e))][1];
    if (h.is_leaf(ElemId(e))) ++c[h.level(ElemId(e))][2];
  }
  return c;
}

void run_hierarchy_info(const InfoArgs& a) {
  const auto t0 = std::chrono::steady_clock::now();
  const HierarchyFile f = read_hierarchy(a.file);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const auto counts = std::visit([](const auto& h) { return level_counts(h); }, f.hierarchy);
  const std::size_t nv = std::visit([](const auto& h) { return h.vertex_count(); }, f.hierarchy);
  const std::size_t ne = std::visit([](const auto& h) { return h.element_count(); }, f.hierarchy);
  const std::size_t nl = std::visit([](const auto& h) { return h.leaves().size(); }, f.hierarchy);
  const auto num = [](double x) { return std::isnan(x) ? nlohmann::json(nullptr) : nlohmann::json(x); };
  // A label map (mlfe build --labels): its labels decoded at the samples, named from the stored
  // table (or --label-table).
  nlohmann::json labels;
  if (is_label_hierarchy(f)) {
    StoredLabelMap m = read_stored_label_map(f, a.file);
    if (!a.label_table.empty()) m.table = read_label_table(a.label_table);
    labels = label_rows(m.grid, m.table);
  } else if (a.labels) {
    throw Error(a.file + ": not a label map (no stored label table; build it with mlfe build --labels)");
  }
  if (a.json) {
    nlohmann::json j;
    j["file"] = a.file;
    j["format"] = "mlfeh";
    j["version"] = f.version;
    j["dim"] = f.dim;
    j["vertices"] = nv;
    j["elements"] = ne;
    j["leaves"] = nl;
    j["levels"] = f.file_levels + 1;
    j["values"] = f.values.empty()    ? "none"
                  : f.integer_values  ? "integer"
                  : f.value_bound > 0 ? "quantized"
                                      : "exact";
    j["value_bound"] = f.value_bound;
    j["on_lattice"] = f.on_lattice;
    if (f.on_lattice) {
      j["lattice_level"] = f.lattice_level;
      j["data_dims"] = f.data_dims;
    }
    j["sample_error_bound"] = num(f.sample_error_bound);
    j["range"] = {f.value_min, f.value_max};
    j["norm"] = f.norm;
    j["rms_error"] = num(f.rms_error);
    j["max_error"] = num(f.max_error);
    j["psnr_db"] = f.psnr_db > 0 && std::isinf(f.psnr_db) ? nlohmann::json("inf") : num(f.psnr_db);
    j["spacing"] = f.transform.spacing;
    j["origin"] = f.transform.origin;
    j["direction"] = f.transform.direction;
    j["space"] = f.space;
    j["metadata"] = f.metadata;
    for (std::size_t k = 0; k < counts.size(); ++k)
      j["per_level"].push_back(
          {{"level", k}, {"vertices", counts[k][0]}, {"elements", counts[k][1]}, {"leaves", counts[k][2]}});
    for (const auto& s : f.sections)
      j["sections"].push_back({{"name", s.name}, {"file_bytes", s.file_bytes}, {"raw_bytes", s.raw_bytes}});
    j["read_seconds"] = seconds;
    if (!labels.is_null()) {
      j["labels"] = labels["rows"];
      j["label_table"] = labels["table"];
    }
    std::printf("%s\n", j.dump(2).c_str());
    return;
  }
  std::uint64_t total = 0;
  for (const auto& s : f.sections) total += s.file_bytes;
  fmt::print("file:      {}\n", a.file);
  fmt::print("format:    mlfe hierarchy, version {} ({}D), {} bytes; read in {:.3f} s\n", f.version, f.dim,
             total, seconds);
  fmt::print("mesh:      {} vertices, {} elements, {} leaves, {} levels\n", nv, ne, nl, f.file_levels + 1);
  fmt::print(
      "values:    {}\n",
      f.values.empty() ? std::string("none")
      : f.integer_values
          ? (f.value_bound > 0 ? fmt::format("integer surpluses, every vertex within {:.6g}", f.value_bound)
                               : std::string("integer surpluses, exact"))
      : f.value_bound > 0 ? fmt::format("quantized, every vertex within {:.6g}", f.value_bound)
                          : std::string("exact (f64)"));
  if (f.on_lattice)
    fmt::print("lattice:   level {} on the samples (T0 {} samples wide), data {} x {} x {} samples\n",
               f.lattice_level, std::int64_t(1) << f.lattice_level, f.data_dims[0], f.data_dims[1],
               f.data_dims[2]);
  if (!std::isnan(f.sample_error_bound))
    fmt::print("bound:     every sample within {:.6g} of the decoded function\n", f.sample_error_bound);
  fmt::print("range:     {} .. {}\n", f.value_min, f.value_max);
  if (!f.norm.empty()) fmt::print("norm:      {}\n", f.norm);
  if (!std::isnan(f.rms_error))
    fmt::print(
        "error:     RMS {:.6g}, max {:.6g}, PSNR {:.2f} dB (stored approximation against its source)\n",
        f.rms_error, f.max_error, f.psnr_db);
  const auto& t = f.transform;
  fmt::print("spacing:   {} {} {}\n", t.spacing[0], t.spacing[1], t.spacing[2]);
  fmt::print("origin:    {} {} {}\n", t.origin[0], t.origin[1], t.origin[2]);
  const auto& d = t.direction;
  fmt::print("direction: [{} {} {}; {} {} {}; {} {} {}]\n", d[0], d[1], d[2], d[3], d[4], d[5], d[6], d[7],
             d[8]);
  fmt::print("space:     {}\n", f.space.empty() ? "(not given)" : f.space);
  if (!f.metadata.empty()) {
    nlohmann::json shown = f.metadata;  // the stored label table is listed below, not here
    if (!labels.is_null()) shown.erase("labels");
    fmt::print("metadata:  {}\n", shown.dump());
  }
  fmt::print("{:>7} {:>12} {:>12} {:>12}\n", "level", "vertices", "elements", "leaves");
  for (std::size_t k = 0; k < counts.size(); ++k)
    fmt::print("{:>7} {:>12} {:>12} {:>12}\n", k, counts[k][0], counts[k][1], counts[k][2]);
  fmt::print("{:<10} {:>12} {:>12}\n", "section", "file bytes", "raw bytes");
  for (const auto& s : f.sections) fmt::print("{:<10} {:>12} {:>12}\n", s.name, s.file_bytes, s.raw_bytes);
  if (!labels.is_null()) print_label_rows(labels);
}

void run_info(const InfoArgs& a) {
  if (is_hierarchy_file(a.file)) return run_hierarchy_info(a);
  const auto t0 = std::chrono::steady_clock::now();
  ScalarGrid g = read_volume(a.file, a.read);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const auto range = g.value_range();
  const std::uint64_t memory = static_cast<std::uint64_t>(g.voxel_count()) * sizeof(float);
  std::vector<std::string> grids;
  if (g.format == "vdb") grids = list_vdb_grids(a.file);
  const auto& t = g.transform;
  if (a.json) {
    nlohmann::json j;
    j["file"] = a.file;
    j["format"] = g.format;
    j["dim"] = g.dim;
    j["dims"] = g.dims;
    j["type"] = scalar_type_name(g.source_type);
    j["spacing"] = t.spacing;
    j["origin"] = t.origin;
    j["direction"] = t.direction;
    j["space"] = g.space;
    j["range"] = {range[0], range[1]};
    j["memory_bytes"] = memory;
    j["read_seconds"] = seconds;
    j["notes"] = g.notes;
    if (!grids.empty()) j["grids"] = grids;
    if (a.labels) {
      const auto l = label_rows(g, a.label_table);
      j["labels"] = l["rows"];
      j["label_table"] = l["table"];
    }
    std::printf("%s\n", j.dump(2).c_str());
    return;
  }
  fmt::print("file:      {}\n", a.file);
  fmt::print("format:    {}\n", g.format);
  fmt::print("dims:      {} x {} x {} ({}D, {} voxels)\n", g.dims[0], g.dims[1], g.dims[2], g.dim,
             g.voxel_count());
  fmt::print("type:      {} (stored as float32)\n", scalar_type_name(g.source_type));
  fmt::print("spacing:   {} {} {}\n", t.spacing[0], t.spacing[1], t.spacing[2]);
  fmt::print("origin:    {} {} {}\n", t.origin[0], t.origin[1], t.origin[2]);
  const auto& d = t.direction;
  fmt::print("direction: [{} {} {}; {} {} {}; {} {} {}]\n", d[0], d[1], d[2], d[3], d[4], d[5], d[6], d[7],
             d[8]);
  fmt::print("space:     {}\n", g.space.empty() ? "(not given)" : g.space);
  fmt::print("range:     {} .. {}\n", range[0], range[1]);
  fmt::print("memory:    {} bytes as float32 ({:.1f} MiB); read in {:.3f} s\n", memory, memory / 1048576.0,
             seconds);
  for (const auto& name : grids) fmt::print("grid:      {}\n", name);
  if (a.labels) print_label_rows(label_rows(g, a.label_table));
  if (!g.notes.empty()) {
    std::string notes = g.notes;
    std::size_t start = 0;
    while (start <= notes.size()) {
      auto end = notes.find('\n', start);
      if (end == std::string::npos) end = notes.size();
      fmt::print("note:      {}\n", notes.substr(start, end - start));
      start = end + 1;
    }
  }
}

void add_info_command(CLI::App& app) {
  auto args = std::make_shared<InfoArgs>();
  CLI::App* cmd = app.add_subcommand("info",
                                     "print the format, grid, transform and value range of a volume file, or "
                                     "the levels, errors and sections of a hierarchy file");
  cmd->add_option(
         "FILE", args->file,
         "volume or height field (vdb, nrrd, nii[.gz], mha/mhd, raw+json, pgm, png) or hierarchy (.mlfeh)")
      ->required()
      ->check(CLI::ExistingFile);
  add_volume_read_options(cmd, args->read);
  cmd->add_flag("--json", args->json, "print JSON instead of text");
  cmd->add_flag("--labels", args->labels, "a label map: list its labels with voxel counts, mm3 and names");
  cmd->add_option("--label-table", args->label_table,
                  "with --labels: names from this table (default: the one beside the volume)");
  cmd->callback([args] { run_info(*args); });
}

}  // namespace

MLFE_REGISTER_COMMAND(20, add_info_command);

}  // namespace mlfe::cli
