// Ray casting an unstructured tetrahedral mesh as its own finest level (RayEntry::
// kBoundaryFaces): rays that leave a non-convex mesh and re-enter it get both parts (against
// the analytic chord), no ray is lost through boundary vertices and edges, the image equals the
// hierarchy renderer's on the same tetrahedra (camera outside and inside, with and without
// empty-space skipping), the same bytes with 1 and 2 threads, non-conforming meshes rejected.
#include <gtest/gtest.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/render/volume_render.h>
#include <tbb/global_control.h>

#include <cmath>
#include <cstring>

#include "tests/tet_meshes.h"

namespace mlfe {
namespace {

using Vec3 = std::array<double, 3>;

// The unit cube without the column x, y > 0.5 (the Poisson cut corner, extruded along z).
bool in_column(const Vec3& c) { return c[0] > 0.5 && c[1] > 0.5; }
const Vec3 kLo{0, 0, 0}, kHi{1, 1, 1}, kColLo{0.5, 0.5, 0}, kColHi{1, 1, 1};

double l_chord(const Vec3& o, const Vec3& d) {
  return test::box_chord(kLo, kHi, o, d) - test::box_chord(kColLo, kColHi, o, d);
}

TransferFunction constant_opacity(double alpha, double unit) {
  TransferFunction tf;
  tf.color = {{0, 1, 1, 1}};
  tf.opacity = {{0, alpha}};
  tf.unit_length = unit;
  return tf;
}

TEST(UnstructuredRender, RayLeavingAndReenteringGetsBothParts) {
  const TetMesh mesh = test::kuhn_mesh(
      8, [](const Vec3&) { return 1.0; }, in_column);
  const Hierarchy<3> h = test::coarse_hierarchy(mesh);
  const TetRenderMesh m(h, mesh.values, -1, nullptr, RayEntry::kBoundaryFaces);
  // Squares of 1/8 on the boundary: 48 on top and bottom, 64 on x = 0 and y = 0, 32 on x = 1
  // and y = 1, 32 on each wall of the cut; two triangles each.
  EXPECT_EQ(m.boundary_face_count(), 2u * (2 * 48 + 2 * 64 + 2 * 32 + 2 * 32));
  // One ray by hand: from (0.2, 1) toward (1, 0.2) at z = 0.3, through the material, the
  // column and the material again.
  const double s = 1 / std::sqrt(2.0);
  const Vec3 o{0.2 - 0.5 * s, 1 + 0.5 * s, 0.3}, d{s, -s, 0};
  double inside = 0;
  int pieces = 0;
  double last = -1;
  const TraceResult r = trace_ray(m, o, d, nullptr, [&](const TraceSegment& seg) {
    if (seg.t0 != last) ++pieces;
    last = seg.t1;
    inside += seg.t1 - seg.t0;
    return true;
  });
  EXPECT_EQ(r.reentries, 1u);
  EXPECT_EQ(pieces, 2);
  EXPECT_FALSE(r.step_bound_hit);
  EXPECT_NEAR(inside, l_chord(o, d), 1e-9);
  EXPECT_NEAR(inside, 2 * 0.3 * std::sqrt(2.0), 1e-9);
  // Whole images against the analytic transmittance 1 − (1 − a)^(chord / unit): an oblique
  // view across the column (many rays re-enter) and a perspective one.
  const TransferFunction tf = constant_opacity(0.3, 0.25);
  RenderOptions opt;
  opt.stop_opacity = 1.0;
  const Camera across = orbit_camera({0.5, 0.5, 0.5}, 0.87, 225, 12, false, 48, 40);
  const Camera persp = orbit_camera({0.5, 0.5, 0.5}, 0.87, 200, 35, true, 40, 30);
  for (const Camera& cam : {across, persp}) {
    RenderStats st;
    const RenderImage img = render_mesh(m, GridTransform{}, tf, cam, opt, &st);
    EXPECT_EQ(st.step_bound_hits, 0u);
    for (int y = 0; y < cam.height; ++y)
      for (int x = 0; x < cam.width; ++x) {
        Vec3 ro, rd;
        cam.ray(x, y, ro, rd);
        const double c = l_chord(ro, rd);
        const double expected = 1 - std::pow(1 - 0.3, c / 0.25);
        EXPECT_NEAR(img.rgba[4 * (y * cam.width + x) + 3], expected, 1e-5) << x << "," << y;
      }
    EXPECT_GT(st.reentries, 0u);
  }
}

TEST(UnstructuredRender, NoRayLostThroughBoundaryVerticesAndEdges) {
  // Rays along the axes on the (1/8) lattice enter through boundary vertices and edges of the
  // Kuhn faces; inside the material each one must cross its whole chord. Rays in the cut's own
  // faces (x or y = 0.5 over the column) graze the boundary: either answer is right there.
  const TetMesh mesh = test::kuhn_mesh(
      8, [](const Vec3&) { return 1.0; }, in_column);
  const Hierarchy<3> h = test::coarse_hierarchy(mesh);
  const TetRenderMesh m(h, mesh.values, -1, nullptr, RayEntry::kBoundaryFaces);
  const Vec3 dirs[] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {-1, 0, 0}, {0, -1, 0}, {0, 0, -1}};
  int rays = 0;
  for (const Vec3& d : dirs) {
    int ax = 0;
    while (std::abs(d[ax]) < 0.5) ++ax;
    for (int i = 0; i <= 8; ++i)
      for (int j = 0; j <= 8; ++j) {
        Vec3 o;
        o[ax] = d[ax] > 0 ? -1.0 : 2.0;
        o[(ax + 1) % 3] = i / 8.0;
        o[(ax + 2) % 3] = j / 8.0;
        double sum = 0;
        const TraceResult r = trace_ray(m, o, d, nullptr, [&](const TraceSegment& seg) {
          sum += seg.t1 - seg.t0;
          return true;
        });
        EXPECT_FALSE(r.step_bound_hit);
        // In the plane of a wall of the cut, and meeting the wall (y or x above 0.5 somewhere).
        const bool on_cut_wall = (o[0] == 0.5 && ax != 0 && (ax == 1 || o[1] >= 0.5)) ||
                                 (o[1] == 0.5 && ax != 1 && (ax == 0 || o[0] >= 0.5));
        const double c = l_chord(o, d);
        if (on_cut_wall) {
          EXPECT_TRUE(std::abs(sum - c) < 1e-9 || std::abs(sum - test::box_chord(kLo, kHi, o, d)) < 1e-9)
              << sum;
          continue;
        }
        ++rays;
        EXPECT_NEAR(sum, c, 1e-9) << "o=" << o[0] << "," << o[1] << "," << o[2] << " axis " << ax;
      }
  }
  EXPECT_GT(rays, 400);
}

// A smooth field on a uniformly refined box hierarchy, and its leaves as an unstructured mesh.
struct SameTetrahedra {
  Hierarchy<3> h = Hierarchy<3>::box({0, 0, 0}, {1, 0.8, 0.6});
  std::vector<double> u;
  TetMesh mesh;
  Hierarchy<3> coarse;
  SameTetrahedra() {
    h.refine_uniform();
    h.refine_uniform();
    h.refine_uniform();
    for (const auto& p : h.points()) u.push_back(std::sin(3 * p[0]) * std::cos(2 * p[1]) + p[2] * p[2]);
    mesh = leaf_mesh(h, u);
    coarse = test::coarse_hierarchy(mesh);
  }
};

TEST(UnstructuredRender, SameImageAsTheHierarchyRendererOnTheSameTetrahedra) {
  const SameTetrahedra s;
  const TetRenderMesh by_hierarchy(s.h, s.u);
  const TetRenderMesh by_boundary(s.coarse, s.mesh.values, -1, nullptr, RayEntry::kBoundaryFaces);
  ASSERT_EQ(by_hierarchy.size(), by_boundary.size());
  const TransferFunction tf = transfer_function_preset("bone", -1, 1.4, 0.05);
  Camera inside = orbit_camera({0.5, 0.4, 0.3}, 0.8, 30, 20, true, 32, 24);
  inside.position = {0.3, 0.2, 0.25};  // in the mesh
  const Camera cams[] = {orbit_camera({0.5, 0.4, 0.3}, 0.8, 30, 20, true, 40, 32),
                         orbit_camera({0.5, 0.4, 0.3}, 0.8, 250, -40, false, 36, 36), inside};
  for (const Camera& cam : cams)
    for (bool skip : {true, false}) {
      RenderOptions opt;
      opt.skip_empty = skip;
      opt.shading = true;
      RenderStats sa, sb;
      const RenderImage a = render_mesh(by_hierarchy, GridTransform{}, tf, cam, opt, &sa);
      const RenderImage b = render_mesh(by_boundary, GridTransform{}, tf, cam, opt, &sb);
      EXPECT_EQ(sb.step_bound_hits, 0u);
      EXPECT_EQ(sb.reentries, 0u);  // convex
      double alpha = 0;
      for (std::size_t i = 0; i < a.rgba.size(); ++i) {
        ASSERT_NEAR(a.rgba[i], b.rgba[i], 2e-5) << "pixel " << i / 4 << " skip " << skip;
        alpha += a.rgba[i];
      }
      EXPECT_GT(alpha, 1.0);  // not a blank image
    }
}

TEST(UnstructuredRender, SameBytesWithOneAndTwoThreads) {
  const TetMesh mesh = test::kuhn_mesh(10, test::poisson_u, in_column);
  const Hierarchy<3> h = test::coarse_hierarchy(mesh);
  const TetRenderMesh m(h, mesh.values, -1, nullptr, RayEntry::kBoundaryFaces);
  const TransferFunction tf = transfer_function_preset("hot", 0, 0.8, 0.1);
  const Camera cam = orbit_camera({0.5, 0.5, 0.5}, 0.87, 215, 25, true, 64, 48);
  RenderOptions opt;
  opt.shading = true;
  RenderImage img[2];
  for (int t = 1; t <= 2; ++t) {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, t);
    img[t - 1] = render_mesh(m, GridTransform{}, tf, cam, opt);
  }
  ASSERT_EQ(img[0].rgba.size(), img[1].rgba.size());
  EXPECT_EQ(0, std::memcmp(img[0].rgba.data(), img[1].rgba.data(), img[0].rgba.size() * sizeof(float)));
  EXPECT_EQ(0, std::memcmp(img[0].z.data(), img[1].z.data(), img[0].z.size() * sizeof(float)));
}

TEST(UnstructuredRender, RejectsAFaceSharedByThreeTetrahedra) {
  TetMesh mesh = test::kuhn_mesh(2, [](const Vec3& p) { return p[0]; });
  mesh.tets.push_back(mesh.tets[3]);  // the same tetrahedron twice
  const Hierarchy<3> h = test::coarse_hierarchy(mesh);
  try {
    TetRenderMesh m(h, mesh.values, -1, nullptr, RayEntry::kBoundaryFaces);
    FAIL() << "accepted a non-conforming mesh";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("more than two tetrahedra"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace mlfe
