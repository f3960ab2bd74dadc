// mlfe::pipeline::convert, iso and compare (`mlfe convert`, `mlfe iso`, `mlfe compare`): files
// in, assets (and hierarchy, report, image) out, through mlfe::convert, write_assets and
// convert_labels.
#include <mlfe/core/base/error.h>
#include <mlfe/core/base/usage_error.h>
#include <mlfe/pipeline.h>
#include <mlfe/pipeline/preview.h>
#include <mlfe/version.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <optional>

#include "converters/label_hierarchy.h"
#include "converters/progress_reporter.h"

namespace mlfe::pipeline {
namespace {

VolumeReadOptions budgeted(VolumeReadOptions read, const BuildOptions& build) {
  // The readers refuse, before allocating, a volume over the budget the build keeps to.
  if (read.max_bytes == 0) read.max_bytes = build.max_memory.bytes();
  return read;
}

// --png needs the image it converts; --preview a glTF asset to show.
void check_image_and_preview(const std::string& output, const ConvertFileOptions& o) {
  if (!o.png.empty()) {
    if (o.render.empty())
      throw OptionError(option_ref("png") + ": the PNG is of the " + option_ref("render") + " image; give " +
                        option_ref("render") + " too");
    check_output_path(o.png, {".png"});
  }
  if (!o.preview.empty()) check_preview_paths(o.preview, output);
}

// convert --preview: the page of the asset just written, with the report's figures and the
// image (a PNG, or none), listed last.
void add_preview(const std::string& input, const std::string& output, const ConvertFileOptions& o,
                 const nlohmann::json& report, const std::string& image, ConvertFileResult& r,
                 detail::OutputGuard& written) {
  if (o.preview.empty()) return;
  write_preview(o.preview, {output, report, image, std::filesystem::path(input).filename().string()});
  r.written.push_back(o.preview);
  written.add(o.preview);
}

void check_convert_outputs(const std::string& output, const ConvertFileOptions& o) {
  check_output_path(output, kAssetExtensions);
  if (!o.hierarchy.empty()) check_output_path(o.hierarchy, {".mlfeh"});
  if (!o.report.empty()) check_output_path(o.report, {});
  if (!o.render.empty()) check_output_path(o.render, {".exr"});
  check_image_and_preview(output, o);
}

// Every file convert reads and writes, checked before any work.
void check_convert_files(const std::string& input, const std::string& output, const ConvertFileOptions& o) {
  NamedFiles inputs = {{"input", input}};
  if (o.labels)
    inputs.emplace_back(option_ref("label_table"), detail::label_table_file(o.labels->table, input));
  check_distinct_files(inputs, {{"output", output},
                                {"hierarchy", o.hierarchy},
                                {"report", o.report},
                                {"render", o.render},
                                {"png", o.png},
                                {"preview", o.preview}});
}

// convert with labels: a label map in, one surface per structure out.
ConvertFileResult convert_label_map(const std::string& input, const std::string& output,
                                    const ConvertFileOptions& o) {
  const std::string labels = option_ref("labels");
  if (!o.asset.iso.empty())
    throw OptionError(labels + ": " + labels + " and " + option_ref("iso") + " exclude each other");
  if (!o.render.empty())
    throw OptionError(labels + ": " + labels + " writes no image (no " + option_ref("render") + ")");
  // The label path converts the whole map at once: an explicit brick size would be ignored.
  if (o.asset.bricks > 0)
    throw OptionError(option_ref("bricks") + ": " + labels + " converts the whole label map at once (no " +
                      option_ref("bricks") + ")");
  check_options(*o.labels);
  check_output_path(output, kAssetExtensions);
  if (!o.hierarchy.empty()) {
    if (is_hierarchy_file(input))
      throw OptionError(option_ref("hierarchy") + ": " + input + " is a hierarchy already (no " +
                        option_ref("hierarchy") + ")");
    check_output_path(o.hierarchy, {".mlfeh"});
  }
  if (!o.report.empty()) check_output_path(o.report, {});
  check_image_and_preview(output, o);
  const detail::Reporter report(o.progress);
  report(0, "reading");
  ConvertFileResult r;
  LabelOptions lo = *o.labels;
  lo.max_memory = o.build.max_memory;
  if (!lo.warn) lo.warn = [&r](const std::string& w) { r.warnings.push_back(w); };
  ScalarGrid grid;
  if (is_hierarchy_file(input)) {
    // A label hierarchy (mlfe build --labels): the same labels at the samples, its stored table.
    const HierarchyFile f = read_hierarchy(input);
    grid = detail::read_stored_label_map(f, input).grid;
    if (!f.metadata["labels"].value("labels", nlohmann::json::array()).empty()) {
      lo.table_json = f.metadata["labels"].dump();
      lo.table_json_source = input + " (stored)";
    }
  } else {
    grid = read_volume(input, budgeted(o.read, o.build));
  }
  report(0.1, "extracting");
  detail::OutputGuard written;
  r.asset = convert_labels(grid, output, lo);
  r.written.push_back(output);
  written.add(output);
  // hierarchy: the labels stored exactly with their table, as mlfe build --labels writes them.
  if (!o.hierarchy.empty()) {
    report(0.8, "writing the hierarchy");
    BuildFileOptions b;
    b.labels = true;
    b.label_table = lo.table;
    b.read = o.read;
    b.build.max_memory = o.build.max_memory;
    const BuildFileResult h = build(input, o.hierarchy, b);
    r.warnings.insert(r.warnings.end(), h.warnings.begin(), h.warnings.end());
    r.written.push_back(o.hierarchy);
    written.add(o.hierarchy);
  }
  nlohmann::json rep = {{"input", input}, {"dims", grid.dims}, {"asset", r.asset}};
  rep["peak_rss_mb"] = peak_rss_mb();
  if (!o.report.empty()) {
    write_json(o.report, rep);
    r.written.push_back(o.report);
  }
  add_preview(input, output, o, rep, "", r, written);
  written.release();
  report.finish("writing");
  return r;
}

// convert with the volume read window by window (reads_in_bricks): no hierarchy, the asset and
// the report.
ConvertFileResult convert_in_bricks(const VolumeWindows& v, const std::string& input,
                                    const std::string& output, const ConvertFileOptions& o,
                                    const detail::Reporter& report) {
  ConvertFileResult r;
  nlohmann::json prov = bricks_provenance(input, o.asset);
  if (o.provenance.is_object()) prov.merge_patch(o.provenance);
  AssetOptions asset = o.asset;
  if (report) asset.progress = report.share(0.02, 1).as_progress();
  detail::OutputGuard written;
  r.asset = write_assets(output, v, asset, prov);
  r.written.push_back(output);
  written.add(output);
  const ScalarGrid& f = v.frame();
  nlohmann::json rep = {{"input", input},
                        {"dims", f.dims},
                        {"spacing", f.transform.spacing},
                        {"format", f.format},
                        {"read_in_windows", v.streamed()},
                        {"asset", r.asset}};
  rep["peak_rss_mb"] = peak_rss_mb();
  if (!o.report.empty()) {
    write_json(o.report, rep);
    r.written.push_back(o.report);
    written.add(o.report);
  }
  add_preview(input, output, o, rep, "", r, written);
  written.release();
  return r;
}

// The written files of a conversion, in the order the command line lists them.
void list_written(const std::string& output, const ConvertOptions& c, ConvertFileResult& r) {
  r.written.push_back(output);
  if (!c.hierarchy.empty()) r.written.push_back(c.hierarchy);
  if (!c.report.empty()) r.written.push_back(c.report);
}

// The volume given for snapping must be the one the hierarchy was built from: same frame and
// the same box ([0, (n - 1) * spacing] per axis: the hierarchy's coarse mesh, or its data box
// on the samples' lattice).
void check_volume_matches(const std::string& volume, const ScalarGrid& g, const std::string& hierarchy,
                          const Built& b) {
  if (b.dim() != 3 || g.dim != 3)
    throw OptionInputError(volume + ": " + option_ref("volume") + " needs a 3D volume and a 3D hierarchy (" +
                           hierarchy + ")");
  auto near = [](double x, double y) {
    return std::abs(x - y) <= 1e-6 * std::max({1.0, std::abs(x), std::abs(y)});
  };
  const auto& t = g.transform;
  const auto& h = b.get<3>().hierarchy;
  std::array<double, 3> hi{0, 0, 0};  // the coarse mesh's vertices include the box's corners
  for (std::size_t e = 0; e < h.coarse_count(); ++e)
    for (VertexId v : h.cell(ElemId(std::uint32_t(e))))
      for (int a = 0; a < 3; ++a) hi[a] = std::max(hi[a], h.point(v)[a]);
  // On the samples' lattice T0 is a padded cube: the data's box is the one to match.
  if (b.get<3>().on_lattice) hi = b.get<3>().data_extent;
  for (int a = 0; a < 3; ++a) {
    if (!near(t.spacing[a], b.transform.spacing[a]) || !near(t.origin[a], b.transform.origin[a]))
      throw Error(volume + ": spacing or origin differ from the hierarchy's (" + hierarchy + ")");
    if (!near(double(g.dims[a] - 1) * t.spacing[a], hi[a]))
      throw Error(volume + ": its extent differs from the hierarchy's domain (" + hierarchy + ")");
  }
  for (int k = 0; k < 9; ++k)
    if (!near(t.direction[k], b.transform.direction[k]))
      throw Error(volume + ": its direction matrix differs from the hierarchy's (" + hierarchy + ")");
}

}  // namespace

std::optional<VolumeWindows> open_in_bricks(const std::string& input, ConvertFileOptions& o) {
  const bool whole_volume_outputs = !o.render.empty() || !o.hierarchy.empty();
  std::optional<VolumeWindows> v;
  if (!detect_tet_mesh_format(input).empty()) {
    o.asset.bricks = std::max<std::int64_t>(o.asset.bricks, 0);
    return v;
  }
  if (o.asset.bricks < 0) {
    o.asset.bricks = 0;
    AssetOptions probe = o.asset;
    probe.bricks = 2;  // any edge: would the other options read in bricks?
    if (reads_in_windows(input, o.read) && reads_in_bricks(o.build, probe, whole_volume_outputs)) {
      v.emplace(input, budgeted(o.read, o.build));
      o.asset.bricks = auto_bricks(v->frame().dims);
    }
  }
  if (!reads_in_bricks(o.build, o.asset, whole_volume_outputs)) return std::nullopt;
  if (!v) v.emplace(input, budgeted(o.read, o.build));
  return v;
}

ConvertFileResult convert(const std::string& input, const std::string& output, const ConvertFileOptions& o) {
  check_convert_files(input, output, o);
  check_options(o.build);
  check_options(o.asset);
  check_options(o.read);
  if (o.labels) return convert_label_map(input, output, o);
  check_convert_outputs(output, o);
  const detail::Reporter report(o.progress);
  report(0, "reading");
  ConvertFileOptions resolved = o;
  if (std::optional<VolumeWindows> v = open_in_bricks(input, resolved); v && v->frame().dim == 3) {
    ConvertFileResult r = convert_in_bricks(*v, input, output, resolved, report);
    report.finish("writing");
    return r;
  }
  ConvertOptions c;
  c.build = o.build;
  c.asset = resolved.asset;
  c.hierarchy = o.hierarchy;
  c.report = o.report;
  c.provenance = o.provenance;
  c.keep_u = !o.render.empty();  // the image is of u
  const double convert_end = o.render.empty() ? 1.0 : 0.85;
  if (report) c.progress = report.share(0.05, convert_end).as_progress();
  // A tetrahedral mesh input: its P1 interpolant is the input function (no voxel grid).
  std::optional<ScalarGrid> grid;
  ConvertResult cr;
  if (!detect_tet_mesh_format(input).empty()) {
    cr = mlfe::convert(read_tet_mesh(input, tet_mesh_read_options(o.read)), output, c);
  } else {
    grid = read_volume(input, budgeted(o.read, o.build));
    cr = mlfe::convert(*grid, output, c);
  }
  ConvertFileResult r;
  detail::OutputGuard written;
  for (const std::string& f : {output, c.hierarchy, c.report})
    if (!f.empty()) written.add(f);
  r.built = std::move(cr.built);
  r.asset = std::move(cr.asset);
  r.warnings = std::move(cr.warnings);
  list_written(output, c, r);
  // convert --render: the image of the hierarchy just built, with render's defaults.
  if (!o.render.empty()) {
    RenderFileOptions ro;
    ro.png = o.png;
    if (report) ro.progress = report.share(convert_end, 1).as_progress();
    r.render = render(r.built, o.render, ro, grid ? &*grid : nullptr, input);
    for (const auto& f : r.render.written) {
      r.written.push_back(f);
      written.add(f);
    }
  }
  add_preview(input, output, o, cr.report, o.png, r, written);
  written.release();
  report.finish("writing");
  return r;
}

ConvertFileResult iso(const std::string& input, const std::string& output, const IsoOptions& o) {
  if (!is_hierarchy_file(input)) {
    if (!o.volume.empty())
      throw OptionInputError(option_ref("volume") + " is for a hierarchy input; " + input +
                             " is a volume itself");
    ConvertFileOptions c;
    c.build = o.build;
    c.asset = o.asset;
    c.read = o.read;
    c.report = o.report;
    c.progress = o.progress;
    return convert(input, output, c);
  }
  check_distinct_files({{"input", input}, {option_ref("volume"), o.volume}},
                       {{"output", output}, {"report", o.report}});
  const nlohmann::json prov = {{"input", std::filesystem::path(input).filename().string()},
                               {"tool", std::string("mlfe ") + MLFE_VERSION}};
  check_output_path(output, kAssetExtensions);
  if (!o.report.empty()) check_output_path(o.report, {});
  check_options(o.asset);
  check_options(o.build);
  check_options(o.read);
  const detail::Reporter report(o.progress);
  report(0, "reading");
  std::optional<ScalarGrid> grid;
  ConvertFileResult r;
  r.built = built_from_file(input);
  if (!o.volume.empty()) {
    grid = read_volume(o.volume, budgeted(o.read, o.build));
    check_volume_matches(o.volume, *grid, input, r.built);
  }
  AssetOptions asset = o.asset;
  if (report) asset.progress = report.share(0.1, 1).as_progress();
  detail::OutputGuard written;
  r.asset = write_assets(output, r.built, asset, prov, grid ? &*grid : nullptr);
  r.written.push_back(output);
  written.add(output);
  if (!o.report.empty()) {
    nlohmann::json rep = build_report(input, grid ? &*grid : nullptr, r.built);
    rep["asset"] = r.asset;
    rep["peak_rss_mb"] = peak_rss_mb();
    write_json(o.report, rep);
    r.written.push_back(o.report);
  }
  written.release();
  report.finish("writing");
  return r;
}

CompareResult compare(const std::string& expected, const std::string& actual, const CompareOptions& options,
                      const std::string& report) {
  check_distinct_files({{"expected", expected}, {"actual", actual}}, {{"report", report}});
  CompareResult r = compare_files(expected, actual, options);
  if (!report.empty()) write_compare_report(report, expected, actual, r);
  return r;
}

}  // namespace mlfe::pipeline
