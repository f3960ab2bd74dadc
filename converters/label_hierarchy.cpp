// Label maps stored as hierarchies; see label_hierarchy.h.
#include "converters/label_hierarchy.h"

#include <fmt/format.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/fem/hierarchy_resample.h>

#include <algorithm>
#include <cmath>

namespace mlfe::pipeline::detail {

nlohmann::json stored_label_table(const LabelTable& table,
                                  const std::map<std::uint16_t, std::size_t>& counts) {
  nlohmann::json rows = nlohmann::json::array();
  for (const auto& [l, n] : counts) {
    if (l == 0) continue;
    const auto c = table.color(l);
    rows.push_back({{"value", l}, {"name", table.name(l)}, {"color", {c[0], c[1], c[2]}}});
  }
  return {{"labels", rows}};
}

bool is_label_hierarchy(const HierarchyFile& f) {
  return f.metadata.is_object() && f.metadata.contains("labels") && f.metadata["labels"].is_object();
}

StoredLabelMap read_stored_label_map(const HierarchyFile& f, const std::string& path) {
  if (!is_label_hierarchy(f))
    throw Error(path + ": not a label map (no stored label table; build it with mlfe build --labels)");
  if (!f.on_lattice || f.dim != 3 || f.values.empty())
    throw Error(path + ": a label map must be a 3D hierarchy on the samples' lattice with values");
  StoredLabelMap m;
  // An empty stored table (only background) parses as none: the table format needs an entry.
  if (!f.metadata["labels"].value("labels", nlohmann::json::array()).empty())
    m.table = parse_label_table(f.metadata["labels"].dump(), path + " (stored label table).json");
  m.table.source = m.table.entries.empty() ? "" : path + " (stored)";
  ScalarGrid& g = m.grid;
  g.dim = 3;
  g.dims = f.data_dims;
  g.transform = f.transform;
  g.space = f.space;
  g.source = path;
  g.format = "mlfeh";
  g.values = resample_to_grid(std::get<Hierarchy<3>>(f.hierarchy), f.values, g.dims, f.transform.spacing);
  for (float& v : g.values) {
    const float r = std::nearbyint(v);
    if (!(std::fabs(v - r) <= kLabelSampleBound))
      throw Error(fmt::format("{}: a decoded sample ({}) is not near a label: not a label map", path, v));
    v = r;
  }
  label_grid(g);  // labels 0..65535, else mlfe::Error
  return m;
}

template <int D>
std::vector<std::uint16_t> leaf_labels(const Hierarchy<D>& h, const std::vector<ElemId>& leaves,
                                       const std::vector<double>& values) {
  std::vector<std::uint16_t> out;
  out.reserve(leaves.size());
  for (ElemId e : leaves) {
    std::array<std::uint16_t, D + 1> c{};
    const auto& vs = h.cell(e);
    for (int s = 0; s <= D; ++s) {
      const double v = std::nearbyint(values[vs[s].value]);
      c[s] = static_cast<std::uint16_t>(std::clamp(v, 0.0, 65535.0));
    }
    std::sort(c.begin(), c.end());
    // The labels with the most corners; a tie goes to one of them picked by the element's
    // vertex ids (their sum modulo the number tied), so no label (the background, the lowest)
    // is favoured and region volumes stay unbiased.
    std::array<std::uint16_t, D + 1> tied{};
    int n_tied = 0, best_n = 0;
    std::uint64_t id_sum = 0;
    for (int s = 0; s <= D; ++s) id_sum += vs[s].value;
    for (int s = 0; s <= D;) {
      int t = s;
      while (t <= D && c[t] == c[s]) ++t;
      if (t - s > best_n) best_n = t - s, n_tied = 0;
      if (t - s == best_n) tied[n_tied++] = c[s];
      s = t;
    }
    const std::uint16_t best = tied[id_sum % std::uint64_t(n_tied)];
    out.push_back(best);
  }
  return out;
}

template std::vector<std::uint16_t> leaf_labels<2>(const Hierarchy<2>&, const std::vector<ElemId>&,
                                                   const std::vector<double>&);
template std::vector<std::uint16_t> leaf_labels<3>(const Hierarchy<3>&, const std::vector<ElemId>&,
                                                   const std::vector<double>&);

std::string label_table_file(const std::string& named, const std::string& volume) {
  return named.empty() ? find_label_table(volume) : named;
}

LabelTable named_or_beside_table(const std::string& named, const std::string& volume,
                                 std::vector<std::string>& warnings) {
  if (!named.empty()) return read_label_table(named);
  LabelTable table;
  if (const std::string found = find_label_table(volume); !found.empty()) {
    try {
      table = read_label_table(found);
    } catch (const Error& e) {
      warnings.push_back(std::string(e.what()) + " (found beside the volume; not used)");
    }
  }
  return table;
}

nlohmann::json label_metadata(const ScalarGrid& grid, const std::string& label_table,
                              std::vector<std::string>& warnings) {
  const LabelGrid lg = label_grid(grid);
  return stored_label_table(named_or_beside_table(label_table, grid.source, warnings), label_counts(lg));
}

}  // namespace mlfe::pipeline::detail
