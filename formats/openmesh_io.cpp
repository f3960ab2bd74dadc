// GCC 12 reports -Wmaybe-uninitialized inside OpenMesh's PropertyT<VectorT>::push_back (a
// default-constructed VectorT is deliberately uninitialized); the warning is not about our code.
// GCC matches the pragma by source location, so it must precede the OpenMesh/libstdc++ headers.
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"

#include "formats/openmesh_io.h"

#include <OpenMesh/Tools/Decimater/DecimaterT.hh>
#include <OpenMesh/Tools/Decimater/ModHausdorffT.hh>
#include <OpenMesh/Tools/Decimater/ModNormalFlippingT.hh>
#include <OpenMesh/Tools/Decimater/ModQuadricT.hh>
#include <algorithm>
#include <cctype>
#include <cmath>
#include <fstream>
#include <mutex>

#include "core/error.h"
#include "formats/atomic_file.h"
#include "formats/file_names.h"

namespace mlfe {
namespace {

// OpenMesh reports every refused face and every file written on its global log streams; a
// command line converting large meshes must not print thousands of such lines. The failures
// that matter are reported through return values and become mlfe::Error.
// The streams are process-global and OpenMesh does not guard them (surfaces are converted and
// simplified on several threads at once; unsynchronised omlog() calls crashed there), so all
// users share one count under a mutex: the first mutes the streams, the last restores them.
class QuietOpenMesh {
 public:
  QuietOpenMesh() {
    const std::lock_guard<std::mutex> lock(shared().mutex);
    Shared& s = shared();
    if (s.users++ == 0) {
      s.log = ::omlog().is_enabled();
      s.err = ::omerr().is_enabled();
      ::omlog().disable();
      ::omerr().disable();
    }
  }
  ~QuietOpenMesh() {
    const std::lock_guard<std::mutex> lock(shared().mutex);
    Shared& s = shared();
    if (--s.users == 0) {
      if (s.log) ::omlog().enable();
      if (s.err) ::omerr().enable();
    }
  }
  QuietOpenMesh(const QuietOpenMesh&) = delete;
  QuietOpenMesh& operator=(const QuietOpenMesh&) = delete;

 private:
  struct Shared {
    std::mutex mutex;
    int users = 0;
    bool log = false, err = false;
  };
  static Shared& shared() {
    static Shared s;
    return s;
  }
};

void check_mesh(const TriangleMesh& mesh, const std::string& what) {
  const std::size_t n = mesh.positions.size();
  if (!mesh.normals.empty() && mesh.normals.size() != n)
    throw Error(what + ": " + std::to_string(mesh.normals.size()) + " normals for " + std::to_string(n) +
                " positions");
  for (const auto& t : mesh.triangles)
    if (t[0] >= n || t[1] >= n || t[2] >= n) throw Error(what + ": triangle index out of range");
}

OpenMeshTriMesh convert(const TriangleMesh& mesh, const std::string& what) {
  check_mesh(mesh, what);
  const QuietOpenMesh quiet;
  OpenMeshTriMesh om;
  const bool normals = !mesh.normals.empty();
  if (normals) om.request_vertex_normals();
  om.reserve(mesh.positions.size(), mesh.triangles.size() * 3 / 2, mesh.triangles.size());
  auto add_vertex = [&](std::size_t i) {
    const auto& p = mesh.positions[i];
    const auto vh = om.add_vertex(OpenMeshTriMesh::Point(p[0], p[1], p[2]));
    if (normals) {
      const auto& q = mesh.normals[i];
      om.set_normal(vh, OpenMeshTriMesh::Normal(q[0], q[1], q[2]));
    }
    return vh;
  };
  for (std::size_t i = 0; i < mesh.positions.size(); ++i) add_vertex(i);
  for (const auto& t : mesh.triangles) {
    if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2]) continue;
    const auto fh = om.add_face(om.vertex_handle(t[0]), om.vertex_handle(t[1]), om.vertex_handle(t[2]));
    if (!fh.is_valid()) {
      // Non-manifold configuration (complex edge/vertex): detach this triangle.
      om.add_face(add_vertex(t[0]), add_vertex(t[1]), add_vertex(t[2]));
    }
  }
  return om;
}

// Area-weighted vertex normals (cross products are twice the area times the unit normal).
void recompute_normals(TriangleMesh& mesh) {
  std::vector<std::array<double, 3>> sum(mesh.positions.size(), {0.0, 0.0, 0.0});
  for (const auto& t : mesh.triangles) {
    const auto &a = mesh.positions[t[0]], &b = mesh.positions[t[1]], &c = mesh.positions[t[2]];
    const double u[3] = {double(b[0]) - a[0], double(b[1]) - a[1], double(b[2]) - a[2]};
    const double v[3] = {double(c[0]) - a[0], double(c[1]) - a[1], double(c[2]) - a[2]};
    const double n[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
    for (auto i : t)
      for (int k = 0; k < 3; ++k) sum[i][k] += n[k];
  }
  mesh.normals.resize(mesh.positions.size());
  for (std::size_t i = 0; i < sum.size(); ++i) {
    const double len = std::sqrt(sum[i][0] * sum[i][0] + sum[i][1] * sum[i][1] + sum[i][2] * sum[i][2]);
    if (len > 0)
      mesh.normals[i] = {float(sum[i][0] / len), float(sum[i][1] / len), float(sum[i][2] / len)};
    else
      mesh.normals[i] = {0.0f, 0.0f, 1.0f};  // isolated vertex: any unit vector
  }
}

}  // namespace

OpenMeshTriMesh to_openmesh(const TriangleMesh& mesh) { return convert(mesh, "OpenMesh conversion"); }

TriangleMesh from_openmesh(const OpenMeshTriMesh& om) {
  TriangleMesh mesh;
  const bool normals = om.has_vertex_normals();
  // Deleted vertices (after decimation without garbage collection) must not leave holes.
  std::vector<std::uint32_t> index(om.n_vertices(), 0);
  for (const auto vh : om.vertices()) {  // vertices() skips deleted ones when status is present
    index[vh.idx()] = std::uint32_t(mesh.positions.size());
    const auto& p = om.point(vh);
    mesh.positions.push_back({p[0], p[1], p[2]});
    if (normals) {
      const auto& q = om.normal(vh);
      mesh.normals.push_back({q[0], q[1], q[2]});
    }
  }
  mesh.triangles.reserve(om.n_faces());
  for (const auto fh : om.faces()) {
    std::array<std::uint32_t, 3> t{};
    int k = 0;
    for (const auto vh : om.fv_range(fh)) {
      if (k < 3) t[k] = index[vh.idx()];
      ++k;
    }
    if (k == 3) mesh.triangles.push_back(t);
  }
  return mesh;
}

void write_mesh_file(const std::string& path, const TriangleMesh& mesh) {
  const std::string ext = lower_extension(path);
  OpenMesh::IO::Options opt;
  if (ext == ".ply" || ext == ".stl") {
    opt += OpenMesh::IO::Options::Binary;
    opt += OpenMesh::IO::Options::LSB;  // PLY: fixed little-endian whatever the host is
  } else if (ext != ".obj" && ext != ".off") {
    throw Error(path + ": unsupported mesh extension (expected .ply, .obj, .off or .stl)");
  }
  OpenMeshTriMesh om = convert(mesh, path);
  if (ext == ".stl") {
    om.request_face_normals();
    om.update_face_normals();
    opt += OpenMesh::IO::Options::FaceNormal;
  } else if (om.has_vertex_normals()) {
    opt += OpenMesh::IO::Options::VertexNormal;
  }
  const QuietOpenMesh quiet;
  // 9 significant digits round-trip every float exactly in the text formats.
  write_path_atomically(path,
                        [&](const std::string& tmp) { return OpenMesh::IO::write_mesh(om, tmp, opt, 9); });
}

TriangleMesh read_mesh_file(const std::string& path) {
  if (!std::ifstream(path).good()) throw Error(path + ": cannot open file");
  OpenMeshTriMesh om;
  om.request_vertex_normals();
  OpenMesh::IO::Options opt = OpenMesh::IO::Options::VertexNormal;
  const QuietOpenMesh quiet;
  if (!OpenMesh::IO::read_mesh(om, path, opt)) throw Error(path + ": cannot read mesh");
  if (!opt.vertex_has_normal()) om.release_vertex_normals();
  return from_openmesh(om);
}

TriangleMesh decimate_to(const TriangleMesh& mesh, std::size_t target_triangles) {
  if (mesh.triangles.size() <= target_triangles) {
    check_mesh(mesh, "decimation");
    return mesh;
  }
  OpenMeshTriMesh om = convert(mesh, "decimation");
  if (om.has_vertex_normals()) om.release_vertex_normals();  // recomputed below
  {
    using Decimater = OpenMesh::Decimater::DecimaterT<OpenMeshTriMesh>;
    using ModQuadric = OpenMesh::Decimater::ModQuadricT<OpenMeshTriMesh>;
    using ModNormalFlipping = OpenMesh::Decimater::ModNormalFlippingT<OpenMeshTriMesh>;
    Decimater decimater(om);
    ModQuadric::Handle quadric;
    decimater.add(quadric);
    decimater.module(quadric).unset_max_err();  // the target count, not an error bound, decides
    // Quadrics alone happily fold triangles over at coarse targets; forbid collapses that turn
    // a face normal by more than 60 degrees.
    om.request_face_normals();  // present before the module is added, so it does not warn
    om.update_face_normals();
    ModNormalFlipping::Handle flipping;
    decimater.add(flipping);
    decimater.module(flipping).set_max_normal_deviation(60.0);
    if (!decimater.initialize()) throw Error("decimation: OpenMesh decimater failed to initialize");
    decimater.decimate_to_faces(0, target_triangles);
    // Inside the scope: the decimater releases the status flags that mark deleted elements.
    om.garbage_collection();
  }
  TriangleMesh out = from_openmesh(om);
  recompute_normals(out);
  return out;
}

TriangleMesh simplify_within(const TriangleMesh& mesh, double tolerance, std::size_t min_triangles) {
  if (!(tolerance > 0) || !std::isfinite(tolerance))
    throw Error("simplification: the tolerance must be positive");
  OpenMeshTriMesh om = convert(mesh, "simplification");
  if (om.has_vertex_normals()) om.release_vertex_normals();  // recomputed below
  om.request_face_normals();
  om.update_face_normals();
  using Decimater = OpenMesh::Decimater::DecimaterT<OpenMeshTriMesh>;
  using ModQuadric = OpenMesh::Decimater::ModQuadricT<OpenMeshTriMesh>;
  using ModNormalFlipping = OpenMesh::Decimater::ModNormalFlippingT<OpenMeshTriMesh>;
  {
    // Quadrics order the collapses (cheapest first); the Hausdorff module is the bound: it
    // keeps every removed vertex attached to the face that now covers it and refuses a
    // collapse that would leave any of them farther than `tolerance` from the surface. Small
    // closed parts therefore survive (collapsing them would move their points too far),
    // which is what a count-driven quadric decimation loses.
    using ModHausdorff = OpenMesh::Decimater::ModHausdorffT<OpenMeshTriMesh>;
    Decimater decimater(om);
    ModQuadric::Handle quadric;
    decimater.add(quadric);
    decimater.module(quadric).unset_max_err();
    ModHausdorff::Handle hausdorff;
    decimater.add(hausdorff);
    decimater.module(hausdorff).set_tolerance(static_cast<float>(tolerance));
    ModNormalFlipping::Handle flipping;
    decimater.add(flipping);
    decimater.module(flipping).set_max_normal_deviation(45.0);
    if (!decimater.initialize()) throw Error("simplification: OpenMesh decimater failed to initialize");
    decimater.decimate_to_faces(0, min_triangles);
    om.garbage_collection();
  }
  TriangleMesh out = from_openmesh(om);
  recompute_normals(out);
  return out;
}

}  // namespace mlfe
