// mlfe info FILE: what a volume file holds and what reading it costs, without computing
// anything; for a hierarchy file (.mlfeh), its levels, counts, error figures and bytes per
// section.
#include <fmt/format.h>
#include <mlfe/pipeline.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>

#include "converters/cli/commands.h"
#include "converters/cli/volume_options.h"

namespace mlfe::cli {
namespace {

struct InfoArgs {
  std::string file;
  VolumeReadOptions read;
  bool json = false;
  bool labels = false;      ///< list the labels of a label map
  std::string label_table;  ///< names from this table (default: the one beside the volume)
};

std::string join(const std::array<double, 9>& d) {
  return fmt::format("[{} {} {}; {} {} {}; {} {} {}]", d[0], d[1], d[2], d[3], d[4], d[5], d[6], d[7], d[8]);
}

void print_labels(const pipeline::InfoResult& r) {
  fmt::print("labels:    {} (table: {})\n", r.labels.size(), r.label_table.empty() ? "none" : r.label_table);
  fmt::print("{:>8} {:>12} {:>14}  {}\n", "label", "voxels", "mm3", "name");
  for (const auto& l : r.labels)
    fmt::print("{:>8} {:>12} {:>14.2f}  {}\n", int(l.label), l.voxels, l.volume_mm3, l.name);
}

void print_hierarchy(const pipeline::InfoResult& r) {
  const HierarchyFileInfo& f = r.header;
  std::uint64_t total = 0;
  for (const auto& s : r.sections) total += s.file_bytes;
  fmt::print("file:      {}\n", r.file);
  fmt::print("format:    mlfe hierarchy, version {} ({}D), {} bytes; read in {:.3f} s\n", r.version, r.dim,
             total, r.read_seconds);
  fmt::print("mesh:      {} vertices, {} elements, {} leaves, {} levels\n", r.vertices, r.elements, r.leaves,
             r.levels);
  fmt::print(
      "values:    {}\n",
      r.value_coding == "none" ? std::string("none")
      : r.integer_values
          ? (r.value_bound > 0 ? fmt::format("integer surpluses, every vertex within {:.6g}", r.value_bound)
                               : std::string("integer surpluses, exact"))
      : r.value_bound > 0 ? fmt::format("quantized, every vertex within {:.6g}", r.value_bound)
                          : std::string("exact (f64)"));
  if (f.on_lattice)
    fmt::print("lattice:   level {} on the samples (T0 {} samples wide), data {} x {} x {} samples\n",
               f.lattice_level, std::int64_t(1) << f.lattice_level, f.data_dims[0], f.data_dims[1],
               f.data_dims[2]);
  if (!std::isnan(f.sample_error_bound))
    fmt::print("bound:     every sample within {:.6g} of the decoded function\n", f.sample_error_bound);
  fmt::print("range:     {} .. {}\n", f.value_min, f.value_max);
  if (!f.norm.empty()) fmt::print("norm:      {}\n", f.norm);
  if (!std::isnan(f.rms_error))
    fmt::print(
        "error:     RMS {:.6g}, max {:.6g}, PSNR {:.2f} dB (stored approximation against its source)\n",
        f.rms_error, f.max_error, f.psnr_db);
  const auto& t = f.transform;
  fmt::print("spacing:   {} {} {}\n", t.spacing[0], t.spacing[1], t.spacing[2]);
  fmt::print("origin:    {} {} {}\n", t.origin[0], t.origin[1], t.origin[2]);
  fmt::print("direction: {}\n", join(t.direction));
  fmt::print("space:     {}\n", f.space.empty() ? "(not given)" : f.space);
  if (!f.metadata.empty()) {
    nlohmann::json shown = f.metadata;  // a stored label table is listed below, not here
    if (r.has_labels) shown.erase("labels");
    fmt::print("metadata:  {}\n", shown.dump());
  }
  fmt::print("{:>7} {:>12} {:>12} {:>12}\n", "level", "vertices", "elements", "leaves");
  for (std::size_t k = 0; k < r.per_level.size(); ++k)
    fmt::print("{:>7} {:>12} {:>12} {:>12}\n", k, r.per_level[k].vertices, r.per_level[k].elements,
               r.per_level[k].leaves);
  fmt::print("{:<10} {:>12} {:>12}\n", "section", "file bytes", "raw bytes");
  for (const auto& s : r.sections) fmt::print("{:<10} {:>12} {:>12}\n", s.name, s.file_bytes, s.raw_bytes);
  if (r.has_labels) print_labels(r);
}

void print_volume(const pipeline::InfoResult& r) {
  const auto& t = r.transform;
  fmt::print("file:      {}\n", r.file);
  fmt::print("format:    {}\n", r.format);
  fmt::print("dims:      {} x {} x {} ({}D, {} voxels)\n", r.dims[0], r.dims[1], r.dims[2], r.dim, r.voxels);
  fmt::print("type:      {} (stored as float32)\n", r.type);
  fmt::print("spacing:   {} {} {}\n", t.spacing[0], t.spacing[1], t.spacing[2]);
  fmt::print("origin:    {} {} {}\n", t.origin[0], t.origin[1], t.origin[2]);
  fmt::print("direction: {}\n", join(t.direction));
  fmt::print("space:     {}\n", r.space.empty() ? "(not given)" : r.space);
  // The range is the float32 samples': printed as floats, as they were read.
  fmt::print("range:     {} .. {}\n", static_cast<float>(r.range[0]), static_cast<float>(r.range[1]));
  fmt::print("memory:    {} bytes as float32 ({:.1f} MiB); read in {:.3f} s\n", r.memory_bytes,
             r.memory_bytes / 1048576.0, r.read_seconds);
  for (const auto& name : r.grids) fmt::print("grid:      {}\n", name);
  if (r.has_labels) print_labels(r);
  std::size_t start = 0;
  while (!r.notes.empty() && start <= r.notes.size()) {
    auto end = r.notes.find('\n', start);
    if (end == std::string::npos) end = r.notes.size();
    fmt::print("note:      {}\n", r.notes.substr(start, end - start));
    start = end + 1;
  }
}

void run_info(const InfoArgs& a) {
  pipeline::InfoOptions o;
  o.read = a.read;
  o.labels = a.labels;
  o.label_table = a.label_table;
  const pipeline::InfoResult r = pipeline::info(a.file, o);
  for (const auto& w : r.warnings) std::fprintf(stderr, "mlfe: warning: %s\n", w.c_str());
  if (a.json)
    std::printf("%s\n", r.to_json().dump(2).c_str());
  else if (r.hierarchy)
    print_hierarchy(r);
  else
    print_volume(r);
}

void add_info_command(CLI::App& app) {
  auto args = std::make_shared<InfoArgs>();
  CLI::App* cmd = app.add_subcommand("info",
                                     "print the format, grid, transform and value range of a volume file, or "
                                     "the levels, errors and sections of a hierarchy file");
  cmd->add_option(
         "FILE", args->file,
         "volume or height field (vdb, nrrd, nii[.gz], mha/mhd, raw+json, pgm, png, OME-Zarr folder) or "
         "hierarchy (.mlfeh)")
      ->required()
      ->check(CLI::ExistingPath);
  add_volume_read_options(cmd, args->read);
  cmd->add_flag("--json", args->json, "print JSON instead of text");
  cmd->add_flag("--labels", args->labels, "a label map: list its labels with voxel counts, mm3 and names");
  cmd->add_option("--label-table", args->label_table,
                  "with --labels: names from this table (default: the one beside the volume)");
  cmd->callback([args] { run_info(*args); });
}

}  // namespace

MLFE_REGISTER_COMMAND(20, add_info_command);

}  // namespace mlfe::cli
