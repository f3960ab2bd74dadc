// mlfe convert: volume in, iso-surface asset (glTF/Draco, PLY/OBJ/STL/OFF) out, in one command;
// the work is mlfe::convert (converters/pipeline.h).
#include <mlfe/core/error.h>

#include <cstdio>
#include <memory>
#include <optional>

#include "converters/commands.h"
#include "converters/convert_command.h"
#include "converters/label_hierarchy.h"
#include "converters/render_command.h"
#include "converters/volume_options.h"

namespace mlfe::cli {

void add_convert_options(CLI::App* cmd, ConvertState& s) {
  cmd->add_option("-o,--output", s.output, "output: .glb .gltf .drc .ply .obj .stl .off")->required();
  cmd->add_option("--report", s.report, "JSON report (build statistics and the asset summary)");
  add_asset_options(cmd, s.asset);
  add_build_options(cmd, s.params);
  add_volume_read_options(cmd, s.read);
}

void print_written(const ConvertState& s, const nlohmann::json& summary, const char* command) {
  if (!s.params.quiet)
    std::fprintf(stderr, "mlfe %s: %zu triangles, %zu bytes -> %s\n", command,
                 summary["triangles"].get<std::size_t>(), summary["bytes"].get<std::size_t>(),
                 s.output.c_str());
  std::printf("%s\n", s.output.c_str());
  if (!s.hierarchy.empty()) std::printf("%s\n", s.hierarchy.c_str());
  if (!s.report.empty()) std::printf("%s\n", s.report.c_str());
}

void run_convert(const ConvertState& s, const char* command) {
  ConvertOptions c;
  c.hierarchy = s.hierarchy;
  c.report = s.report;
  check_distinct_files(
      {{"input", s.input}, {"--volume", s.volume}},
      {{"--output", s.output}, {"--hierarchy", s.hierarchy}, {"--report", s.report}, {"--render", s.render}});
  check_output_path(s.output, kAssetExtensions);
  if (!c.hierarchy.empty()) check_output_path(c.hierarchy, {".mlfeh"});
  if (!c.report.empty()) check_output_path(c.report, {});
  if (!s.render.empty()) check_output_path(s.render, {".exr"});
  c.asset = asset_options(s.asset);
  c.build = build_options(s.params);
  c.keep_u = !s.render.empty();  // the image is of u
  // The provenance keeps --rms as it was spelled.
  if (!s.params.rms.empty()) c.provenance["options"]["rms"] = s.params.rms;
  // A tetrahedral mesh input: its P1 interpolant is the input function (no voxel grid).
  std::optional<ScalarGrid> grid;
  std::optional<ConvertResult> r;
  if (!detect_tet_mesh_format(s.input).empty()) {
    r = convert(read_tet_mesh(s.input, tet_mesh_read_options(s.read)), s.output, c);
  } else {
    grid = read_volume(s.input, s.read);
    r = convert(*grid, s.output, c);
  }
  warn_if_memory_limited(r->built, s.input, s.params.max_memory);
  print_written(s, r->asset, command);
  // convert --render: the image of the hierarchy just built, with mlfe render's defaults.
  if (!s.render.empty())
    for (const auto& f :
         render_outputs(s.render, RenderParams{}, r->built, grid ? &*grid : nullptr, s.input, s.params.quiet))
      std::printf("%s\n", f.c_str());
}

void run_convert_labels(const ConvertState& s) {
  if (!s.asset.iso.empty()) throw CLI::ValidationError("--labels", "--labels and --iso exclude each other");
  if (!s.render.empty()) throw CLI::ValidationError("--labels", "--labels writes no image (no --render)");
  check_output_path(s.output, kAssetExtensions);
  if (!s.hierarchy.empty()) {
    if (is_hierarchy_file(s.input))
      throw CLI::ValidationError("--hierarchy", s.input + " is a hierarchy already (no --hierarchy)");
    check_distinct_files({{"input", s.input}}, {{"--output", s.output}, {"--hierarchy", s.hierarchy}});
    check_output_path(s.hierarchy, {".mlfeh"});
  }
  if (!s.report.empty()) check_output_path(s.report, {});
  LabelOptions o = label_options(s.labels, s.asset);
  ScalarGrid grid;
  if (is_hierarchy_file(s.input)) {
    // A label hierarchy (mlfe build --labels): the same labels at the samples, its stored table.
    const HierarchyFile f = read_hierarchy(s.input);
    grid = read_stored_label_map(f, s.input).grid;
    if (!f.metadata["labels"].value("labels", nlohmann::json::array()).empty()) {
      o.table_json = f.metadata["labels"].dump();
      o.table_json_source = s.input + " (stored)";
    }
  } else {
    grid = read_volume(s.input, s.read);
  }
  const nlohmann::json summary = convert_labels(grid, s.output, o);
  // --hierarchy: the labels stored exactly with their table, as mlfe build --labels writes them.
  if (!s.hierarchy.empty()) write_label_hierarchy(grid, s.input, s.hierarchy, s.labels.table, s.params);
  if (!s.report.empty()) {
    nlohmann::json r = {{"input", s.input}, {"dims", grid.dims}, {"asset", summary}};
    r["peak_rss_mb"] = peak_rss_mb();
    write_json(s.report, r);
  }
  if (!s.params.quiet) {
    std::size_t islands = 0;
    for (const auto& [l, n] : summary["islands_removed"].items()) islands += n.get<std::size_t>();
    std::size_t pieces = 0, open = 0;
    for (const auto& st : summary["structures"]) {
      pieces += st["pieces"].get<std::size_t>();
      open += !st["closed"].get<bool>();
    }
    std::fprintf(stderr,
                 "mlfe convert: %zu structures (%zu pieces%s), %zu islands removed by --min-component%s\n",
                 summary["structure_count"].get<std::size_t>(), pieces,
                 open ? ", SOME NOT CLOSED" : ", all closed", islands,
                 summary["label_table"].get<std::string>().empty()
                     ? ", no label table (label_N names)"
                     : (", table " + summary["label_table"].get<std::string>()).c_str());
  }
  print_written(s, summary, "convert");
}

namespace {

void add_convert_command(CLI::App& app) {
  auto state = std::make_shared<ConvertState>();
  CLI::App* cmd = app.add_subcommand(
      "convert", "Volume in, iso-surface asset out: adaptive build + marching tetrahedra + glTF/Draco");
  cmd->add_option("input", state->input, "volume, height field or tetrahedral mesh (vtu, msh)")->required();
  cmd->add_option("--hierarchy", state->hierarchy, "also keep the hierarchy it built (.mlfeh)");
  cmd->add_option("--render", state->render,
                  "also a ray-cast image of the hierarchy (.exr; mlfe render's defaults)");
  add_convert_options(cmd, *state);
  add_label_options(cmd, state->labels);
  cmd->callback([state] {
    apply_memory_budget(state->read, state->params);
    if (state->labels.labels->count() > 0)
      run_convert_labels(*state);
    else
      run_convert(*state, "convert");
  });
}

}  // namespace

MLFE_REGISTER_COMMAND(50, add_convert_command);

}  // namespace mlfe::cli
