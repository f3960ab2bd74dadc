// Shared command-line options for reading volumes, so every subcommand that takes an input
// volume spells them the same way.
#pragma once
#include <mlfe/formats/volume_reader.h>

#include <CLI/CLI.hpp>
#include <string>
#include <utility>
#include <vector>

namespace mlfe::cli {

/// Adds --grid, --vec-magnitude, --nan-as, --space, --raw-dims, --raw-type, --raw-endian,
/// --raw-spacing, --raw-origin and --raw-offset to `cmd`, writing into `opts` when parsed.
/// `opts` must outlive parsing (keep it next to the CLI::App, e.g. in a static or a
/// shared_ptr captured by the callback).
void add_volume_read_options(CLI::App* cmd, VolumeReadOptions& opts);

}  // namespace mlfe::cli

namespace mlfe {
using cli::add_volume_read_options;
}
