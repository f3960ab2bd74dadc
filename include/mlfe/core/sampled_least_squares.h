// Least squares at the samples (sample_lattice.h) applied from the samples themselves: the
// system of Grosso, Lürig & Ertl (IEEE Vis 1997, Sec. 3) in the discrete L2 norm of the
// samples, as an operator (MFEM's matrix-free style) instead of an assembled matrix:
//     (M x)_i = Σ_s w φ_i(x_s) Σ_j φ_j(x_s) x_j,   F_i = Σ_s w f_s φ_i(x_s),
//     E_T = Σ_{s owned by T} w (f_s − u(x_s))².
// Why: summed per element, the sampled mass and load are 136 bytes per element id, kept across
// the refine-solve loop, and the matrix and its incidence table come on top (2.8 of the 3.9 GB
// a 7 M-voxel full head's default build held). Per sample the operator keeps its owning leaf
// and barycentrics instead (16 bytes a sample, fewer samples than elements), and a product
// streams them once, as a sparse product streams the matrix.
//
// Determinism: sums into vertices (and leaves) would race when two threads handle samples of
// one element. The samples are cut into tiles of T × T rows (y, z; in 2D bands of T rows),
// T at least twice the largest extent of a leaf that owns samples, and the tiles are coloured
// by the parity of their indices: tiles of one colour share no vertex and no leaf, so a colour
// runs in parallel and the colours one after the other. Every sum then has a fixed order
// (colour, then sample order within the tile) whatever the thread count.
#pragma once
#include <mlfe/core/hierarchy.h>
#include <mlfe/core/linear_operator.h>
#include <mlfe/core/sample_lattice.h>
#include <mlfe/core/scalar_grid.h>

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
  /// y = M x (+ padding ⊙ x).
  void apply(const Vector& x, Vector& y) const override;

  /// The load F (without the padding's terms) and the diagonal of M (with the padding's weights).
  void load(Vector& rhs, Vector& diagonal) const;

  /// Per element id (sized to the hierarchy's element count; 0 for elements that are not
  /// leaves or own no sample): Σ w (f_s − u(x_s))² and the number of samples each leaf owns.
  void leaf_errors(const Vector& u, std::vector<double>& error, std::vector<std::uint32_t>& samples) const;

  /// Bytes held per sample (owner and barycentrics), for memory estimates.
  static constexpr std::size_t kBytesPerSample = 4 + (D + 1) * 4 + D * sizeof(float);

 private:
  // Calls visit(s, cell, λ) for every sample of the tiles of colour `colour`, tiles in
  // parallel, samples of a tile in order.
  template <class Visit>
  void for_each_sample(int colour, Visit&& visit) const;

  const SampleLattice& lattice_;
  const ScalarGrid& grid_;
  const Hierarchy<D>* h_ = nullptr;
  std::vector<std::uint32_t> owner_;           // per sample: its leaf's element id
  // Per sample: its leaf's vertices (a copy: read through the leaf id, the cell was a cache
  // miss per sample and 40 % of a product's time).
  std::vector<typename Hierarchy<D>::Cell> cells_;
  std::vector<std::array<float, D>> lambda_;   // per sample: λ_1 .. λ_D (λ_0 = 1 − their sum)
  std::vector<double> padding_;                // per vertex
  std::size_t elements_seen_ = 0;              // element count at the last update()
  std::int64_t extent_ = 1;                    // largest y/z extent of a leaf owning samples
  std::int64_t tile_ = 2;                      // T
};

extern template class SampledLeastSquares<2>;
extern template class SampledLeastSquares<3>;

}  // namespace mlfe
