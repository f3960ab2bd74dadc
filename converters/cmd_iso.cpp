// mlfe iso: iso-surface assets (glTF/Draco, PLY/OBJ/STL/OFF) from a hierarchy, or from a volume
// as mlfe convert does.
#include <fmt/format.h>
#include <mlfe/core/error.h>
#include <mlfe/version.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <memory>
#include <optional>

#include "converters/commands.h"
#include "converters/convert_command.h"
#include "converters/volume_options.h"

namespace mlfe::cli {
namespace {

// The volume given for snapping must be the one the hierarchy was built from: same frame and
// the same box ([0, (n - 1) * spacing] per axis: the hierarchy's coarse mesh, or its data box
// on the samples' lattice).
void check_volume_matches(const std::string& volume, const ScalarGrid& g, const std::string& hierarchy,
                          const Built& b) {
  if (b.dim() != 3 || g.dim != 3)
    throw Error(volume + ": --volume needs a 3D volume and a 3D hierarchy (" + hierarchy + ")");
  auto near = [](double x, double y) {
    return std::abs(x - y) <= 1e-6 * std::max({1.0, std::abs(x), std::abs(y)});
  };
  const auto& t = g.transform;
  const auto& h = b.get<3>().hierarchy;
  std::array<double, 3> hi{0, 0, 0};  // the coarse mesh's vertices include the box's corners
  for (std::size_t e = 0; e < h.coarse_count(); ++e)
    for (VertexId v : h.cell(ElemId(std::uint32_t(e))))
      for (int a = 0; a < 3; ++a) hi[a] = std::max(hi[a], h.point(v)[a]);
  // On the samples' lattice T0 is a padded cube: the data's box is the one to match.
  if (b.get<3>().on_lattice) hi = b.get<3>().data_extent;
  for (int a = 0; a < 3; ++a) {
    if (!near(t.spacing[a], b.transform.spacing[a]) || !near(t.origin[a], b.transform.origin[a]))
      throw Error(volume + ": spacing or origin differ from the hierarchy's (" + hierarchy + ")");
    if (!near(double(g.dims[a] - 1) * t.spacing[a], hi[a]))
      throw Error(volume + ": its extent differs from the hierarchy's domain (" + hierarchy + ")");
  }
  for (int k = 0; k < 9; ++k)
    if (!near(t.direction[k], b.transform.direction[k]))
      throw Error(volume + ": its direction matrix differs from the hierarchy's (" + hierarchy + ")");
}

void run_iso(const ConvertState& s) {
  if (!is_hierarchy_file(s.input)) {
    if (!s.volume.empty())
      throw Error("--volume is for a hierarchy input; " + s.input + " is a volume itself");
    run_convert(s, "iso");
    return;
  }
  const nlohmann::json prov = {{"input", std::filesystem::path(s.input).filename().string()},
                               {"tool", std::string("mlfe ") + MLFE_VERSION}};
  check_distinct_files({{"input", s.input}, {"--volume", s.volume}},
                       {{"--output", s.output}, {"--report", s.report}});
  check_output_path(s.output, kAssetExtensions);
  if (!s.report.empty()) check_output_path(s.report, {});
  const AssetOptions asset = asset_options(s.asset);
  std::optional<ScalarGrid> grid;
  const Built b = built_from_file(s.input);
  if (!s.volume.empty()) {
    grid = read_volume(s.volume, s.read);
    check_volume_matches(s.volume, *grid, s.input, b);
  }
  const nlohmann::json summary = write_assets(s.output, b, asset, prov, grid ? &*grid : nullptr);
  if (!s.report.empty()) {
    nlohmann::json r = build_report(s.input, grid ? &*grid : nullptr, b);
    r["asset"] = summary;
    r["peak_rss_mb"] = peak_rss_mb();
    write_json(s.report, r);
  }
  print_written(s, summary, "iso");
}

void add_iso_command(CLI::App& app) {
  auto state = std::make_shared<ConvertState>();
  CLI::App* cmd =
      app.add_subcommand("iso", "Iso-surfaces from a hierarchy (.mlfeh) or a volume (built first)");
  cmd->add_option("input", state->input, "hierarchy (.mlfeh), volume or tetrahedral mesh (vtu, msh)")
      ->required();
  cmd->add_option(
      "--volume", state->volume,
      "with a hierarchy input: the volume it was built from, so surfaces snap onto it as in convert");
  add_convert_options(cmd, *state);
  cmd->callback([state] {
    apply_memory_budget(state->read, state->params);
    run_iso(*state);
  });
}

}  // namespace

MLFE_REGISTER_COMMAND(40, add_iso_command);

}  // namespace mlfe::cli
