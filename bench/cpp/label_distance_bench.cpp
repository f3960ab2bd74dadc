// Distances of bench/py/labels_bench.py: per label, mlfe's structure (from its .glb), the VTK
// pipeline's (vtk_<label>.ply) and each further peer's (<peer>_<label>.ply, e.g. Surface Nets with
// and without its smoothing) against the label's voxel-boundary surface (ref_<label>.ply,
// discrete flying edges), all in index coordinates (voxels): symmetric Hausdorff and the
// larger one-sided mean over vertices + 20 000 area samples per mesh (core/surface/mesh_distance.h),
// and the mesh's topology (core/surface/triangle_mesh.h's mesh_topology, welded by position):
// closed (no boundary edge), manifold (no edge in three or more triangles, every vertex one fan),
// edges whose two triangles disagree in orientation. Each row also has the label's voxel count.
// Also packs the VTK meshes into a Draco .glb at mlfe's default tolerance, for the bytes.
//
//   label_distance_bench VOLUME MLFE.glb DIR [PEER ...]      (prints JSON)
#include <mlfe/core/surface/mesh_distance.h>
#include <mlfe/core/surface/triangle_mesh.h>
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

namespace {

// mlfe's structures by label, mapped from glTF metres back to the grid's index coordinates.
std::map<int, TriangleMesh> mlfe_meshes(const std::string& glb, const ScalarGrid& grid) {
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
  const GltfAsset a = read_gltf(glb);
  std::map<int, TriangleMesh> meshes;
  for (const auto& p : a.primitives) {
    const int label = a.structure["nodes"][p.node]["extras"]["label"].get<int>();
    TriangleMesh mesh = p.mesh_data;
    for (auto& q : mesh.positions) q = to_index(q);
    meshes[label] = std::move(mesh);
  }
  return meshes;
}

// Distances and topology of `mesh` against `ref`; an empty mesh (decimated away: the whole
// reference is missing) is marked lost with 1e9 distances.
nlohmann::json mesh_row(const TriangleMesh& ref, const TriangleMesh& mesh, const SurfaceSamplingOptions& so) {
  if (mesh.triangles.empty())
    return {{"mean", 1e9},  {"hausdorff", 1e9}, {"triangles", 0},
            {"lost", true}, {"closed", false},  {"manifold", false}};
  const MeshDistance d = mesh_distance(ref, mesh, so);
  const MeshTopology top = mesh_topology(mesh);
  return {{"mean", d.mean()},
          {"hausdorff", d.hausdorff()},
          {"triangles", mesh.triangles.size()},
          {"closed", top.boundary_edges == 0},
          {"manifold", top.non_manifold_edges == 0 && top.non_manifold_vertices == 0},
          {"boundary_edges", top.boundary_edges},
          {"non_manifold_edges", top.non_manifold_edges},
          {"non_manifold_vertices", top.non_manifold_vertices},
          {"inconsistent_edges", top.inconsistent_edges}};
}

TriangleMesh read_if_present(const std::string& path) {
  return std::filesystem::exists(path) ? read_mesh_file(path) : TriangleMesh{};
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 4) {
    std::fprintf(stderr, "usage: label_distance_bench VOLUME MLFE.glb DIR [PEER ...]\n");
    return 1;
  }
  const std::string dir = argv[3];
  const std::vector<std::string> peers(argv + 4, argv + argc);
  VolumeReadOptions ro;
  const ScalarGrid grid = read_volume(argv[1], ro);
  const GridTransform& t = grid.transform;
  std::map<int, std::int64_t> voxels;
  for (const float v : grid.values) ++voxels[int(v)];
  SurfaceSamplingOptions so;
  so.area_samples = 20000;
  nlohmann::json rows = nlohmann::json::array();
  std::vector<GltfSurface> vtk_surfaces;
  for (const auto& [label, mesh] : mlfe_meshes(argv[2], grid)) {
    auto path = [&](const std::string& peer) {
      return dir + "/" + peer + "_" + std::to_string(label) + ".ply";
    };
    const TriangleMesh ref = read_mesh_file(path("ref"));
    nlohmann::json row = {{"label", label}, {"voxels", voxels[label]}};
    row["mlfe"] = mesh_row(ref, mesh, so);
    TriangleMesh vtk = read_if_present(path("vtk"));
    row["vtk"] = mesh_row(ref, vtk, so);
    for (const auto& peer : peers) row[peer] = mesh_row(ref, read_if_present(path(peer)), so);
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
