// Integrals of the data f against one P1 element, resolving every voxel under the element.
//
// An element much larger than a voxel integrated with one fixed rule misses features inside
// it, and the error estimate then lies. So the element is split by regular (red) refinement —
// Bey's rule in 3D — into sub-simplices whose longest edge is at most `max_sub_edge` (a voxel
// spacing by default; see integrate_element), and a degree-2 rule with POSITIVE weights is applied on each:
// 3 points in 2D, the 4-point Stroud rule in 3D. Positive weights and exactness for u² (u
// linear) make the error identity below a non-negative sum of squares, so an element's
// error estimate can never come out negative:
//     E_T = ∫_T (f - u)² = ∫_T f² - 2 Σ_j U_j ∫_T f λ_j + Uᵀ M_T U.
// The same rule gives the load vector, so Galerkin orthogonality holds for the discrete
// integrals exactly (to the solver tolerance).
//
// The points are evaluated in batches through Field::values (the bottom refinement levels at
// once; shallow elements take their barycentrics from a per-depth table), but every sum is
// accumulated point by point in the fixed depth-first order of the sub-simplices, so the
// result does not depend on the batching, bit for bit.
#pragma once
#include <mlfe/core/field/field.h>

#include <array>
#include <cstdint>
#include <utility>

namespace mlfe {

// The fields the assembly and the error estimate read for every leaf (f2, fphi, mass) come
// last and together: a cache entry is read at random, once per corner, and these 120 bytes
// (3D) span 2-3 cache lines where the former order spanned 3-4. The H1 term's sums are kept
// apart (ElementGradients): the cache, 136 bytes per element in 3D, is the largest array of
// a build that uses it (the H1 norm, the iso-aware estimate, quadrature of unstructured input;
// least squares at the samples in L2 does without: sampled_least_squares.h).
template <int D>
struct ElementIntegrals {
  float fmin = 0, fmax = 0;  ///< range of f at the quadrature points
  std::uint32_t points = 0;  ///< quadrature points used (samples owned, when sampled)
  /// Least squares at the samples (sample_lattice.h): `mass` holds Σ w λ_i λ_j (upper triangle,
  /// row major) and replaces the exact P1 mass matrix of the element in the system and in E_T.
  bool sampled = false;
  double f2 = 0;                     ///< ∫_T f²
  std::array<double, D + 1> fphi{};  ///< ∫_T f λ_j
  std::array<double, (D + 1) * (D + 2) / 2> mass{};
  /// Entry (i, j) of `mass` (either order).
  double mass_at(int i, int j) const {
    if (i > j) std::swap(i, j);
    return mass[static_cast<std::size_t>(i * (D + 1) - i * (i - 1) / 2 + (j - i))];
  }
};

/// The sums of the H1 term over one element (only with gradients requested).
template <int D>
struct ElementGradients {
  std::array<double, D> grad{};  ///< ∫_T ∇f
  double grad2 = 0;              ///< ∫_T |∇f|²
};

/// Integrals over the simplex with vertices p (local frame, units of the field's spacing).
/// The element is subdivided until the size (D!·measure)^(1/D) of the pieces is at most
/// max_sub_edge > 0 (a Kuhn simplex of a voxel-sized cube has size one voxel); the depth is
/// capped at 12 levels. With `gradients`, the H1 sums go there.
template <int D>
ElementIntegrals<D> integrate_element(const std::array<std::array<double, D>, D + 1>& p, const Field& f,
                                      double max_sub_edge, ElementGradients<D>* gradients = nullptr);

/// Subdivision depth for an element of the given size.
int integration_depth(double size, double max_sub_size);

}  // namespace mlfe
