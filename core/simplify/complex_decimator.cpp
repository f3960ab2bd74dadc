// Garland & Heckbert's quadric edge collapse ("Surface simplification using quadric error
// metrics", SIGGRAPH 1997) over a whole interface complex at once, with the merged vertex at the
// quadric's least point, constrained so the complex stays a partition. See complex_decimator.h
// for the contract.
#include <mlfe/core/base/check.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/base/vec.h>
#include <mlfe/core/simplify/complex_decimator.h>
#include <mlfe/core/surface/mesh_distance.h>
#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <iterator>
#include <limits>
#include <numeric>
#include <string>
#include <type_traits>

namespace mlfe {

namespace {

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

// Per vertex the triangles at it, in one pool: each vertex starts with a slot sized for its
// triangles then (the slot numbered as the vertex); a merge chains the gone vertex's slots after
// the survivor's, and those hold every triangle the survivor gains (each comes from the gone
// one's list); packing a list (dropping its dead triangles) fills its first slots and unchains
// the rest. 12 bytes per vertex and 4 per corner, where a vector per vertex took 56 bytes.
class TriangleLists {
 public:
  static constexpr std::uint32_t kNoSlot = ~0u;

  class Iterator {
   public:
    Iterator(const TriangleLists* l, std::uint32_t slot) : l_(l), slot_(slot) { skip_full(); }
    std::uint32_t operator*() const { return l_->pool_[l_->start_[slot_] + i_]; }
    Iterator& operator++() {
      ++i_;
      skip_full();
      return *this;
    }
    bool operator!=(const Iterator& o) const { return slot_ != o.slot_ || i_ != o.i_; }

   private:
    void skip_full() {
      while (slot_ != kNoSlot && i_ == l_->size_[slot_]) slot_ = l_->next_[slot_], i_ = 0;
    }
    const TriangleLists* l_;
    std::uint32_t slot_, i_ = 0;
  };
  struct Range {
    Iterator b, e;
    Iterator begin() const { return b; }
    Iterator end() const { return e; }
  };

  /// Vertex v's triangles, in list order.
  Range of(std::uint32_t v) const { return {Iterator(this, v), Iterator(this, kNoSlot)}; }

  /// Per vertex of `triangles` (nv of them) its triangles, in triangle order.
  void build(std::size_t nv, const std::vector<std::array<std::uint32_t, 3>>& triangles) {
    std::vector<std::uint32_t> count(nv, 0);
    for (const auto& t : triangles)
      for (auto v : t) ++count[v];
    allocate(count);
    std::vector<std::uint32_t> at(start_.begin(), start_.end() - 1);
    for (std::uint32_t t = 0; t < triangles.size(); ++t)
      for (auto v : triangles[t]) pool_[at[v]++] = t;
  }

  /// `sizes[v]` triangles per vertex, written by fill(v, out) (in parallel over the vertices).
  template <class Fill>
  void assign(const std::vector<std::uint32_t>& sizes, Fill fill) {
    allocate(sizes);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, sizes.size(), 4096),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        for (std::size_t v = r.begin(); v != r.end(); ++v) fill(v, pool_.data() + start_[v]);
                      });
  }

  /// Chains u's list after v's (u is gone into v).
  void append(std::uint32_t v, std::uint32_t u) {
    std::uint32_t s = v;
    while (next_[s] != kNoSlot) s = next_[s];
    next_[s] = u;
  }

  /// Keeps the triangles of v's list for which keep(t) holds, in their order.
  template <class Keep>
  void pack(std::uint32_t v, Keep keep) {
    // Writing never overtakes reading: a slot is written only after every earlier one is full.
    std::uint32_t to = v, at = 0, room = start_[v + 1] - start_[v];
    for (std::uint32_t s = v; s != kNoSlot; s = next_[s]) {
      const std::uint32_t* from = pool_.data() + start_[s];
      for (std::uint32_t i = 0, n = size_[s]; i < n; ++i) {
        const std::uint32_t t = from[i];
        if (!keep(t)) continue;
        while (at == room) size_[to] = at, to = next_[to], at = 0, room = start_[to + 1] - start_[to];
        pool_[start_[to] + at++] = t;
      }
    }
    size_[to] = at, next_[to] = kNoSlot;
  }

 private:
  void allocate(const std::vector<std::uint32_t>& sizes) {
    const std::size_t n = sizes.size();
    std::vector<std::uint32_t>().swap(pool_);
    start_.assign(n + 1, 0);
    std::partial_sum(sizes.begin(), sizes.end(), start_.begin() + 1);
    size_ = sizes;
    next_.assign(n, kNoSlot);
    pool_.resize(start_[n]);
  }

  // Per slot its first place in the pool (and the end), its triangles, the next slot in its chain.
  std::vector<std::uint32_t> start_, size_, next_, pool_;
};

// Garland & Heckbert's quadric edge collapse (SIGGRAPH 1997) over the whole interface complex
// at once, with the optimal placement of the merged vertex, constrained so the complex stays a
// partition: a vertex inside one interface merges with a neighbour inside the same interface
// (placed where the summed quadric is least) or moves onto a junction-curve neighbour (which
// stays put); a vertex on a junction curve merges only with its neighbours along that curve
// (placed on the segment between them where the quadric is least); where curves meet, and at
// vertices whose triangles do not form one fan, nothing moves. Merging vertices maps every
// region's closed surface onto a closed surface, so closed stays closed and shared stays shared.
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
  ComplexDecimator(InterfaceComplex& x, double tolerance)
      : x_(x), tol2_(tolerance * tolerance), reach_(kReach * tolerance), reach_out_(reach_) {}

  // Numbered by block first, so every later array is read block by block; the triangle lists,
  // kinds and quadrics before any collapse reads them; then the three passes (blocks, halves,
  // seam: above) and the compaction the caller sees.
  void run() {
    order_by_block();
    vertex_triangles();
    absorbed_lists();
    classify();
    init_quadrics();
    decimate_blocks();
    decimate_halves();
    decimate_seam();
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
    Vec3 times(const Vec3& p) const {
      return {a[0] * p[0] + a[1] * p[1] + a[2] * p[2], a[1] * p[0] + a[3] * p[1] + a[4] * p[2],
              a[2] * p[0] + a[4] * p[1] + a[5] * p[2]};
    }
    double eval(const Vec3& p) const {
      return dot(p, times(p)) - 2 * (b[0] * p[0] + b[1] * p[1] + b[2] * p[2]) + c;
    }
    // The same quadric about an origin moved by d (p - d in place of p).
    void move_origin(const Vec3& d) {
      const Vec3 ad = times(d);
      c += dot(d, ad) - 2 * (b[0] * d[0] + b[1] * d[1] + b[2] * d[2]);
      for (int i = 0; i < 3; ++i) b[i] -= ad[i];
    }
  };
  // A vertex's quadric as kept: in float, about the vertex's position, where the distances that
  // matter (a fraction of a voxel) keep their digits; 44 bytes instead of 88.
  struct StoredQuadric {
    float a[6], b[3], c, w;
  };
  // A queued edge. Every change to an end queues its edges again, so an entry whose edge now
  // plans into another bucket (or not at all) is stale and skipped: the fresh entry is elsewhere.
  struct Candidate {
    std::uint32_t a, b;
  };
  static constexpr std::size_t kBuckets = 2048;
  // A triangle a collapse moves or removes, with its corners before.
  struct Moved {
    std::uint32_t t;
    std::array<std::uint32_t, 3> corners;
  };
  // An input vertex's place after a collapse: its owner's list, or (marked kTriangle) a
  // triangle's, with the owner's corner there.
  struct Staged {
    std::uint32_t i, to;
    std::uint8_t corner;
  };
  // Cheapest first, by buckets of the cost (a bucket queue: a heap of the few million
  // candidates, most of them stale, costs more than the collapses). Within a bucket the last
  // pushed goes first. Also the scratch lists of one pass.
  struct Queue {
    std::vector<std::vector<Candidate>> buckets = std::vector<std::vector<Candidate>>(kBuckets);
    std::size_t lowest = kBuckets;
    double limit2 = 0;  // the pass's largest cost
    std::vector<std::uint32_t> nu, nv, common, apex;
    // A collapse's check (stays_near): its ends (the merged vertex v, the gone one u), whether v
    // moves, the pass's scope; v's triangles after the collapse (corners, corner ids, triangle
    // ids), its neighbours then, the triangles the collapse moves or removes, the input vertices
    // it places again (and their positions), the one nearest p and the last one the output check
    // found near a sample.
    std::uint32_t merged = 0, gone = 0, scope = 0;
    bool v_moves = false;
    std::vector<std::array<Vec3, 3>> fan;
    std::vector<std::array<std::uint32_t, 3>> fan_ids;
    std::vector<std::uint32_t> fan_tri, spokes;
    std::vector<Moved> moved;
    std::vector<Staged> staged;
    std::vector<Vec3> staged_at;
    Vec3 nearest{}, hit{};
    double nearest2 = 0;
    bool moved_end(std::uint32_t w) const { return w == merged || w == gone; }
  };
  // Blocks of kBlock³ voxels; a pass's scope is a part's number or the whole complex. The
  // blocks merge up to kBlockShare of the tolerance: 55 % of the JHU atlas's merges at 0.1,
  // 73 % at 0.2, with distances within the spread that reordering near-equal merges of one
  // pass over the whole gives (bench/RESULTS.md); more makes the blocks' seams show.
  static constexpr double kBlock = 16, kBlockShare = 0.2;
  static constexpr std::uint32_t kEverywhere = ~0u, kBorder = ~0u - 1;
  // The end of an input list; the mark of a triangle's number among places (Staged).
  static constexpr std::uint32_t kNone = ~0u, kTriangle = 1u << 31;

  // Per vertex its triangles in triangle order.
  void vertex_triangles() {
    const std::size_t nv = x_.positions.size();
    tris_of_.build(nv, x_.triangles);
    tri_alive_.assign(x_.triangles.size(), 1);
    alive_.assign(nv, 1);
  }

  // Every input vertex in its own list (numbered as after order_by_block), in float: the bound
  // is a fraction of a voxel; and the output check's reach.
  void absorbed_lists() {
    const std::size_t nv = x_.positions.size();
    MLFE_CHECK(nv < kTriangle && x_.triangles.size() < kTriangle);
    input_.resize(nv);
    for (std::size_t v = 0; v < nv; ++v)
      for (int c = 0; c < 3; ++c) input_[v][c] = float(x_.positions[v][c]);
    next_input_.assign(nv, kNone);
    corner_.assign(nv, 0);
    vertex_list_.resize(nv);
    std::iota(vertex_list_.begin(), vertex_list_.end(), 0u);
    triangle_list_.assign(x_.triangles.size(), kNone);
    // The input is represented by its vertices: a new triangle's sample within reach_ of the input
    // surface may be up to about half an edge from the nearest one.
    double sum = 0;
    for (const auto& t : x_.triangles)
      for (int k = 0; k < 3; ++k) sum += distance(x_.positions[t[k]], x_.positions[t[(k + 1) % 3]]);
    const double mean_edge = x_.triangles.empty() ? 0.0 : sum / (3.0 * double(x_.triangles.size()));
    reach_out_ = reach_ + kOutSlack * mean_edge;
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
            for (auto t : tris_of_.of(v))
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
    for (auto t : tris_of_.of(v)) {
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

  // Per vertex the sum of its triangles' area-weighted plane quadrics, in triangle order, about
  // the vertex.
  void init_quadrics() {
    q_.resize(x_.positions.size());
    tbb::parallel_for(
        tbb::blocked_range<std::size_t>(0, q_.size(), 4096), [&](const tbb::blocked_range<std::size_t>& r) {
          for (std::size_t v = r.begin(); v != r.end(); ++v) {
            Quadric sum;
            for (auto t : tris_of_.of(std::uint32_t(v))) {
              const auto& tri = x_.triangles[t];
              const Vec3 &p0 = x_.positions[tri[0]], &p1 = x_.positions[tri[1]], &p2 = x_.positions[tri[2]];
              Vec3 n = cross(sub(p1, p0), sub(p2, p0));
              const double len = std::sqrt(dot(n, n));
              if (!(len > 0)) continue;
              const double area = len / 2;
              for (auto& c : n) c /= len;
              const double d = -dot(n, sub(p0, x_.positions[v]));
              // area * (n.p + d)^2
              Quadric q;
              q.a[0] = area * n[0] * n[0], q.a[1] = area * n[0] * n[1], q.a[2] = area * n[0] * n[2];
              q.a[3] = area * n[1] * n[1], q.a[4] = area * n[1] * n[2], q.a[5] = area * n[2] * n[2];
              for (int c = 0; c < 3; ++c) q.b[c] = -area * d * n[c];
              q.c = area * d * d;
              q.w = area;
              sum.add(q);
            }
            store_quadric(std::uint32_t(v), sum);
          }
        });
  }

  // v's quadric about `origin`.
  Quadric quadric_about(std::uint32_t v, const Vec3& origin) const {
    const StoredQuadric& s = q_[v];
    Quadric q;
    for (int i = 0; i < 6; ++i) q.a[i] = s.a[i];
    for (int i = 0; i < 3; ++i) q.b[i] = s.b[i];
    q.c = s.c, q.w = s.w;
    if (origin != x_.positions[v]) q.move_origin(sub(origin, x_.positions[v]));
    return q;
  }

  // Keeps q (about v's position) as v's quadric.
  void store_quadric(std::uint32_t v, const Quadric& q) {
    StoredQuadric& s = q_[v];
    for (int i = 0; i < 6; ++i) s.a[i] = float(q.a[i]);
    for (int i = 0; i < 3; ++i) s.b[i] = float(q.b[i]);
    s.c = float(q.c), s.w = float(q.w);
  }

  // Each block's inside alone, the cheap merges only: most merges of the complex, where the
  // order hardly matters, in parallel and in cache. The block numbers are not needed after.
  void decimate_blocks() {
    const std::vector<std::vector<std::uint32_t>> blocks = block_insides(cell_);
    std::vector<std::uint64_t>().swap(cell_);
    decimate_parts(blocks, tol2_ * kBlockShare * kBlockShare);
  }

  // Each half of the complex alone (below and above its vertices' median height), up to the
  // tolerance: the merges that shape the result, both halves at once, on the live vertices
  // renumbered for a smaller working set.
  void decimate_halves() {
    renumber_alive();
    decimate_parts(block_insides(halves()), tol2_);
  }

  // The whole complex, for the seam between the halves.
  void decimate_seam() {
    std::vector<std::uint32_t> all(x_.positions.size());
    std::iota(all.begin(), all.end(), 0u);
    Queue q;
    q.limit2 = tol2_;
    decimate(all, kEverywhere, q);
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
                          for (auto t : tris_of_.of(v))
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
    std::vector<Vec3> positions(nv);
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

  // One pass: the edges of `vertices` within `scope` queued, then collapsed cheapest first.
  void decimate(const std::vector<std::uint32_t>& vertices, std::uint32_t scope, Queue& q) {
    queue_edges(vertices, scope, q);
    collapse_cheapest(scope, q);
  }

  // Every edge of `vertices` within `scope` queued once, from its lower vertex, in vertex order
  // (the order breaks ties between equal costs, so it is a function of the numbering alone).
  void queue_edges(const std::vector<std::uint32_t>& vertices, std::uint32_t scope, Queue& q) {
    for (auto v : vertices) {
      neighbours(v, q.nv);
      for (auto w : q.nv)
        if (w > v && in_scope(w, scope)) push(v, w, q);
    }
  }

  // Collapses the queued edges cheapest first while within the pass's limit; each collapse
  // queues its survivor's edges again, and stale entries (an end gone, or a cost that moved to
  // another bucket) are skipped.
  void collapse_cheapest(std::uint32_t scope, Queue& q) {
    for (;;) {
      while (q.lowest < kBuckets && q.buckets[q.lowest].empty()) ++q.lowest;
      if (q.lowest == kBuckets) break;
      const Candidate c = q.buckets[q.lowest].back();
      q.buckets[q.lowest].pop_back();
      if (!alive_[c.a] || !alive_[c.b]) continue;
      std::uint32_t from = 0, to = 0;
      Vec3 p{};
      const double cost = plan(c.a, c.b, from, to, p);
      if (!(cost <= q.limit2) || bucket_of(cost, q) != q.lowest) continue;
      if (collapsible(from, to, p, scope, q)) collapse(from, to, p, scope, q);
    }
  }

  // The triangles on edge {a, b} and whether it lies on a junction curve (not exactly two
  // triangles of one interface).
  bool junction_edge(std::uint32_t a, std::uint32_t b) const {
    int n = 0;
    std::uint32_t pair = 0;
    bool same = true;
    for (auto t : tris_of_.of(a)) {
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
  static Vec3 best_on_segment(const Quadric& q, const Vec3& a, const Vec3& b) {
    const Vec3 d = sub(b, a);
    const Vec3 ad{q.a[0] * d[0] + q.a[1] * d[1] + q.a[2] * d[2],
                  q.a[1] * d[0] + q.a[3] * d[1] + q.a[4] * d[2],
                  q.a[2] * d[0] + q.a[4] * d[1] + q.a[5] * d[2]};
    const double dad = dot(d, ad);
    double t = 0.5;
    if (dad > 1e-18)
      t = std::clamp(((q.b[0] * d[0] + q.b[1] * d[1] + q.b[2] * d[2]) - dot(a, ad)) / dad, 0.0, 1.0);
    return {a[0] + t * d[0], a[1] + t * d[1], a[2] + t * d[2]};
  }

  // The least of q over space when well conditioned and near the edge, else on the segment.
  static Vec3 best_point(const Quadric& q, const Vec3& a, const Vec3& b) {
    const double* m = q.a;
    const double c00 = m[3] * m[5] - m[4] * m[4], c01 = m[2] * m[4] - m[1] * m[5],
                 c02 = m[1] * m[4] - m[2] * m[3];
    const double det = m[0] * c00 + m[1] * c01 + m[2] * c02;
    const double scale = m[0] + m[3] + m[5];
    if (scale > 0 && std::abs(det) > 1e-3 * scale * scale * scale) {
      const double c11 = m[0] * m[5] - m[2] * m[2], c12 = m[1] * m[2] - m[0] * m[4],
                   c22 = m[0] * m[3] - m[1] * m[1];
      const Vec3 p{(c00 * q.b[0] + c01 * q.b[1] + c02 * q.b[2]) / det,
                   (c01 * q.b[0] + c11 * q.b[1] + c12 * q.b[2]) / det,
                   (c02 * q.b[0] + c12 * q.b[1] + c22 * q.b[2]) / det};
      const Vec3 mid{(a[0] + b[0]) / 2, (a[1] + b[1]) / 2, (a[2] + b[2]) / 2}, ab = sub(b, a),
                                                                               pm = sub(p, mid);
      if (dot(pm, pm) <= dot(ab, ab)) return p;
    }
    return best_on_segment(q, a, b);
  }

  // The allowed collapse of edge {a, b} (which end goes, where the other moves) and its cost:
  // the summed quadric per unit area (a mean squared distance to the merged planes) at the
  // placement. Infinite when the edge may not collapse.
  double plan(std::uint32_t a, std::uint32_t b, std::uint32_t& from, std::uint32_t& to, Vec3& p) const {
    constexpr double kNever = std::numeric_limits<double>::infinity();
    const Kind ka = kind_[a], kb = kind_[b];
    if (ka == kFixed && kb == kFixed) return kNever;
    // About a's position: the edge runs from 0 to ab.
    const Vec3& origin = x_.positions[a];
    Quadric q = quadric_about(a, origin);
    q.add(quadric_about(b, origin));
    const Vec3 zero{}, ab = sub(x_.positions[b], origin);
    Vec3 at{};
    if (ka == kInterior && kb == kInterior) {
      at = best_point(q, zero, ab);
      from = std::max(a, b), to = std::min(a, b);
    } else if (ka == kInterior || kb == kInterior) {
      from = ka == kInterior ? a : b, to = ka == kInterior ? b : a;
      at = to == a ? zero : ab;
    } else {
      // Both on curves (or one where curves meet): only along a junction curve.
      if (!junction_edge(a, b)) return kNever;
      if (ka == kCurve && kb == kCurve) {
        at = best_on_segment(q, zero, ab);
        from = std::max(a, b), to = std::min(a, b);
      } else {
        from = ka == kCurve ? a : b, to = ka == kCurve ? b : a;
        at = to == a ? zero : ab;
      }
    }
    p = at == zero ? origin : at == ab ? x_.positions[b] : add(origin, at);
    return q.w > 0 ? std::max(0.0, q.eval(at)) / q.w : 0.0;
  }

  // Queues the collapse of edge {a, b} when it is allowed and within the tolerance.
  void push(std::uint32_t a, std::uint32_t b, Queue& q) const {
    std::uint32_t from = 0, to = 0;
    Vec3 p{};
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
    tris_of_.pack(v, [&](std::uint32_t t) {
      if (!tri_alive_[t]) return false;
      for (auto w : x_.triangles[t])
        if (w != v) out.push_back(w);
      return true;
    });
    std::sort(out.begin(), out.end());
    out.erase(std::unique(out.begin(), out.end()), out.end());
  }

  // Topology (the link condition: the common neighbours of the two ends are exactly the apexes
  // of the triangles on the edge; no closed piece below a tetrahedron; a junction curve keeps at
  // least three vertices per loop) and geometry (no triangle flips or degenerates).
  bool collapsible(std::uint32_t u, std::uint32_t v, const Vec3& p, std::uint32_t scope, Queue& q) {
    neighbours(u, q.nu);
    neighbours(v, q.nv);
    if (q.nu.size() <= 3 && q.nv.size() <= 3) return false;
    q.common.clear();
    std::set_intersection(q.nu.begin(), q.nu.end(), q.nv.begin(), q.nv.end(), std::back_inserter(q.common));
    q.apex.clear();
    for (auto t : tris_of_.of(u)) {
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
    return !flips(u, v, p) && !flips(v, u, p) && stays_near(u, v, p, scope, q);
  }

  // Whether the collapse keeps the result near its input both ways.
  //
  // Input -> output: every input vertex stays within reach_ of a triangle of the live vertex
  // that absorbed it (its owner). The quadric is a mean over infinite planes, so a tip, a thin
  // sheet's rim or a junction corner can be cut off at a small mean cost while the input points
  // there end voxels away. Each input vertex is kept in one list that says why it is near: its
  // owner's (within reach_ of the owner's position, so of all its triangles) or a triangle's
  // (within reach_ of that triangle, owned by one of its corners). A collapse moves u, the
  // triangles of u, and v and its triangles when v moves, so only those lists are looked at
  // again: the input vertices of u and v, and those of the one-ring kept by a triangle that moves
  // (their triangles move with p: without re-checking them, 2 mm atlas: Hausdorff 1.23 instead
  // of 1.06 voxels). A ring vertex's input vertex goes to its owner's list or to one of the
  // owner's triangles at p: the lists a part's collapses write are then those of its own
  // vertices and of the triangles at them, never another part's. The new places wait in the
  // queue until the collapse is made.
  //
  // Output -> input: each new triangle's corners, edge midpoints and centroid lie within
  // reach_out_ of an input vertex, looked for among those of the merged vertex and its
  // neighbours: a new triangle may run across a fold away from every input point. Only what the
  // collapse moves is checked: p, the midpoints of the edges at p and the centroids of the
  // triangles at p; an edge opposite p keeps its midpoint since it was last checked.
  bool stays_near(std::uint32_t u, std::uint32_t v, const Vec3& p, std::uint32_t scope, Queue& q) const {
    merged_fan(u, v, p, q);
    q.scope = scope;
    if (q.fan.empty()) return false;
    q.staged.clear(), q.staged_at.clear();
    q.nearest2 = std::numeric_limits<double>::infinity();
    if (!placed_again(vertex_list_[u], nullptr, p, q)) return false;
    if (q.v_moves && !placed_again(vertex_list_[v], nullptr, p, q)) return false;
    for (const auto& m : q.moved)
      if (!placed_again(triangle_list_[m.t], &m.corners, p, q)) return false;
    return fan_near_input(u, v, p, q);
  }

  // The merged vertex's triangles once u merges into v at p (corners, corner ids with v for u,
  // triangle ids) in the queue's fan, its neighbours then in `spokes`, and the triangles the
  // collapse moves or removes (u's, and v's when v moves) with their corners before in `moved`.
  void merged_fan(std::uint32_t u, std::uint32_t v, const Vec3& p, Queue& q) const {
    q.v_moves = p != x_.positions[v], q.merged = v, q.gone = u;
    q.fan.clear(), q.fan_ids.clear(), q.fan_tri.clear(), q.moved.clear(), q.spokes.clear();
    for (std::uint32_t w : {u, v})
      for (auto t : tris_of_.of(w)) {
        if (!tri_alive_[t]) continue;
        const auto& tri = x_.triangles[t];
        const bool has_u = tri[0] == u || tri[1] == u || tri[2] == u,
                   has_v = tri[0] == v || tri[1] == v || tri[2] == v;
        if (w == u || (q.v_moves && !has_u)) q.moved.push_back({t, tri});
        if (has_u && (w == v || has_v)) continue;  // seen from u, or on the edge (removed)
        std::array<Vec3, 3> corners;
        std::array<std::uint32_t, 3> ids;
        for (int k = 0; k < 3; ++k) {
          const bool moved = tri[k] == u || tri[k] == v;
          corners[k] = moved ? p : x_.positions[tri[k]];
          ids[k] = moved ? v : tri[k];
          if (!moved && std::find(q.spokes.begin(), q.spokes.end(), tri[k]) == q.spokes.end())
            q.spokes.push_back(tri[k]);
        }
        q.fan.push_back(corners), q.fan_ids.push_back(ids), q.fan_tri.push_back(t);
      }
  }

  // Whether every input vertex of a list (first `i`: an owner's when `corners` is null, else a
  // moved triangle's with its corners before) has a place once the collapse is made, staged in
  // the queue; keeps the one nearest p.
  bool placed_again(std::uint32_t i, const std::array<std::uint32_t, 3>* corners, const Vec3& p,
                    Queue& q) const {
    const double reach2 = reach_ * reach_;
    std::array<double, 3> bary{};
    for (; i != kNone; i = next_input_[i]) {
      const Vec3 x = to_vec3(input_[i]);
      const double to_p = distance2(p, x);
      if (to_p < q.nearest2) q.nearest2 = to_p, q.nearest = x;
      // The owner after the collapse (u's and v's are the merged vertex).
      std::uint32_t owner = corners ? (*corners)[corner_[i]] : q.merged;
      if (corners && q.moved_end(owner)) owner = q.merged;
      Staged s{i, kNone, 0};
      if (owner == q.merged ? to_p <= reach2 : distance2(x_.positions[owner], x) <= reach2) {
        s.to = owner;
      } else {
        for (std::size_t f = 0; f < q.fan.size() && s.to == kNone; ++f) {
          const auto& ids = q.fan_ids[f];
          const int k = ids[0] == owner ? 0 : ids[1] == owner ? 1 : ids[2] == owner ? 2 : 3;
          if (k == 3) continue;
          const auto& c = q.fan[f];
          if (distance2(closest_point_on_triangle(x, c[0], c[1], c[2], bary), x) <= reach2)
            s.to = q.fan_tri[f] | kTriangle, s.corner = std::uint8_t(k);
        }
        if (s.to == kNone && owner != q.merged) s = placed_by_ring_triangle(i, x, owner, q);
        if (s.to == kNone) return false;
      }
      q.staged.push_back(s), q.staged_at.push_back(x);
    }
    return true;
  }

  // Input vertex i at x, owned by ring vertex w, placed in one of w's triangles away from p
  // (kNone: none within reach_) whose corners are w and vertices inside the pass's part: another
  // part's collapses never write such a triangle's list.
  Staged placed_by_ring_triangle(std::uint32_t i, const Vec3& x, std::uint32_t w, const Queue& q) const {
    const double reach2 = reach_ * reach_;
    std::array<double, 3> bary{};
    for (auto t : tris_of_.of(w)) {
      if (!tri_alive_[t]) continue;
      const auto& tri = x_.triangles[t];
      int k = 3;
      bool ours = true;
      for (int c = 0; c < 3; ++c) {
        if (tri[c] == w) k = c;
        ours &= tri[c] == w || (!q.moved_end(tri[c]) && in_scope(tri[c], q.scope));
      }
      if (!ours) continue;
      const Vec3 &a = x_.positions[tri[0]], &b = x_.positions[tri[1]], &c = x_.positions[tri[2]];
      if (distance2(closest_point_on_triangle(x, a, b, c, bary), x) <= reach2)
        return {i, t | kTriangle, std::uint8_t(k)};
    }
    return {i, kNone, 0};
  }

  static double distance2(const Vec3& a, const Vec3& b) {
    const Vec3 d = sub(a, b);
    return dot(d, d);
  }

  // Whether what the collapse moves of the merged vertex's triangles (the queue's fan) lies near
  // the input: p, the midpoints of the edges at p and the centroids (near_input).
  bool fan_near_input(std::uint32_t u, std::uint32_t v, const Vec3& p, Queue& q) const {
    q.hit = q.nearest;
    if (!near_input(p, {v, kNone, kNone}, u, q)) return false;
    for (auto a : q.spokes)
      if (!near_input(scale(add(p, x_.positions[a]), 0.5), {v, a, kNone}, u, q)) return false;
    for (std::size_t f = 0; f < q.fan.size(); ++f) {
      const auto& c = q.fan[f];
      const auto& ids = q.fan_ids[f];
      const Vec3 centroid{(c[0][0] + c[1][0] + c[2][0]) / 3, (c[0][1] + c[1][1] + c[2][1]) / 3,
                          (c[0][2] + c[1][2] + c[2][2]) / 3};
      if (!near_input(centroid, ids, u, q)) return false;
    }
    return true;
  }

  // Whether s lies within reach_out_ of an input vertex: the last one found near a sample (at
  // first the one nearest p) and those the collapse places again, then those that `owners`
  // (kNone: none; the merged vertex stands for u too) absorbed, in their lists the collapse does
  // not move.
  bool near_input(const Vec3& s, const std::array<std::uint32_t, 3>& owners, std::uint32_t u,
                  Queue& q) const {
    const double reach2 = reach_out_ * reach_out_;
    auto hit = [&](const Vec3& x) { return distance2(s, x) <= reach2 && (q.hit = x, true); };
    if (hit(q.hit)) return true;
    for (const auto& x : q.staged_at)
      if (hit(x)) return true;
    for (auto w : owners) {
      if (w == kNone || (w == q.merged && q.v_moves)) continue;  // all placed again
      for (std::uint32_t i = vertex_list_[w]; i != kNone; i = next_input_[i])
        if (hit(to_vec3(input_[i]))) return true;
      for (auto t : tris_of_.of(w)) {
        const auto& tri = x_.triangles[t];
        if (!tri_alive_[t] || tri[0] == u || tri[1] == u || tri[2] == u) continue;
        if (q.v_moves && (tri[0] == q.merged || tri[1] == q.merged || tri[2] == q.merged)) continue;
        for (std::uint32_t i = triangle_list_[t]; i != kNone; i = next_input_[i])
          if (tri[corner_[i]] == w && hit(to_vec3(input_[i]))) return true;
      }
    }
    return false;
  }

  // Whether moving `v` to `p` (with `other` merged into it) flips or flattens a triangle of v
  // that survives.
  bool flips(std::uint32_t v, std::uint32_t other, const Vec3& p) const {
    for (auto t : tris_of_.of(v)) {
      if (!tri_alive_[t]) continue;
      const auto& tri = x_.triangles[t];
      if (tri[0] == other || tri[1] == other || tri[2] == other) continue;
      Vec3 before[3], after[3];
      for (int k = 0; k < 3; ++k) before[k] = after[k] = x_.positions[tri[k]];
      for (int k = 0; k < 3; ++k)
        if (tri[k] == v) after[k] = p;
      const Vec3 n0 = cross(sub(before[1], before[0]), sub(before[2], before[0]));
      const Vec3 n1 = cross(sub(after[1], after[0]), sub(after[2], after[0]));
      const double l0 = dot(n0, n0), l1 = dot(n1, n1);
      if (!(l1 > 1e-12)) return true;
      if (dot(n0, n1) < kMinCos * std::sqrt(l0 * l1)) return true;
    }
    return false;
  }

  // Merges u into v at p and queues v's edges within `scope` again.
  void collapse(std::uint32_t u, std::uint32_t v, const Vec3& p, std::uint32_t scope, Queue& q) {
    for (auto t : tris_of_.of(u)) {
      if (!tri_alive_[t]) continue;
      auto& tri = x_.triangles[t];
      if (tri[0] == v || tri[1] == v || tri[2] == v) {
        tri_alive_[t] = 0;
        continue;
      }
      for (auto& w : tri)
        if (w == u) w = v;
    }
    tris_of_.append(v, u);
    // The input vertices placed again, in their new lists.
    vertex_list_[u] = kNone;
    if (q.v_moves) vertex_list_[v] = kNone;
    for (const auto& m : q.moved) triangle_list_[m.t] = kNone;
    for (const auto& st : q.staged) {
      std::uint32_t& head = st.to & kTriangle ? triangle_list_[st.to & ~kTriangle] : vertex_list_[st.to];
      next_input_[st.i] = head, head = st.i, corner_[st.i] = st.corner;
    }
    alive_[u] = 0;
    Quadric merged = quadric_about(v, p);
    merged.add(quadric_about(u, p));
    x_.positions[v] = p;
    store_quadric(v, merged);
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
    keep(vertex_list_, copy);
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
    std::vector<std::uint32_t> lists(m);
    for (std::size_t t = 0; t < nt; ++t)
      if (tmap[t] != ~0u) lists[tmap[t]] = triangle_list_[t];
    triangle_list_.swap(lists);
    // Fresh lists, each part's next to each other.
    std::vector<std::uint32_t> sizes(n, 0);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nv, 4096),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        for (std::size_t o = r.begin(); o != r.end(); ++o)
                          if (rank[o] != ~0u)
                            for (auto t : tris_of_.of(at[o])) sizes[rank[o]] += tri_alive_[t];
                      });
    std::vector<std::uint32_t> old_of(n);
    for (std::size_t o = 0; o < nv; ++o)
      if (rank[o] != ~0u) old_of[rank[o]] = at[o];
    TriangleLists fresh;
    fresh.assign(sizes, [&](std::size_t v, std::uint32_t* out) {
      for (auto t : tris_of_.of(old_of[v]))
        if (tri_alive_[t]) *out++ = tmap[t];
    });
    tris_of_ = std::move(fresh);
    tri_alive_.assign(m, 1);
  }

  // Drops dead triangles and unused vertices; vertices numbered in first use.
  void compact() {
    std::vector<std::array<std::uint32_t, 3>> tris;
    std::vector<std::array<std::uint16_t, 2>> labels;
    for (std::size_t t = 0; t < x_.triangles.size(); ++t)
      if (tri_alive_[t]) tris.push_back(x_.triangles[t]), labels.push_back(x_.labels[t]);
    std::vector<std::uint32_t> remap(x_.positions.size(), ~0u);
    std::vector<Vec3> positions;
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
  // How far (in tolerances) an absorbed input vertex may end from the triangles of the vertex
  // that absorbed it. The tolerance bounds a mean over the absorbed planes, so a worst point a
  // half more: on the atlases (0.34 voxel) the worst Hausdorff to the voxel boundary went from
  // 1.9 to 1.2-1.6 voxels for 2-3 % more triangles (issue #40's notes).
  static constexpr double kReach = 1.5;
  // How much further than reach_ a new triangle's sample may lie from the nearest input vertex,
  // in mean input edge lengths (0.5 voxel on the atlases' complexes, 1 when clustered). Measured
  // on the 1 / 2 / 0.5 mm atlases at tolerance 0.34: a slack of 0.5 voxel gives worst Hausdorff
  // 1.59 / 1.06 / 1.56 voxels, 0.25 voxel 1.33 / 1.09 / 1.64, 0.1 voxel (this) 1.13 / 1.08 / 1.53
  // for 1 % more triangles than 0.5.
  static constexpr double kOutSlack = 0.2;
  InterfaceComplex& x_;
  const double tol2_, reach_;
  double reach_out_;
  std::vector<Kind> kind_;
  std::vector<char> alive_, tri_alive_;
  TriangleLists tris_of_;
  std::vector<StoredQuadric> q_;
  std::vector<std::uint32_t> scope_;
  std::vector<std::uint64_t> cell_;
  std::vector<std::uint32_t> original_;
  // Per input vertex its position, the next input vertex in its list and its owner's corner in
  // its triangle (triangle lists); per live vertex and per triangle the first input vertex of its
  // list (stays_near).
  std::vector<std::array<float, 3>> input_;
  std::vector<std::uint32_t> next_input_, vertex_list_, triangle_list_;
  std::vector<std::uint8_t> corner_;
  // Per thread the pass's queue, kept for the next pass (its buckets' storage).
  tbb::enumerable_thread_specific<Queue> queues_;
};

}  // namespace

std::size_t decimate_interface_complex(InterfaceComplex& x, double tolerance) {
  if (!(tolerance > 0) || !std::isfinite(tolerance))
    throw Error("simplification tolerance must be positive and finite (got " + std::to_string(tolerance) +
                ")");
  const std::size_t before = x.positions.size();
  ComplexDecimator(x, tolerance).run();
  return before - x.positions.size();
}

}  // namespace mlfe
