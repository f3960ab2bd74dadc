// mlfe iso / mlfe convert: iso-surface assets (glTF/Draco, PLY/OBJ/STL/OFF) from a hierarchy or
// a volume, in one command.
#include <fmt/format.h>

#include <filesystem>
#include <memory>

#include "converters/commands.h"
#include "converters/pipeline.h"
#include "converters/volume_options.h"
#include "core/error.h"

namespace mlfe::cli {
namespace {

struct IsoState {
  std::string input, output, hierarchy, report;
  BuildParams params;
  AssetParams asset;
  VolumeReadOptions read;
};

void run(const IsoState& s, bool convert) {
  nlohmann::json prov = {{"input", std::filesystem::path(s.input).filename().string()},
                         {"tool", std::string("mlfe ") + MLFE_VERSION}};
  check_output_path(s.output, kAssetExtensions);
  if (!s.hierarchy.empty()) check_output_path(s.hierarchy, {".mlfeh"});
  if (!s.report.empty()) check_output_path(s.report, {});
  if (!s.asset.iso.empty()) parse_values(s.asset.iso, "--iso");
  std::optional<ScalarGrid> grid;
  Built b;
  if (!convert && is_hierarchy_file(s.input)) {
    b = built_from_file(s.input);
  } else {
    grid = read_volume(s.input, s.read);
    std::vector<double> isos;
    if (grid->dim == 3) {
      if (s.asset.iso.empty()) throw Error("--iso is required for 3D volumes (e.g. --iso 80,150)");
      isos = parse_values(s.asset.iso, "--iso");
    }
    b = build_from_grid(*grid, s.params, isos);
    const auto& last = b.iterations().back();
    prov["rms_error"] = last.rms_error;
    prov["rms_error_percent"] = last.rms_percent;
    prov["psnr_db"] = last.psnr_db;
    prov["vertices"] = b.vertices();
    prov["options"] = {{"rms", s.params.rms},
                       {"threshold", s.params.threshold},
                       {"max_vertices", s.params.max_vertices},
                       {"norm", s.params.norm},
                       {"surface_tolerance", s.params.surface_tolerance}};
    if (!s.hierarchy.empty()) write_built(s.hierarchy, b, prov);
  }
  const nlohmann::json summary = write_assets(s.output, b, s.asset, prov, grid ? &*grid : nullptr);
  if (!s.report.empty()) {
    nlohmann::json r = build_report(s.input, grid ? &*grid : nullptr, b);
    r["asset"] = summary;
    r["peak_rss_mb"] = peak_rss_mb();
    write_json(s.report, r);
  }
  if (!s.params.quiet)
    std::fprintf(stderr, "mlfe %s: %zu triangles, %zu bytes -> %s\n", convert ? "convert" : "iso",
                 summary["triangles"].get<std::size_t>(), summary["bytes"].get<std::size_t>(),
                 s.output.c_str());
  std::printf("%s\n", s.output.c_str());
  if (!s.hierarchy.empty()) std::printf("%s\n", s.hierarchy.c_str());
  if (!s.report.empty()) std::printf("%s\n", s.report.c_str());
}

void add_common(CLI::App* cmd, IsoState& s) {
  cmd->add_option("-o,--output", s.output, "output: .glb .gltf .drc .ply .obj .stl .off")->required();
  cmd->add_option("--report", s.report, "JSON report (build statistics and the asset summary)");
  add_asset_options(cmd, s.asset);
  add_build_options(cmd, s.params);
  add_volume_read_options(cmd, s.read);
}

void add_iso_command(CLI::App& app) {
  auto state = std::make_shared<IsoState>();
  CLI::App* cmd =
      app.add_subcommand("iso", "Iso-surfaces from a hierarchy (.mlfeh) or a volume (built first)");
  cmd->add_option("input", state->input, "hierarchy (.mlfeh) or volume")->required();
  add_common(cmd, *state);
  cmd->callback([state] { run(*state, false); });
}

void add_convert_command(CLI::App& app) {
  auto state = std::make_shared<IsoState>();
  CLI::App* cmd = app.add_subcommand(
      "convert", "Volume in, iso-surface asset out: adaptive build + marching tetrahedra + glTF/Draco");
  cmd->add_option("input", state->input, "volume or height field")->required();
  cmd->add_option("--hierarchy", state->hierarchy, "also keep the hierarchy it built (.mlfeh)");
  add_common(cmd, *state);
  cmd->callback([state] { run(*state, true); });
}

}  // namespace

MLFE_REGISTER_COMMAND(40, add_iso_command);
MLFE_REGISTER_COMMAND(50, add_convert_command);

}  // namespace mlfe::cli
