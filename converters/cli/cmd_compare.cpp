// mlfe compare EXPECTED ACTUAL: semantic diff of two outputs for golden-file tests (issue #17).
// Exit status (diff(1)'s convention): 0 equal within the tolerances, 1 different (one line per
// difference on stdout), 2 unreadable input or a usage error (main() maps compare's usage errors
// to 2 so that 1 always means "different").
#include <fmt/format.h>
#include <mlfe/core/base/error.h>
#include <mlfe/pipeline.h>
#include <mlfe/pipeline/compare.h>

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "converters/cli/commands.h"
#include "converters/cli/volume_options.h"

namespace mlfe::cli {
namespace {

struct CompareArgs {
  std::string expected, actual, report, count_tolerance;
  std::optional<double> tolerance, mean_tolerance, image_max, psnr, value_max, value_rms;
  CompareOptions options;
  bool quiet = false;
};

void run_compare(CompareArgs& a) {
  CompareOptions o = a.options;
  o.tolerance = a.tolerance;
  o.mean_tolerance = a.mean_tolerance;
  o.image_max = a.image_max;
  o.min_psnr = a.psnr;
  o.value_max = a.value_max;
  o.value_rms = a.value_rms;
  if (!a.count_tolerance.empty())
    o.count_tolerance_percent = pipeline::parse_percent(a.count_tolerance, "count_tolerance");
  const CompareResult r = pipeline::compare(a.expected, a.actual, o, a.report);
  if (!a.quiet) {
    if (r.equal())
      fmt::print("equal ({})\n", r.kind);
    else
      fmt::print("different ({}): {} vs {}\n", r.kind, a.expected, a.actual);
    for (const Difference& d : r.differences) fmt::print("  {}: {}\n", d.item, d.reason);
    for (const std::string& n : r.notes) fmt::print("  note: {}\n", n);
  }
  if (!r.equal()) command_exit_status() = 1;
}

void add_compare_command(CLI::App& app) {
  auto args = std::make_shared<CompareArgs>();
  CLI::App* cmd = app.add_subcommand("compare",
                                     "compare two outputs by content (meshes, glTF, images, volumes, "
                                     "hierarchies); exit 0 equal, 1 different, "
                                     "2 unreadable input or usage error");
  cmd->add_option("EXPECTED", args->expected, "the golden file")->required();
  cmd->add_option("ACTUAL", args->actual, "the file to check")->required();
  cmd->add_option(
      "--tolerance", args->tolerance,
      "meshes: largest Hausdorff distance and bounding-box difference, in the files' units "
      "(glTF: metres; default 1e-4 of the expected bounding-box diagonal); hierarchies: vertex positions");
  cmd->add_option("--mean-tolerance", args->mean_tolerance,
                  "meshes: largest mean distance (default: --tolerance)");
  cmd->add_option("--count-tolerance", args->count_tolerance,
                  "meshes: allowed vertex/triangle count difference, percent of the expected count (e.g. 2%; "
                  "default exact)");
  cmd->add_option("--normal-angle", args->options.normal_angle_deg,
                  "meshes: largest mean angle between matched normals, degrees")
      ->capture_default_str();
  cmd->add_option("--samples", args->options.samples, "meshes: area samples per mesh on top of every vertex")
      ->capture_default_str();
  cmd->add_option(
      "--image-max", args->image_max,
      "images: largest absolute channel difference (PNG values in [0,1]; default exact unless --psnr)");
  cmd->add_option("--psnr", args->psnr, "images: smallest PSNR per channel, dB");
  cmd->add_option(
      "--value-max", args->value_max,
      "volumes and hierarchy values: largest absolute difference (default exact unless --value-rms)");
  cmd->add_option("--value-rms", args->value_rms, "volumes and hierarchy values: largest RMS difference");
  cmd->add_option("--number-tolerance", args->options.number_tolerance,
                  "relative tolerance for numbers in headers, transforms, materials, extras")
      ->capture_default_str();
  cmd->add_option(
      "--ignore", args->options.ignore,
      "JSON pointer not compared (glTF structure, hierarchy metadata), e.g. /asset/generator; repeatable");
  cmd->add_flag("--strict", args->options.strict,
                "also compare provenance (input, generator, tool, timings) and the encoding (Draco or not, "
                "quantization, file format); by default only the content is compared");
  cmd->add_option("--report", args->report, "write every figure and difference as JSON");
  cmd->add_flag("--quiet", args->quiet, "print nothing; the exit status says it");
  cmd->callback([args] { run_compare(*args); });
}

}  // namespace

MLFE_REGISTER_COMMAND(60, add_compare_command);

}  // namespace mlfe::cli
