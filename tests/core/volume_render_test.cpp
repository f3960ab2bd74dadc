// Ray casting on the tetrahedral hierarchy: no lost rays through vertices, along edges and in
// faces; analytic transmittance; exactness on linear fields across levels; empty-space
// skipping; the same image with 1 and 2 threads; the renderer's memory per tetrahedron.
#include <gtest/gtest.h>
#include <mlfe/core/render/volume_render.h>
#include <tbb/global_control.h>

#include <cmath>
#include <cstring>
#include <set>

#include "tests/core/test_hierarchies.h"
#include "tests/tet_meshes.h"

namespace mlfe {
namespace {

using Vec3 = std::array<double, 3>;

Hierarchy<3> lattice_box() {  // [0,1]^3, vertices on the lattice (1/4) Z^3, plus adaptive corner
  Hierarchy<3> h = Hierarchy<3>::box({0, 0, 0}, {1, 1, 1});
  h.refine_uniform();
  h.refine_uniform();
  return test::refine_toward_origin(std::move(h), 1);
}

TEST(TraceRay, NoLostRaysThroughVerticesEdgesAndFaces) {
  const Hierarchy<3> h = lattice_box();
  const std::vector<double> u(h.vertex_count(), 1.0);
  const TetRenderMesh m(h, u);
  const double s3 = 1 / std::sqrt(3.0);
  // Axis-aligned both ways, and the cube's main diagonal (an edge of every Kuhn tetrahedron
  // around it). Pixel centres on the (1/8) lattice: through vertices, along edges, inside
  // faces, and in the box's own faces (grazing).
  const Vec3 dirs[] = {{1, 0, 0},  {0, 1, 0},  {0, 0, 1},    {-1, 0, 0},
                       {0, -1, 0}, {0, 0, -1}, {s3, s3, s3}, {-s3, -s3, -s3}};
  std::size_t rays = 0, segments = 0;
  for (const Vec3& d : dirs) {
    int ax = 0;
    while (std::abs(d[ax]) < 0.5 && ax < 2) ++ax;
    const bool diag = std::abs(d[0]) < 0.9 && std::abs(d[0]) > 0.1;
    for (int i = 0; i <= 8; ++i)
      for (int j = 0; j <= 8; ++j) {
        Vec3 o;
        if (diag) {
          const Vec3 p{i / 8.0, j / 8.0, d[2] > 0 ? 0.0 : 1.0};
          o = {p[0] - 2 * d[0], p[1] - 2 * d[1], p[2] - 2 * d[2]};
        } else {
          const int a1 = (ax + 1) % 3, a2 = (ax + 2) % 3;
          o[ax] = d[ax] > 0 ? -1.0 : 2.0;
          o[a1] = i / 8.0;
          o[a2] = j / 8.0;
        }
        std::set<std::int32_t> seen;
        double sum = 0, last = -1;
        bool repeated = false, gap = false;
        const TraceResult r = trace_ray(m, o, d, nullptr, [&](const TraceSegment& s) {
          repeated |= !seen.insert(s.tet).second;
          if (last >= 0) gap |= s.t0 != last;
          last = s.t1;
          sum += s.t1 - s.t0;
          return true;
        });
        const double c = test::box_chord(m.box_lo(), m.box_hi(), o, d);
        if (c == 0) continue;
        ++rays;
        segments += seen.size();
        ASSERT_TRUE(r.hit);
        EXPECT_FALSE(r.step_bound_hit) << "o=" << o[0] << "," << o[1] << "," << o[2];
        EXPECT_EQ(r.relocations, 0u);
        EXPECT_FALSE(repeated) << "a tetrahedron visited twice, o=" << o[0] << "," << o[1] << "," << o[2];
        EXPECT_FALSE(gap);
        EXPECT_NEAR(sum, c, 1e-6 * c)
            << "o=" << o[0] << "," << o[1] << "," << o[2] << " d=" << d[0] << "," << d[1];
        EXPECT_NEAR(last, r.t_far, 1e-9);
      }
  }
  EXPECT_GT(rays, 500u);
  EXPECT_GT(segments, rays);
}

TEST(RenderMesh, ConstantOpacityGivesAnalyticTransmittanceIncludingGrazingRays) {
  const Hierarchy<3> h = lattice_box();
  const std::vector<double> u(h.vertex_count(), 2.0);
  const TetRenderMesh m(h, u);
  TransferFunction tf;
  tf.color = {{0, 1, 1, 1}};
  tf.opacity = {{0, 0.4}};
  tf.unit_length = 0.5;
  const GridTransform identity;
  RenderOptions opt;
  opt.stop_opacity = 1.0;
  // Lattice-aligned orthographic view (pixel centres on the box faces: grazing) and an oblique
  // perspective one.
  Camera ortho;
  ortho.width = ortho.height = 9;
  ortho.ortho_height = 9.0 / 8.0;
  ortho.position = {0.5, 0.5, 3};
  ortho.target = {0.5, 0.5, 0.5};
  ortho.up = {0, 1, 0};
  Camera persp = orbit_camera({0.5, 0.5, 0.5}, 0.87, 33, 21, true, 40, 30);
  for (const Camera& cam : {ortho, persp}) {
    const RenderImage img = render_mesh(m, identity, tf, cam, opt);
    for (int y = 0; y < cam.height; ++y)
      for (int x = 0; x < cam.width; ++x) {
        Vec3 o, d;
        cam.ray(x, y, o, d);
        const double expected = 1 - std::pow(1 - 0.4, test::box_chord(m.box_lo(), m.box_hi(), o, d) / 0.5);
        EXPECT_NEAR(img.rgba[4 * (y * cam.width + x) + 3], expected, 1e-5) << x << "," << y;
      }
  }
}

TEST(RenderMesh, LinearFieldGivesTheSameImageOnEveryLevel) {
  Hierarchy<3> h = Hierarchy<3>::box({0, 0, 0}, {2, 1, 1.5});
  h.refine_uniform();
  h = test::refine_toward_origin(std::move(h), 2);
  std::vector<double> u(h.vertex_count());
  for (std::size_t v = 0; v < u.size(); ++v) {
    const auto& p = h.point(VertexId(std::uint32_t(v)));
    u[v] = 3 * p[0] - 2 * p[1] + p[2] + 1;
  }
  TransferFunction tf;  // linear over the whole range [-1, 8.5]: one piece
  tf.color = {{-1, 0.1, 0.2, 0.3}, {8.5, 0.9, 0.5, 0.1}};
  tf.opacity = {{-1, 0.05}, {8.5, 0.5}};
  tf.unit_length = 0.3;
  const Camera cam = orbit_camera({1, 0.5, 0.75}, 1.35, 40, 25, true, 48, 40);
  RenderOptions opt;
  opt.stop_opacity = 1.0;
  opt.rule = RayAccumulator::Rule::kExact;
  const TetRenderMesh fine(h, u), coarse(h, u, 0);
  ASSERT_EQ(coarse.size(), 6u);
  ASSERT_GT(fine.size(), 200u);
  RenderStats sf, sc;
  const RenderImage a = render_mesh(fine, GridTransform{}, tf, cam, opt, &sf);
  const RenderImage b = render_mesh(coarse, GridTransform{}, tf, cam, opt, &sc);
  EXPECT_GT(sf.segments, 2 * sc.segments);
  double max_alpha = 0;
  for (std::size_t i = 0; i < a.rgba.size(); ++i) {
    EXPECT_NEAR(a.rgba[i], b.rgba[i], 2e-6) << i;
    if (i % 4 == 3) max_alpha = std::max(max_alpha, double(a.rgba[i]));
  }
  EXPECT_GT(max_alpha, 0.5);
  // The tabulated mean transmittance (the default): the same opacity, colours within 1e-4 on
  // both levels, though each splits the rays differently.
  opt.rule = RayAccumulator::Rule::kPreIntegrated;
  const RenderImage ta = render_mesh(fine, GridTransform{}, tf, cam, opt);
  const RenderImage tb = render_mesh(coarse, GridTransform{}, tf, cam, opt);
  for (std::size_t i = 0; i < a.rgba.size(); ++i) {
    const double tol = i % 4 == 3 ? 2e-6 : 1e-4;
    EXPECT_NEAR(ta.rgba[i], a.rgba[i], tol) << i;
    EXPECT_NEAR(tb.rgba[i], a.rgba[i], tol) << i;
  }
}

// A radial field with a transparent band: skipping must not change the image.
struct Blob {
  Hierarchy<3> h = Hierarchy<3>::box({0, 0, 0}, {1, 1, 1});
  std::vector<double> u;
  Blob() {
    for (int k = 0; k < 4; ++k) h.refine_uniform();
    u.resize(h.vertex_count());
    for (std::size_t v = 0; v < u.size(); ++v) {
      const auto& p = h.point(VertexId(std::uint32_t(v)));
      u[v] = 1 - std::sqrt(std::pow(p[0] - 0.45, 2) + std::pow(p[1] - 0.5, 2) + std::pow(p[2] - 0.55, 2));
    }
  }
};

TEST(RenderMesh, EmptySpaceSkippingKeepsTheImage) {
  const Blob b;
  const TetRenderMesh m(b.h, b.u);
  TransferFunction tf;
  tf.color = {{0.6, 1, 0.5, 0.2}, {1, 1, 1, 1}};
  tf.opacity = {{0.6, 0}, {0.7, 0.3}, {1, 0.8}};
  tf.unit_length = 0.05;
  const Camera cam = orbit_camera({0.5, 0.5, 0.5}, 0.87, 20, 30, false, 40, 40);
  RenderOptions with, without;
  with.skip_levels = 1;  // the blob has 4 levels: let ancestors be crossed too
  without.skip_empty = false;
  RenderStats sw, so;
  const RenderImage a = render_mesh(m, GridTransform{}, tf, cam, with, &sw);
  const RenderImage c = render_mesh(m, GridTransform{}, tf, cam, without, &so);
  EXPECT_GT(sw.skips, 0u);
  EXPECT_LT(sw.segments, so.segments);
  EXPECT_EQ(sw.step_bound_hits + so.step_bound_hits, 0u);
  for (std::size_t i = 0; i < a.rgba.size(); ++i) EXPECT_NEAR(a.rgba[i], c.rgba[i], 1e-6) << i;
}

TEST(RenderMesh, SameBytesWithOneAndTwoThreads) {
  const Blob b;
  const TetRenderMesh m(b.h, b.u);
  TransferFunction tf = transfer_function_preset("hot", 0.3, 1, 0.05);
  const Camera cam = orbit_camera({0.5, 0.5, 0.5}, 0.87, 70, -10, true, 64, 48);
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

// The renderer's neighbours (StepRecord::next) against the hierarchy's own face_neighbors on
// T_level of h: the same elements across every face, and the shared face's index in the
// neighbour pointing back.
void expect_adjacency_of_face_neighbors(const Hierarchy<3>& h, const std::vector<double>& u, int level) {
  const TetRenderMesh m(h, u, level);
  const auto elems = level < 0 || level >= h.max_level() ? h.leaves() : h.level_elements(level);
  const auto expected = h.face_neighbors(elems);
  ASSERT_EQ(expected.size(), m.size());
  // The renderer keeps the elements in its own (spatial) order: compare through the elements.
  std::vector<std::int32_t> position(h.element_count(), -1);
  for (std::size_t i = 0; i < elems.size(); ++i) position[elems[i].value] = std::int32_t(i);
  std::set<std::uint32_t> seen;
  for (std::uint32_t r = 0; r < m.size(); ++r) {
    const std::int32_t i = position[m.element(r).value];
    ASSERT_GE(i, 0) << "element " << r << " is not in T_" << level;
    EXPECT_TRUE(seen.insert(m.element(r).value).second) << "element rendered twice";
    EXPECT_EQ(m.render_index(m.element(r)), std::int32_t(r));
    for (int f = 0; f < 4; ++f) {
      const std::int32_t n = m.neighbors(r)[f], e = expected[std::size_t(i)][f];
      ASSERT_EQ(n < 0, e < 0) << r << " face " << f;
      if (n < 0) continue;
      EXPECT_EQ(m.element(std::uint32_t(n)), elems[std::size_t(e)]) << r << " face " << f;
      const std::uint32_t next = m.record(r).next[f];
      EXPECT_EQ(m.record(next >> 2).next[next & 3u], 4 * r + std::uint32_t(f)) << r << " face " << f;
    }
  }
}

// The step records computed at every step instead of stored are the same bytes: so is the
// image, with either thread count.
TEST(RenderMesh, StoredAndComputedStepRecordsGiveTheSameImage) {
  const Blob b;
  const TransferFunction tf = transfer_function_preset("hot", 0.3, 1, 0.05);
  const Camera cam = orbit_camera({0.5, 0.5, 0.5}, 0.87, 70, -10, true, 64, 48);
  RenderImage img[3];
  for (int k = 0; k < 3; ++k) {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, k == 2 ? 1 : 2);
    const TetRenderMesh m(b.h, b.u);
    RenderOptions opt;
    opt.shading = true;
    opt.records = k == 0 ? RenderOptions::Records::kStore : RenderOptions::Records::kCompute;
    RenderStats s;
    img[k] = render_mesh(m, GridTransform{}, tf, cam, opt, &s);
    EXPECT_EQ(s.records_stored, k == 0);
    EXPECT_EQ(m.records_built() > 0, k == 0);
    EXPECT_GT(s.segments, 0u);
  }
  for (int k = 1; k < 3; ++k) {
    ASSERT_EQ(img[0].rgba.size(), img[k].rgba.size());
    EXPECT_EQ(0, std::memcmp(img[0].rgba.data(), img[k].rgba.data(), img[0].rgba.size() * sizeof(float)));
    EXPECT_EQ(0, std::memcmp(img[0].z.data(), img[k].z.data(), img[0].z.size() * sizeof(float)));
  }
}

// kAuto stores the step records only where they are reused: not for a small image over many
// elements, but for the same with many images to come, or for a large image.
TEST(RenderMesh, AutoStoresStepRecordsWhereTheyAreReused) {
  const Blob b;
  const TransferFunction tf = transfer_function_preset("grey", 0, 1, 0.05);
  const auto cam = [](int size) { return orbit_camera({0.5, 0.5, 0.5}, 0.87, 30, 20, false, size, size); };
  RenderStats s;
  {
    const TetRenderMesh m(b.h, b.u);  // 24 576 leaves: a 16x16 image crosses few of them
    render_mesh(m, GridTransform{}, tf, cam(16), RenderOptions{}, &s);
    EXPECT_FALSE(s.records_stored);
    EXPECT_EQ(m.records_built(), 0u);
    RenderOptions turntable;
    turntable.images = 1000;
    render_mesh(m, GridTransform{}, tf, cam(16), turntable, &s);
    EXPECT_TRUE(s.records_stored);
    EXPECT_GT(m.records_built(), 0u);
    render_mesh(m, GridTransform{}, tf, cam(16), RenderOptions{}, &s);  // all built: used
    EXPECT_EQ(s.records_stored, m.records_built() == m.size());
  }
  {
    const TetRenderMesh m(b.h, b.u);
    render_mesh(m, GridTransform{}, tf, cam(400), RenderOptions{}, &s);
    EXPECT_TRUE(s.records_stored);
    EXPECT_EQ(m.records_built(), m.size());  // built up front for a large image
  }
}

TEST(RenderMesh, CompactAdjacency) {
  const Blob b;
  const TetRenderMesh m(b.h, b.u);
  // Neighbours (16 bytes), render order and value ranges (ancestors' included); the 128-byte
  // step records only once built.
  EXPECT_LE(double(m.memory_bytes()) / double(m.size()), 40.0);
  m.build_all_records();
  EXPECT_EQ(m.records_built(), m.size());
  EXPECT_LE(double(m.memory_bytes()) / double(m.size()), 165.0);
  for (int level : {-1, 1, 2, 3}) {
    SCOPED_TRACE(level);
    expect_adjacency_of_face_neighbors(b.h, b.u, level);
  }
  // Graded (green closures across several levels) and on a lattice.
  const Hierarchy<3> g = lattice_box();
  const std::vector<double> ug(g.vertex_count(), 1.0);
  for (int level : {-1, 2, 3}) {
    SCOPED_TRACE(level);
    expect_adjacency_of_face_neighbors(g, ug, level);
  }
}

TEST(RenderGrid, MatchesTheMeshOnTrilinearData) {
  // A linear function sampled on voxels is reproduced exactly by trilinear interpolation and
  // by the P1 mesh, so the reference and the mesh images agree.
  ScalarGrid g;
  g.dims = {9, 9, 9};
  g.transform.spacing = {0.125, 0.125, 0.125};
  for (int k = 0; k < 9; ++k)
    for (int j = 0; j < 9; ++j)
      for (int i = 0; i < 9; ++i) g.values.push_back(float(i + 0.5 * j - 0.25 * k));
  Hierarchy<3> h = Hierarchy<3>::box({0, 0, 0}, {1, 1, 1});
  h.refine_uniform();
  std::vector<double> u(h.vertex_count());
  for (std::size_t v = 0; v < u.size(); ++v) {
    const auto& p = h.point(VertexId(std::uint32_t(v)));
    u[v] = 8 * p[0] + 4 * p[1] - 2 * p[2];
  }
  TransferFunction tf;
  tf.color = {{-2, 0, 0.3, 1}, {4, 1, 0.7, 0}};
  tf.opacity = {{-2, 0.02}, {2, 0.3}, {4, 0.1}};
  tf.unit_length = 0.1;
  const Camera cam = orbit_camera({0.5, 0.5, 0.5}, 0.87, 15, 35, true, 32, 32);
  RenderOptions opt;
  const RenderImage a = render_grid(g, tf, cam, opt);
  const RenderImage b = render_mesh(TetRenderMesh(h, u), GridTransform{}, tf, cam, opt);
  for (std::size_t i = 0; i < a.rgba.size(); ++i) EXPECT_NEAR(a.rgba[i], b.rgba[i], 1e-5) << i;
}

}  // namespace
}  // namespace mlfe
