// Face-to-face ray casting on the multilevel tetrahedral mesh (Grosso, Lürig & Ertl, IEEE Vis
// 1997, Sec. 6) with exact pre-integrated segments (Röttger, Kraus & Ertl 2000; Moreland &
// Angel 2004) and empty-space skipping through the hierarchy's per-element ranges. See
// volume_render.h for the traversal steps.
#include <mlfe/core/base/check.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/base/huge_pages.h>
#include <mlfe/core/base/vec.h>
#include <mlfe/core/fem/hierarchical_basis.h>
#include <mlfe/core/field/field.h>
#include <mlfe/core/render/volume_render.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <Eigen/Dense>
#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <memory>

#include "base/counting_sort.h"
#include "base/morton.h"

namespace mlfe {

namespace {

constexpr std::uint32_t kNone = 0xFFFFFFFFu;
constexpr int kFaceVerts[4][3] = {{1, 2, 3}, {0, 2, 3}, {0, 1, 3}, {0, 1, 2}};
// trace_ray's default for RenderOptions::skip_levels: skip a transparent ancestor only when it
// is at least this many levels above the leaf. A skip ends in a point location (climb +
// descent, ~0.2 µs), a leaf step costs ~15 ns; with rays starting at the range grid's first
// visible cell, 5 levels measured 3-5 % faster than 3 and the same as never skipping
// (bench/RESULTS.md, render_bench).
constexpr int kSkipLevels = 5;

// The face a ray o + t d leaves a tetrahedron through after t_in, and where (t_out): the
// nearest plane n_i · x = h_i among the faces with n_i · d > 0, never `entry` (the face the ray
// came in by). When rounding leaves no candidate (a ray grazing a face), the least-entering face
// other than `entry`, at t_in. normal(i) gives n_i in double precision.
template <typename Normal>
int exit_face(const Normal& normal, const double (&h)[4], const Vec3& o, const Vec3& d, double t_in,
              int entry, double& t_out) {
  int best = -1;
  double best_t = std::numeric_limits<double>::infinity();
  for (int i = 0; i < 4; ++i) {
    if (i == entry) continue;
    const Vec3 n = normal(i);
    const double den = dot(n, d);
    if (den <= 0) continue;
    const double t = (h[i] - dot(n, o)) / den;
    if (t < best_t) {
      best_t = t;
      best = i;
    }
  }
  if (best < 0) {
    double best_den = -std::numeric_limits<double>::infinity();
    for (int i = 0; i < 4; ++i) {
      if (i == entry) continue;
      const Vec3 n = normal(i);
      const double den = dot(n, d) / norm(n);
      if (den > best_den) {
        best_den = den;
        best = i;
      }
    }
    best_t = t_in;
  }
  t_out = std::max(t_in, best_t);
  return best;
}

// Outward face normals (unnormalised) of a tetrahedron, face i opposite vertex i, and the
// offsets h_i = n_i · (a vertex of face i), so face i's plane is n_i · x = h_i.
struct TetPlanes {
  Vec3 n[4];
  double h[4];
  explicit TetPlanes(const Vec3 (&p)[4]) {
    for (int i = 0; i < 4; ++i) {
      const Vec3& a = p[kFaceVerts[i][0]];
      n[i] = cross(sub(p[kFaceVerts[i][1]], a), sub(p[kFaceVerts[i][2]], a));
      if (dot(n[i], sub(p[i], a)) > 0) n[i] = {-n[i][0], -n[i][1], -n[i][2]};
      h[i] = dot(n[i], a);
    }
  }
  int exit(const Vec3& o, const Vec3& d, double t_in, int entry, double& t_out) const {
    return exit_face([&](int i) { return n[i]; }, h, o, d, t_in, entry, t_out);
  }
};

// The same rule on a precomputed record (float normals, widened exactly to double), with the
// same arithmetic, but all four faces computed and the nearest picked without branches (the
// branches of exit_face's loop depend on the ray and mispredict); exit_face itself only for
// the grazing fallback.
inline int record_exit(const TetRenderMesh::StepRecord& R, const Vec3& o, const Vec3& d, double t_in,
                       int entry, double& t_out) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  double t[4];
  for (int i = 0; i < 4; ++i) {
    const double nx = R.n[0][i], ny = R.n[1][i], nz = R.n[2][i];
    const double den = nx * d[0] + ny * d[1] + nz * d[2];
    const double num = R.h[i] - (nx * o[0] + ny * o[1] + nz * o[2]);
    t[i] = den > 0 && i != entry ? num / den : kInf;
  }
  int best = -1;
  double best_t = kInf;
  for (int i = 0; i < 4; ++i) {
    const bool nearer = t[i] < best_t;  // the first of equal ones, as exit_face
    best_t = nearer ? t[i] : best_t;
    best = nearer ? i : best;
  }
  if (best < 0) {
    const auto normal = [&](int i) { return Vec3{double(R.n[0][i]), double(R.n[1][i]), double(R.n[2][i])}; };
    return exit_face(normal, R.h, o, d, t_in, entry, t_out);
  }
  t_out = std::max(t_in, best_t);
  return best;
}

void load(const Hierarchy<3>& h, ElemId e, Vec3 (&p)[4]) {
  const auto& c = h.cell(e);
  for (int i = 0; i < 4; ++i) p[i] = h.point(c[i]);
}

// Smallest barycentric coordinate of q in the tetrahedron p (sign-correct for either
// orientation).
double min_barycentric(const Vec3 (&p)[4], const Vec3& q) {
  const Vec3 a = sub(p[1], p[0]), b = sub(p[2], p[0]), c = sub(p[3], p[0]), x = sub(q, p[0]);
  const double det = dot(a, cross(b, c));
  if (det == 0) return -std::numeric_limits<double>::infinity();
  const double l1 = dot(x, cross(b, c)) / det;
  const double l2 = dot(a, cross(x, c)) / det;
  const double l3 = dot(a, cross(b, x)) / det;
  return std::min({1.0 - l1 - l2 - l3, l1, l2, l3});
}

// For each red child and face: the sibling sharing that face and the face's index there, or -1
// for a face on the parent's boundary. Every red refinement stores its children in one pattern
// (Bey's, Hierarchy::red_children; from_arrays checks files against it) and its ten vertices
// are distinct, so the table is read off the first red-refined element by matching vertex sets.
struct RedFacePairs {
  std::int8_t child[8][4];
  std::int8_t face[8][4];
};

RedFacePairs red_face_pairs(const Hierarchy<3>& h) {
  RedFacePairs t;
  for (int k = 0; k < 8; ++k)
    for (int f = 0; f < 4; ++f) t.child[k][f] = t.face[k][f] = -1;
  for (std::uint32_t e = 0; e < h.element_count(); ++e) {
    if (h.is_leaf(ElemId(e)) || h.kind(h.first_child(ElemId(e))) != ElemKind::kRed) continue;
    const std::uint32_t first = h.first_child(ElemId(e)).value;
    MLFE_CHECK(h.num_children(ElemId(e)) == 8);
    const auto face = [&](int k, int f) {
      const auto& c = h.cell(ElemId(first + std::uint32_t(k)));
      std::array<std::uint32_t, 3> v = {c[kFaceVerts[f][0]].value, c[kFaceVerts[f][1]].value,
                                        c[kFaceVerts[f][2]].value};
      std::sort(v.begin(), v.end());
      return v;
    };
    for (int k = 0; k < 8; ++k)
      for (int f = 0; f < 4; ++f)
        for (int j = 0; j < 8; ++j)
          for (int g = 0; g < 4; ++g)
            if (j != k && face(j, g) == face(k, f)) {
              t.child[k][f] = std::int8_t(j);
              t.face[k][f] = std::int8_t(g);
            }
    break;
  }
  return t;
}

// Face neighbours of a conforming element set, as Hierarchy::face_neighbors, as the step
// records' `next` holds them (4 × render index + the local index of the shared face in it);
// render_of gives each hierarchy element's render index (kNone: not rendered). With `siblings`,
// a face between two rendered red children of one element (half of a red refinement's faces)
// is matched within the parent by the red pattern's table: on a conforming mesh no third
// element has that face, so the global match below would pair the same two. (Green siblings
// have no fixed pattern; comparing their faces cost more than the global match of them.) The
// other faces are bucketed by their
// lowest vertex id (a counting sort, linear and parallel: several times faster than
// comparison-sorting all faces on a million tetrahedra), then matched within each bucket (a
// few dozen faces) by their other two vertex ids. Within a bucket the faces are put in
// (key, slot) order before matching, so the result does not depend on the order the buckets
// were filled in. The counting passes read the elements in the hierarchy's order (contiguous
// cells; render order is spatial and would read them at random) in fixed chunks, each with its
// own counters, so that the threads share no counter.
// Returns how many faces more than two elements share (0 on a conforming mesh; the extra ones
// are left as boundary faces).
template <class Next>
std::size_t face_adjacency(const Hierarchy<3>& h, const std::uint32_t* render_of, std::size_t rendered,
                           Next& next, bool siblings) {
  constexpr std::uint32_t kNo = TetRenderMesh::kNoNeighbor;
  const std::size_t nv = h.vertex_count(), ne = h.element_count();
  struct Face {
    std::uint32_t v1, v2;  // the face's two higher vertex ids
    std::uint32_t slot;    // 4 * render index + local face
  };
  // Per rendered element: bit f set when face f is left to the global match (set by the
  // counting pass; not initialised for the others, which are never read).
  std::vector<std::uint8_t, DefaultInit<std::uint8_t>> global(ne);
  const RedFacePairs pairs = siblings ? red_face_pairs(h) : RedFacePairs{};
  // Calls visit(low, v1, v2, slot) for the faces of rendered element e in the global match,
  // face vertex ids ascending.
  const auto faces_of = [&](std::size_t e, auto&& visit) {
    const std::uint32_t r = render_of[e];
    if (r == kNone) return;
    const auto& c = h.cell(ElemId(std::uint32_t(e)));
    for (int f = 0; f < 4; ++f) {
      if (!(global[e] >> f & 1)) continue;
      std::uint32_t v[3] = {c[kFaceVerts[f][0]].value, c[kFaceVerts[f][1]].value, c[kFaceVerts[f][2]].value};
      if (v[0] > v[1]) std::swap(v[0], v[1]);
      if (v[1] > v[2]) std::swap(v[1], v[2]);
      if (v[0] > v[1]) std::swap(v[0], v[1]);
      visit(v[0], v[1], v[2], 4 * r + std::uint32_t(f));
    }
  };
  // 1. faces per (chunk, lowest vertex); 2. bucket offsets, chunk after chunk within a bucket;
  // 3. faces into their buckets, chunks in parallel.
  constexpr std::size_t kChunks = 4;
  const std::size_t per_chunk = (ne + kChunks - 1) / kChunks;
  std::vector<std::uint32_t, DefaultInit<std::uint32_t>> at(kChunks * nv);  // zeroed by each chunk
  tbb::parallel_for(std::size_t(0), kChunks, [&](std::size_t k) {
    std::uint32_t* count = at.data() + k * nv;
    std::fill(count, count + nv, 0u);
    for (std::size_t e = k * per_chunk, end = std::min(ne, e + per_chunk); e < end; ++e) {
      const std::uint32_t r = render_of[e];
      if (r == kNone) continue;
      // Faces shared with a rendered red sibling (the table), the rest to the global match.
      unsigned left = 15;
      const ElemId p = h.parent(ElemId(std::uint32_t(e)));
      if (siblings && p.valid() && h.kind(ElemId(std::uint32_t(e))) == ElemKind::kRed) {
        const std::uint32_t first = h.first_child(p).value;
        const std::uint32_t child = std::uint32_t(e) - first;
        for (int f = 0; f < 4; ++f) {
          if (pairs.child[child][f] < 0) continue;
          const std::uint32_t s = render_of[first + std::uint32_t(pairs.child[child][f])];
          if (s == kNone) continue;
          next[r][f] = 4 * s + std::uint32_t(pairs.face[child][f]);
          left &= ~(1u << f);
        }
      }
      global[e] = std::uint8_t(left);
      faces_of(e, [&](std::uint32_t low, std::uint32_t, std::uint32_t, std::uint32_t) { ++count[low]; });
    }
  });
  std::vector<std::uint32_t> start(nv + 1);
  const std::uint32_t sum = detail::chunked_offsets(at.data(), kChunks, nv, start.data());
  MLFE_CHECK(sum <= 4 * rendered);
  std::unique_ptr<Face[]> faces(new Face[std::max<std::size_t>(sum, 1)]);
  advise_huge_pages(faces.get(), sum * sizeof(Face));
  tbb::parallel_for(std::size_t(0), kChunks, [&](std::size_t k) {
    std::uint32_t* fill = at.data() + k * nv;
    for (std::size_t e = k * per_chunk, end = std::min(ne, e + per_chunk); e < end; ++e)
      faces_of(e, [&](std::uint32_t low, std::uint32_t v1, std::uint32_t v2, std::uint32_t slot) {
        faces[fill[low]++] = {v1, v2, slot};
      });
  });
  // 4. per bucket: equal keys are the two sides of one face.
  std::atomic<std::size_t> overshared{0};
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nv, 1024), [&](const auto& range) {
    for (std::size_t v = range.begin(); v != range.end(); ++v) {
      Face* first = faces.get() + start[v];
      Face* last = faces.get() + start[v + 1];
      // (v1, v2, slot) order, compared as one 64-bit key and the slot: fewer branches.
      std::sort(first, last, [](const Face& x, const Face& y) {
        const std::uint64_t kx = std::uint64_t(x.v1) << 32 | x.v2, ky = std::uint64_t(y.v1) << 32 | y.v2;
        return kx != ky ? kx < ky : x.slot < y.slot;
      });
      for (Face* q = first; q != last; ++q) {
        const bool shared = q + 1 != last && q[1].v1 == q->v1 && q[1].v2 == q->v2;
        const std::uint32_t a = q->slot;
        if (!shared) {
          next[a / 4][a % 4] = kNo;
          continue;
        }
        const std::uint32_t b = q[1].slot;
        next[a / 4][a % 4] = b;
        next[b / 4][b % 4] = a;
        ++q;
        if (q + 1 != last && q[1].v1 == q->v1 && q[1].v2 == q->v2) overshared.fetch_add(1);
      }
    }
  });
  return overshared.load();
}

// Whether T_k renders element e: e is of level k, or a leaf above it.
inline bool rendered_at(const Hierarchy<3>& h, ElemId e, int k) {
  const int l = h.level(e);
  return l == k || (l < k && h.is_leaf(e));
}

// Value ranges of the rendered elements from their vertices, as floats rounded outward, and
// count[e] = 1 for them; 0 and the empty range [inf, -inf] for every other element. In the
// hierarchy's element order: contiguous cells and entries.
void rendered_ranges(const Hierarchy<3>& h, int k, const std::vector<double>& u, std::uint32_t* count,
                     float* lo_out, float* hi_out) {
  constexpr float kInf = std::numeric_limits<float>::infinity();
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, h.element_count(), 4096), [&](const auto& range) {
    for (std::size_t e = range.begin(); e != range.end(); ++e) {
      if (!rendered_at(h, ElemId(std::uint32_t(e)), k)) {
        count[e] = 0;
        lo_out[e] = kInf;
        hi_out[e] = -kInf;
        continue;
      }
      count[e] = 1;
      double lo = std::numeric_limits<double>::infinity(), hi = -lo;
      for (VertexId v : h.cell(ElemId(std::uint32_t(e)))) {
        lo = std::min(lo, u[v.value]);
        hi = std::max(hi, u[v.value]);
      }
      lo_out[e] = std::nextafter(float(lo), -kInf);
      hi_out[e] = std::nextafter(float(hi), kInf);
    }
  });
}

// Calls visit(e) for every element of level l that has children, in parallel.
template <class Visit>
void for_parents_of_level(const Hierarchy<3>& h, int l, Visit&& visit) {
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, h.element_count(), 8192), [&](const auto& range) {
    for (std::size_t i = range.begin(); i != range.end(); ++i) {
      const ElemId e(static_cast<std::uint32_t>(i));
      if (h.level(e) == l && !h.is_leaf(e)) visit(e);
    }
  });
}

// Level after level, finest first, each parent of level < k takes the union of its children's
// ranges and count[e] becomes the number of rendered elements in e's subtree (children are
// contiguous; a parent reads its own children, so the elements of a level go in parallel).
// Returns how many elements T_k has.
std::size_t sweep_up(const Hierarchy<3>& h, int k, std::uint32_t* count, float* lo, float* hi) {
  for (int l = k - 1; l >= 0; --l)
    for_parents_of_level(h, l, [&](ElemId p) {
      const std::uint32_t first = h.first_child(p).value;
      std::uint32_t n = 0;
      float a = lo[p.value], b = hi[p.value];
      for (std::uint32_t c = first, end = first + std::uint32_t(h.num_children(p)); c < end; ++c) {
        n += count[c];
        a = std::min(a, lo[c]);
        b = std::max(b, hi[c]);
      }
      count[p.value] = n;
      lo[p.value] = a;
      hi[p.value] = b;
    });
  std::size_t n = 0;
  for (std::size_t e = 0; e < h.coarse_count(); ++e) n += count[e];
  return n;
}

// The rendered elements in the depth-first order of the refinement tree (T0's elements in id
// order, children in their stored order): a ray steps to face neighbours and the pixels of a
// tile cross neighbouring elements, so records close in space should be close in memory, and a
// subtree is a compact piece of space (a red child lies inside its parent) — the locality of a
// Z-order curve (an octree's depth-first order) without sorting keys read at random points. On
// entry count[e] holds the rendered elements under e (sweep_up); on exit render_of[e] (the
// same array) is e's render index, kNone when e is not rendered. T0's elements get the first
// index of their ranges, then level after level each parent hands consecutive ranges to its
// children.
template <class Elems>
void tree_order(const Hierarchy<3>& h, int k, std::uint32_t* count, std::size_t n, Elems& elems) {
  std::uint32_t* const render_of = count;
  std::uint32_t next = 0;
  for (std::size_t e = 0; e < h.coarse_count(); ++e) {
    const std::uint32_t c = count[e];
    render_of[e] = next;
    next += c;
  }
  MLFE_CHECK(next == n);
  for (int l = 0; l < k; ++l)
    for_parents_of_level(h, l, [&](ElemId p) {
      std::uint32_t first = render_of[p.value];
      const std::uint32_t child = h.first_child(p).value;
      for (std::uint32_t c = child, end = child + std::uint32_t(h.num_children(p)); c < end; ++c) {
        const std::uint32_t m = count[c];
        render_of[c] = first;
        first += m;
      }
      render_of[p.value] = kNone;
    });
  elems.reserve(n);
  advise_huge_pages(elems);
  elems.resize(n);  // not initialised: set below, in parallel
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, h.element_count(), 8192), [&](const auto& range) {
    for (std::size_t i = range.begin(); i != range.end(); ++i) {
      const ElemId e(static_cast<std::uint32_t>(i));
      if (h.level(e) > k)
        render_of[i] = kNone;
      else if (render_of[i] != kNone)
        elems[render_of[i]] = e.value;
    }
  });
}

// Sorts elements along a Z-order (Morton) curve of their centroids: a ray steps to face
// neighbours, and the pixels of a tile cross neighbouring elements, so records close in space
// should be close in memory (the hierarchy's order follows refinement, not space).
// The order is that of the (key, element id) pairs. They are bucketed by the key's top 16 bits
// (a counting sort in fixed chunks, each with its own counters, as face_adjacency's), then each
// bucket (a few dozen pairs) is sorted on its own, buckets in parallel: the same order as a
// comparison sort of all pairs, without its log n passes over them.
template <class Elems>
void morton_order(const Hierarchy<3>& h, Elems& elems) {
  Vec3 lo, hi;
  lo.fill(std::numeric_limits<double>::infinity());
  hi.fill(-std::numeric_limits<double>::infinity());
  for (const auto& q : h.points())
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], q[a]);
      hi[a] = std::max(hi[a], q[a]);
    }
  using Keyed = std::pair<std::uint64_t, std::uint32_t>;
  constexpr int kBucketBits = 16, kKeyBits = 63;
  constexpr std::size_t kBuckets = std::size_t(1) << kBucketBits, kChunks = 4;
  const std::size_t n = elems.size(), per_chunk = (n + kChunks - 1) / kChunks;
  std::vector<std::uint64_t, DefaultInit<std::uint64_t>> keys(n);
  std::vector<Keyed, DefaultInit<Keyed>> sorted(n);
  std::vector<std::uint32_t> at(kChunks * kBuckets, 0);
  // 1. keys, and elements per (chunk, bucket).
  tbb::parallel_for(std::size_t(0), kChunks, [&](std::size_t k) {
    std::uint32_t* count = at.data() + k * kBuckets;
    for (std::size_t i = k * per_chunk, end = std::min(n, i + per_chunk); i < end; ++i) {
      const auto& c = h.cell(ElemId(elems[i]));
      std::uint64_t key = 0;
      for (int a = 0; a < 3; ++a) {
        double m = 0;
        for (VertexId v : c) m += h.point(v)[a];
        const double f = hi[a] > lo[a] ? (0.25 * m - lo[a]) / (hi[a] - lo[a]) : 0.0;
        key |= detail::spread_bits(std::uint64_t(std::clamp(f, 0.0, 1.0) * double(0x1FFFFF))) << a;
      }
      keys[i] = key;
      ++count[key >> (kKeyBits - kBucketBits)];
    }
  });
  // 2. bucket offsets, chunk after chunk within a bucket; 3. pairs into their buckets.
  std::vector<std::uint32_t> start(kBuckets + 1);
  detail::chunked_offsets(at.data(), kChunks, kBuckets, start.data());
  tbb::parallel_for(std::size_t(0), kChunks, [&](std::size_t k) {
    std::uint32_t* fill = at.data() + k * kBuckets;
    for (std::size_t i = k * per_chunk, end = std::min(n, i + per_chunk); i < end; ++i)
      sorted[fill[keys[i] >> (kKeyBits - kBucketBits)]++] = {keys[i], elems[i]};
  });
  // 4. each bucket in (key, id) order, written back.
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, kBuckets, 256), [&](const auto& range) {
    for (std::size_t b = range.begin(); b != range.end(); ++b) {
      std::sort(sorted.begin() + start[b], sorted.begin() + start[b + 1]);
      for (std::size_t i = start[b]; i < start[b + 1]; ++i) elems[i] = sorted[i].second;
    }
  });
}

}  // namespace

// ---------------------------------------------------------------- camera

namespace {

// Camera::ray with the camera's frame computed once per image instead of per pixel (the same
// arithmetic, so the same rays).
class CameraRays {
 public:
  explicit CameraRays(const Camera& c)
      : c_(c), f_(normalized(sub(c.target, c.position))), r_(normalized(cross(f_, c.up))), u_(cross(r_, f_)) {
    aspect_ = double(c.width) / double(c.height);
    th_ = std::tan(0.5 * c.fov_degrees * M_PI / 180.0);
  }
  void ray(double x, double y, Vec3& origin, Vec3& dir) const {
    const Vec3 &f = f_, &r = r_, &u = u_;
    const double sx = 2.0 * (x + 0.5) / c_.width - 1.0, sy = 1.0 - 2.0 * (y + 0.5) / c_.height;
    if (c_.perspective) {
      origin = c_.position;
      dir = normalized({f[0] + (sx * th_ * aspect_) * r[0] + (sy * th_) * u[0],
                        f[1] + (sx * th_ * aspect_) * r[1] + (sy * th_) * u[1],
                        f[2] + (sx * th_ * aspect_) * r[2] + (sy * th_) * u[2]});
    } else {
      const double hh = 0.5 * c_.ortho_height, hw = hh * aspect_;
      origin = {c_.position[0] + sx * hw * r[0] + sy * hh * u[0],
                c_.position[1] + sx * hw * r[1] + sy * hh * u[1],
                c_.position[2] + sx * hw * r[2] + sy * hh * u[2]};
      dir = f;
    }
  }

 private:
  const Camera& c_;
  Vec3 f_, r_, u_;
  double aspect_, th_;
};

// world_to_local_point / _direction with the transform factored once per image.
class ToLocal {
 public:
  explicit ToLocal(const GridTransform& t)
      : origin_(t.origin),
        lu_(Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(t.direction.data())) {}
  Vec3 direction(const Vec3& d) const {
    const Eigen::Vector3d x = lu_.solve(Eigen::Vector3d(d[0], d[1], d[2]));
    return {x[0], x[1], x[2]};
  }
  Vec3 point(const Vec3& p) const { return direction(sub(p, origin_)); }

 private:
  Vec3 origin_;
  Eigen::PartialPivLU<Eigen::Matrix3d> lu_;
};

}  // namespace

void Camera::ray(double x, double y, std::array<double, 3>& origin, std::array<double, 3>& dir) const {
  CameraRays(*this).ray(x, y, origin, dir);
}

std::array<double, 16> Camera::world_to_camera() const {
  const Vec3 f = normalized(sub(target, position));
  const Vec3 r = normalized(cross(f, up));
  const Vec3 u = cross(r, f);
  return {r[0],  r[1],  r[2],  -dot(r, position), u[0], u[1], u[2], -dot(u, position),
          -f[0], -f[1], -f[2], dot(f, position),  0,    0,    0,    1};
}

std::array<double, 16> Camera::world_to_ndc() const {
  Eigen::Matrix4d view =
      Eigen::Map<const Eigen::Matrix<double, 4, 4, Eigen::RowMajor>>(world_to_camera().data());
  Eigen::Matrix4d proj = Eigen::Matrix4d::Zero();
  const double aspect = double(width) / double(height), n = near_clip, fa = far_clip;
  if (perspective) {
    const double th = std::tan(0.5 * fov_degrees * M_PI / 180.0);
    proj(0, 0) = 1.0 / (th * aspect);
    proj(1, 1) = 1.0 / th;
    proj(2, 2) = -(fa + n) / (fa - n);
    proj(2, 3) = -2.0 * fa * n / (fa - n);
    proj(3, 2) = -1.0;
  } else {
    const double hh = 0.5 * ortho_height;
    proj(0, 0) = 1.0 / (hh * aspect);
    proj(1, 1) = 1.0 / hh;
    proj(2, 2) = -2.0 / (fa - n);
    proj(2, 3) = -(fa + n) / (fa - n);
    proj(3, 3) = 1.0;
  }
  const Eigen::Matrix4d m = proj * view;
  std::array<double, 16> out;
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) out[4 * i + j] = m(i, j);
  return out;
}

Camera orbit_camera(const std::array<double, 3>& center, double radius, double azimuth_deg,
                    double elevation_deg, bool perspective, int width, int height) {
  if (!(radius > 0) || width <= 0 || height <= 0)
    throw Error("camera: needs a positive distance and image size (got radius " + std::to_string(radius) +
                ", " + std::to_string(width) + "x" + std::to_string(height) + ")");
  Camera c;
  c.perspective = perspective;
  c.width = width;
  c.height = height;
  const double az = azimuth_deg * M_PI / 180.0, el = elevation_deg * M_PI / 180.0;
  // Direction from the centre to the camera: −y at azimuth 0, turned about z, lifted.
  const Vec3 back{std::sin(az) * std::cos(el), -std::cos(az) * std::cos(el), std::sin(el)};
  const double aspect = double(width) / double(height);
  const double fit = 1.05 * radius * std::max(1.0, 1.0 / aspect);  // half-height that frames the ball
  double dist;
  if (perspective) {
    dist = fit / std::sin(0.5 * c.fov_degrees * M_PI / 180.0);
  } else {
    c.ortho_height = 2.0 * fit;
    dist = 3.0 * radius;
  }
  c.position = axpy(center, dist, back);
  c.target = center;
  // Straight up or down: any horizontal up vector.
  c.up = std::abs(std::cos(el)) < 1e-9 ? Vec3{-std::sin(az), std::cos(az), 0} : Vec3{0, 0, 1};
  c.near_clip = std::max(dist - 1.01 * radius, 1e-3 * radius);
  c.far_clip = dist + 1.01 * radius;
  return c;
}

std::array<double, 3> world_to_local_point(const GridTransform& t, const std::array<double, 3>& p) {
  return ToLocal(t).point(p);
}

std::array<double, 3> world_to_local_direction(const GridTransform& t, const std::array<double, 3>& d) {
  return ToLocal(t).direction(d);
}

// ---------------------------------------------------------------- render mesh

namespace {

// A uniform grid over a box of extent `ext`: per_axis cells along its longest axis, the other
// axes in proportion (at least one cell each; a flat axis gets one cell of size 1).
void shape_grid(const Vec3& ext, double per_axis, int (&n)[3], Vec3& cell) {
  const double longest = std::max({ext[0], ext[1], ext[2]});
  for (int a = 0; a < 3; ++a) {
    n[a] = std::max(1, int(std::ceil(per_axis * ext[a] / longest)));
    cell[a] = ext[a] > 0 ? ext[a] / n[a] : 1.0;
  }
}

}  // namespace

TetRenderMesh::~TetRenderMesh() = default;

// Defined ahead of its callers so that it is inlined (the range grid calls it six times per
// element).
inline int TetRenderMesh::grid_index(int a, double x) const {
  return std::clamp(int(std::floor((x - lo_box_[a]) / grid_cell_[a])), 0, grid_n_[a] - 1);
}

// The set-up, phase after phase, in the order what each phase reads forces: u before the
// ranges, the render order before everything indexed by it (records, neighbours), the box before
// the two grids over it, the neighbours before the boundary faces (the faces without one).
TetRenderMesh::TetRenderMesh(const Hierarchy<3>& h, const std::vector<double>& values, int level,
                             const std::array<double, 3>* clip_to, RayEntry entry)
    : h_(h), entry_(entry) {
  if (values.size() != h.vertex_count())
    throw Error("render: " + std::to_string(values.size()) + " values for a hierarchy of " +
                std::to_string(h.vertex_count()) + " vertices");
  select_values(values, level);
  order_elements();
  reserve_records();
  find_neighbors();
  bound_domain(clip_to);
  build_range_grid();
  if (entry_ == RayEntry::kBoundaryFaces) build_boundary_grid();
}

// u on T_k: on the finest level the values themselves; on a coarser one the hierarchical basis
// without the surpluses of finer vertices, which is what T_k interpolates (so a coarse render
// shows the coarse approximation, not the leaf values at coarse vertices).
void TetRenderMesh::select_values(const std::vector<double>& values, int level) {
  const int finest = h_.max_level();
  level_ = level < 0 || level >= finest ? finest : level;
  if (level_ < finest) {
    coarse_values_ = hierarchical_reconstruct(h_, hierarchical_decompose(h_, values), level_);
    u_ = &coarse_values_;
  } else {
    u_ = &values;
  }
}

// The rendered elements: their value ranges (every element of level ≤ k, for empty-space
// skipping), their render order and their render indices. Everything after is indexed in render
// order, so it comes first; its order is the memory layout the rays walk (tree_order's comment).
void TetRenderMesh::order_elements() {
  const std::size_t ne = h_.element_count();
  for (auto* a : {&lo_, &hi_}) {
    a->reserve(ne);
    advise_huge_pages(*a);
    a->resize(ne);  // not initialised: rendered_ranges sets every entry
  }
  render_of_.reserve(ne);
  advise_huge_pages(render_of_);
  render_of_.resize(ne);
  rendered_ranges(h_, level_, *u_, render_of_.data(), lo_.data(), hi_.data());
  const std::size_t rendered = sweep_up(h_, level_, render_of_.data(), lo_.data(), hi_.data());
  // Neighbour records pack 4 × index + face into 32 bits.
  if (rendered >= (std::size_t(1) << 30))
    throw Error("render: " + std::to_string(rendered) + " tetrahedra exceed the renderer's limit of 2^30");
  tree_order(h_, level_, render_of_.data(), rendered, elems_);
  if (entry_ == RayEntry::kBoundaryFaces) {
    // An unstructured mesh has no refinement tree to follow (T0 is the mesh): Z-order.
    morton_order(h_, elems_);
    tbb::parallel_for(std::size_t(0), elems_.size(),
                      [&](std::size_t r) { render_of_[elems_[r]] = std::uint32_t(r); });
  }
}

// The step records' address space and their chunks' flags, nothing computed: record() builds a
// chunk on first use, so a small image never pays for the records its rays do not cross.
void TetRenderMesh::reserve_records() {
  records_.resize(elems_.size());
  advise_huge_pages(records_);
  const std::size_t chunks = chunk_count();
  built_.reset(new std::atomic<bool>[chunks]);
  for (std::size_t c = 0; c < chunks; ++c) built_[c].store(false, std::memory_order_relaxed);
  build_once_.reset(new std::once_flag[chunks]);
}

// Face neighbours of the rendered elements, up front unlike the records: matching a face needs
// the whole mesh. An unstructured mesh that is not conforming is bad input, reported here.
void TetRenderMesh::find_neighbors() {
  next_.resize(elems_.size());  // not initialised: face_adjacency sets every entry
  advise_huge_pages(next_);
  const std::size_t overshared =
      face_adjacency(h_, render_of_.data(), elems_.size(), next_, entry_ == RayEntry::kHierarchy);
  if (overshared > 0 && entry_ == RayEntry::kBoundaryFaces)
    throw Error("render: " + std::to_string(overshared) +
                " faces are shared by more than two tetrahedra (not a conforming mesh)");
}

// The domain box rays are clipped to: T0 spans the domain, so its vertices bound it; `clip_to`
// cuts it down to the data's box.
void TetRenderMesh::bound_domain(const std::array<double, 3>* clip_to) {
  lo_box_.fill(std::numeric_limits<double>::infinity());
  hi_box_.fill(-std::numeric_limits<double>::infinity());
  for (std::size_t e = 0; e < h_.coarse_count(); ++e)
    for (VertexId v : h_.cell(ElemId(std::uint32_t(e))))
      for (int a = 0; a < 3; ++a) {
        lo_box_[a] = std::min(lo_box_[a], h_.point(v)[a]);
        hi_box_[a] = std::max(hi_box_[a], h_.point(v)[a]);
      }
  if (clip_to)
    for (int a = 0; a < 3; ++a) hi_box_[a] = std::min(hi_box_[a], (*clip_to)[a]);
  diag_ = distance(hi_box_, lo_box_);
}

// The range grid first_visible walks: about one cell per 8 rendered elements (at most 64 along
// the longest axis), each with the union of the ranges of the elements whose (padded) bounding
// boxes overlap it; in the hierarchy's element order, in which its cells are stored.
void TetRenderMesh::build_range_grid() {
  const std::size_t ne = h_.element_count();
  const Vec3 ext = sub(hi_box_, lo_box_);
  const double longest = std::max({ext[0], ext[1], ext[2]});
  shape_grid(ext, std::clamp(std::cbrt(double(elems_.size()) / 8.0), 1.0, 64.0), grid_n_, grid_cell_);
  const std::size_t cells = std::size_t(grid_n_[0]) * grid_n_[1] * grid_n_[2];
  grid_lo_.assign(cells, std::numeric_limits<float>::infinity());
  grid_hi_.assign(cells, -std::numeric_limits<float>::infinity());
  const double pad = 1e-6 * longest;
  // An element's cell range per axis is grid_index of its box's padded ends; grid_index and
  // x ∓ pad are monotone in x, so that is the min (max) of its vertices' padded cells, found
  // once per vertex here instead of six divisions per element.
  for (int a = 0; a < 3; ++a) MLFE_CHECK(grid_n_[a] <= 256);
  std::vector<std::array<std::uint8_t, 6>> vertex_cells(h_.vertex_count());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, h_.vertex_count(), 4096), [&](const auto& range) {
    for (std::size_t v = range.begin(); v != range.end(); ++v) {
      const auto& q = h_.point(VertexId(std::uint32_t(v)));
      for (int a = 0; a < 3; ++a) {
        vertex_cells[v][a] = std::uint8_t(grid_index(a, q[a] - pad));
        vertex_cells[v][3 + a] = std::uint8_t(grid_index(a, q[a] + pad));
      }
    }
  });
  // Chunks of elements in parallel, each into its own grid, then merged: min and max are exact,
  // so the grid does not depend on the split.
  constexpr std::size_t kChunks = 4;
  const std::size_t per_chunk = (ne + kChunks - 1) / kChunks;
  std::vector<std::vector<float>> part_lo(kChunks), part_hi(kChunks);
  tbb::parallel_for(std::size_t(0), kChunks, [&](std::size_t k) {
    std::vector<float>& glo = part_lo[k];
    std::vector<float>& ghi = part_hi[k];
    glo.assign(cells, std::numeric_limits<float>::infinity());
    ghi.assign(cells, -std::numeric_limits<float>::infinity());
    for (std::size_t i = k * per_chunk, end = std::min(ne, i + per_chunk); i < end; ++i) {
      if (render_of_[i] == kNone) continue;
      int c0[3] = {255, 255, 255}, c1[3] = {0, 0, 0};
      for (VertexId v : h_.cell(ElemId(std::uint32_t(i))))
        for (int a = 0; a < 3; ++a) {
          c0[a] = std::min<int>(c0[a], vertex_cells[v.value][a]);
          c1[a] = std::max<int>(c1[a], vertex_cells[v.value][3 + a]);
        }
      for (int z = c0[2]; z <= c1[2]; ++z)
        for (int y = c0[1]; y <= c1[1]; ++y)
          for (int x = c0[0]; x <= c1[0]; ++x) {
            const std::size_t c = (std::size_t(z) * grid_n_[1] + y) * grid_n_[0] + x;
            glo[c] = std::min(glo[c], lo_[i]);
            ghi[c] = std::max(ghi[c], hi_[i]);
          }
    }
  });
  for (std::size_t k = 0; k < kChunks; ++k)
    for (std::size_t c = 0; c < cells; ++c) {
      grid_lo_[c] = std::min(grid_lo_[c], part_lo[k][c]);
      grid_hi_[c] = std::max(grid_hi_[c], part_hi[k][c]);
    }
}

// One step record (see StepRecord): the face planes, u's plane and the neighbours of element r.
void TetRenderMesh::compute_record(std::uint32_t r, StepRecord& R) const {
  const auto& c = h_.cell(ElemId(elems_[r]));
  Vec3 p[4];
  for (int i = 0; i < 4; ++i) p[i] = h_.point(c[i]);
  Vec3 g{0, 0, 0};
  for (int i = 0; i < 4; ++i) {
    // The face's vertices in id order, so both elements sharing it compute the same normal.
    int f[3] = {kFaceVerts[i][0], kFaceVerts[i][1], kFaceVerts[i][2]};
    std::sort(f, f + 3, [&](int x, int y) { return c[x] < c[y]; });
    Vec3 n = cross(sub(p[f[1]], p[f[0]]), sub(p[f[2]], p[f[0]]));
    if (dot(n, sub(p[i], p[f[0]])) > 0) n = {-n[0], -n[1], -n[2]};
    const Vec3 nf{double(float(n[0])), double(float(n[1])), double(float(n[2]))};
    for (int a = 0; a < 3; ++a) R.n[a][i] = float(nf[a]);
    R.h[i] = dot(nf, p[f[0]]);
    // ∇λ_i = n_i / (n_i · (p_i − p_face)), from the exact normal.
    const double w = (*u_)[c[i].value] / dot(n, sub(p[i], p[f[0]]));
    for (int a = 0; a < 3; ++a) g[a] += w * n[a];
  }
  for (int a = 0; a < 3; ++a) R.g[a] = float(g[a]);
  const Vec3 gf{double(R.g[0]), double(R.g[1]), double(R.g[2])};
  R.b = (*u_)[c[0].value] - dot(gf, p[0]);
  for (int f = 0; f < 4; ++f) R.next[f] = next_[r][f];
}

void TetRenderMesh::build_all_records() const {
  const std::size_t chunks = chunk_count();
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, chunks, 4), [&](const auto& range) {
    for (std::size_t c = range.begin(); c != range.end(); ++c)
      if (!built_[c].load(std::memory_order_acquire)) build_chunk(std::uint32_t(c));
  });
}

void TetRenderMesh::build_chunk(std::uint32_t chunk) const {
  std::call_once(build_once_[chunk], [&] {
    const std::size_t first = std::size_t(chunk) << kChunkBits;
    const std::size_t last = std::min(records_.size(), first + (std::size_t(1) << kChunkBits));
    for (std::size_t r = first; r < last; ++r) compute_record(std::uint32_t(r), records_[r]);
    built_[chunk].store(true, std::memory_order_release);
  });
}

double TetRenderMesh::first_visible(const std::array<double, 3>& o, const std::array<double, 3>& d, double t0,
                                    double t1, const CompiledTransferFunction& tf) const {
  // 3D DDA (Amanatides & Woo 1987) from the cell of o + t0 d.
  const Vec3 p = axpy(o, t0, d);
  int i[3], step[3];
  double t_next[3], t_delta[3];
  for (int a = 0; a < 3; ++a) {
    i[a] = grid_index(a, p[a]);
    step[a] = d[a] > 0 ? 1 : d[a] < 0 ? -1 : 0;
    if (step[a] == 0) {
      t_next[a] = t_delta[a] = std::numeric_limits<double>::infinity();
      continue;
    }
    const double face = lo_box_[a] + (i[a] + (step[a] > 0 ? 1 : 0)) * grid_cell_[a];
    t_next[a] = t0 + (face - p[a]) / d[a];
    t_delta[a] = grid_cell_[a] / std::abs(d[a]);
  }
  // Back off into the transparent cell before (by far more than locate's nudge).
  const double back = 1e-3 * std::min({grid_cell_[0], grid_cell_[1], grid_cell_[2]}) / norm(d);
  double t = t0;
  while (true) {
    const std::size_t c = (std::size_t(i[2]) * grid_n_[1] + i[1]) * grid_n_[0] + i[0];
    if (!(grid_lo_[c] > grid_hi_[c]) && !tf.transparent(grid_lo_[c], grid_hi_[c]))
      return std::max(t0, t - back);
    const int a = t_next[0] < t_next[1] ? (t_next[0] < t_next[2] ? 0 : 2) : (t_next[1] < t_next[2] ? 1 : 2);
    t = t_next[a];
    if (t >= t1) return t1;
    i[a] += step[a];
    if (i[a] < 0 || i[a] >= grid_n_[a]) return t1;
    t_next[a] += t_delta[a];
  }
}

// ---------------------------------------------------------------- boundary faces

// The boundary faces of an unstructured mesh (RayEntry::kBoundaryFaces) in a uniform grid of
// buckets over the box: each bucket lists the faces whose (padded) bounding box overlaps it.
struct TetRenderMesh::BoundaryGrid {
  struct Face {
    Vec3 p[3];           // the vertices in ascending id order (see face_crossed)
    std::uint32_t slot;  // 4 × render index + local face
  };
  std::vector<Face> faces;
  int n[3] = {1, 1, 1};
  Vec3 lo{0, 0, 0}, cell{1, 1, 1};
  std::vector<std::uint32_t> start, list;  // bucket c holds list[start[c] .. start[c + 1])

  int index(int a, double x) const { return std::clamp(int(std::floor((x - lo[a]) / cell[a])), 0, n[a] - 1); }
  std::size_t bytes() const {
    return faces.capacity() * sizeof(Face) + (start.capacity() + list.capacity()) * sizeof(std::uint32_t);
  }
};

void TetRenderMesh::build_boundary_grid() {
  auto g = std::make_unique<BoundaryGrid>();
  // 1. the faces without a neighbour, in render order.
  for (std::size_t r = 0; r < records_.size(); ++r)
    for (int f = 0; f < 4; ++f) {
      if (next_[r][f] != kNoNeighbor) continue;
      const auto& c = h_.cell(ElemId(elems_[r]));
      VertexId v[3] = {c[kFaceVerts[f][0]], c[kFaceVerts[f][1]], c[kFaceVerts[f][2]]};
      std::sort(v, v + 3);
      BoundaryGrid::Face face;
      for (int i = 0; i < 3; ++i) face.p[i] = h_.point(v[i]);
      face.slot = std::uint32_t(4 * r + f);
      g->faces.push_back(face);
    }
  // 2. buckets: about 8 faces per bucket along a surface (a closed surface of F faces in a grid
  // of n³ buckets meets ~6 n² of them), at most 256 along the longest axis.
  const Vec3 ext = sub(hi_box_, lo_box_);
  const double longest = std::max({ext[0], ext[1], ext[2]});
  g->lo = lo_box_;
  shape_grid(ext, std::clamp(std::sqrt(double(g->faces.size()) / 8.0), 1.0, 256.0), g->n, g->cell);
  const std::size_t cells = std::size_t(g->n[0]) * g->n[1] * g->n[2];
  const double pad = 1e-7 * longest;
  // Calls visit(bucket) for every bucket face i's padded bounding box overlaps.
  const auto for_buckets = [&](const BoundaryGrid::Face& face, auto&& visit) {
    int c0[3], c1[3];
    for (int a = 0; a < 3; ++a) {
      const double lo = std::min({face.p[0][a], face.p[1][a], face.p[2][a]});
      const double hi = std::max({face.p[0][a], face.p[1][a], face.p[2][a]});
      c0[a] = g->index(a, lo - pad);
      c1[a] = g->index(a, hi + pad);
    }
    for (int z = c0[2]; z <= c1[2]; ++z)
      for (int y = c0[1]; y <= c1[1]; ++y)
        for (int x = c0[0]; x <= c1[0]; ++x) visit((std::size_t(z) * g->n[1] + y) * g->n[0] + x);
  };
  g->start.assign(cells + 1, 0);
  for (const auto& face : g->faces) for_buckets(face, [&](std::size_t c) { ++g->start[c + 1]; });
  for (std::size_t c = 0; c < cells; ++c) g->start[c + 1] += g->start[c];
  g->list.resize(g->start[cells]);
  std::vector<std::uint32_t> fill(g->start.begin(), g->start.end() - 1);
  for (std::size_t i = 0; i < g->faces.size(); ++i)
    for_buckets(g->faces[i], [&](std::size_t c) { g->list[fill[c]++] = std::uint32_t(i); });
  boundary_ = std::move(g);
}

std::size_t TetRenderMesh::boundary_face_count() const { return boundary_ ? boundary_->faces.size() : 0; }

namespace {

// Whether the line o + t d meets the triangle (inclusive), by the signs of the edge terms
// d · ((a − o) × (b − o)). Each is computed with the edge's lower vertex id first (face
// vertices are stored in id order), so two faces sharing an edge compute the same number and
// no ray slips between them.
inline bool face_crossed(const Vec3 (&p)[3], const Vec3& o, const Vec3& d) {
  const Vec3 a = sub(p[0], o), b = sub(p[1], o), c = sub(p[2], o);
  const double e01 = dot(d, cross(a, b)), e12 = dot(d, cross(b, c)), e02 = dot(d, cross(a, c));
  // Around the triangle 0 → 1 → 2 → 0 the terms are e01, e12, −e02.
  return (e01 >= 0 && e12 >= 0 && e02 <= 0) || (e01 <= 0 && e12 <= 0 && e02 >= 0);
}

}  // namespace

bool TetRenderMesh::boundary_hit(const std::array<double, 3>& o, const std::array<double, 3>& d, double t_min,
                                 double t_max, bool inward_only, const std::uint32_t (&skip)[2],
                                 BoundaryHit& hit) const {
  MLFE_CHECK(boundary_ != nullptr);
  const BoundaryGrid& g = *boundary_;
  // 3D DDA (as first_visible) from the bucket of o + t_min d; a hit found in a bucket is the
  // first when it lies before the bucket's far side (a nearer face would be listed in a
  // bucket already visited).
  const Vec3 p = axpy(o, t_min, d);
  int i[3], step[3];
  double t_next[3], t_delta[3];
  for (int a = 0; a < 3; ++a) {
    i[a] = g.index(a, p[a]);
    step[a] = d[a] > 0 ? 1 : d[a] < 0 ? -1 : 0;
    if (step[a] == 0) {
      t_next[a] = t_delta[a] = std::numeric_limits<double>::infinity();
      continue;
    }
    const double face = g.lo[a] + (i[a] + (step[a] > 0 ? 1 : 0)) * g.cell[a];
    t_next[a] = t_min + (face - p[a]) / d[a];
    t_delta[a] = g.cell[a] / std::abs(d[a]);
  }
  bool found = false;
  double best_t = std::numeric_limits<double>::infinity();
  std::uint32_t best_slot = kNoNeighbor;
  while (true) {
    const std::size_t c = (std::size_t(i[2]) * g.n[1] + i[1]) * g.n[0] + i[0];
    for (std::uint32_t k = g.start[c]; k != g.start[c + 1]; ++k) {
      const BoundaryGrid::Face& face = g.faces[g.list[k]];
      if (face.slot == skip[0] || face.slot == skip[1]) continue;
      // The plane as record_exit sees it.
      const StepRecord& R = record(face.slot / 4);
      const int f = int(face.slot % 4);
      const double nx = R.n[0][f], ny = R.n[1][f], nz = R.n[2][f];
      const double den = nx * d[0] + ny * d[1] + nz * d[2];
      if (den == 0 || (inward_only && den > 0)) continue;
      const double t = (R.h[f] - (nx * o[0] + ny * o[1] + nz * o[2])) / den;
      if (!(t >= t_min && t <= t_max)) continue;
      if (t > best_t || (t == best_t && face.slot > best_slot)) continue;
      if (!face_crossed(face.p, o, d)) continue;
      found = true;
      best_t = t;
      best_slot = face.slot;
    }
    const int a = t_next[0] < t_next[1] ? (t_next[0] < t_next[2] ? 0 : 2) : (t_next[1] < t_next[2] ? 1 : 2);
    if (found && best_t <= t_next[a]) break;
    if (t_next[a] > t_max) break;
    i[a] += step[a];
    if (i[a] < 0 || i[a] >= g.n[a]) break;
    t_next[a] += t_delta[a];
  }
  if (!found) return false;
  hit.tet = best_slot / 4;
  hit.face = int(best_slot % 4);
  hit.t = best_t;
  const StepRecord& R = record(hit.tet);
  hit.inward =
      double(R.n[0][hit.face]) * d[0] + double(R.n[1][hit.face]) * d[1] + double(R.n[2][hit.face]) * d[2] < 0;
  return true;
}

std::size_t TetRenderMesh::records_built() const {
  // One flag per 512 records: a scan costs nothing beside a render.
  const std::size_t chunks = chunk_count();
  std::size_t n = 0;
  for (std::size_t c = 0; c < chunks; ++c)
    if (built_[c].load(std::memory_order_acquire))
      n += std::min(records_.size(), (c + 1) << kChunkBits) - (c << kChunkBits);
  return n;
}

std::size_t TetRenderMesh::memory_bytes() const {
  return coarse_values_.capacity() * sizeof(double) + elems_.capacity() * sizeof(elems_[0]) +
         records_built() * sizeof(StepRecord) + next_.capacity() * sizeof(next_[0]) +
         render_of_.capacity() * sizeof(std::uint32_t) + (lo_.capacity() + hi_.capacity()) * sizeof(float) +
         (boundary_ ? boundary_->bytes() : 0);
}

std::uint32_t TetRenderMesh::locate(const std::array<double, 3>& p, const std::array<double, 3>& d,
                                    ElemId hint) const {
  const Vec3 q = axpy(p, 1e-7 * diag_ / norm(d), d);
  Vec3 pts[4];
  // 1. climb from the hint to an ancestor containing q (none: start from T0).
  while (hint.valid()) {
    load(h_, hint, pts);
    if (min_barycentric(pts, q) >= 0) break;
    hint = h_.parent(hint);
  }
  auto best_of = [&](ElemId first, std::size_t count) {
    ElemId best = first;
    double best_b = -std::numeric_limits<double>::infinity();
    for (std::size_t i = 0; i < count; ++i) {
      const ElemId e(first.value + std::uint32_t(i));
      load(h_, e, pts);
      const double b = min_barycentric(pts, q);
      if (b > best_b) {
        best_b = b;
        best = e;
      }
      if (b >= 0) break;  // inside (children do not overlap)
    }
    return best;
  };
  // 2. descend to T_k.
  ElemId e = hint.valid() ? hint : best_of(ElemId(0), h_.coarse_count());
  while (render_of_[e.value] == kNone) {
    MLFE_CHECK(!h_.is_leaf(e));
    e = best_of(h_.first_child(e), std::size_t(h_.num_children(e)));
  }
  return render_of_[e.value];
}

std::uint32_t TetRenderMesh::walk_to(std::uint32_t start, const std::array<double, 3>& p,
                                     const std::array<double, 3>& d) const {
  const Vec3 q = axpy(p, 1e-7 * diag_ / norm(d), d);
  Vec3 pts[4];
  std::uint32_t r = start;
  for (int step = 0; step < 32; ++step) {
    load(h_, ElemId(elems_[r]), pts);
    const Vec3 a = sub(pts[1], pts[0]), b = sub(pts[2], pts[0]), c = sub(pts[3], pts[0]), x = sub(q, pts[0]);
    const double det = dot(a, cross(b, c));
    const double l1 = dot(x, cross(b, c)) / det, l2 = dot(a, cross(x, c)) / det,
                 l3 = dot(a, cross(b, x)) / det;
    const double l[4] = {1.0 - l1 - l2 - l3, l1, l2, l3};
    const int f = int(std::min_element(l, l + 4) - l);
    if (l[f] >= 0) return r;
    const std::uint32_t next = next_[r][f];
    if (next == kNoNeighbor) break;
    r = next >> 2;
  }
  return locate(p, d, ElemId(elems_[start]));
}

// ---------------------------------------------------------------- traversal

namespace {

// Clips o + t d (t ≥ 0) to the box; false when it misses.
bool clip_to_box(const Vec3& lo, const Vec3& hi, const Vec3& o, const Vec3& d, double& t0, double& t1) {
  t0 = 0;
  t1 = std::numeric_limits<double>::infinity();
  for (int a = 0; a < 3; ++a) {
    if (d[a] == 0) {
      if (o[a] < lo[a] || o[a] > hi[a]) return false;
      continue;
    }
    double ta = (lo[a] - o[a]) / d[a], tb = (hi[a] - o[a]) / d[a];
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
  }
  return t0 < t1;
}

// What empty-space skipping does with a rendered element: u is evaluated (kVisible), the
// element is walked without evaluating u (kEmptyLeaf), or its largest transparent ancestor,
// kSkipLevels or more above it, is crossed in one step (kSkipAncestor).
enum EmptyState : std::uint8_t { kVisible = 0, kEmptyLeaf = 1, kSkipAncestor = 2 };

// The largest ancestor of e (or e) whose range is transparent for `skip`; e must be.
ElemId largest_transparent(const TetRenderMesh& m, const CompiledTransferFunction& skip, ElemId e) {
  const Hierarchy<3>& h = m.hierarchy();
  ElemId a = e;
  while (h.parent(a).valid() && skip.transparent(m.range_lo(h.parent(a)), m.range_hi(h.parent(a))))
    a = h.parent(a);
  return a;
}

EmptyState empty_state(const TetRenderMesh& m, const CompiledTransferFunction& skip, ElemId e, int levels) {
  if (!skip.transparent(m.range_lo(e), m.range_hi(e))) return kVisible;
  const Hierarchy<3>& h = m.hierarchy();
  return h.level(e) - h.level(largest_transparent(m, skip, e)) >= levels ? kSkipAncestor : kEmptyLeaf;
}

// One ray's walk through m (steps 1–5 of volume_render.h): begin_walk, then walk_step per
// element.
struct RayWalk {
  Vec3 o, d;
  double t = 0, eps = 0;
  std::uint64_t bound = 0;
  std::uint32_t r = 0;
  int entry = -1;
  std::uint32_t entered = TetRenderMesh::kNoNeighbor;  // boundary face of the last entry
  bool stored = true;  // step records from the mesh's store, else computed per step
  TraceResult res;
};

// RayEntry::kBoundaryFaces: the element containing o + t d, walked back along −d from the
// boundary face `hit` the ray leaves through after t (the ray is inside the mesh in between:
// a camera inside the mesh, or a start moved forward by first_visible).
std::uint32_t walk_back(const TetRenderMesh& m, const Vec3& o, const Vec3& d,
                        const TetRenderMesh::BoundaryHit& hit, double t, std::uint64_t bound) {
  const Vec3 back{-d[0], -d[1], -d[2]};
  std::uint32_t r = hit.tet;
  int entry = hit.face;
  double s = -hit.t;  // o + s·back = o + t·d at s = −t
  for (std::uint64_t step = 0; step < bound; ++step) {
    const TetRenderMesh::StepRecord& R = m.record(r);
    double s_out;
    const int f = record_exit(R, o, back, s, entry, s_out);
    const std::uint32_t next = R.next[f];
    if (s_out >= -t || next == TetRenderMesh::kNoNeighbor) break;
    r = next >> 2;
    entry = int(next & 3u);
    s = s_out;
  }
  return r;
}

// Step 2 for RayEntry::kBoundaryFaces: the first boundary face crossed after w.t; inward, the
// walk starts there, else at the element walked back to.
inline bool begin_boundary_walk(const TetRenderMesh& m, RayWalk& w) {
  const std::uint32_t none[2] = {TetRenderMesh::kNoNeighbor, TetRenderMesh::kNoNeighbor};
  TetRenderMesh::BoundaryHit hit;
  if (!m.boundary_hit(w.o, w.d, w.t - w.eps, w.res.t_far + w.eps, false, none, hit)) return false;
  if (hit.inward) {
    w.r = hit.tet;
    w.entry = hit.face;
    w.entered = 4 * hit.tet + std::uint32_t(hit.face);
    w.t = std::max(w.t, hit.t);
  } else {
    w.r = walk_back(m, w.o, w.d, hit, w.t, w.bound);
  }
  return true;
}

// Steps 1–2: clips the ray and finds its entry element; false when nothing is to be walked.
inline bool begin_walk(const TetRenderMesh& m, const Vec3& o, const Vec3& d,
                       const CompiledTransferFunction* skip, ElemId* entry_hint, RayWalk& w) {
  w.o = o, w.d = d;
  w.res = TraceResult{};
  w.entry = -1;
  w.entered = TetRenderMesh::kNoNeighbor;
  if (!clip_to_box(m.box_lo(), m.box_hi(), o, d, w.res.t_near, w.res.t_far)) return false;
  w.res.hit = true;
  w.eps = 1e-9 * (w.res.t_far - w.res.t_near + distance(m.box_hi(), m.box_lo()));
  w.bound = m.size() + 64;
  w.t = w.res.t_near;
  if (skip) {
    w.t = m.first_visible(o, d, w.t, w.res.t_far, *skip);
    if (w.t >= w.res.t_far) return false;
  }
  if (m.ray_entry() == RayEntry::kBoundaryFaces) return begin_boundary_walk(m, w);
  // Entry: walk from the previous pixel's entry (usually the same or a neighbouring element),
  // else descend the hierarchy.
  const std::int32_t start = entry_hint && entry_hint->valid() ? m.render_index(*entry_hint) : -1;
  w.r = start >= 0 ? m.walk_to(std::uint32_t(start), axpy(o, w.t, d), d) : m.locate(axpy(o, w.t, d), d);
  if (entry_hint) *entry_hint = m.element(w.r);
  return true;
}

// Steps 3–5 for one element (or one skipped ancestor); false when the ray is finished. state(r)
// gives the EmptyState of element r (only called with skip set): computed per element crossed
// for a single ray, looked up in a table made once per image when rendering.
template <class State, class Visit>
inline bool walk_step(const TetRenderMesh& m, const CompiledTransferFunction* skip, State&& state,
                      Visit&& visit, RayWalk& w) {
  TraceResult& res = w.res;
  const Vec3 &o = w.o, &d = w.d;
  if (++res.steps > w.bound) {
    res.step_bound_hit = true;
    return false;
  }
  // Empty space: the largest transparent ancestor is crossed in one step when it is at least
  // kSkipLevels above (locating again behind it costs about as much as walking a few leaves);
  // a transparent leaf is walked without evaluating u.
  const EmptyState es = skip ? EmptyState(state(w.r)) : kVisible;
  if (es == kSkipAncestor) {
    const ElemId a = largest_transparent(m, *skip, m.element(w.r));
    Vec3 p[4];
    load(m.hierarchy(), a, p);
    double t_out;
    TetPlanes(p).exit(o, d, w.t, -1, t_out);
    t_out = std::min(t_out, res.t_far);
    if (!visit(TraceSegment{-1, w.t, t_out, 0, 0, {0, 0, 0}, true})) return false;
    ++res.skips;
    w.t = t_out;
    if (w.t >= res.t_far - w.eps) return false;
    w.r = m.locate(axpy(o, w.t, d), d, a);
    w.entry = -1;
    return true;
  }
  const bool empty = es != kVisible;
  TetRenderMesh::StepRecord computed;
  if (!w.stored) m.compute_record(w.r, computed);
  const TetRenderMesh::StepRecord& R = w.stored ? m.record(w.r) : computed;
  // The next record is one of three: ask for them now, so their loads overlap this step's work
  // instead of stalling the next one.
  for (int i = 0; i < 4 && w.stored; ++i)
    if (i != w.entry && R.next[i] != TetRenderMesh::kNoNeighbor) {
      const char* q = reinterpret_cast<const char*>(m.record_address(R.next[i] >> 2));
      __builtin_prefetch(q);
      __builtin_prefetch(q + 64);
    }
  double t_out;
  const int f = record_exit(R, o, d, w.t, w.entry, t_out);
  t_out = std::min(t_out, res.t_far);
  TraceSegment seg{std::int32_t(w.r), w.t, t_out, 0, 0, {0, 0, 0}, empty};
  if (!empty) {
    seg.gradient = {double(R.g[0]), double(R.g[1]), double(R.g[2])};
    seg.s0 = R.b + dot(seg.gradient, axpy(o, w.t, d));
    seg.s1 = R.b + dot(seg.gradient, axpy(o, t_out, d));
  }
  if (!visit(seg)) return false;
  w.t = t_out;
  const std::uint32_t next = R.next[f];
  if (next == TetRenderMesh::kNoNeighbor) {
    if (w.t >= res.t_far - w.eps) return false;
    if (m.ray_entry() == RayEntry::kBoundaryFaces) {
      // Left through the boundary: on to the next inward face behind (a non-convex mesh), never
      // the face just left nor the one last entered by (a ray grazing an edge would bounce).
      const std::uint32_t skip[2] = {4 * w.r + std::uint32_t(f), w.entered};
      TetRenderMesh::BoundaryHit hit;
      if (!m.boundary_hit(o, d, w.t - w.eps, res.t_far, true, skip, hit)) return false;
      ++res.reentries;
      w.r = hit.tet;
      w.entry = hit.face;
      w.entered = 4 * hit.tet + std::uint32_t(hit.face);
      w.t = std::max(w.t, hit.t);
      return true;
    }
    // Left the mesh before the box exit (rounding at the boundary): locate again.
    ++res.relocations;
    w.r = m.locate(axpy(o, w.t, d), d, m.element(w.r));
    w.entry = -1;
    return true;
  }
  w.entry = int(next & 3u);
  w.r = next >> 2;
  return true;
}

template <class State, class Visit>
TraceResult trace(const TetRenderMesh& m, const Vec3& o, const Vec3& d, const CompiledTransferFunction* skip,
                  State&& state, Visit&& visit, ElemId* entry_hint, bool stored = true) {
  RayWalk w;
  w.stored = stored;
  if (begin_walk(m, o, d, skip, entry_hint, w))
    while (walk_step(m, skip, state, visit, w)) {
    }
  return w.res;
}

}  // namespace

TraceResult trace_ray(const TetRenderMesh& m, const std::array<double, 3>& origin,
                      const std::array<double, 3>& dir, const CompiledTransferFunction* skip,
                      const std::function<bool(const TraceSegment&)>& visit, ElemId* entry_hint) {
  const int levels =
      m.ray_entry() == RayEntry::kBoundaryFaces ? std::numeric_limits<int>::max() : kSkipLevels;
  return trace(
      m, origin, dir, skip, [&](std::uint32_t r) { return empty_state(m, *skip, m.element(r), levels); },
      visit, entry_hint);
}

// ---------------------------------------------------------------- images

namespace {

struct Counters {
  std::atomic<std::uint64_t> rays{0}, segments{0}, skips{0}, relocations{0}, bound{0}, reentries{0};
  void to(RenderStats* s) const {
    if (!s) return;
    s->reentries = reentries;
    s->rays = rays;
    s->segments = segments;
    s->skips = skips;
    s->relocations = relocations;
    s->step_bound_hits = bound;
  }
};

constexpr int kTile = 16;

RenderImage blank_image(const Camera& cam) {
  if (cam.width <= 0 || cam.height <= 0)
    throw Error("render: image size must be positive (got " + std::to_string(cam.width) + "x" +
                std::to_string(cam.height) + ")");
  RenderImage img;
  img.width = cam.width;
  img.height = cam.height;
  img.rgba.assign(std::size_t(cam.width) * cam.height * 4, 0.0f);
  img.z.assign(std::size_t(cam.width) * cam.height, std::numeric_limits<float>::infinity());
  return img;
}

void store(RenderImage& img, int x, int y, const RayAccumulator& acc) {
  const std::size_t i = std::size_t(y) * img.width + x;
  for (int c = 0; c < 3; ++c) img.rgba[4 * i + c] = float(acc.rgb()[c]);
  img.rgba[4 * i + 3] = float(1.0 - acc.transmittance());
  img.z[i] = float(acc.depth());
}

// Runs pixel(x, y, acc, hint) over fixed 16x16 tiles in parallel. A pixel depends only on its
// tile (the entry hint is reset per tile), so the image does not depend on how tiles are
// distributed over threads.
template <class Pixel>
RenderImage render_tiles(const Camera& cam, const CompiledTransferFunction& ctf, const RenderOptions& opt,
                         Pixel&& pixel) {
  RenderImage img = blank_image(cam);
  const int tx = (cam.width + kTile - 1) / kTile, ty = (cam.height + kTile - 1) / kTile;
  tbb::parallel_for(0, tx * ty, [&](int tile) {
    RayAccumulator acc(ctf, opt.rule, opt.stop_opacity, opt.z_opacity);
    ElemId hint = ElemId::invalid();
    const int x0 = (tile % tx) * kTile, y0 = (tile / tx) * kTile;
    for (int y = y0; y < std::min(y0 + kTile, cam.height); ++y)
      for (int x = x0; x < std::min(x0 + kTile, cam.width); ++x) {
        acc.reset();
        pixel(x, y, acc, hint);
        store(img, x, y, acc);
      }
  });
  return img;
}

// RenderOptions::records. kAuto: the segments of the images expected, estimated as the rays
// that hit the box times kCrossed × n^(1/3) (a ray crosses about that many of n elements:
// 0.41-0.69 measured on the full heads' hierarchies of 1.3 M, 10.6 M and 13.7 M leaves), against
// twice the elements. Measured at 500x500: H225k (3.7 crossings per element) renders as fast
// either way; the default build's file (0.7) twice as fast end to end computed, with 1.3 GB
// less memory.
bool store_records(const TetRenderMesh& m, const CameraRays& rays, const ToLocal& to_local,
                   const Camera& camera, const RenderOptions& opt) {
  using Records = RenderOptions::Records;
  if (m.ray_entry() == RayEntry::kBoundaryFaces || opt.records == Records::kStore) return true;
  if (opt.records == Records::kCompute) return false;
  if (m.records_built() == m.size()) return true;
  constexpr double kCrossed = 0.5, kStoreFrom = 2.0;
  const std::size_t hits = tbb::parallel_reduce(
      tbb::blocked_range<int>(0, camera.height, 16), std::size_t(0),
      [&](const tbb::blocked_range<int>& r, std::size_t n) {
        for (int y = r.begin(); y != r.end(); ++y)
          for (int x = 0; x < camera.width; ++x) {
            Vec3 ow, dw;
            rays.ray(x, y, ow, dw);
            double t0, t1;
            n += clip_to_box(m.box_lo(), m.box_hi(), to_local.point(ow), to_local.direction(dw), t0, t1);
          }
        return n;
      },
      std::plus<>());
  const double n = double(m.size());
  const double segments = double(hits) * double(std::max(opt.images, 1)) * kCrossed * std::cbrt(n);
  return segments >= kStoreFrom * n;
}

double shade_factor(const Vec3& g, const Vec3& d) {
  const double gg = dot(g, g);
  if (gg == 0) return 1.0;
  return 0.35 + 0.65 * std::abs(dot(g, d)) / std::sqrt(gg * dot(d, d));
}

}  // namespace

RenderImage render_mesh(const TetRenderMesh& m, const GridTransform& transform, const TransferFunction& tf,
                        const Camera& camera, const RenderOptions& opt, RenderStats* stats) {
  const CompiledTransferFunction ctf(tf);
  const CameraRays rays(camera);
  const ToLocal to_local(transform);
  const bool stored = store_records(m, rays, to_local, camera, opt);
  // An image whose rays will cross most elements (a ray crosses some 50-100 on the meshes
  // measured) builds all step records first, in parallel: built on first touch instead, its
  // threads wait on each other's chunks.
  if (stored && std::size_t(camera.width) * std::size_t(camera.height) * 64 >= m.size())
    m.build_all_records();
  // What skipping does with each element, for this transfer function: once per image rather
  // than per element crossed.
  std::vector<std::uint8_t> state;
  if (opt.skip_empty) {
    state.resize(m.size());
    const int levels =
        m.ray_entry() == RayEntry::kBoundaryFaces ? std::numeric_limits<int>::max() : opt.skip_levels;
    // In the hierarchy's element order, in which its per-element arrays are read.
    tbb::parallel_for(
        tbb::blocked_range<std::uint32_t>(0, std::uint32_t(m.hierarchy().element_count()), 4096),
        [&](const auto& range) {
          for (std::uint32_t e = range.begin(); e != range.end(); ++e) {
            const std::int32_t r = m.render_index(ElemId(e));
            if (r >= 0) state[std::size_t(r)] = empty_state(m, ctf, ElemId(e), levels);
          }
        });
  }
  // Tiles in parallel (render_tiles), one ray at a time. Advancing two rays of a tile in turn,
  // one element each, so that one fills the other's latency chain, measured 14-16 % slower per
  // frame on one thread (skull v8000, MRI v215000): its bookkeeping cost more than it hid.
  const CompiledTransferFunction* skip = opt.skip_empty ? &ctf : nullptr;
  Counters n;
  // All rays share their direction (orthographic) or their origin (perspective): mapped to the
  // local frame once, with the same arithmetic as per ray.
  Vec3 shared_local;
  {
    Vec3 ow, dw;
    rays.ray(0, 0, ow, dw);
    shared_local = camera.perspective ? to_local.point(ow) : to_local.direction(dw);
  }
  auto state_of = [&](std::uint32_t e) { return state[e]; };
  RenderImage img = render_tiles(camera, ctf, opt, [&](int x, int y, RayAccumulator& acc, ElemId& hint) {
    Vec3 ow, dw;
    rays.ray(x, y, ow, dw);
    const Vec3 o = camera.perspective ? shared_local : to_local.point(ow);
    const Vec3 d = camera.perspective ? to_local.direction(dw) : shared_local;
    std::uint64_t segments = 0;
    const auto visit = [&](const TraceSegment& s) {
      if (s.tet >= 0) ++segments;
      if (!s.empty) acc.add(s.s0, s.s1, s.t0, s.t1 - s.t0, opt.shading ? shade_factor(s.gradient, d) : 1.0);
      return !acc.done();
    };
    const TraceResult r = trace(m, o, d, skip, state_of, visit, &hint, stored);
    if (!r.hit) return;
    n.rays.fetch_add(1, std::memory_order_relaxed);
    n.segments.fetch_add(segments, std::memory_order_relaxed);
    if (r.skips) n.skips.fetch_add(r.skips, std::memory_order_relaxed);
    if (r.relocations) n.relocations.fetch_add(r.relocations, std::memory_order_relaxed);
    if (r.reentries) n.reentries.fetch_add(r.reentries, std::memory_order_relaxed);
    if (r.step_bound_hit) n.bound.fetch_add(1, std::memory_order_relaxed);
  });
  n.to(stats);
  if (stats) stats->records_stored = stored;
  return img;
}

RenderImage render_grid(const ScalarGrid& grid, const TransferFunction& tf, const Camera& camera,
                        const RenderOptions& opt, RenderStats* stats) {
  if (grid.dim != 3) throw Error(grid.source + ": the reference renderer needs a 3D volume");
  const GridField f(grid);
  const CompiledTransferFunction ctf(tf);
  const Vec3 lo{0, 0, 0}, hi = grid.local_extent();
  const double step = 0.5 * f.resolution();
  Counters n;
  const CameraRays rays(camera);
  const ToLocal to_local(grid.transform);
  RenderImage img = render_tiles(camera, ctf, opt, [&](int x, int y, RayAccumulator& acc, ElemId&) {
    Vec3 ow, dw;
    rays.ray(x, y, ow, dw);
    const Vec3 o = to_local.point(ow), d = to_local.direction(dw);
    double t0, t1;
    if (!clip_to_box(lo, hi, o, d, t0, t1)) return;
    std::uint64_t segs = 0;
    double s_prev = f.value(axpy(o, t0, d));
    for (std::int64_t j = 1; !acc.done(); ++j) {
      const double ta = t0 + double(j - 1) * step;
      const double tb = std::min(t1, t0 + double(j) * step);
      if (!(tb > ta)) break;
      const Vec3 xb = axpy(o, tb, d);
      const double s_next = f.value(xb);
      const double shade = opt.shading ? shade_factor(f.gradient(axpy(o, 0.5 * (ta + tb), d)), d) : 1.0;
      acc.add(s_prev, s_next, ta, tb - ta, shade);
      ++segs;
      s_prev = s_next;
      if (tb >= t1) break;
    }
    n.rays.fetch_add(1, std::memory_order_relaxed);
    n.segments.fetch_add(segs, std::memory_order_relaxed);
  });
  n.to(stats);
  return img;
}

}  // namespace mlfe
