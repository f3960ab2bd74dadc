// Error-bounded mesh simplification by edge collapses (half-edge, or to the quadric minimum).
//
// - Ordering: Garland & Heckbert, "Surface Simplification Using Quadric Error Metrics",
//   SIGGRAPH 1997 (area-weighted plane quadrics, summed into the surviving vertex).
// - Bound: Klein, Liebich & Straßer, "Mesh Reduction with Error Control", IEEE Visualization
//   1996: every input vertex stays attached to a face of the current mesh within the
//   tolerance; a collapse re-homes the points of the faces it changes and is refused when one
//   of them finds no face close enough. This is what OpenMesh's ModHausdorff does; doing it on
//   flat arrays made the MRI's 470 k-triangle surfaces about ten times faster to simplify.
// - Topology: the link condition (Dey, Edelsbrunner, Guha & Nekhayev, "Topology preserving
//   edge contraction", 1999), with boundary vertices joined to a virtual vertex.
//
// Placement (optional): the survivor moves to the minimum of the merged quadrics (Garland &
// Heckbert's optimal placement); as their full-edge collapses it removes more triangles at the
// same bound, since the surface is no longer pinned to input vertices. The bound then also
// holds the other way round: a moved vertex stays within the tolerance of the input surface.
// Boundary vertices never move, and one is only removed within the tolerance of the boundary
// edge that replaces it (the one-sided bound alone lets rim edges cut across concave bays).
//
// Parallel and deterministic, in passes. Each pass (1) computes a cheap key (the quadric cost of
// the best-looking neighbour) for every vertex whose one-ring changed, (2) walks the vertices
// by key and picks greedily those whose closed one-rings are disjoint from the rings already
// picked, (3) collapses the picked vertices in parallel, each onto the cheapest neighbour that
// passes the topology, normal and distance checks. Disjoint rings (two-rings when survivors
// move) make the collapses independent: none writes a face, a point, a position or a quadric
// another one reads, so each sees the pass's starting state and the result does not depend on
// the order or the thread count.
// A vertex that passes no check is stuck until something near it changes. Once most picked
// vertices turn out stuck (late, when the bound binds), every candidate is checked up front in
// parallel instead, so stuck vertices stop blocking their neighbours' rings.
// With an estimated bound on big meshes the passes are preceded by blocks (as complex_decimator.cpp
// does for interface complexes): cubes of space, each simplified on its own, sequentially,
// cheapest collapse first, with both ends of every collapse inside the cube; then the cubes
// shifted by half their edge, whose insides hold the first cubes' seams. Blocks share nothing a
// collapse reads or writes, so they run in parallel with the same result for any thread count.
// On a full head's 1.4 M triangles they do 99 % of the collapses, and the passes (28 instead of
// 76) the rest, without the per-pass scans of the sorted candidates that made them slow
// (bench/RESULTS.md).
//
// Local numbering of a collapse v0 -> v1 (v0 disappears; faces around v0 not containing v1
// get v1 in its place, the one or two faces on edge v0 v1 are removed; with optimal placement
// v1 then moves to p, so v1's other faces change shape too):
//
//          a                     a
//        /   \                 /   |
//      v0 --- v1      ->         v1
//        \   /                 \   |
//          b                     b
// (v0's other neighbours keep their faces, now fanned around v1.)
#include <mlfe/core/base/check.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/simplify/surface_simplification.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <initializer_list>
#include <iterator>
#include <limits>
#include <memory>
#include <queue>
#include <string>
#include <vector>

namespace mlfe {
namespace {

using Vec3 = Eigen::Vector3d;
using Index = std::uint32_t;
constexpr Index kNone = std::numeric_limits<Index>::max();
constexpr double kNoKey = std::numeric_limits<double>::infinity();

// Symmetric 4x4 plane quadric: xx xy xz xw yy yz yw zz zw ww.
struct Quadric {
  std::array<double, 10> q{};
  void add_plane(const Vec3& n, double d, double w) {
    const double a = n.x(), b = n.y(), c = n.z();
    const double v[10] = {a * a, a * b, a * c, a * d, b * b, b * c, b * d, c * c, c * d, d * d};
    for (int i = 0; i < 10; ++i) q[i] += w * v[i];
  }
  void add(const Quadric& o) {
    for (int i = 0; i < 10; ++i) q[i] += o.q[i];
  }
  // The summed plane weights (the planes' normals are unit vectors).
  double weight() const { return q[0] + q[4] + q[7]; }
  double eval(const Vec3& p) const {
    const double x = p.x(), y = p.y(), z = p.z();
    return q[0] * x * x + 2 * q[1] * x * y + 2 * q[2] * x * z + 2 * q[3] * x + q[4] * y * y +
           2 * q[5] * y * z + 2 * q[6] * y + q[7] * z * z + 2 * q[8] * z + q[9];
  }
};

double eval_sum(const Quadric& a, const Quadric& b, const Vec3& p) { return a.eval(p) + b.eval(p); }

// Squared distance from p to triangle abc (Ericson, Real-Time Collision Detection, 5.1.5).
double point_triangle_distance2(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return ap.squaredNorm();
  const Vec3 bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return bp.squaredNorm();
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return (ap - ab * (d1 / (d1 - d3))).squaredNorm();
  const Vec3 cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return cp.squaredNorm();
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return (ap - ac * (d2 / (d2 - d6))).squaredNorm();
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0)
    return (bp - (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)))).squaredNorm();
  const double denom = 1.0 / (va + vb + vc);
  return (ap - ab * (vb * denom) - ac * (vc * denom)).squaredNorm();
}

// Compressed rows: items of row r are items[offset[r] .. offset[r + 1]).
struct Csr {
  std::vector<Index> offset, items;
  std::size_t size(Index r) const { return offset[r + 1] - offset[r]; }
  const Index* begin(Index r) const { return items.data() + offset[r]; }
  const Index* end(Index r) const { return items.data() + offset[r + 1]; }
};

// Storage that never moves what it handed out, so rows can be placed in it by several
// threads, each with its own arena.
class Arena {
 public:
  Index* take(std::size_t n) {
    if (n > left_) {
      const std::size_t size = std::max<std::size_t>(n, std::size_t(1) << 14);
      chunks_.emplace_back(new Index[size]);
      next_ = chunks_.back().get();
      left_ = size;
    }
    Index* p = next_;
    next_ += n;
    left_ -= n;
    used_ += n;
    return p;
  }
  std::size_t used() const { return used_; }

 private:
  std::vector<std::unique_ptr<Index[]>> chunks_;
  Index* next_ = nullptr;
  std::size_t left_ = 0, used_ = 0;
};

// Per-vertex lists that change a few at a time: row r is row[r][0 .. count[r]), with room for
// cap[r] items in place; a row that outgrows its room moves to an arena. The collapses of a
// pass change the stars of a few thousand vertices of hundreds of thousands, so the rows are
// updated where they change instead of being rebuilt every pass.
struct Rows {
  std::vector<Index*> row;
  std::vector<Index> count, cap, items;  // items: the rows as last built, contiguous
  std::size_t size(Index r) const { return count[r]; }
  const Index* begin(Index r) const { return row[r]; }
  const Index* end(Index r) const { return row[r] + count[r]; }
  // Row r := `list`, in place when it fits (else in `arena`, with some room to grow).
  void assign(Index r, const std::vector<Index>& list, Arena& arena) {
    if (list.size() > cap[r]) {
      cap[r] = Index(list.size() + 4);
      row[r] = arena.take(cap[r]);
    }
    std::copy(list.begin(), list.end(), row[r]);
    count[r] = Index(list.size());
  }
  // Drops the items of row r for which dead(item).
  template <class Dead>
  void remove_if(Index r, Dead&& dead) {
    count[r] = Index(std::remove_if(row[r], row[r] + count[r], dead) - row[r]);
  }
};

// Rows built contiguous from (row, item) pairs given in item order: each(add) calls add(r, i)
// for every item, twice (once to count, once to fill), in the same order.
template <class Each>
void build_rows(Rows& rows, std::size_t n, Each&& each) {
  rows.count.assign(n, 0);
  each([&](Index r, Index) { ++rows.count[r]; });
  std::vector<Index> start(n);
  Index total = 0;
  for (std::size_t r = 0; r < n; ++r) {
    start[r] = total;
    total += rows.count[r];
  }
  rows.cap = rows.count;
  rows.items.resize(total);
  rows.row.resize(n);
  for (std::size_t r = 0; r < n; ++r) rows.row[r] = rows.items.data() + start[r];
  each([&](Index r, Index i) { rows.items[start[r]++] = i; });
}

// A neighbour of a vertex and the number of its faces that contain the edge to it
// (1: boundary edge, 2: interior edge, more: non-manifold).
struct Neighbour {
  Index v;
  int faces;
};

// Some edge to a neighbour lies in one face only.
bool on_boundary(const std::vector<Neighbour>& n) {
  return std::any_of(n.begin(), n.end(), [](const Neighbour& x) { return x.faces == 1; });
}

// A collapse being evaluated: v0 moves onto v1, and v1 (with it the merged vertex) sits at p.
struct Move {
  Index v0, v1;
  Vec3 p;
};

// A neighbour a vertex may move onto: the collapse's key and where the survivor goes.
struct Target {
  double cost;
  Index w;
  Vec3 p;
};

// Per-task scratch, reused across the vertices of a chunk.
struct Scratch {
  std::vector<Neighbour> n0, n1;
  std::vector<Target> order;
  Vec3 p;                                 // the last placement evaluated
  std::vector<Index> targets;             // faces around v1 after the collapse
  Move move{kNone, kNone, Vec3::Zero()};  // the last legal move found
  // The costs of the edges of vertex `from` (the blocks' last survivor) whose placement is the
  // same from either end, for its neighbours' keys (see edge_cost()).
  Index from = kNone;
  std::vector<Target> from_costs;
  bool record = false;  // for_each_target() fills from_costs
};

class Simplifier {
 public:
  // Reading the input, then the adjacency, the quadrics, the points of the bound and the locked
  // vertices that every pass reads; every vertex starts dirty, so the first pass keys them all.
  Simplifier(const TriangleMesh& mesh, const SimplifyOptions& opts, SimplifyCarry* carry)
      : opts_(opts), optimal_(opts.placement == Placement::kOptimal), carry_(carry) {
    read_input(mesh);
    build_vertex_faces();
    init_quadrics();
    attach_points();
    classify_vertices();
    start_state();
  }

  // Collapses, then valence-improving flips, which free further collapses, twice. On the MRI's
  // 467 k-triangle surface this gave 2.5 % fewer triangles and a 2.7 % smaller Draco file for
  // 20 % more time; further rounds gained under 0.5 % each.
  TriangleMesh run(SimplifyStats* stats) {
    SimplifyStats st;
    for (int round = 0; round < 2; ++round) {
      // Blocks, then blocks shifted by half their size: the first ones' seams inside the second.
      if (round == 0 && !opts_.verify_bound && faces_.size() >= opts_.blocks_from)
        for (double shift : {0.0, 0.5}) simplify_blocks(shift, st.collapses);
      collapse_all(st.passes, st.collapses);
      if (alive_faces_ <= opts_.min_triangles || !opts_.flip_edges) break;
      if (!flip_round(st.flips)) break;
    }
    if (stats) *stats = st;
    return output();
  }

 private:
  // The faces (triangles with a repeated corner dropped), positions and normals, checked; the
  // copies only the verified bound reads (the input faces with a moving survivor, the input
  // positions as the points kept within the bound).
  void read_input(const TriangleMesh& mesh) {
    const std::size_t nv = mesh.positions.size();
    if (nv >= kNone) throw Error("simplification: too many vertices");
    faces_.reserve(mesh.triangles.size());
    const bool carried = carry_ && !carry_->point_face.empty();
    std::vector<Index> face_of(carried ? mesh.triangles.size() : 0, kNone);
    for (std::size_t i = 0; i < mesh.triangles.size(); ++i) {
      const auto& t = mesh.triangles[i];
      if (t[0] >= nv || t[1] >= nv || t[2] >= nv) throw Error("simplification: triangle index out of range");
      if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2]) continue;
      if (carried) face_of[i] = Index(faces_.size());
      faces_.push_back({t[0], t[1], t[2]});
    }
    if (carried) read_carried_points(face_of);
    if (carry_ && !carry_->locked.empty() && carry_->locked.size() != nv)
      throw Error("simplification: the locked flags are not one per vertex");
    if (faces_.size() >= kNone) throw Error("simplification: too many triangles");
    // The input surface is only read by the verified bound's checks.
    if (optimal_ && opts_.verify_bound) input_faces_ = faces_;
    pos_.resize(nv);
    for (std::size_t i = 0; i < nv; ++i)
      pos_[i] = Vec3(mesh.positions[i][0], mesh.positions[i][1], mesh.positions[i][2]);
    if (opts_.verify_bound) points_ = pos_;
    for (const auto& f : faces_)
      for (Index v : f)
        if (!pos_[v].allFinite()) throw Error("simplification: non-finite vertex position");
    if (!mesh.normals.empty()) {
      if (mesh.normals.size() != nv)
        throw Error("simplification: the mesh has normals for some vertices only");
      normals_ = mesh.normals;
    }
    face_alive_.assign(faces_.size(), 1);
    alive_faces_ = faces_.size();
    tol2_ = opts_.tolerance * opts_.tolerance;
    cos_max_turn_ = std::cos(opts_.max_normal_turn_degrees * 3.14159265358979323846 / 180.0);
  }

  // The bound's points carried in (SimplifyCarry), attached to the faces their input triangles
  // became (`face_of`: per input triangle, its face or kNone).
  void read_carried_points(const std::vector<Index>& face_of) {
    if (!opts_.verify_bound) throw Error("simplification: carried points need the verified bound");
    if (carry_->points.size() != carry_->point_face.size())
      throw Error("simplification: carried points and their triangles differ in number");
    carried_.resize(carry_->points.size());
    carried_owner_.resize(carry_->points.size());
    for (std::size_t p = 0; p < carried_.size(); ++p) {
      const std::uint32_t t = carry_->point_face[p];
      if (t >= face_of.size() || face_of[t] == kNone)
        throw Error("simplification: a carried point's triangle is out of range or degenerate");
      const auto& q = carry_->points[p];
      carried_[p] = Vec3(q[0], q[1], q[2]);
      carried_owner_[p] = face_of[t];
    }
  }

  // Each vertex sums the planes of its faces in face order, in parallel: the same sums for any
  // thread count.
  void init_quadrics() {
    quadric_.resize(pos_.size());
    tbb::parallel_for(tbb::blocked_range<Index>(0, Index(pos_.size()), 4096),
                      [&](const tbb::blocked_range<Index>& r) {
                        for (Index v = r.begin(); v != r.end(); ++v)
                          for (const Index* f = vf_.begin(v); f != vf_.end(v); ++f) {
                            const auto& face = faces_[*f];
                            const Vec3 n = normal_of(face);
                            const double len = n.norm();
                            if (!(len > 0)) continue;
                            const Vec3 u = n / len;
                            quadric_[v].add_plane(u, -u.dot(pos_[face[0]]), 0.5 * len);
                          }
                      });
  }

  // Every input vertex is a point to keep within the bound, attached to its first face
  // (distance 0). Vertices no triangle uses are not part of the surface. An estimated bound
  // attaches none, so no collapse checks or moves points. A moving survivor also keeps the
  // input's vertex -> face rows, for near_input().
  void attach_points() {
    const std::size_t nv = pos_.size();
    if (optimal_ && opts_.verify_bound) {
      input_vf_.offset.assign(1, 0);
      for (Index v = 0; v < Index(nv); ++v)
        input_vf_.offset.push_back(input_vf_.offset.back() + vf_.count[v]);
      input_vf_.items = vf_.items;  // as just built: contiguous, in vertex order
    }
    if (carry_ && !carry_->point_face.empty()) {
      owner_ = std::move(carried_owner_);
      return;
    }
    owner_.assign(nv, kNone);
    for (Index v = 0; v < nv && opts_.verify_bound; ++v)
      if (vf_.size(v) > 0) owner_[v] = *vf_.begin(v);
  }

  // Stars that are not a single fan (non-manifold edges or vertices) never change. Boundary
  // vertices stay boundary vertices (collapses keep the topology, flips only take interior
  // edges), so the flag is set once, from the same neighbour lists.
  void classify_vertices() {
    const std::size_t nv = pos_.size();
    locked_.assign(nv, 0);
    held_.assign(nv, 0);
    boundary_.assign(nv, 0);
    tbb::parallel_for(tbb::blocked_range<Index>(0, Index(nv), 1024), [&](const tbb::blocked_range<Index>& r) {
      std::vector<Neighbour> n;
      for (Index v = r.begin(); v != r.end(); ++v) {
        if (vf_.size(v) == 0) continue;
        if (!single_fan(v, n)) locked_[v] = 1;  // single_fan() leaves v's neighbours in n
        boundary_[v] = on_boundary(n);
        if (carry_ && !carry_->locked.empty() && carry_->locked[v]) locked_[v] = held_[v] = 1;
      }
    });
  }

  // No keys yet and every vertex dirty, so the first pass keys them all; the face -> points
  // rows of the bound (rebuilt every pass when verified).
  void start_state() {
    const std::size_t nv = pos_.size();
    key_.assign(nv, kNoKey);
    target_.assign(nv, kNone);
    stuck_.assign(nv, 0);
    screened_.assign(nv, 0);
    keyed_.assign(nv, 0);
    found_.assign(nv, kNone);
    found_in_.assign(nv, 0);
    dirty_.assign(nv, 1);
    dirty_list_.resize(nv);
    for (Index v = 0; v < Index(nv); ++v) dirty_list_[v] = v;
    build_face_points();
    stamp_.assign(nv, 0);
    removed_faces_.assign(nv, 0);
  }

  // One pass of flips; false when none was made. The flips change stars, so the adjacency and
  // the points' rows are rebuilt and the flipped vertices' rings keyed again.
  bool flip_round(std::size_t& flips) {
    std::vector<Index> flipped;
    flip_all(flipped);
    flips += flipped.size() / 4;
    if (flipped.empty()) return false;
    build_vertex_faces();
    build_face_points();
    mark_changed(flipped);
    return true;
  }

  // Passes of independent collapses until the floor, or until no candidate is left: each pass
  // keys the vertices whose ring changed, ranks the candidates, selects rings that do not touch,
  // collapses them in parallel and marks what changed for the next pass.
  void collapse_all(std::size_t& passes, std::size_t& collapses) {
    std::vector<Index> selected;
    bool screen = false;
    while (alive_faces_ > opts_.min_triangles) {
      pass_ = Index(++passes);
      if (opts_.verify_bound) build_face_points();
      rank_candidates(rekey_dirty());
      if (sorted_.empty()) break;
      // Late on, most cheap candidates fail the checks and a selected failure blocks its ring
      // for the pass; then the candidates are checked before they are picked.
      if (screen)
        select_screened(pass_, selected);
      else
        select_independent(selected);
      const std::size_t applied = collapse_selected(selected);
      collapses += applied;
      screen = screen || 2 * applied < selected.size();
      if (applied == 0) continue;  // only stuck vertices were selected; they are skipped now
      update_vertex_faces(selected);
      std::vector<Index> survivors;
      for (Index v0 : selected)
        if (target_[v0] != kNone) {
          key_[v0] = kNoKey;  // gone
          survivors.push_back(target_[v0]);
        }
      mark_changed(survivors);
    }
  }

  // Cheap keys (quadric cost of the best-looking neighbour) for vertices whose neighbourhood
  // changed, in parallel; the full legality check waits until a vertex is selected. Returns
  // the vertices keyed.
  std::vector<Index> rekey_dirty() {
    std::vector<Index> work;
    work.swap(dirty_list_);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, work.size(), 512),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        Scratch s;
                        for (std::size_t i = r.begin(); i != r.end(); ++i) {
                          const Index v = work[i];
                          key_[v] = cheapest(v, s);
                          stuck_[v] = 0;
                          screened_[v] = 0;
                          dirty_[v] = 0;
                          keyed_[v] = pass_;
                        }
                      });
    return work;
  }

  // Candidates cheapest first, ties by index, so the order is a function of the mesh alone. The
  // sorted list carries over between passes: only the fresh keys of `keyed` are sorted and
  // merged in; entries whose vertex was re-keyed, collapsed or got stuck drop out.
  void rank_candidates(const std::vector<Index>& keyed) {
    std::vector<std::pair<double, Index>> fresh, kept;
    for (Index v : keyed)
      if (key_[v] < kNoKey) fresh.push_back({key_[v], v});
    tbb::parallel_sort(fresh.begin(), fresh.end());
    for (const auto& c : sorted_)
      if (keyed_[c.second] != pass_ && !stuck_[c.second] && key_[c.second] < kNoKey) kept.push_back(c);
    sorted_.resize(kept.size() + fresh.size());
    std::merge(kept.begin(), kept.end(), fresh.begin(), fresh.end(), sorted_.begin());
  }

  // Collapses the selected vertices and returns how many moved. Each collapse removes at most
  // two faces: far from the floor, all run at once; near it, one by one in cost order until
  // the floor is reached (`selected` then cut to those tried).
  std::size_t collapse_selected(std::vector<Index>& selected) {
    if (alive_faces_ > opts_.min_triangles + 2 * selected.size()) {
      tbb::parallel_for(tbb::blocked_range<std::size_t>(0, selected.size(), 64),
                        [&](const tbb::blocked_range<std::size_t>& r) {
                          Scratch s;
                          for (std::size_t i = r.begin(); i != r.end(); ++i) collapse(selected[i], s);
                        });
      for (Index v0 : selected) alive_faces_ -= removed_faces_[v0];
    } else {
      Scratch s;
      std::size_t n = 0;
      for (; n < selected.size() && alive_faces_ > opts_.min_triangles; ++n)
        if (collapse(selected[n], s)) alive_faces_ -= removed_faces_[selected[n]];
      selected.resize(n);
    }
    std::size_t applied = 0;
    for (Index v0 : selected) applied += target_[v0] != kNone;
    return applied;
  }

  // v0's closed one-ring (two-ring when survivors move) holds no vertex stamped with `stamp`.
  bool ring_free(Index v0, Index stamp) const {
    if (stamp_[v0] == stamp) return false;
    for (const Index* f = vf_.begin(v0); f != vf_.end(v0); ++f)
      for (Index v : faces_[*f])
        if (stamp_[v] == stamp) return false;
    return true;
  }

  // Stamps v0's closed one-ring, or with optimal placement its closed two-ring: the survivor (a
  // neighbour) moves too, changing its own star, so selected vertices are then at least four
  // edges apart and no collapse reads what another writes.
  void stamp_ring(Index v0, Index stamp) {
    for (const Index* f = vf_.begin(v0); f != vf_.end(v0); ++f)
      for (Index v : faces_[*f]) {
        stamp_[v] = stamp;
        if (optimal_)
          for (const Index* g = vf_.begin(v); g != vf_.end(v); ++g)
            for (Index w : faces_[*g]) stamp_[w] = stamp;
      }
  }

  // Greedy independent set over the sorted candidates: closed rings pairwise disjoint.
  void select_independent(std::vector<Index>& selected) {
    const Index stamp = ++stamp_counter_;
    selected.clear();
    for (const auto& c : sorted_)
      if (ring_free(c.second, stamp)) {
        stamp_ring(c.second, stamp);
        selected.push_back(c.second);
      }
  }

  // The same greedy set without the candidates that fail the checks, which are marked stuck and
  // leave the sorted list. Only a candidate whose ring is still free when its turn comes is
  // checked: the list is walked in windows of fixed size, the free unchecked candidates of a
  // window are checked in parallel, then the window is picked from in order. (Checking every
  // candidate up front checked four to ten times more.) A pure function of the mesh: the
  // windows do not depend on the thread count, and a check's result on the state the pass
  // started from. Each check that finds a target keeps it for collapse() in the same pass.
  void select_screened(Index pass, std::vector<Index>& selected) {
    constexpr std::size_t kWindow = 2048;
    const Index stamp = ++stamp_counter_;
    selected.clear();
    std::vector<Index> todo;
    for (std::size_t begin = 0; begin < sorted_.size(); begin += kWindow) {
      const std::size_t end = std::min(sorted_.size(), begin + kWindow);
      todo.clear();
      for (std::size_t i = begin; i < end; ++i) {
        const Index v = sorted_[i].second;
        if (!screened_[v] && ring_free(v, stamp)) todo.push_back(v);
      }
      tbb::parallel_for(tbb::blocked_range<std::size_t>(0, todo.size(), 32),
                        [&](const tbb::blocked_range<std::size_t>& r) {
                          Scratch s;
                          for (std::size_t i = r.begin(); i != r.end(); ++i) {
                            const Index v = todo[i];
                            const Index t = find_target(v, s);
                            if (t == kNone) {
                              stuck_[v] = 1;
                            } else {
                              screened_[v] = 1;
                              found_[v] = t;
                              found_in_[v] = pass;
                            }
                          }
                        });
      for (std::size_t i = begin; i < end; ++i) {
        const Index v = sorted_[i].second;
        if (!stuck_[v] && ring_free(v, stamp)) {
          stamp_ring(v, stamp);
          selected.push_back(v);
        }
      }
    }
    sorted_.erase(std::remove_if(sorted_.begin(), sorted_.end(),
                                 [&](const std::pair<double, Index>& c) { return stuck_[c.second] != 0; }),
                  sorted_.end());
  }

  // Step 1 on big meshes with an estimated bound: every block of space on its own, in parallel,
  // cheapest collapse first (a heap per block), with both ends of each collapse inside the block
  // (no neighbour in another block). A collapse writes the faces around v0, the survivor's
  // position, quadric and row, and the rows of v0's neighbours, and reads the rings of its two ends: all of
  // it belongs to the block, and a vertex inside a block stays inside (it only gains neighbours of the
  // block). So blocks never see each other's changes, each is sequential in itself, and the result does not
  // depend on the thread count. A triangle floor is shared out: each block stops at
  // kBlockFloorShare times the floor's share of its faces, so the passes, which take the seams
  // and whatever the order left, still choose the last collapses cheapest first over the whole.
  // Not with the verified bound: there the blocks' local order let the bound bind early (σ 3
  // head: 10.6 % of the triangles left instead of the 10 % floor) and took longer.
  void simplify_blocks(double shift, std::size_t& collapses) {
    const std::vector<std::vector<Index>> blocks = block_insides(shift);
    std::vector<std::size_t> removed(blocks.size(), 0), done(blocks.size(), 0);
    std::vector<std::size_t> budget(blocks.size(), std::numeric_limits<std::size_t>::max());
    if (opts_.min_triangles > 0) {
      // A face with a vertex inside a block lies in it (all its vertices are that one's
      // neighbours).
      std::vector<std::size_t> faces(blocks.size(), 0);
      for (std::size_t f = 0; f < faces_.size(); ++f)
        if (face_alive_[f])
          for (Index v : faces_[f])
            if (inside_[v] != kNone) {
              ++faces[inside_[v]];
              break;
            }
      const double share = std::min(1.0, kBlockFloorShare * double(opts_.min_triangles) /
                                             double(std::max<std::size_t>(alive_faces_, 1)));
      for (std::size_t b = 0; b < blocks.size(); ++b)
        budget[b] = faces[b] - std::size_t(std::ceil(share * double(faces[b])));
    }
    block_vf_arenas_.resize(blocks.size());
    in_blocks_ = true;
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, blocks.size(), 1),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        for (std::size_t b = r.begin(); b != r.end(); ++b)
                          simplify_block(blocks[b], Index(b), budget[b], removed[b], done[b]);
                      });
    in_blocks_ = false;
    for (std::size_t b = 0; b < blocks.size(); ++b) {
      alive_faces_ -= removed[b];
      collapses += done[b];
    }
    // Contiguous again (this drops the blocks' arenas); every vertex is still dirty, so the
    // passes key all. (No face points: the bound is estimated.)
    build_vertex_faces();
  }

  // The vertices inside each block of space (cubes of kBlockEdges mean input edges, moved by
  // `shift` of their edge along each axis), ascending; inside_[v] is the number of v's block,
  // or kNone for vertices with a neighbour in another block (and locked or unused ones).
  std::vector<std::vector<Index>> block_insides(double shift) {
    const std::size_t nv = pos_.size();
    if (!(cell_ > 0)) {  // from the input mesh (the first call)
      double length = 0;
      lo_ = Vec3::Constant(std::numeric_limits<double>::infinity());
      for (const auto& f : faces_)
        for (int k = 0; k < 3; ++k) {
          length += (pos_[f[k]] - pos_[f[(k + 1) % 3]]).norm();
          lo_ = lo_.cwiseMin(pos_[f[k]]);
        }
      cell_ = kBlockEdges * length / (3.0 * double(std::max<std::size_t>(faces_.size(), 1)));
    }
    const double cell = cell_;
    std::vector<std::uint64_t> key(nv, ~std::uint64_t(0));
    tbb::parallel_for(
        tbb::blocked_range<std::size_t>(0, nv, 4096), [&](const tbb::blocked_range<std::size_t>& r) {
          for (std::size_t v = r.begin(); v != r.end(); ++v) {
            if (vf_.size(Index(v)) == 0 || !(cell > 0)) continue;
            std::uint64_t k = 0;
            for (int c = 0; c < 3; ++c)
              k = (k << 21) | std::uint64_t(std::floor((pos_[v][c] - lo_[c]) / cell + 1 - shift));
            key[v] = k;
          }
        });
    inside_.assign(nv, kNone);
    best_.assign(nv, kNone);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nv, 4096),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        for (std::size_t v = r.begin(); v != r.end(); ++v) {
                          if (key[v] == ~std::uint64_t(0) || locked_[v]) continue;
                          bool in = true;
                          for (const Index* f = vf_.begin(Index(v)); f != vf_.end(Index(v)) && in; ++f)
                            for (Index w : faces_[*f]) in = in && key[w] == key[v];
                          if (in) inside_[v] = 0;
                        }
                      });
    std::vector<std::uint64_t> cells;
    for (std::size_t v = 0; v < nv; ++v)
      if (inside_[v] != kNone) cells.push_back(key[v]);
    tbb::parallel_sort(cells.begin(), cells.end());  // plain numbers: one order for any thread count
    cells.erase(std::unique(cells.begin(), cells.end()), cells.end());
    tbb::parallel_for(
        tbb::blocked_range<std::size_t>(0, nv, 4096), [&](const tbb::blocked_range<std::size_t>& r) {
          for (std::size_t v = r.begin(); v != r.end(); ++v)
            if (inside_[v] != kNone)
              inside_[v] = Index(std::lower_bound(cells.begin(), cells.end(), key[v]) - cells.begin());
        });
    std::vector<std::vector<Index>> blocks(cells.size());
    for (std::size_t v = 0; v < nv; ++v)
      if (inside_[v] != kNone) blocks[inside_[v]].push_back(Index(v));
    return blocks;
  }

  // One block's collapses, cheapest first: after each, the survivor's ring is keyed again and
  // stuck vertices next to it are tried again (as mark_changed() does between passes).
  void simplify_block(const std::vector<Index>& verts, Index b, std::size_t budget, std::size_t& removed,
                      std::size_t& done) {
    using Item = std::pair<double, Index>;
    std::priority_queue<Item, std::vector<Item>, std::greater<Item>> heap;
    Scratch s;
    std::vector<Index> row, ring, again;
    auto push = [&](Index v) {
      stuck_[v] = 0;
      if (key_[v] < kNoKey) heap.push({key_[v], v});
    };
    for (Index v : verts) {
      key_[v] = cheapest(v, s, &best_[v]);
      push(v);
    }
    while (!heap.empty() && removed + 2 <= budget) {
      const Item top = heap.top();
      heap.pop();
      const Index v0 = top.second;
      if (top.first != key_[v0] || stuck_[v0] || !collapse(v0, s)) continue;  // stale, or stuck
      const Index v1 = target_[v0];
      key_[v0] = kNoKey;
      removed += removed_faces_[v0];
      ++done;
      update_vertex_faces(v0, v1, row, block_vf_arenas_[b]);
      // Keys: v1's quadric, position and ring changed; a neighbour's only through its edges to
      // v0 (gone) and v1, as every other edge's cost reads the same quadrics and positions. So
      // a neighbour whose cheapest edge went elsewhere needs that one edge only, for the very
      // key a full evaluation gives.
      ring.clear();
      for (const Index* f = vf_.begin(v1); f != vf_.end(v1); ++f)
        for (Index a : faces_[*f]) ring.push_back(a);
      std::sort(ring.begin(), ring.end());
      ring.erase(std::unique(ring.begin(), ring.end()), ring.end());
      // Pushed again: changed keys (a heap entry whose key is unchanged is still valid) and
      // stuck vertices next to a changed one, which are tried again. v1's edges are costed
      // first, and its neighbours take the costs of their edges to v1 from there.
      again.clear();
      const double v1_old = key_[v1];
      s.record = true;
      key_[v1] = cheapest(v1, s, &best_[v1]);
      s.record = false;
      for (Index a : ring) {
        if (inside_[a] == b) {
          const double old = a == v1 ? v1_old : key_[a];
          if (a == v1) {
            // keyed above
          } else if (best_[a] == v0 || best_[a] == v1) {
            key_[a] = cheapest(a, s, &best_[a]);
          } else {  // also when no other edge qualified (best_[a] == kNone)
            auto lower = [&](double cost, Index w, const Vec3&) {
              if (cost < key_[a]) {
                key_[a] = cost;
                best_[a] = w;
              }
            };
            double cost;
            if (boundary_[a])  // the edge's face count matters
              for_each_target(a, s, lower, v1);
            else if (known_cost(a, s, cost))
              lower(cost, v1, s.p);
            else
              lower(edge_cost(a, v1, false, s.p), v1, s.p);
          }
          if (key_[a] != old || stuck_[a]) again.push_back(a);
        }
        for (const Index* g = vf_.begin(a); g != vf_.end(a); ++g)
          for (Index w : faces_[*g])
            if (inside_[w] == b && stuck_[w]) again.push_back(w);
      }
      s.from = kNone;
      std::sort(again.begin(), again.end());
      again.erase(std::unique(again.begin(), again.end()), again.end());
      for (Index a : again) push(a);
    }
  }

  // After the stars of `changed` vertices changed (vf_ rebuilt): keys read the closed one-ring
  // (quadric, neighbours' faces), so that ring is re-keyed; the full checks of a stuck vertex
  // also read its neighbours' rings, so a stuck vertex next to a re-keyed one is tried again.
  // (A stuck vertex shares a face with a re-keyed one exactly when it lies in that one's ring,
  // so the rings of the re-keyed vertices are searched, not every vertex.)
  void mark_changed(const std::vector<Index>& changed) {
    for (Index v : changed)
      for (const Index* f = vf_.begin(v); f != vf_.end(v); ++f)
        for (Index a : faces_[*f]) mark_dirty(a);
    std::vector<Index> unstick;
    for (Index a : dirty_list_)
      for (const Index* f = vf_.begin(a); f != vf_.end(a); ++f)
        for (Index v : faces_[*f])
          if (stuck_[v] && !dirty_[v]) unstick.push_back(v);
    for (Index v : unstick) mark_dirty(v);
  }

  void mark_dirty(Index v) {
    if (dirty_[v]) return;
    dirty_[v] = 1;
    dirty_list_.push_back(v);
  }

  // Edge flips that bring valences toward 6 (4 on the boundary): Draco's connectivity coder
  // and later collapses both do better on regular meshes. A flip of edge a b between faces
  // (a, b, c) and (b, a, d) makes (a, d, c) and (b, c, d); it must keep the bound for the
  // points of both faces, turn no normal past the limit, and not create an existing edge.
  // Sequential and in face order (deterministic); a vertex or face takes part in at most one
  // flip per pass, so the pass's adjacency stays valid for everything not yet touched.
  void flip_all(std::vector<Index>& flipped) {
    std::vector<int> valence(pos_.size());
    std::vector<uint8_t> boundary(pos_.size());
    std::vector<Neighbour> n;
    for (int pass = 0; pass < 3; ++pass) {  // later passes flip a few hundred edges
      build_vertex_faces();
      if (opts_.verify_bound) build_face_points();
      for (Index v = 0; v < Index(pos_.size()); ++v) {
        neighbours(v, n);
        valence[v] = int(n.size());
        boundary[v] = on_boundary(n);
      }
      const Index stamp = ++stamp_counter_;
      face_stamp_.resize(faces_.size(), 0);
      auto dev = [&](Index v, int val) {
        const int d = val - (boundary[v] ? 4 : 6);
        return d * d;
      };
      std::size_t flips = 0;
      for (Index f = 0; f < Index(faces_.size()); ++f) {
        if (!face_alive_[f] || face_stamp_[f] == stamp) continue;
        for (int k = 0; k < 3; ++k) {
          const Index a = faces_[f][k], b = faces_[f][(k + 1) % 3], c = faces_[f][(k + 2) % 3];
          if (locked_[a] || locked_[b] || stamp_[a] == stamp || stamp_[b] == stamp || stamp_[c] == stamp)
            continue;
          // The other face on a b, with the edge the other way round.
          Index g = kNone;
          int on_edge = 0;
          for (const Index* h = vf_.begin(a); h != vf_.end(a); ++h)
            if (*h != f && contains(faces_[*h], b)) {
              g = *h;
              ++on_edge;
            }
          if (on_edge != 1 || face_stamp_[g] == stamp) continue;
          const auto& fg = faces_[g];
          int ia = 0;
          while (fg[ia] != a) ++ia;
          if (fg[(ia + 2) % 3] != b) continue;  // inconsistent orientation
          const Index d = fg[(ia + 1) % 3];
          if (d == c || stamp_[d] == stamp || (held_[c] && held_[d])) continue;
          if (valence[a] <= 3 || valence[b] <= 3) continue;
          const int before =
              dev(a, valence[a]) + dev(b, valence[b]) + dev(c, valence[c]) + dev(d, valence[d]);
          const int after = dev(a, valence[a] - 1) + dev(b, valence[b] - 1) + dev(c, valence[c] + 1) +
                            dev(d, valence[d] + 1);
          if (after >= before) continue;
          bool exists = false;
          for (const Index* h = vf_.begin(c); h != vf_.end(c) && !exists; ++h)
            exists = contains(faces_[*h], d);
          if (exists) continue;
          const std::array<Index, 3> nf{a, d, c}, ng{b, c, d};
          const Vec3 nf_old = normal_of(faces_[f]), ng_old = normal_of(fg);
          if (!keeps_shape(nf, nullptr, {nf_old, ng_old}) || !keeps_shape(ng, nullptr, {nf_old, ng_old}))
            continue;
          // The surface moves most at the old edge's midpoint, onto the new edge; an estimated
          // bound takes that distance, a verified one the points' below.
          bool bound =
              opts_.verify_bound || segment_distance2(0.5 * (pos_[a] + pos_[b]), pos_[c], pos_[d]) <= tol2_;
          for (Index face : {f, g})
            for (const Index* p = points_begin(face); p != points_end(face) && bound; ++p)
              bound = std::min(distance2(*p, nf), distance2(*p, ng)) <= tol2_;
          if (!bound) continue;
          for (Index face : {f, g})
            for (const Index* p = points_begin(face); p != points_end(face); ++p)
              owner_[*p] = distance2(*p, nf) <= distance2(*p, ng) ? f : g;
          faces_[f] = nf;
          faces_[g] = ng;
          for (Index v : {a, b, c, d}) {
            stamp_[v] = stamp;
            flipped.push_back(v);
          }
          face_stamp_[f] = face_stamp_[g] = stamp;
          ++flips;
          break;
        }
      }
      if (flips == 0) break;
    }
  }

  // Position of vertex v in the geometry after move m (nullptr: the current geometry): v0 and
  // v1 both sit at m->p.
  const Vec3& at(Index v, const Move* m) const { return m && (v == m->v0 || v == m->v1) ? m->p : pos_[v]; }

  // Normal (twice the area) of triangle t after move m.
  Vec3 normal_of(const std::array<Index, 3>& t, const Move* m = nullptr) const {
    return (at(t[1], m) - at(t[0], m)).cross(at(t[2], m) - at(t[0], m));
  }

  // Triangle t (after move m) is not degenerate and its normal is within the turn limit of
  // each of `old` (the normals of the faces it replaces).
  bool keeps_shape(const std::array<Index, 3>& t, const Move* m, std::initializer_list<Vec3> old) const {
    const Vec3 &a = at(t[0], m), &b = at(t[1], m), &c = at(t[2], m);
    const Vec3 n = normal_of(t, m);
    const double scale = std::max({(b - a).squaredNorm(), (c - a).squaredNorm(), (c - b).squaredNorm()});
    if (!(n.norm() > 1e-10 * scale)) return false;
    for (const Vec3& o : old)
      if (n.dot(o) < cos_max_turn_ * n.norm() * o.norm()) return false;
    return true;
  }

  static bool contains(const std::array<Index, 3>& f, Index v) { return f[0] == v || f[1] == v || f[2] == v; }

  void build_vertex_faces() {
    build_rows(vf_, pos_.size(), [&](auto&& add) {
      for (std::size_t f = 0; f < faces_.size(); ++f)
        if (face_alive_[f])
          for (Index v : faces_[f]) add(v, Index(f));
    });
    vf_arena_ = Arena();
    block_vf_arenas_.clear();
  }

  // vf_ after the collapses v0 -> target_[v0] of `selected` (faces_ and face_alive_ updated).
  // The collapses are disjoint, so the order does not matter. Rows that moved leave holes;
  // once these outweigh the rows, all are rebuilt (a function of the mesh alone, like
  // everything here).
  // With a verified bound the checks read the points and rows of every candidate's
  // neighbourhood, and both rebuilt contiguous each pass measured faster than rows moved into
  // arenas (the σ 1.5 head: 15-40 % more CPU time with the moved rows).
  void update_vertex_faces(const std::vector<Index>& selected) {
    if (opts_.verify_bound) {
      build_vertex_faces();
      return;
    }
    std::vector<Index> row;
    for (Index v0 : selected)
      if (target_[v0] != kNone) update_vertex_faces(v0, target_[v0], row, vf_arena_);
    if (vf_arena_.used() > 3 * alive_faces_ + (std::size_t(1) << 16)) build_vertex_faces();
  }

  // vf_ after the collapse v0 -> v1: v1's row becomes the ascending merge of its own and v0's
  // alive faces, the vertices opposite the edge lose its faces. Writes the rows of v0's closed
  // ring only.
  void update_vertex_faces(Index v0, Index v1, std::vector<Index>& row, Arena& arena) {
    auto dead = [&](Index f) { return !face_alive_[f]; };
    for (const Index* f = vf_.begin(v0); f != vf_.end(v0); ++f)
      if (!face_alive_[*f])
        for (Index x : faces_[*f])
          if (x != v0 && x != v1) vf_.remove_if(x, dead);
    row.clear();
    std::set_union(vf_.begin(v0), vf_.end(v0), vf_.begin(v1), vf_.end(v1), std::back_inserter(row));
    row.erase(std::remove_if(row.begin(), row.end(), dead), row.end());
    vf_.assign(v1, row, arena);
    vf_.count[v0] = 0;
  }

  // The points attached to face f (none with an estimated bound, which attaches none and
  // leaves fp_ unbuilt: on the full heads' first stage its rows took a tenth of a second).
  const Index* points_begin(Index f) const { return opts_.verify_bound ? fp_.begin(f) : nullptr; }
  const Index* points_end(Index f) const { return opts_.verify_bound ? fp_.end(f) : nullptr; }

  void build_face_points() {
    if (!opts_.verify_bound) return;
    build_rows(fp_, faces_.size(), [&](auto&& add) {
      for (Index p = 0; p < Index(owner_.size()); ++p)
        if (owner_[p] != kNone) add(owner_[p], p);
    });
  }

  void neighbours(Index v, std::vector<Neighbour>& out) const {
    out.clear();
    for (const Index* f = vf_.begin(v); f != vf_.end(v); ++f)
      for (Index w : faces_[*f]) {
        if (w == v) continue;
        auto it = std::find_if(out.begin(), out.end(), [w](const Neighbour& n) { return n.v == w; });
        if (it == out.end())
          out.push_back({w, 1});
        else
          ++it->faces;
      }
  }

  // The faces around v form one fan: a cycle (interior) or one open chain (boundary).
  bool single_fan(Index v, std::vector<Neighbour>& n) const {
    neighbours(v, n);
    int ends = 0;
    for (const auto& x : n) {
      if (x.faces > 2) return false;
      ends += x.faces == 1;
    }
    if (ends != 0 && ends != 2) return false;
    // Walk the fan from one face across shared edges; it must reach every face.
    const std::size_t count = vf_.size(v);
    std::vector<uint8_t> seen(count, 0);
    std::vector<std::size_t> stack{0};
    seen[0] = 1;
    std::size_t reached = 1;
    while (!stack.empty()) {
      const std::size_t i = stack.back();
      stack.pop_back();
      const auto& fi = faces_[vf_.begin(v)[i]];
      for (std::size_t j = 0; j < count; ++j) {
        if (seen[j]) continue;
        const auto& fj = faces_[vf_.begin(v)[j]];
        bool shares = false;
        for (Index a : fi)
          if (a != v && contains(fj, a)) shares = true;
        if (shares) {
          seen[j] = 1;
          ++reached;
          stack.push_back(j);
        }
      }
    }
    return reached == count;
  }

  static int faces_on_edge(const std::vector<Neighbour>& n, Index w) {
    for (const auto& x : n)
      if (x.v == w) return x.faces;
    return 0;
  }

  // Calls each(cost, w, p) for every neighbour w that v0 may move onto (cost: the quadric error
  // with a tiny length term breaking ties; p: where the survivor goes); returns whether v0 is on the
  // boundary. Fills s.n0. `only` (if not kNone): that neighbour alone is considered.
  template <class Each>
  bool for_each_target(Index v0, Scratch& s, Each&& each, Index only = kNone) const {
    neighbours(v0, s.n0);
    const bool boundary0 = on_boundary(s.n0);
    // Each cost reads the neighbour's quadric (two cache lines) and position, far apart in
    // memory in the extraction's order: asked for all at once, their misses overlap.
    for (const auto& x : s.n0) {
      const char* q = reinterpret_cast<const char*>(&quadric_[x.v]);
      __builtin_prefetch(q);
      __builtin_prefetch(q + sizeof(Quadric) - 1);
      __builtin_prefetch(&pos_[x.v]);
    }
    const bool record = s.record;
    s.record = false;
    if (record) {
      s.from = v0;
      s.from_costs.clear();
    }
    for (const auto& x : s.n0) {
      if (only != kNone && x.v != only) continue;
      if (boundary0 && x.faces != 1) continue;  // a boundary vertex only slides along the boundary
      double cost;
      if (!boundary0 && x.v == s.from && !record && known_cost(v0, s, cost)) {
        if (cost < kNoKey) each(cost, x.v, s.p);
        continue;
      }
      bool symmetric = false;
      cost = edge_cost(v0, x.v, boundary0, s.p, &symmetric);
      if (record && symmetric) s.from_costs.push_back({cost, x.v, s.p});
      if (cost < kNoKey) each(cost, x.v, s.p);
    }
    return boundary0;
  }

  // The key of moving v0 onto its neighbour w (kNoKey: not allowed), the edge's face count
  // aside (see for_each_target); p := place(v0, w, boundary0) when allowed. *symmetric: the
  // key and p are bit for bit those of moving w onto v0 (the quadric minimum of two interior
  // vertices, both unlocked, the key's sums commutative), so one evaluation serves both ends.
  double edge_cost(Index v0, Index w, bool boundary0, Vec3& p, bool* symmetric = nullptr) const {
    if (symmetric) *symmetric = false;
    // A held vertex takes half-edge collapses (place() leaves it where it is); a non-manifold
    // star takes none.
    if ((locked_[w] && !held_[w]) || (in_blocks_ && inside_[w] != inside_[v0])) return kNoKey;
    p = place(v0, w, boundary0, symmetric);
    if (symmetric) *symmetric = *symmetric && !locked_[v0];
    const double cost = eval_sum(quadric_[v0], quadric_[w], p);
    // The estimated bound: the merged planes' mean squared distance.
    if (!opts_.verify_bound && cost > tol2_ * (quadric_[v0].weight() + quadric_[w].weight())) return kNoKey;
    return cost + 1e-12 * (pos_[w] - pos_[v0]).squaredNorm();
  }

  // The cost of v0's edge to s.from, recorded from s.from's end (false: not recorded, or not
  // the same from v0's end, v0 being interior); s.p := its placement.
  bool known_cost(Index v0, Scratch& s, double& cost) const {
    if (boundary_[v0] || boundary_[s.from]) return false;
    for (const auto& t : s.from_costs)
      if (t.w == v0) {
        cost = t.cost;
        s.p = t.p;
        return true;
      }
    return false;
  }

  // Neighbours v0 may move onto, cheapest first (ties by index).
  bool ordered_targets(Index v0, Scratch& s) const {
    s.order.clear();
    const bool boundary0 = for_each_target(v0, s, [&](double cost, Index w, const Vec3& p) {
      s.order.push_back({cost, w, p});
    });
    std::sort(s.order.begin(), s.order.end(), [](const Target& a, const Target& b) {
      return a.cost < b.cost || (a.cost == b.cost && a.w < b.w);
    });
    return boundary0;
  }

  // The first key of ordered_targets(), without sorting; *target: a neighbour with that key.
  double cheapest(Index v0, Scratch& s, Index* target = nullptr) const {
    if (locked_[v0] || vf_.size(v0) == 0) return kNoKey;
    double best = kNoKey;
    Index at = kNone;
    for_each_target(v0, s, [&](double cost, Index w, const Vec3&) {
      if (cost < best) {
        best = cost;
        at = w;
      }
    });
    if (target) *target = at;
    return best;
  }

  // The cheapest neighbour v0 may move onto under all checks, or kNone.
  Index find_target(Index v0, Scratch& s) const {
    const bool boundary0 = ordered_targets(v0, s);
    for (const auto& c : s.order)
      if (passes(v0, c.w, boundary0, c.p, s)) return c.w;
    return kNone;
  }

  // find_target(), trying the neighbour that gave v0's key first (in the blocks, where keys
  // come with it: most collapses then need no other cost evaluated).
  Index find_target_from(Index v0, Index first, Scratch& s) const {
    if (first != kNone) {
      neighbours(v0, s.n0);
      const bool boundary0 = on_boundary(s.n0);
      if (passes(v0, first, boundary0, place(v0, first, boundary0), s)) return first;
    }
    return find_target(v0, s);
  }

  // v0 may move onto v1 under all checks (s.n0: v0's neighbours; p: place(v0, v1, boundary0)).
  bool passes(Index v0, Index v1, bool boundary0, const Vec3& p, Scratch& s) const {
    const int edge_faces = keeps_topology(v0, v1, boundary0, s);
    if (edge_faces < 0) return false;
    if (keeps_geometry(v0, v1, edge_faces, p, s)) return true;
    // Where the quadric minimum leaves the surface (tight tolerances on curved parts), the
    // half-edge collapse may still pass.
    return p != pos_[v1] && keeps_geometry(v0, v1, edge_faces, pos_[v1], s);
  }

  // Where the merged vertex goes: the minimum of the summed quadrics (Garland & Heckbert) when
  // it is well defined and near the edge, else the cheapest point of the edge; on the boundary
  // (and in input-vertex mode) v1's own position, so boundaries stay where they are.
  // *symmetric: the minimum of the summed quadrics was taken (the same for place(v1, v0)).
  Vec3 place(Index v0, Index v1, bool boundary0, bool* symmetric = nullptr) const {
    if (symmetric) *symmetric = false;
    if (!optimal_ || boundary0 || boundary_[v1] || held_[v1]) return pos_[v1];
    Quadric q = quadric_[v0];
    q.add(quadric_[v1]);
    const auto& a = q.q;
    const Vec3 b(a[3], a[6], a[8]);
    const Vec3 e = pos_[v1] - pos_[v0];
    const double len2 = e.squaredNorm();
    const double scale = a[0] + a[4] + a[7];
    // The symmetric matrix's adjugate (six cofactors) and determinant: the minimum is
    // -adj b / det (a general 3x3 inverse did half again as much arithmetic, in the hottest
    // function of the checks).
    const double c00 = a[4] * a[7] - a[5] * a[5], c01 = a[2] * a[5] - a[1] * a[7],
                 c02 = a[1] * a[5] - a[2] * a[4], c11 = a[0] * a[7] - a[2] * a[2],
                 c12 = a[1] * a[2] - a[0] * a[5], c22 = a[0] * a[4] - a[1] * a[1];
    const double det = a[0] * c00 + a[1] * c01 + a[2] * c02;
    if (scale > 0 && std::abs(det) > 1e-6 * scale * scale * scale) {
      const Vec3 p = Vec3(c00 * b.x() + c01 * b.y() + c02 * b.z(), c01 * b.x() + c11 * b.y() + c12 * b.z(),
                          c02 * b.x() + c12 * b.y() + c22 * b.z()) /
                     -det;
      const Vec3 mid = 0.5 * (pos_[v0] + pos_[v1]);
      if (p.allFinite() && (p - mid).squaredNorm() <= len2) {
        if (symmetric) *symmetric = true;
        return p;
      }
    }
    Eigen::Matrix3d m;
    m << a[0], a[1], a[2], a[1], a[4], a[5], a[2], a[5], a[7];
    // Along the edge: cost(t) = (p0 + t e)^T m (p0 + t e) + 2 b.(p0 + t e) + c.
    const double qa = e.dot(m * e), qb = e.dot(m * pos_[v0] + b);
    if (qa > 1e-12 * scale * len2) {
      const double t = std::clamp(-qb / qa, 0.0, 1.0);
      return pos_[v0] + t * e;
    }
    return pos_[v1];
  }

  // Collapses v0 onto the cheapest neighbour the checks allow; false (and marks v0 stuck) when
  // none does. Touches only faces around v0, points attached to them and the survivor's
  // quadric (optimal placement: also the survivor's position and the points of its faces):
  // disjoint from every other selected collapse.
  bool collapse(Index v0, Scratch& s) {
    target_[v0] = kNone;
    removed_faces_[v0] = 0;
    // (Both leave the move in s.move and the faces around v1 in s.targets.)
    // In the blocks the key's neighbour comes first; after a check in this pass, its target
    // (the state is the one it saw: the pass's collapses are independent).
    const Index v1 = in_blocks_               ? find_target_from(v0, best_[v0], s)
                     : found_in_[v0] == pass_ ? find_target_from(v0, found_[v0], s)
                                              : find_target(v0, s);
    if (v1 == kNone) {
      stuck_[v0] = 1;
      return false;
    }
    const Move& m = s.move;
    for (const Index* f = vf_.begin(v0); f != vf_.end(v0); ++f)
      for (const Index* p = points_begin(*f); p != points_end(*f); ++p)
        owner_[*p] = nearest(*p, m, s.targets).second;
    if (optimal_)
      for (const Index* g = vf_.begin(v1); g != vf_.end(v1); ++g)
        if (!contains(faces_[*g], v0))
          for (const Index* p = points_begin(*g); p != points_end(*g); ++p)
            owner_[*p] = nearest(*p, m, s.targets).second;
    pos_[v1] = m.p;
    std::size_t removed = 0;
    for (const Index* f = vf_.begin(v0); f != vf_.end(v0); ++f) {
      auto& face = faces_[*f];
      if (contains(face, v1)) {
        face_alive_[*f] = 0;
        ++removed;
      } else {
        for (Index& a : face)
          if (a == v0) a = v1;
      }
    }
    removed_faces_[v0] = removed;
    target_[v0] = v1;
    quadric_[v1].add(quadric_[v0]);
    return true;
  }

  // The checks of v0 onto v1 that do not depend on where the survivor goes: the number of
  // faces on edge v0 v1, or -1 when the collapse would change the topology or cut a boundary
  // corner. Fills s.n1 (v1's neighbours).
  int keeps_topology(Index v0, Index v1, bool boundary0, Scratch& s) const {
    const int edge_faces = faces_on_edge(s.n0, v1);
    neighbours(v1, s.n1);
    const bool boundary1 = on_boundary(s.n1);
    // Link condition: the common neighbours are exactly the vertices opposite the edge, and
    // two boundary vertices joined by an interior edge would pinch the surface.
    if (boundary0 && boundary1 && edge_faces != 1) return -1;
    // A boundary vertex that slides away must stay within the tolerance of the boundary edge
    // that replaces its two: the bound in the other direction along the boundary curve.
    if (boundary0)
      for (const auto& x : s.n0)
        if (x.faces == 1 && x.v != v1 && segment_distance2(pos_[v0], pos_[v1], pos_[x.v]) > tol2_) return -1;
    int common = 0;
    for (const auto& x : s.n0) {
      const bool shared = x.v != v1 && faces_on_edge(s.n1, x.v) > 0;
      common += shared;
      // Held vertices gain no edge between them: the part this mesh is glued to may hold it.
      if (held_[v1] && held_[x.v] && x.v != v1 && !shared) return -1;
    }
    return common == edge_faces ? edge_faces : -1;
  }

  // The checks of v0 onto v1 with the survivor at p (pos_[v1]: a half-edge collapse), after
  // keeps_topology(): shapes, the bound, and (moved survivor) nearness to the input. Leaves
  // the move in s.move and the faces around the survivor in s.targets.
  bool keeps_geometry(Index v0, Index v1, int edge_faces, const Vec3& p, Scratch& s) const {
    s.move = {v0, v1, p};
    const Move& m = s.move;

    // Faces around v0 that survive with v1 in v0's place: no duplicate of a face around v1,
    // no flip, no degeneracy. After the link condition, a face (v1, x, y) can only exist when
    // x and y are both common neighbours, i.e. the two vertices opposite the edge (a valence-3
    // v0 inside a tetrahedron-like cap); only then are v1's faces searched.
    s.targets.clear();
    for (const Index* f = vf_.begin(v0); f != vf_.end(v0); ++f) {
      const auto& face = faces_[*f];
      if (contains(face, v1)) continue;
      Index x = kNone, y = kNone;
      for (Index a : face)
        if (a != v0) (x == kNone ? x : y) = a;
      if (edge_faces == 2 && faces_on_edge(s.n1, x) > 0 && faces_on_edge(s.n1, y) > 0)
        for (const Index* g = vf_.begin(v1); g != vf_.end(v1); ++g)
          if (contains(faces_[*g], x) && contains(faces_[*g], y)) return false;
      if (!keeps_shape(face, &m, {normal_of(face)})) return false;
      s.targets.push_back(*f);
    }
    const bool moves = m.p != pos_[v1];
    for (const Index* g = vf_.begin(v1); g != vf_.end(v1); ++g)
      if (!contains(faces_[*g], v0)) {
        if (moves && !keeps_shape(faces_[*g], &m, {normal_of(faces_[*g])})) return false;
        s.targets.push_back(*g);
      }
    // The bound: every point attached to a face around v0 must find a face around v1.
    for (const Index* f = vf_.begin(v0); f != vf_.end(v0); ++f) {
      const Index first = contains(faces_[*f], v1) ? kNone : *f;  // its own face, moved, if kept
      for (const Index* p = points_begin(*f); p != points_end(*f); ++p)
        if (!within(*p, first, m, s.targets)) return false;
    }
    if (moves)
      for (const Index* g = vf_.begin(v1); g != vf_.end(v1); ++g)
        if (!contains(faces_[*g], v0))
          for (const Index* p = points_begin(*g); p != points_end(*g); ++p)
            if (!within(*p, *g, m, s.targets)) return false;
    // Last: when the quadric minimum is off the surface this scans every candidate triangle.
    if (moves && opts_.verify_bound && !near_input(m.p, v0, v1)) return false;
    return true;
  }

  static double segment_distance2(const Vec3& p, const Vec3& a, const Vec3& b) {
    const Vec3 ab = b - a;
    const double len2 = ab.squaredNorm();
    const double t = len2 > 0 ? std::clamp((p - a).dot(ab) / len2, 0.0, 1.0) : 0.0;
    return (a + t * ab - p).squaredNorm();
  }

  // A moved vertex stays within the tolerance of the input surface (the bound the other way
  // round): of an input triangle around the points attached to the faces it joins. Without it
  // a quadric minimum could leave the surface where the one-sided bound does not look.
  bool near_input(const Vec3& p, Index v0, Index v1) const {
    auto near = [&](Index point) {
      for (const Index* t = input_vf_.begin(point); t != input_vf_.end(point); ++t) {
        const auto& it = input_faces_[*t];
        if (point_triangle_distance2(p, points_[it[0]], points_[it[1]], points_[it[2]]) <= tol2_) return true;
      }
      return false;
    };
    // p lies near the edge v0 v1: the input triangles around those two input vertices first,
    // then those around the points attached to their faces.
    if (near(v1) || near(v0)) return true;
    if (!carried_.empty()) return false;  // carried points are no input vertices
    for (Index v : {v1, v0})
      for (const Index* f = vf_.begin(v); f != vf_.end(v); ++f)
        for (const Index* q = points_begin(*f); q != points_end(*f); ++q)
          if (near(*q)) return true;
    return false;
  }

  // Squared distance from input vertex `point` (its input position) to triangle t after move
  // m (nullptr: the current geometry).
  double distance2(Index point, const std::array<Index, 3>& t, const Move* m = nullptr) const {
    const Vec3& q = carried_.empty() ? points_[point] : carried_[point];
    return point_triangle_distance2(q, at(t[0], m), at(t[1], m), at(t[2], m));
  }

  // Some target face lies within the tolerance of the point after move m; `first` (a target
  // or kNone) is tried first, as the likeliest.
  bool within(Index point, Index first, const Move& m, const std::vector<Index>& targets) const {
    if (first != kNone && distance2(point, faces_[first], &m) <= tol2_) return true;
    for (Index f : targets) {
      if (f == first) continue;
      if (distance2(point, faces_[f], &m) <= tol2_) return true;
    }
    return false;
  }

  // Nearest target face (lowest index among equals) and its squared distance after move m.
  std::pair<double, Index> nearest(Index point, const Move& m, const std::vector<Index>& targets) const {
    double best = std::numeric_limits<double>::infinity();
    Index best_face = kNone;
    for (Index f : targets) {
      const double d = distance2(point, faces_[f], &m);
      if (d < best || (d == best && f < best_face)) {
        best = d;
        best_face = f;
      }
    }
    return {best, best_face};
  }

  TriangleMesh output() const {
    TriangleMesh out;
    std::vector<Index> index(pos_.size(), kNone);
    for (std::size_t f = 0; f < faces_.size(); ++f)
      if (face_alive_[f])
        for (Index v : faces_[f]) index[v] = 0;
    for (Index v = 0; v < Index(pos_.size()); ++v)
      if (index[v] != kNone) {
        index[v] = Index(out.positions.size());
        out.positions.push_back({float(pos_[v].x()), float(pos_[v].y()), float(pos_[v].z())});
        if (!normals_.empty()) out.normals.push_back(normals_[v]);
      }
    for (std::size_t f = 0; f < faces_.size(); ++f)
      if (face_alive_[f])
        out.triangles.push_back({index[faces_[f][0]], index[faces_[f][1]], index[faces_[f][2]]});
    // With input-vertex placement every output vertex is an input vertex, so its input normal
    // (for iso-surfaces the data's gradient there) still holds; it is closer to the data's
    // surface normal than one averaged from the coarser triangles. (Optimal placement keeps
    // the survivor's normal at a point within the tolerance; the CLI then writes surface
    // normals instead.)
    if (normals_.empty()) compute_area_weighted_normals(out);
    if (carry_) report_carry(index);
    return out;
  }

  // SimplifyCarry's outputs: `index` maps each vertex to its output vertex (kNone: gone).
  void report_carry(const std::vector<Index>& index) const {
    carry_->source.clear();
    for (Index v = 0; v < Index(index.size()); ++v)
      if (index[v] != kNone) carry_->source.push_back(v);
    carry_->point_face.clear();
    if (!opts_.verify_bound) return;
    std::vector<Index> output_face(faces_.size(), kNone);
    Index next = 0;
    for (std::size_t f = 0; f < faces_.size(); ++f)
      if (face_alive_[f]) output_face[f] = next++;
    carry_->point_face.resize(owner_.size(), kNone);
    for (std::size_t p = 0; p < owner_.size(); ++p)
      if (owner_[p] != kNone) carry_->point_face[p] = output_face[owner_[p]];
  }

  SimplifyOptions opts_;
  double tol2_ = 0, cos_max_turn_ = 0;
  std::vector<Vec3> pos_;
  std::vector<Vec3> points_;  // input positions: the points kept within the bound
  bool optimal_ = false;
  SimplifyCarry* carry_ = nullptr;
  std::vector<Vec3> carried_;         // the carried points, in place of points_ (SimplifyCarry)
  std::vector<Index> carried_owner_;  // their faces, until attach_points()
  std::vector<std::array<Index, 3>> input_faces_;
  Csr input_vf_;  // input vertex -> input faces
  std::vector<uint8_t> boundary_;
  std::vector<std::array<float, 3>> normals_;  // input normals (empty: area-weighted output)
  std::vector<std::array<Index, 3>> faces_;
  std::vector<uint8_t> face_alive_, locked_, dirty_, stuck_;
  std::vector<uint8_t> held_;            // locked by SimplifyCarry: never moves or vanishes, takes collapses
  std::vector<Index> dirty_list_;        // the vertices with dirty_ set
  std::vector<uint8_t> screened_;        // passed the full checks since its last key
  std::vector<Index> keyed_;             // pass in which the key was last computed
  std::vector<Index> found_, found_in_;  // the target a check found, and its pass
  Index pass_ = 0;                       // the current pass (from 1)
  std::vector<std::pair<double, Index>> sorted_;  // candidates by (key, vertex)
  std::size_t alive_faces_ = 0;
  std::vector<Quadric> quadric_;
  std::vector<Index> owner_;       // per input vertex: the face it is attached to
  std::vector<double> key_;        // cheapest quadric cost per vertex (kNoKey: cannot move)
  std::vector<Index> target_;      // survivor of each collapsed vertex
  std::vector<Index> stamp_;       // per vertex: last stamp_counter_ value that marked it
  std::vector<Index> face_stamp_;  // per face, for the flips
  Index stamp_counter_ = 0;
  // Faces removed by the collapse of each vertex, written by collapse(): one slot per vertex, so
  // parallel collapses never share one.
  std::vector<std::size_t> removed_faces_;
  // Step 1 (simplify_blocks): the blocks' cube edge in mean input edge lengths.
  static constexpr double kBlockEdges = 48;
  static constexpr double kBlockFloorShare = 1.5;
  std::vector<Index> inside_;           // per vertex: its block, kNone on a block's border
  std::vector<Index> best_;             // per vertex inside a block: the neighbour giving its key
  bool in_blocks_ = false;              // collapses stay inside the blocks
  double cell_ = 0;                     // the blocks' edge
  Vec3 lo_;                             // the corner of the blocks' grid
  Rows vf_;                             // vertex -> alive faces, ascending
  Arena vf_arena_;                      // rows moved by the passes
  std::vector<Arena> block_vf_arenas_;  // rows moved by the blocks' collapses
  Rows fp_;                             // face -> attached points, ascending
};

}  // namespace

TriangleMesh simplify_within(const TriangleMesh& mesh, const SimplifyOptions& opts, SimplifyStats* stats,
                             SimplifyCarry* carry) {
  if (!(opts.tolerance > 0) || !std::isfinite(opts.tolerance))
    throw Error("simplification: the tolerance must be positive and finite");
  if (!(opts.max_normal_turn_degrees > 0) || !(opts.max_normal_turn_degrees <= 180))
    throw Error("simplification: the normal turn limit must be in (0, 180] degrees");
  return Simplifier(mesh, opts, carry).run(stats);
}

}  // namespace mlfe
