// mlfe render: ray-cast EXR images of a hierarchy (.mlfeh) or a volume (built first with the
// same defaults as mlfe build), face to face through the adaptive tetrahedral mesh.
#include <fmt/format.h>
#include <mlfe/core/error.h>
#include <mlfe/core/usage_error.h>
#include <mlfe/core/volume_render.h>
#include <mlfe/formats/exr_writer.h>
#include <mlfe/formats/file_names.h>
#include <mlfe/formats/transfer_function_io.h>
#include <mlfe/version.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <memory>

#include "converters/commands.h"
#include "converters/render_command.h"
#include "converters/volume_options.h"

namespace mlfe::cli {

void add_render_options(CLI::App* cmd, RenderParams& p) {
  std::string presets;
  for (const auto& n : transfer_function_presets()) presets += (presets.empty() ? "" : ", ") + n;
  cmd->add_option("--tf", p.tf,
                  "transfer function: a preset (" + presets + ") or a ParaView colour map .json")
      ->capture_default_str();
  cmd->add_option("--tf-unit", p.tf_unit,
                  "length (mm) the opacities refer to (0: one voxel for presets, 1 for ParaView files)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--camera", p.camera, "projection")
      ->check(CLI::IsMember({"ortho", "perspective"}))
      ->capture_default_str();
  cmd->add_option("--azimuth", p.azimuth, "degrees about +z (0: looking along +y)");
  cmd->add_option("--elevation", p.elevation, "degrees above the horizontal plane")
      ->check(CLI::Range(-90.0, 90.0));
  cmd->add_option("--position", p.position, "camera position x,y,z (physical frame; replaces the orbit)");
  cmd->add_option("--target", p.target, "point looked at, x,y,z (default: the volume's centre)");
  cmd->add_option("--up", p.up, "up direction x,y,z (default 0,0,1)");
  cmd->add_option("--size", p.size, "image size WxH")->capture_default_str();
  cmd->add_option(
      "--level", p.level,
      "render the approximation on this hierarchy level (-1: finest); a .mlfeh file is read only up to it");
  cmd->add_flag("--reference", p.reference, "ray-cast the original voxels instead (volume input)");
  cmd->add_option(
         "--integration", p.integration,
         "segment integration: pre-integrated with the tabulated mean transmittance, with the exact one, "
         "or the trapezoid rule")
      ->check(CLI::IsMember({"preintegrated", "exact", "trapezoid"}))
      ->capture_default_str();
  cmd->add_flag("--shading", p.shading, "shade with the per-tetrahedron gradient (headlight)");
  cmd->add_flag("--no-skip", p.no_skip, "no empty-space skipping");
  cmd->add_option("--png", p.png, "also write an sRGB PNG preview over the background");
  cmd->add_option("--frames", p.frames, "turntable: this many frames around +z, numbered files")
      ->check(CLI::Range(1, 3600));
  cmd->add_option("--background", p.background, "PNG background, linear r,g,b in [0,1]")
      ->capture_default_str();
  cmd->add_option("--stop-opacity", p.stop_opacity, "early ray termination")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  cmd->add_option("--z-opacity", p.z_opacity, "Z is where the accumulated opacity reaches this")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
}

namespace {

std::array<double, 3> parse3(const std::string& text, const std::string& what) {
  const auto v = parse_values(text, what);
  if (v.size() != 3) throw UsageError(what + ": expected x,y,z, got '" + text + "'");
  return {v[0], v[1], v[2]};
}

std::string numbered(const std::string& path, int frame, int frames) {
  if (frames <= 1) return path;
  const std::filesystem::path p(path);
  return (p.parent_path() / fmt::format("{}_{:04d}{}", p.stem().string(), frame, p.extension().string()))
      .string();
}

nlohmann::json tf_json(const TransferFunction& tf) {
  return {{"name", tf.name},
          {"RGBPoints", tf.color},
          {"opacityPoints", tf.opacity},
          {"opacityUnitLength", tf.unit_length}};
}

}  // namespace

std::vector<std::string> render_outputs(const std::string& out, const RenderParams& p, const Built& b,
                                        const ScalarGrid* grid, const std::string& source, bool quiet) {
  check_output_path(out, {".exr"});
  if (!p.png.empty()) check_output_path(p.png, {".png"});
  if (b.dim() != 3) throw Error(source + ": rendering needs a 3D volume or hierarchy");
  if (p.reference && !grid)
    throw Error(source + ": --reference needs the volume itself as input, not a hierarchy");
  int w = 0, h = 0;
  {
    char x = 0, rest = 0;
    if (std::sscanf(p.size.c_str(), "%d%c%d%c", &w, &x, &h, &rest) != 3 || (x != 'x' && x != 'X') || w < 1 ||
        h < 1 || w > 16384 || h > 16384)
      throw UsageError("--size: expected WxH (1..16384), got '" + p.size + "'");
  }
  const auto bg = parse3(p.background, "--background");
  // The orbit camera has its own target and up; silently dropping them would render another view.
  if (p.position.empty() && (!p.target.empty() || !p.up.empty()))
    throw UsageError(std::string(p.up.empty() ? "--target" : "--up") + ": needs --position");
  const GridTransform& tr = b.transform;
  const auto& hier = b.get<3>().hierarchy;

  // Transfer function: presets over the data's range, opacities per voxel unless told.
  double voxel = std::min({tr.spacing[0], tr.spacing[1], tr.spacing[2]});
  TransferFunction tf;
  const std::string ext = lower_extension(p.tf);
  if (ext == ".json") {
    tf = read_paraview_transfer_function(p.tf, p.tf_unit > 0 ? p.tf_unit : 1.0);
  } else {
    const double lo = b.value_min, hi = b.value_max > b.value_min ? b.value_max : b.value_min + 1;
    tf = transfer_function_preset(p.tf, lo, hi, p.tf_unit > 0 ? p.tf_unit : voxel);
  }

  // The volume's bounding ball in the physical frame.
  std::array<double, 3> lo_l{1e300, 1e300, 1e300}, hi_l{-1e300, -1e300, -1e300};
  for (const auto& q : hier.points())
    for (int a = 0; a < 3; ++a) {
      lo_l[a] = std::min(lo_l[a], q[a]);
      hi_l[a] = std::max(hi_l[a], q[a]);
    }
  if (b.get<3>().on_lattice) {  // T0's cube is padded: the volume is the data's box
    lo_l = {0, 0, 0};
    hi_l = b.get<3>().data_extent;
  }
  const std::array<double, 3> mid_l{0.5 * (lo_l[0] + hi_l[0]), 0.5 * (lo_l[1] + hi_l[1]),
                                    0.5 * (lo_l[2] + hi_l[2])};
  const auto center = tr.local_to_physical(mid_l);
  double radius = 0;
  for (int c = 0; c < 8; ++c) {
    const auto q = tr.local_to_physical(
        {c & 1 ? hi_l[0] : lo_l[0], c & 2 ? hi_l[1] : lo_l[1], c & 4 ? hi_l[2] : lo_l[2]});
    radius = std::max(radius, std::sqrt(std::pow(q[0] - center[0], 2) + std::pow(q[1] - center[1], 2) +
                                        std::pow(q[2] - center[2], 2)));
  }

  RenderOptions opt;
  opt.rule = p.integration == "trapezoid" ? RayAccumulator::Rule::kTrapezoid
             : p.integration == "exact"   ? RayAccumulator::Rule::kExact
                                          : RayAccumulator::Rule::kPreIntegrated;
  opt.stop_opacity = p.stop_opacity;
  opt.z_opacity = p.z_opacity;
  opt.shading = p.shading;
  opt.skip_empty = !p.no_skip;

  if (p.level < -1 || p.level > hier.max_level())
    throw UsageError(fmt::format("--level: expected -1 (finest) .. {} (the hierarchy's levels), got {}",
                                 hier.max_level(), p.level));
  std::unique_ptr<TetRenderMesh> mesh;
  if (!p.reference) {
    const Approximation<3>& a3 = b.get<3>();
    mesh =
        std::make_unique<TetRenderMesh>(hier, a3.values, p.level, a3.on_lattice ? &a3.data_extent : nullptr);
    if (!quiet)
      std::fprintf(
          stderr, "mlfe render: %zu tetrahedra on level %d, renderer adds %.1f MB (%.0f bytes/tetrahedron)\n",
          mesh->size(), mesh->level(), mesh->memory_bytes() / 1e6,
          double(mesh->memory_bytes()) / double(mesh->size()));
  }

  std::vector<std::string> written;
  for (int frame = 0; frame < p.frames; ++frame) {
    const double az = p.azimuth + 360.0 * frame / p.frames;
    Camera cam = orbit_camera(center, radius, az, p.elevation, p.camera == "perspective", w, h);
    if (!p.position.empty()) {
      cam.position = parse3(p.position, "--position");
      if (!p.target.empty()) cam.target = parse3(p.target, "--target");
      if (!p.up.empty()) cam.up = parse3(p.up, "--up");
      const double dist = std::sqrt(std::pow(cam.position[0] - cam.target[0], 2) +
                                    std::pow(cam.position[1] - cam.target[1], 2) +
                                    std::pow(cam.position[2] - cam.target[2], 2));
      if (!(dist > 0)) throw UsageError("--position and --target must differ");
      const std::array<double, 3> f{cam.target[0] - cam.position[0], cam.target[1] - cam.position[1],
                                    cam.target[2] - cam.position[2]};
      const std::array<double, 3> side{f[1] * cam.up[2] - f[2] * cam.up[1],
                                       f[2] * cam.up[0] - f[0] * cam.up[2],
                                       f[0] * cam.up[1] - f[1] * cam.up[0]};
      const double up_len = std::sqrt(cam.up[0] * cam.up[0] + cam.up[1] * cam.up[1] + cam.up[2] * cam.up[2]);
      if (!(std::sqrt(side[0] * side[0] + side[1] * side[1] + side[2] * side[2]) > 1e-9 * dist * up_len))
        throw UsageError("--up must not be parallel to the viewing direction (or zero)");
      cam.near_clip = std::max(dist - radius, 1e-3 * radius);
      cam.far_clip = dist + 2 * radius;
    }
    const auto t0 = std::chrono::steady_clock::now();
    RenderStats stats;
    const RenderImage img =
        p.reference ? render_grid(*grid, tf, cam, opt, &stats) : render_mesh(*mesh, tr, tf, cam, opt, &stats);
    const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    ExrAttributes attr;
    attr.world_to_camera = cam.world_to_camera();
    attr.world_to_ndc = cam.world_to_ndc();
    attr.strings = {
        {"mlfe/source", std::filesystem::path(source).filename().string()},
        {"mlfe/renderer", p.reference ? std::string("reference: trilinear voxels, 2 samples per voxel")
                                      : fmt::format("tetrahedral mesh, level {} of {}, {} integration",
                                                    mesh->level(), hier.max_level(), p.integration)},
        {"mlfe/transferFunction", tf_json(tf).dump()},
        {"mlfe/zConvention",
         fmt::format(
             "Z = distance along the ray from its origin (camera position; orthographic: the image plane "
             "through it), physical units, to where the accumulated opacity first reaches {}; +inf where "
             "it never does",
             p.z_opacity)},
        {"mlfe/alpha", "linear RGB, premultiplied alpha, no background"},
        {"mlfe/tool", std::string("mlfe ") + MLFE_VERSION},
    };
    const std::string exr_path = numbered(out, frame, p.frames);
    write_exr(exr_path, img, attr);
    written.push_back(exr_path);
    if (!p.png.empty()) {
      write_png_preview(numbered(p.png, frame, p.frames), img, bg);
      written.push_back(numbered(p.png, frame, p.frames));
    }
    if (!quiet)
      std::fprintf(
          stderr,
          "mlfe render: %dx%d in %.3f s, %llu rays, %llu segments, %llu skips, %llu relocated, %llu at the "
          "step bound -> %s\n",
          w, h, secs, (unsigned long long)stats.rays, (unsigned long long)stats.segments,
          (unsigned long long)stats.skips, (unsigned long long)stats.relocations,
          (unsigned long long)stats.step_bound_hits, exr_path.c_str());
  }
  return written;
}

namespace {

struct RenderState {
  std::string input, output;
  RenderParams render;
  BuildParams build;
  VolumeReadOptions read;
};

void run_render(const RenderState& s) {
  check_distinct_files({{"input", s.input}, {"--tf", s.render.tf}},
                       {{"--output", s.output}, {"--png", s.render.png}});
  check_output_path(s.output, {".exr"});
  std::optional<ScalarGrid> grid;
  Built b;
  if (is_hierarchy_file(s.input)) {
    // --level K reads the file's prefix up to level K only (docs/mlfeh-v3.md).
    b = built_from_file(s.input, s.render.level);
  } else {
    grid = read_volume(s.input, s.read);
    if (grid->dim != 3) throw Error(s.input + ": rendering needs a 3D volume");
    for (int a = 0; a < 3; ++a)
      if (grid->dims[a] < 2) throw Error(s.input + ": rendering needs at least 2 samples along every axis");
    if (!s.render.reference)
      b = build_from_grid(*grid, s.build, {});
    else {
      b.transform = grid->transform;
      const auto r = grid->value_range();
      b.value_min = r[0];
      b.value_max = r[1];
      // The reference needs no approximation; the box for the camera comes from T0.
      Approximation<3> a;
      a.hierarchy = Hierarchy<3>::box({0, 0, 0}, grid->local_extent());
      a.values.assign(a.hierarchy.vertex_count(), 0.0);
      b.approximation = std::move(a);
    }
  }
  for (const auto& f : render_outputs(s.output, s.render, b, grid ? &*grid : nullptr, s.input, s.build.quiet))
    std::printf("%s\n", f.c_str());
}

void add_render_command(CLI::App& app) {
  auto state = std::make_shared<RenderState>();
  CLI::App* cmd = app.add_subcommand(
      "render",
      "Ray-cast EXR image of a hierarchy or a volume, face to face through the adaptive tetrahedral mesh");
  cmd->add_option("input", state->input, "hierarchy (.mlfeh) or 3D volume (built first, as mlfe build)")
      ->required();
  cmd->add_option("-o,--output", state->output, "image (.exr; numbered with --frames)")->required();
  add_render_options(cmd, state->render);
  add_build_options(cmd, state->build);
  add_volume_read_options(cmd, state->read);
  cmd->callback([state] {
    apply_memory_budget(state->read, state->build);
    run_render(*state);
  });
}

}  // namespace

MLFE_REGISTER_COMMAND(45, add_render_command);

}  // namespace mlfe::cli
