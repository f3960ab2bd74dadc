// mlfe convert: volume in, iso-surface asset (glTF/Draco, PLY/OBJ/STL/OFF) out, in one command;
// the work is mlfe::pipeline::convert (include/mlfe/pipeline.h).
#include <fmt/format.h>
#include <mlfe/core/base/error.h>

#include <cstdio>
#include <memory>
#include <optional>

#include "converters/cli/commands.h"
#include "converters/cli/convert_command.h"
#include "converters/cli/render_command.h"
#include "converters/cli/volume_options.h"

namespace mlfe::cli {

void add_convert_options(CLI::App* cmd, ConvertState& s) {
  cmd->add_option("-o,--output", s.output, "output: .glb .gltf .drc .ply .obj .stl .off")->required();
  cmd->add_option("--report", s.report, "JSON report (build statistics and the asset summary)");
  add_asset_options(cmd, s.asset);
  add_build_options(cmd, s.params);
  add_volume_read_options(cmd, s.read);
}

void print_written(const ConvertState& s, const pipeline::ConvertFileResult& r, const char* command) {
  if (!s.params.quiet)
    status_line(fmt::format("mlfe {}: {} triangles, {} bytes -> {}", command,
                            r.asset["triangles"].get<std::size_t>(), r.asset["bytes"].get<std::size_t>(),
                            s.output));
  // The image's lines come after the asset's, then its files (and the preview page).
  for (std::size_t i = 0; i < r.written.size(); ++i)
    if (r.render.written.empty() || r.written[i] != r.render.written.front()) {
      std::printf("%s\n", r.written[i].c_str());
    } else {
      print_render(r.render, s.params.quiet);
      i += r.render.written.size() - 1;
    }
}

void run_convert(const ConvertState& s, const char* command) {
  pipeline::ConvertFileOptions c;
  c.hierarchy = s.hierarchy;
  c.report = s.report;
  c.render = s.render;
  c.png = s.png;
  c.preview = s.preview;
  c.read = s.read;
  c.asset = asset_options(s.asset);
  c.build = build_options(s.params);
  // The provenance keeps --rms as it was spelled.
  if (!s.params.rms.empty()) c.provenance["options"]["rms"] = s.params.rms;
  c.progress = progress_display(std::string("mlfe ") + command, s.params.quiet);
  const pipeline::ConvertFileResult r = pipeline::convert(s.input, s.output, c);
  warn_if_memory_limited(r.built, s.input, s.params.max_memory);
  print_warnings(r.warnings);
  print_written(s, r, command);
}

void run_convert_labels(const ConvertState& s) {
  if (!s.asset.iso.empty()) throw CLI::ValidationError("--labels", "--labels and --iso exclude each other");
  if (!s.render.empty()) throw CLI::ValidationError("--labels", "--labels writes no image (no --render)");
  if (s.asset.bricks > 0)
    throw CLI::ValidationError("--bricks", "--labels converts the whole label map at once (no --bricks)");
  check_output_path(s.output, kAssetExtensions);
  if (!s.hierarchy.empty()) {
    if (is_hierarchy_file(s.input))
      throw CLI::ValidationError("--hierarchy", s.input + " is a hierarchy already (no --hierarchy)");
    check_output_path(s.hierarchy, {".mlfeh"});
  }
  if (!s.report.empty()) check_output_path(s.report, {});
  pipeline::ConvertFileOptions c;
  c.preview = s.preview;
  c.png = s.png;
  c.labels = label_options(s.labels, s.asset);
  c.hierarchy = s.hierarchy;
  c.report = s.report;
  c.read = s.read;
  c.build.max_memory = parse_memory_budget(s.params.max_memory, "max_memory");
  c.progress = progress_display("mlfe convert", s.params.quiet);
  const pipeline::ConvertFileResult r = pipeline::convert(s.input, s.output, c);
  const nlohmann::json& summary = r.asset;
  if (!s.params.quiet) {
    std::size_t islands = 0;
    for (const auto& [l, n] : summary["islands_removed"].items()) islands += n.get<std::size_t>();
    std::size_t pieces = 0, open = 0;
    for (const auto& st : summary["structures"]) {
      pieces += st["pieces"].get<std::size_t>();
      open += !st["closed"].get<bool>();
    }
    status_line(
        fmt::format("mlfe convert: {} structures ({} pieces{}), {} islands removed by --min-component{}",
                    summary["structure_count"].get<std::size_t>(), pieces,
                    open ? ", SOME NOT CLOSED" : ", all closed", islands,
                    summary["label_table"].get<std::string>().empty()
                        ? ", no label table (label_N names)"
                        : ", table " + summary["label_table"].get<std::string>()));
  }
  print_written(s, r, "convert");
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
  cmd->add_option("--png", state->png, "with --render: the image as an sRGB PNG too (shown by --preview)");
  cmd->add_option(
      "--preview", state->preview,
      "also a self-contained HTML page showing the asset (.glb/.gltf output): open it from disk in "
      "any browser with WebGL; structures, the report's figures and the --png image");
  add_convert_options(cmd, *state);
  add_label_options(cmd, state->labels);
  cmd->callback([state] {
    if (state->labels.labels->count() > 0)
      run_convert_labels(*state);
    else
      run_convert(*state, "convert");
  });
}

}  // namespace

MLFE_REGISTER_COMMAND(50, add_convert_command);

}  // namespace mlfe::cli
