// mlfe iso: iso-surface assets (glTF/Draco, PLY/OBJ/STL/OFF) from a hierarchy, or from a volume
// as mlfe convert does.
#include <mlfe/core/base/error.h>
#include <mlfe/pipeline.h>

#include <memory>

#include "converters/cli/commands.h"
#include "converters/cli/convert_command.h"
#include "converters/cli/volume_options.h"

namespace mlfe::cli {
namespace {

void run_iso(const ConvertState& s) {
  if (!is_hierarchy_file(s.input)) {
    if (!s.volume.empty())
      throw Error("--volume is for a hierarchy input; " + s.input + " is a volume itself");
    run_convert(s, "iso");
    return;
  }
  pipeline::IsoOptions o;
  o.asset = asset_options(s.asset);
  o.build.max_memory = parse_memory_budget(s.params.max_memory, "max_memory");
  o.read = s.read;
  o.volume = s.volume;
  o.report = s.report;
  o.progress = progress_display("mlfe iso", s.params.quiet);
  print_written(s, pipeline::iso(s.input, s.output, o), "iso");
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
  cmd->callback([state] { run_iso(*state); });
}

}  // namespace

MLFE_REGISTER_COMMAND(40, add_iso_command);

}  // namespace mlfe::cli
