// What `mlfe convert` and `mlfe iso` share: their options and the conversion of a volume input
// through mlfe::pipeline::convert (include/mlfe/pipeline.h), with the command line's messages.
#pragma once
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <string>

#include "converters/cli/pipeline_options.h"
#include "converters/cli/render_command.h"

namespace mlfe::cli {

struct ConvertState {
  std::string input, output, hierarchy, report;
  std::string volume;  ///< iso on a hierarchy: the volume it was built from, for --snap
  BuildParams params;
  AssetParams asset;
  VolumeReadOptions read;
  std::string render;   ///< convert --render: also a ray-cast image (.exr) with the default view
  std::string png;      ///< convert --png: --render's image as PNG too
  std::string preview;  ///< convert --preview: the page showing the asset (.html)
  LabelParams labels;   ///< convert --labels: a label map, one surface per structure
};

/// Adds -o, --report and the asset, build and volume reading options.
void add_convert_options(CLI::App* cmd, ConvertState& s);

/// Volume in, asset (and --hierarchy, --report, --render) out; `command` names the
/// subcommand in messages.
void run_convert(const ConvertState& s, const char* command);

/// convert --labels: a label map in, one surface per structure out (convert_labels).
void run_convert_labels(const ConvertState& s);

/// The closing lines of convert and iso: the asset summary on stderr (unless quiet), then
/// the written files on stdout (convert --render: the image's lines before its files).
void print_written(const ConvertState& s, const pipeline::ConvertFileResult& r, const char* command);

}  // namespace mlfe::cli
