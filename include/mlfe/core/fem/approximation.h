// The adaptive multilevel finite-element loop of R. Grosso, C. Lürig, T. Ertl, "The Multilevel
// Finite Element Method for Adaptive Mesh Optimization and Visualization of Volume Data",
// IEEE Visualization 1997:
//
//   T0 (a box as 2 triangles / 6 tetrahedra) → solve M U = F → E_T = ∫_T (f − u)² per element
//   → red-green refine the elements whose error is too large → solve again (CG + BPX, warm
//   started from the previous solution) → … until the global error is small enough.
//
// Beyond the paper: stopping by a target RMS error, a vertex budget, a memory budget or a
// maximum level; optional H1 norm (u,v) + s²(∇u,∇v) with s the voxel spacing (the paper's
// future work); surface-driven refinement for assets (surface_estimator.h): the mesh is
// refined where the iso-surfaces need it, decided from the data before the first solve, and
// u is then checked against the same rule.
#pragma once
#include <mlfe/core/fem/sample_lattice.h>
#include <mlfe/core/field/field.h>
#include <mlfe/core/mesh/hierarchy.h>

#include <cstddef>
#include <functional>
#include <string>
#include <vector>

namespace mlfe {

struct IterationStats {
  int iteration = 0;
  int level = 0;  ///< finest element level
  std::size_t vertices = 0;
  std::size_t elements = 0;  ///< leaf elements
  std::size_t marked = 0;    ///< elements marked for refinement after this solve
  double l2_error = 0;       ///< sqrt(Σ E_T), data units × length^(D/2)
  double rms_error = 0;      ///< l2_error / sqrt(|Ω|), data units
  double rms_percent = 0;    ///< rms_error / value range × 100
  double psnr_db = 0;        ///< 20 log10(range / rms_error)
  int cg_iterations = 0;     ///< 0 for a direct solve
  double cg_residual = 0;
  double assembly_seconds = 0, solve_seconds = 0, estimate_seconds = 0, refine_seconds = 0;
  double seconds = 0;  ///< since the start
};

/// One pass of the surface-driven refinement before the first solve.
struct SurfacePassStats {
  std::size_t vertices = 0;
  std::size_t elements = 0;    ///< leaf elements
  std::size_t candidates = 0;  ///< leaves whose data range brackets an iso-value
  std::size_t marked = 0;
  double seconds = 0;  ///< since the start of approximate()
};

/// kAuto: BPX, except for the least squares at the samples in the L2 norm, where the matrix is
/// a (sampled) mass matrix, well conditioned after diagonal scaling alone, while BPX's
/// level scaling of the continuous mass does not fit vertices that few samples see
/// (the padding's rim): 20 CG iterations with Jacobi against 500-1500 with BPX
/// (bench/RESULTS.md, session 10).
enum class Preconditioner { kAuto, kBpx, kJacobi, kNone };

struct ApproximationOptions {
  double target_rms = 0;         ///< stop when RMS error ≤ this (data units); 0: unused
  double threshold = 0;          ///< paper's rule: refine T when sqrt(E_T/|T|) > threshold; 0: unused
  std::size_t max_vertices = 0;  ///< never exceed this many vertices; 0: no limit
  int max_level = 20;            ///< elements of this level are not refined
  int max_iterations = 60;       ///< refine-solve cycles
  int start_level = -1;          ///< uniform levels before adapting; -1: until edges ≤ 16 voxels
  bool h1 = false;               ///< (u,v) + s²(∇u,∇v) instead of (u,v)
  double quadrature_edge = 0;    ///< sub-simplex size for integration; 0: 2 × Field::voxel_size()
  /// Iso-aware refinement: elements where f or u crosses one of these values are also refined
  /// while the surface's estimated distance error sqrt(E_T/|T|) / |∇u| exceeds
  /// surface_tolerance voxels (or the surface is missing from u), down to voxel-sized elements.
  std::vector<double> iso_values;
  double surface_tolerance = 0.5;
  /// With iso_values: refine only where a surface needs it. Before the first solve, leaves
  /// whose data range (Field::range_in_box) brackets an iso-value are refined while the
  /// surfaces of f and of f's linear interpolant are more than surface_tolerance voxels apart
  /// (surface_gap_exceeds), down to voxel-sized elements; flat parts of a surface stay on
  /// coarse elements. After each solve the same rule is applied to u. target_rms, threshold and
  /// max_vertices still apply when set.
  bool surface_driven = false;
  /// With surface_driven: after the first solve, also refine where u's surfaces miss the data's
  /// or lie more than twice the tolerance from them, and solve once more. u smooths away small
  /// noise blobs that f's interpolant kept, so this adds vertices (bench/RESULTS.md).
  bool check_surfaces_against_u = false;
  /// With surface_driven: false ends the build after the surface passes, without assembling or
  /// solving: values are then f's interpolant (data_values), iterations and leaf_errors are
  /// empty and stop_reason is the surface passes'. For callers whose outputs need only the mesh
  /// and the data (assets extracted from the interpolant), not u or its error.
  bool solve = true;
  /// With iso_values, the loop ends when a refinement added fewer than this fraction of
  /// vertices: iso-aware marks can trickle in a few elements per iteration, each a full solve.
  /// 0: off. Not applied to the paper's threshold rule.
  double min_growth = 0.01;
  /// Refinement stops before the estimated memory of the approximation (hierarchy, integrals,
  /// matrix, solver vectors: estimated_memory_bytes()) would exceed this; 0: no limit.
  std::size_t max_memory_bytes = 0;
  /// For fields with samples (Field::samples()): T0 on the samples' lattice and least squares
  /// at the samples (sample_lattice.h). false keeps the paper's box over the extent and the
  /// continuous L2 norm (always the case for fields without samples).
  bool lattice = true;
  /// ≥ 0: the error-bounded interpolating build instead of least squares (fields with samples
  /// on the lattice; approximate() throws mlfe::Error otherwise). The values are the samples
  /// themselves at the vertices (level L's vertices are the samples) and leaves are refined
  /// while a sample they own deviates from their linear interpolant by more than this (data
  /// units). Level L interpolates exactly, so the loop always ends with every sample within
  /// the bound, unless max_vertices, max_memory_bytes or max_level stop it first (stop_reason
  /// says so). Nothing is solved: iterations holds one row, with the errors at the samples;
  /// target_rms, threshold and the iso-value options are not used.
  double max_sample_error = -1;
  Preconditioner preconditioner = Preconditioner::kAuto;
  double cg_tolerance = 1e-9;   ///< relative residual
  int direct_solve_max = 1000;  ///< direct (LDLT) solve while vertices ≤ this (T0 and the first
                                ///< uniform levels; beyond, 3D fill-in makes BPX-CG cheaper); 0: never
  std::function<void(const IterationStats&)> progress;            ///< called after every solve
  std::function<void(const SurfacePassStats&)> surface_progress;  ///< after every surface pass
};

template <int D>
struct Approximation {
  Hierarchy<D> hierarchy;
  std::vector<double> values;  ///< u at every vertex of the hierarchy (local frame)
  std::vector<SurfacePassStats> surface_passes;
  std::vector<IterationStats> iterations;
  std::vector<double> leaf_errors;  ///< E_T per leaf (h.leaves() order) of the final u
  double domain_measure = 0;        ///< |Ω|, or samples × voxel volume on the lattice
  double value_min = 0, value_max = 0;
  /// Whether T0 and the errors are on the samples' lattice; then `lattice` describes it, the
  /// hierarchy's box is T0's padded cube and `data_extent` the data's box (outputs clip to it).
  bool on_lattice = false;
  SampleLattice lattice;
  std::array<double, 3> data_extent{0, 0, 0};
  /// The interpolating build's bound (ApproximationOptions::max_sample_error), else −1.
  double max_sample_error = -1;
  /// Interpolating build on integer samples: every value is an integer (samples, and in the
  /// padding floor((v_a + v_b) / 2) of the parents instead of their mean), so a file can store
  /// them losslessly as integer surpluses.
  bool integer_values = false;
  std::string stop_reason;
  bool memory_limited = false;  ///< refinement stopped at max_memory_bytes
  /// Surface-driven builds: f at every vertex (the nodal values of f's interpolant, which the
  /// refinement certified near the surfaces); empty otherwise.
  std::vector<double> data_values;
};

/// Extends `values` to f at every vertex of h: vertices from values.size() on are sampled (in
/// the local frame), earlier ones kept. Parallel; the values do not depend on the thread count.
template <int D>
void sample_at_vertices(const Hierarchy<D>& h, const Field& f, std::vector<double>& values);

/// Estimated peak bytes of approximate() for a hierarchy of this size (hierarchy, cached
/// integrals, matrix, preconditioner and solver vectors); an upper-side model, used for the
/// memory budget.
std::size_t estimated_memory_bytes(int dim, std::size_t vertices, std::size_t leaves);

/// Runs the adaptive loop for a field of dimension D (CHECKed) on its domain box
/// [0, extent] in the field's local frame. Deterministic for any thread count.
template <int D>
Approximation<D> approximate(const Field& f, const ApproximationOptions& opts);

/// L2 (or H1) best approximation on a fixed hierarchy's leaves: returns nodal values and the
/// CG statistics in `stats` (when not null). `warm` (may be empty) is the start value.
template <int D>
std::vector<double> solve_best_approximation(const Hierarchy<D>& h, const Field& f,
                                             const ApproximationOptions& opts,
                                             const std::vector<double>& warm, IterationStats* stats = nullptr,
                                             const SampleLattice* lattice = nullptr);

extern template Approximation<2> approximate<2>(const Field&, const ApproximationOptions&);
extern template void sample_at_vertices<2>(const Hierarchy<2>&, const Field&, std::vector<double>&);
extern template void sample_at_vertices<3>(const Hierarchy<3>&, const Field&, std::vector<double>&);
extern template Approximation<3> approximate<3>(const Field&, const ApproximationOptions&);

}  // namespace mlfe
