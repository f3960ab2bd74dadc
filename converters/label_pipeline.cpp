// convert_labels (pipeline.h): a label map to one named, coloured, closed surface per
// structure, through the shared interface complex of core/labels/label_surface.h.
#include <fmt/format.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/labels/label_surface.h>
#include <mlfe/core/simplify/simplifier.h>
#include <mlfe/formats/asset_writer.h>
#include <mlfe/formats/atomic_file.h>
#include <mlfe/formats/file_names.h>
#include <mlfe/formats/gltf_writer.h>
#include <mlfe/formats/label_table.h>
#include <mlfe/pipeline.h>
#include <mlfe/version.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <functional>
#include <map>

#include "converters/label_hierarchy.h"

namespace mlfe {

namespace {

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// glTF colours are linear; tables hold sRGB bytes.
float srgb_to_linear(std::uint8_t c) {
  const double x = c / 255.0;
  return float(x <= 0.04045 ? x / 12.92 : std::pow((x + 0.055) / 1.055, 2.4));
}

}  // namespace

std::vector<std::uint16_t> parse_label_list(const std::string& text) {
  std::vector<std::uint16_t> out;
  auto number = [&](const std::string& s) -> long long {
    std::size_t used = 0;
    long long v = -1;
    try {
      v = std::stoll(s, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (s.empty() || used != s.size() || v < 0 || v > 65535)
      throw pipeline::OptionInputError(fmt::format("{}: '{}' is not a label 0..65535 (expected e.g. 3,7-9)",
                                                   pipeline::option_ref("labels"), s));
    return v;
  };
  std::size_t start = 0;
  while (start <= text.size()) {
    const std::size_t comma = std::min(text.find(',', start), text.size());
    const std::string item = text.substr(start, comma - start);
    const std::size_t dash = item.find('-', 1);
    const long long lo = number(item.substr(0, dash)),
                    hi = dash == std::string::npos ? lo : number(item.substr(dash + 1));
    if (hi < lo)
      throw pipeline::OptionInputError(
          fmt::format("{}: range '{}' runs backwards", pipeline::option_ref("labels"), item));
    for (long long v = lo; v <= hi; ++v) out.push_back(static_cast<std::uint16_t>(v));
    start = comma + 1;
  }
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

namespace {

// The named table, else one held in memory (a label hierarchy's), else the one beside the volume.
LabelTable label_table_for(const LabelOptions& o, const ScalarGrid& grid,
                           const std::function<void(const std::string&)>& warn) {
  if (o.table.empty() && !o.table_json.empty()) {
    LabelTable table = parse_label_table(o.table_json, o.table_json_source + ".json");
    table.source = o.table_json_source;
    return table;
  }
  std::vector<std::string> warnings;
  LabelTable table = pipeline::detail::named_or_beside_table(o.table, grid.source, warnings);
  for (const auto& w : warnings) warn(w);
  return table;
}

// None of the labels asked for is in the volume: which ones, and a few that are.
std::string absent_labels_message(const std::vector<std::uint16_t>& missing,
                                  const std::map<std::uint16_t, std::size_t>& present,
                                  const std::string& source) {
  std::vector<std::uint16_t> labels;
  for (const auto& [l, n] : present)
    if (l != 0) labels.push_back(l);
  constexpr std::size_t kShown = 8;
  std::string shown = labels.empty() ? "none but the background 0" : "";
  for (std::size_t i = 0; i < std::min(labels.size(), kShown); ++i)
    shown += (i ? ", " : "") + std::to_string(labels[i]);
  if (labels.size() > kShown) shown += fmt::format(" and {} more", labels.size() - kShown);
  std::string asked;
  for (std::size_t i = 0; i < missing.size(); ++i) asked += (i ? ", " : "") + std::to_string(missing[i]);
  return fmt::format("{}: {} {} {} not in the volume (its labels: {})", source,
                     missing.size() == 1 ? "label" : "labels", asked, missing.size() == 1 ? "is" : "are",
                     shown);
}

// The labels to write: the picked ones present (absent ones warned about), else every label
// but the background; the table's labels absent from the volume are warned about too.
std::vector<std::uint16_t> pick_labels(const LabelOptions& o,
                                       const std::map<std::uint16_t, std::size_t>& present,
                                       const LabelTable& table, const std::string& source,
                                       const std::function<void(const std::string&)>& warn) {
  std::vector<std::uint16_t> absent;
  for (const auto& [l, e] : table.entries)
    if (l != 0 && !present.count(l)) absent.push_back(l);
  if (!absent.empty())
    warn(fmt::format("{}: {} labels of the table are absent from {} (e.g. {})", table.source, absent.size(),
                     source, absent.front()));
  std::vector<std::uint16_t> picked, missing;
  for (auto l : o.labels) {
    if (l == 0)
      throw pipeline::OptionInputError(pipeline::option_ref("labels") +
                                       ": 0 is the background and has no surface");
    (present.count(l) ? picked : missing).push_back(l);
  }
  if (!o.labels.empty() && picked.empty()) throw Error(absent_labels_message(missing, present, source));
  for (auto l : missing) warn(fmt::format("label {} is absent from {}", l, source));
  if (o.labels.empty())
    for (const auto& [l, n] : present)
      if (l != 0) picked.push_back(l);
  if (picked.empty()) throw Error(source + ": no labels to convert (only background)");
  return picked;
}

// One surface per picked structure, named and coloured from the table, with its summary row.
struct Structures {
  std::vector<GltfSurface> surfaces;
  nlohmann::json rows = nlohmann::json::array();
  std::size_t triangles = 0;
};

Structures structure_surfaces(const LabelInterfaces& x, const std::vector<std::uint16_t>& picked,
                              const LabelTable& table, const std::map<std::uint16_t, std::size_t>& counts,
                              const GridTransform& transform) {
  const double voxel_mm3 = transform.spacing[0] * transform.spacing[1] * transform.spacing[2];
  Structures out;
  for (auto l : labels_with_surfaces(x)) {
    if (std::find(picked.begin(), picked.end(), l) == picked.end()) continue;
    GltfSurface s;
    s.mesh = label_surface(x, l, transform);
    compute_area_weighted_normals(s.mesh);
    s.name = table.name(l);
    s.node_name = s.name;
    const auto c = table.color(l);
    s.color = {srgb_to_linear(c[0]), srgb_to_linear(c[1]), srgb_to_linear(c[2]), 1.0f};
    s.iso_value = l;
    const std::size_t voxels = counts.count(l) ? counts.at(l) : 0;
    s.node_extras = {{"label", l}, {"voxels", voxels}, {"volume_mm3", double(voxels) * voxel_mm3}};
    out.rows.push_back({{"label", l},
                        {"name", s.name},
                        {"color", {c[0], c[1], c[2]}},
                        {"voxels", voxels},
                        {"volume_mm3", double(voxels) * voxel_mm3},
                        {"triangles", s.mesh.triangles.size()},
                        {"vertices", s.mesh.positions.size()},
                        {"pieces", connected_pieces(s.mesh)},
                        {"closed", unmatched_edges(s.mesh) == 0}});
    out.triangles += s.mesh.triangles.size();
    out.surfaces.push_back(std::move(s));
  }
  return out;
}

// Peak bytes of a label conversion per triangle extraction makes: the complex (positions,
// triangles, labels), smoothing's neighbour lists and the decimator's state, all of which
// scale with the interfaces. Measured as peak RSS over extracted triangles on the atlases of
// bench/py/labels_bench.py (bench/RESULTS.md, session 25), and rounded up.
constexpr double kBytesPerInterfaceTriangle = 160;

// Refuses, before any interface is built, a label map whose conversion would not fit the
// budget: its interfaces scale with their area, not the volume's size, so the reader's budget
// check does not bound them (a noisy 250 M-voxel map fits as a volume and has billions of
// interface triangles).
void check_label_memory(const ScalarGrid& grid, const LabelGrid& g, const LabelOptions& o) {
  const std::size_t budget = o.max_memory.bytes();
  if (budget == 0) return;
  const InterfaceCount n = count_label_interfaces(g);
  const double volume =
      double(grid.values.size()) * sizeof(float) + double(g.labels.size()) * sizeof(std::uint16_t);
  const double need = volume + double(n.triangles) * kBytesPerInterfaceTriangle;
  if (need <= double(budget)) return;
  throw pipeline::OptionInputError(
      fmt::format("{}: its label interfaces ({} triangles) need about {:.0f} MiB, over {} {}", grid.source,
                  n.triangles, need / 1048576.0, pipeline::option_ref("max_memory"), o.max_memory.text()));
}

}  // namespace

nlohmann::json convert_labels(const ScalarGrid& grid, const std::string& out, const LabelOptions& o,
                              const nlohmann::json& provenance) {
  const auto t0 = std::chrono::steady_clock::now();
  check_output_path(out, kAssetExtensions);
  const std::string ext = lower_extension(out);
  pipeline::check_options(o);
  const std::function<void(const std::string&)> warn = [&](const std::string& w) {
    if (o.warn) o.warn(w);
  };

  // Step 1: the labels (bad values fail here, before any output), the table, the picked ones.
  LabelGrid g = label_grid(grid);
  const LabelTable table = label_table_for(o, grid, warn);
  const std::vector<std::uint16_t> picked = pick_labels(o, label_counts(g), table, grid.source, warn);
  const bool single = ext != ".glb" && ext != ".gltf";
  if (single && picked.size() != 1)
    throw pipeline::OptionInputError(
        fmt::format("{}: {} writes one mesh, but {} labels are picked; pick one with {} or write .glb/.gltf",
                    out, ext, picked.size(), pipeline::option_ref("labels")));
  if (!o.labels.empty()) keep_labels(g, picked);

  // Step 2: small pieces take their surroundings' label; voxel counts after that.
  const ComponentRemoval removed = remove_small_components(g, o.min_component);
  const auto counts = label_counts(g);
  check_label_memory(grid, g, o);
  const double prepare_s = seconds_since(t0);

  // Step 3: the interface complex, smoothed and simplified as a whole.
  const auto t1 = std::chrono::steady_clock::now();
  LabelInterfaces x = extract_label_interfaces(g, mixed_kuhn_tets(g));
  const std::size_t extracted_triangles = x.triangles.size();
  const double extract_s = seconds_since(t1);
  const auto t2 = std::chrono::steady_clock::now();
  LabelSmoothingOptions so;
  so.iterations = o.smoothing_iterations;
  so.max_offset = o.max_offset;
  smooth_label_interfaces(x, so);
  const double smooth_s = seconds_since(t2);
  const auto t3 = std::chrono::steady_clock::now();
  std::size_t vertices_removed = 0;
  if (o.simplify > 0) {
    SimplifierOptions simplifier;
    simplifier.tolerance = o.simplify;
    vertices_removed = simplify(x, simplifier);
  }
  const double simplify_s = seconds_since(t3);

  // Step 4: one surface per structure, written.
  const auto t4 = std::chrono::steady_clock::now();
  const Structures st = structure_surfaces(x, picked, table, counts, grid.transform);
  // Picked labels whose every voxel min_component relabelled have no surface left.
  if (st.surfaces.empty())
    throw pipeline::OptionInputError(grid.source + ": no structure left to write (see " +
                                     pipeline::option_ref("min_component") + ")");
  double smallest = grid.transform.spacing[0];
  for (double s : grid.transform.spacing) smallest = std::min(smallest, std::abs(s));
  const double tol = o.tolerance > 0 ? o.tolerance : smallest / 10.0;
  nlohmann::json prov = {{"input", std::filesystem::path(grid.source).filename().string()},
                         {"tool", std::string("mlfe ") + MLFE_VERSION},
                         // The method as the assets name it: part of every label asset's bytes (golden
                         // files), so it keeps the header's name from before core/ had rooms.
                         {"labels", "multi-material marching tetrahedra (core/label_surface.h)"},
                         {"label_table", table.source},
                         {"label_table_format", table.format},
                         {"smoothing_iterations", o.smoothing_iterations},
                         {"max_offset_voxels", o.max_offset},
                         {"simplify_voxels", o.simplify},
                         {"min_component_voxels", o.min_component}};
  if (provenance.is_object()) prov.merge_patch(provenance);
  // One glTF scene of every structure, or the single structure's mesh (checked above).
  write_asset(st.surfaces, out, {o.draco, o.quantize, tol, grid.space, prov});
  const double write_s = seconds_since(t4);

  nlohmann::json removed_json = nlohmann::json::object();
  for (const auto& [l, n] : removed.removed) removed_json[std::to_string(l)] = n;
  nlohmann::json summary;
  summary["output"] = out;
  summary["structures"] = st.rows;
  summary["structure_count"] = st.rows.size();
  summary["triangles"] = st.triangles;
  summary["extracted_interface_triangles"] = extracted_triangles;
  summary["interface_triangles"] = x.triangles.size();
  summary["simplify_vertices_removed"] = vertices_removed;
  summary["islands_removed"] = removed_json;
  summary["islands_removed_voxels"] = removed.voxels;
  summary["label_table"] = table.source;
  summary["bytes"] = written_file_size(out);
  summary["tolerance_mm"] = tol;
  summary["seconds"] = seconds_since(t0);
  summary["stage_seconds"] = {{"labels", prepare_s},
                              {"extract", extract_s},
                              {"smooth", smooth_s},
                              {"simplify", simplify_s},
                              {"write", write_s}};
  return summary;
}

}  // namespace mlfe
