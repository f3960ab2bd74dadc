// GCC 12 reports -Wmaybe-uninitialized inside OpenMesh's PropertyT<VectorT>::push_back (a
// default-constructed VectorT is deliberately uninitialized); the warning is not about our code.
// GCC matches the pragma by source location, so it must precede the OpenMesh/libstdc++ headers.
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"

#include <mlfe/core/base/error.h>
#include <mlfe/formats/atomic_file.h>
#include <mlfe/formats/file_names.h>
#include <mlfe/formats/openmesh_io.h>
#include <mlfe/formats/safe_read.h>

#include <OpenMesh/Core/IO/reader/OFFReader.hh>
#include <OpenMesh/Core/IO/reader/PLYReader.hh>
#include <OpenMesh/Tools/Decimater/DecimaterT.hh>
#include <OpenMesh/Tools/Decimater/ModNormalFlippingT.hh>
#include <OpenMesh/Tools/Decimater/ModQuadricT.hh>
#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <iterator>
#include <mutex>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

namespace mlfe {
namespace {

// OpenMesh reports every refused face and every file written on its global log streams; a
// command line converting large meshes must not print thousands of such lines. The failures
// that matter are reported through return values and become mlfe::Error.
// The streams are process-global and OpenMesh does not guard them (callers may convert meshes
// on several threads at once; unsynchronised omlog() calls crashed `mlfe convert` when it
// simplified surfaces through OpenMesh in parallel), so all users share one count under a
// mutex: the first mutes the streams, the last restores them.
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

namespace {

// A count a header declares: a whole non-negative number.
std::uint64_t header_count(const std::string& path, const std::string& what, const std::string& token) {
  std::uint64_t v = 0;
  const auto r = std::from_chars(token.data(), token.data() + token.size(), v);
  if (token.empty() || r.ec != std::errc() || r.ptr != token.data() + token.size())
    throw Error(path + ": " + what + " '" + token.substr(0, 40) + "' is not a count");
  return v;
}

// What a mesh file's header says it holds, to be compared with what OpenMesh hands over.
struct Declared {
  std::optional<std::uint64_t> vertices, faces;
  /// PLY or ASCII OFF: read on a stream whose state shows a read past the end of the file
  /// (OpenMesh's readers read on past the end of a short one without failing).
  bool on_stream = false;
};

// OpenMesh loops over (and reserves for) the counts an OFF or PLY header declares before it
// finds the data short: 30 bytes declaring a million vertices took minutes. Each count is
// weighed against the file size with the fewest bytes an item can take (a value as text is a
// digit and a separator; in binary at least a byte).
Declared check_declared_counts(const std::string& path, const std::string& ext, const std::string& head,
                               std::uint64_t size) {
  Declared declared;
  std::istringstream in(head);
  if (ext == ".off") {
    std::vector<std::string> words;
    for (std::string line; words.size() < 5 && std::getline(in, line);) {
      std::istringstream w(line.substr(0, line.find('#')));
      for (std::string word; w >> word;) words.push_back(word);
    }
    if (words.size() > 1 && words[1] == "BINARY") return declared;  // binary counts: OpenMesh checks them
    if (words.size() < 3) throw Error(path + ": truncated OFF header (no vertex and face counts)");
    declared.vertices = header_count(path, "the OFF vertex count", words[1]);
    declared.faces = header_count(path, "the OFF face count", words[2]);
    declared.on_stream = true;
    check_declared_count(path, "the OFF header's vertex count", *declared.vertices, 6, size);
    check_declared_count(path, "the OFF header's face count", *declared.faces, 8, size);
    return declared;
  }
  declared.on_stream = true;
  bool ascii = false;
  std::string element;
  std::uint64_t count = 0, properties = 0;
  const auto weigh = [&] {
    if (element.empty()) return;
    check_declared_count(path, "the PLY element '" + element.substr(0, 40) + "'", count,
                         (ascii ? 2 : 1) * std::max<std::uint64_t>(properties, 1), size);
    if (element == "vertex") declared.vertices = count;
    if (element == "face") declared.faces = count;
  };
  for (std::string line; std::getline(in, line);) {
    std::istringstream w(line);
    std::string key, a, b;
    w >> key >> a >> b;
    if (key == "format") ascii = a == "ascii";
    if (key == "property") ++properties;
    if (key == "element" || key == "end_header") {
      weigh();
      if (key == "end_header") return declared;
      element = a;
      count = header_count(path, "the PLY element '" + a.substr(0, 40) + "' count", b);
      properties = 0;
    }
  }
  return declared;
}

// OpenMesh's ASCII STL reader skips the lines it does not know, so text that is not STL became
// an empty mesh: every line must start with one of the format's keywords, three vertices to a
// facet. Returns the number of facets.
std::uint64_t ascii_stl_facets(const std::string& path) {
  static const char* const kKeywords[] = {"solid",   "facet",    "outer",   "vertex",
                                          "endloop", "endfacet", "endsolid"};
  std::ifstream in(path, std::ios::binary);
  std::uint64_t facets = 0, vertices = 0, line_number = 0;
  for (std::string line; std::getline(in, line);) {
    ++line_number;
    std::istringstream words(line);
    std::string word;
    if (!(words >> word)) continue;
    std::transform(word.begin(), word.end(), word.begin(),
                   [](unsigned char c) { return char(std::tolower(c)); });
    if (std::find(std::begin(kKeywords), std::end(kKeywords), word) == std::end(kKeywords))
      throw Error(path + ": line " + std::to_string(line_number) + ": '" + word.substr(0, 40) +
                  "' is not an STL keyword");
    facets += word == "facet";
    vertices += word == "vertex";
  }
  if (vertices != 3 * facets)
    throw Error(path + ": " + std::to_string(facets) + " facets with " + std::to_string(vertices) +
                " vertices (three to a facet)");
  return facets;
}

// OpenMesh reads what it can and skips the rest, so random bytes named .stl or .obj became an
// empty mesh (and two such files compared equal). What each format must start with is checked
// here; a binary STL must also be exactly as long as its triangle count says.
Declared check_mesh_file_header(const std::string& path) {
  RegularFile file(path);
  const std::uint64_t size = file.size();
  std::string head(static_cast<std::size_t>(std::min<std::uint64_t>(4096, size)), '\0');
  head.resize(file.read(head.data(), head.size()));
  const std::string ext = lower_extension(path);
  const auto starts = [&](const char* s) { return head.compare(0, std::strlen(s), s) == 0; };
  const auto text = [&] {
    return std::all_of(head.begin(), head.end(), [](char c) {
      const auto u = static_cast<unsigned char>(c);
      return u >= 0x20 || c == '\n' || c == '\r' || c == '\t';
    });
  };
  if (ext == ".ply" && !starts("ply\n") && !starts("ply\r\n")) throw Error(path + ": not a PLY file");
  if (ext == ".off") {
    const std::size_t first = head.find_first_not_of(" \t\r\n");
    const std::string word = first == std::string::npos ? "" : head.substr(first, 6);
    if (word.find("OFF") == std::string::npos) throw Error(path + ": not an OFF file");
  }
  if (ext == ".off" || ext == ".ply") return check_declared_counts(path, ext, head, size);
  if (ext == ".obj" && !text()) throw Error(path + ": not an OBJ file (binary bytes in a text format)");
  Declared declared;
  if (ext == ".stl") {
    std::uint32_t count = 0;
    if (head.size() >= 84) std::memcpy(&count, head.data() + 80, 4);
    const bool binary = size >= 84 && size == 84 + 50 * std::uint64_t(count);
    if (!binary && !(starts("solid") && text()))
      throw Error(path + ": not an STL file (binary: " + std::to_string(size) +
                  " bytes do not match its triangle count; ASCII: does not start with 'solid')");
    declared.faces = binary ? count : ascii_stl_facets(path);
  }
  return declared;
}

// OpenMesh's importer, counting what the readers hand it: they pass on a face whose vertex
// index is out of range (OBJ 'f 1 2 99', a PLY index past its vertices) and the importer drops
// it without failing the read, so a damaged file read as a smaller mesh.
class CountingImporter : public OpenMesh::IO::ImporterT<OpenMeshTriMesh> {
 public:
  explicit CountingImporter(OpenMeshTriMesh& mesh) : ImporterT(mesh), mesh_(mesh) {}

  OpenMesh::FaceHandle add_face(const VHandles& indices) override {
    ++faces;
    if (problem.empty() && indices.size() < 3)
      problem = "face " + std::to_string(faces) + " has fewer than 3 vertices";
    for (const auto vh : indices)
      if (problem.empty() && !mesh_.is_valid_handle(vh))
        problem = "face " + std::to_string(faces) + " refers to vertex " + std::to_string(vh.idx()) +
                  " (counted from 0) of " + std::to_string(mesh_.n_vertices());
    // A face that would make the mesh non-manifold is added on copies of its vertices.
    const std::size_t before = mesh_.n_vertices();
    const auto fh = ImporterT::add_face(indices);
    copies += mesh_.n_vertices() - before;
    return fh;
  }

  std::uint64_t faces = 0;   ///< faces handed over
  std::uint64_t copies = 0;  ///< vertices the importer added for non-manifold faces
  std::string problem;       ///< the first face that could not be added as it was written

 private:
  OpenMeshTriMesh& mesh_;
};

// The mesh OpenMesh read must be the one the file declares: every face added, the counts of the
// header met, and no read past the end of the file (OpenMesh's OFF and PLY readers read on past
// the end of a short one, taking uninitialised or repeated indices).
void check_as_declared(const std::string& path, const Declared& declared, const CountingImporter& importer,
                       const OpenMeshTriMesh& om, bool read_past_end) {
  if (read_past_end) throw Error(path + ": the file ends before the vertices and faces its header declares");
  if (!importer.problem.empty()) throw Error(path + ": " + importer.problem);
  const std::uint64_t vertices = om.n_vertices() - importer.copies;
  if (declared.vertices && *declared.vertices != vertices)
    throw Error(path + ": declares " + std::to_string(*declared.vertices) + " vertices, " +
                std::to_string(vertices) + " read");
  if (declared.faces && *declared.faces != importer.faces)
    throw Error(path + ": declares " + std::to_string(*declared.faces) + " faces, " +
                std::to_string(importer.faces) + " read");
}

}  // namespace

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
  // 9 significant digits round-trip every float exactly in the text formats. On a stream of the
  // shared writer, whose state is checked: OpenMesh does not report a failed write to a path.
  write_file_atomically(path, [&](std::ostream& out) {
    if (!OpenMesh::IO::write_mesh(om, out, ext, opt, 9)) throw Error(path + ": OpenMesh cannot write it");
  });
}

TriangleMesh read_mesh_file(const std::string& path) {
  const Declared declared = check_mesh_file_header(path);
  OpenMeshTriMesh om;
  OpenMesh::IO::Options opt;
  // STL has facet normals only, yet OpenMesh's STL reader reports the vertex normals asked for
  // as read, uninitialised: `compare X.stl X.stl` found them different.
  if (lower_extension(path) != ".stl") {
    om.request_vertex_normals();
    opt += OpenMesh::IO::Options::VertexNormal;
  }
  const QuietOpenMesh quiet;
  CountingImporter importer(om);
  bool ok = false, read_past_end = false;
  if (declared.on_stream) {
    // On a stream of our own, whose state shows whether the reader wanted more than there was.
    // can_u_read parses the header into the reader's record of what the file holds (normals,
    // colours), as a read by name does first.
    OpenMesh::IO::BaseReader& reader = lower_extension(path) == ".off"
                                           ? static_cast<OpenMesh::IO::BaseReader&>(OpenMesh::IO::OFFReader())
                                           : OpenMesh::IO::PLYReader();
    std::ifstream in(path, std::ios::binary);
    ok = reader.can_u_read(path) && reader.read(in, importer, opt);
    read_past_end = in.fail();
  } else {
    ok = OpenMesh::IO::IOManager().read(path, importer, opt);
  }
  if (!ok && !read_past_end) throw Error(path + ": cannot read mesh");
  check_as_declared(path, declared, importer, om, read_past_end);
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
  compute_area_weighted_normals(out);
  return out;
}

}  // namespace mlfe
