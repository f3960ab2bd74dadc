// Distances of bench/py/labels_bench.py: per label, mlfe's structure (from its .glb) and the VTK
// pipeline's (vtk_<label>.ply) against the label's voxel-boundary surface (ref_<label>.ply,
// discrete flying edges), all in index coordinates (voxels): symmetric Hausdorff and the
// larger one-sided mean over vertices + 20 000 area samples per mesh (core/surface/mesh_distance.h).
// Also packs the VTK meshes into a Draco .glb at mlfe's default tolerance, for the bytes.
//
//   label_distance_bench VOLUME MLFE.glb DIR      (prints JSON)
#include <mlfe/core/surface/mesh_distance.h>
#include <mlfe/formats/gltf_reader.h>
#include <mlfe/formats/gltf_writer.h>
#include <mlfe/formats/openmesh_io.h>
#include <mlfe/formats/volume_reader.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>

using namespace mlfe;

int main(int argc, char** argv) {
  if (argc != 4) {
    std::fprintf(stderr, "usage: label_distance_bench VOLUME MLFE.glb DIR\n");
    return 1;
  }
  const std::string dir = argv[3];
  VolumeReadOptions ro;
  const ScalarGrid grid = read_volume(argv[1], ro);
  const GridTransform& t = grid.transform;
  const auto m = physical_to_gltf_matrix(grid.space);
  // glTF metres -> physical mm (M is 1/1000 of a rotation) -> index coordinates.
  auto to_index = [&](const std::array<float, 3>& g) {
    std::array<double, 3> p{};
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) p[c] += 1e6 * m[r * 3 + c] * g[r];
    std::array<float, 3> idx{};
    for (int c = 0; c < 3; ++c) {
      double s = 0;
      for (int r = 0; r < 3; ++r) s += t.direction[r * 3 + c] * (p[r] - t.origin[r]);
      idx[c] = float(s / t.spacing[c]);
    }
    return idx;
  };
  const GltfAsset a = read_gltf(argv[2]);
  std::map<int, TriangleMesh> mlfe_mesh;
  for (const auto& p : a.primitives) {
    const int label = a.structure["nodes"][p.node]["extras"]["label"].get<int>();
    TriangleMesh mesh = p.mesh_data;
    for (auto& q : mesh.positions) q = to_index(q);
    mlfe_mesh[label] = std::move(mesh);
  }
  SurfaceSamplingOptions so;
  so.area_samples = 20000;
  nlohmann::json rows = nlohmann::json::array();
  std::vector<GltfSurface> vtk_surfaces;
  for (const auto& [label, mesh] : mlfe_mesh) {
    const std::string ref_path = dir + "/ref_" + std::to_string(label) + ".ply",
                      vtk_path = dir + "/vtk_" + std::to_string(label) + ".ply";
    const TriangleMesh ref = read_mesh_file(ref_path);
    nlohmann::json row = {{"label", label}};
    const MeshDistance dm = mesh_distance(ref, mesh, so);
    row["mlfe"] = {{"mean", dm.mean()}, {"hausdorff", dm.hausdorff()}, {"triangles", mesh.triangles.size()}};
    TriangleMesh vtk;
    if (std::filesystem::exists(vtk_path)) vtk = read_mesh_file(vtk_path);
    if (!vtk.triangles.empty()) {
      const MeshDistance dv = mesh_distance(ref, vtk, so);
      row["vtk"] = {{"mean", dv.mean()}, {"hausdorff", dv.hausdorff()}, {"triangles", vtk.triangles.size()}};
    } else {
      // Decimated away: the whole reference is missing (1e9 marks it).
      row["vtk"] = {{"mean", 1e9}, {"hausdorff", 1e9}, {"triangles", 0}, {"lost", true}};
    }
    rows.push_back(row);
    GltfSurface s;
    s.name = s.node_name = "label_" + std::to_string(label);
    for (auto& q : vtk.positions) {
      const auto p = t.index_to_physical(q[0], q[1], q[2]);
      q = {float(p[0]), float(p[1]), float(p[2])};
    }
    s.mesh = std::move(vtk);
    s.node_extras = {{"label", label}};
    vtk_surfaces.push_back(std::move(s));
  }
  GltfOptions go;
  go.space = grid.space;
  go.tolerance_mm = std::min({t.spacing[0], t.spacing[1], t.spacing[2]}) / 10.0;
  const std::string vtk_glb = dir + "/vtk.glb";
  write_gltf(vtk_glb, vtk_surfaces, go);
  nlohmann::json out = {{"labels", rows}, {"vtk_glb_bytes", std::filesystem::file_size(vtk_glb)}};
  std::printf("%s\n", out.dump().c_str());
  return 0;
}
