// mlfe::pipeline::export_hierarchy (`mlfe export`): a hierarchy file's approximation as a voxel
// grid (NIfTI, NRRD, raw + JSON, OpenVDB) on the grid it was built from, or its leaf mesh (VTK
// .vtu, Gmsh .msh) with the values and element levels, in the file's physical frame.
#include <mlfe/core/base/error.h>
#include <mlfe/core/base/usage_error.h>
#include <mlfe/core/fem/hierarchy_resample.h>
#include <mlfe/core/fem/sample_lattice.h>
#include <mlfe/formats/file_names.h>
#include <mlfe/formats/hierarchy_io.h>
#include <mlfe/formats/msh_writer.h>
#include <mlfe/formats/volume_writer.h>
#include <mlfe/formats/vtu_writer.h>
#include <mlfe/pipeline.h>

#include <chrono>
#include <cmath>
#include <string>

#include "converters/label_hierarchy.h"
#include "converters/progress_reporter.h"

namespace mlfe::pipeline {
namespace {

bool is_mesh_output(const std::string& ext) { return ext == ".vtu" || ext == ".msh"; }

// The leaf mesh. On the samples' lattice the mesh is the data's box: the padding's leaves are
// left out and those across the box's faces refined until none is (u carried along its edges).
template <int D>
void export_mesh(const std::string& input, const std::string& output, const HierarchyFile& f,
                 const Hierarchy<D>& h_in, ExportResult& r) {
  const std::vector<double>* values = f.values.empty() ? nullptr : &f.values;
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
  const bool labelled = D == 3 && detail::is_label_hierarchy(f) && values;
  if (labelled) {
    const LabelTable table = detail::read_stored_label_map(f, input).table;
    regions.label = detail::leaf_labels(h, leaves, *values);
    for (std::uint16_t l : regions.label)
      if (!regions.names.count(l))
        regions.names[l] = l == 0 && !table.entries.count(0) ? "background" : table.name(l);
  }
  if (lower_extension(output) == ".vtu")
    write_vtu(output, h, leaves, values, &f.transform, labelled ? &regions : nullptr);
  else
    write_msh(output, h, leaves, values, &f.transform, labelled ? &regions : nullptr);
  r.mesh = true;
  r.elements = leaves.size();
  r.vertices = h.vertex_count();
  r.level = h.max_level();
}

// The approximation resampled on the voxel grid: the data's on the samples' lattice (v3, where
// T0 is a padded cube), else T0's box at the file's spacing.
template <int D>
void export_grid(const std::string& input, const std::string& output, const HierarchyFile& f,
                 const Hierarchy<D>& h, ExportResult& r, const detail::Reporter& report) {
  if (f.values.empty()) throw Error(input + ": the file stores no values, so there is no grid to export");
  ScalarGrid g;
  g.dim = D;
  g.transform = f.transform;
  g.space = f.space;
  try {
    g.dims = f.on_lattice ? f.data_dims : hierarchy_grid_dims(h, f.transform.spacing);
  } catch (const Error& e) {
    throw Error(input + ": " + e.what());
  }
  report(0.3, "resampling");
  const auto t0 = std::chrono::steady_clock::now();
  g.values = resample_to_grid(h, f.values, g.dims, f.transform.spacing);
  // An error-bounded build of integer data (integer surpluses) at a bound rounding keeps (an
  // integer, or below 1/2): the samples are integers (pipeline_build.cpp, on_grid).
  const double e = f.sample_error_bound;
  if (f.integer_values && std::isfinite(e) && (e < 0.5 || e == std::floor(e)))
    for (float& v : g.values) v = std::nearbyint(v);
  r.resample_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  report(0.7, "writing");
  write_volume(output, g);
  r.dims = g.dims;
  r.level = h.max_level();
}

template <int D>
void export_file(const std::string& input, const std::string& output, const HierarchyFile& f, ExportResult& r,
                 const detail::Reporter& report) {
  const Hierarchy<D>& h = std::get<Hierarchy<D>>(f.hierarchy);
  if (is_mesh_output(lower_extension(output))) {
    report(0.3, "writing");
    export_mesh(input, output, f, h, r);
  } else {
    export_grid(input, output, f, h, r, report);
  }
}

}  // namespace

ExportResult export_hierarchy(const std::string& input, const std::string& output,
                              const ExportOptions& options) {
  const std::string ext = lower_extension(output);
  // A .raw volume is written with its sidecar.
  check_distinct_files({{"input", input}},
                       {{"output", output}, {"output", ext == ".raw" ? output + ".json" : ""}});
  if (!is_mesh_output(ext) && !is_volume_output(output))
    throw Error(output + ": unknown output type '" + ext + "' (use .nii.gz .nii .nrrd .raw .vdb .vtu .msh)");
  check_output_path(output, {});
  check_option("level", options.level);
  const detail::Reporter report(options.progress);
  report(0, "reading");
  const HierarchyFile f = read_hierarchy(input, options.level);
  if (options.level > f.file_levels)
    throw OptionError(input + ": " + option_ref("level") + " " + std::to_string(options.level) +
                      " but the file has " + std::to_string(f.file_levels) + " levels");
  ExportResult r;
  if (f.dim == 2)
    export_file<2>(input, output, f, r, report);
  else
    export_file<3>(input, output, f, r, report);
  r.written.push_back(output);
  report.finish("writing");
  return r;
}

}  // namespace mlfe::pipeline
