// Red-green refinement of simplex hierarchies: Bank, Sherman & Weiser (1983) in 2D and
// Bey, "Tetrahedral grid refinement", Computing 55 (1995) in 3D, with the green closure of
// Grosso, Lürig & Ertl (IEEE Vis 1997). See hierarchy.h for the local numbering.
#include <mlfe/core/base/check.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/base/huge_pages.h>
#include <mlfe/core/mesh/hierarchy.h>
#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <string>

namespace mlfe {

namespace {

// The i-th of the contiguous children from `first`; an id from a count or loop position.
ElemId child(ElemId first, std::size_t i) { return ElemId(static_cast<std::uint32_t>(first.value + i)); }
ElemId elem_id(std::size_t i) { return ElemId(static_cast<std::uint32_t>(i)); }
VertexId vertex_id(std::size_t i) { return VertexId(static_cast<std::uint32_t>(i)); }

int popcount(unsigned m) { return __builtin_popcount(m); }

// Faces of a tetrahedron as masks of their three edges; face i is opposite vertex i.
constexpr unsigned kTetFaceEdges[4] = {0x38, 0x26, 0x15, 0x0B};
// Children of each green type (index: green_type()).
constexpr int kGreenChildren[5] = {0, 2, 3, 4, 4};
// Pairs of opposite edges of a tetrahedron.
constexpr unsigned kTetOppositePairs[3] = {(1u << 0) | (1u << 5), (1u << 1) | (1u << 4),
                                           (1u << 2) | (1u << 3)};

template <int D>
double det_measure(const std::array<std::array<double, D>, D + 1>& p) {
  if constexpr (D == 2) {
    const double ax = p[1][0] - p[0][0], ay = p[1][1] - p[0][1];
    const double bx = p[2][0] - p[0][0], by = p[2][1] - p[0][1];
    return 0.5 * (ax * by - ay * bx);
  } else {
    double a[3], b[3], c[3];
    for (int i = 0; i < 3; ++i) {
      a[i] = p[1][i] - p[0][i];
      b[i] = p[2][i] - p[0][i];
      c[i] = p[3][i] - p[0][i];
    }
    return (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) +
            a[2] * (b[0] * c[1] - b[1] * c[0])) /
           6.0;
  }
}

}  // namespace

int green_type(int dim, unsigned mask) {
  const int n = popcount(mask);
  if (n == 0) return 0;
  if (dim == 2) return n == 1 ? 1 : -1;
  if (n == 1) return 1;
  if (n == 2) {
    for (unsigned pair : kTetOppositePairs)
      if (mask == pair) return 4;
    return 2;  // two edges of a tetrahedron that are not opposite share a vertex, hence a face
  }
  if (n == 3) {
    for (unsigned face : kTetFaceEdges)
      if (mask == face) return 3;
  }
  return -1;
}

template <int D>
Hierarchy<D> Hierarchy<D>::box(const Point& lo, const Point& hi) {
  for (int a = 0; a < D; ++a)
    if (!(lo[a] < hi[a])) throw Error("box: the lower corner must lie below the upper one on every axis");
  std::vector<Point> pts;
  for (int c = 0; c < (1 << D); ++c) {
    Point p;
    for (int a = 0; a < D; ++a) p[a] = (c >> a) & 1 ? hi[a] : lo[a];
    pts.push_back(p);
  }
  std::vector<Cell> cells;
  if constexpr (D == 2) {
    cells.push_back({VertexId(0), VertexId(1), VertexId(3)});
    cells.push_back({VertexId(0), VertexId(3), VertexId(2)});
  } else {
    // Kuhn simplices: walk from corner 0 to corner 7 along the axes in the order of a
    // permutation; the vertex order along the walk is the order Bey's rule needs.
    int perm[3] = {0, 1, 2};
    do {
      const unsigned v1 = 1u << perm[0];
      const unsigned v2 = v1 | (1u << perm[1]);
      cells.push_back({VertexId(0), VertexId(v1), VertexId(v2), VertexId(7)});
    } while (std::next_permutation(perm, perm + 3));
  }
  return from_coarse(std::move(pts), std::move(cells));
}

template <int D>
Hierarchy<D> Hierarchy<D>::from_coarse(std::vector<Point> points, std::vector<Cell> cells) {
  Hierarchy h;
  h.vx_.points = IndexVector<VertexId, Point>(std::move(points));
  h.vx_.parents.resize(h.vx_.points.size(), {VertexId::invalid(), VertexId::invalid()});
  h.vx_.level.resize(h.vx_.points.size(), 0);
  for (const Cell& c : cells) {
    for (VertexId v : c)
      if (!v.valid() || v.value >= h.vx_.points.size())
        throw Error("coarse mesh: a cell refers to a vertex beyond the " +
                    std::to_string(h.vx_.points.size()) + " points");
    if (h.cell_measure(c) == 0.0) throw Error("coarse mesh: a cell is degenerate (zero measure)");
    h.add_element(c, ElemId::invalid(), 0, ElemKind::kCoarse);
  }
  h.coarse_count_ = cells.size();
  return h;
}

namespace {

// Throws mlfe::Error naming the source file and the problem.
using Fail = std::function<void(const std::string&)>;

// from_arrays' checks of the vertex arrays: finite points, each refined vertex the midpoint of
// two earlier ones on a lower level, no edge bisected twice. Returns the edge → midpoint map.
template <int D>
EdgeMap checked_edge_midpoints(const typename Hierarchy<D>::Arrays& a, const Fail& fail) {
  using Point = typename Hierarchy<D>::Point;
  auto vs = [](std::size_t i) { return std::to_string(i); };
  const std::size_t nv = a.points.size();
  EdgeMap mid;
  mid.reserve(nv);
  for (std::size_t v = 0; v < nv; ++v) {
    const Point& p = a.points[v];
    for (int i = 0; i < D; ++i)
      if (!std::isfinite(p[i])) fail("vertex " + vs(v) + " has a non-finite coordinate");
    const auto& par = a.vertex_parents[v];
    if (!par[0].valid() && !par[1].valid()) {
      if (a.vertex_level[v] != 0) fail("vertex " + vs(v) + " has no parents but level > 0");
      continue;
    }
    if (!par[0].valid() || !par[1].valid() || !(par[0] < par[1]) || par[1].value >= v)
      fail("vertex " + vs(v) + " has invalid parents (" + vs(par[0].value) + ", " + vs(par[1].value) +
           "): need p0 < p1 < vertex");
    const Point& pa = a.points[par[0].value];
    const Point& pb = a.points[par[1].value];
    double scale = 0, err = 0;
    for (int i = 0; i < D; ++i) {
      scale = std::max({scale, std::abs(pa[i]), std::abs(pb[i]), std::abs(pa[i] - pb[i])});
      err = std::max(err, std::abs(p[i] - 0.5 * (pa[i] + pb[i])));
    }
    if (!(err <= 1e-9 * scale))
      fail("vertex " + vs(v) + " is not the midpoint of its parents " + vs(par[0].value) + " and " +
           vs(par[1].value));
    if (a.vertex_level[v] == 0 || a.vertex_level[v] <= a.vertex_level[par[0].value] ||
        a.vertex_level[v] <= a.vertex_level[par[1].value])
      fail("vertex " + vs(v) + " has level " + vs(a.vertex_level[v]) + ", not above its parents' levels");
    if (mid.find(par[0], par[1]).valid())
      fail("edge (" + vs(par[0].value) + ", " + vs(par[1].value) + ") is bisected twice");
    mid.insert(par[0], par[1], VertexId(static_cast<std::uint32_t>(v)));
  }
  return mid;
}

// from_arrays' checks of each element's own entries: vertex indices, kind, level, parent and
// child ranges consistent both ways, coarse elements first. Returns the number of coarse ones.
// `nv`: the number of vertices (a.points has been moved into the hierarchy by then).
template <int D>
std::size_t checked_element_links(const typename Hierarchy<D>::Arrays& a, std::size_t nv, const Fail& fail) {
  using Cell = typename Hierarchy<D>::Cell;
  auto vs = [](std::size_t i) { return std::to_string(i); };
  const std::size_t ne = a.cells.size();
  std::size_t coarse = 0;
  for (std::size_t e = 0; e < ne; ++e) {
    const std::string el = "element " + vs(e);
    const Cell& c = a.cells[e];
    for (int i = 0; i <= D; ++i) {
      if (c[i].value >= nv) fail(el + " has vertex index " + vs(c[i].value) + " out of range");
      for (int j = 0; j < i; ++j)
        if (c[i] == c[j]) fail(el + " repeats vertex " + vs(c[i].value));
    }
    const auto k = static_cast<unsigned>(a.kind[e]);
    if (k > 2) fail(el + " has invalid kind " + vs(k));
    if (a.level[e] >= 255) fail(el + " has level " + vs(a.level[e]) + " (limit 254)");
    if (a.kind[e] == ElemKind::kCoarse) {
      if (coarse != e) fail(el + " is coarse but follows refined elements");
      ++coarse;
      if (a.parent[e].valid() || a.level[e] != 0) fail(el + " is coarse but has a parent or level > 0");
    } else {
      const ElemId p = a.parent[e];
      if (!p.valid() || p.value >= e)
        fail(el + " has invalid parent " + vs(p.value) + " (need parent < child)");
      const ElemId f = a.first_child[p.value];
      const std::size_t n = a.num_children[p.value];
      if (!f.valid() || e < f.value || e >= f.value + n)
        fail(el + " is not in the child range of its parent " + vs(p.value));
      if (a.level[e] != a.level[p.value] + 1)
        fail(el + " has level " + vs(a.level[e]) + ", not its parent's level + 1");
      if (a.kind[f.value] != a.kind[e]) fail(el + " differs in kind from its siblings");
    }
    const std::size_t n = a.num_children[e];
    const ElemId f = a.first_child[e];
    if (n == 0) {
      if (f.valid()) fail(el + " is a leaf but has a first child");
      continue;
    }
    if (a.kind[e] == ElemKind::kGreen) fail(el + " is green but has children");
    if (!f.valid() || f.value <= e || f.value + n > ne)
      fail(el + " has child range [" + vs(f.value) + ", +" + vs(n) + ") out of range");
    for (std::size_t i = 0; i < n; ++i)
      if (a.parent[f.value + i].value != e) fail(el + ": child " + vs(f.value + i) + " names another parent");
  }
  return coarse;
}

}  // namespace

template <int D>
Hierarchy<D> Hierarchy<D>::from_arrays(Arrays a, const std::string& source) {
  using T = SimplexTraits<D>;
  const Fail fail = [&](const std::string& what) { throw Error(source + ": " + what); };
  auto vs = [](std::size_t i) { return std::to_string(i); };
  const std::size_t nv = a.points.size();
  const std::size_t ne = a.cells.size();
  // Ids must stay below the invalid marker, or "invalid" could alias a real index.
  if (nv >= VertexId::kInvalidValue) fail("too many vertices (" + vs(nv) + ")");
  if (ne >= ElemId::kInvalidValue) fail("too many elements (" + vs(ne) + ")");
  if (a.vertex_parents.size() != nv || a.vertex_level.size() != nv)
    fail("vertex arrays differ in size (points " + vs(nv) + ", parents " + vs(a.vertex_parents.size()) +
         ", levels " + vs(a.vertex_level.size()) + ")");
  if (a.parent.size() != ne || a.first_child.size() != ne || a.num_children.size() != ne ||
      a.level.size() != ne || a.kind.size() != ne)
    fail("element arrays differ in size (cells " + vs(ne) + ")");
  if (ne == 0) fail("no elements");

  Hierarchy h;
  h.edge_mid_ = checked_edge_midpoints<D>(a, fail);
  h.vx_.points = IndexVector<VertexId, Point>(std::move(a.points));
  h.vx_.parents = IndexVector<VertexId, std::array<VertexId, 2>>(std::move(a.vertex_parents));
  h.vx_.level = IndexVector<VertexId, std::uint8_t>(std::move(a.vertex_level));

  // ---- elements: local checks, then the geometry of each refinement ----
  const std::size_t coarse = checked_element_links<D>(a, nv, fail);
  h.el_.cells = IndexVector<ElemId, Cell>(std::move(a.cells));
  h.el_.parent = IndexVector<ElemId, ElemId>(std::move(a.parent));
  h.el_.first_child = IndexVector<ElemId, ElemId>(std::move(a.first_child));
  h.el_.num_children = IndexVector<ElemId, std::uint8_t>(std::move(a.num_children));
  h.el_.level = IndexVector<ElemId, std::uint8_t>(std::move(a.level));
  h.el_.kind = IndexVector<ElemId, ElemKind>(std::move(a.kind));
  h.coarse_count_ = coarse;

  // ---- elements: geometry of each refinement (links are consistent from here on) ----
  for (ElemId e(0); e < h.el_.cells.end_id(); ++e.value) {
    const std::string el = "element " + vs(e.value);
    const Cell& c = h.el_.cells[e];
    const double m = h.cell_measure(c);
    if (!(m != 0.0) || !std::isfinite(m)) fail(el + " is degenerate");
    const std::size_t n = h.el_.num_children[e];
    if (n == 0) continue;
    const ElemId f = h.el_.first_child[e];
    std::array<VertexId, T::kEdges> mid;
    for (int i = 0; i < T::kEdges; ++i)
      mid[i] = h.edge_mid_.find(c[T::kEdgeVerts[i][0]], c[T::kEdgeVerts[i][1]]);
    if (h.el_.kind[f] == ElemKind::kRed) {
      if (n != T::kRedChildren) fail(el + " has " + vs(n) + " red children");
      for (int i = 0; i < T::kEdges; ++i)
        if (!mid[i].valid()) fail(el + " is red-refined but edge " + vs(i) + " has no midpoint");
      const auto kids = red_children(c, mid);
      for (std::size_t i = 0; i < n; ++i)
        if (h.el_.cells[child(f, i)] != kids[i])
          fail(el + ": red child " + vs(f.value + i) + " does not match the red pattern");
      continue;
    }
    // Green: every child vertex is a corner or an edge midpoint of e; the split edges form an
    // admissible pattern with its number of children; the children tile e.
    unsigned mask = 0;
    double sum = 0;
    for (std::size_t i = 0; i < n; ++i) {
      const Cell& k = h.el_.cells[child(f, i)];
      for (VertexId v : k) {
        bool ok = std::find(c.begin(), c.end(), v) != c.end();
        for (int j = 0; j < T::kEdges && !ok; ++j)
          if (mid[j] == v) {
            mask |= 1u << j;
            ok = true;
          }
        if (!ok)
          fail(el + ": green child " + vs(f.value + i) + " uses vertex " + vs(v.value) +
               " outside its parent");
      }
      sum += std::abs(h.cell_measure(k));
    }
    const int type = green_type(D, mask);
    if (type <= 0 || static_cast<int>(n) != kGreenChildren[type])
      fail(el + " has an invalid green refinement (" + vs(n) + " children)");
    if (!(std::abs(sum - std::abs(m)) <= 1e-9 * std::abs(m)))
      fail(el + ": green children do not tile their parent");
  }
  return h;
}

template <int D>
ElemId Hierarchy<D>::add_element(const Cell& c, ElemId parent, int level, ElemKind kind) {
  MLFE_CHECK(el_.cells.size() < ElemId::kInvalidValue);
  MLFE_CHECK_MSG(level < 255, "refinement level limit (254) reached");
  ElemId id(static_cast<std::uint32_t>(el_.cells.size()));
  el_.cells.push_back(c);
  el_.parent.push_back(parent);
  el_.first_child.push_back(ElemId::invalid());
  el_.num_children.push_back(0);
  el_.level.push_back(static_cast<std::uint8_t>(level));
  el_.kind.push_back(kind);
  return id;
}

template <int D>
VertexId Hierarchy<D>::midpoint(VertexId a, VertexId b, int level) {
  VertexId m = edge_mid_.find(a, b);
  if (m.valid()) return m;
  MLFE_CHECK(vx_.points.size() < VertexId::kInvalidValue);
  m = VertexId(static_cast<std::uint32_t>(vx_.points.size()));
  Point p;
  const Point& pa = vx_.points[a];
  const Point& pb = vx_.points[b];
  for (int i = 0; i < D; ++i) p[i] = 0.5 * (pa[i] + pb[i]);
  vx_.points.push_back(p);
  // Parents in increasing id order so that the vertex data does not depend on which
  // element created the midpoint.
  vx_.parents.push_back(a < b ? std::array<VertexId, 2>{a, b} : std::array<VertexId, 2>{b, a});
  vx_.level.push_back(static_cast<std::uint8_t>(level));
  edge_mid_.insert(a, b, m);
  return m;
}

template <int D>
std::array<typename Hierarchy<D>::Cell, SimplexTraits<D>::kRedChildren> Hierarchy<D>::red_children(
    const Cell& c, const std::array<VertexId, SimplexTraits<D>::kEdges>& m) {
  using T = SimplexTraits<D>;
  std::array<Cell, T::kRedChildren> kids;
  if constexpr (D == 2) {
    // m: x01, x02, x12
    kids = {{{c[0], m[0], m[1]}, {m[0], c[1], m[2]}, {m[1], m[2], c[2]}, {m[0], m[2], m[1]}}};
  } else {
    // m: x01, x02, x03, x12, x13, x23 — Bey's children in Bey's vertex order.
    const VertexId x01 = m[0], x02 = m[1], x03 = m[2], x12 = m[3], x13 = m[4], x23 = m[5];
    kids = {{{c[0], x01, x02, x03},
             {x01, c[1], x12, x13},
             {x02, x12, c[2], x23},
             {x03, x13, x23, c[3]},
             {x01, x02, x03, x13},
             {x01, x02, x12, x13},
             {x02, x03, x13, x23},
             {x02, x12, x13, x23}}};
  }
  return kids;
}

template <int D>
void Hierarchy<D>::red_refine(ElemId e) {
  using T = SimplexTraits<D>;
  MLFE_CHECK(is_leaf(e) && kind(e) != ElemKind::kGreen);
  const Cell c = el_.cells[e];
  const int lvl = el_.level[e] + 1;
  std::array<VertexId, T::kEdges> m;
  for (int i = 0; i < T::kEdges; ++i) m[i] = midpoint(c[T::kEdgeVerts[i][0]], c[T::kEdgeVerts[i][1]], lvl);
  const std::array<Cell, T::kRedChildren> kids = red_children(c, m);
  const ElemId first(static_cast<std::uint32_t>(el_.cells.size()));
  for (const Cell& k : kids) add_element(k, e, lvl, ElemKind::kRed);
  el_.first_child[e] = first;
  el_.num_children[e] = static_cast<std::uint8_t>(kids.size());
}

template <int D>
unsigned Hierarchy<D>::hanging_mask(ElemId e, const std::vector<std::uint8_t>* flagged) const {
  using T = SimplexTraits<D>;
  const Cell& c = el_.cells[e];
  unsigned mask = 0;
  for (int i = 0; i < T::kEdges; ++i) {
    const VertexId a = c[T::kEdgeVerts[i][0]], b = c[T::kEdgeVerts[i][1]];
    if (flagged && !((*flagged)[a.value] && (*flagged)[b.value])) continue;
    if (edge_mid_.find(a, b).valid()) mask |= 1u << i;
  }
  return mask;
}

template <int D>
bool Hierarchy<D>::hanging_on_parent_edges(ElemId e, unsigned mask) const {
  using T = SimplexTraits<D>;
  const Cell& c = el_.cells[e];
  const Cell& pc = el_.cells[parent(e)];
  auto corner = [&](VertexId v) { return std::find(pc.begin(), pc.end(), v) != pc.end(); };
  for (int i = 0; i < T::kEdges; ++i)
    if ((mask & (1u << i)) && !(corner(c[T::kEdgeVerts[i][0]]) && corner(c[T::kEdgeVerts[i][1]])))
      return false;
  return true;
}

template <int D>
int Hierarchy<D>::green_children(ElemId e, unsigned mask, std::array<Cell, 4>& kids) const {
  MLFE_CHECK(green_type(D, mask) > 0 && is_leaf(e) && kind(e) != ElemKind::kGreen);
  return green_pattern(e, mask, kids);
}

template <int D>
bool Hierarchy<D>::green_edges_split(ElemId e, unsigned mask,
                                     const std::vector<std::uint8_t>& flagged) const {
  std::array<Cell, 4> kids;
  return any_edge_split(kids, green_pattern(e, mask, kids), flagged);
}

template <int D>
bool Hierarchy<D>::any_edge_split(const std::array<Cell, 4>& kids, int n,
                                  const std::vector<std::uint8_t>& flagged) const {
  using T = SimplexTraits<D>;
  for (int k = 0; k < n; ++k)
    for (int i = 0; i < T::kEdges; ++i) {
      const VertexId a = kids[k][T::kEdgeVerts[i][0]], b = kids[k][T::kEdgeVerts[i][1]];
      if (flagged[a.value] && flagged[b.value] && edge_mid_.find(a, b).valid()) return true;
    }
  return false;
}

template <int D>
int Hierarchy<D>::green_pattern(ElemId e, unsigned mask, std::array<Cell, 4>& kids) const {
  using T = SimplexTraits<D>;
  const int type = green_type(D, mask);
  MLFE_CHECK(type > 0 && kind(e) != ElemKind::kGreen);
  const Cell& c = el_.cells[e];
  auto mid = [&](VertexId a, VertexId b) {
    VertexId m = edge_mid_.find(a, b);
    MLFE_CHECK(m.valid());
    return m;
  };
  int n = 0;
  int edge = 0;
  while (!(mask & (1u << edge))) ++edge;
  if (type == 1) {
    const int la = T::kEdgeVerts[edge][0], lb = T::kEdgeVerts[edge][1];
    const VertexId m = mid(c[la], c[lb]);
    Cell k0 = c, k1 = c;
    k0[lb] = m;  // keeps the vertex order, hence the orientation, of the parent
    k1[la] = m;
    kids[0] = k0;
    kids[1] = k1;
    n = 2;
  } else if constexpr (D == 3) {
    if (type == 4) {
      const int other = 5 - edge;  // opposite edges have indices summing to 5
      const VertexId a = c[T::kEdgeVerts[edge][0]], b = c[T::kEdgeVerts[edge][1]];
      const VertexId cc = c[T::kEdgeVerts[other][0]], d = c[T::kEdgeVerts[other][1]];
      const VertexId m1 = mid(a, b), m2 = mid(cc, d);
      kids = {{{a, m1, cc, m2}, {a, m1, m2, d}, {m1, b, cc, m2}, {m1, b, m2, d}}};
      n = 4;
    } else {
      // Types 2 and 3 split one face (s, p, q) and join it to the apex d.
      int face = -1;
      for (int f = 0; f < 4; ++f)
        if ((mask & ~kTetFaceEdges[f]) == 0) face = f;
      MLFE_CHECK(face >= 0);
      const VertexId d = c[face];
      std::array<std::array<VertexId, 3>, 4> tris;
      int nt = 0;
      if (type == 3) {
        std::array<VertexId, 3> f;
        int nf = 0;
        for (int i = 0; i < 4; ++i)
          if (i != face) f[nf++] = c[i];
        const VertexId m01 = mid(f[0], f[1]), m02 = mid(f[0], f[2]), m12 = mid(f[1], f[2]);
        tris = {{{f[0], m01, m02}, {m01, f[1], m12}, {m02, m12, f[2]}, {m01, m12, m02}}};
        nt = 4;
      } else {
        // Two hanging edges (s,p), (s,q) sharing s. The quadrilateral m_sp, p, q, m_sq is cut by
        // a diagonal that the element across the face must choose identically: it starts at
        // the midpoint of the longer edge, ties broken by the points' coordinates (not their
        // ids, so a hierarchy rebuilt with other vertex numbers, as a file reader does, has
        // the same diagonals).
        const int e0 = edge;
        int e1 = e0 + 1;
        while (!(mask & (1u << e1))) ++e1;
        const int a0 = T::kEdgeVerts[e0][0], b0 = T::kEdgeVerts[e0][1];
        const int a1 = T::kEdgeVerts[e1][0], b1 = T::kEdgeVerts[e1][1];
        const int s = (a0 == a1 || a0 == b1) ? a0 : b0;
        const VertexId vs = c[s];
        const VertexId vp = c[a0 == s ? b0 : a0];
        const VertexId vq = c[a1 == s ? b1 : a1];
        auto len2 = [&](VertexId x, VertexId y) {
          double l = 0;
          for (int i = 0; i < 3; ++i) {
            const double t = vx_.points[x][i] - vx_.points[y][i];
            l += t * t;
          }
          return l;
        };
        const double lp = len2(vs, vp), lq = len2(vs, vq);
        const VertexId msp = mid(vs, vp), msq = mid(vs, vq);
        const bool from_p = lp > lq || (lp == lq && vx_.points[vp] < vx_.points[vq]);
        tris[0] = {vs, msp, msq};
        if (from_p) {
          tris[1] = {msp, vp, vq};
          tris[2] = {msp, vq, msq};
        } else {
          tris[1] = {msq, msp, vp};
          tris[2] = {msq, vp, vq};
        }
        nt = 3;
      }
      for (int i = 0; i < nt; ++i) kids[n++] = {tris[i][0], tris[i][1], tris[i][2], d};
    }
  }
  MLFE_CHECK(n == kGreenChildren[type]);
  const double parent_sign = signed_measure(e) > 0 ? 1.0 : -1.0;
  for (int i = 0; i < n; ++i) {
    // Green children carry no similarity guarantee; give them the parent's orientation.
    if (cell_measure(kids[i]) * parent_sign < 0) std::swap(kids[i][0], kids[i][1]);
  }
  return n;
}

template <int D>
void Hierarchy<D>::reserve(std::size_t vertices, std::size_t elements, bool exact) {
  if (exact && vertices > vx_.points.size())
    edge_mid_.reserve(edge_mid_.size() + vertices - vx_.points.size());
  if (elements > el_.cells.capacity())
    el_.for_each([&](auto& a) {
      a.reserve(elements);
      advise_huge_pages(a.vector());
    });
  if (vertices > vx_.points.capacity())
    vx_.for_each([&](auto& a) {
      a.reserve(vertices);
      advise_huge_pages(a.vector());
    });
}

template <int D>
void Hierarchy<D>::reserve_for(std::size_t red_count) {
  // Growing the parallel arrays geometrically would copy them about twice per refine() of a
  // big mesh; reserve what the red refinements need (closure adds little beyond).
  using T = SimplexTraits<D>;
  const std::size_t ne = el_.cells.size() + T::kRedChildren * red_count;
  const std::size_t nv = vx_.points.size() + T::kEdges * red_count / 2;
  if (ne > el_.cells.capacity()) {
    const std::size_t cap = std::max(ne, el_.cells.size() + el_.cells.size() / 4);
    el_.for_each([&](auto& a) { a.reserve(cap); });
  }
  if (nv > vx_.points.capacity()) {
    const std::size_t cap = std::max(nv, vx_.points.size() + vx_.points.size() / 4);
    vx_.for_each([&](auto& a) { a.reserve(cap); });
  }
  edge_mid_.reserve(edge_mid_.size() + T::kEdges * red_count / 2);
}

// The red rounds of refine(). Each round (1) applies the round's decisions: green children
// dropped where a parent is re-greened or refined red, red refinements made; (2) flags the
// endpoints of the edges it split (dirty) and the vertices any round touched; (3) picks the
// candidates: the elements created in the round and older leaves with two dirty vertices;
// (4) decides, in parallel, which candidates need red (or their parent a new green pattern).
// The rounds end when a round decides nothing; green_closure() then closes the mesh.
template <int D>
class Hierarchy<D>::RedRounds {
 public:
  RedRounds(Hierarchy& h, std::size_t old_count, bool keep_undo)
      : h_(h), old_count_(old_count), keep_undo_(keep_undo) {
    dead.assign(h.el_.cells.size(), 0);
    touched.assign(h.vx_.points.size(), 0);
    dirty_.assign(h.vx_.points.size(), 0);
  }

  void run(std::vector<ElemId> to_red) {
    std::vector<ElemId> to_regreen;
    while (!to_red.empty() || !to_regreen.empty()) {
      const std::size_t round_first_elem = h_.el_.cells.size();
      const std::size_t first_new_vertex = h_.vx_.points.size();
      apply(to_regreen, to_red);
      flag_split_edges(first_new_vertex);
      decide(pick_candidates(round_first_elem), round_first_elem, to_red, to_regreen);
      for (VertexId v : dirty_list_) dirty_[v.value] = 0;
      dirty_list_.clear();
      if (!use_incidence_ && (!to_red.empty() || !to_regreen.empty())) switch_to_incidence();
    }
    // The closure and the compaction that follow need only `dead` and `touched`: the incidence
    // (20 bytes a leaf) goes before they add their own arrays.
    std::vector<std::uint32_t>().swap(inc_head_);
    std::vector<std::uint32_t>().swap(inc_next_);
    std::vector<ElemId>().swap(inc_elem_);
    std::vector<std::uint8_t>().swap(seen_);
    std::vector<std::uint8_t>().swap(dirty_);
  }

  std::vector<std::uint8_t> dead;     // elements removed (green children replaced)
  std::vector<std::uint8_t> touched;  // vertices of split edges in any round (and re-greened corners)
  // With a vertex limit: the child links of older elements as they were before this call
  // changed them, for the rollback (elements and vertices created here are truncated away).
  std::vector<UndoLink> undo_links;

 private:
  static constexpr std::uint32_t kNone = ~std::uint32_t(0);

  bool alive_leaf(ElemId e) const { return !dead[e.value] && h_.is_leaf(e); }

  // The closure usually needs a few rounds, but a local refinement can need dozens (a wave of
  // green→red upgrades travelling along the refined region). Scanning every leaf each round
  // made that O(leaves × rounds); from the second round on, candidates are found through a
  // vertex → element incidence (singly linked lists in flat arrays) instead, so a round costs
  // what it touches. The candidate set is the same (elements created this round, and leaves
  // with ≥ 2 dirty vertices), so the result does not change.
  void add_incidence(ElemId e) {
    const auto idx = static_cast<std::uint32_t>(inc_elem_.size());
    inc_elem_.push_back(e);
    const Cell& c = h_.el_.cells[e];
    for (int k = 0; k <= D; ++k) {
      const std::uint32_t slot = idx * (D + 1) + static_cast<std::uint32_t>(k);
      inc_next_.push_back(inc_head_[c[k].value]);
      inc_head_[c[k].value] = slot;
    }
  }

  void switch_to_incidence() {
    use_incidence_ = true;
    inc_head_.assign(h_.vx_.points.size(), kNone);
    // The alive leaves, in id order; counted first rather than listed (4 bytes a leaf beside
    // the lists).
    std::size_t n = 0;
    for (std::size_t i = 0; i < h_.el_.cells.size(); ++i) n += alive_leaf(elem_id(i));
    inc_elem_.reserve(n);
    inc_next_.reserve(n * (D + 1));
    for (std::size_t i = 0; i < h_.el_.cells.size(); ++i)
      if (alive_leaf(elem_id(i))) add_incidence(elem_id(i));
  }

  // Alive leaves incident to any vertex of `verts` with ≥ 2 vertices flagged in `flag`
  // (sorted, unique). An element reached through several of its vertices is taken once (a
  // flag per element instead of sorting the duplicates away); a long list is put in id order
  // by a scan of the flags rather than a sort.
  std::vector<ElemId> incident_candidates(const std::vector<VertexId>& verts,
                                          const std::vector<std::uint8_t>& flag, std::size_t below) {
    std::vector<ElemId> out;
    seen_.resize(h_.el_.cells.size(), 0);
    for (VertexId v : verts) {
      if (v.value >= inc_head_.size()) continue;
      for (std::uint32_t s = inc_head_[v.value]; s != kNone; s = inc_next_[s]) {
        const ElemId e = inc_elem_[s / (D + 1)];
        if (e.value >= below || seen_[e.value] || !alive_leaf(e)) continue;
        int n = 0;
        for (VertexId w : h_.el_.cells[e]) n += flag[w.value];
        if (n >= 2) {
          seen_[e.value] = 1;
          out.push_back(e);
        }
      }
    }
    if (out.size() > h_.el_.cells.size() / 32) {
      out.clear();
      for (std::size_t i = 0; i < below && i < seen_.size(); ++i)
        if (seen_[i]) {
          out.push_back(ElemId(static_cast<std::uint32_t>(i)));
          seen_[i] = 0;
        }
    } else {
      std::sort(out.begin(), out.end());
      for (ElemId e : out) seen_[e.value] = 0;
    }
    return out;
  }

  // Alive leaves below `below` with ≥ 2 vertices flagged in `flag`, in id order; chunks in
  // parallel, concatenated in order.
  std::vector<ElemId> leaves_with_two_flagged(const std::vector<std::uint8_t>& flag,
                                              std::size_t below) const {
    constexpr std::size_t kChunk = 1 << 15;
    const std::size_t nchunks = (below + kChunk - 1) / kChunk;
    std::vector<std::vector<ElemId>> found(nchunks);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nchunks, 1),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        for (std::size_t k = r.begin(); k != r.end(); ++k)
                          for (std::size_t i = k * kChunk, end = std::min(below, i + kChunk); i < end; ++i) {
                            const ElemId e = elem_id(i);
                            if (h_.el_.num_children[e] != 0 || dead[i]) continue;
                            int m = 0;
                            for (VertexId v : h_.el_.cells[e]) m += flag[v.value];
                            if (m >= 2) found[k].push_back(e);
                          }
                      });
    std::vector<ElemId> out;
    for (auto& f : found) out.insert(out.end(), f.begin(), f.end());
    return out;
  }

  // A parent whose green children go becomes a leaf again.
  void drop_green_children(ElemId e) {
    if (keep_undo_ && e.value < old_count_)
      undo_links.push_back({e, h_.el_.first_child[e], h_.el_.num_children[e]});
    for (int i = 0; i < h_.num_children(e); ++i) {
      const ElemId ch(h_.first_child(e).value + i);
      MLFE_CHECK(h_.kind(ch) == ElemKind::kGreen && h_.is_leaf(ch));
      dead[ch.value] = 1;
    }
    h_.el_.num_children[e] = 0;
    h_.el_.first_child[e] = ElemId::invalid();
  }

  // Step 1: the round's decisions applied.
  void apply(const std::vector<ElemId>& to_regreen, const std::vector<ElemId>& to_red) {
    h_.reserve_for(to_red.size());
    for (ElemId e : to_regreen) {
      drop_green_children(e);
      // e is a leaf again, with midpoints from earlier calls on its edges: flag its corners so
      // hanging_mask(e, &touched) probes all of its edges.
      for (VertexId v : h_.el_.cells[e]) touched[v.value] = 1;
      // Re-greening comes from a round's decisions, so the incidence is in use by then.
      MLFE_CHECK(use_incidence_);
      add_incidence(e);
    }
    for (ElemId e : to_red) {
      if (!h_.is_leaf(e)) drop_green_children(e);  // e's green children go; e is refined red instead
      if (keep_undo_ && e.value < old_count_) undo_links.push_back({e, ElemId::invalid(), 0});
      h_.red_refine(e);
    }
    dead.resize(h_.el_.cells.size(), 0);
    dirty_.resize(h_.vx_.points.size(), 0);
    touched.resize(h_.vx_.points.size(), 0);
  }

  // Step 2: only the endpoints of split edges: a new vertex starts with no split edge around
  // it, and an older leaf cannot contain it, so flagging it would only add candidates and
  // probes. A split edge can also be an edge of a leaf's future green children (a half edge,
  // or an edge between midpoints of the leaf's edges), whose endpoints need not be corners of
  // that leaf: the parents of those endpoints are, so they are made dirty too and the leaf
  // becomes a candidate (green_edges_split then sends it to red). Not touched: no edge of
  // theirs is split by this.
  void flag_split_edges(std::size_t first_new_vertex) {
    const auto mark_dirty = [&](VertexId v) {
      if (!dirty_[v.value]) {
        dirty_[v.value] = 1;
        dirty_list_.push_back(v);
      }
    };
    for (VertexId v = vertex_id(first_new_vertex); v < h_.vx_.points.end_id(); ++v.value)
      for (VertexId p : h_.vx_.parents[v]) {
        mark_dirty(p);
        touched[p.value] = 1;
        for (VertexId g : h_.vx_.parents[p])
          if (g.valid()) mark_dirty(g);
      }
  }

  // Step 3: older leaves with ≥ 2 dirty vertices; with every element created in this round
  // (ids from round_first_elem on, not listed: a rebuild's last round creates 10^7) they are
  // the candidates.
  std::vector<ElemId> pick_candidates(std::size_t round_first_elem) {
    std::vector<ElemId> candidates;
    if (use_incidence_) {
      inc_head_.resize(h_.vx_.points.size(), kNone);
      for (std::size_t e = round_first_elem; e < h_.el_.cells.size(); ++e)
        add_incidence(ElemId(static_cast<std::uint32_t>(e)));
      // Many dirty vertices: their incidence lists would be walked at a cache miss per slot,
      // while one parallel pass over the element arrays streams them (same set, in id order).
      if (dirty_list_.size() * 1024 > round_first_elem)
        candidates = leaves_with_two_flagged(dirty_, round_first_elem);
      else
        candidates = incident_candidates(dirty_list_, dirty_, round_first_elem);
    } else {
      // The first round: older leaves with ≥ 2 dirty vertices (the others decide() would pass
      // over) by one parallel pass, and the elements it created. A list of every leaf, kept up
      // to date and handed to decide() whole, cost O(leaves) in allocations and copies per
      // call, however little the call refines (rebuilding the levels of a file, whose last
      // steps add a few hundred vertices to a million elements).
      candidates = leaves_with_two_flagged(dirty_, round_first_elem);
    }
    return candidates;
  }

  // Step 4: which candidates need red now? Parallel and read-only; the result is sorted, so it
  // does not depend on scheduling. Parents of green leaves whose new hanging midpoints all lie
  // on the parent's own edges, with an admissible combined pattern, get a new green closure
  // instead of red (green elements are still never refined): without this, one new midpoint on
  // a ring of green-refined elements turns the whole ring red, whose neighbours then turn red,
  // ... — a local mark could add 10^5 vertices.
  void decide(const std::vector<ElemId>& older, std::size_t round_first_elem, std::vector<ElemId>& to_red,
              std::vector<ElemId>& to_regreen) const {
    // Candidate i: older[i], then the round's elements. The requests are few, so each thread
    // keeps its own list (a slot per candidate was 8 bytes a new element, at refine()'s peak);
    // sorted below, they do not depend on the split.
    const std::size_t n = older.size() + (h_.el_.cells.size() - round_first_elem);
    struct Requests {
      std::vector<ElemId> red, regreen;
    };
    tbb::enumerable_thread_specific<Requests> found;
    tbb::parallel_for(
        tbb::blocked_range<std::size_t>(0, n, 4096), [&](const tbb::blocked_range<std::size_t>& r) {
          Requests& mine = found.local();
          for (std::size_t i = r.begin(); i != r.end(); ++i) {
            const ElemId e = i < older.size() ? older[i] : elem_id(round_first_elem + (i - older.size()));
            if (e.value < round_first_elem) {
              int m = 0;
              for (VertexId v : h_.el_.cells[e]) m += dirty_[v.value];
              if (m < 2) continue;  // no edge of e was split in this round
            }
            const unsigned mask = h_.hanging_mask(e, &touched);
            if (mask == 0) continue;
            if (h_.kind(e) == ElemKind::kGreen) {
              const ElemId p = h_.parent(e);
              const unsigned pmask = h_.hanging_on_parent_edges(e, mask) ? h_.hanging_mask(p) : 0;
              if (green_type(D, pmask) > 0 && !h_.green_edges_split(p, pmask, touched))
                mine.regreen.push_back(p);
              else
                mine.red.push_back(p);
            } else if (green_type(D, mask) < 0 || h_.green_edges_split(e, mask, touched)) {
              mine.red.push_back(e);
            }
          }
        });
    to_red.clear();
    to_regreen.clear();
    for (const Requests& f : found) {
      to_red.insert(to_red.end(), f.red.begin(), f.red.end());
      to_regreen.insert(to_regreen.end(), f.regreen.begin(), f.regreen.end());
    }
    std::sort(to_red.begin(), to_red.end());
    to_red.erase(std::unique(to_red.begin(), to_red.end()), to_red.end());
    to_regreen.erase(
        std::remove_if(to_regreen.begin(), to_regreen.end(),
                       [&](ElemId r) { return std::binary_search(to_red.begin(), to_red.end(), r); }),
        to_regreen.end());
    std::sort(to_regreen.begin(), to_regreen.end());
    to_regreen.erase(std::unique(to_regreen.begin(), to_regreen.end()), to_regreen.end());
  }

  Hierarchy& h_;
  const std::size_t old_count_;
  const bool keep_undo_;
  std::vector<std::uint8_t> dirty_;  // endpoints of edges split in this round
  std::vector<VertexId> dirty_list_;
  bool use_incidence_ = false;
  std::vector<std::uint32_t> inc_head_;  // per vertex: first slot or kNone
  std::vector<std::uint32_t> inc_next_;  // per slot (= element index * (D + 1) + corner)
  std::vector<ElemId> inc_elem_;         // per element index
  std::vector<std::uint8_t> seen_;
};

template <int D>
std::vector<ElemId> Hierarchy<D>::refine(std::vector<ElemId> marked, std::size_t vertex_limit,
                                         std::size_t* vertices_reached) {
  const std::size_t old_count = el_.cells.size();
  const std::size_t old_vertex_count = vx_.points.size();
  if (vertices_reached) *vertices_reached = old_vertex_count;
  // Step 1: the marked leaves, green ones replaced by their parents (green is never refined).
  std::vector<ElemId> to_red;
  to_red.reserve(marked.size());
  for (ElemId e : marked) {
    if (!e.valid() || e.value >= el_.cells.size() || !is_leaf(e))
      throw Error("refine: element " + std::to_string(e.value) + " is not a leaf of this hierarchy");
    to_red.push_back(kind(e) == ElemKind::kGreen ? parent(e) : e);
  }
  std::sort(to_red.begin(), to_red.end());
  to_red.erase(std::unique(to_red.begin(), to_red.end()), to_red.end());
  if (to_red.empty()) return compact(std::vector<std::uint8_t>(el_.cells.size(), 0), old_count);

  // Step 2: red rounds until the closure asks for no more.
  RedRounds rounds(*this, old_count, vertex_limit > 0);
  rounds.run(std::move(to_red));

  // Step 3: only red refinement adds vertices, so the count is final here: over the limit,
  // undo.
  if (vertices_reached) *vertices_reached = vx_.points.size();
  if (vertex_limit > 0 && vx_.points.size() > vertex_limit) {
    roll_back(rounds.undo_links, old_count, old_vertex_count);
    return {};
  }

  // Step 4: close: green children for every leaf left with hanging midpoints.
  green_closure(rounds.touched, rounds.dead);
  rounds.dead.resize(el_.cells.size(), 0);
  return compact(rounds.dead, old_count);
}

template <int D>
void Hierarchy<D>::roll_back(const std::vector<UndoLink>& undo_links, std::size_t old_count,
                             std::size_t old_vertex_count) {
  // Newest first, so an element changed twice ends with its state before the call.
  for (auto u = undo_links.rbegin(); u != undo_links.rend(); ++u) {
    el_.first_child[u->e] = u->first_child;
    el_.num_children[u->e] = u->num_children;
  }
  for (std::size_t v = vx_.points.size(); v-- > old_vertex_count;)
    edge_mid_.erase(vx_.parents[vertex_id(v)][0], vx_.parents[vertex_id(v)][1]);
  vx_.for_each([&](auto& a) { a.resize(old_vertex_count); });
  el_.for_each([&](auto& a) { a.resize(old_count); });
}

template <int D>
void Hierarchy<D>::green_closure(const std::vector<std::uint8_t>& touched, std::vector<std::uint8_t>& dead) {
  // Every remaining leaf with hanging midpoints has an admissible pattern.
  // Candidates: leaves with ≥ 2 flagged corners, in id order (deterministic child numbering).
  // One parallel pass over the element arrays (streamed; the flags fit in cache) costs less
  // than walking the incidence lists of every flagged vertex, which misses at every step.
  std::vector<std::pair<ElemId, unsigned>> closure;
  {
    constexpr std::size_t kChunk = 1 << 15;
    const std::size_t n = el_.cells.size(), nchunks = (n + kChunk - 1) / kChunk;
    dead.resize(n, 0);
    std::vector<std::vector<std::pair<ElemId, unsigned>>> found(nchunks);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nchunks, 1),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        for (std::size_t k = r.begin(); k != r.end(); ++k)
                          for (std::size_t i = k * kChunk, end = std::min(n, i + kChunk); i < end; ++i) {
                            const ElemId e = elem_id(i);
                            if (el_.num_children[e] != 0 || dead[i]) continue;
                            int m = 0;
                            for (VertexId v : el_.cells[e]) m += touched[v.value];
                            if (m < 2) continue;
                            if (const unsigned mask = hanging_mask(e, &touched))
                              found[k].emplace_back(e, mask);
                          }
                      });
    for (auto& f : found) closure.insert(closure.end(), f.begin(), f.end());
  }
  // Children are appended in closure order, so each element's child range is a prefix sum
  // over the child counts of the ones before it; the children themselves (hash look-ups and
  // orientation tests) are then computed in parallel into their ranges.
  if (!closure.empty()) {
    const std::size_t first = el_.cells.size();
    std::vector<std::size_t> offset(closure.size() + 1, 0);
    for (std::size_t i = 0; i < closure.size(); ++i)
      offset[i + 1] = offset[i] + kGreenChildren[std::max(0, green_type(D, closure[i].second))];
    const std::size_t ne = first + offset.back();
    MLFE_CHECK(ne < ElemId::kInvalidValue);
    // New entries: no children (invalid first child, count 0), green; the rest is set below.
    el_.for_each([&](auto& a) { a.resize(ne); });
    std::fill(el_.kind.begin() + static_cast<std::ptrdiff_t>(first), el_.kind.end(), ElemKind::kGreen);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, closure.size(), 1024),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        std::array<Cell, 4> kids;
                        for (std::size_t i = r.begin(); i != r.end(); ++i) {
                          const auto [e, mask] = closure[i];
                          const int n = green_children(e, mask, kids);
                          // A hanging vertex here would pass silently and abort a later refine().
                          MLFE_CHECK_MSG(!any_edge_split(kids, n, touched), "green child with a split edge");
                          const std::size_t at = first + offset[i];
                          MLFE_CHECK(at + n == first + offset[i + 1]);
                          const int lvl = el_.level[e] + 1;
                          MLFE_CHECK_MSG(lvl < 255, "refinement level limit (254) reached");
                          for (int k = 0; k < n; ++k) {
                            const ElemId kid = elem_id(at + k);
                            el_.cells[kid] = kids[k];
                            el_.parent[kid] = e;
                            el_.level[kid] = static_cast<std::uint8_t>(lvl);
                          }
                          el_.first_child[e] = elem_id(at);
                          el_.num_children[e] = static_cast<std::uint8_t>(n);
                        }
                      });
  }
}

template <int D>
void Hierarchy<D>::refine_uniform() {
  refine(leaves());
}

template <int D>
std::vector<ElemId> Hierarchy<D>::compact(const std::vector<std::uint8_t>& dead, std::size_t old_count) {
  MLFE_CHECK(dead.size() == el_.cells.size());
  // Nothing removed (most calls): ids unchanged, without the id table (a fresh array of every
  // element's id, whose page faults cost more than the scan for a dead flag).
  if (std::find(dead.begin(), dead.end(), std::uint8_t(1)) == dead.end()) {
    std::vector<ElemId> same(old_count);
    for (std::size_t i = 0; i < old_count; ++i) same[i] = elem_id(i);
    return same;
  }
  // One id table, truncated to the old elements for the caller afterwards (a second table of
  // the old ids was 4 bytes an element at the build's peak).
  std::vector<ElemId> new_id(el_.cells.size(), ElemId::invalid());
  std::uint32_t n = 0;
  for (std::size_t i = 0; i < el_.cells.size(); ++i)
    if (!dead[i]) new_id[i] = ElemId(n++);
  if (n != el_.cells.size()) {
    auto remap = [&](ElemId e) { return e.valid() ? new_id[e.value] : e; };
    for (ElemId i(0); i < el_.cells.end_id(); ++i.value) {
      if (dead[i.value]) continue;
      const ElemId j = new_id[i.value];
      MLFE_CHECK(!el_.parent[i].valid() || !dead[el_.parent[i].value]);
      el_.for_each([&](auto& a) { a[j] = a[i]; });
      el_.parent[j] = remap(el_.parent[j]);
      el_.first_child[j] = remap(el_.first_child[j]);
    }
    el_.for_each([&](auto& a) { a.resize(n); });
  }
  new_id.resize(old_count);
  return new_id;
}

template <int D>
int Hierarchy<D>::max_level() const {
  int m = 0;
  for (auto l : el_.level) m = std::max<int>(m, l);
  return m;
}

template <int D>
std::vector<ElemId> Hierarchy<D>::leaves() const {
  std::vector<ElemId> out;
  out.reserve(el_.cells.size());
  for (ElemId e(0); e < el_.cells.end_id(); ++e.value)
    if (el_.num_children[e] == 0) out.push_back(e);
  return out;
}

template <int D>
std::vector<ElemId> Hierarchy<D>::level_elements(int k) const {
  std::vector<ElemId> out;
  for (ElemId e(0); e < el_.cells.end_id(); ++e.value)
    if (el_.level[e] == k || (el_.level[e] < k && el_.num_children[e] == 0)) out.push_back(e);
  return out;
}

template <int D>
std::vector<std::array<std::int32_t, D + 1>> Hierarchy<D>::face_neighbors(
    const std::vector<ElemId>& elems) const {
  struct FaceRec {
    std::array<std::uint32_t, D> key;
    std::uint32_t elem;
    std::uint8_t face;
  };
  std::vector<FaceRec> faces;
  faces.reserve(elems.size() * (D + 1));
  for (std::size_t i = 0; i < elems.size(); ++i) {
    const Cell& c = el_.cells[elems[i]];
    for (int f = 0; f <= D; ++f) {
      FaceRec r;
      int n = 0;
      for (int j = 0; j <= D; ++j)
        if (j != f) r.key[n++] = c[j].value;
      std::sort(r.key.begin(), r.key.end());
      r.elem = static_cast<std::uint32_t>(i);
      r.face = static_cast<std::uint8_t>(f);
      faces.push_back(r);
    }
  }
  std::sort(faces.begin(), faces.end(), [](const FaceRec& a, const FaceRec& b) {
    return a.key != b.key ? a.key < b.key : a.elem < b.elem;
  });
  std::vector<std::array<std::int32_t, D + 1>> nb(elems.size());
  for (auto& a : nb) a.fill(-1);
  for (std::size_t i = 0; i + 1 < faces.size(); ++i) {
    if (faces[i].key == faces[i + 1].key) {
      nb[faces[i].elem][faces[i].face] = static_cast<std::int32_t>(faces[i + 1].elem);
      nb[faces[i + 1].elem][faces[i + 1].face] = static_cast<std::int32_t>(faces[i].elem);
      ++i;
    }
  }
  return nb;
}

template <int D>
double Hierarchy<D>::cell_measure(const Cell& c) const {
  std::array<std::array<double, D>, D + 1> p;
  for (int i = 0; i <= D; ++i) p[i] = vx_.points[c[i]];
  return det_measure<D>(p);
}

template <int D>
double Hierarchy<D>::signed_measure(ElemId e) const {
  return cell_measure(el_.cells[e]);
}

template <int D>
double Hierarchy<D>::measure(ElemId e) const {
  return std::abs(signed_measure(e));
}

template <int D>
std::size_t Hierarchy<D>::memory_bytes() const {
  std::size_t bytes = edge_mid_.memory_bytes();
  const auto add = [&](const auto& a) { bytes += a.capacity() * sizeof(*a.begin()); };
  vx_.for_each(add);
  el_.for_each(add);
  return bytes;
}

template class Hierarchy<2>;
template class Hierarchy<3>;

}  // namespace mlfe
