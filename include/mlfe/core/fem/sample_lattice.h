// The samples' lattice: T0 and the refinement rules put the vertices of level L exactly on the
// samples of a grid, and the approximation is fitted to the samples themselves.
//
// Grosso, Lürig & Ertl (IEEE Vis 1997) start from a box as 6 tetrahedra and measure errors
// against f in the continuous L2 norm. For sampled data the box over the extent puts no
// vertex of any level on a sample (level k's vertices are extent / 2^k apart), so features
// of one sample are invisible to every level and refinement goes on below the sample spacing.
// Here T0 is a cube W = 2^L samples wide on every axis (index space; W·spacing in the local
// frame), padded beyond the data's last sample where the data is shorter than W:
//
//      index 0                      n-1        W
//        +-----+-----+-----+-----+---.-+-----+      level 0: one cube, 6 Kuhn tetrahedra
//        |                           .       |      level k: vertices W/2^k samples apart
//        |        data               .  pad  |      level L: the vertices are the samples;
//        |    (samples 0..n-1)       .       |               nothing is refined below it
//        +-----+-----+-----+-----+---.-+-----+
//        '-- W = 2^L >= max(n_a - 1) --------'
//
// Red refinement (Bey) of Kuhn tetrahedra bisects edges between lattice points, so the
// vertices of level k are the lattice points with indices divisible by 2^(L-k). Elements that
// hold no sample (wholly in the padding) are never refined; the outputs clip to the data box.
//
// The approximation is the least-squares fit at the samples (the discrete L2 norm over the
// samples, each weighted by the voxel volume so the figures keep the units of ∫(f − u)²):
//     u = argmin Σ_s w (f_s − u(x_s))²,   M_ij = Σ_s w φ_i(x_s) φ_j(x_s),   F_i = Σ_s w f_s φ_i(x_s).
// On a leaf of level L the only samples are its corners, so the finest level interpolates
// the data exactly and refinement ends there; errors, RMS, PSNR and maximum error are those
// at the samples. Each sample belongs to exactly one leaf: the one that contains the sample
// pushed an infinitesimal step along (±1, ±ε, ±ε²) (inward on the data's upper faces), decided
// in exact integer arithmetic, so no sample is counted twice or missed.
#pragma once
#include <mlfe/core/fem/element_integrals.h>
#include <mlfe/core/field/scalar_grid.h>
#include <mlfe/core/mesh/hierarchy.h>

#include <array>
#include <cstdint>
#include <vector>

namespace mlfe {

struct SampleLattice {
  int dim = 3;
  std::array<std::int64_t, 3> dims{1, 1, 1};  ///< samples per axis (1 on unused axes)
  std::array<double, 3> spacing{1, 1, 1};
  int level = 0;             ///< L: level whose vertices are the samples
  std::int64_t width = 1;    ///< W = 2^L samples: T0's cube edge in index space
  double sample_weight = 1;  ///< w: the voxel volume (area in 2D)

  /// Upper corner of the data box in the local frame: (n − 1)·spacing.
  std::array<double, 3> data_extent() const;
  /// Upper corner of T0's box: W·spacing (0 on unused axes).
  std::array<double, 3> box_extent() const;
  /// Number of samples.
  std::int64_t samples() const { return dims[0] * dims[1] * dims[2]; }
};

/// The lattice of a 2D or 3D grid: L is the smallest level with 2^L ≥ n_a − 1 on every axis.
/// Throws mlfe::Error for grids with fewer than 2 samples on an axis of their dimension or
/// more than 2^24 samples along one.
SampleLattice sample_lattice(const ScalarGrid& grid);

/// The lattice of a stored hierarchy: level L on the samples of a dim-D grid with these dims and
/// spacing (as a version 3 file records them, validated by its reader).
SampleLattice sample_lattice(int dim, const std::array<std::int64_t, 3>& dims,
                             const std::array<double, 3>& spacing, int level);

/// Least-squares integrals of the samples an element owns (see above): f2 = Σ w f², fphi[j] =
/// Σ w f λ_j, mass = Σ w λ_i λ_j (upper triangle, row major), points = samples owned, fmin/fmax
/// over them; with `gradients`, its grad and grad2 from the field's gradient at the samples. The
/// corners p (local frame) must be lattice points (CHECKed).
template <int D>
ElementIntegrals<D> sample_integrals(const std::array<std::array<double, D>, D + 1>& p,
                                     const SampleLattice& lattice, const ScalarGrid& grid, const Field& f,
                                     ElementGradients<D>* gradients = nullptr);

/// A sample an element owns: its linear index in the grid (x fastest) and its barycentric
/// coordinates in the element (exact rationals of the lattice, rounded once to double).
template <int D>
struct OwnedSample {
  std::int64_t index;
  std::array<double, D + 1> lambda;
};

/// Adds one sample's terms to the least-squares sums of its element: f2 += w f²,
/// fphi_i += w f λ_i and mass (upper triangle, row major, as ElementIntegrals) += w λ_i λ_j.
/// The one place those sums are formed, so every path that sums samples (sample_integrals, the
/// sampled operator's summed leaves) gives the same bits.
template <int D>
inline void add_sample_terms(double w, double f, const std::array<double, D + 1>& lambda, double& f2,
                             std::array<double, D + 1>& fphi,
                             std::array<double, (D + 1) * (D + 2) / 2>& mass) {
  f2 += w * f * f;
  for (int i = 0, m = 0; i <= D; ++i) {
    fphi[static_cast<std::size_t>(i)] += w * f * lambda[static_cast<std::size_t>(i)];
    for (int j = i; j <= D; ++j)
      mass[static_cast<std::size_t>(m++)] +=
          w * lambda[static_cast<std::size_t>(i)] * lambda[static_cast<std::size_t>(j)];
  }
}

/// The samples the simplex with lattice corners p (local frame; CHECKed) owns, by the rule above,
/// in row order (x fastest, then y, then z); `out` is cleared first. Sums over every leaf's
/// owned samples visit each sample of the data exactly once.
template <int D>
void owned_samples(const std::array<std::array<double, D>, D + 1>& p, const SampleLattice& lattice,
                   std::vector<OwnedSample<D>>& out);

/// How far the samples an element owns (the rule above) are from the linear interpolant of
/// the corner values v: the largest |f_s − Σ λ_i v_i|, the sum of squares and the count. At a
/// sample on a corner, and on an element whose corner values are equal, the interpolant is
/// exact; elsewhere it carries the rounding of double arithmetic (~1e-16 relative). Stops scanning once the
/// largest exceeds `stop` (then sum2 and samples are partial). Corners as for sample_integrals.
struct SampleDeviation {
  double max = 0;
  double sum2 = 0;
  std::int64_t samples = 0;
};
template <int D>
SampleDeviation sample_deviation(const std::array<std::array<double, D>, D + 1>& p,
                                 const SampleLattice& lattice, const ScalarGrid& grid,
                                 const std::array<double, D + 1>& v, double stop);

/// Whether the simplex with corners p (local frame) lies wholly outside the data box's
/// interior: it owns no sample and is never refined.
template <int D>
bool outside_data(const std::array<std::array<double, D>, D + 1>& p, const SampleLattice& lattice);

/// A leaf mesh of exactly the data's box, for exports (simulation meshes): refines `h` until
/// no leaf straddles the box's upper faces (a face is a plane of level L's lattice, so this
/// ends there at the latest), giving new vertices the mean of their edge's values (u is
/// linear along the edge; where a green family is replaced by its parent's red children, u
/// changes within those elements to the interpolant of the same vertex values), and returns
/// the leaves inside the box in id order. The caller's hierarchy and values change.
template <int D>
std::vector<ElemId> leaves_in_data(Hierarchy<D>& h, std::vector<double>& values,
                                   const SampleLattice& lattice);

}  // namespace mlfe
