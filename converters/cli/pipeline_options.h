// The command line's spelling of the pipeline's options (include/mlfe/pipeline.h): CLI11 options
// that fill text parameters, parsed into the library's typed options with the library's one
// vocabulary (mlfe::pipeline::parse_*), and the progress the commands show on stderr.
#pragma once
#include <mlfe/pipeline.h>

#include <CLI/CLI.hpp>
#include <cstdint>
#include <string>
#include <type_traits>
#include <variant>
#include <vector>

namespace mlfe::cli {

struct BuildParams {
  /// Target RMS error: "0.5%" of the value range, or absolute. Empty: the default, which is
  /// 0.5% without iso-values and none with them (surface-driven refinement; see mlfe::build).
  std::string rms;
  double threshold = 0;  ///< the paper's per-element threshold (data units), 0: off
  std::size_t max_vertices = 0;
  int max_level = 20;
  int start_level = -1;
  std::string norm = "l2";              ///< "l2" or "h1"
  std::string preconditioner = "auto";  ///< "auto", "bpx", "jacobi", "none"
  double surface_tolerance = 0.5;       ///< voxels, for iso-aware refinement
  bool check_against_u = false;         ///< surface-driven: refine where u misses the data's surfaces
  /// Memory budget of the build: "50%" of the machine's RAM (default), or bytes with an
  /// optional K/M/G suffix; "0": none. Refinement stops at it with a message.
  std::string max_memory = "50%";
  bool quiet = false;
};

/// Adds --rms, --threshold, --max-vertices, --max-level, --start-level, --norm,
/// --preconditioner, --surface-tolerance, --check-u, --max-memory and --quiet.
void add_build_options(CLI::App* cmd, BuildParams& p);

/// The typed options of `p`, with the refinement table on stderr unless p.quiet; throws
/// mlfe::UsageError on bad text (--rms, --max-memory).
BuildOptions build_options(const BuildParams& p);

/// Adds one option per field of `fields` (a table of the library's, e.g.
/// pipeline::render_fields()) to `cmd`, writing into `o` when parsed: a bool as a flag (one
/// spelled "--no-..." clears it), numbers and text bound typed, the other types parsed from
/// their text by the library (pipeline::set_option_text); the help shows the default where the
/// field asks. `o` and `fields` must outlive parsing.
template <class O>
void add_fields(CLI::App* cmd, const std::vector<pipeline::OptionField<O>>& fields, O& o) {
  for (const pipeline::OptionField<O>& f : fields) {
    const std::string flag = f.spec.flag;
    CLI::Option* opt = std::visit(
        [&](const auto& m) -> CLI::Option* {
          using M = std::decay_t<decltype(m)>;
          if constexpr (std::is_same_v<M, bool O::*>) {
            if (flag.rfind("--no-", 0) == 0)
              return cmd->add_flag_callback(
                  flag, [&o, m] { o.*m = false; }, f.help);
            return cmd->add_flag(flag, o.*m, f.help);
          } else if constexpr (std::is_same_v<M, int O::*> || std::is_same_v<M, double O::*> ||
                               std::is_same_v<M, std::string O::*>) {
            return cmd->add_option(flag, o.*m, f.help);
          } else {
            return cmd->add_option_function<std::string>(
                flag, [&o, &f](const std::string& text) { pipeline::set_option_text(f, o, text); }, f.help);
          }
        },
        f.member);
    if (f.show_default) opt->default_str(pipeline::option_text(f, O{}));
  }
}

using pipeline::parse_memory_budget;
using pipeline::parse_values;

/// The warning on stderr when `b` stopped refining at its memory budget.
void warn_if_memory_limited(const Built& b, const std::string& source, const std::string& max_memory);

/// Warnings of a pipeline call, one "mlfe: warning: ..." line each.
void print_warnings(const std::vector<std::string>& warnings);

/// The progress of `command` ("mlfe convert") on stderr, nothing when quiet: on a terminal one
/// bar redrawn in place ([#####.....] 45% building); otherwise a line when one of the last
/// stages starts (rendering, resampling, writing), so logs show where the time goes without a
/// line per percent (the build prints its own table). Also installs the Ctrl-C handler: the
/// first Ctrl-C makes the returned Progress (quiet too) ask the call to stop, which then throws
/// pipeline::Cancelled with no output written; a second one ends the process.
pipeline::Progress progress_display(const std::string& command, bool quiet);

/// Prints one line of text on stderr, clearing a progress bar drawn on the terminal first.
void status_line(const std::string& text);

struct AssetParams {
  std::string iso;  ///< comma-separated iso-values (3D)
  double tolerance = 0;
  bool no_draco = false;
  bool quantize = false;
  int lod = 0;
  std::size_t decimate = 0;
  double simplify = 0.3;
  double ratio = 0.1;
  std::string simplifier = "auto";  ///< "auto", "fast", "bounded"
  double snap = 1.0;
  std::size_t min_component = 0;
  bool normals_toward_higher = false;
  std::string normals = "auto";    ///< "auto", "gradient", "surface"
  std::string placement = "auto";  ///< "auto", "input", "optimal"
  double z_scale = 1.0;
  int level = -1;
  std::int64_t bricks = -1;
  std::string surface = "auto";  ///< "auto", "samples", "hierarchy"
};

/// Adds --iso, --tolerance, --no-draco, --quantize, --lod, --decimate, --simplify,
/// --simplifier, --placement, --snap, --min-component, --normals-toward-higher, --normals, --z-scale,
/// --level.
void add_asset_options(CLI::App* cmd, AssetParams& p);

/// The typed options of `p`; throws mlfe::Error on bad --iso text.
AssetOptions asset_options(const AssetParams& p);

/// `mlfe convert --labels`: a label map to one surface per structure (convert_labels).
struct LabelParams {
  CLI::Option* labels = nullptr;  ///< --labels [LIST]; given when count() > 0
  std::string list;               ///< "3,7-9"; empty: every label present
  std::string table;              ///< --label-table FILE
  int smooth = 20;                ///< --smooth-iterations
  double max_offset = 0.5;        ///< --max-offset (voxels)
  /// The asset options' --simplify: given, it overrides the label default (LabelOptions).
  CLI::Option* simplify = nullptr;
};

/// Adds --labels [LIST], --label-table, --smooth-iterations and --max-offset (--min-component is
/// the asset option's).
void add_label_options(CLI::App* cmd, LabelParams& p);

/// The typed options of `p` and the asset options they share (--simplify, --tolerance,
/// --no-draco, --quantize), warnings on stderr; throws mlfe::Error on a bad label list.
LabelOptions label_options(const LabelParams& p, const AssetParams& asset);

}  // namespace mlfe::cli
