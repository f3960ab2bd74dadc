#include <gtest/gtest.h>
#include <mlfe/core/fem/approximation.h>
#include <mlfe/core/fem/bpx.h>
#include <mlfe/core/fem/fe_assembly.h>
#include <mlfe/core/fem/hierarchical_basis.h>
#include <mlfe/core/field/field.h>
#include <tbb/global_control.h>

#include <cmath>
#include <functional>
#include <random>

#include "tests/core/test_hierarchies.h"

namespace mlfe {
namespace {

constexpr double kPi = 3.14159265358979323846;

ScalarGrid make_grid(int dim, int n, double spacing, const std::function<double(double, double, double)>& f) {
  ScalarGrid g;
  g.dim = dim;
  g.dims = {n, n, dim == 3 ? n : 1};
  g.transform.spacing = {spacing, spacing * 1.25, spacing};  // anisotropic on purpose
  g.values.resize(static_cast<std::size_t>(g.voxel_count()));
  for (std::int64_t k = 0; k < g.dims[2]; ++k)
    for (std::int64_t j = 0; j < g.dims[1]; ++j)
      for (std::int64_t i = 0; i < g.dims[0]; ++i)
        g.values[i + g.dims[0] * (j + g.dims[1] * k)] =
            float(f(i * g.transform.spacing[0], j * g.transform.spacing[1], k * g.transform.spacing[2]));
  return g;
}

template <int D>
typename Hierarchy<D>::Point pt(double v) {
  typename Hierarchy<D>::Point p;
  p.fill(v);
  return p;
}

template <int D>
Hierarchy<D> box_for(const Field& f) {
  typename Hierarchy<D>::Point lo, hi;
  for (int a = 0; a < D; ++a) {
    lo[a] = 0;
    hi[a] = f.extent()[a];
  }
  return Hierarchy<D>::box(lo, hi);
}

template <int D>
double l2_error(const Hierarchy<D>& h, const Field& f, const std::vector<double>& u) {
  const auto leaves = h.leaves();
  const auto in = compute_element_integrals<D>(h, leaves, f, f.resolution(), nullptr);
  Vector uv = Eigen::Map<const Vector>(u.data(), u.size());
  const auto err = element_errors(h, leaves, in, uv, 0.0);
  double s = 0;
  for (double e : err) s += e;
  return std::sqrt(s);
}

template <int D>
double l2_norm(const Hierarchy<D>& h, const Field& f) {  // ∫ f²
  const auto leaves = h.leaves();
  double s = 0;
  for (const auto& in : compute_element_integrals<D>(h, leaves, f, f.resolution(), nullptr)) s += in.f2;
  return s;
}

TEST(Approximation, LinearFunctionIsReproducedExactlyOnT0) {
  for (int dim : {2, 3}) {
    // Small values keep ∫f² moderate; linear data is interpolated exactly by the grid.
    const auto g =
        make_grid(dim, 9, 0.5, [](double x, double y, double z) { return 1.5 + 2 * x - 0.75 * y + 0.5 * z; });
    GridField f(g);
    ApproximationOptions o;
    if (dim == 2) {
      auto h = box_for<2>(f);
      const auto u = solve_best_approximation<2>(h, f, o, {});
      for (std::size_t v = 0; v < h.vertex_count(); ++v) {
        const auto& p = h.point(VertexId(v));
        EXPECT_NEAR(u[v], f.value({p[0], p[1], 0}), 1e-10 * 10);
      }
      // E is a difference of O(||f||²) terms, so its square root resolves ~1e-8 ||f||.
      EXPECT_LE(l2_error(h, f, u), 1e-7 * std::sqrt(l2_norm(h, f)));
    } else {
      auto h = box_for<3>(f);
      const auto u = solve_best_approximation<3>(h, f, o, {});
      for (std::size_t v = 0; v < h.vertex_count(); ++v) {
        const auto& p = h.point(VertexId(v));
        EXPECT_NEAR(u[v], f.value({p[0], p[1], p[2]}), 1e-10 * 10);
      }
      EXPECT_LE(l2_error(h, f, u), 1e-7 * std::sqrt(l2_norm(h, f)));
    }
  }
}

TEST(Approximation, GalerkinOrthogonalityHoldsToSolverTolerance) {
  const auto g = make_grid(3, 33, 1.0, [](double x, double y, double z) {
    return std::exp(-((x - 12) * (x - 12) + (y - 20) * (y - 20) + (z - 15) * (z - 15)) / 40.0) * 100;
  });
  GridField f(g);
  auto h = box_for<3>(f);
  h.refine_uniform();
  h.refine_uniform();
  // Local refinement makes the hierarchy non-trivial for BPX.
  std::vector<ElemId> marked;
  for (ElemId e : h.leaves())
    if (h.point(h.cell(e)[0])[0] < 16) marked.push_back(e);
  h.refine(marked);
  ApproximationOptions o;
  o.direct_solve_max = 0;  // force CG + BPX
  o.cg_tolerance = 1e-10;
  IterationStats st;
  const auto u = solve_best_approximation<3>(h, f, o, {}, &st);
  EXPECT_GT(st.cg_iterations, 0);
  const auto leaves = h.leaves();
  // The same discrete integrals as the solver (default quadrature size: 2 voxels).
  const auto in = compute_element_integrals<3>(h, leaves, f, 2.0 * f.voxel_size(), nullptr);
  const SparseMatrix m = assemble_matrix(h, leaves, 0.0);
  const Vector rhs = assemble_load(h, leaves, in, 0.0);
  const Vector uv = Eigen::Map<const Vector>(u.data(), u.size());
  const Vector r = rhs - m * uv;  // (f - u, φ_i) for every i
  EXPECT_LE(r.norm(), 1e-9 * rhs.norm());

  // The solver reads a per-element cache in place (IntegralIndex::kElementId): scattered by
  // element id, the same integrals must give the same load and errors bit for bit.
  std::vector<ElementIntegrals<3>> by_id(h.element_count());
  for (std::size_t i = 0; i < leaves.size(); ++i) by_id[leaves[i].value] = in[i];
  const Vector rhs_by_id = assemble_load(h, leaves, by_id, 0.0, IntegralIndex::kElementId);
  EXPECT_TRUE(rhs_by_id == rhs);
  EXPECT_EQ(element_errors(h, leaves, by_id, uv, 0.0, IntegralIndex::kElementId),
            element_errors(h, leaves, in, uv, 0.0));
}

TEST(Approximation, UniformRefinementConvergesWithRateTwo) {
  for (int dim : {2, 3}) {
    const int n = dim == 2 ? 257 : 65;
    const double s = 1.0 / (n - 1);
    const auto g = make_grid(dim, n, s, [](double x, double y, double z) {
      return std::sin(kPi * x) * std::cos(0.8 * kPi * y) + 0.5 * std::sin(1.5 * kPi * z);
    });
    GridField f(g);
    ApproximationOptions o;
    std::vector<double> errs;
    if (dim == 2) {
      auto h = box_for<2>(f);
      h.refine_uniform();
      for (int l = 2; l <= 5; ++l) {
        h.refine_uniform();
        errs.push_back(l2_error(h, f, solve_best_approximation<2>(h, f, o, {})));
      }
    } else {
      auto h = box_for<3>(f);
      h.refine_uniform();
      for (int l = 2; l <= 4; ++l) {
        h.refine_uniform();
        errs.push_back(l2_error(h, f, solve_best_approximation<3>(h, f, o, {})));
      }
    }
    for (std::size_t i = 1; i < errs.size(); ++i) {
      const double rate = std::log2(errs[i - 1] / errs[i]);
      EXPECT_NEAR(rate, 2.0, 0.2) << "dim " << dim << " level step " << i;
    }
  }
}

// u at x if leaf e contains x, else NaN.
double eval_u_in(const Hierarchy<3>& h, ElemId e, const std::vector<double>& u,
                 const std::array<double, 3>& x) {
  const auto& c = h.cell(e);
  const auto lam = test::barycentric(h, e, x);
  if (std::min({lam[0], lam[1], lam[2], lam[3]}) < -1e-12) return std::nan("");
  double v = 0;
  for (int i = 0; i < 4; ++i) v += lam[i] * u[c[i].value];
  return v;
}

TEST(Approximation, ReportedErrorMatchesBruteForceVoxelSum) {
  const auto g = make_grid(3, 25, 1.0, [](double x, double y, double z) {
    return 50 + 40 * std::exp(-((x - 9) * (x - 9) + (y - 14) * (y - 14) + (z - 11) * (z - 11)) / 30.0);
  });
  GridField f(g);
  ApproximationOptions o;
  o.start_level = 1;
  o.target_rms = 1.0;
  o.lattice = false;  // the continuous L2 norm (unstructured input); the lattice: sample_lattice_test
  const auto a = approximate<3>(f, o);
  const auto& st = a.iterations.back();
  // Brute force: (f - u)² at the centres of a lattice 5x finer than the voxels (midpoint
  // rule; sampling only the voxel centres is biased by ~h²|∇(f-u)|²/12, which is 5-30% for
  // elements a few voxels wide), each point located in its leaf by a barycentric test.
  const auto leaves = a.hierarchy.leaves();
  const auto& h = a.hierarchy;
  const int sub = 5;
  const std::array<double, 3> sp{1.0, 1.25, 1.0};
  const std::array<int, 3> np{24 * sub, 24 * sub, 24 * sub};
  std::vector<std::uint8_t> seen(std::size_t(np[0]) * np[1] * np[2], 0);
  double sum = 0;
  for (ElemId e : leaves) {
    const auto& c = h.cell(e);
    std::array<int, 3> lo, hi;
    for (int k = 0; k < 3; ++k) {
      double mn = 1e9, mx = -1e9;
      for (VertexId v : c) {
        mn = std::min(mn, h.point(v)[k]);
        mx = std::max(mx, h.point(v)[k]);
      }
      lo[k] = std::max(0, int(std::floor(mn / sp[k] * sub - 0.5)));
      hi[k] = std::min(np[k] - 1, int(std::ceil(mx / sp[k] * sub - 0.5)));
    }
    for (int k = lo[2]; k <= hi[2]; ++k)
      for (int j = lo[1]; j <= hi[1]; ++j)
        for (int i = lo[0]; i <= hi[0]; ++i) {
          const std::size_t idx = i + std::size_t(np[0]) * (j + std::size_t(np[1]) * k);
          if (seen[idx]) continue;
          const std::array<double, 3> x{(i + 0.5) / sub * sp[0], (j + 0.5) / sub * sp[1],
                                        (k + 0.5) / sub * sp[2]};
          const double uv = eval_u_in(h, e, a.values, x);
          if (std::isnan(uv)) continue;
          seen[idx] = 1;
          const double d = f.value(x) - uv;
          sum += d * d;
        }
  }
  for (auto s : seen) ASSERT_TRUE(s);
  sum *= sp[0] * sp[1] * sp[2] / (sub * sub * sub);
  const double brute = std::sqrt(sum);
  EXPECT_NEAR(st.l2_error, brute, 0.02 * brute) << "estimate " << st.l2_error << " brute force " << brute;
}

// On the samples' lattice the reported error is the samples' own: Σ_s w (f_s − u(x_s))², each
// sample located in a leaf by a barycentric test.
TEST(Approximation, ReportedErrorOnTheLatticeIsTheSampleSum) {
  const auto g = make_grid(3, 25, 1.0, [](double x, double y, double z) {
    return 50 + 40 * std::exp(-((x - 9) * (x - 9) + (y - 14) * (y - 14) + (z - 11) * (z - 11)) / 30.0);
  });
  GridField f(g);
  ApproximationOptions o;
  o.target_rms = 1.0;
  const auto a = approximate<3>(f, o);
  ASSERT_TRUE(a.on_lattice);
  const auto& st = a.iterations.back();
  const auto leaves = a.hierarchy.leaves();
  std::vector<std::array<double, 6>> box(leaves.size());
  for (std::size_t l = 0; l < leaves.size(); ++l) {
    box[l] = {1e300, 1e300, 1e300, -1e300, -1e300, -1e300};
    for (VertexId v : a.hierarchy.cell(leaves[l]))
      for (int c = 0; c < 3; ++c) {
        box[l][c] = std::min(box[l][c], a.hierarchy.point(v)[c]);
        box[l][c + 3] = std::max(box[l][c + 3], a.hierarchy.point(v)[c]);
      }
  }
  double sum = 0;
  for (std::int64_t k = 0; k < g.dims[2]; ++k)
    for (std::int64_t j = 0; j < g.dims[1]; ++j)
      for (std::int64_t i = 0; i < g.dims[0]; ++i) {
        const std::array<double, 3> x{i * g.transform.spacing[0], j * g.transform.spacing[1],
                                      k * g.transform.spacing[2]};
        double uv = std::nan("");
        for (std::size_t l = 0; l < leaves.size() && std::isnan(uv); ++l) {
          bool in = true;
          for (int c = 0; c < 3; ++c) in = in && x[c] >= box[l][c] - 1e-9 && x[c] <= box[l][c + 3] + 1e-9;
          if (in) uv = eval_u_in(a.hierarchy, leaves[l], a.values, x);
        }
        ASSERT_FALSE(std::isnan(uv));
        const double d = g.at(i, j, k) - uv;
        sum += d * d;
      }
  const double brute =
      std::sqrt(sum * g.transform.spacing[0] * g.transform.spacing[1] * g.transform.spacing[2]);
  EXPECT_NEAR(st.l2_error, brute, 1e-6 * brute);
  EXPECT_NEAR(st.rms_error, brute / std::sqrt(a.domain_measure), 1e-6 * st.rms_error);
}

TEST(Approximation, SmallFeatureInsideOneCoarseElementIsFoundAndRefined) {
  // A bright ball of radius 2 voxels in a dark 33³ volume; T0's 6 tetrahedra are ~30 voxels
  // across, so a point-sampling rule would step right over it.
  const std::array<double, 3> c{21.3, 9.7, 12.2};
  const auto g = make_grid(3, 33, 1.0, [&](double x, double y, double z) {
    const double r =
        std::sqrt((x - c[0]) * (x - c[0]) + (y - c[1] * 1.25) * (y - c[1] * 1.25) + (z - c[2]) * (z - c[2]));
    return r <= 2.0 ? 100.0 : 0.0;
  });
  GridField f(g);
  ApproximationOptions o;
  o.start_level = 0;
  o.target_rms = 0.5;
  o.max_level = 8;
  const auto a = approximate<3>(f, o);
  const auto& h = a.hierarchy;
  int level_at_ball = 0, max_level_far = 0;
  for (ElemId e : h.leaves()) {
    double lo[3] = {1e9, 1e9, 1e9}, hi[3] = {-1e9, -1e9, -1e9};
    for (VertexId v : h.cell(e))
      for (int k = 0; k < 3; ++k) {
        lo[k] = std::min(lo[k], h.point(v)[k]);
        hi[k] = std::max(hi[k], h.point(v)[k]);
      }
    const std::array<double, 3> cc{c[0], c[1] * 1.25, c[2]};
    double d2 = 0;
    for (int k = 0; k < 3; ++k) {
      const double t = std::max({lo[k] - cc[k], cc[k] - hi[k], 0.0});
      d2 += t * t;
    }
    if (d2 <= 4.0) level_at_ball = std::max(level_at_ball, h.level(e));
    if (d2 > 225.0) max_level_far = std::max(max_level_far, h.level(e));
  }
  std::printf("stop: %s, leaves %zu, level at ball %d, far %d, rms %g -> %g\n", a.stop_reason.c_str(),
              h.leaves().size(), level_at_ball, max_level_far, a.iterations.front().rms_error,
              a.iterations.back().rms_error);
  EXPECT_GE(level_at_ball, 5);
  // The L2 projection of a step rings for a few element layers, so refinement reaches a few
  // voxels beyond the ball, but no further, and stays a small fraction of uniform refinement.
  EXPECT_LT(max_level_far, level_at_ball);
  EXPECT_LT(h.leaves().size(), 6u * (1u << (3 * level_at_ball)) / 10);
  EXPECT_LT(a.iterations.back().rms_error, a.iterations.front().rms_error * 0.5);
}

template <int D>
int pcg_iterations(const Hierarchy<D>& h, double gw, Preconditioner p) {
  const auto leaves = h.leaves();
  const SparseMatrix m = assemble_matrix(h, leaves, gw);
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> U(-1, 1);
  Vector b(m.rows());
  for (Eigen::Index i = 0; i < b.size(); ++i) b[i] = U(rng);
  SparseOperator a(m);
  std::unique_ptr<LinearOperator> pre;
  if (p == Preconditioner::kBpx)
    pre = std::make_unique<BpxPreconditioner<D>>(h, gw);
  else
    pre = std::make_unique<IdentityOperator>(m.rows());
  Vector x = Vector::Zero(m.rows());
  const auto r = conjugate_gradient(a, *pre, b, x, 1e-8, 20000);
  EXPECT_TRUE(r.converged);
  return r.iterations;
}

TEST(Bpx, IterationCountsStayBoundedFromTwoToTenLevels) {
  // Local refinement toward a corner region: levels 2..10.
  Hierarchy<3> h = Hierarchy<3>::box(pt<3>(0), pt<3>(1));
  h.refine_uniform();
  std::vector<int> bpx_l2, bpx_h1, cg_h1;
  for (int level = 2; level <= 10; ++level) {
    // Elements meeting a ball that shrinks with the level around (0.31, 0.17, 0.23): a
    // graded mesh with a few hundred new elements per level.
    const double r = 0.6 / (1 << (level - 1));
    std::vector<ElemId> marked;
    for (ElemId e : h.leaves()) {
      double d2 = 0;
      const std::array<double, 3> c{0.31, 0.17, 0.23};
      for (int k = 0; k < 3; ++k) {
        double lo = 1e9, hi = -1e9;
        for (VertexId v : h.cell(e)) {
          lo = std::min(lo, h.point(v)[k]);
          hi = std::max(hi, h.point(v)[k]);
        }
        const double t = std::max({lo - c[k], c[k] - hi, 0.0});
        d2 += t * t;
      }
      if (d2 <= r * r) marked.push_back(e);
    }
    h.refine(marked);
    ASSERT_EQ(h.max_level(), level);
    const double s2 = 1.0 / 64 / 64;  // gradient weight as for a 64-voxel volume
    bpx_l2.push_back(pcg_iterations(h, 0.0, Preconditioner::kBpx));
    bpx_h1.push_back(pcg_iterations(h, s2 * 64 * 64, Preconditioner::kBpx));
    cg_h1.push_back(pcg_iterations(h, s2 * 64 * 64, Preconditioner::kNone));
  }
  for (std::size_t i = 0; i < bpx_l2.size(); ++i) {
    std::printf("levels %zu: BPX-CG L2 %d, BPX-CG H1 %d, CG H1 %d\n", i + 2, bpx_l2[i], bpx_h1[i], cg_h1[i]);
    EXPECT_LE(bpx_l2[i], 40);
    EXPECT_LE(bpx_h1[i], 40);
  }
  // Plain CG in H1 degrades with the level count.
  EXPECT_GT(cg_h1.back(), 2 * cg_h1.front());
  EXPECT_GT(cg_h1.back(), 2 * bpx_h1.back());
}

TEST(Approximation, ThresholdLoopTerminatesWithMonotoneErrorAndIsThreadIndependent) {
  const auto g = make_grid(3, 33, 1.0, [](double x, double y, double z) {
    return 100 *
           std::tanh((std::sqrt((x - 16) * (x - 16) + (y - 18) * (y - 18) + (z - 14) * (z - 14)) - 9) / 1.5);
  });
  GridField f(g);
  auto run = [&](int threads) {
    tbb::global_control gc(tbb::global_control::max_allowed_parallelism, threads);
    ApproximationOptions o;
    o.threshold = 4.0;
    o.start_level = 0;
    o.direct_solve_max = 500;  // exercise BPX-CG too
    return approximate<3>(f, o);
  };
  const auto a = run(1);
  const auto b = run(2);
  ASSERT_GE(a.iterations.size(), 3u);
  EXPECT_EQ(a.stop_reason, "no element above the threshold");
  for (std::size_t i = 1; i < a.iterations.size(); ++i)
    EXPECT_LE(a.iterations[i].l2_error, a.iterations[i - 1].l2_error * (1 + 1e-12));
  ASSERT_EQ(a.values.size(), b.values.size());
  for (std::size_t i = 0; i < a.values.size(); ++i) ASSERT_EQ(a.values[i], b.values[i]);
  ASSERT_EQ(a.iterations.back().l2_error, b.iterations.back().l2_error);
}

TEST(Approximation, VertexBudgetIsNeverExceeded) {
  const auto g = make_grid(
      2, 129, 1.0, [](double x, double y, double) { return std::sin(x / 7.0) * std::cos(y / 5.0) * 50; });
  GridField f(g);
  ApproximationOptions o;
  o.target_rms = 1e-3;
  o.max_vertices = 700;
  o.start_level = 0;
  const auto a = approximate<2>(f, o);
  EXPECT_LE(a.hierarchy.vertex_count(), 700u);
  EXPECT_GT(a.hierarchy.vertex_count(), 350u);
  EXPECT_EQ(a.stop_reason, "vertex budget");
}

TEST(Approximation, TheBudgetIsReachedInTwoStepsWithASolveBetween) {
  // A sharp edge plus smooth variation: more marks than the budget holds.
  const auto g = make_grid(2, 129, 1.0, [](double x, double y, double) {
    return (std::hypot(x - 60, y - 70) < 35 ? 80.0 : 0.0) + 10 * std::sin(x / 9.0);
  });
  GridField f(g);
  ApproximationOptions o;
  o.target_rms = 1e-3;
  o.max_vertices = 3000;
  o.start_level = 0;
  const auto a = approximate<2>(f, o);
  EXPECT_EQ(a.stop_reason, "vertex budget");
  // The first refinement that takes a large share of the room (the budget cuts it) leaves a
  // good part of it to a refinement after one more solve (one ranking spent 97 % at once here).
  const std::size_t budget = o.max_vertices;
  bool cut = false;
  for (std::size_t i = 0; i + 1 < a.iterations.size() && !cut; ++i) {
    const std::size_t before = a.iterations[i].vertices, after = a.iterations[i + 1].vertices;
    if (after - before <= (budget - before) / 3) continue;
    cut = true;
    EXPECT_GE(budget - after, (budget - before) / 10) << "iteration " << i;
  }
  EXPECT_TRUE(cut);
  EXPECT_GE(a.hierarchy.vertex_count(), budget * 95 / 100);
  EXPECT_LE(a.hierarchy.vertex_count(), budget);
}

TEST(HierarchicalBasis, DecompositionRoundTripsAndTruncationInterpolates) {
  const auto g =
      make_grid(3, 17, 1.0, [](double x, double y, double z) { return std::sin(x / 3) + y * z / 50; });
  GridField f(g);
  ApproximationOptions o;
  o.start_level = 1;
  o.target_rms = 0.01;
  o.max_level = 4;
  const auto a = approximate<3>(f, o);
  const auto& h = a.hierarchy;
  const auto s = hierarchical_decompose(h, a.values);
  const auto back = hierarchical_reconstruct(h, s, 99);
  for (std::size_t v = 0; v < back.size(); ++v) ASSERT_NEAR(back[v], a.values[v], 1e-12);
  for (int k = 0; k < h.max_level(); ++k) {
    const auto uk = hierarchical_reconstruct(h, s, k);
    for (std::size_t v = 0; v < uk.size(); ++v) {
      const VertexId id(v);
      if (h.vertex_level(id) <= k) {
        ASSERT_NEAR(uk[v], a.values[v], 1e-12);  // nodal values of T_k are kept
      } else {
        const auto& p = h.vertex_parents(id);
        ASSERT_NEAR(uk[v], 0.5 * (uk[p[0].value] + uk[p[1].value]), 1e-12);  // linear on T_k
      }
    }
  }
  // Coarser levels approximate worse.
  EXPECT_GT(l2_error(h, f, hierarchical_reconstruct(h, s, 1)), l2_error(h, f, a.values));
}

}  // namespace
}  // namespace mlfe
