// Multi-material marching tetrahedra on the Kuhn triangulation of a label lattice (interfaces
// through edge midpoints and face and tetrahedron centroids, as in the multi-material
// extensions of marching tetrahedra: Bloomenthal & Ferguson 1995, "Polygonization of
// non-manifold implicit surfaces"; Wu & Sullivan 2003, "Multiple material marching cubes"), Taubin's λ|μ
// smoothing (SIGGRAPH 1995) restricted to the interface complex, and per-interface
// simplification with meshoptimizer (Kapoulkine; Garland & Heckbert 1997 quadrics).
// See label_surface.h for the contracts and why the partition is the right one for categories.
#include <meshoptimizer.h>
#include <mlfe/core/check.h>
#include <mlfe/core/error.h>
#include <mlfe/core/label_surface.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <string>
#include <unordered_map>

namespace mlfe {

namespace {

using V3 = std::array<double, 3>;
V3 sub(const V3& a, const V3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
V3 cross(const V3& a, const V3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
double dot(const V3& a, const V3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

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

// The signed volume enclosed by triangles given in piece-local indices.
double enclosed_volume(const std::vector<std::array<std::uint32_t, 3>>& tris,
                       const std::vector<std::uint32_t>& global, const std::vector<V3>& pos) {
  double v = 0;
  for (const auto& t : tris) v += dot(pos[global[t[0]]], cross(pos[global[t[1]]], pos[global[t[2]]])) / 6.0;
  return v;
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
    int distinct = 1;
    for (int s = 1; s < 4; ++s) {
      bool seen = false;
      for (int r = 0; r < s; ++r) seen |= label_[r] == label_[s];
      distinct += !seen;
    }
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
    const std::uint32_t centre = add_point({(x_[0][0] + x_[1][0] + x_[2][0] + x_[3][0]) / 4,
                                            (x_[0][1] + x_[1][1] + x_[2][1] + x_[3][1]) / 4,
                                            (x_[0][2] + x_[1][2] + x_[2][2] + x_[3][2]) / 4});
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

  LabelInterfaces take() { return std::move(out_); }

 private:
  std::uint32_t add_point(const V3& p) {
    MLFE_CHECK(out_.positions.size() < 0xffffffffu);
    out_.positions.push_back(p);
    return static_cast<std::uint32_t>(out_.positions.size() - 1);
  }

  // The midpoint of corners s and t (s < t in the tetrahedron's path order, so bits_[s] is a
  // subset of bits_[t]).
  std::uint32_t mid(int s, int t) {
    if (s > t) std::swap(s, t);
    const std::uint64_t key = key_[s] * 8 + (bits_[s] ^ bits_[t]);
    auto [it, added] = edges_.try_emplace(key, 0u);
    if (added)
      it->second =
          add_point({(x_[s][0] + x_[t][0]) / 2, (x_[s][1] + x_[t][1]) / 2, (x_[s][2] + x_[t][2]) / 2});
    return it->second;
  }

  // The centroid of the face with corners r < s < t.
  std::uint32_t face_point(int r, int s, int t) {
    const std::uint64_t key = key_[r] * 64 + (bits_[s] ^ bits_[r]) * 8 + (bits_[t] ^ bits_[r]);
    auto [it, added] = faces_.try_emplace(key, 0u);
    if (added)
      it->second = add_point({(x_[r][0] + x_[s][0] + x_[t][0]) / 3, (x_[r][1] + x_[s][1] + x_[t][1]) / 3,
                              (x_[r][2] + x_[s][2] + x_[t][2]) / 3});
    return it->second;
  }

  // A triangle separating the cells of corners s and t (which carry different labels): oriented
  // so its normal points from the lower label's corner to the higher's. The two corners are on
  // strictly opposite sides of every triangle made here (each lies in a plane through the
  // edge's midpoint that the edge crosses), so the sign test is exact.
  void emit(std::uint32_t p, std::uint32_t q, std::uint32_t r, int s, int t) {
    if (label_[s] > label_[t]) std::swap(s, t);
    const auto& P = out_.positions;
    const V3 n = cross(sub(P[q], P[p]), sub(P[r], P[p]));
    if (dot(n, sub(x_[t], x_[s])) < 0) std::swap(q, r);
    out_.triangles.push_back({p, q, r});
    out_.labels.push_back({label_[s], label_[t]});
  }

  const LabelGrid& g_;
  const std::int64_t sx_, sy_;
  std::uint8_t bits_[4]{};
  V3 x_[4]{};
  std::uint16_t label_[4]{};
  std::uint64_t key_[4]{};
  std::unordered_map<std::uint64_t, std::uint32_t> edges_, faces_;
  LabelInterfaces out_;
};

// The edges of the complex, sorted, each marked when it lies on a junction curve: where its
// triangles are not exactly two of the same interface (three or more labels meet there).
std::vector<std::pair<std::uint64_t, bool>> classified_edges(const LabelInterfaces& x) {
  std::vector<std::pair<std::uint64_t, std::uint32_t>> edges;
  edges.reserve(x.triangles.size() * 3);
  for (std::size_t t = 0; t < x.triangles.size(); ++t) {
    const std::uint32_t pair = std::uint32_t(x.labels[t][0]) << 16 | x.labels[t][1];
    for (int c = 0; c < 3; ++c)
      edges.emplace_back(edge_key(x.triangles[t][c], x.triangles[t][(c + 1) % 3]), pair);
  }
  std::sort(edges.begin(), edges.end());
  std::vector<std::pair<std::uint64_t, bool>> unique;
  for (std::size_t i = 0; i < edges.size();) {
    std::size_t j = i;
    bool same = true;
    for (; j < edges.size() && edges[j].first == edges[i].first; ++j)
      same &= edges[j].second == edges[i].second;
    unique.emplace_back(edges[i].first, !(same && j - i == 2));
    i = j;
  }
  return unique;
}

double segment_distance(const V3& p, const V3& a, const V3& b) {
  const V3 ab = sub(b, a), ap = sub(p, a);
  const double l2 = dot(ab, ab);
  const double t = l2 > 0 ? std::clamp(dot(ap, ab) / l2, 0.0, 1.0) : 0.0;
  const V3 d{ap[0] - t * ab[0], ap[1] - t * ab[1], ap[2] - t * ab[2]};
  return std::sqrt(dot(d, d));
}

// Douglas-Peucker on chain[first..last]: marks the vertices to keep.
void keep_far(const std::vector<std::uint32_t>& chain, std::size_t first, std::size_t last,
              const std::vector<V3>& pos, double tolerance, std::vector<char>& keep) {
  if (last <= first + 1) return;
  double worst = -1;
  std::size_t at = first;
  for (std::size_t i = first + 1; i < last; ++i) {
    const double d = segment_distance(pos[chain[i]], pos[chain[first]], pos[chain[last]]);
    if (d > worst) worst = d, at = i;
  }
  if (worst <= tolerance) return;
  keep[at] = 1;
  keep_far(chain, first, at, pos, tolerance, keep);
  keep_far(chain, at, last, pos, tolerance, keep);
}

// Simplifies the junction curves along themselves: per curve between meeting points (or per
// closed loop), Douglas-Peucker within `tolerance`, and every dropped curve vertex merged into
// the nearest kept one along its curve (the previous on ties). Merging vertices maps each
// label's surface onto a surface with the same boundary (none), so closed stays closed;
// triangles that lose a corner go. Returns the map old vertex -> vertex.
std::vector<std::uint32_t> simplify_junction_curves(const LabelInterfaces& x, double tolerance) {
  const std::size_t nv = x.positions.size();
  std::vector<std::uint32_t> to(nv);
  std::iota(to.begin(), to.end(), 0u);
  // The curves' adjacency (CSR): degree 2 inside a curve, other degrees where curves meet.
  std::vector<std::uint32_t> degree(nv, 0), start(nv + 1, 0), nbr;
  const auto edges = classified_edges(x);
  for (const auto& [e, junction] : edges)
    if (junction) ++start[(e >> 32) + 1], ++start[(e & 0xffffffffu) + 1];
  for (std::size_t v = 0; v < nv; ++v) start[v + 1] += start[v];
  nbr.resize(start[nv]);
  for (const auto& [e, junction] : edges) {
    if (!junction) continue;
    const std::uint32_t a = std::uint32_t(e >> 32), b = std::uint32_t(e & 0xffffffffu);
    nbr[start[a] + degree[a]++] = b;
    nbr[start[b] + degree[b]++] = a;
  }
  std::vector<char> done(nv, 0);
  std::vector<std::uint32_t> chain;
  std::vector<char> keep;
  auto simplify_chain = [&]() {
    keep.assign(chain.size(), 0);
    keep.front() = keep.back() = 1;
    keep_far(chain, 0, chain.size() - 1, x.positions, tolerance, keep);
    std::size_t prev = 0;
    for (std::size_t i = 1; i < chain.size(); ++i) {
      if (!keep[i]) continue;
      for (std::size_t j = prev + 1; j < i; ++j) to[chain[j]] = chain[j - prev <= i - j ? prev : i];
      prev = i;
    }
  };
  // Walks from `from` through `first` along curve vertices until a meeting point or `stop`.
  auto walk = [&](std::uint32_t from, std::uint32_t first, std::uint32_t stop) {
    chain.assign(1, from);
    std::uint32_t prev = from, cur = first;
    while (degree[cur] == 2 && cur != stop && !done[cur]) {
      done[cur] = 1;
      chain.push_back(cur);
      const std::uint32_t n = nbr[start[cur]] == prev ? nbr[start[cur] + 1] : nbr[start[cur]];
      prev = cur;
      cur = n;
    }
    chain.push_back(cur);
  };
  // Step 1: curves between meeting points (vertices where other than two curve edges meet).
  for (std::uint32_t v = 0; v < nv; ++v) {
    if (degree[v] == 0 || degree[v] == 2) continue;
    for (std::uint32_t n = start[v]; n < start[v + 1]; ++n) {
      const std::uint32_t w = nbr[n];
      if (done[w] || degree[w] != 2) continue;
      walk(v, w, v);
      simplify_chain();
    }
  }
  // Step 2: closed loops, anchored at their first vertex.
  for (std::uint32_t v = 0; v < nv; ++v) {
    if (degree[v] != 2 || done[v]) continue;
    done[v] = 1;
    walk(v, nbr[start[v]], v);
    if (chain.back() != v) continue;  // not a loop after all (a meeting point was reached)
    simplify_chain();
  }
  return to;
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

std::vector<KuhnTet> mixed_kuhn_tets(const LabelGrid& g) {
  const std::int64_t nx = g.dims[0], ny = g.dims[1], nz = g.dims[2];
  // One list per z layer of cubes (from -1: the padding), concatenated in order.
  std::vector<std::vector<KuhnTet>> layers(std::size_t(nz + 1));
  tbb::parallel_for(std::int64_t(-1), nz, [&](std::int64_t k) {
    auto& out = layers[std::size_t(k + 1)];
    for (std::int64_t j = -1; j < ny; ++j)
      for (std::int64_t i = -1; i < nx; ++i) {
        std::uint16_t c[8];
        bool uniform = true;
        for (int b = 0; b < 8; ++b) {
          c[b] = g.at(i + (b & 1), j + ((b >> 1) & 1), k + ((b >> 2) & 1));
          uniform &= c[b] == c[0];
        }
        if (uniform) continue;
        for (std::uint8_t o = 0; o < 6; ++o) {
          const std::uint16_t l0 = c[kCorner[o][0]];
          if (c[kCorner[o][1]] != l0 || c[kCorner[o][2]] != l0 || c[kCorner[o][3]] != l0)
            out.push_back({std::int32_t(i), std::int32_t(j), std::int32_t(k), o});
        }
      }
  });
  std::size_t total = 0;
  for (const auto& l : layers) total += l.size();
  std::vector<KuhnTet> all;
  all.reserve(total);
  for (const auto& l : layers) all.insert(all.end(), l.begin(), l.end());
  return all;
}

LabelInterfaces extract_label_interfaces(const LabelGrid& g, const std::vector<KuhnTet>& tets) {
  Extractor x(g);
  for (const auto& t : tets) {
    MLFE_CHECK(t.order < 6 && t.i >= -1 && t.j >= -1 && t.k >= -1 && t.i < g.dims[0] && t.j < g.dims[1] &&
               t.k < g.dims[2]);
    x.tet(t);
  }
  return x.take();
}

void smooth_label_interfaces(LabelInterfaces& x, const LabelSmoothingOptions& o) {
  if (o.iterations <= 0 || x.triangles.empty()) return;
  const std::size_t nv = x.positions.size();
  // Step 1: the edges, junction curves marked.
  const std::vector<std::pair<std::uint64_t, bool>> unique = classified_edges(x);
  // Step 2: each vertex's smoothing neighbours: all of them inside an interface, the two along
  // its curve on a junction, none where curves meet.
  std::vector<std::uint32_t> junction_degree(nv, 0);
  for (const auto& [e, junction] : unique)
    if (junction) ++junction_degree[e >> 32], ++junction_degree[e & 0xffffffffu];
  auto follows = [&](std::uint32_t v, bool junction) {
    return junction_degree[v] == 0 || (junction_degree[v] == 2 && junction);
  };
  std::vector<std::uint32_t> start(nv + 1, 0);
  for (const auto& [e, junction] : unique) {
    const std::uint32_t a = std::uint32_t(e >> 32), b = std::uint32_t(e & 0xffffffffu);
    start[a + 1] += follows(a, junction);
    start[b + 1] += follows(b, junction);
  }
  for (std::size_t v = 0; v < nv; ++v) start[v + 1] += start[v];
  std::vector<std::uint32_t> nbr(start[nv]);
  {
    std::vector<std::uint32_t> fill(start.begin(), start.end() - 1);
    for (const auto& [e, junction] : unique) {
      const std::uint32_t a = std::uint32_t(e >> 32), b = std::uint32_t(e & 0xffffffffu);
      if (follows(a, junction)) nbr[fill[a]++] = b;
      if (follows(b, junction)) nbr[fill[b]++] = a;
    }
  }
  // Step 3: Taubin's λ|μ passes (Jacobi), each move clamped to the offset bound.
  const std::vector<V3> original = x.positions;
  std::vector<V3> next(nv);
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
                          V3 avg{0, 0, 0};
                          for (std::uint32_t n = b; n < e; ++n)
                            for (int c = 0; c < 3; ++c) avg[c] += cur[nbr[n]][c];
                          V3 p;
                          for (int c = 0; c < 3; ++c)
                            p[c] = cur[v][c] + f * (avg[c] / double(e - b) - cur[v][c]);
                          const V3 d = sub(p, original[v]);
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

std::size_t simplify_label_interfaces(LabelInterfaces& x, double tolerance) {
  if (!(tolerance > 0) || !std::isfinite(tolerance))
    throw Error("simplification tolerance must be positive and finite (got " + std::to_string(tolerance) +
                ")");
  // Step 1: the junction curves simplified along themselves, so the interfaces' borders do not
  // stay at the extraction's resolution.
  {
    const std::vector<std::uint32_t> to = simplify_junction_curves(x, tolerance);
    std::size_t kept = 0;
    for (std::size_t t = 0; t < x.triangles.size(); ++t) {
      auto tri = x.triangles[t];
      for (auto& v : tri) v = to[v];
      if (tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2]) continue;
      x.triangles[kept] = tri;
      x.labels[kept++] = x.labels[t];
    }
    x.triangles.resize(kept);
    x.labels.resize(kept);
  }
  // Step 2: the interfaces: triangles grouped by label pair, in pair order.
  std::vector<std::uint32_t> order(x.triangles.size());
  std::iota(order.begin(), order.end(), 0u);
  auto pair_of = [&](std::uint32_t t) { return std::uint32_t(x.labels[t][0]) << 16 | x.labels[t][1]; };
  std::stable_sort(order.begin(), order.end(),
                   [&](std::uint32_t a, std::uint32_t b) { return pair_of(a) < pair_of(b); });
  std::vector<std::size_t> first{0};
  for (std::size_t i = 1; i <= order.size(); ++i)
    if (i == order.size() || pair_of(order[i]) != pair_of(order[i - 1])) first.push_back(i);
  const std::size_t n_iface = first.size() - 1;
  std::vector<std::vector<std::array<std::uint32_t, 3>>> result(n_iface);
  std::vector<std::size_t> kept_as_is(n_iface, 0);
  // Step 3: each connected piece of each interface on its own, junction curves (its border)
  // locked. Pieces one by one, so the guard below falls back for a piece, not an interface.
  tbb::parallel_for(std::size_t(0), n_iface, [&](std::size_t f) {
    std::vector<std::array<std::uint32_t, 3>> all;
    for (std::size_t i = first[f]; i < first[f + 1]; ++i) all.push_back(x.triangles[order[i]]);
    std::vector<std::uint32_t> global, local;
    std::unordered_map<std::uint32_t, std::uint32_t> slot;
    for (const auto& t : all)
      for (auto v : t) {
        auto [it, added] = slot.try_emplace(v, std::uint32_t(global.size()));
        if (added) global.push_back(v);
        local.push_back(it->second);
      }
    UnionFind uf(global.size());
    for (std::size_t t = 0; t < all.size(); ++t) {
      uf.unite(local[3 * t], local[3 * t + 1]);
      uf.unite(local[3 * t + 1], local[3 * t + 2]);
    }
    // Triangles per piece (by the piece's lowest local vertex), pieces in order of appearance.
    std::unordered_map<std::uint32_t, std::size_t> piece_of;
    std::vector<std::vector<std::uint32_t>> piece_tris;
    for (std::size_t t = 0; t < all.size(); ++t) {
      auto [it, added] = piece_of.try_emplace(uf.find(local[3 * t]), piece_tris.size());
      if (added) piece_tris.emplace_back();
      piece_tris[it->second].push_back(std::uint32_t(t));
    }
    std::vector<std::array<std::uint32_t, 3>>& out = result[f];
    std::vector<float> lp;
    for (const auto& piece : piece_tris) {
      // Local numbering of the piece: meshoptimizer allocates per vertex it is given.
      std::vector<std::uint32_t> pglobal, plocal;
      std::unordered_map<std::uint32_t, std::uint32_t> pslot;
      for (auto t : piece)
        for (int c = 0; c < 3; ++c) {
          auto [it, added] = pslot.try_emplace(all[t][c], std::uint32_t(pglobal.size()));
          if (added) pglobal.push_back(all[t][c]);
          plocal.push_back(it->second);
        }
      std::vector<std::array<std::uint32_t, 3>> in_local(piece.size());
      for (std::size_t t = 0; t < piece.size(); ++t)
        in_local[t] = {plocal[3 * t], plocal[3 * t + 1], plocal[3 * t + 2]};
      const auto border = boundary_chain(in_local);
      // meshoptimizer locks the vertices it sees on a border, but where a junction curve passes
      // a non-manifold spot of the piece it may see none. So every vertex of the piece's
      // border gets a tiny dangling triangle with two extra vertices, which gives it two open
      // edge pairs: locked. The extra triangles are dropped after.
      const std::uint32_t n_real = std::uint32_t(pglobal.size());
      std::vector<char> on_border(n_real, 0);
      for (const auto& [e, net] : border) on_border[e >> 32] = on_border[e & 0xffffffffu] = 1;
      std::vector<unsigned> indices(plocal.begin(), plocal.end());
      lp.resize(n_real * 3);
      for (std::size_t i = 0; i < n_real; ++i)
        for (int c = 0; c < 3; ++c) lp[3 * i + c] = float(x.positions[pglobal[i]][c]);
      const float scale = meshopt_simplifyScale(lp.data(), n_real, sizeof(float) * 3);
      for (std::uint32_t v = 0; v < n_real; ++v) {
        if (!on_border[v]) continue;
        const std::uint32_t d = std::uint32_t(lp.size() / 3);
        for (int k = 0; k < 2; ++k)
          for (int c = 0; c < 3; ++c) lp.push_back(lp[3 * v + c] + (c == k ? 1e-3f : 0.0f));
        indices.insert(indices.end(), {v, d, d + 1});
      }
      std::vector<unsigned> kept(indices.size());
      kept.resize(meshopt_simplify(kept.data(), indices.data(), indices.size(), lp.data(), lp.size() / 3,
                                   sizeof(float) * 3, 0, scale > 0 ? float(tolerance / scale) : 0.0f,
                                   meshopt_SimplifyLockBorder, nullptr));
      // Step 4: the guard: the piece keeps its boundary (junction curves), so every label's
      // surface stays closed; a closed piece (an island's whole surface) keeps at least a
      // tetrahedron's worth of triangles and half its volume. Else it stays as it came.
      std::vector<std::array<std::uint32_t, 3>> out_local;
      for (std::size_t t = 0; t + 2 < kept.size(); t += 3)
        if (kept[t] < n_real && kept[t + 1] < n_real && kept[t + 2] < n_real)
          out_local.push_back({kept[t], kept[t + 1], kept[t + 2]});
      bool ok = !out_local.empty() && border == boundary_chain(out_local);
      if (ok && border.empty()) {
        const double before = enclosed_volume(in_local, pglobal, x.positions),
                     after = enclosed_volume(out_local, pglobal, x.positions);
        ok =
            out_local.size() >= 4 && std::abs(after) >= 0.5 * std::abs(before) && (after > 0) == (before > 0);
      }
      if (!ok) ++kept_as_is[f];
      for (const auto& t : ok ? out_local : in_local)
        out.push_back({pglobal[t[0]], pglobal[t[1]], pglobal[t[2]]});
    }
  });
  // Step 5: the complex again, interface by interface, unused vertices dropped.
  std::vector<std::array<std::uint16_t, 2>> labels;
  std::vector<std::array<std::uint32_t, 3>> tris;
  for (std::size_t f = 0; f < n_iface; ++f)
    for (const auto& t : result[f]) {
      tris.push_back(t);
      labels.push_back(x.labels[order[first[f]]]);
    }
  std::vector<std::uint32_t> remap(x.positions.size(), ~0u);
  std::vector<V3> positions;
  for (auto& t : tris)
    for (auto& v : t) {
      if (remap[v] == ~0u) {
        remap[v] = std::uint32_t(positions.size());
        positions.push_back(x.positions[v]);
      }
      v = remap[v];
    }
  x.positions = std::move(positions);
  x.triangles = std::move(tris);
  x.labels = std::move(labels);
  return std::accumulate(kept_as_is.begin(), kept_as_is.end(), std::size_t(0));
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
