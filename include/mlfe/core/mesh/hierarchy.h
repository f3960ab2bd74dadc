// Nested simplex hierarchy T0 ⊂ T1 ⊂ … ⊂ Tj with red-green refinement.
//
//   2D: R. E. Bank, A. H. Sherman, A. Weiser, "Refinement algorithms and data structures for
//       regular local mesh refinement", Scientific Computing (1983): red = 4 congruent
//       triangles from the edge midpoints, green = bisection toward one hanging midpoint.
//   3D: J. Bey, "Tetrahedral grid refinement", Computing 55 (1995): regular (red) refinement
//       with the octahedron cut along the diagonal x02–x13 fixed by the vertex order, so all
//       red descendants of a tetrahedron fall into at most 3 similarity classes; green
//       closure with the four types kept by Grosso, Lürig & Ertl (IEEE Vis 1997, Fig. 3).
//
// For gridded input T0 is a cube 2^L samples wide and level L's vertices are the samples (the
// samples' lattice, drawn in sample_lattice.h); the rules below put every level's vertices on
// that lattice, since each new vertex bisects an edge between lattice points.
//
// Green elements are never refined: when one must be, its parent loses its green children and
// is red-refined instead, and the closure runs again. So every vertex ever created is the
// midpoint of an edge of a red-refined element; the edge→midpoint map records both parents,
// which the hierarchical basis and the BPX preconditioner need.
//
// Storage: structure of arrays indexed by VertexId / ElemId. Children of an element are
// contiguous: [first_child, first_child + num_children). ElemIds are stable between calls to
// refine() only (refine compacts removed green children away and renumbers).
//
// Local numbering (3D tetrahedron, vertices 0..3; edges e0..e5; face f_i is opposite vertex i):
//
//            3                 e0 = (0,1)   e3 = (1,2)
//           /|\                e1 = (0,2)   e4 = (1,3)
//          / | \               e2 = (0,3)   e5 = (2,3)
//        e2  e4 e5
//        /   |   \             red children (xij = midpoint of edge ij):
//       0----|----2  (e1)        [x0,x01,x02,x03] [x01,x1,x12,x13] [x02,x12,x2,x23] [x03,x13,x23,x3]
//        \   |   /               [x01,x02,x03,x13] [x01,x02,x12,x13] [x02,x03,x13,x23] [x02,x12,x13,x23]
//        e0  |  e3
//          \ | /
//            1
// 2D triangle: edges e0 = (0,1), e1 = (0,2), e2 = (1,2); red children
//   [x0,x01,x02] [x01,x1,x12] [x02,x12,x2] [x01,x12,x02].
#pragma once
#include <mlfe/core/mesh/edge_map.h>
#include <mlfe/core/mesh/ids.h>

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace mlfe {

enum class ElemKind : std::uint8_t {
  kCoarse = 0,  ///< element of T0
  kRed = 1,     ///< child of a red (regular) refinement
  kGreen = 2,   ///< child of a green (closure) refinement; never refined itself
};

template <int D>
struct SimplexTraits;
template <>
struct SimplexTraits<2> {
  static constexpr int kVerts = 3;
  static constexpr int kEdges = 3;
  static constexpr int kFaces = 3;  // faces = edges opposite each vertex
  static constexpr int kRedChildren = 4;
  static constexpr int kEdgeVerts[3][2] = {{0, 1}, {0, 2}, {1, 2}};
};
template <>
struct SimplexTraits<3> {
  static constexpr int kVerts = 4;
  static constexpr int kEdges = 6;
  static constexpr int kFaces = 4;
  static constexpr int kRedChildren = 8;
  static constexpr int kEdgeVerts[6][2] = {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}};
};

template <int D>
class Hierarchy {
 public:
  static_assert(D == 2 || D == 3, "2D triangles or 3D tetrahedra");
  static constexpr int kDim = D;
  static constexpr int kVerts = D + 1;
  using Point = std::array<double, D>;
  using Cell = std::array<VertexId, D + 1>;

  /// T0 of the axis-aligned box [lo, hi]: 2 triangles (2D) or the 6 Kuhn/Freudenthal
  /// tetrahedra around the main diagonal lo→hi (3D), so that neighbouring boxes would match.
  /// Throws mlfe::Error unless lo < hi componentwise.
  static Hierarchy box(const Point& lo, const Point& hi);

  /// Builds T0 from given points and cells (each cell's vertex order is kept; Bey's
  /// similarity bound assumes the order the cells come in). Throws mlfe::Error for indices out
  /// of range or degenerate cells.
  static Hierarchy from_coarse(std::vector<Point> points, std::vector<Cell> cells);

  /// Every array of a hierarchy, as stored (for serialization). Vertex arrays are indexed by
  /// VertexId, element arrays by ElemId.
  struct Arrays {
    std::vector<Point> points;
    std::vector<std::array<VertexId, 2>> vertex_parents;
    std::vector<std::uint8_t> vertex_level;
    std::vector<Cell> cells;
    std::vector<ElemId> parent;
    std::vector<ElemId> first_child;
    std::vector<std::uint8_t> num_children;
    std::vector<std::uint8_t> level;
    std::vector<ElemKind> kind;
  };

  /// Rebuilds a hierarchy from untrusted arrays (e.g. a file), with the edge map rebuilt from
  /// vertex_parents. Validates everything the other members rely on: equal sizes; finite
  /// points; vertex parents either both invalid (T0, level 0) or valid with p0 < p1 < v, the
  /// point equal to their mean within 1e-9 relative, each edge bisected once and vertex level
  /// above its parents'; every cell index in range and distinct; kinds in range; coarse
  /// elements (level 0, no parent) first and non-degenerate; parent < child, the child inside
  /// its parent's contiguous child range and at the parent's level + 1, all siblings of one
  /// kind; red children exactly the red pattern of the parent (Bey's order); green children a
  /// valid green pattern covering the parent, and never refined. Throws mlfe::Error with the
  /// one-line message "<source>: <problem>" on the first violation; never aborts on bad input.
  static Hierarchy from_arrays(Arrays arrays, const std::string& source = "hierarchy");

  // ---- refinement ----
  /// Red-refines the given leaf elements (a green leaf red-refines its parent instead), then
  /// runs the green closure so the leaf triangulation is conforming again. The result does not
  /// depend on the order of `marked` or on the thread count. Throws mlfe::Error for ids that
  /// are not leaves (before changing anything).
  /// ElemIds are renumbered (compacted); VertexIds are stable and new vertices are appended.
  /// Returns, for every element id before the call, its id after the call (invalid for the
  /// green children that were removed), so callers can carry per-element data across.
  ///
  /// With a vertex_limit > 0, a refinement that would end with more vertices than the limit
  /// is rolled back instead: the hierarchy is left as it was (same arrays, same edge
  /// midpoints) and an empty vector is returned. It stops before the green closure, which
  /// adds no vertex, so a budgeted caller needs no copy to undo an overshooting attempt and
  /// does not pay for its closure. *vertices_reached, if given, is the vertex count the
  /// refinement reached (the final count unless rolled back).
  std::vector<ElemId> refine(std::vector<ElemId> marked, std::size_t vertex_limit = 0,
                             std::size_t* vertices_reached = nullptr);
  /// Red-refines every leaf once.
  void refine_uniform();
  /// Room for this many vertices and elements in all, so that refinement up to them does not
  /// reallocate (and copy) the arrays; address space only until used. With `exact`, the
  /// edge→midpoint map is sized for `vertices` too (it is filled when sized: for counts known in
  /// advance, such as a rebuild). No effect on results. Throws std::bad_alloc when the address
  /// space is not there.
  void reserve(std::size_t vertices, std::size_t elements, bool exact = false);

  // ---- vertices ----
  std::size_t vertex_count() const { return vx_.points.size(); }
  const Point& point(VertexId v) const { return vx_.points[v]; }
  const std::vector<Point>& points() const { return vx_.points.vector(); }
  /// The endpoints of the edge whose midpoint v is; both invalid for vertices of T0.
  const std::array<VertexId, 2>& vertex_parents(VertexId v) const { return vx_.parents[v]; }
  /// 0 for vertices of T0, else 1 + the level of the element whose edge v bisects.
  int vertex_level(VertexId v) const { return vx_.level[v]; }
  const EdgeMap& edge_midpoints() const { return edge_mid_; }
  /// Whole per-vertex arrays (see vertex_parents(v), vertex_level(v)), for serialization.
  const std::vector<std::array<VertexId, 2>>& vertex_parents_array() const { return vx_.parents.vector(); }
  const std::vector<std::uint8_t>& vertex_level_array() const { return vx_.level.vector(); }

  // ---- elements ----
  std::size_t element_count() const { return el_.cells.size(); }
  std::size_t coarse_count() const { return coarse_count_; }
  const Cell& cell(ElemId e) const { return el_.cells[e]; }
  /// The points of element e's vertices, in the cell's order.
  std::array<Point, D + 1> corner_points(ElemId e) const {
    std::array<Point, D + 1> p;
    for (int i = 0; i <= D; ++i) p[i] = point(cell(e)[i]);
    return p;
  }
  ElemId parent(ElemId e) const { return el_.parent[e]; }
  ElemId first_child(ElemId e) const { return el_.first_child[e]; }
  int num_children(ElemId e) const { return el_.num_children[e]; }
  int level(ElemId e) const { return el_.level[e]; }
  ElemKind kind(ElemId e) const { return el_.kind[e]; }
  bool is_leaf(ElemId e) const { return el_.num_children[e] == 0; }
  /// Whole per-element arrays, indexed by ElemId, for serialization and bulk readers.
  const std::vector<Cell>& cells() const { return el_.cells.vector(); }
  const std::vector<ElemId>& parent_array() const { return el_.parent.vector(); }
  const std::vector<ElemId>& first_child_array() const { return el_.first_child.vector(); }
  const std::vector<std::uint8_t>& num_children_array() const { return el_.num_children.vector(); }
  const std::vector<std::uint8_t>& level_array() const { return el_.level.vector(); }
  const std::vector<ElemKind>& kind_array() const { return el_.kind.vector(); }
  int max_level() const;

  /// Leaf elements in id order: the finest, conforming triangulation Tj.
  std::vector<ElemId> leaves() const;
  /// The triangulation T_k: elements with level == k, plus leaves with level < k.
  std::vector<ElemId> level_elements(int k) const;

  /// Face neighbours of the given conforming element set: for element i of `elems`, entry
  /// [i][f] is the index into `elems` of the element across face f (opposite local vertex f),
  /// or -1 on the boundary.
  std::vector<std::array<std::int32_t, D + 1>> face_neighbors(const std::vector<ElemId>& elems) const;

  /// Signed measure (area/volume) of element e, and of an arbitrary cell.
  double signed_measure(ElemId e) const;
  double measure(ElemId e) const;
  double cell_measure(const Cell& c) const;

  /// Bytes held by the hierarchy (vertices, elements, links, edge map).
  std::size_t memory_bytes() const;

 private:
  ElemId add_element(const Cell& c, ElemId parent, int level, ElemKind kind);
  VertexId midpoint(VertexId a, VertexId b, int level);
  void red_refine(ElemId e);
  void reserve_for(std::size_t red_count);
  static std::array<Cell, SimplexTraits<D>::kRedChildren> red_children(
      const Cell& c, const std::array<VertexId, SimplexTraits<D>::kEdges>& m);
  // The green children of leaf e for its hanging-edge mask (kids[0..n), n returned), each
  // oriented like e. Read-only, so the closure computes them in parallel.
  int green_children(ElemId e, unsigned mask, std::array<Cell, 4>& kids) const;
  // green_children without the leaf requirement: the closure also asks it for the parent of
  // green leaves it considers re-greening.
  int green_pattern(ElemId e, unsigned mask, std::array<Cell, 4>& kids) const;
  // Whether an edge of the green children of e for `mask` (half edges of split edges, edges
  // between midpoints or to them) already has a midpoint: those children would be
  // nonconforming, so e must be red-refined instead. `flagged` as for hanging_mask: such a
  // midpoint is one the current refine() created (the old children of a re-greened parent had
  // the edges that use only older midpoints, and they were conforming).
  bool green_edges_split(ElemId e, unsigned mask, const std::vector<std::uint8_t>& flagged) const;
  bool any_edge_split(const std::array<Cell, 4>& kids, int n, const std::vector<std::uint8_t>& flagged) const;
  // Bit i set when local edge i has a midpoint. With `flagged`, only edges whose endpoints are
  // both flagged are probed: inside refine(), a midpoint on a leaf's edge is one the call
  // created (the leaves were conforming when it began), and refine() flags the endpoints of
  // every edge it splits — so for leaves that is the same mask with 1-3 hash probes instead
  // of 6. Non-leaves (green parents) carry older midpoints and need the full probe.
  unsigned hanging_mask(ElemId e, const std::vector<std::uint8_t>* flagged = nullptr) const;
  bool hanging_on_parent_edges(ElemId e, unsigned mask) const;
  std::vector<ElemId> compact(const std::vector<std::uint8_t>& dead, std::size_t old_count);
  // refine()'s steps after its red rounds: undo an attempt over the vertex limit (the child
  // links of older elements as they were, then truncation), or close the mesh with green
  // children for every leaf whose corners were `touched` and that has hanging midpoints.
  struct UndoLink {
    ElemId e, first_child;
    std::uint8_t num_children;
  };
  void roll_back(const std::vector<UndoLink>& undo_links, std::size_t old_count,
                 std::size_t old_vertex_count);
  void green_closure(const std::vector<std::uint8_t>& touched, std::vector<std::uint8_t>& dead);
  // refine()'s red rounds (hierarchy.cpp): the elements to refine red, then every element the
  // conformity closure sends to red or to a new green pattern, round by round.
  class RedRounds;

  // The parallel arrays, declared once: whatever applies to all of them (sizing, reserving,
  // truncating, moving an entry, memory) goes through for_each.
  struct VertexArrays {
    IndexVector<VertexId, Point> points;
    IndexVector<VertexId, std::array<VertexId, 2>> parents;  // the bisected edge's endpoints
    IndexVector<VertexId, std::uint8_t> level;
    template <class F>
    void for_each(F&& f) {
      f(points), f(parents), f(level);
    }
    template <class F>
    void for_each(F&& f) const {
      f(points), f(parents), f(level);
    }
  };
  struct ElementArrays {
    IndexVector<ElemId, Cell> cells;
    IndexVector<ElemId, ElemId> parent;
    IndexVector<ElemId, ElemId> first_child;  // children are contiguous
    IndexVector<ElemId, std::uint8_t> num_children;
    IndexVector<ElemId, std::uint8_t> level;
    IndexVector<ElemId, ElemKind> kind;
    template <class F>
    void for_each(F&& f) {
      f(cells), f(parent), f(first_child), f(num_children), f(level), f(kind);
    }
    template <class F>
    void for_each(F&& f) const {
      f(cells), f(parent), f(first_child), f(num_children), f(level), f(kind);
    }
  };
  VertexArrays vx_;
  ElementArrays el_;
  std::size_t coarse_count_ = 0;

  EdgeMap edge_mid_;
};

/// The green type of a mask of hanging edges (bit i = local edge i has a midpoint), or -1 when
/// the pattern must be red-refined. 2D: one edge → bisection. 3D (the paper's Fig. 3): one edge
/// (2 children), two edges sharing a vertex (3), three edges of one face (4), two opposite
/// edges (4).
int green_type(int dim, unsigned mask);

extern template class Hierarchy<2>;
extern template class Hierarchy<3>;

}  // namespace mlfe
