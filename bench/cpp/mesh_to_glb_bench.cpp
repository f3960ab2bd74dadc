// mesh_to_glb_bench: a triangle mesh file (PLY/OBJ/OFF/STL, read with read_mesh_file) as a
// Draco-compressed .glb written by write_gltf — the same writer and tolerance `mlfe convert`
// uses — so meshes from VTK or OpenVDB can be compared byte for byte with mlfe's assets.
//
//   mesh_to_glb_bench IN.ply OUT.glb [--scale sx,sy,sz] [--tolerance MM] [--no-draco]
//     --scale      multiply positions per axis first (voxel index -> millimetres: the spacing)
//     --tolerance  Draco position tolerance in mm (default: min(scale) / 10, mlfe's default)
//     --drc P      also write the positions alone as Draco (.drc, same tolerance): "bytes without
//                  normals" in the JSON
// Prints one JSON line: triangles, vertices, bytes, seconds (all), write_seconds (the .glb alone).
#include <mlfe/formats/draco_io.h>
#include <mlfe/formats/gltf_writer.h>
#include <mlfe/formats/openmesh_io.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(
        stderr, "usage: mesh_to_glb_bench IN.ply OUT.glb [--scale sx,sy,sz] [--tolerance MM] [--no-draco]\n");
    return 1;
  }
  std::array<double, 3> scale{1, 1, 1};
  double tol = 0;
  bool draco = true;
  std::string drc;
  for (int i = 3; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--scale" && i + 1 < argc) {
      if (std::sscanf(argv[++i], "%lf,%lf,%lf", &scale[0], &scale[1], &scale[2]) != 3) return 1;
    } else if (a == "--tolerance" && i + 1 < argc) {
      tol = std::atof(argv[++i]);
    } else if (a == "--drc" && i + 1 < argc) {
      drc = argv[++i];
    } else if (a == "--no-draco") {
      draco = false;
    } else {
      std::fprintf(stderr, "unknown argument %s\n", a.c_str());
      return 1;
    }
  }
  if (tol <= 0) tol = std::min({scale[0], scale[1], scale[2]}) / 10.0;
  try {
    const auto t0 = std::chrono::steady_clock::now();
    mlfe::GltfSurface s;
    s.mesh = mlfe::read_mesh_file(argv[1]);
    for (auto& p : s.mesh.positions)
      for (int a = 0; a < 3; ++a) p[a] = float(p[a] * scale[a]);
    s.mesh.normals.clear();  // recomputed from the (scaled) triangles by write_gltf
    std::size_t drc_bytes = 0;
    if (!drc.empty()) {
      mlfe::DracoOptions d;
      d.tolerance = tol;
      mlfe::write_draco_file(drc, s.mesh, d);
      drc_bytes = std::filesystem::file_size(drc);
    }
    s.name = "surface";
    const std::size_t tris = s.mesh.triangles.size(), verts = s.mesh.positions.size();
    mlfe::GltfOptions o;
    o.draco = draco;
    o.tolerance_mm = tol;
    o.generator = "mlfe mesh_to_glb_bench";
    std::vector<mlfe::GltfSurface> surfaces;
    surfaces.push_back(std::move(s));
    const auto tw = std::chrono::steady_clock::now();
    mlfe::write_gltf(argv[2], surfaces, o);
    const double write_sec = std::chrono::duration<double>(std::chrono::steady_clock::now() - tw).count();
    const double sec = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    nlohmann::json j = {
        {"triangles", tris},         {"vertices", verts}, {"bytes", std::filesystem::file_size(argv[2])},
        {"tolerance_mm", tol},       {"draco", draco},    {"seconds", sec},
        {"write_seconds", write_sec}};
    if (!drc.empty()) j["drc_positions_bytes"] = drc_bytes;
    std::printf("%s\n", j.dump().c_str());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "mesh_to_glb_bench: %s\n", e.what());
    return 2;
  }
  return 0;
}
