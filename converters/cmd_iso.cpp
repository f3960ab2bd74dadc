// mlfe iso / mlfe convert: iso-surface assets (glTF/Draco, PLY/OBJ/STL/OFF) from a hierarchy or
// a volume, in one command.
#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <memory>

#include "converters/commands.h"
#include "converters/pipeline.h"
#include "converters/render_command.h"
#include "converters/volume_options.h"
#include "core/error.h"

namespace mlfe::cli {
namespace {

struct IsoState {
  std::string input, output, hierarchy, report;
  std::string volume;  ///< iso on a hierarchy: the volume it was built from, for --snap
  BuildParams params;
  AssetParams asset;
  VolumeReadOptions read;
  std::string render;  ///< convert --render: also a ray-cast image (.exr) with the default view
};

// The volume given for snapping must be the one the hierarchy was built from: same frame and
// the same box (the hierarchy's coarse mesh spans the grid, [0, (n - 1) * spacing] per axis).
void check_volume_matches(const std::string& volume, const ScalarGrid& g, const std::string& hierarchy,
                          const Built& b) {
  if (b.dim != 3 || g.dim != 3)
    throw Error(volume + ": --volume needs a 3D volume and a 3D hierarchy (" + hierarchy + ")");
  auto near = [](double x, double y) {
    return std::abs(x - y) <= 1e-6 * std::max({1.0, std::abs(x), std::abs(y)});
  };
  const auto& t = g.transform;
  const auto& h = b.a3->hierarchy;
  std::array<double, 3> hi{0, 0, 0};  // the coarse mesh's vertices include the box's corners
  for (std::size_t e = 0; e < h.coarse_count(); ++e)
    for (VertexId v : h.cell(ElemId(std::uint32_t(e))))
      for (int a = 0; a < 3; ++a) hi[a] = std::max(hi[a], h.point(v)[a]);
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

void run(const IsoState& s, bool convert) {
  nlohmann::json prov = {{"input", std::filesystem::path(s.input).filename().string()},
                         {"tool", std::string("mlfe ") + MLFE_VERSION}};
  check_output_path(s.output, kAssetExtensions);
  if (!s.hierarchy.empty()) check_output_path(s.hierarchy, {".mlfeh"});
  if (!s.report.empty()) check_output_path(s.report, {});
  if (!s.render.empty()) check_output_path(s.render, {".exr"});
  if (!s.asset.iso.empty()) parse_values(s.asset.iso, "--iso");
  std::optional<ScalarGrid> grid;
  Built b;
  if (!convert && is_hierarchy_file(s.input)) {
    b = built_from_file(s.input);
    if (!s.volume.empty()) {
      grid = read_volume(s.volume, s.read);
      check_volume_matches(s.volume, *grid, s.input, b);
    }
  } else {
    if (!s.volume.empty())
      throw Error("--volume is for a hierarchy input; " + s.input + " is a volume itself");
    grid = read_volume(s.input, s.read);
    std::vector<double> isos;
    if (grid->dim == 3) {
      if (s.asset.iso.empty()) throw Error("--iso is required for 3D volumes (e.g. --iso 80,150)");
      isos = parse_values(s.asset.iso, "--iso");
    }
    // u is solved for only when an output holds it (the hierarchy file, the rendered image).
    BuildParams params = s.params;
    params.solve_u = !s.hierarchy.empty() || !s.render.empty();
    b = build_from_grid(*grid, params, isos);
    if (!b.iterations().empty()) {
      const auto& last = b.iterations().back();
      prov["rms_error"] = last.rms_error;
      prov["rms_error_percent"] = last.rms_percent;
      prov["psnr_db"] = last.psnr_db;
    }
    prov["vertices"] = b.vertices();
    // The effective target: the default RMS applies only without iso-values (surface-driven
    // refinement otherwise) or alongside another global target.
    const bool surface_driven =
        s.params.rms.empty() && s.params.threshold <= 0 && s.params.max_vertices == 0 && !isos.empty();
    prov["options"] = {{"rms", !s.params.rms.empty() ? s.params.rms
                               : surface_driven      ? "none (surface-driven)"
                                                     : "0.5%"},
                       {"threshold", s.params.threshold},
                       {"max_vertices", s.params.max_vertices},
                       {"norm", s.params.norm},
                       {"surface_tolerance", s.params.surface_tolerance}};
    prov["refinement"] = b.surface_driven ? "surface-driven" : "global";
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
  // convert --render: the image of the hierarchy just built, with mlfe render's defaults.
  if (!s.render.empty())
    for (const auto& f :
         render_outputs(s.render, RenderParams{}, b, grid ? &*grid : nullptr, s.input, s.params.quiet))
      std::printf("%s\n", f.c_str());
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
  cmd->add_option(
      "--volume", state->volume,
      "with a hierarchy input: the volume it was built from, so surfaces snap onto it as in convert");
  add_common(cmd, *state);
  cmd->callback([state] { run(*state, false); });
}

void add_convert_command(CLI::App& app) {
  auto state = std::make_shared<IsoState>();
  CLI::App* cmd = app.add_subcommand(
      "convert", "Volume in, iso-surface asset out: adaptive build + marching tetrahedra + glTF/Draco");
  cmd->add_option("input", state->input, "volume or height field")->required();
  cmd->add_option("--hierarchy", state->hierarchy, "also keep the hierarchy it built (.mlfeh)");
  cmd->add_option("--render", state->render,
                  "also a ray-cast image of the hierarchy (.exr; mlfe render's defaults)");
  add_common(cmd, *state);
  cmd->callback([state] { run(*state, true); });
}

}  // namespace

MLFE_REGISTER_COMMAND(40, add_iso_command);
MLFE_REGISTER_COMMAND(50, add_convert_command);

}  // namespace mlfe::cli
