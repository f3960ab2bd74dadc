// Multi-material marching tetrahedra on the Kuhn triangulation of a label lattice (interfaces
// through edge midpoints and face and tetrahedron centroids, as in the multi-material
// extensions of marching tetrahedra: Bloomenthal & Ferguson 1995, "Polygonization of
// non-manifold implicit surfaces"; Wu & Sullivan 2003, "Multiple material marching cubes") and
// Taubin's λ|μ smoothing (SIGGRAPH 1995) restricted to the interface complex; its simplification
// is core/simplify's (complex_decimator.h). See label_surface.h for the contracts and why the
// partition is the right one for categories.
#include <mlfe/core/base/check.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/base/vec.h>
#include <mlfe/core/labels/label_surface.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <string>
#include <unordered_map>

namespace mlfe {

namespace {

// The 6 axis orders of the Kuhn tetrahedra; corner s of tetrahedron `order` is the cube corner
// whose offset bits are kCorner[order][s] (bit a: +1 along axis a).
constexpr std::uint8_t kCorner[6][4] = {{0, 1, 3, 7}, {0, 1, 5, 7}, {0, 2, 3, 7},
                                        {0, 2, 6, 7}, {0, 4, 5, 7}, {0, 4, 6, 7}};

std::string voxel_text(std::int64_t i, std::int64_t j, std::int64_t k) {
  return "(" + std::to_string(i) + ", " + std::to_string(j) + ", " + std::to_string(k) + ")";
}

struct UnionFind {
  std::vector<std::uint32_t> parent;
  explicit UnionFind(std::size_t n) : parent(n) { std::iota(parent.begin(), parent.end(), 0u); }
  std::uint32_t find(std::uint32_t v) {
    while (parent[v] != v) v = parent[v] = parent[parent[v]];
    return v;
  }
  void unite(std::uint32_t a, std::uint32_t b) {
    a = find(a), b = find(b);
    if (a != b) parent[std::max(a, b)] = std::min(a, b);
  }
};

std::uint64_t edge_key(std::uint32_t a, std::uint32_t b) {
  return a < b ? (std::uint64_t(a) << 32) | b : (std::uint64_t(b) << 32) | a;
}

// Net oriented-edge counts of a triangle set, nonzero entries sorted by edge: the boundary of
// the set as a 1-chain (empty for a closed, consistently oriented surface).
std::vector<std::pair<std::uint64_t, int>> boundary_chain(
    const std::vector<std::array<std::uint32_t, 3>>& tris) {
  std::vector<std::pair<std::uint64_t, int>> e;
  e.reserve(tris.size() * 3);
  for (const auto& t : tris)
    for (int c = 0; c < 3; ++c) {
      const std::uint32_t a = t[c], b = t[(c + 1) % 3];
      e.emplace_back(edge_key(a, b), a < b ? 1 : -1);
    }
  std::sort(e.begin(), e.end());
  std::vector<std::pair<std::uint64_t, int>> out;
  for (std::size_t i = 0; i < e.size();) {
    std::size_t j = i;
    int net = 0;
    for (; j < e.size() && e[j].first == e[i].first; ++j) net += e[j].second;
    if (net != 0) out.emplace_back(e[i].first, net);
    i = j;
  }
  return out;
}

std::size_t pieces(const std::vector<std::array<std::uint32_t, 3>>& tris, std::size_t vertex_count) {
  UnionFind uf(vertex_count);
  std::vector<char> used(vertex_count, 0);
  for (const auto& t : tris) {
    uf.unite(t[0], t[1]);
    uf.unite(t[1], t[2]);
    used[t[0]] = used[t[1]] = used[t[2]] = 1;
  }
  std::size_t n = 0;
  for (std::uint32_t v = 0; v < vertex_count; ++v) n += used[v] && uf.find(v) == v;
  return n;
}

// Point numbers by lattice key (never 0), open addressing: the extraction looks a key up for
// every corner pair of every mixed tetrahedron, and a node per key costs more than the rest.
class PointIds {
 public:
  // The number stored for `key`, or make()'s, stored, when there is none.
  template <class Make>
  std::uint32_t get(std::uint64_t key, Make make) {
    std::size_t i = slot(key);
    if (keys_[i] == key) return ids_[i];
    const std::uint32_t id = make();
    keys_[i] = key, ids_[i] = id;
    if (++size_ * 2 > keys_.size()) grow();
    return id;
  }

 private:
  std::size_t slot(std::uint64_t key) const {
    const std::size_t mask = keys_.size() - 1;
    std::size_t i = std::size_t((key * 0x9E3779B97F4A7C15ull) >> 20) & mask;
    while (keys_[i] != 0 && keys_[i] != key) i = (i + 1) & mask;
    return i;
  }
  void grow() {
    std::vector<std::uint64_t> keys(keys_.size() * 2, 0);
    std::vector<std::uint32_t> ids(keys.size());
    keys.swap(keys_), ids.swap(ids_);
    for (std::size_t i = 0; i < keys.size(); ++i)
      if (keys[i] != 0) {
        const std::size_t j = slot(keys[i]);
        keys_[j] = keys[i], ids_[j] = ids[i];
      }
  }
  std::vector<std::uint64_t> keys_ = std::vector<std::uint64_t>(1 << 12, 0);
  std::vector<std::uint32_t> ids_ = std::vector<std::uint32_t>(1 << 12);
  std::size_t size_ = 0;
};

// How many labels a tetrahedron's four corners carry: its case in the extraction (and in the
// count of what extraction makes).
int distinct_labels(const std::uint16_t l[4]) {
  int distinct = 1;
  for (int s = 1; s < 4; ++s) {
    bool seen = false;
    for (int r = 0; r < s; ++r) seen |= l[r] == l[s];
    distinct += !seen;
  }
  return distinct;
}

// Builds the interface complex tetrahedron by tetrahedron. Interface vertices are keyed by the
// lattice element they lie in (edge: lower corner and offset bits; face: lowest corner and the
// bits of the other two), so neighbouring tetrahedra find the same vertex.
class Extractor {
 public:
  explicit Extractor(const LabelGrid& g) : g_(g), sx_(g.dims[0] + 2), sy_(g.dims[1] + 2) {}

  void tet(const KuhnTet& t) {
    // Step 1: the corners, their labels and lattice keys.
    for (int s = 0; s < 4; ++s) {
      const std::uint8_t b = kCorner[t.order][s];
      bits_[s] = b;
      x_[s] = {double(t.i + (b & 1)), double(t.j + ((b >> 1) & 1)), double(t.k + ((b >> 2) & 1))};
      label_[s] = g_.at(t.i + (b & 1), t.j + ((b >> 1) & 1), t.k + ((b >> 2) & 1));
      key_[s] = std::uint64_t((t.i + (b & 1) + 1) +
                              sx_ * ((t.j + ((b >> 1) & 1) + 1) + sy_ * (t.k + ((b >> 2) & 1) + 1)));
    }
    const int distinct = distinct_labels(label_);
    if (distinct == 1) return;
    // Step 2: two labels: the dual cells of each label merge into one planar piece, a triangle
    // cutting off one corner or a quad between two pairs (plain marching tetrahedra).
    if (distinct == 2) {
      int same[4], n_same = 0, other[4], n_other = 0;
      for (int s = 0; s < 4; ++s) (label_[s] == label_[0] ? same[n_same++] : other[n_other++]) = s;
      if (n_same == 2) {
        const int i = same[0], j = same[1], k = other[0], l = other[1];
        const std::uint32_t ik = mid(i, k), il = mid(i, l), jl = mid(j, l), jk = mid(j, k);
        emit(ik, il, jl, i, k);
        emit(ik, jl, jk, i, k);
      } else {
        const int u = n_same == 1 ? same[0] : other[0];
        int v[3], n = 0;
        for (int s = 0; s < 4; ++s)
          if (s != u) v[n++] = s;
        emit(mid(u, v[0]), mid(u, v[1]), mid(u, v[2]), u, v[0]);
      }
      return;
    }
    // Step 3: three or four labels: the interface graph on the faces (a segment across each
    // two-label face, three spokes to the centroid of each three-label face) is fanned to the
    // tetrahedron's centroid, where the junction curves of the labels meet.
    const std::uint32_t centre = add_point(
        {(x_[0][0] + x_[1][0] + x_[2][0] + x_[3][0]) / 4, (x_[0][1] + x_[1][1] + x_[2][1] + x_[3][1]) / 4,
         (x_[0][2] + x_[1][2] + x_[2][2] + x_[3][2]) / 4},
        0);
    for (int omit = 3; omit >= 0; --omit) {
      int f[3], n = 0;
      for (int s = 0; s < 4; ++s)
        if (s != omit) f[n++] = s;
      const bool e01 = label_[f[0]] != label_[f[1]], e02 = label_[f[0]] != label_[f[2]],
                 e12 = label_[f[1]] != label_[f[2]];
      const int mixed = e01 + e02 + e12;
      if (mixed == 0) continue;
      if (mixed == 2) {
        // The odd corner is on both mixed edges.
        const int o = !e12 ? f[0] : !e02 ? f[1] : f[2];
        const int a = o == f[0] ? f[1] : f[0], b = o == f[2] ? f[1] : f[2];
        emit(mid(o, a), mid(o, b), centre, o, a);
      } else {
        const std::uint32_t fc = face_point(f[0], f[1], f[2]);
        emit(mid(f[0], f[1]), fc, centre, f[0], f[1]);
        emit(mid(f[0], f[2]), fc, centre, f[0], f[2]);
        emit(mid(f[1], f[2]), fc, centre, f[1], f[2]);
      }
    }
  }

  // The complex of the tetrahedra given, and per point its lattice key (edge keys even, face
  // keys odd, 0 for tetrahedron centroids).
  struct Piece {
    LabelInterfaces x;
    std::vector<std::uint64_t> keys;
  };
  Piece take() { return {std::move(out_), std::move(keys_of_)}; }

 private:
  std::uint32_t add_point(const Vec3& p, std::uint64_t key) {
    MLFE_CHECK(out_.positions.size() < 0xffffffffu);
    out_.positions.push_back(p);
    keys_of_.push_back(key);
    return static_cast<std::uint32_t>(out_.positions.size() - 1);
  }

  // The midpoint of corners s and t (s < t in the tetrahedron's path order, so bits_[s] is a
  // subset of bits_[t]).
  std::uint32_t mid(int s, int t) {
    if (s > t) std::swap(s, t);
    const std::uint64_t key = key_[s] * 8 + (bits_[s] ^ bits_[t]);
    return edges_.get(key, [&] {
      return add_point({(x_[s][0] + x_[t][0]) / 2, (x_[s][1] + x_[t][1]) / 2, (x_[s][2] + x_[t][2]) / 2},
                       key * 2);
    });
  }

  // The centroid of the face with corners r < s < t.
  std::uint32_t face_point(int r, int s, int t) {
    const std::uint64_t key = key_[r] * 64 + (bits_[s] ^ bits_[r]) * 8 + (bits_[t] ^ bits_[r]);
    return faces_.get(key, [&] {
      return add_point({(x_[r][0] + x_[s][0] + x_[t][0]) / 3, (x_[r][1] + x_[s][1] + x_[t][1]) / 3,
                        (x_[r][2] + x_[s][2] + x_[t][2]) / 3},
                       key * 2 + 1);
    });
  }

  // A triangle separating the cells of corners s and t (which carry different labels): oriented
  // so its normal points from the lower label's corner to the higher's. The two corners are on
  // strictly opposite sides of every triangle made here (each lies in a plane through the
  // edge's midpoint that the edge crosses), so the sign test is exact.
  void emit(std::uint32_t p, std::uint32_t q, std::uint32_t r, int s, int t) {
    if (label_[s] > label_[t]) std::swap(s, t);
    const auto& P = out_.positions;
    const Vec3 n = cross(sub(P[q], P[p]), sub(P[r], P[p]));
    if (dot(n, sub(x_[t], x_[s])) < 0) std::swap(q, r);
    out_.triangles.push_back({p, q, r});
    out_.labels.push_back({label_[s], label_[t]});
  }

  const LabelGrid& g_;
  const std::int64_t sx_, sy_;
  std::uint8_t bits_[4]{};
  Vec3 x_[4]{};
  std::uint16_t label_[4]{};
  std::uint64_t key_[4]{};
  PointIds edges_, faces_;
  LabelInterfaces out_;
  std::vector<std::uint64_t> keys_of_;
};

// Per vertex its triangles, in triangle order (compressed rows).
struct VertexTriangles {
  std::vector<std::uint32_t> start, tris;
  explicit VertexTriangles(const LabelInterfaces& x) : start(x.positions.size() + 1, 0) {
    for (const auto& t : x.triangles)
      for (auto v : t) ++start[v + 1];
    for (std::size_t v = 0; v + 1 < start.size(); ++v) start[v + 1] += start[v];
    tris.resize(start.back());
    std::vector<std::uint32_t> fill(start.begin(), start.end() - 1);
    for (std::uint32_t t = 0; t < x.triangles.size(); ++t)
      for (auto v : x.triangles[t]) tris[fill[v]++] = t;
  }
};

// The neighbours of v, ascending, each marked when the edge to it lies on a junction curve:
// where its triangles are not exactly two of the same interface (three or more labels meet).
// `around` is scratch.
void classified_neighbours(const LabelInterfaces& x, const VertexTriangles& vt, std::uint32_t v,
                           std::vector<std::pair<std::uint32_t, std::uint32_t>>& around,
                           std::vector<std::pair<std::uint32_t, bool>>& out) {
  around.clear();
  for (std::uint32_t n = vt.start[v]; n < vt.start[v + 1]; ++n) {
    const std::uint32_t t = vt.tris[n];
    for (auto w : x.triangles[t])
      if (w != v) around.emplace_back(w, std::uint32_t(x.labels[t][0]) << 16 | x.labels[t][1]);
  }
  std::sort(around.begin(), around.end());
  out.clear();
  for (std::size_t i = 0; i < around.size();) {
    std::size_t j = i;
    bool same = true;
    for (; j < around.size() && around[j].first == around[i].first; ++j)
      same &= around[j].second == around[i].second;
    out.emplace_back(around[i].first, !(same && j - i == 2));
    i = j;
  }
}

}  // namespace

LabelGrid label_grid(const ScalarGrid& grid) {
  if (grid.dim != 3 || grid.dims[2] < 1) throw Error(grid.source + ": label maps need a 3D volume");
  LabelGrid g;
  g.dims = grid.dims;
  g.transform = grid.transform;
  g.labels.resize(grid.values.size());
  for (std::size_t n = 0; n < grid.values.size(); ++n) {
    const float v = grid.values[n];
    if (!(v >= 0 && v <= 65535 && v == std::floor(v))) {
      const std::int64_t i = std::int64_t(n) % grid.dims[0],
                         j = std::int64_t(n) / grid.dims[0] % grid.dims[1],
                         k = std::int64_t(n) / grid.dims[0] / grid.dims[1];
      const std::string what =
          !std::isfinite(v) || v != std::floor(v) ? "labels must be integers" : "labels must be 0..65535";
      throw Error(grid.source + ": " + what + ", but voxel " + voxel_text(i, j, k) + " holds " +
                  std::to_string(v));
    }
    g.labels[n] = static_cast<std::uint16_t>(v);
  }
  return g;
}

std::map<std::uint16_t, std::size_t> label_counts(const LabelGrid& g) {
  std::vector<std::size_t> count(65536, 0);
  for (auto l : g.labels) ++count[l];
  std::map<std::uint16_t, std::size_t> out;
  for (std::size_t l = 0; l < count.size(); ++l)
    if (count[l]) out.emplace(static_cast<std::uint16_t>(l), count[l]);
  return out;
}

void keep_labels(LabelGrid& g, const std::vector<std::uint16_t>& keep) {
  std::vector<char> kept(65536, 0);
  for (auto l : keep) kept[l] = 1;
  for (auto& l : g.labels)
    if (!kept[l]) l = 0;
}

ComponentRemoval remove_small_components(LabelGrid& g, std::size_t min_voxels) {
  ComponentRemoval result;
  if (min_voxels <= 1) return result;
  const std::int64_t nx = g.dims[0], ny = g.dims[1], nz = g.dims[2];
  std::vector<char> seen(g.labels.size(), 0);
  std::vector<std::size_t> piece, stack;
  for (std::size_t start = 0; start < g.labels.size(); ++start) {
    if (seen[start] || g.labels[start] == 0) continue;
    // Step 1: the 6-connected piece of the start voxel's label.
    const std::uint16_t label = g.labels[start];
    piece.clear();
    stack.assign(1, start);
    seen[start] = 1;
    std::map<std::uint16_t, std::size_t> around;
    while (!stack.empty()) {
      const std::size_t v = stack.back();
      stack.pop_back();
      piece.push_back(v);
      const std::int64_t i = std::int64_t(v) % nx, j = std::int64_t(v) / nx % ny,
                         k = std::int64_t(v) / nx / ny;
      const std::int64_t nb[6][3] = {{i - 1, j, k}, {i + 1, j, k}, {i, j - 1, k},
                                     {i, j + 1, k}, {i, j, k - 1}, {i, j, k + 1}};
      for (const auto& p : nb) {
        if (p[0] < 0 || p[1] < 0 || p[2] < 0 || p[0] >= nx || p[1] >= ny || p[2] >= nz) {
          ++around[0];
          continue;
        }
        const std::size_t w = std::size_t(p[0] + nx * (p[1] + ny * p[2]));
        if (g.labels[w] != label) {
          ++around[g.labels[w]];
        } else if (!seen[w]) {
          seen[w] = 1;
          stack.push_back(w);
        }
      }
    }
    if (piece.size() >= min_voxels) continue;
    // Step 2: a small piece takes the label most of its outside neighbours carry.
    std::uint16_t best = 0;
    std::size_t best_count = 0;
    for (const auto& [l, c] : around)
      if (c > best_count) best = l, best_count = c;
    for (std::size_t v : piece) g.labels[v] = best;
    ++result.removed[label];
    result.voxels += piece.size();
  }
  return result;
}

namespace {

// Visits every Kuhn tetrahedron of z layer k of cubes (-1 .. nz-1: the padded lattice) whose
// corners carry more than one label, in lattice order, as visit(i, j, order, corner labels c[8]
// of its cube, corner b at offset bits (b & 1, b >> 1 & 1, b >> 2 & 1)).
template <class Visit>
void scan_mixed_layer(const LabelGrid& g, std::int64_t k, Visit&& visit) {
  const std::int64_t nx = g.dims[0], ny = g.dims[1], nz = g.dims[2];
  for (std::int64_t j = -1; j < ny; ++j) {
    // The four rows of voxels along i around this row of cubes (r = dj + 2 dk; null outside
    // the lattice), read a column (the four labels at one i) at a time.
    const std::uint16_t* row[4];
    for (int r = 0; r < 4; ++r) {
      const std::int64_t jj = j + (r & 1), kk = k + (r >> 1);
      row[r] = jj >= 0 && jj < ny && kk >= 0 && kk < nz
                   ? g.labels.data() + static_cast<std::size_t>(nx * (jj + ny * kk))
                   : nullptr;
    }
    std::uint16_t column[2][4];
    auto read_column = [&](std::int64_t i, std::uint16_t* c) {
      for (int r = 0; r < 4; ++r) c[r] = row[r] && i >= 0 && i < nx ? row[r][i] : 0;
    };
    read_column(-1, column[1]);
    for (std::int64_t i = -1; i < nx; ++i) {
      std::copy(column[1], column[1] + 4, column[0]);
      read_column(i + 1, column[1]);
      std::uint16_t c[8];
      bool uniform = true;
      for (int b = 0; b < 8; ++b) {
        c[b] = column[b & 1][b >> 1];
        uniform &= c[b] == c[0];
      }
      if (uniform) continue;
      for (std::uint8_t o = 0; o < 6; ++o) {
        const std::uint16_t l0 = c[kCorner[o][0]];
        if (c[kCorner[o][1]] != l0 || c[kCorner[o][2]] != l0 || c[kCorner[o][3]] != l0) visit(i, j, o, c);
      }
    }
  }
}

// The triangles Extractor::tet emits for a tetrahedron with these corner labels.
std::size_t tet_triangles(const std::uint16_t l[4]) {
  const int distinct = distinct_labels(l);
  if (distinct == 1) return 0;
  if (distinct == 2) {
    int same = 0;
    for (int s = 0; s < 4; ++s) same += l[s] == l[0];
    return same == 2 ? 2 : 1;
  }
  std::size_t n = 0;
  for (int omit = 0; omit < 4; ++omit) {
    int f[3], m = 0;
    for (int s = 0; s < 4; ++s)
      if (s != omit) f[m++] = s;
    const int mixed = (l[f[0]] != l[f[1]]) + (l[f[0]] != l[f[2]]) + (l[f[1]] != l[f[2]]);
    n += mixed == 2 ? 1 : mixed == 3 ? 3 : 0;
  }
  return n;
}

}  // namespace

std::vector<KuhnTet> mixed_kuhn_tets(const LabelGrid& g) {
  // One list per z layer of cubes (from -1: the padding), concatenated in order.
  std::vector<std::vector<KuhnTet>> layers(std::size_t(g.dims[2] + 1));
  tbb::parallel_for(std::int64_t(-1), g.dims[2], [&](std::int64_t k) {
    auto& out = layers[std::size_t(k + 1)];
    scan_mixed_layer(g, k, [&](std::int64_t i, std::int64_t j, std::uint8_t o, const std::uint16_t*) {
      out.push_back({std::int32_t(i), std::int32_t(j), std::int32_t(k), o});
    });
  });
  std::size_t total = 0;
  for (const auto& l : layers) total += l.size();
  std::vector<KuhnTet> all;
  all.reserve(total);
  for (const auto& l : layers) all.insert(all.end(), l.begin(), l.end());
  return all;
}

InterfaceCount count_label_interfaces(const LabelGrid& g) {
  std::vector<InterfaceCount> layers(std::size_t(g.dims[2] + 1));
  tbb::parallel_for(std::int64_t(-1), g.dims[2], [&](std::int64_t k) {
    auto& out = layers[std::size_t(k + 1)];
    scan_mixed_layer(g, k, [&](std::int64_t, std::int64_t, std::uint8_t o, const std::uint16_t* c) {
      const std::uint16_t l[4] = {c[kCorner[o][0]], c[kCorner[o][1]], c[kCorner[o][2]], c[kCorner[o][3]]};
      ++out.tetrahedra;
      out.triangles += tet_triangles(l);
    });
  });
  InterfaceCount total;
  for (const auto& l : layers) total.tetrahedra += l.tetrahedra, total.triangles += l.triangles;
  return total;
}

LabelInterfaces extract_label_interfaces(const LabelGrid& g, const std::vector<KuhnTet>& tets) {
  for (const auto& t : tets)
    MLFE_CHECK(t.order < 6 && t.i >= -1 && t.j >= -1 && t.k >= -1 && t.i < g.dims[0] && t.j < g.dims[1] &&
               t.k < g.dims[2]);
  // Step 1: runs of whole z layers (when the tetrahedra come in layer order) extracted apart,
  // in parallel. Two runs share only the points in the plane between them.
  std::vector<std::size_t> cut{0};
  if (std::is_sorted(tets.begin(), tets.end(),
                     [](const KuhnTet& a, const KuhnTet& b) { return a.k < b.k; })) {
    const std::size_t run = std::max<std::size_t>(tets.size() / 16, 1);
    for (std::size_t n = 1; n < tets.size(); ++n)
      if (tets[n].k != tets[n - 1].k && n - cut.back() >= run) cut.push_back(n);
  }
  cut.push_back(tets.size());
  std::vector<Extractor::Piece> pieces(cut.size() - 1);
  tbb::parallel_for(std::size_t(0), pieces.size(), [&](std::size_t c) {
    Extractor x(g);
    for (std::size_t n = cut[c]; n < cut[c + 1]; ++n) x.tet(tets[n]);
    pieces[c] = x.take();
  });
  // Step 2: joined in order. A run's point already made by the run below (in the plane
  // between them, found by key) keeps that number; the others are numbered in the order they
  // were made, so the numbering is the one a single pass over all tetrahedra gives.
  LabelInterfaces out;
  std::size_t points = 0, triangles = 0;
  for (const auto& piece : pieces) points += piece.x.positions.size(), triangles += piece.x.triangles.size();
  out.positions.reserve(points);  // at most: the runs share the points between them
  out.triangles.reserve(triangles);
  out.labels.reserve(triangles);
  PointIds below;  // the previous run's points in its top plane
  for (std::size_t c = 0; c < pieces.size(); ++c) {
    Extractor::Piece& piece = pieces[c];
    const double bottom = cut[c] < tets.size() ? double(tets[cut[c]].k) : 0,
                 top = cut[c + 1] > cut[c] ? double(tets[cut[c + 1] - 1].k + 1) : 0;
    const bool shares_below = c > 0, shares_above = c + 1 < pieces.size();
    PointIds above;
    std::vector<std::uint32_t> id(piece.x.positions.size());
    for (std::size_t i = 0; i < id.size(); ++i) {
      const Vec3& p = piece.x.positions[i];
      auto add = [&] {
        MLFE_CHECK(out.positions.size() < 0xffffffffu);
        out.positions.push_back(p);
        return std::uint32_t(out.positions.size() - 1);
      };
      id[i] = shares_below && p[2] == bottom ? below.get(piece.keys[i], add) : add();
      if (shares_above && p[2] == top) above.get(piece.keys[i], [&] { return id[i]; });
    }
    below = std::move(above);
    for (const auto& t : piece.x.triangles) out.triangles.push_back({id[t[0]], id[t[1]], id[t[2]]});
    out.labels.insert(out.labels.end(), piece.x.labels.begin(), piece.x.labels.end());
    piece = {};
  }
  return out;
}

void smooth_label_interfaces(LabelInterfaces& x, const LabelSmoothingOptions& o) {
  if (o.iterations <= 0 || x.triangles.empty()) return;
  const std::size_t nv = x.positions.size();
  // Step 1: each vertex's smoothing neighbours, ascending: all of them inside an interface,
  // the two along its curve on a junction (the edges to them on junction curves), none where
  // curves meet. Counted, then listed, vertex by vertex in parallel.
  const VertexTriangles vt(x);
  std::vector<std::uint32_t> start(nv + 1, 0), nbr;
  auto each_followed = [&](auto&& visit) {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nv, 4096),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        std::vector<std::pair<std::uint32_t, std::uint32_t>> around;
                        std::vector<std::pair<std::uint32_t, bool>> nb;
                        for (std::size_t v = r.begin(); v != r.end(); ++v) {
                          classified_neighbours(x, vt, std::uint32_t(v), around, nb);
                          std::size_t junction_degree = 0;
                          for (const auto& [w, junction] : nb) junction_degree += junction;
                          if (junction_degree != 0 && junction_degree != 2) continue;
                          for (const auto& [w, junction] : nb)
                            if (junction_degree == 0 || junction) visit(v, w);
                        }
                      });
  };
  each_followed([&](std::size_t v, std::uint32_t) { ++start[v + 1]; });
  for (std::size_t v = 0; v < nv; ++v) start[v + 1] += start[v];
  nbr.resize(start[nv]);
  {
    std::vector<std::uint32_t> fill(start.begin(), start.end() - 1);
    each_followed([&](std::size_t v, std::uint32_t w) { nbr[fill[v]++] = w; });
  }
  // Step 3: Taubin's λ|μ passes (Jacobi), each move clamped to the offset bound.
  const std::vector<Vec3> original = x.positions;
  std::vector<Vec3> next(nv);
  const double bound2 = o.max_offset * o.max_offset;
  for (int it = 0; it < 2 * o.iterations; ++it) {
    const double f = it % 2 == 0 ? o.lambda : o.mu;
    const auto& cur = x.positions;
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nv, 4096),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        for (std::size_t v = r.begin(); v != r.end(); ++v) {
                          const std::uint32_t b = start[v], e = start[v + 1];
                          if (b == e) {
                            next[v] = cur[v];
                            continue;
                          }
                          Vec3 avg{0, 0, 0};
                          for (std::uint32_t n = b; n < e; ++n)
                            for (int c = 0; c < 3; ++c) avg[c] += cur[nbr[n]][c];
                          Vec3 p;
                          for (int c = 0; c < 3; ++c)
                            p[c] = cur[v][c] + f * (avg[c] / double(e - b) - cur[v][c]);
                          const Vec3 d = sub(p, original[v]);
                          const double d2 = dot(d, d);
                          if (d2 > bound2) {
                            const double s = o.max_offset / std::sqrt(d2);
                            for (int c = 0; c < 3; ++c) p[c] = original[v][c] + s * d[c];
                          }
                          next[v] = p;
                        }
                      });
    x.positions.swap(next);
  }
}

TriangleMesh label_surface(const LabelInterfaces& x, std::uint16_t label, const GridTransform& tr) {
  const auto& d = tr.direction;
  const double det = (d[0] * (d[4] * d[8] - d[5] * d[7]) - d[1] * (d[3] * d[8] - d[5] * d[6]) +
                      d[2] * (d[3] * d[7] - d[4] * d[6])) *
                     tr.spacing[0] * tr.spacing[1] * tr.spacing[2];
  const bool mirrored = det < 0;
  TriangleMesh m;
  std::unordered_map<std::uint32_t, std::uint32_t> slot;
  auto vertex = [&](std::uint32_t v) {
    auto [it, added] = slot.try_emplace(v, std::uint32_t(m.positions.size()));
    if (added) {
      const auto& p = x.positions[v];
      const auto q = tr.index_to_physical(p[0], p[1], p[2]);
      m.positions.push_back({float(q[0]), float(q[1]), float(q[2])});
    }
    return it->second;
  };
  for (std::size_t t = 0; t < x.triangles.size(); ++t) {
    const bool inside = x.labels[t][0] == label, outside = x.labels[t][1] == label;
    if (!inside && !outside) continue;
    const auto& tri = x.triangles[t];
    // Stored normals point out of the lower label; the higher one takes the triangle reversed.
    const bool reverse = outside != mirrored;
    const std::uint32_t a = vertex(tri[0]), b = vertex(reverse ? tri[2] : tri[1]),
                        c = vertex(reverse ? tri[1] : tri[2]);
    m.triangles.push_back({a, b, c});
  }
  return m;
}

std::vector<std::uint16_t> labels_with_surfaces(const LabelInterfaces& x) {
  std::vector<char> has(65536, 0);
  for (const auto& l : x.labels) has[l[0]] = has[l[1]] = 1;
  std::vector<std::uint16_t> out;
  for (std::size_t l = 1; l < has.size(); ++l)
    if (has[l]) out.push_back(static_cast<std::uint16_t>(l));
  return out;
}

std::size_t unmatched_edges(const TriangleMesh& mesh) {
  std::size_t n = 0;
  for (const auto& [e, net] : boundary_chain(mesh.triangles)) n += std::size_t(std::abs(net));
  return n;
}

std::size_t connected_pieces(const TriangleMesh& mesh) {
  return pieces(mesh.triangles, mesh.positions.size());
}

}  // namespace mlfe
