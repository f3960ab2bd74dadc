// Distances between two triangle meshes for semantic comparison (mlfe compare): deterministic
// surface sampling, a bounding-volume hierarchy for closest-point queries, and one-sided /
// symmetric Hausdorff and mean distances with the angle between the normals at matched points.
//
// Everything here depends only on the meshes and the options: samples come from a fixed-seed
// generator drawn sequentially, queries run in parallel but write to their own slot, and the
// reductions over the slots are sequential, so results are identical for any thread count.
#pragma once
#include <mlfe/core/mesh/ids.h>
#include <mlfe/core/surface/triangle_mesh.h>

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace mlfe {

/// The closest point of triangle (a, b, c) to p, with its barycentric weights in `bary`; also
/// when corners coincide (the triangle is then a segment or a point).
std::array<double, 3> closest_point_on_triangle(const std::array<double, 3>& p,
                                                const std::array<double, 3>& a,
                                                const std::array<double, 3>& b,
                                                const std::array<double, 3>& c, std::array<double, 3>& bary);

/// A closest-point acceleration structure over the triangles of a mesh (binary BVH of
/// axis-aligned boxes, median split on the longest axis, a few triangles per leaf).
/// Keeps a reference to nothing: positions and triangles are copied at construction.
class TriangleBvh {
 public:
  /// Builds the hierarchy. Triangles with indices out of range are a bug (CHECK); degenerate
  /// triangles are kept (their closest point is still well defined).
  explicit TriangleBvh(const TriangleMesh& mesh);

  struct Hit {
    TriId triangle;                 ///< invalid only for a mesh without triangles
    double distance = 0.0;          ///< Euclidean distance to the closest point
    std::array<double, 3> point{};  ///< the closest point on the mesh
    std::array<double, 3> bary{};   ///< its barycentric weights in `triangle`
  };

  /// The closest point on any triangle to `p`. Ties between triangles at the same distance go
  /// to the lower triangle index after a fixed traversal order, so the answer is deterministic.
  Hit closest(const std::array<double, 3>& p) const;

  std::size_t triangle_count() const { return tri_.size(); }

 private:
  struct Node {
    std::array<double, 3> lo, hi;
    std::uint32_t first = 0;  ///< leaf: first triangle slot; inner: left child (right = left + 1)
    std::uint32_t count = 0;  ///< triangles in a leaf, 0 for inner nodes
  };
  /// Corner positions per triangle slot, in leaf order so that a leaf's triangles are adjacent
  /// in memory; id_[slot] is the triangle's index in the mesh.
  std::vector<std::array<std::array<double, 3>, 3>> tri_;
  std::vector<std::uint32_t> id_;
  std::vector<Node> nodes_;
};

struct SurfaceSamplingOptions {
  /// Points drawn uniformly by area on top of every vertex (vertices are always samples, so a
  /// lost or moved vertex is never missed). 0 samples vertices only.
  std::size_t area_samples = 100000;
  std::uint64_t seed = 17;  ///< fixed: the same meshes give the same samples
};

/// A point on a mesh with the triangle it came from (for the face normal at the sample).
struct SurfaceSample {
  std::array<double, 3> point;
  TriId triangle;
  std::array<double, 3> bary;  ///< barycentric weights of `point` in `triangle`
};

/// The vertices of `mesh` that lie on a triangle (each with one of its triangles, the lowest
/// index), followed by options.area_samples points chosen with probability proportional to
/// triangle area by a fixed-seed generator. Empty when the mesh has no triangle of positive area
/// and no referenced vertex.
std::vector<SurfaceSample> sample_surface(const TriangleMesh& mesh, const SurfaceSamplingOptions& options);

/// Distances from the samples of one mesh to the other mesh.
struct OneSidedDistance {
  std::size_t samples = 0;
  double max = 0.0;                ///< one-sided Hausdorff distance (over the samples)
  double mean = 0.0;               ///< mean distance over the samples
  std::array<double, 3> max_at{};  ///< the sample realising `max` (first one on ties)
  /// Angle in degrees between the face normals of the sample's triangle and of the closest
  /// triangle, ignoring orientation when `oriented` was false: maximum and mean over samples.
  double normal_angle_max_deg = 0.0;
  double normal_angle_mean_deg = 0.0;
  /// Fraction of samples whose matched face normals point in opposite directions (angle > 90°).
  double flipped_fraction = 0.0;
};

/// Distances from every sample of `from` to the surface of `to` (`to_bvh` built from `to`).
/// Both meshes must have triangles (CHECK). Deterministic for any thread count.
OneSidedDistance one_sided_distance(const TriangleMesh& from, const std::vector<SurfaceSample>& samples,
                                    const TriangleMesh& to, const TriangleBvh& to_bvh);

struct MeshDistance {
  OneSidedDistance expected_to_actual, actual_to_expected;
  double hausdorff() const;  ///< symmetric: the larger one-sided maximum
  double mean() const;       ///< the larger one-sided mean
};

/// Symmetric distances between two meshes sampled with `options`. Both need triangles (CHECK).
MeshDistance mesh_distance(const TriangleMesh& expected, const TriangleMesh& actual,
                           const SurfaceSamplingOptions& options);

/// Axis-aligned bounding box of the vertices referenced by triangles (all vertices when there
/// are no triangles): {min, max}. Both are 0 for an empty mesh.
std::array<std::array<double, 3>, 2> bounding_box(const TriangleMesh& mesh);

/// Signed volume enclosed by the triangles (divergence theorem about the bounding box centre):
/// positive for a closed mesh whose triangles are counter-clockwise seen from outside, negative
/// when its handedness or orientation is reversed. Meaningful for closed meshes only.
double signed_volume(const TriangleMesh& mesh);

/// Total triangle area.
double surface_area(const TriangleMesh& mesh);

}  // namespace mlfe
