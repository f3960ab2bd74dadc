// P1 interpolation on a tetrahedral mesh with bucket-grid point location and the closest-point
// extension outside the mesh (see tet_mesh_field.h), the closest boundary face found through
// Eigen's KdBVH. The closest point on a triangle follows Ericson, "Real-Time Collision
// Detection" (2005), 5.1.5.
#include <mlfe/core/base/check.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/base/vec.h>
#include <mlfe/core/field/tet_mesh_field.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>
#include <unsupported/Eigen/BVH>

namespace mlfe {

namespace {

// Face f of a tetrahedron is the one opposite its vertex f.
constexpr int kFaces[4][3] = {{1, 2, 3}, {0, 2, 3}, {0, 1, 3}, {0, 1, 2}};

Vec3 closest_on_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 ab = sub(b, a), ac = sub(c, a), ap = sub(p, a);
  const double d1 = dot(ab, ap), d2 = dot(ac, ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const Vec3 bp = sub(p, b);
  const double d3 = dot(ab, bp), d4 = dot(ac, bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return axpy(a, d1 / (d1 - d3), ab);
  const Vec3 cp = sub(p, c);
  const double d5 = dot(ab, cp), d6 = dot(ac, cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return axpy(a, d2 / (d2 - d6), ac);
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0)
    return axpy(b, (d4 - d3) / ((d4 - d3) + (d5 - d6)), sub(c, b));
  const double denom = 1.0 / (va + vb + vc);
  const double v = vb * denom, w = vc * denom;
  return {a[0] + ab[0] * v + ac[0] * w, a[1] + ab[1] * v + ac[1] * w, a[2] + ab[2] * v + ac[2] * w};
}

// Barycentric coordinates 1..3 of x are inv's rows applied to x - p0; returns the smallest of
// all four.
template <class T>
double min_barycentric(const T& t, const Vec3& x) {
  const Vec3 d = sub(x, t.p0);
  const double l1 = t.inv[0] * d[0] + t.inv[1] * d[1] + t.inv[2] * d[2];
  const double l2 = t.inv[3] * d[0] + t.inv[4] * d[1] + t.inv[5] * d[2];
  const double l3 = t.inv[6] * d[0] + t.inv[7] * d[1] + t.inv[8] * d[2];
  return std::min({1.0 - l1 - l2 - l3, l1, l2, l3});
}

// Rounding on a shared face or at the boundary gives barycentric coordinates of about -1e-16;
// a point that close counts as inside (f is continuous, so either side gives the same value).
constexpr double kInsideTolerance = 1e-12;

}  // namespace

// Value ranges of the buckets over index boxes: level k holds blocks of 2^k cells per axis.
struct TetMeshField::RangePyramid {
  struct Level {
    std::array<std::int64_t, 3> n;
    std::vector<double> lo, hi;
  };
  std::vector<Level> levels;

  RangePyramid(const std::array<std::int64_t, 3>& n, std::vector<double> lo, std::vector<double> hi) {
    levels.push_back({n, std::move(lo), std::move(hi)});
    while (levels.back().n[0] > 1 || levels.back().n[1] > 1 || levels.back().n[2] > 1) {
      const Level& f = levels.back();
      Level c;
      for (int a = 0; a < 3; ++a) c.n[a] = (f.n[a] + 1) / 2;
      const std::size_t count = std::size_t(c.n[0] * c.n[1] * c.n[2]);
      c.lo.assign(count, std::numeric_limits<double>::infinity());
      c.hi.assign(count, -std::numeric_limits<double>::infinity());
      for (std::int64_t k = 0; k < f.n[2]; ++k)
        for (std::int64_t j = 0; j < f.n[1]; ++j)
          for (std::int64_t i = 0; i < f.n[0]; ++i) {
            const std::size_t s = std::size_t(i + f.n[0] * (j + f.n[1] * k));
            const std::size_t d = std::size_t(i / 2 + c.n[0] * (j / 2 + c.n[1] * (k / 2)));
            c.lo[d] = std::min(c.lo[d], f.lo[s]);
            c.hi[d] = std::max(c.hi[d], f.hi[s]);
          }
      levels.push_back(std::move(c));
    }
  }

  // Cells [i0, i1] inclusive (already clamped to the grid): the blocks of the finest level
  // where the box covers at most 512 of them, so small boxes get the buckets' own ranges.
  std::array<double, 2> range(const std::int64_t i0[3], const std::int64_t i1[3]) const {
    const auto blocks = [&](std::size_t k) {
      std::int64_t n = 1;
      for (int a = 0; a < 3; ++a) n *= (i1[a] >> k) - (i0[a] >> k) + 1;
      return n;
    };
    std::size_t k = 0;
    while (k + 1 < levels.size() && blocks(k) > 512) ++k;
    const Level& l = levels[k];
    double lo = std::numeric_limits<double>::infinity(), hi = -lo;
    for (std::int64_t z = i0[2] >> k; z <= (i1[2] >> k); ++z)
      for (std::int64_t y = i0[1] >> k; y <= (i1[1] >> k); ++y)
        for (std::int64_t x = i0[0] >> k; x <= (i1[0] >> k); ++x) {
          const std::size_t s = std::size_t(x + l.n[0] * (y + l.n[1] * z));
          lo = std::min(lo, l.lo[s]);
          hi = std::max(hi, l.hi[s]);
        }
    return {lo, hi};
  }
};

// The boundary faces' tree: objects are indices into boundary_.
struct TetMeshField::FaceTree : Eigen::KdBVH<double, 3, std::uint32_t> {
  using KdBVH::KdBVH;
};

// Eigen::BVMinimize's query: squared distance from x to the boxes and faces, keeping the
// nearest face (the lower tetrahedron index among equal distances). A box is reported a hair
// nearer than it is, so that BVMinimize (which enters only boxes strictly nearer than the best
// so far) also enters boxes at exactly the best distance: then the tie rule sees every face
// at that distance and the answer does not depend on the tree's order.
struct TetMeshField::ClosestFace {
  using Scalar = double;
  const TetMeshField& field;
  Vec3 x;
  double best_d2 = std::numeric_limits<double>::infinity();
  Hit best{0, {0, 0, 0}};

  double minimumOnVolume(const Eigen::AlignedBox3d& box) const {
    const double d2 = box.squaredExteriorDistance(Eigen::Vector3d(x[0], x[1], x[2]));
    return std::nextafter(d2, -std::numeric_limits<double>::infinity());
  }
  double minimumOnObject(std::uint32_t f) {
    const BoundaryFace& bf = field.boundary_[f];
    const auto& v = field.tets_[bf.tet].vertex;
    const int* k = kFaces[bf.face];
    const Vec3 q =
        closest_on_triangle(x, field.points_[v[k[0]]], field.points_[v[k[1]]], field.points_[v[k[2]]]);
    const Vec3 d = sub(q, x);
    const double d2 = dot(d, d);
    if (d2 < best_d2 || (d2 == best_d2 && bf.tet < best.tet)) {
      best_d2 = d2;
      best = {bf.tet, q};
    }
    return d2;
  }
};

namespace {

// Every point finite and within ±1e100 (beyond that, products of coordinate differences such as
// volumes and inverses overflow), every value finite.
void check_points(const TetMesh& mesh, const std::string& src) {
  const std::size_t np = mesh.points.size();
  for (std::size_t i = 0; i < np; ++i) {
    const auto& p = mesh.points[i];
    if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2]))
      throw Error(src + ": point " + std::to_string(i) + " has a coordinate that is not a finite number");
    if (std::max({std::abs(p[0]), std::abs(p[1]), std::abs(p[2])}) > 1e100)
      throw Error(src + ": point " + std::to_string(i) + " has a coordinate beyond ±1e100");
    if (!std::isfinite(mesh.values[i]))
      throw Error(src + ": the value at point " + std::to_string(i) + " is not a finite number");
  }
}

// Step 1 of the constructor: the tetrahedra of positive volume (relative to their longest edge,
// so the test does not depend on the mesh's unit) whose inverse and gradient are representable;
// `degenerate` counts the others. Throws when none is left.
std::vector<std::uint32_t> positive_volume_tets(const TetMesh& mesh, const std::string& src,
                                                std::size_t& degenerate) {
  const std::size_t np = mesh.points.size();
  std::vector<std::uint32_t> keep;
  keep.reserve(mesh.tets.size());
  for (std::size_t t = 0; t < mesh.tets.size(); ++t) {
    const auto& c = mesh.tets[t];
    for (std::int32_t v : c)
      if (v < 0 || std::size_t(v) >= np)
        throw Error(src + ": tetrahedron " + std::to_string(t) + " has point index " + std::to_string(v) +
                    " out of range (" + std::to_string(np) + " points)");
    const Vec3 d1 = sub(mesh.points[c[1]], mesh.points[c[0]]), d2 = sub(mesh.points[c[2]], mesh.points[c[0]]),
               d3 = sub(mesh.points[c[3]], mesh.points[c[0]]);
    double longest = std::max({dot(d1, d1), dot(d2, d2), dot(d3, d3)});
    for (const auto& [a, b] : {std::pair{1, 2}, std::pair{1, 3}, std::pair{2, 3}}) {
      const Vec3 e = sub(mesh.points[c[a]], mesh.points[c[b]]);
      longest = std::max(longest, dot(e, e));
    }
    const double det = dot(d1, cross(d2, d3));
    // The inverse and the gradient must be representable too (tiny tetrahedra, huge values).
    bool ok = longest > 0 && std::abs(det) > 1e-12 * longest * std::sqrt(longest);
    if (ok) {
      const Vec3 r[3] = {cross(d2, d3), cross(d3, d1), cross(d1, d2)};
      for (int k = 0; k < 3; ++k) {
        const double dv = mesh.values[c[k + 1]] - mesh.values[c[0]];
        for (int a = 0; a < 3; ++a) ok &= std::isfinite(r[k][a] / det) && std::isfinite(dv * (r[k][a] / det));
      }
    }
    if (ok)
      keep.push_back(std::uint32_t(t));
    else
      ++degenerate;
  }
  if (keep.empty())
    throw Error(src + ": no tetrahedron of positive volume (" + std::to_string(mesh.tets.size()) +
                " tetrahedra, all flat)");
  return keep;
}

// The faces of exactly one kept tetrahedron (index into `keep`, face opposite vertex k), in the
// order of their sorted vertices.
std::vector<std::pair<std::uint32_t, std::uint8_t>> boundary_faces(const TetMesh& mesh,
                                                                   const std::vector<std::uint32_t>& keep) {
  std::vector<std::pair<std::uint32_t, std::uint8_t>> faces;
  struct FaceKey {
    std::array<std::int32_t, 3> v;
    std::uint32_t tet;
    std::uint8_t face;
  };
  std::vector<FaceKey> keys;
  keys.reserve(keep.size() * 4);
  for (std::uint32_t t = 0; t < keep.size(); ++t)
    for (std::uint8_t f = 0; f < 4; ++f) {
      std::array<std::int32_t, 3> v{mesh.tets[keep[t]][kFaces[f][0]], mesh.tets[keep[t]][kFaces[f][1]],
                                    mesh.tets[keep[t]][kFaces[f][2]]};
      std::sort(v.begin(), v.end());
      keys.push_back({v, t, f});
    }
  std::sort(keys.begin(), keys.end(), [](const FaceKey& a, const FaceKey& b) {
    return a.v != b.v ? a.v < b.v : a.tet != b.tet ? a.tet < b.tet : a.face < b.face;
  });
  for (std::size_t i = 0; i < keys.size();) {
    std::size_t j = i + 1;
    while (j < keys.size() && keys[j].v == keys[i].v) ++j;
    if (j - i == 1) faces.emplace_back(keys[i].tet, keys[i].face);
    i = j;
  }
  return faces;
}

}  // namespace

TetMesh leaf_mesh(const Hierarchy<3>& h, const std::vector<double>& values) {
  MLFE_CHECK(values.size() == h.vertex_count());
  TetMesh m;
  m.points.reserve(h.vertex_count());
  for (std::size_t v = 0; v < h.vertex_count(); ++v) m.points.push_back(h.point(VertexId(std::uint32_t(v))));
  m.tets.reserve(h.leaves().size());
  for (ElemId e : h.leaves()) {
    const auto& c = h.cell(e);
    m.tets.push_back({std::int32_t(c[0].value), std::int32_t(c[1].value), std::int32_t(c[2].value),
                      std::int32_t(c[3].value)});
  }
  m.values = values;
  return m;
}

TetMeshField::~TetMeshField() = default;

TetMeshField::TetMeshField(const TetMesh& mesh) {
  const std::string& src = mesh.source.empty() ? std::string("tetrahedral mesh") : mesh.source;
  const std::size_t np = mesh.points.size();
  if (mesh.values.size() != np)
    throw Error(src + ": " + std::to_string(mesh.values.size()) + " point values for " + std::to_string(np) +
                " points");
  if (np > std::size_t(std::numeric_limits<std::int32_t>::max()) ||
      mesh.tets.size() >= std::size_t(std::numeric_limits<std::uint32_t>::max()))
    throw Error(src + ": too many points or tetrahedra");
  check_points(mesh, src);
  // Step 1: keep the tetrahedra of positive volume.
  const std::vector<std::uint32_t> keep = positive_volume_tets(mesh, src, degenerate_);

  // Step 2: the box of the kept tetrahedra, and the local frame.
  Vec3 lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
  for (std::uint32_t t : keep)
    for (std::int32_t v : mesh.tets[t])
      for (int a = 0; a < 3; ++a) {
        lo[a] = std::min(lo[a], mesh.points[v][a]);
        hi[a] = std::max(hi[a], mesh.points[v][a]);
      }
  origin_ = lo;
  for (int a = 0; a < 3; ++a) extent_[a] = hi[a] - lo[a];
  points_.resize(np);
  for (std::size_t i = 0; i < np; ++i) points_[i] = sub(mesh.points[i], origin_);

  tets_.reserve(keep.size());
  std::vector<double> edges, sizes;
  edges.reserve(keep.size() * 6);
  sizes.reserve(keep.size());
  range_ = {1e300, -1e300};
  for (std::uint32_t t : keep) {
    const auto& c = mesh.tets[t];
    Tet T;
    T.vertex = c;
    T.p0 = points_[c[0]];
    const Vec3 d1 = sub(points_[c[1]], T.p0), d2 = sub(points_[c[2]], T.p0), d3 = sub(points_[c[3]], T.p0);
    const double det = dot(d1, cross(d2, d3));
    const Vec3 r1 = cross(d2, d3), r2 = cross(d3, d1), r3 = cross(d1, d2);
    for (int a = 0; a < 3; ++a) {
      T.inv[a] = r1[a] / det;
      T.inv[3 + a] = r2[a] / det;
      T.inv[6 + a] = r3[a] / det;
    }
    const double v0 = mesh.values[c[0]];
    T.v0 = v0;
    for (int a = 0; a < 3; ++a)
      T.grad[a] = (mesh.values[c[1]] - v0) * T.inv[a] + (mesh.values[c[2]] - v0) * T.inv[3 + a] +
                  (mesh.values[c[3]] - v0) * T.inv[6 + a];
    tets_.push_back(T);
    for (int i = 0; i < 4; ++i) {
      range_[0] = std::min(range_[0], mesh.values[c[i]]);
      range_[1] = std::max(range_[1], mesh.values[c[i]]);
      for (int j = i + 1; j < 4; ++j) {
        const Vec3 e = sub(points_[c[i]], points_[c[j]]);
        edges.push_back(std::sqrt(dot(e, e)));
      }
    }
    sizes.push_back(std::cbrt(std::abs(det)));
  }
  const auto percentile10 = [](std::vector<double>& v) {
    auto it = v.begin() + std::ptrdiff_t(v.size() / 10);
    std::nth_element(v.begin(), it, v.end());
    return *it;
  };
  resolution_ = percentile10(edges);
  voxel_size_ = percentile10(sizes);
  if (!(extent_[0] * extent_[1] * extent_[2] > 0) || !(resolution_ > 0) || !(voxel_size_ > 0))
    throw Error(src + ": the mesh is flat (its bounding box has no volume)");
  if (!std::isfinite(extent_[0] * extent_[1] * extent_[2]))
    throw Error(src + ": the mesh's bounding box is too large for double precision");

  // Step 3: buckets of about two tetrahedra each (cubes as far as the box allows), at most
  // 2^22 of them.
  const double target = std::clamp(double(tets_.size()) / 2.0, 1.0, double(1 << 22));
  const double side = std::cbrt(extent_[0] * extent_[1] * extent_[2] / target);
  for (int a = 0; a < 3; ++a) {
    n_[a] = std::int64_t(std::clamp(std::ceil(extent_[a] / side), 1.0, double(1 << 12)));
    cell_size_[a] = extent_[a] / double(n_[a]);
    inv_cell_[a] = double(n_[a]) / extent_[a];
  }
  const std::size_t cells = std::size_t(n_[0] * n_[1] * n_[2]);
  std::vector<std::uint64_t> count(cells + 1, 0);
  const auto tet_cells = [&](const Tet& T, std::int64_t i0[3], std::int64_t i1[3]) {
    Vec3 tlo = points_[T.vertex[0]], thi = tlo;
    for (int i = 1; i < 4; ++i)
      for (int a = 0; a < 3; ++a) {
        tlo[a] = std::min(tlo[a], points_[T.vertex[i]][a]);
        thi[a] = std::max(thi[a], points_[T.vertex[i]][a]);
      }
    cell_of(tlo, i0);
    cell_of(thi, i1);
  };
  for (const Tet& T : tets_) {
    std::int64_t i0[3], i1[3];
    tet_cells(T, i0, i1);
    for (std::int64_t k = i0[2]; k <= i1[2]; ++k)
      for (std::int64_t j = i0[1]; j <= i1[1]; ++j)
        for (std::int64_t i = i0[0]; i <= i1[0]; ++i) ++count[std::size_t(i + n_[0] * (j + n_[1] * k)) + 1];
  }
  for (std::size_t c = 0; c < cells; ++c) count[c + 1] += count[c];
  if (count[cells] >= std::numeric_limits<std::uint32_t>::max())
    throw Error(src + ": the tetrahedra overlap too much for point location (bounding boxes cover " +
                std::to_string(count[cells]) + " buckets)");
  cell_start_.assign(count.begin(), count.end());
  cell_tets_.resize(cell_start_.back());
  std::vector<std::uint32_t> fill(cell_start_.begin(), cell_start_.end() - 1);
  for (std::uint32_t t = 0; t < tets_.size(); ++t) {
    std::int64_t i0[3], i1[3];
    tet_cells(tets_[t], i0, i1);
    for (std::int64_t k = i0[2]; k <= i1[2]; ++k)
      for (std::int64_t j = i0[1]; j <= i1[1]; ++j)
        for (std::int64_t i = i0[0]; i <= i1[0]; ++i)
          cell_tets_[fill[std::size_t(i + n_[0] * (j + n_[1] * k))]++] = t;
  }

  // Step 4: the boundary faces (faces of one kept tetrahedron only) in a bounding-volume tree
  // (Eigen's KdBVH). Outside the mesh the closest point of the mesh lies on one of them; a
  // nearest-face query in the tree costs O(log n) box tests, where growing rings of buckets
  // cost a whole ring of buckets per step (~1 ms a point deep in a cut corner of a 1 M-tet mesh).
  for (const auto& [t, f] : boundary_faces(mesh, keep)) boundary_.push_back({t, f});
  std::vector<std::uint32_t> ids(boundary_.size());
  std::vector<Eigen::AlignedBox3d> boxes(boundary_.size());
  for (std::uint32_t f = 0; f < boundary_.size(); ++f) {
    ids[f] = f;
    const auto& v = tets_[boundary_[f].tet].vertex;
    for (int i = 0; i < 3; ++i) {
      const Vec3& p = points_[v[kFaces[boundary_[f].face][i]]];
      boxes[f].extend(Eigen::Vector3d(p[0], p[1], p[2]));
    }
  }
  faces_ = std::make_unique<FaceTree>(ids.begin(), ids.end(), boxes.begin(), boxes.end());
}

std::int64_t TetMeshField::cell_of(const std::array<double, 3>& x, std::int64_t c[3]) const {
  for (int a = 0; a < 3; ++a) {
    const double s = x[a] * inv_cell_[a];
    c[a] = s <= 0 ? 0 : s >= double(n_[a] - 1) ? n_[a] - 1 : std::int64_t(s);
  }
  return c[0] + n_[0] * (c[1] + n_[1] * c[2]);
}

TetMeshField::Hit TetMeshField::locate(const std::array<double, 3>& x_in) const {
  Vec3 x;
  for (int a = 0; a < 3; ++a) x[a] = std::clamp(x_in[a], 0.0, extent_[a]);
  std::int64_t c[3];
  const std::size_t cell = std::size_t(cell_of(x, c));
  // Inside: the first tetrahedron of the bucket (index order) that contains x.
  double best_inside = -std::numeric_limits<double>::infinity();
  std::uint32_t best_tet = 0;
  for (std::uint32_t s = cell_start_[cell]; s < cell_start_[cell + 1]; ++s) {
    const std::uint32_t t = cell_tets_[s];
    const double m = min_barycentric(tets_[t], x);
    if (m >= 0) return {t, x};
    if (m > best_inside) {
      best_inside = m;
      best_tet = t;
    }
  }
  if (best_inside >= -kInsideTolerance) return {best_tet, x};
  // Outside: the closest point on the boundary faces, best-first through the tree. Among faces
  // at the same distance the lower tetrahedron index wins, whatever the order they are met in.
  ClosestFace query{*this, x};
  Eigen::BVMinimize(*faces_, query);
  const double best_d2 = query.best_d2;
  const Hit best = query.best;
  MLFE_CHECK(best_d2 < std::numeric_limits<double>::infinity());
  return best;
}

bool TetMeshField::inside(const std::array<double, 3>& x) const {
  const Hit h = locate(x);
  return h.at == x;
}

double TetMeshField::value(const std::array<double, 3>& x) const {
  const Hit h = locate(x);
  const Tet& T = tets_[h.tet];
  return T.v0 + dot(T.grad, sub(h.at, T.p0));
}

void TetMeshField::values(const std::array<double, 3>* x, double* out, std::size_t n) const {
  for (std::size_t j = 0; j < n; ++j) {
    const Hit h = locate(x[j]);
    const Tet& T = tets_[h.tet];
    out[j] = T.v0 + dot(T.grad, sub(h.at, T.p0));
  }
}

std::array<double, 3> TetMeshField::gradient(const std::array<double, 3>& x) const {
  return tets_[locate(x).tet].grad;
}

void TetMeshField::gradients(const std::array<double, 3>* x, std::array<double, 3>* out,
                             std::size_t n) const {
  for (std::size_t j = 0; j < n; ++j) out[j] = tets_[locate(x[j]).tet].grad;
}

void TetMeshField::build_ranges() const {
  const std::size_t cells = std::size_t(n_[0] * n_[1] * n_[2]);
  std::vector<double> lo(cells, std::numeric_limits<double>::infinity()), hi(cells, -lo[0]);
  for (std::size_t c = 0; c < cells; ++c)
    for (std::uint32_t s = cell_start_[c]; s < cell_start_[c + 1]; ++s) {
      const Tet& T = tets_[cell_tets_[s]];
      for (int i = 0; i < 4; ++i) {
        // Vertex values from the linear form, as value() computes them.
        const double v = T.v0 + dot(T.grad, sub(points_[T.vertex[i]], T.p0));
        lo[c] = std::min(lo[c], v);
        hi[c] = std::max(hi[c], v);
      }
    }
  const RangePyramid raw(n_, lo, hi);
  // A point x of cell c with centre m takes f at its closest point q of the mesh, and
  // |q - m| <= |q - x| + |x - m| <= dist(m, mesh) + 2 |x - m|: q lies in the ball of radius
  // dist(m, mesh) + diagonal around m, so the buckets over that ball bound f on the cell.
  const double diagonal = std::sqrt(dot(cell_size_, cell_size_));
  std::vector<double> elo(cells), ehi(cells);
  for (std::int64_t k = 0; k < n_[2]; ++k)
    for (std::int64_t j = 0; j < n_[1]; ++j)
      for (std::int64_t i = 0; i < n_[0]; ++i) {
        const Vec3 m{(double(i) + 0.5) * cell_size_[0], (double(j) + 0.5) * cell_size_[1],
                     (double(k) + 0.5) * cell_size_[2]};
        const Vec3 d = sub(locate(m).at, m);
        const double radius = std::sqrt(dot(d, d)) + diagonal;
        Vec3 blo, bhi;
        for (int a = 0; a < 3; ++a) {
          blo[a] = m[a] - radius;
          bhi[a] = m[a] + radius;
        }
        std::int64_t i0[3], i1[3];
        cell_of(blo, i0);
        cell_of(bhi, i1);
        const auto r = raw.range(i0, i1);
        const std::size_t c = std::size_t(i + n_[0] * (j + n_[1] * k));
        elo[c] = r[0];
        ehi[c] = r[1];
      }
  ranges_ = std::make_unique<RangePyramid>(n_, std::move(elo), std::move(ehi));
}

std::array<double, 2> TetMeshField::range_in_box(const std::array<double, 3>& lo,
                                                 const std::array<double, 3>& hi) const {
  std::call_once(ranges_once_, [&] { build_ranges(); });
  std::int64_t i0[3], i1[3];
  cell_of(lo, i0);
  cell_of(hi, i1);
  for (int a = 0; a < 3; ++a) i1[a] = std::max(i1[a], i0[a]);
  // value() rounds differently from the vertex values the buckets hold: widen by that much.
  const auto r = ranges_->range(i0, i1);
  const double slack = 1e-12 * std::max({1.0, std::abs(range_[0]), std::abs(range_[1])});
  return {r[0] - slack, r[1] + slack};
}

}  // namespace mlfe
