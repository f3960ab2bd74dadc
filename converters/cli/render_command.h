// What mlfe render (and convert --render) print of mlfe::pipeline::render's result.
#pragma once
#include <CLI/CLI.hpp>
#include <string>

#include "converters/cli/pipeline_options.h"

namespace mlfe::cli {

/// The render mesh and one line per frame on stderr (unless quiet), then the written files on
/// stdout.
void print_render(const pipeline::RenderResult& r, bool quiet);

}  // namespace mlfe::cli
