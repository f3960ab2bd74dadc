// Refitting a simplified surface's vertices to the surface it was simplified from: the
// fixed-connectivity step of mesh optimization (Hoppe, DeRose, Duchamp, McDonald & Stuetzle,
// "Mesh optimization", SIGGRAPH 1993).
#pragma once
#include <mlfe/core/surface/triangle_mesh.h>

#include <cstddef>

namespace mlfe {

struct SurfaceFitOptions {
  /// Every vertex of the dense surface stays within this distance (mesh units) of the fitted
  /// surface, or no further than it was before: the simplifier's bound is kept. > 0.
  double tolerance = 0;
  /// Weight of the spring energy per edge against the data term (per unit area of the dense
  /// surface): it keeps vertices without nearby data in place and the triangles well shaped.
  double spring = 0.01;
  /// A moved triangle's normal may turn by at most this much (degrees), else its corners stay.
  double max_normal_turn_degrees = 60.0;
};

struct SurfaceFitReport {
  std::size_t samples = 0;  ///< dense vertices fitted (those on a triangle)
  std::size_t moved = 0;    ///< fitted vertices that moved
  std::size_t kept = 0;     ///< vertices put back by the bound or the normal check
  double rms_before = 0;    ///< area-weighted RMS distance of the samples to the surface
  double rms_after = 0;     ///< the same after the fit (to the triangles they were matched to)
};

/// Moves the vertices of `coarse`, a simplification of `dense` with the same orientation, to the
/// least-squares fit of `dense`: each referenced vertex of `dense`, weighted by a third of its
/// triangles' area, is matched to its closest point on `coarse` (triangle and barycentric
/// weights), and the positions minimising the summed squared distances of the samples to their
/// matched points plus `spring` times the squared edge vectors' changes are solved for (conjugate
/// gradients, one system per axis). Vertices on a boundary edge of `coarse` stay. A vertex is
/// put back where a moved triangle would turn its normal by more than the limit or where a
/// sample would end up further than both the tolerance and its distance before, so the
/// simplifier's bound holds and no triangle flips. Connectivity, normals and vertex order are
/// unchanged (normals are not recomputed). Deterministic for any thread count. Throws
/// mlfe::Error unless options.tolerance is positive and finite; triangle indices out of range
/// are a bug (CHECK).
SurfaceFitReport fit_surface(TriangleMesh& coarse, const TriangleMesh& dense,
                             const SurfaceFitOptions& options);

}  // namespace mlfe
