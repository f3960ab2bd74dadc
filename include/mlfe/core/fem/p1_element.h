// Piecewise-linear (P1) finite element on a simplex: measure, barycentric gradients, and the
// exact element mass and stiffness matrices.
//   mass:      M_ij = |T| (1 + δ_ij) / ((D+1)(D+2))
//   stiffness: K_ij = |T| ∇λ_i · ∇λ_j
#pragma once
#include <array>
#include <cmath>

namespace mlfe {

template <int D>
struct P1Element {
  using Point = std::array<double, D>;
  double measure = 0;                               ///< |T| > 0
  std::array<std::array<double, D>, D + 1> grad{};  ///< ∇λ_i, constant on T

  /// From the vertex positions; a degenerate simplex gives measure 0 and zero gradients.
  explicit P1Element(const std::array<Point, D + 1>& p) {
    double j[D][D];
    jacobian(p, j);
    const double det = determinant(j);
    if (det == 0) return;
    double inv[D][D];
    if constexpr (D == 2) {
      inv[0][0] = j[1][1] / det;
      inv[0][1] = -j[0][1] / det;
      inv[1][0] = -j[1][0] / det;
      inv[1][1] = j[0][0] / det;
    } else {
      inv[0][0] = (j[1][1] * j[2][2] - j[1][2] * j[2][1]) / det;
      inv[0][1] = (j[0][2] * j[2][1] - j[0][1] * j[2][2]) / det;
      inv[0][2] = (j[0][1] * j[1][2] - j[0][2] * j[1][1]) / det;
      inv[1][0] = (j[1][2] * j[2][0] - j[1][0] * j[2][2]) / det;
      inv[1][1] = (j[0][0] * j[2][2] - j[0][2] * j[2][0]) / det;
      inv[1][2] = (j[0][2] * j[1][0] - j[0][0] * j[1][2]) / det;
      inv[2][0] = (j[1][0] * j[2][1] - j[1][1] * j[2][0]) / det;
      inv[2][1] = (j[0][1] * j[2][0] - j[0][0] * j[2][1]) / det;
      inv[2][2] = (j[0][0] * j[1][1] - j[0][1] * j[1][0]) / det;
    }
    measure = measure_from(det);
    // λ_{i+1} = row i of J^{-1} applied to (x - p0); λ_0 = 1 - Σ.
    for (int a = 0; a < D; ++a) grad[0][a] = 0;
    for (int i = 0; i < D; ++i)
      for (int a = 0; a < D; ++a) {
        grad[i + 1][a] = inv[i][a];
        grad[0][a] -= inv[i][a];
      }
  }

  /// |T| alone (no gradients: no 3×3 inverse), bit-identical to P1Element(p).measure, for the
  /// loops that need only the measure (pure L2 mass matrices, error densities).
  static double measure_of(const std::array<Point, D + 1>& p) {
    double j[D][D];
    jacobian(p, j);
    return measure_from(determinant(j));
  }

  static constexpr double mass_factor() { return 1.0 / ((D + 1) * (D + 2)); }
  /// M_ik of a simplex of the given measure (the mass matrix depends on nothing else).
  static double mass_of(double measure, int i, int k) {
    return measure * mass_factor() * (i == k ? 2.0 : 1.0);
  }
  double mass(int i, int k) const { return mass_of(measure, i, k); }
  double stiffness(int i, int k) const {
    double s = 0;
    for (int a = 0; a < D; ++a) s += grad[i][a] * grad[k][a];
    return measure * s;
  }

 private:
  // Columns p_i - p_0.
  static void jacobian(const std::array<Point, D + 1>& p, double (&j)[D][D]) {
    for (int i = 0; i < D; ++i)
      for (int a = 0; a < D; ++a) j[a][i] = p[i + 1][a] - p[0][a];
  }
  static double determinant(const double (&j)[D][D]) {
    if constexpr (D == 2) {
      return j[0][0] * j[1][1] - j[0][1] * j[1][0];
    } else {
      return j[0][0] * (j[1][1] * j[2][2] - j[1][2] * j[2][1]) -
             j[0][1] * (j[1][0] * j[2][2] - j[1][2] * j[2][0]) +
             j[0][2] * (j[1][0] * j[2][1] - j[1][1] * j[2][0]);
    }
  }
  static double measure_from(double det) { return std::abs(det) / (D == 2 ? 2 : 6); }
};

}  // namespace mlfe
