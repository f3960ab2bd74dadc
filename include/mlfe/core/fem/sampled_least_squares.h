// Least squares at the samples (sample_lattice.h) applied from the samples themselves: the
// system of Grosso, Lürig & Ertl (IEEE Vis 1997, Sec. 3) in the discrete L2 norm of the
// samples, as an operator (MFEM's matrix-free style) instead of an assembled matrix:
//     (M x)_i = Σ_s w φ_i(x_s) Σ_j φ_j(x_s) x_j,   F_i = Σ_s w f_s φ_i(x_s),
//     E_T = Σ_{s owned by T} w (f_s − u(x_s))².
// Why: summed per element, the sampled mass and load are 136 bytes per element id, kept across
// the refine-solve loop, and the matrix and its incidence table come on top (2.8 of the 3.9 GB
// a 7 M-voxel full head's default build held). Per sample the operator keeps its leaf, the
// leaf's vertices and the barycentrics instead (32 bytes a sample; a full head at its noise
// level has about two leaves per sample), and a product streams them once.
// Leaves that own many samples (the coarse ones of the first iterations) keep their sums
// instead — the element's sampled mass, load and Σ w f² — so a product costs what the mesh
// has, not what the samples have, until leaves are small.
//
// Determinism: sums into vertices (and leaves) would race when two threads handle samples of
// one element. The samples are cut into tiles of T × T rows (y, z; in 2D bands of T rows),
// T at least twice the largest extent of a leaf that owns samples, and the tiles are coloured
// by the parity of their indices: tiles of one colour share no vertex and no leaf, so a colour
// runs in parallel and the colours one after the other. A leaf with sums belongs to the tile of
// its first sample and is applied before the tile's samples. Every sum then has a fixed order
// whatever the thread count.
//
// Vertex order: the operator numbers the vertices its own way, tile by tile and within a tile
// in the samples' (z, y, x) order, so a tile's products touch a compact range of the vectors
// (in the hierarchy's order, refinement scatters a tile's vertices over the whole vector, and
// a product waited on those misses). Vectors passed to apply(), load() and leaf_errors() are in
// the operator's order: to_operator_order() and from_operator_order() convert.
#pragma once
#include <mlfe/core/fem/linear_operator.h>
#include <mlfe/core/fem/sample_lattice.h>
#include <mlfe/core/field/scalar_grid.h>
#include <mlfe/core/mesh/hierarchy.h>

#include <array>
#include <cstdint>
#include <vector>

namespace mlfe {

template <int D>
class SampledLeastSquares final : public LinearOperator {
 public:
  /// For the samples of `grid` on `lattice` (both must outlive the operator). No hierarchy yet:
  /// call update() before anything else.
  SampledLeastSquares(const SampleLattice& lattice, const ScalarGrid& grid);

  /// Follows `h` to its current leaves: on the first call every leaf's samples are found; after
  /// a refine(), `remap` is what it returned (old → new element ids; empty: ids unchanged) and
  /// only the samples of leaves created since the last call are found again. CHECKs that every
  /// sample ends with a leaf. `padding` holds a weight per vertex (0 for most) added to the
  /// diagonal (see regularize_padding in approximation.cpp); its size is the vertex count.
  void update(const Hierarchy<D>& h, const std::vector<ElemId>& remap, std::vector<double> padding);

  Eigen::Index size() const override { return static_cast<Eigen::Index>(padding_.size()); }
  /// y = M x (+ padding ⊙ x), in the operator's vertex order.
  void apply(const Vector& x, Vector& y) const override;

  /// The load F (without the padding's terms) and the diagonal of M (with the padding's weights).
  void load(Vector& rhs, Vector& diagonal) const;

  /// A vector indexed by vertex id in the operator's order, and back.
  void to_operator_order(const std::vector<double>& by_vertex, Vector& out) const;
  void to_operator_order(const double* by_vertex, std::size_t n, Vector& out) const;
  void from_operator_order(const Vector& v, std::vector<double>& by_vertex) const;

  /// For each of `leaves` (the hierarchy's, in any order): Σ w (f_s − u(x_s))² over the samples
  /// it owns (never negative) and how many it owns.
  void leaf_errors(const Vector& u, const std::vector<ElemId>& leaves, std::vector<double>& error,
                   std::vector<std::uint32_t>& samples) const;

  /// Leaves owning at least this many samples keep their sums instead of their samples.
  static constexpr std::size_t kSummedLeaf = 8;

 private:
  static constexpr int kPairs = (D + 1) * (D + 2) / 2;
  // A leaf that keeps its sums (upper triangle of its sampled mass, row major, as
  // ElementIntegrals).
  struct SummedLeaf {
    ElemId id;
    std::uint32_t samples;
    std::int64_t first_sample;
    std::int64_t tile;
    typename Hierarchy<D>::Cell cell;
    double f2;
    std::array<double, D + 1> fphi;
    std::array<double, kPairs> mass;
  };

  // The tile of lattice point (·, y, z); points beyond the data fall in the axis's last tile.
  std::int64_t tile_at(std::int64_t y, std::int64_t z) const;
  // The vertex order: tile, then (z, y, x) of the vertex's lattice point (rank_: vertex id →
  // operator index, order_: back); and the stored cells renumbered through `map`.
  void order_vertices(const Hierarchy<D>& h);
  void renumber_cells(const std::vector<std::uint32_t>& map);
  // Calls leaf(summed leaf) and sample(s, cell, λ) for every tile, colour by colour, a colour's
  // tiles in parallel; per tile its summed leaves first, then its other samples in order.
  template <class Leaf, class Sample>
  void for_each(Leaf&& leaf, Sample&& sample) const;
  template <class Leaf, class Sample>
  void for_each_in_colour(int colour, Leaf& leaf, Sample& sample) const;

  const SampleLattice& lattice_;
  const ScalarGrid& grid_;
  const Hierarchy<D>* h_ = nullptr;
  std::vector<std::uint32_t> owner_;  // per sample: its leaf's element id
  // Per sample: its leaf's vertices (a copy: read through the leaf id, the cell was a cache
  // miss per sample and 40 % of a product's time); the first is invalid for a summed leaf's.
  std::vector<typename Hierarchy<D>::Cell> cells_;
  std::vector<std::array<float, D>> lambda_;  // per sample: λ_1 .. λ_D (λ_0 = 1 − their sum)
  std::vector<std::uint8_t> loose_rows_;      // per row (y, z): has samples not in summed leaves
  std::vector<SummedLeaf> summed_;            // by (tile, id)
  std::vector<std::size_t> summed_start_;     // per tile: its first in summed_ (CSR)
  std::vector<double> padding_;               // per vertex, in the operator's order
  std::vector<std::uint32_t> rank_, order_;   // vertex id ↔ operator index (empty: identity)
  std::size_t elements_seen_ = 0;             // element count at the last update()
  std::int64_t extent_ = 1;                   // largest y/z extent of a leaf owning samples
  std::int64_t tile_ = 2;                     // T
  std::int64_t tiles_y_ = 1, tiles_z_ = 1;
};

extern template class SampledLeastSquares<2>;
extern template class SampledLeastSquares<3>;

}  // namespace mlfe
