// A red-green hierarchy described level by level, as the .mlfeh v2 file stores it (after
// R. Grosso, C. Lürig, T. Ertl, IEEE Vis 1997, Sec. 6: the coarse mesh, the deterministic
// refinement rules and the ids of the simplices to be regularly subdivided rebuild every
// level), and the hierarchical-basis value coding on top of it (H. Yserentant, Numer. Math. 49,
// 1986), quantized SZ-style against the already decoded coarser values (S. Di, F. Cappello,
// "Fast error-bounded lossy HPC data compression with SZ", IPDPS 2016) so the bound is exact.
//
// Canonical rebuild. Start from T0 (the coarse points and cells, in the original order). For
// k = 1, 2, …: the candidates of step k are the elements of level k−1 that are not green, in
// ElemId order of the hierarchy rebuilt so far; one mark per candidate says "red-refined".
// Step k passes to Hierarchy::refine() every marked candidate that is a leaf, and for a
// marked candidate that already has green children (closure of step k−1) its first green
// child (refine() then red-refines the candidate instead); the green closure runs inside
// refine(). A hierarchy's marks are the set of its red-refined elements, so the rebuild yields
// the same elements, vertices and levels in a canonical numbering (the ids differ from the
// original's in general, the mesh does not).
#pragma once
#include <mlfe/core/base/error.h>
#include <mlfe/core/mesh/hierarchy.h>

#include <cstdint>
#include <vector>

namespace mlfe {

/// The candidates of step `level` (≥ 1): elements of level − 1 that are not green, in id order.
template <int D>
std::vector<ElemId> refinement_candidates(const Hierarchy<D>& h, int level);

/// One rebuild step: refines per `marks` (one byte, 0 or 1, per candidate of
/// refinement_candidates(h, level), sizes CHECKed). Returns refine()'s old → new element ids,
/// or an empty vector when nothing was marked (ids unchanged).
template <int D>
std::vector<ElemId> apply_refinement_marks(Hierarchy<D>& h, const std::vector<ElemId>& candidates,
                                           const std::vector<std::uint8_t>& marks);

/// Thrown by encode_levels for a hierarchy the canonical rebuild does not reproduce (a green
/// closure that depended on the refinement history; Hierarchy::green_pattern breaks ties by
/// the points' coordinates so that it does not). Hierarchies of refine() rebuild in every case
/// tested; write_hierarchy's callers may fall back to format version 1 on this error.
struct LevelRebuildError : Error {
  using Error::Error;
};

/// A hierarchy's level-by-level description: what the file stores besides the values.
template <int D>
struct LevelDescription {
  std::vector<typename Hierarchy<D>::Point> coarse_points;
  std::vector<typename Hierarchy<D>::Cell> coarse_cells;  ///< ids into coarse_points
  /// marks[k − 1]: the marks of step k, k = 1 .. levels.
  std::vector<std::vector<std::uint8_t>> marks;
  /// Rebuilt vertex count after step k (k = 0 .. levels); vertices of step k are the ids
  /// [vertex_end[k − 1], vertex_end[k]).
  std::vector<std::size_t> vertex_end;
};

template <int D>
struct LevelEncoding : LevelDescription<D> {
  Hierarchy<D> rebuilt;               ///< the canonical rebuild (up to the requested level)
  std::vector<VertexId> to_original;  ///< rebuilt vertex id → vertex id in the input hierarchy
};

/// The level-by-level description of h, rebuilt canonically up to `max_level` (−1: all
/// levels). With max_level < h.max_level(), `rebuilt` is T_max_level of h (its elements of
/// level ≤ max_level). The full rebuild equals h up to numbering (verified: vertex, element
/// and leaf counts, and the sum of a 64-bit hash of every leaf's vertex set, so other leaves
/// pass only by a 2^-64 coincidence); when it does not, throws LevelRebuildError (no file name
/// in the message).
template <int D>
LevelEncoding<D> encode_levels(const Hierarchy<D>& h, int max_level = -1);

/// Replaces h by its canonical rebuild (encode_levels(h).rebuilt, the same mesh in the file's
/// numbering) and permutes each array of `per_vertex` (h.vertex_count() values each, or empty)
/// to its vertex order; returns the description, for write_hierarchy without a second rebuild.
/// A writer that rebuilt beside the caller's hierarchy held both at its peak; here h is freed
/// before the rebuild, which follows only h's T0, edge → midpoint map and the vertex sets of
/// its red-refined elements. Throws LevelRebuildError as encode_levels does, with h then
/// empty (a caller that needs it afterwards uses encode_levels) and the arrays untouched.
template <int D>
LevelDescription<D> renumber_canonically(Hierarchy<D>& h,
                                         const std::vector<std::vector<double>*>& per_vertex);

/// Hierarchical-basis quantization: visiting vertices in id order (parents first), the
/// prediction is 0 for vertices of T0 and the mean of the two decoded parent values otherwise;
/// the stored integer is q = round((u − prediction) / (2E)) and the decoded value
/// prediction + q·2E (q ± 1 when rounding of the product would leave the bound). Returns the
/// decoded values, every one within `max_error` (> 0) of u (an exact tie between two codes may
/// exceed it by rounding, at most 1e-12 relative); `codes` (if given) receives q.
/// The decoded value of a vertex depends only on its own value and its parents' decoded values,
/// so it is the same whatever the vertex numbering. Throws mlfe::Error when |q| would reach 2^52
/// (a bound too small for the values).
template <int D>
std::vector<double> quantize_hierarchical(const Hierarchy<D>& h, const std::vector<double>& u,
                                          double max_error, std::vector<std::int64_t>* codes = nullptr);

/// Integer hierarchical-basis quantization (the .mlfeh v3 integer coding): values must be
/// integers of magnitude < 2^52 (else mlfe::Error). Visiting vertices in id order, the
/// prediction is 0 for vertices of T0 and floor((d_a + d_b) / 2) of the decoded parents
/// otherwise; the code is q = floor((u − p + E) / (2E + 1)) and the decoded value p + q·(2E + 1),
/// within E of u (E = 0: exactly u, lossless). Returns the decoded values; `codes` receives q.
template <int D>
std::vector<double> quantize_integer(const Hierarchy<D>& h, const std::vector<double>& u,
                                     std::int64_t max_error, std::vector<std::int64_t>* codes = nullptr);

/// One value of quantize_hierarchical: the code q of u under prediction `pred` (stored in
/// *code) and the decoded value pred + q·2E, within max_error (> 0) of u; throws mlfe::Error as
/// quantize_hierarchical does.
double quantize_value(double u, double pred, double max_error, std::int64_t* code);

/// One value of quantize_integer: u must be an integer of magnitude < 2^52 (else mlfe::Error);
/// stores q = floor((u − pred + E) / (2E + 1)) in *code and returns pred + q·(2E + 1).
std::int64_t quantize_integer_value(double u, std::int64_t pred, std::int64_t max_error, std::int64_t* code);

/// The integer prediction of that coding: floor((a + b) / 2), exact for |a|, |b| < 2^62.
inline std::int64_t integer_prediction(std::int64_t a, std::int64_t b) {
  return (a >> 1) + (b >> 1) + (a & b & 1);
}

extern template struct LevelDescription<2>;
extern template struct LevelDescription<3>;
extern template struct LevelEncoding<2>;
extern template struct LevelEncoding<3>;

}  // namespace mlfe
