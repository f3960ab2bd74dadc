// Surface error of a linear element against the data, for surface-driven refinement.
//
// Grosso, Lürig & Ertl (IEEE Vis 1997) refine by the L2 error of u over whole elements; an
// asset needs its iso-surfaces right and nothing else, so where iso-values are given the
// refinement can be driven by the distance between the surfaces {f = iso} and {ℓ = iso},
// with ℓ linear on the element (f's interpolant at the corners while the mesh is built, u
// afterwards). Points where f and ℓ lie on different sides of the iso-value are exactly the
// points between the two surfaces, so the largest distance of such a point to ℓ's surface
// measures the gap in both directions: pieces of f's surface that ℓ misses and pieces of ℓ's
// surface that f does not have. Noise away from the surfaces never changes a side, so it does
// not drive refinement (an L2 estimate would refine all of it).
#pragma once
#include <mlfe/core/field/field.h>

#include <array>
#include <vector>

namespace mlfe {

enum class SurfaceGap {
  kWithin,   ///< the surfaces are within the tolerance everywhere in the simplex
  kDistant,  ///< somewhere they are farther apart than the tolerance
  kMissing,  ///< f has surface in the simplex and the linear function has none there
};

/// How the iso-surfaces of f and of the linear function with the given corner values on the
/// simplex p (local frame) compare inside the simplex, for all of `iso_values`. When f is a
/// sample grid (Field::samples), its samples inside the simplex are tested: a surface of the
/// data has samples on both sides, so none falls between them. Other fields are sampled on the
/// simplex's barycentric lattice with spacing at most `sample_spacing` along the longest edge
/// (one voxel: a feature of a voxel or more cannot fall between samples). A sample on the
/// other side than the linear function lies between the surfaces, and counts with its distance
/// |ℓ(x) − iso| / |∇ℓ| to ℓ's plane (kDistant beyond `tolerance`), or as kMissing when ℓ has no
/// surface in the simplex. Returns kMissing as soon as one is found, and kDistant as soon as one
/// is found when `stop_at_distant` (the caller treats both alike); deterministic; thread-safe
/// for a thread-safe field.
template <int D>
SurfaceGap surface_gap(const std::array<std::array<double, D>, D + 1>& p,
                       const std::array<double, D + 1>& corner_values, const Field& f,
                       const std::vector<double>& iso_values, double tolerance, double sample_spacing,
                       bool stop_at_distant = false);

}  // namespace mlfe
