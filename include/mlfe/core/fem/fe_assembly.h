// Assembly of the L2 (or H1) best-approximation system M U = F on the leaf triangulation,
// and the element error estimate E_T = ∫_T (f - u)² (+ s² ∫_T |∇f - ∇u|² in H1).
// Grosso, Lürig & Ertl, IEEE Vis 1997, Sec. 3: mesh reduction as L2 approximation.
//
// Degrees of freedom are the hierarchy's vertices (every vertex is a vertex of some leaf).
// The bilinear form is (u, v) + gradient_weight (∇u, ∇v); gradient_weight = 0 is plain L2.
// All functions are TBB-parallel and bitwise deterministic: per-element results go to fixed
// slots and are summed in element order.
#pragma once
#include <mlfe/core/base/default_init.h>
#include <mlfe/core/fem/element_integrals.h>
#include <mlfe/core/fem/linear_operator.h>
#include <mlfe/core/fem/sample_lattice.h>
#include <mlfe/core/mesh/hierarchy.h>

#include <cstdint>
#include <vector>

namespace mlfe {

/// How `integrals` lines up with `leaves`: integrals[i] belongs to leaves[i] (kLeafOrder), or
/// integrals is a per-element cache and integrals[leaves[i].value] belongs to leaves[i]
/// (kElementId; saves gathering a copy of a cache that already exists). Sizes are CHECKed.
enum class IntegralIndex { kLeafOrder, kElementId };

/// Integrals of f for each element of `elems`: with a lattice (f must then have samples()), the
/// least-squares sums over the samples each element owns (sample_lattice.h); without, the
/// resolving quadrature of element_integrals.h. With `gradients`, it receives the H1 sums of
/// each element, in the same order.
template <int D>
std::vector<ElementIntegrals<D>> compute_element_integrals(const Hierarchy<D>& h,
                                                           const std::vector<ElemId>& elems, const Field& f,
                                                           double max_sub_edge,
                                                           std::vector<ElementGradients<D>>* gradients,
                                                           const SampleLattice* lattice = nullptr);

/// compute_element_integrals written in place: the integrals of elems[i] go to out[i]
/// (kLeafOrder) or out[elems[i]] (kElementId), and its H1 sums to the same place of
/// `gradients` unless that is null; both must have room for them.
template <int D>
void compute_element_integrals_into(const Hierarchy<D>& h, const std::vector<ElemId>& elems, const Field& f,
                                    double max_sub_edge, ElementGradients<D>* gradients,
                                    const SampleLattice* lattice, ElementIntegrals<D>* out,
                                    IntegralIndex index);

/// Global matrix M + gradient_weight K over `leaves` (vertex_count() x vertex_count()). With
/// sampled `integrals` (least squares at the samples), M is their sampled mass (singular for
/// vertices in the padding that no sample sees: see regularize_padding in approximation.cpp).
template <int D>
SparseMatrix assemble_matrix(const Hierarchy<D>& h, const std::vector<ElemId>& leaves, double gradient_weight,
                             const std::vector<ElementIntegrals<D>>* integrals = nullptr,
                             IntegralIndex index = IntegralIndex::kLeafOrder);

/// What the assembly keeps from one call to the next (the refine-solve loop's): the vertex →
/// incidence table keeps its capacity, so an iteration writes the pages the previous one used
/// instead of having fresh ones zero-filled by the kernel. Holds no results; any workspace
/// gives the same values.
struct AssemblyWorkspace {
  template <class T>
  using Array = std::vector<T, DefaultInit<T>>;
  Array<std::uint32_t> start, inc, counts;  // CSR of incidences, per-chunk counts
};

/// assemble_matrix into `m` and, for gradient_weight = 0, assemble_load into `rhs` in the same
/// pass (else assemble_load itself): bit-identical to the two, every row and entry summed in
/// leaf order. The storage of m's non-zeros is reused when it has room (a call reserves twice
/// what it needs when it has to grow it: address space, untouched pages cost nothing).
template <int D>
void assemble_system(const Hierarchy<D>& h, const std::vector<ElemId>& leaves, double gradient_weight,
                     const std::vector<ElementIntegrals<D>>& integrals, IntegralIndex index,
                     AssemblyWorkspace& ws, SparseMatrix& m, Vector& rhs,
                     const std::vector<ElementGradients<D>>* gradients = nullptr);

/// Load vector F_j = (f, φ_j) + gradient_weight (∇f, ∇φ_j). A gradient term needs `gradients`
/// (the H1 sums, indexed like the integrals; CHECKed).
template <int D>
Vector assemble_load(const Hierarchy<D>& h, const std::vector<ElemId>& leaves,
                     const std::vector<ElementIntegrals<D>>& integrals, double gradient_weight,
                     IntegralIndex index = IntegralIndex::kLeafOrder,
                     const std::vector<ElementGradients<D>>* gradients = nullptr);

/// E_T for each leaf, from the cached integrals and nodal values U (never negative). A
/// gradient term needs `gradients` as assemble_load does.
template <int D>
std::vector<double> element_errors(const Hierarchy<D>& h, const std::vector<ElemId>& leaves,
                                   const std::vector<ElementIntegrals<D>>& integrals, const Vector& u,
                                   double gradient_weight, IntegralIndex index = IntegralIndex::kLeafOrder,
                                   const std::vector<ElementGradients<D>>* gradients = nullptr);

}  // namespace mlfe
