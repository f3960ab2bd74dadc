// Multi-material marching tetrahedra on the Kuhn triangulation of a label lattice (interfaces
// through edge midpoints and face and tetrahedron centroids, as in the multi-material
// extensions of marching tetrahedra: Bloomenthal & Ferguson 1995, "Polygonization of
// non-manifold implicit surfaces"; Wu & Sullivan 2003, "Multiple material marching cubes"), Taubin's λ|μ
// smoothing (SIGGRAPH 1995) restricted to the interface complex, and Garland & Heckbert's
// quadric edge collapse ("Surface simplification using quadric error metrics", SIGGRAPH 1997)
// over the whole complex, with the merged vertex at the quadric's least point.
// See label_surface.h for the contracts and why the partition is the right one for categories.
#include <mlfe/core/base/check.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/labels/label_surface.h>
#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <iterator>
#include <limits>
#include <numeric>
#include <string>
#include <type_traits>
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

// Numbers the items i < n for which kept(i) holds in their order (number[i]; ~0u for the
// others) and returns how many: counted per chunk in parallel, then numbered per chunk from
// the chunk's offset.
template <class Kept>
std::uint32_t number_kept(std::size_t n, Kept kept, std::vector<std::uint32_t>& number) {
  constexpr std::size_t kChunk = 1 << 14;
  const std::size_t chunks = (n + kChunk - 1) / kChunk;
  std::vector<std::uint32_t> offset(chunks + 1, 0);
  number.resize(n);
  tbb::parallel_for(std::size_t(0), chunks, [&](std::size_t c) {
    for (std::size_t i = c * kChunk; i < std::min(n, (c + 1) * kChunk); ++i) offset[c + 1] += kept(i);
  });
  std::partial_sum(offset.begin(), offset.end(), offset.begin());
  tbb::parallel_for(std::size_t(0), chunks, [&](std::size_t c) {
    std::uint32_t next = offset[c];
    for (std::size_t i = c * kChunk; i < std::min(n, (c + 1) * kChunk); ++i)
      number[i] = kept(i) ? next++ : ~0u;
  });
  return offset[chunks];
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
  std::uint32_t add_point(const V3& p, std::uint64_t key) {
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

// Garland & Heckbert's quadric edge collapse (SIGGRAPH 1997) over the whole interface complex
// at once, with the optimal placement of the merged vertex, constrained so the complex stays a
// partition: a vertex inside one interface merges with a neighbour inside the same interface
// (placed where the summed quadric is least) or moves onto a junction-curve neighbour (which
// stays put); a vertex on a junction curve merges only with its neighbours along that curve
// (placed on the segment between them where the quadric is least); where curves meet, and at
// vertices whose triangles do not form one fan, nothing moves. Merging vertices maps every
// label's closed surface onto a closed surface, so closed stays closed and shared stays shared.
//
// Three passes: first every block of a fixed partition of space into small blocks on its own
// (in parallel), collapsing only edges whose ends and all their neighbours lie in the block and
// only the cheap merges; then the two halves of the complex, below and above the median height
// of its vertices, the same way (one at a time per thread) up to the tolerance; then the whole
// complex, where the halves meet. A part's collapses touch nothing outside it (see
// decimate_parts), and each part's pass is sequential in itself, so the result does not depend
// on the thread count; a block's few thousand vertices stay in cache, and the halves share the
// collapse over the complex, which waits on memory for every triangle list it reads, between
// two threads. One seam across the complex costs nothing measurable (bench/RESULTS.md); many
// (the small blocks at the full tolerance) show in the distances.
class ComplexDecimator {
 public:
  ComplexDecimator(LabelInterfaces& x, double tolerance) : x_(x), tol2_(tolerance * tolerance) {}

  void run() {
    // Step 1: vertices numbered block by block; kinds, triangle lists and quadrics.
    order_by_block();
    vertex_triangles();
    classify();
    init_quadrics();
    // Step 2: each block's inside alone, the cheap merges only (where the order hardly
    // matters).
    const std::vector<std::vector<std::uint32_t>> blocks = block_insides(cell_);
    std::vector<std::uint64_t>().swap(cell_);
    decimate_parts(blocks, tol2_ * kBlockShare * kBlockShare);
    // Step 3: each half of the complex alone (below and above its vertices' median height), up
    // to the tolerance: the merges that shape the result, both halves at once.
    renumber_alive();
    decimate_parts(block_insides(halves()), tol2_);
    // Step 4: the whole complex, for the seam between the halves.
    std::vector<std::uint32_t> all(x_.positions.size());
    std::iota(all.begin(), all.end(), 0u);
    Queue q;
    q.limit2 = tol2_;
    decimate(all, kEverywhere, q);
    compact();
  }

 private:
  enum Kind : std::uint8_t { kInterior, kCurve, kFixed };
  struct Quadric {
    double a[6]{}, b[3]{}, c = 0, w = 0;  // p^T A p - 2 b^T p + c, A = {xx xy xz yy yz zz}
    void add(const Quadric& q) {
      for (int i = 0; i < 6; ++i) a[i] += q.a[i];
      for (int i = 0; i < 3; ++i) b[i] += q.b[i];
      c += q.c, w += q.w;
    }
    double eval(const V3& p) const {
      const double ap0 = a[0] * p[0] + a[1] * p[1] + a[2] * p[2],
                   ap1 = a[1] * p[0] + a[3] * p[1] + a[4] * p[2],
                   ap2 = a[2] * p[0] + a[4] * p[1] + a[5] * p[2];
      return p[0] * ap0 + p[1] * ap1 + p[2] * ap2 - 2 * (b[0] * p[0] + b[1] * p[1] + b[2] * p[2]) + c;
    }
  };
  // A queued edge. Every change to an end queues its edges again, so an entry whose edge now
  // plans into another bucket (or not at all) is stale and skipped: the fresh entry is elsewhere.
  struct Candidate {
    std::uint32_t a, b;
  };
  static constexpr std::size_t kBuckets = 2048;
  // Cheapest first, by buckets of the cost (a bucket queue: a heap of the few million
  // candidates, most of them stale, costs more than the collapses). Within a bucket the last
  // pushed goes first. Also the scratch lists of one pass.
  struct Queue {
    std::vector<std::vector<Candidate>> buckets = std::vector<std::vector<Candidate>>(kBuckets);
    std::size_t lowest = kBuckets;
    double limit2 = 0;  // the pass's largest cost
    std::vector<std::uint32_t> nu, nv, common, apex;
  };
  // Blocks of kBlock³ voxels; a pass's scope is a part's number or the whole complex. The
  // blocks merge up to kBlockShare of the tolerance: 55 % of the JHU atlas's merges at 0.1,
  // 73 % at 0.2, with distances within the spread that reordering near-equal merges of one
  // pass over the whole gives (bench/RESULTS.md); more makes the blocks' seams show.
  static constexpr double kBlock = 16, kBlockShare = 0.2;
  static constexpr std::uint32_t kEverywhere = ~0u, kBorder = ~0u - 1;

  // Per vertex its triangles in triangle order, each list reserved at its final size.
  void vertex_triangles() {
    const std::size_t nv = x_.positions.size();
    std::vector<std::uint32_t> count(nv, 0);
    for (const auto& t : x_.triangles)
      for (auto v : t) ++count[v];
    tris_of_.resize(nv);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nv, 4096),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        for (std::size_t v = r.begin(); v != r.end(); ++v) tris_of_[v].reserve(count[v]);
                      });
    for (std::uint32_t t = 0; t < x_.triangles.size(); ++t)
      for (auto v : x_.triangles[t]) tris_of_[v].push_back(t);
    tri_alive_.assign(x_.triangles.size(), 1);
    alive_.assign(nv, 1);
  }

  // Kinds: interior (no junction edge), curve (two junction edges), fixed (other counts, or a
  // vertex whose triangles do not form one closed fan: a non-manifold point of an interface).
  void classify() {
    const std::size_t nv = x_.positions.size();
    kind_.assign(nv, kInterior);
    tbb::parallel_for(
        tbb::blocked_range<std::size_t>(0, nv, 4096), [&](const tbb::blocked_range<std::size_t>& r) {
          // Per vertex its junction edges, counted from its own triangles (a global edge list would
          // cost more memory than the collapse itself).
          std::vector<std::pair<std::uint32_t, std::uint32_t>> around, link;
          for (std::size_t v = r.begin(); v != r.end(); ++v) {
            around.clear();
            for (auto t : tris_of_[v])
              for (auto w : x_.triangles[t])
                if (w != v) around.emplace_back(w, std::uint32_t(x_.labels[t][0]) << 16 | x_.labels[t][1]);
            std::sort(around.begin(), around.end());
            int junction_degree = 0;
            for (std::size_t i = 0; i < around.size();) {
              std::size_t j = i;
              while (j < around.size() && around[j].first == around[i].first) ++j;
              junction_degree += !(j - i == 2 && around[i].second == around[i + 1].second);
              i = j;
            }
            if (junction_degree == 2) kind_[v] = kCurve;
            if (junction_degree != 0 && junction_degree != 2) kind_[v] = kFixed;
            if (kind_[v] == kInterior && !one_fan(std::uint32_t(v), link)) kind_[v] = kFixed;
          }
        });
  }

  // Whether the triangles around an interior vertex form one closed fan: the edges opposite v
  // form one cycle.
  bool one_fan(std::uint32_t v, std::vector<std::pair<std::uint32_t, std::uint32_t>>& link) const {
    link.clear();
    for (auto t : tris_of_[v]) {
      const auto& tri = x_.triangles[t];
      const int c = tri[0] == v ? 0 : tri[1] == v ? 1 : 2;
      link.emplace_back(tri[(c + 1) % 3], tri[(c + 2) % 3]);
    }
    if (link.size() < 3) return false;
    // Follow the oriented cycle from the first edge; it must use every edge once.
    std::size_t steps = 0;
    std::uint32_t at = link[0].second;
    while (at != link[0].first) {
      std::size_t found = 0, next = 0;
      for (std::size_t i = 0; i < link.size(); ++i)
        if (link[i].first == at) ++found, next = i;
      if (found != 1 || ++steps > link.size()) return false;
      at = link[next].second;
    }
    return steps + 1 == link.size();
  }

  // Per vertex the sum of its triangles' area-weighted plane quadrics, in triangle order.
  void init_quadrics() {
    q_.assign(x_.positions.size(), Quadric{});
    tbb::parallel_for(
        tbb::blocked_range<std::size_t>(0, q_.size(), 4096), [&](const tbb::blocked_range<std::size_t>& r) {
          for (std::size_t v = r.begin(); v != r.end(); ++v)
            for (auto t : tris_of_[v]) {
              const auto& tri = x_.triangles[t];
              const V3 &p0 = x_.positions[tri[0]], &p1 = x_.positions[tri[1]], &p2 = x_.positions[tri[2]];
              V3 n = cross(sub(p1, p0), sub(p2, p0));
              const double len = std::sqrt(dot(n, n));
              if (!(len > 0)) continue;
              const double area = len / 2;
              for (auto& c : n) c /= len;
              const double d = -dot(n, p0);
              // area * (n.p + d)^2
              Quadric q;
              q.a[0] = area * n[0] * n[0], q.a[1] = area * n[0] * n[1], q.a[2] = area * n[0] * n[2];
              q.a[3] = area * n[1] * n[1], q.a[4] = area * n[1] * n[2], q.a[5] = area * n[2] * n[2];
              for (int c = 0; c < 3; ++c) q.b[c] = -area * d * n[c];
              q.c = area * d * d;
              q.w = area;
              q_[v].add(q);
            }
        });
  }

  // The parts of a partition of the live vertices (by `cell`, per vertex): the vertices inside
  // each non-empty part (no neighbour in another part), ascending, parts in the order of their
  // cells; every vertex's scope_ is its part's number in that list, or kBorder.
  std::vector<std::vector<std::uint32_t>> block_insides(const std::vector<std::uint64_t>& cell) {
    const std::size_t nv = x_.positions.size();
    scope_.assign(nv, kBorder);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nv, 4096),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        for (std::size_t v = r.begin(); v != r.end(); ++v) {
                          bool inside = alive_[v];
                          for (auto t : tris_of_[v])
                            if (tri_alive_[t])
                              for (auto w : x_.triangles[t]) inside &= cell[w] == cell[v];
                          if (inside) scope_[v] = 0;
                        }
                      });
    // Number the blocks in order of their cells.
    std::vector<std::uint64_t> cells;
    for (std::size_t v = 0; v < nv; ++v)
      if (scope_[v] == 0) cells.push_back(cell[v]);
    std::sort(cells.begin(), cells.end());
    cells.erase(std::unique(cells.begin(), cells.end()), cells.end());
    std::vector<std::vector<std::uint32_t>> blocks(cells.size());
    for (std::uint32_t v = 0; v < nv; ++v) {
      if (scope_[v] == kBorder) continue;
      scope_[v] = std::uint32_t(std::lower_bound(cells.begin(), cells.end(), cell[v]) - cells.begin());
      blocks[scope_[v]].push_back(v);
    }
    return blocks;
  }

  // The block of every vertex (its cell of kBlock³ voxels), and the vertices numbered by block,
  // in their order within a block: a block's pass then reads contiguous memory. Within a block
  // the order is the same as before, so are the collapses; original_[v] is v's number before,
  // the order renumber_alive restores for the pass over the whole complex.
  void order_by_block() {
    const std::size_t nv = x_.positions.size();
    std::vector<std::array<std::uint32_t, 3>> at(nv);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nv, 4096),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        for (std::size_t v = r.begin(); v != r.end(); ++v)
                          for (int c = 0; c < 3; ++c) {
                            const double s = std::floor((x_.positions[v][c] + 2) / kBlock);
                            at[v][c] = std::uint32_t(std::clamp(s, 0.0, double(1 << 20)));
                          }
                      });
    std::array<std::uint64_t, 3> dims{1, 1, 1};
    for (const auto& b : at)
      for (int c = 0; c < 3; ++c) dims[c] = std::max(dims[c], std::uint64_t(b[c]) + 1);
    // Counting sort by block: stable, so each block keeps its vertices' order.
    std::vector<std::uint32_t> first(dims[0] * dims[1] * dims[2] + 1, 0);
    cell_.resize(nv);
    for (std::size_t v = 0; v < nv; ++v) {
      cell_[v] = (at[v][0] * dims[1] + at[v][1]) * dims[2] + at[v][2];
      ++first[cell_[v] + 1];
    }
    std::partial_sum(first.begin(), first.end(), first.begin());
    original_.resize(nv);
    std::vector<std::uint64_t> cell(nv);
    for (std::uint32_t v = 0; v < nv; ++v) {
      const std::uint32_t to = first[cell_[v]]++;
      original_[to] = v, cell[to] = cell_[v];
    }
    cell_.swap(cell);
    std::vector<std::uint32_t> where(nv);
    std::vector<V3> positions(nv);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nv, 4096),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        for (std::size_t v = r.begin(); v != r.end(); ++v) {
                          where[original_[v]] = std::uint32_t(v);
                          positions[v] = x_.positions[original_[v]];
                        }
                      });
    x_.positions.swap(positions);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, x_.triangles.size(), 4096),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        for (std::size_t t = r.begin(); t != r.end(); ++t)
                          for (auto& v : x_.triangles[t]) v = where[v];
                      });
  }

  // Every part's vertices decimated alone, up to cost `limit2`, parts in parallel (scope_ holds
  // each vertex's part, see block_insides). A collapse of u into v writes u's and v's triangle
  // lists, their triangles, v's position and quadric, and reads their neighbours; with both ends
  // inside a part (no neighbour in another part: a collapse inside a part never adds one, so
  // this stays true), all of that belongs to the part.
  void decimate_parts(const std::vector<std::vector<std::uint32_t>>& parts, double limit2) {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, parts.size(), 1),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        Queue& q = queues_.local();
                        q.limit2 = limit2;
                        for (std::size_t b = r.begin(); b != r.end(); ++b)
                          decimate(parts[b], std::uint32_t(b), q);
                      });
  }

  // Per vertex its half of the complex: 1 at or above the median height of the vertices.
  std::vector<std::uint64_t> halves() const {
    const std::size_t n = x_.positions.size();
    std::vector<std::uint64_t> half(n);
    if (n == 0) return half;
    std::vector<double> z(n);
    for (std::size_t v = 0; v < n; ++v) z[v] = x_.positions[v][2];
    std::nth_element(z.begin(), z.begin() + n / 2, z.end());
    const double split = z[n / 2];
    for (std::size_t v = 0; v < n; ++v) half[v] = x_.positions[v][2] >= split;
    return half;
  }

  bool in_scope(std::uint32_t v, std::uint32_t scope) const {
    return scope == kEverywhere || scope_[v] == scope;
  }

  // One pass: every edge of `vertices` within `scope` queued once, from its lower vertex, in
  // vertex order, then collapsed cheapest first while within the tolerance.
  void decimate(const std::vector<std::uint32_t>& vertices, std::uint32_t scope, Queue& q) {
    for (auto v : vertices) {
      neighbours(v, q.nv);
      for (auto w : q.nv)
        if (w > v && in_scope(w, scope)) push(v, w, q);
    }
    for (;;) {
      while (q.lowest < kBuckets && q.buckets[q.lowest].empty()) ++q.lowest;
      if (q.lowest == kBuckets) break;
      const Candidate c = q.buckets[q.lowest].back();
      q.buckets[q.lowest].pop_back();
      if (!alive_[c.a] || !alive_[c.b]) continue;
      std::uint32_t from = 0, to = 0;
      V3 p{};
      const double cost = plan(c.a, c.b, from, to, p);
      if (!(cost <= q.limit2) || bucket_of(cost, q) != q.lowest) continue;
      if (collapsible(from, to, p, q)) collapse(from, to, p, scope, q);
    }
  }

  // The triangles on edge {a, b} and whether it lies on a junction curve (not exactly two
  // triangles of one interface).
  bool junction_edge(std::uint32_t a, std::uint32_t b) const {
    int n = 0;
    std::uint32_t pair = 0;
    bool same = true;
    for (auto t : tris_of_[a]) {
      if (!tri_alive_[t]) continue;
      const auto& tri = x_.triangles[t];
      if (tri[0] != b && tri[1] != b && tri[2] != b) continue;
      const std::uint32_t p = std::uint32_t(x_.labels[t][0]) << 16 | x_.labels[t][1];
      if (n++ == 0) pair = p;
      same &= p == pair;
    }
    return !(same && n == 2);
  }

  // The least of q on the segment a..b.
  static V3 best_on_segment(const Quadric& q, const V3& a, const V3& b) {
    const V3 d = sub(b, a);
    const V3 ad{q.a[0] * d[0] + q.a[1] * d[1] + q.a[2] * d[2], q.a[1] * d[0] + q.a[3] * d[1] + q.a[4] * d[2],
                q.a[2] * d[0] + q.a[4] * d[1] + q.a[5] * d[2]};
    const double dad = dot(d, ad);
    double t = 0.5;
    if (dad > 1e-18)
      t = std::clamp(((q.b[0] * d[0] + q.b[1] * d[1] + q.b[2] * d[2]) - dot(a, ad)) / dad, 0.0, 1.0);
    return {a[0] + t * d[0], a[1] + t * d[1], a[2] + t * d[2]};
  }

  // The least of q over space when well conditioned and near the edge, else on the segment.
  static V3 best_point(const Quadric& q, const V3& a, const V3& b) {
    const double* m = q.a;
    const double c00 = m[3] * m[5] - m[4] * m[4], c01 = m[2] * m[4] - m[1] * m[5],
                 c02 = m[1] * m[4] - m[2] * m[3];
    const double det = m[0] * c00 + m[1] * c01 + m[2] * c02;
    const double scale = m[0] + m[3] + m[5];
    if (scale > 0 && std::abs(det) > 1e-3 * scale * scale * scale) {
      const double c11 = m[0] * m[5] - m[2] * m[2], c12 = m[1] * m[2] - m[0] * m[4],
                   c22 = m[0] * m[3] - m[1] * m[1];
      const V3 p{(c00 * q.b[0] + c01 * q.b[1] + c02 * q.b[2]) / det,
                 (c01 * q.b[0] + c11 * q.b[1] + c12 * q.b[2]) / det,
                 (c02 * q.b[0] + c12 * q.b[1] + c22 * q.b[2]) / det};
      const V3 mid{(a[0] + b[0]) / 2, (a[1] + b[1]) / 2, (a[2] + b[2]) / 2}, ab = sub(b, a), pm = sub(p, mid);
      if (dot(pm, pm) <= dot(ab, ab)) return p;
    }
    return best_on_segment(q, a, b);
  }

  // The allowed collapse of edge {a, b} (which end goes, where the other moves) and its cost:
  // the summed quadric per unit area (a mean squared distance to the merged planes) at the
  // placement. Infinite when the edge may not collapse.
  double plan(std::uint32_t a, std::uint32_t b, std::uint32_t& from, std::uint32_t& to, V3& p) const {
    constexpr double kNever = std::numeric_limits<double>::infinity();
    const Kind ka = kind_[a], kb = kind_[b];
    if (ka == kFixed && kb == kFixed) return kNever;
    Quadric q = q_[a];
    q.add(q_[b]);
    if (ka == kInterior && kb == kInterior) {
      p = best_point(q, x_.positions[a], x_.positions[b]);
      from = std::max(a, b), to = std::min(a, b);
    } else if (ka == kInterior || kb == kInterior) {
      from = ka == kInterior ? a : b, to = ka == kInterior ? b : a;
      p = x_.positions[to];
    } else {
      // Both on curves (or one where curves meet): only along a junction curve.
      if (!junction_edge(a, b)) return kNever;
      if (ka == kCurve && kb == kCurve) {
        p = best_on_segment(q, x_.positions[a], x_.positions[b]);
        from = std::max(a, b), to = std::min(a, b);
      } else {
        from = ka == kCurve ? a : b, to = ka == kCurve ? b : a;
        p = x_.positions[to];
      }
    }
    return q.w > 0 ? std::max(0.0, q.eval(p)) / q.w : 0.0;
  }

  // Queues the collapse of edge {a, b} when it is allowed and within the tolerance.
  void push(std::uint32_t a, std::uint32_t b, Queue& q) const {
    std::uint32_t from = 0, to = 0;
    V3 p{};
    const double cost = plan(a, b, from, to, p);
    if (!(cost <= q.limit2)) return;
    const std::size_t bucket = bucket_of(cost, q);
    q.buckets[bucket].push_back({a, b});
    q.lowest = std::min(q.lowest, bucket);
  }

  static std::size_t bucket_of(double cost, const Queue& q) {
    return std::min(kBuckets - 1, std::size_t(std::sqrt(cost / q.limit2) * double(kBuckets)));
  }

  // The live neighbours of v, ascending; drops v's dead triangles from its list on the way.
  void neighbours(std::uint32_t v, std::vector<std::uint32_t>& out) {
    out.clear();
    auto& tv = tris_of_[v];
    std::size_t kept = 0;
    for (auto t : tv)
      if (tri_alive_[t]) {
        tv[kept++] = t;
        for (auto w : x_.triangles[t])
          if (w != v) out.push_back(w);
      }
    tv.resize(kept);
    std::sort(out.begin(), out.end());
    out.erase(std::unique(out.begin(), out.end()), out.end());
  }

  // Topology (the link condition: the common neighbours of the two ends are exactly the apexes
  // of the triangles on the edge; no closed piece below a tetrahedron; a junction curve keeps at
  // least three vertices per loop) and geometry (no triangle flips or degenerates).
  bool collapsible(std::uint32_t u, std::uint32_t v, const V3& p, Queue& q) {
    neighbours(u, q.nu);
    neighbours(v, q.nv);
    if (q.nu.size() <= 3 && q.nv.size() <= 3) return false;
    q.common.clear();
    std::set_intersection(q.nu.begin(), q.nu.end(), q.nv.begin(), q.nv.end(), std::back_inserter(q.common));
    q.apex.clear();
    for (auto t : tris_of_[u]) {
      const auto& tri = x_.triangles[t];
      if (tri[0] != v && tri[1] != v && tri[2] != v) continue;
      for (auto w : tri)
        if (w != u && w != v) q.apex.push_back(w);
    }
    if (q.apex.empty()) return false;
    std::sort(q.apex.begin(), q.apex.end());
    q.apex.erase(std::unique(q.apex.begin(), q.apex.end()), q.apex.end());
    if (q.apex != q.common) return false;
    if (kind_[u] == kCurve && kind_[v] != kInterior) {
      // The other curve neighbours of u and v must differ (else a loop of three closes up).
      for (auto w : q.common)
        if (kind_[w] != kInterior && junction_edge(u, w) && junction_edge(v, w)) return false;
    }
    return !flips(u, v, p) && !flips(v, u, p);
  }

  // Whether moving `v` to `p` (with `other` merged into it) flips or flattens a triangle of v
  // that survives.
  bool flips(std::uint32_t v, std::uint32_t other, const V3& p) const {
    for (auto t : tris_of_[v]) {
      if (!tri_alive_[t]) continue;
      const auto& tri = x_.triangles[t];
      if (tri[0] == other || tri[1] == other || tri[2] == other) continue;
      V3 before[3], after[3];
      for (int k = 0; k < 3; ++k) before[k] = after[k] = x_.positions[tri[k]];
      for (int k = 0; k < 3; ++k)
        if (tri[k] == v) after[k] = p;
      const V3 n0 = cross(sub(before[1], before[0]), sub(before[2], before[0]));
      const V3 n1 = cross(sub(after[1], after[0]), sub(after[2], after[0]));
      const double l0 = dot(n0, n0), l1 = dot(n1, n1);
      if (!(l1 > 1e-12)) return true;
      if (dot(n0, n1) < kMinCos * std::sqrt(l0 * l1)) return true;
    }
    return false;
  }

  // Merges u into v at p and queues v's edges within `scope` again.
  void collapse(std::uint32_t u, std::uint32_t v, const V3& p, std::uint32_t scope, Queue& q) {
    for (auto t : tris_of_[u]) {
      if (!tri_alive_[t]) continue;
      auto& tri = x_.triangles[t];
      if (tri[0] == v || tri[1] == v || tri[2] == v) {
        tri_alive_[t] = 0;
        continue;
      }
      for (auto& w : tri)
        if (w == u) w = v;
      tris_of_[v].push_back(t);
    }
    tris_of_[u].clear();
    tris_of_[u].shrink_to_fit();
    alive_[u] = 0;
    x_.positions[v] = p;
    q_[v].add(q_[u]);
    neighbours(v, q.nv);
    for (auto w : q.nv)
      if (in_scope(w, scope)) push(v, w, q);
  }

  // Drops dead vertices and triangles, numbering the rest in the same order (so every choice
  // that compares numbers or follows their order is the same), for a smaller working set.
  void renumber_alive() {
    const std::size_t nv = x_.positions.size(), nt = x_.triangles.size();
    // Vertices in their order before order_by_block: at[o] is the vertex numbered o then.
    std::vector<std::uint32_t> at(nv), rank, vmap(nv), tmap;
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nv, 4096),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        for (std::size_t v = r.begin(); v != r.end(); ++v)
                          at[original_[v]] = std::uint32_t(v);
                      });
    const std::uint32_t n = number_kept(
        nv, [&](std::size_t o) { return alive_[at[o]] != 0; }, rank);
    // One array at a time (the old one freed before the next is made), for the peak.
    auto keep = [&](auto& array, auto move) {
      std::remove_reference_t<decltype(array)> kept(n);
      tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nv, 4096),
                        [&](const tbb::blocked_range<std::size_t>& r) {
                          for (std::size_t o = r.begin(); o != r.end(); ++o)
                            if (rank[o] != ~0u) move(kept[rank[o]], array[at[o]]);
                        });
      array.swap(kept);
    };
    auto copy = [](auto& to, auto& from) { to = from; };
    keep(x_.positions, copy), keep(q_, copy), keep(kind_, copy);
    keep(tris_of_, copy);  // fresh lists, each part's next to each other
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nv, 4096),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        for (std::size_t o = r.begin(); o != r.end(); ++o) vmap[at[o]] = rank[o];
                      });
    alive_.assign(n, 1);
    original_.clear(), cell_.clear();
    const std::uint32_t m = number_kept(
        nt, [&](std::size_t t) { return tri_alive_[t] != 0; }, tmap);
    std::vector<std::array<std::uint32_t, 3>> triangles(m);
    std::vector<std::array<std::uint16_t, 2>> labels(m);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nt, 4096),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        for (std::size_t t = r.begin(); t != r.end(); ++t) {
                          if (tmap[t] == ~0u) continue;
                          for (int c = 0; c < 3; ++c) triangles[tmap[t]][c] = vmap[x_.triangles[t][c]];
                          labels[tmap[t]] = x_.labels[t];
                        }
                      });
    x_.triangles.swap(triangles), x_.labels.swap(labels);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 4096),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        for (std::size_t v = r.begin(); v != r.end(); ++v) {
                          auto& tv = tris_of_[v];
                          std::size_t kept = 0;
                          for (auto t : tv)
                            if (tri_alive_[t]) tv[kept++] = tmap[t];
                          tv.resize(kept);
                        }
                      });
    tri_alive_.assign(m, 1);
  }

  // Drops dead triangles and unused vertices; vertices numbered in first use.
  void compact() {
    std::vector<std::array<std::uint32_t, 3>> tris;
    std::vector<std::array<std::uint16_t, 2>> labels;
    for (std::size_t t = 0; t < x_.triangles.size(); ++t)
      if (tri_alive_[t]) tris.push_back(x_.triangles[t]), labels.push_back(x_.labels[t]);
    std::vector<std::uint32_t> remap(x_.positions.size(), ~0u);
    std::vector<V3> positions;
    for (auto& t : tris)
      for (auto& v : t) {
        if (remap[v] == ~0u) {
          remap[v] = std::uint32_t(positions.size());
          positions.push_back(x_.positions[v]);
        }
        v = remap[v];
      }
    x_.positions = std::move(positions);
    x_.triangles = std::move(tris);
    x_.labels = std::move(labels);
  }

  static constexpr double kMinCos = 0.2;
  LabelInterfaces& x_;
  const double tol2_;
  std::vector<Kind> kind_;
  std::vector<char> alive_, tri_alive_;
  std::vector<std::vector<std::uint32_t>> tris_of_;
  std::vector<Quadric> q_;
  std::vector<std::uint32_t> scope_;
  std::vector<std::uint64_t> cell_;
  std::vector<std::uint32_t> original_;
  // Per thread the pass's queue, kept for the next pass (its buckets' storage).
  tbb::enumerable_thread_specific<Queue> queues_;
};

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
        // Corner b of the cube: offset bits (i, j, k) = (b & 1, b >> 1 & 1, b >> 2 & 1).
        std::uint16_t c[8];
        bool uniform = true;
        for (int b = 0; b < 8; ++b) {
          c[b] = column[b & 1][b >> 1];
          uniform &= c[b] == c[0];
        }
        if (uniform) continue;
        for (std::uint8_t o = 0; o < 6; ++o) {
          const std::uint16_t l0 = c[kCorner[o][0]];
          if (c[kCorner[o][1]] != l0 || c[kCorner[o][2]] != l0 || c[kCorner[o][3]] != l0)
            out.push_back({std::int32_t(i), std::int32_t(j), std::int32_t(k), o});
        }
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
      const V3& p = piece.x.positions[i];
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
  const std::size_t before = x.positions.size();
  ComplexDecimator(x, tolerance).run();
  return before - x.positions.size();
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
