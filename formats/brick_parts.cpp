// The encoding of a brick's parts; the layout is in brick_parts.h.
#include <mlfe/core/base/error.h>
#include <mlfe/formats/brick_parts.h>

#include <cstdint>
#include <cstring>
#include <type_traits>

namespace mlfe {

namespace {

constexpr char kMagic[8] = {'M', 'L', 'F', 'E', 'B', 'R', 'K', '3'};

// The arrays are copied with memcpy, as hierarchy_io.cpp's are; a big-endian host would swap.
static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "brick_parts assumes a little-endian host");
static_assert(sizeof(float) == 4 && sizeof(LatticePlace) == 16 && std::is_trivially_copyable_v<LatticePlace>);
struct Writer {
  std::string out;
  template <class T>
  void put(const T& v) {
    out.append(reinterpret_cast<const char*>(&v), sizeof v);
  }
  template <class T>
  void put_all(const std::vector<T>& v) {
    if (!v.empty()) out.append(reinterpret_cast<const char*>(v.data()), v.size() * sizeof(T));
  }
};

struct Reader {
  const std::string& in;
  std::size_t at = 0;
  void need(std::size_t n) const {
    if (n > in.size() - at) throw Error("brick parts: truncated");
  }
  template <class T>
  T get() {
    need(sizeof(T));
    T v;
    std::memcpy(&v, in.data() + at, sizeof v);
    at += sizeof v;
    return v;
  }
  template <class T>
  void get_all(std::vector<T>& v, std::size_t n) {
    if (n > (in.size() - at) / sizeof(T)) throw Error("brick parts: truncated");
    v.resize(n);
    if (n > 0) std::memcpy(v.data(), in.data() + at, n * sizeof(T));  // an empty vector's data() may be null
    at += n * sizeof(T);
  }
};

}  // namespace

std::string encode_brick_parts(const BrickParts& p) {
  Writer w;
  w.out.append(kMagic, sizeof kMagic);
  w.put(std::uint64_t(p.brick));
  w.put(std::uint64_t(p.first_slab));
  w.put(std::uint64_t(p.end_slab));
  w.put(p.lo);
  w.put(p.hi);
  w.put(std::uint32_t(p.surfaces.size()));
  for (const BrickPart& s : p.surfaces) {
    w.put(std::uint64_t(s.extracted_triangles));
    w.put(std::uint32_t(s.mesh.positions.size()));
    w.put(std::uint32_t(s.mesh.triangles.size()));
    w.put(std::uint8_t(!s.mesh.normals.empty()));
    w.put(std::uint32_t(s.points.size()));
    w.put(std::uint32_t(s.face_vertex.size()));
    w.put_all(s.mesh.positions);
    w.put_all(s.mesh.normals);
    w.put_all(s.mesh.triangles);
    w.put_all(s.face_vertex);
    w.put_all(s.face_place);
    w.put_all(s.points);
    w.put_all(s.point_face);
  }
  return std::move(w.out);
}

BrickParts decode_brick_parts(const std::string& bytes) {
  Reader r{bytes};
  r.need(sizeof kMagic);
  if (std::memcmp(bytes.data(), kMagic, sizeof kMagic) != 0)
    throw Error("brick parts: not an mlfe brick (magic)");
  r.at = sizeof kMagic;
  BrickParts p;
  p.brick = std::size_t(r.get<std::uint64_t>());
  p.first_slab = std::size_t(r.get<std::uint64_t>());
  p.end_slab = std::size_t(r.get<std::uint64_t>());
  if (p.end_slab < p.first_slab || (p.end_slab > p.first_slab && p.brick != 0) ||
      (p.end_slab == p.first_slab && p.first_slab != 0))
    throw Error("brick parts: a bad slab range");
  p.lo = r.get<float>();
  p.hi = r.get<float>();
  const std::uint32_t n = r.get<std::uint32_t>();
  for (std::uint32_t i = 0; i < n; ++i) {
    BrickPart s;
    s.extracted_triangles = std::size_t(r.get<std::uint64_t>());
    const std::uint32_t nv = r.get<std::uint32_t>(), nt = r.get<std::uint32_t>();
    const std::uint8_t normals = r.get<std::uint8_t>();
    const std::uint32_t np = r.get<std::uint32_t>(), nf = r.get<std::uint32_t>();
    // Only a surface with vertices has normals: the encoding is canonical (one per set of parts).
    if (normals > 1 || (normals == 1 && nv == 0)) throw Error("brick parts: bad normals flag");
    r.get_all(s.mesh.positions, nv);
    if (normals) r.get_all(s.mesh.normals, nv);
    r.get_all(s.mesh.triangles, nt);
    r.get_all(s.face_vertex, nf);
    r.get_all(s.face_place, nf);
    r.get_all(s.points, np);
    r.get_all(s.point_face, np);
    for (const auto& t : s.mesh.triangles)
      for (std::uint32_t v : t)
        if (v >= nv) throw Error("brick parts: a triangle index is out of range");
    for (std::uint32_t f : s.point_face)
      if (f >= nt) throw Error("brick parts: a point's face is out of range");
    for (std::uint32_t k = 0; k < nf; ++k)
      if (s.face_vertex[k] >= nv || (k > 0 && s.face_vertex[k] <= s.face_vertex[k - 1]))
        throw Error("brick parts: the face vertices are not ascending vertices");
    p.surfaces.push_back(std::move(s));
  }
  if (r.at != bytes.size()) throw Error("brick parts: trailing bytes");
  return p;
}

}  // namespace mlfe
