// The one entry point to every simplifier: options naming the kind (the command line's
// --simplifier) and the bound, and simplify(), which picks the algorithm for a surface or for an
// interface complex. The algorithms' own contracts are in surface_simplification.h and
// complex_decimator.h.
#pragma once
#include <mlfe/core/simplify/complex_decimator.h>
#include <mlfe/core/simplify/surface_simplification.h>
#include <mlfe/core/surface/triangle_mesh.h>

#include <cstddef>
#include <utility>
#include <vector>

namespace mlfe {

/// Which simplifier. kBounded: simplify_within, the bound verified; kFast: the same collapses
/// and topology checks with the error estimated from the quadrics (SimplifyOptions::verify_bound
/// false); kMeshopt: meshoptimizer (simplify_fast), error estimated, seconds for millions of
/// triangles but it may pinch the surface (non-manifold spots); kAuto: bounded, but fast for
/// surfaces of over 200 000 triangles with a ratio below 5 % (topology kept either way).
enum class Simplifier { kAuto, kFast, kBounded, kMeshopt };

/// Every kind with its name ("auto", "fast", "bounded", "meshopt"), in the order the options
/// list them: the command line's --simplifier and Python's simplifier= take their names from it,
/// so a new simplifier is a value above, a row here and a case in simplify().
const std::vector<std::pair<Simplifier, const char*>>& simplifier_names();

struct SimplifierOptions {
  Simplifier kind = Simplifier::kAuto;
  double tolerance = 0;  ///< the bound, position units; > 0
  /// Stop at this fraction of the input's triangles, or earlier where the bound binds (0: the
  /// bound alone). Surfaces only: an interface complex stops at the bound.
  double ratio = 0;
  /// Where a collapse puts the surviving vertex (surfaces; not kMeshopt, which keeps input
  /// vertices). kOptimal ends with the least-squares refit of the simplified surface to the
  /// input (core/surface/surface_fitting.h), since the greedy collapses leave each vertex where
  /// its last merge put it.
  Placement placement = Placement::kInputVertex;
};

/// `mesh` simplified by `o.kind` within `o.tolerance`, down to `o.ratio` of its triangles. For
/// kAuto: up to 200 000 triangles the verified bound; above, the estimated bound to half the
/// tolerance first, then the verified bound on what is left (below a 5 % ratio the estimate all
/// the way). Decided from the mesh's size and the options alone, so the output does not depend
/// on the thread count. Throws mlfe::Error as the chosen algorithm does (a tolerance that is not
/// positive and finite, an index out of range, ...).
TriangleMesh simplify(const TriangleMesh& mesh, const SimplifierOptions& o);

/// The runs of simplify_within that simplify() makes, in order, for a surface of `triangles`
/// triangles and `o.kind` (kMeshopt: none, it is not simplify_within): one for kFast and
/// kBounded, kAuto's one or two by size (see simplify()); min_triangles is `o.ratio` of
/// `triangles`. Between two runs simplify() orders the vertices spatially (spatially_ordered).
std::vector<SimplifyOptions> simplify_stages(const SimplifierOptions& o, std::size_t triangles);

/// Simplifies the interface complex `x` in place within `o.tolerance`, keeping its interfaces
/// shared and every region's surface closed; returns the vertices removed. kAuto and kFast:
/// decimate_interface_complex (the bound estimated from the quadrics, as kFast's). Throws
/// mlfe::Error for kBounded and kMeshopt, which simplify one surface at a time and would unshare
/// the interfaces, and as decimate_interface_complex does.
std::size_t simplify(InterfaceComplex& x, const SimplifierOptions& o);

}  // namespace mlfe
