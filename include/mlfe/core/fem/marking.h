// Marking for the adaptive approximation (Grosso, Lürig & Ertl, IEEE Vis 1997, section 3):
// which leaves to refine after a solve, and the surface rules that also drive the surface
// passes before the first solve. Kept apart from the mesh and the solver, as MFEM keeps its
// ThresholdRefiner apart from Mesh.
#pragma once
#include <mlfe/core/fem/approximation.h>
#include <mlfe/core/fem/fe_assembly.h>
#include <mlfe/core/fem/linear_operator.h>
#include <mlfe/core/field/field.h>
#include <mlfe/core/mesh/hierarchy.h>

#include <cstddef>
#include <vector>

namespace mlfe {

/// A leaf marked for refinement: by a surface rule (ranked first: an asset's accuracy is its
/// surfaces'), and its error E_T (then worst first: most error removed per new vertex).
/// (16 bytes: a full head's last solve marks ~10 M leaves.)
struct Mark {
  double error;
  ElemId id;
  bool surface;
};

/// The marks after a solve, in leaf order: the paper's threshold rule (sqrt(E_T/|T|) >
/// threshold), equidistribution toward the RMS target while it is not met (E_T/|T| > τ²), and
/// with iso-values the surface rule (surface-driven builds: u's surfaces against the data's,
/// only with check_surfaces_against_u; otherwise the iso-aware estimate of
/// surface_needs_refinement). Leaves at max_level are never marked. `err` (E_T) is per leaf
/// (leaves order); an error per unit measure decides: E_T over the weight of the samples T
/// owns when `samples` (per leaf) is given or `cache` (per element id) holds sampled integrals,
/// else E_T/|T|. The iso-aware estimate reads f's range on a leaf from `cache` (CHECKed);
/// `u` is the solution at the vertices. *surface_marks counts the surface marks. Parallel; the
/// result does not depend on the thread count.
template <int D>
std::vector<Mark> mark_leaves(const Hierarchy<D>& h, const std::vector<ElemId>& leaves,
                              const std::vector<double>& err, const std::vector<std::uint32_t>* samples,
                              const std::vector<ElementIntegrals<D>>* cache, const Vector& u, const Field& f,
                              const ApproximationOptions& opts, bool surface_driven, bool target_met,
                              std::size_t* surface_marks, const SampleLattice* lattice = nullptr);

/// Ranks the marks (surface marks first, then larger error, ties by id: a strict order) so that
/// the first `cap` are the worst, sorted, and returns how many of them to refine: all `cap`, or
/// with excess_error ≥ 0 (Σ E − τ²|Ω| toward an RMS target) the surface marks plus the fewest
/// worst ones that carry 60 % of the excess (a Dörfler-like bulk criterion, so the last step
/// does not overshoot the target by a whole level), at least one.
std::size_t rank_and_select(std::vector<Mark>& marks, std::size_t cap, std::size_t surface_marks,
                            double excess_error);

/// The surface-driven rule for leaf e and the linear function with nodal values `nodal` (f's
/// interpolant while the mesh is built, u after a solve): true when the data's surfaces and the
/// linear function's are more than tolerance_voxels apart inside e (down to two-voxel
/// elements), or the linear function misses a piece of surface altogether (down to one voxel).
/// *candidate is set when e can hold a surface at all (the data's range brackets an iso-value).
/// Whether leaf e may still be red-refined without passing max_level: a green leaf refines its
/// parent, whose red children are one level below the parent.
template <int D>
bool refinable(const Hierarchy<D>& h, ElemId e, int max_level) {
  return h.kind(e) == ElemKind::kGreen ? h.level(e) <= max_level : h.level(e) < max_level;
}

template <int D, typename Values>
bool surface_gap_mark(const Hierarchy<D>& h, ElemId e, const Values& nodal, const Field& f,
                      const ApproximationOptions& opts, double tolerance_voxels, bool* candidate = nullptr);

}  // namespace mlfe
