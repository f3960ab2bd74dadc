// render_bench: helpers for bench/py/render_bench.py, which times `mlfe render` (mesh and
// reference) against VTK's volume mappers in one run.
//
//   render_bench setup VOL H.mlfeh AZ EL W H TF OUT_PREFIX
//       writes OUT_PREFIX.raw (the voxels as float32, x fastest), OUT_PREFIX.vtu (the leaf mesh
//       of H with u, in the hierarchy's local frame) and prints JSON: dims, spacing, the camera
//       of `mlfe render --azimuth AZ --elevation EL --size WxH` in the local frame, and the
//       transfer function of preset TF as `mlfe render` builds it (so VTK gets the same view
//       and colours);
//   render_bench psnr A.exr B.exr
//       prints JSON {psnr_db, max_abs, rms}: RGBA (premultiplied) of A against B, peak 1.
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>
#include <mlfe/core/render/volume_render.h>
#include <mlfe/formats/hierarchy_io.h>
#include <mlfe/formats/volume_reader.h>
#include <mlfe/formats/vtu_writer.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

using namespace mlfe;

namespace {

std::vector<float> read_rgba(const std::string& path, int& w, int& h) {
  Imf::InputFile in(path.c_str());
  const auto dw = in.header().dataWindow();
  w = dw.max.x - dw.min.x + 1;
  h = dw.max.y - dw.min.y + 1;
  std::vector<float> px(std::size_t(w) * h * 4);
  Imf::FrameBuffer fb;
  const char* names[4] = {"R", "G", "B", "A"};
  for (int c = 0; c < 4; ++c)
    fb.insert(names[c], Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(px.data() + c), 4 * sizeof(float),
                                   4 * sizeof(float) * std::size_t(w)));
  in.setFrameBuffer(fb);
  in.readPixels(dw.min.y, dw.max.y);
  return px;
}

int psnr(const std::string& a, const std::string& b) {
  int wa, ha, wb, hb;
  const auto pa = read_rgba(a, wa, ha), pb = read_rgba(b, wb, hb);
  if (wa != wb || ha != hb) {
    std::fprintf(stderr, "size mismatch\n");
    return 2;
  }
  double se = 0, mx = 0;
  for (std::size_t i = 0; i < pa.size(); ++i) {
    const double d = std::clamp(double(pa[i]), 0.0, 1.0) - std::clamp(double(pb[i]), 0.0, 1.0);
    se += d * d;
    mx = std::max(mx, std::abs(d));
  }
  const double rms = std::sqrt(se / double(pa.size()));
  std::printf("%s\n", nlohmann::json({{"psnr_db", 20 * std::log10(1.0 / rms)}, {"max_abs", mx}, {"rms", rms}})
                          .dump()
                          .c_str());
  return 0;
}

int setup(char** argv) {
  const ScalarGrid g = read_volume(argv[2], {});
  const HierarchyFile hf = read_hierarchy(argv[3]);
  const auto& h = std::get<Hierarchy<3>>(hf.hierarchy);
  const double az = std::stod(argv[4]), el = std::stod(argv[5]);
  const int w = std::stoi(argv[6]), hh = std::stoi(argv[7]);
  const std::string prefix = argv[9];
  {
    std::ofstream raw(prefix + ".raw", std::ios::binary);
    raw.write(reinterpret_cast<const char*>(g.values.data()),
              std::streamsize(g.values.size() * sizeof(float)));
  }
  write_vtu<3>(prefix + ".vtu", h, h.leaves(), &hf.values, nullptr);
  // The camera exactly as `mlfe render` places it (converters/cmd_render.cpp), then in the
  // local frame.
  const auto& tr = hf.transform;
  const auto ext = g.local_extent();
  const std::array<double, 3> mid{0.5 * ext[0], 0.5 * ext[1], 0.5 * ext[2]};
  const auto center = tr.local_to_physical(mid);
  double radius = 0;
  for (int c = 0; c < 8; ++c) {
    const auto q = tr.local_to_physical({c & 1 ? ext[0] : 0, c & 2 ? ext[1] : 0, c & 4 ? ext[2] : 0});
    radius = std::max(radius, std::sqrt(std::pow(q[0] - center[0], 2) + std::pow(q[1] - center[1], 2) +
                                        std::pow(q[2] - center[2], 2)));
  }
  const Camera cam = orbit_camera(center, radius, az, el, false, w, hh);
  const auto pos = world_to_local_point(tr, cam.position), tgt = world_to_local_point(tr, cam.target);
  const auto up = world_to_local_direction(tr, cam.up);
  const double voxel = std::min({tr.spacing[0], tr.spacing[1], tr.spacing[2]});
  const TransferFunction tf = transfer_function_preset(argv[8], hf.value_min, hf.value_max, voxel);
  nlohmann::json j = {{"dims", g.dims},
                      {"spacing", g.transform.spacing},
                      {"tets", h.leaves().size()},
                      {"voxels", g.voxel_count()},
                      {"camera",
                       {{"position", pos},
                        {"focal_point", tgt},
                        {"view_up", up},
                        {"parallel_scale", 0.5 * cam.ortho_height}}},
                      {"tf", {{"rgb", tf.color}, {"opacity", tf.opacity}, {"unit", tf.unit_length}}}};
  std::printf("%s\n", j.dump().c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    if (argc == 4 && std::string(argv[1]) == "psnr") return psnr(argv[2], argv[3]);
    if (argc == 10 && std::string(argv[1]) == "setup") return setup(argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "render_bench: %s\n", e.what());
    return 2;
  }
  std::fprintf(stderr, "usage: render_bench setup VOL H.mlfeh AZ EL W H TF PREFIX | psnr A.exr B.exr\n");
  return 1;
}
