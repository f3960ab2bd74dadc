// mlfe export: a hierarchy file's approximation as a voxel grid (NIfTI, NRRD, raw + JSON,
// OpenVDB) on the grid it was built from, or its leaf mesh (VTK .vtu, Gmsh .msh) with the
// values and element levels, in the file's physical frame.
#include <mlfe/core/error.h>
#include <mlfe/core/sample_lattice.h>
#include <mlfe/core/usage_error.h>
#include <mlfe/formats/file_names.h>
#include <mlfe/formats/hierarchy_io.h>
#include <mlfe/formats/hierarchy_resample.h>
#include <mlfe/formats/msh_writer.h>
#include <mlfe/formats/volume_writer.h>
#include <mlfe/formats/vtu_writer.h>
#include <mlfe/pipeline.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <string>

#include "converters/commands.h"
#include "converters/label_hierarchy.h"
#include "converters/volume_options.h"

namespace mlfe::cli {
namespace {

struct ExportState {
  std::string input, output;
  int level = -1;
};

template <int D>
void export_hierarchy(const ExportState& s, const HierarchyFile& f, const Hierarchy<D>& h_in) {
  const std::string ext = lower_extension(s.output);
  const std::vector<double>* values = f.values.empty() ? nullptr : &f.values;
  if (ext == ".vtu" || ext == ".msh") {
    // On the samples' lattice the mesh is the data's box: the padding's leaves are left out and
    // those across the box's faces refined until none is (u carried along its edges).
    Hierarchy<D> conformed;
    std::vector<double> conformed_values;
    const Hierarchy<D>* hp = &h_in;
    std::vector<ElemId> leaves;
    if (f.on_lattice) {
      conformed = h_in;
      if (values) conformed_values = *values;
      leaves = leaves_in_data(conformed, conformed_values,
                              sample_lattice(D, f.data_dims, f.transform.spacing, f.lattice_level));
      hp = &conformed;
      if (values) values = &conformed_values;
    } else {
      leaves = h_in.leaves();
    }
    const Hierarchy<D>& h = *hp;
    // A label hierarchy (mlfe build --labels): each leaf in the region of its label
    // (label_hierarchy.h: the majority of its corners), named from the stored table.
    ElementRegions regions;
    const bool labelled = D == 3 && is_label_hierarchy(f) && values;
    if (labelled) {
      const LabelTable table = read_stored_label_map(f, s.input).table;
      regions.label = leaf_labels(h, leaves, *values);
      for (std::uint16_t l : regions.label)
        if (!regions.names.count(l))
          regions.names[l] = l == 0 && !table.entries.count(0) ? "background" : table.name(l);
    }
    if (ext == ".vtu")
      write_vtu(s.output, h, leaves, values, &f.transform, labelled ? &regions : nullptr);
    else
      write_msh(s.output, h, leaves, values, &f.transform, labelled ? &regions : nullptr);
    std::fprintf(stderr, "mlfe export: %zu elements, %zu vertices, level %d\n", leaves.size(),
                 h.vertex_count(), h.max_level());
    return;
  }
  if (!values) throw Error(s.input + ": the file stores no values, so there is no grid to export");
  ScalarGrid g;
  g.dim = D;
  g.transform = f.transform;
  g.space = f.space;
  // On the samples' lattice (v3) T0 is a padded cube: the grid is the data's, not T0's box.
  try {
    g.dims = f.on_lattice ? f.data_dims : hierarchy_grid_dims(h_in, f.transform.spacing);
  } catch (const Error& e) {
    throw Error(s.input + ": " + e.what());
  }
  const auto t0 = std::chrono::steady_clock::now();
  g.values = resample_to_grid(h_in, f.values, g.dims, f.transform.spacing);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  write_volume(s.output, g);
  std::fprintf(stderr, "mlfe export: %lld x %lld x %lld grid from level %d (resampled in %.3f s)\n",
               static_cast<long long>(g.dims[0]), static_cast<long long>(g.dims[1]),
               static_cast<long long>(g.dims[2]), h_in.max_level(), seconds);
}

void run_export(const ExportState& s) {
  const std::string ext = lower_extension(s.output);
  check_distinct_files(
      {{"input", s.input}},
      {{"--output", s.output}, {"--output's sidecar", ext == ".raw" ? s.output + ".json" : ""}});
  if (ext != ".vtu" && ext != ".msh" && !is_volume_output(s.output))
    throw Error(s.output + ": unknown output type '" + ext +
                "' (use .nii.gz .nii .nrrd .raw .vdb .vtu .msh)");
  check_output_path(s.output, {});
  const HierarchyFile f = read_hierarchy(s.input, s.level);
  if (s.level > f.file_levels)
    throw UsageError(s.input + ": --level " + std::to_string(s.level) + " but the file has " +
                     std::to_string(f.file_levels) + " levels");
  if (f.dim == 2)
    export_hierarchy(s, f, std::get<Hierarchy<2>>(f.hierarchy));
  else
    export_hierarchy(s, f, std::get<Hierarchy<3>>(f.hierarchy));
  std::printf("%s\n", s.output.c_str());
}

void add_export_command(CLI::App& app) {
  auto state = std::make_shared<ExportState>();
  CLI::App* cmd = app.add_subcommand(
      "export",
      "A hierarchy file's approximation on its voxel grid (.nii.gz .nrrd .raw .vdb) or its leaf mesh "
      "with values and levels (.vtu .msh), in the file's physical frame");
  cmd->add_option("input", state->input, "hierarchy file (.mlfeh)")->required();
  cmd->add_option("-o,--output", state->output,
                  "output (.nii.gz, .nii, .nrrd, .raw + .raw.json, .vdb, .vtu, .msh)")
      ->required();
  cmd->add_option("--level", state->level, "use levels 0..K only (default: all)")
      ->check(CLI::NonNegativeNumber);
  cmd->callback([state] { run_export(*state); });
}

}  // namespace

MLFE_REGISTER_COMMAND(35, add_export_command);

}  // namespace mlfe::cli
