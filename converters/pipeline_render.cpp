// mlfe::pipeline::render (`mlfe render`, `mlfe convert --render`): ray-cast images of a
// hierarchy or a volume, face to face through the adaptive tetrahedral mesh, written as OpenEXR
// (half RGBA premultiplied, float Z, the camera and transfer function in the header) with an
// optional sRGB PNG preview. The steps: the transfer function, the framing of the volume, one
// camera per frame, the render mesh, then per frame the image and its files.
#include <fmt/format.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/base/usage_error.h>
#include <mlfe/core/base/vec.h>
#include <mlfe/core/render/volume_render.h>
#include <mlfe/formats/exr_writer.h>
#include <mlfe/formats/file_names.h>
#include <mlfe/formats/transfer_function_io.h>
#include <mlfe/pipeline.h>
#include <mlfe/version.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <memory>

#include "converters/progress_reporter.h"

namespace mlfe::pipeline {
namespace {

std::string numbered(const std::string& path, int frame, int frames) {
  if (frames <= 1) return path;
  const std::filesystem::path p(path);
  return (p.parent_path() / fmt::format("{}_{:04d}{}", p.stem().string(), frame, p.extension().string()))
      .string();
}

// The length an unstructured mesh's preset opacities refer to: the 10th percentile of its
// edge lengths (TetMeshField::resolution(), the "voxel" of mlfe build on a mesh).
double fine_edge_length(const Hierarchy<3>& h) {
  std::vector<double> len;
  len.reserve(6 * h.coarse_count());
  for (std::size_t e = 0; e < h.coarse_count(); ++e) {
    const auto& c = h.cell(ElemId(std::uint32_t(e)));
    for (const auto& ev : SimplexTraits<3>::kEdgeVerts)
      len.push_back(distance(h.point(c[ev[0]]), h.point(c[ev[1]])));
  }
  const auto at = len.begin() + std::ptrdiff_t(len.size() / 10);
  std::nth_element(len.begin(), at, len.end());
  return *at;
}

// Presets span the data's range with opacities per voxel (per fine edge of an unstructured
// mesh) unless told; a ParaView file keeps its own values, per unit length unless told.
TransferFunction choose_transfer_function(const RenderFileOptions& p, const Built& b, RayEntry entry) {
  if (lower_extension(p.tf) == ".json")
    return read_paraview_transfer_function(p.tf, p.tf_unit > 0 ? p.tf_unit : 1.0);
  const GridTransform& tr = b.transform;
  const double voxel = p.tf_unit > 0 ? p.tf_unit
                       : entry == RayEntry::kBoundaryFaces
                           ? fine_edge_length(b.get<3>().hierarchy)
                           : std::min({tr.spacing[0], tr.spacing[1], tr.spacing[2]});
  const double lo = b.value_min, hi = b.value_max > b.value_min ? b.value_max : b.value_min + 1;
  return transfer_function_preset(p.tf, lo, hi, voxel);
}

// The volume's bounding ball in the physical frame: the data's box (T0's cube is padded on the
// samples' lattice), else the hierarchy's vertices' box.
struct Framing {
  Vec3 center{0, 0, 0};
  double radius = 0;
};

Framing frame_volume(const Built& b) {
  const GridTransform& tr = b.transform;
  const Approximation<3>& a = b.get<3>();
  Vec3 lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
  for (const auto& q : a.hierarchy.points())
    for (int k = 0; k < 3; ++k) {
      lo[k] = std::min(lo[k], q[k]);
      hi[k] = std::max(hi[k], q[k]);
    }
  if (a.on_lattice) {
    lo = {0, 0, 0};
    hi = a.data_extent;
  }
  Framing f;
  f.center = tr.local_to_physical({0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), 0.5 * (lo[2] + hi[2])});
  for (int c = 0; c < 8; ++c)
    f.radius = std::max(
        f.radius,
        distance(tr.local_to_physical({c & 1 ? hi[0] : lo[0], c & 2 ? hi[1] : lo[1], c & 4 ? hi[2] : lo[2]}),
                 f.center));
  return f;
}

// The orbit camera of `frame` (the turntable turns about +z), or the one at options.position.
Camera frame_camera(const RenderFileOptions& p, const Framing& framing, int frame) {
  const double az = p.azimuth + 360.0 * frame / p.frames;
  Camera cam = orbit_camera(framing.center, framing.radius, az, p.elevation,
                            p.camera == Projection::kPerspective, p.size[0], p.size[1]);
  if (!p.position) return cam;
  cam.position = *p.position;
  if (p.target) cam.target = *p.target;
  if (p.up) cam.up = *p.up;
  const double dist = distance(cam.position, cam.target);
  if (!(dist > 0))
    throw OptionError(option_ref("position") + " and " + option_ref("target") + " must differ");
  const Vec3 side = cross(sub(cam.target, cam.position), cam.up);
  if (!(norm(side) > 1e-9 * dist * norm(cam.up)))
    throw OptionError(option_ref("up") + " must not be parallel to the viewing direction (or zero)");
  cam.near_clip = std::max(dist - framing.radius, 1e-3 * framing.radius);
  cam.far_clip = dist + 2 * framing.radius;
  return cam;
}

void check_render_options(const RenderFileOptions& p, const Built& b, const ScalarGrid* grid,
                          const std::string& source, RayEntry entry) {
  if (b.dim() != 3) throw Error(source + ": rendering needs a 3D volume or hierarchy");
  if (p.reference && !grid)
    throw OptionInputError(source + ": " + option_ref("reference") +
                           (entry == RayEntry::kBoundaryFaces
                                ? " needs a volume as input (a mesh is rendered as it is)"
                                : " needs the volume itself as input, not a hierarchy"));
  check_options(p);
  const int max_level = b.get<3>().hierarchy.max_level();
  if (p.level < -1 || p.level > max_level)
    throw OptionError(fmt::format("{}: expected -1 (finest) .. {} (the hierarchy's levels), got {}",
                                  option_ref("level"), max_level, p.level));
}

// Refuses images the memory budget cannot hold, before any work: each frame's RGBA and Z floats
// (every frame's when they are kept), and while a frame is written the EXR's half channels and
// the PNG's pixels and encoding. A 16384x16384 image takes 9 GB written.
void check_image_budget(const RenderFileOptions& p, bool written) {
  const std::size_t budget = p.build.max_memory.bytes();
  if (budget == 0) return;
  const double pixels = double(p.size[0]) * double(p.size[1]);
  const double per_pixel =
      20.0 * (p.keep_images ? p.frames : 1) + (written ? 8.0 : 0.0) + (written && !p.png.empty() ? 6.0 : 0.0);
  if (pixels * per_pixel > double(budget))
    throw OptionInputError(
        fmt::format("{}: {}x{} images take about {:.0f} MB ({} bytes a pixel), more than {} {}",
                    option_ref("size"), p.size[0], p.size[1], pixels * per_pixel / 1048576.0, per_pixel,
                    option_ref("max_memory"), p.build.max_memory.text()));
}

RenderOptions ray_options(const RenderFileOptions& p) {
  RenderOptions opt;
  opt.rule = p.integration;
  opt.stop_opacity = p.stop_opacity;
  opt.z_opacity = p.z_opacity;
  opt.shading = p.shading;
  opt.skip_empty = p.skip_empty;
  return opt;
}

// The header of every frame: the camera, the source, the renderer, the transfer function and
// what Z and alpha mean.
ExrAttributes exr_attributes(const RenderFileOptions& p, const Camera& cam, const TransferFunction& tf,
                             const RenderResult& r, int max_level, const std::string& source,
                             RayEntry entry) {
  const std::string renderer =
      p.reference ? std::string("reference: trilinear voxels, 2 samples per voxel")
      : entry == RayEntry::kBoundaryFaces
          ? fmt::format("unstructured tetrahedral mesh as given, {} integration", enum_name(p.integration))
          : fmt::format("tetrahedral mesh, level {} of {}, {} integration", r.level, max_level,
                        enum_name(p.integration));
  ExrAttributes attr;
  attr.world_to_camera = cam.world_to_camera();
  attr.world_to_ndc = cam.world_to_ndc();
  attr.strings = {
      {"mlfe/source", std::filesystem::path(source).filename().string()},
      {"mlfe/renderer", renderer},
      {"mlfe/transferFunction", transfer_function_record(tf)},
      {"mlfe/zConvention",
       fmt::format(
           "Z = distance along the ray from its origin (camera position; orthographic: the image plane "
           "through it), physical units, to where the accumulated opacity first reaches {}; +inf where "
           "it never does",
           p.z_opacity)},
      {"mlfe/alpha", "linear RGB, premultiplied alpha, no background"},
      {"mlfe/tool", std::string("mlfe ") + MLFE_VERSION},
  };
  return attr;
}

// The render mesh of b: its level p.level, or an unstructured mesh as it is (its errors named
// after the source).
std::unique_ptr<TetRenderMesh> render_mesh_of(const Approximation<3>& a, const RenderFileOptions& p,
                                              RayEntry entry, const std::string& source) {
  if (entry == RayEntry::kHierarchy)
    return std::make_unique<TetRenderMesh>(a.hierarchy, a.values, p.level,
                                           a.on_lattice ? &a.data_extent : nullptr);
  try {
    return std::make_unique<TetRenderMesh>(a.hierarchy, a.values, -1, nullptr, entry);
  } catch (const Cancelled&) {
    throw;
  } catch (const Error& e) {
    std::string what = e.what();
    if (what.rfind("render: ", 0) == 0) what = what.substr(8);
    throw Error(source + ": " + what);
  }
}

// Every frame, rendered and (with `output`) written; the render mesh is built once.
RenderResult render_frames(const Built& b, const std::string& output, const RenderFileOptions& p,
                           const ScalarGrid* grid, const std::string& source,
                           RayEntry entry = RayEntry::kHierarchy) {
  check_render_options(p, b, grid, source, entry);
  check_image_budget(p, !output.empty());
  const TransferFunction tf = choose_transfer_function(p, b, entry);
  const detail::Reporter report(p.progress);
  report(0, "rendering");
  const Framing framing = frame_volume(b);
  const Approximation<3>& a3 = b.get<3>();
  const RenderOptions opt = ray_options(p);
  RenderResult r;
  detail::OutputGuard written;
  std::unique_ptr<TetRenderMesh> mesh;
  if (!p.reference) {
    mesh = render_mesh_of(a3, p, entry, source);
    r.tetrahedra = mesh->size();
    r.level = mesh->level();
  }
  for (int frame = 0; frame < p.frames; ++frame) {
    report(double(frame) / p.frames, "rendering");
    RenderFrame f;
    f.camera = frame_camera(p, framing, frame);
    RenderOptions frame_opt = opt;
    frame_opt.images = p.frames - frame;  // step records pay off over the frames still to come
    const auto t0 = std::chrono::steady_clock::now();
    f.image = p.reference ? render_grid(*grid, tf, f.camera, frame_opt, &f.stats)
                          : render_mesh(*mesh, b.transform, tf, f.camera, frame_opt, &f.stats);
    f.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    f.width = p.size[0];
    f.height = p.size[1];
    if (!output.empty()) {
      report((frame + 0.9) / p.frames, "writing");
      f.exr = numbered(output, frame, p.frames);
      write_exr(f.exr, f.image, exr_attributes(p, f.camera, tf, r, a3.hierarchy.max_level(), source, entry));
      r.written.push_back(f.exr);
      written.add(f.exr);
      if (!p.png.empty()) {
        f.png = numbered(p.png, frame, p.frames);
        write_png_preview(f.png, f.image, p.background);
        r.written.push_back(f.png);
        written.add(f.png);
      }
      if (!p.keep_images) f.image = RenderImage{};
    }
    r.frames.push_back(std::move(f));
  }
  // After the frames: step records count as far as they were built.
  if (mesh) r.mesh_bytes = mesh->memory_bytes();
  written.release();
  report.finish(output.empty() ? "rendering" : "writing");
  return r;
}

// What `render` renders of a volume input: the build with mlfe build's defaults, or for the
// reference only the frame and value range (the box for the camera comes from T0).
Built built_for_render(const ScalarGrid& grid, const RenderFileOptions& o, const detail::Reporter& report) {
  if (!o.reference) {
    BuildOptions bo = o.build;
    if (report) bo.fraction_progress = report.as_progress();
    return mlfe::build(grid, bo, {});
  }
  Built b;
  b.transform = grid.transform;
  const auto r = grid.value_range();
  b.value_min = r[0];
  b.value_max = r[1];
  Approximation<3> a;
  a.hierarchy = Hierarchy<3>::box({0, 0, 0}, grid.local_extent());
  a.values.assign(a.hierarchy.vertex_count(), 0.0);
  b.approximation = std::move(a);
  return b;
}

// An unstructured mesh as a one-level hierarchy (T0 = the mesh, finest level) with its values
// at the points, in the physical frame (identity transform); tetrahedra of zero volume are left
// out, as mlfe build does.
Built built_of_mesh(const TetMesh& mesh) {
  const std::string source = mesh.source.empty() ? std::string("tetrahedral mesh") : mesh.source;
  const std::size_t np = mesh.points.size();
  if (mesh.values.size() != np)
    throw Error(fmt::format("{}: {} values for {} points", source, mesh.values.size(), np));
  for (std::size_t i = 0; i < np; ++i)
    for (double x : {mesh.points[i][0], mesh.points[i][1], mesh.points[i][2], mesh.values[i]})
      if (!std::isfinite(x))
        throw Error(fmt::format("{}: point {} has a non-finite coordinate or value", source, i));
  std::vector<Hierarchy<3>::Cell> cells;
  cells.reserve(mesh.tets.size());
  for (std::size_t t = 0; t < mesh.tets.size(); ++t) {
    Hierarchy<3>::Cell c;
    for (int k = 0; k < 4; ++k) {
      const std::int32_t v = mesh.tets[t][k];
      if (v < 0 || std::size_t(v) >= np)
        throw Error(fmt::format("{}: tetrahedron {} refers to point {} of {}", source, t, v, np));
      c[k] = VertexId(std::uint32_t(v));
    }
    const auto& p0 = mesh.points[c[0].value];
    Vec3 e[3];
    for (int k = 0; k < 3; ++k) e[k] = sub(mesh.points[c[k + 1].value], p0);
    const double volume = e[0][0] * (e[1][1] * e[2][2] - e[1][2] * e[2][1]) -
                          e[0][1] * (e[1][0] * e[2][2] - e[1][2] * e[2][0]) +
                          e[0][2] * (e[1][0] * e[2][1] - e[1][1] * e[2][0]);
    if (volume != 0) cells.push_back(c);
  }
  if (cells.empty()) throw Error(source + ": no tetrahedron of positive volume to render");
  if (cells.size() >= (std::size_t(1) << 30))
    throw Error(fmt::format("{}: {} tetrahedra exceed the renderer's limit of 2^30", source, cells.size()));
  Built b;
  const auto range = std::minmax_element(mesh.values.begin(), mesh.values.end());
  b.value_min = *range.first;
  b.value_max = *range.second;
  Approximation<3> a;
  a.hierarchy = Hierarchy<3>::from_coarse(mesh.points, std::move(cells));
  a.values = mesh.values;
  b.approximation = std::move(a);
  return b;
}

}  // namespace

RenderResult render_images(const TetMesh& mesh, const RenderFileOptions& options) {
  RenderFileOptions o = options;
  o.keep_images = true;
  const Built b = built_of_mesh(mesh);
  RenderResult r = render_frames(b, "", o, nullptr, mesh.source, RayEntry::kBoundaryFaces);
  r.built = b;
  return r;
}

RenderResult render(const TetMesh& mesh, const std::string& output, const RenderFileOptions& options) {
  check_output_path(output, {".exr"});
  if (!options.png.empty()) check_output_path(options.png, {".png"});
  Built b = built_of_mesh(mesh);
  RenderResult r = render_frames(b, output, options, nullptr, mesh.source, RayEntry::kBoundaryFaces);
  r.built = std::move(b);
  return r;
}

RenderResult render_images(const Built& b, const RenderFileOptions& options, const ScalarGrid* grid,
                           const std::string& source) {
  RenderFileOptions o = options;
  o.keep_images = true;
  return render_frames(b, "", o, grid, source);
}

RenderResult render(const Built& b, const std::string& output, const RenderFileOptions& options,
                    const ScalarGrid* grid, const std::string& source) {
  check_output_path(output, {".exr"});
  if (!options.png.empty()) check_output_path(options.png, {".png"});
  return render_frames(b, output, options, grid, source);
}

RenderResult render(const std::string& input, const std::string& output, const RenderFileOptions& options) {
  check_distinct_files({{"input", input}, {option_ref("tf"), options.tf}},
                       {{"output", output}, {"png", options.png}});
  check_output_path(output, {".exr"});
  if (!options.png.empty()) check_output_path(options.png, {".png"});
  check_options(options);
  check_image_budget(options, true);
  const detail::Reporter report(options.progress);
  report(0, "reading");
  RenderFileOptions o = options;
  if (report) o.progress = report.share(0.6, 1).as_progress();
  if (is_hierarchy_file(input)) {
    // level K reads the file's prefix up to level K only (docs/mlfeh-v3.md).
    Built b = built_from_file(input, o.level);
    RenderResult r = render(b, output, o, nullptr, input);
    r.built = std::move(b);
    return r;
  }
  VolumeReadOptions read = options.read;
  if (read.max_bytes == 0) read.max_bytes = options.build.max_memory.bytes();
  if (!detect_tet_mesh_format(input).empty()) {
    // An unstructured mesh is rendered as it is: no build.
    const TetMesh mesh = read_tet_mesh(input, tet_mesh_read_options(read));
    return render(mesh, output, o);
  }
  const ScalarGrid grid = read_volume(input, read);
  if (grid.dim != 3) throw Error(input + ": rendering needs a 3D volume");
  for (int a = 0; a < 3; ++a)
    if (grid.dims[a] < 2) throw Error(input + ": rendering needs at least 2 samples along every axis");
  Built b = built_for_render(grid, options, report.share(0, 0.6));
  RenderResult r = render(b, output, o, &grid, input);
  r.built = std::move(b);
  return r;
}

}  // namespace mlfe::pipeline
