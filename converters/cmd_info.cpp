// mlfe info FILE: what a volume file holds and what reading it costs, without computing anything.
#include <fmt/format.h>

#include <chrono>
#include <cstdio>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>

#include "converters/commands.h"
#include "converters/volume_options.h"
#include "formats/vdb_reader.h"
#include "formats/volume_reader.h"

namespace mlfe::cli {
namespace {

struct InfoArgs {
  std::string file;
  VolumeReadOptions read;
  bool json = false;
};

void run_info(const InfoArgs& a) {
  const auto t0 = std::chrono::steady_clock::now();
  ScalarGrid g = read_volume(a.file, a.read);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const auto range = g.value_range();
  const std::uint64_t memory = static_cast<std::uint64_t>(g.voxel_count()) * sizeof(float);
  std::vector<std::string> grids;
  if (g.format == "vdb") grids = list_vdb_grids(a.file);
  const auto& t = g.transform;
  if (a.json) {
    nlohmann::json j;
    j["file"] = a.file;
    j["format"] = g.format;
    j["dim"] = g.dim;
    j["dims"] = g.dims;
    j["type"] = scalar_type_name(g.source_type);
    j["spacing"] = t.spacing;
    j["origin"] = t.origin;
    j["direction"] = t.direction;
    j["space"] = g.space;
    j["range"] = {range[0], range[1]};
    j["memory_bytes"] = memory;
    j["read_seconds"] = seconds;
    j["notes"] = g.notes;
    if (!grids.empty()) j["grids"] = grids;
    std::printf("%s\n", j.dump(2).c_str());
    return;
  }
  fmt::print("file:      {}\n", a.file);
  fmt::print("format:    {}\n", g.format);
  fmt::print("dims:      {} x {} x {} ({}D, {} voxels)\n", g.dims[0], g.dims[1], g.dims[2], g.dim, g.voxel_count());
  fmt::print("type:      {} (stored as float32)\n", scalar_type_name(g.source_type));
  fmt::print("spacing:   {} {} {}\n", t.spacing[0], t.spacing[1], t.spacing[2]);
  fmt::print("origin:    {} {} {}\n", t.origin[0], t.origin[1], t.origin[2]);
  const auto& d = t.direction;
  fmt::print("direction: [{} {} {}; {} {} {}; {} {} {}]\n", d[0], d[1], d[2], d[3], d[4], d[5], d[6], d[7], d[8]);
  fmt::print("space:     {}\n", g.space.empty() ? "(not given)" : g.space);
  fmt::print("range:     {} .. {}\n", range[0], range[1]);
  fmt::print("memory:    {} bytes as float32 ({:.1f} MiB); read in {:.3f} s\n", memory, memory / 1048576.0, seconds);
  for (const auto& name : grids) fmt::print("grid:      {}\n", name);
  if (!g.notes.empty()) {
    std::string notes = g.notes;
    std::size_t start = 0;
    while (start <= notes.size()) {
      auto end = notes.find('\n', start);
      if (end == std::string::npos) end = notes.size();
      fmt::print("note:      {}\n", notes.substr(start, end - start));
      start = end + 1;
    }
  }
}

void add_info_command(CLI::App& app) {
  auto args = std::make_shared<InfoArgs>();
  CLI::App* cmd = app.add_subcommand("info", "print the format, grid, transform and value range of a volume file");
  cmd->add_option("FILE", args->file, "volume or height field (vdb, nrrd, nii[.gz], mha/mhd, raw+json, pgm, png)")
      ->required()
      ->check(CLI::ExistingFile);
  add_volume_read_options(cmd, args->read);
  cmd->add_flag("--json", args->json, "print JSON instead of text");
  cmd->callback([args] { run_info(*args); });
}

}  // namespace

MLFE_REGISTER_COMMAND(20, add_info_command);

}  // namespace mlfe::cli
