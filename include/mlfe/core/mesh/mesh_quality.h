// Shape measures of simplices, for refinement tests, benchmarks and reports.
#pragma once
#include <array>

namespace mlfe {

/// Smallest interior angle of a triangle, in degrees (0 for a degenerate triangle).
double min_angle_deg(const std::array<std::array<double, 2>, 3>& p);
/// Smallest dihedral angle of a tetrahedron, in degrees (0 for a degenerate tetrahedron).
double min_dihedral_deg(const std::array<std::array<double, 3>, 4>& p);

}  // namespace mlfe
