// BPX multilevel preconditioner: J. H. Bramble, J. E. Pasciak, J. Xu, "Parallel multilevel
// preconditioners", Math. Comp. 55 (1990), in the additive "multilevel diagonal scaling"
// form for locally refined meshes (Bornemann & Yserentant 1993):
//
//     C r = D⁻¹ r + Σ_k Σ_{v ∈ V_k} w_{k,v} (r, φ_v^k) / a(φ_v^k, φ_v^k) · φ_v^k
//
// with D the diagonal of the leaf matrix and w_{k,v} ∈ [0,1) the stiffness share of
// a(φ_v^k, φ_v^k) for the form (u,v) + s²(∇u,∇v): levels coarser than the gradient length
// scale s behave like mass matrices, for which diagonal scaling alone is optimal, so BPX
// reduces to Jacobi for pure L2 and to classical BPX where the stiffness dominates.
// where V_k are the vertices of the level-k elements and φ_v^k the level-k hat functions,
// expressed on the finest mesh by hierarchical interpolation through the midpoint parents.
// Restriction and prolongation walk the vertices level by level (each new vertex folds into /
// interpolates from its two parent vertices), so one application costs O(Σ_k |V_k|) —
// proportional to the number of unknowns on geometrically growing hierarchies.
#pragma once
#include <mlfe/core/fem/linear_operator.h>
#include <mlfe/core/mesh/hierarchy.h>

#include <array>
#include <cstdint>
#include <vector>

namespace mlfe {

template <int D>
class BpxPreconditioner final : public LinearOperator {
 public:
  /// For the operator M + gradient_weight·K (mass plus scaled stiffness) on the leaves of h.
  /// The hierarchy must outlive nothing: all needed data is copied.
  BpxPreconditioner(const Hierarchy<D>& h, double gradient_weight);
  Eigen::Index size() const override { return n_; }
  void apply(const Vector& x, Vector& y) const override;
  int levels() const { return static_cast<int>(level_entries_.size()); }

 private:
  struct Entry {
    std::uint32_t vertex;
    double inv_diag;
  };
  Eigen::Index n_ = 0;
  std::vector<std::array<VertexId, 2>> parents_;
  std::vector<std::vector<std::uint32_t>> new_vertices_;  // [k]: vertices created at level k
  std::vector<std::vector<Entry>> level_entries_;         // [k]: V_k with weight / a(φ, φ)
  std::vector<double> fine_diag_;                         // 1 / diagonal of the leaf matrix
};

extern template class BpxPreconditioner<2>;
extern template class BpxPreconditioner<3>;

}  // namespace mlfe
