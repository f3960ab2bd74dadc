// P1 (barycentric) interpolation of point values on a tetrahedral mesh as the input function
// f, so mlfe reduces irregular grids (finite-element solutions, .vtu / .msh) the way it
// reduces voxel volumes. Points are located with a uniform bucket grid over the tetrahedra's
// bounding boxes (a few tetrahedra per bucket); outside the mesh, the closest boundary face
// comes from a bounding-volume tree of the boundary faces.
//
// Domain: the mesh's axis-aligned bounding box, as the local frame [0, extent] with the box's
// lower corner at 0 (origin() gives it, for GridTransform::origin). The hierarchy covers the
// whole box, so f must be defined where the mesh is not (a cut corner, a curved boundary):
// there f is the value at the closest point of the mesh. That extension is continuous, keeps
// the mesh's value range, and is constant along the normal to the boundary, so it adds no
// detail the approximation would spend elements on; the L2 error it counts there is the
// error against that extension.
#pragma once
#include <mlfe/core/field/field.h>
#include <mlfe/core/mesh/hierarchy.h>

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

namespace mlfe {

/// A tetrahedral mesh with one scalar per point: what the .vtu and .msh readers return.
struct TetMesh {
  std::vector<std::array<double, 3>> points;
  std::vector<std::array<std::int32_t, 4>> tets;  ///< indices into points
  std::vector<double> values;                     ///< one per point
  std::string value_name;                         ///< the point-data array the values came from
  std::string source;                             ///< the file it came from (for messages)
};

/// The leaves of `h` with one value per vertex of `h` (`values`, in VertexId order), so that a
/// TetMeshField evaluates the hierarchy's piecewise-linear function at any point of its box.
TetMesh leaf_mesh(const Hierarchy<3>& h, const std::vector<double>& values);

/// f on the mesh's bounding box (see the file comment). Holds its own copy of what it needs;
/// const member functions are thread-safe. Throws mlfe::Error ("<source>: ...") when the mesh
/// has no tetrahedron of positive volume, values do not match the points, an index is out of
/// range, a coordinate or value is not finite, or the box is flat along an axis. Tetrahedra of
/// zero volume are left out.
class TetMeshField final : public Field {
 public:
  explicit TetMeshField(const TetMesh& mesh);
  ~TetMeshField() override;

  int dim() const override { return 3; }
  double value(const std::array<double, 3>& x) const override;
  void values(const std::array<double, 3>* x, double* out, std::size_t n) const override;
  /// The gradient of the tetrahedron containing x, or of the one holding the closest point
  /// of the mesh outside it.
  std::array<double, 3> gradient(const std::array<double, 3>& x) const override;
  void gradients(const std::array<double, 3>* x, std::array<double, 3>* out, std::size_t n) const override;
  std::array<double, 3> extent() const override { return extent_; }
  /// The 10th percentile of the edge lengths: graded meshes keep their fine part (a median would
  /// be the coarse bulk's), and a few slivers or tiny boundary elements do not set it.
  double resolution() const override { return resolution_; }
  /// The 10th percentile of (6 |T|)^(1/3) over the tetrahedra: the element size measure marking
  /// uses (a Kuhn tetrahedron of a cube of side h has size h).
  double voxel_size() const override { return voxel_size_; }
  std::array<double, 2> range() const override { return range_; }
  /// From the buckets' value ranges, widened by the closest-point extension (built on the first
  /// call, thread-safe).
  std::array<double, 2> range_in_box(const std::array<double, 3>& lo,
                                     const std::array<double, 3>& hi) const override;

  /// The physical position of local 0: the box's lower corner.
  const std::array<double, 3>& origin() const { return origin_; }
  /// Tetrahedra used (positive volume) and left out (zero volume).
  std::size_t tet_count() const { return tets_.size(); }
  std::size_t degenerate_count() const { return degenerate_; }
  /// Whether x (local frame) lies in a tetrahedron of the mesh (within rounding).
  bool inside(const std::array<double, 3>& x) const;

 private:
  struct Tet {
    std::array<double, 3> p0;
    std::array<double, 9> inv;   // rows: ∇λ1, ∇λ2, ∇λ3
    std::array<double, 3> grad;  // ∇f
    double v0;                   // f(p0)
    std::array<std::int32_t, 4> vertex;
  };
  struct Hit {
    std::uint32_t tet;
    std::array<double, 3> at;  // the point of the mesh f is taken at
  };
  Hit locate(const std::array<double, 3>& x) const;
  std::int64_t cell_of(const std::array<double, 3>& x, std::int64_t c[3]) const;
  void build_ranges() const;

  std::vector<std::array<double, 3>> points_;  // local frame
  std::vector<Tet> tets_;
  std::size_t degenerate_ = 0;
  std::array<double, 3> origin_{0, 0, 0}, extent_{0, 0, 0};
  double resolution_ = 0, voxel_size_ = 0;
  std::array<double, 2> range_{0, 0};
  // Buckets: cell (i, j, k) lists the tetrahedra whose bounding box overlaps it, in index
  // order (cell_start_ as in CSR).
  std::array<std::int64_t, 3> n_{1, 1, 1};
  std::array<double, 3> cell_size_{1, 1, 1}, inv_cell_{1, 1, 1};
  std::vector<std::uint32_t> cell_start_, cell_tets_;
  // The boundary faces (face `face` of tetrahedron `tet`, on no other tetrahedron), in a
  // bounding-volume tree for the closest-point search outside the mesh.
  struct BoundaryFace {
    std::uint32_t tet;
    std::uint8_t face;
  };
  struct FaceTree;
  struct ClosestFace;
  std::vector<BoundaryFace> boundary_;
  std::unique_ptr<FaceTree> faces_;
  struct RangePyramid;
  mutable std::once_flag ranges_once_;
  mutable std::unique_ptr<RangePyramid> ranges_;
};

}  // namespace mlfe
