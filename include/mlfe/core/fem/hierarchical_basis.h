// Hierarchical basis decomposition: H. Yserentant, "On the multi-level splitting of finite
// element spaces", Numer. Math. 49 (1986).
//
// A finest-level function with nodal values U is written as coarse values at the vertices of
// T0 plus one surplus per newer vertex: s_v = U_v - (U_a + U_b)/2 where (a, b) is the edge v
// bisects. Dropping the surpluses of levels > k gives the approximation on T_k (expressed at
// all vertices by interpolation), which is how coarser levels of detail are produced.
#pragma once
#include <mlfe/core/mesh/hierarchy.h>

#include <vector>

namespace mlfe {

/// Surpluses of nodal values U (one per vertex of h; size checked).
template <int D>
std::vector<double> hierarchical_decompose(const Hierarchy<D>& h, const std::vector<double>& nodal);

/// Nodal values at every vertex of h of the function that keeps the surpluses of vertex
/// levels ≤ max_level (max_level >= h.max_level() reproduces the input of decompose exactly
/// up to rounding).
template <int D>
std::vector<double> hierarchical_reconstruct(const Hierarchy<D>& h, const std::vector<double>& surplus,
                                             int max_level);

/// Prolongation of nodal values to vertices added since they were computed: vertices with id
/// >= values.size() get the mean of their two parents (the function is unchanged).
template <int D>
void prolongate_to_new_vertices(const Hierarchy<D>& h, std::vector<double>& values);

}  // namespace mlfe
