// Least-squares refit of a simplified surface to the surface it came from, with its
// connectivity fixed: Hoppe, DeRose, Duchamp, McDonald & Stuetzle, "Mesh optimization",
// SIGGRAPH 1993 (the E_dist + E_spring energy, minimised over vertex positions for fixed
// correspondences).
//
// A greedy simplifier places each merged vertex where the quadrics of the triangles it absorbed
// are least, one collapse at a time; the vertices that survive then sit where the order of the
// collapses left them, not where the whole surface fits the data best. One solve of the global
// least-squares problem moves them there: on the noisy full heads' asset it lowers the mean
// distance to the data's surface by 5-7 % for the same triangles (bench/RESULTS.md).
//
// Steps: match (each dense vertex to its closest point on the coarse surface), assemble (the
// normal equations of the data and spring terms, boundary vertices fixed), solve (conjugate
// gradients per axis, from the current positions), guard (put back the corners of triangles
// that would turn too far or leave a sample beyond the bound, until none does).
#include <mlfe/core/base/check.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/base/vec.h>
#include <mlfe/core/surface/mesh_distance.h>
#include <mlfe/core/surface/surface_fitting.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>

#include <Eigen/IterativeLinearSolvers>
#include <Eigen/SparseCore>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numeric>
#include <optional>
#include <string>
#include <vector>

namespace mlfe {
namespace {

// A dense vertex, its weight and where on the coarse surface it is matched.
struct Sample {
  Vec3 p;
  double weight = 0;  // a third of the area of its triangles
  std::uint32_t triangle = 0;
  Vec3 bary{};
  double distance = 0;  // to the matched point, before the fit
};

// The coarse triangles binned by their boxes into cubes of a fixed size. The dense vertices lie
// close to the coarse surface, so for most of them the triangles of their own cube hold the
// closest point, which a cube settles when it is nearer than the cube's walls; the rest ask the
// BVH. The same answer as the BVH's closest point (up to ties), several times faster.
class TriangleGrid {
 public:
  TriangleGrid(const TriangleMesh& m, double cell, double margin) : m_(m), cell_(cell), margin_(margin) {
    lo_ = to_vec3(m.positions[m.triangles[0][0]]);
    Vec3 hi = lo_;
    for (const auto& t : m.triangles)
      for (auto v : t)
        for (int c = 0; c < 3; ++c) {
          lo_[c] = std::min(lo_[c], double(m.positions[v][c]));
          hi[c] = std::max(hi[c], double(m.positions[v][c]));
        }
    for (int c = 0; c < 3; ++c) n_[c] = std::int64_t((hi[c] - lo_[c]) / cell_) + 1;
    // Counting sort of (cell, triangle) pairs into start_/tris_.
    start_.assign(std::size_t(n_[0] * n_[1] * n_[2]) + 1, 0);
    each_cell_pair([&](std::size_t cell, std::uint32_t) { ++start_[cell + 1]; });
    for (std::size_t i = 1; i < start_.size(); ++i) start_[i] += start_[i - 1];
    tris_.resize(start_.back());
    std::vector<std::uint32_t> fill(start_.begin(), start_.end() - 1);
    each_cell_pair([&](std::size_t cell, std::uint32_t t) { tris_[fill[cell]++] = t; });
  }

  // The closest point when the cube of p settles it: true with triangle, weights and distance.
  bool closest(const Vec3& p, std::uint32_t& tri, Vec3& bary, double& distance) const {
    std::int64_t at[3];
    double wall = std::numeric_limits<double>::infinity();
    for (int c = 0; c < 3; ++c) {
      const double u = (p[c] - lo_[c]) / cell_;
      at[c] = std::int64_t(std::floor(u));
      if (at[c] < 0 || at[c] >= n_[c]) return false;
      wall = std::min({wall, (u - double(at[c])) * cell_, (double(at[c] + 1) - u) * cell_});
    }
    const std::size_t cell = std::size_t((at[2] * n_[1] + at[1]) * n_[0] + at[0]);
    double best2 = std::numeric_limits<double>::infinity();
    for (std::uint32_t i = start_[cell]; i < start_[cell + 1]; ++i) {
      const std::uint32_t t = tris_[i];
      const auto& v = m_.triangles[t];
      Vec3 b;
      const Vec3 q = closest_point_on_triangle(p, to_vec3(m_.positions[v[0]]), to_vec3(m_.positions[v[1]]),
                                               to_vec3(m_.positions[v[2]]), b);
      const Vec3 d = sub(p, q);
      const double d2 = dot(d, d);
      if (d2 < best2 || (d2 == best2 && t < tri)) best2 = d2, tri = t, bary = b;
    }
    distance = std::sqrt(best2);
    return distance <= wall + margin_;
  }

  // A grid for points within `margin` of m: cubes of four margins hold a few triangles each at
  // asset tolerances; at most 16 cubes per triangle over the surface's box bound its memory.
  static TriangleGrid within(const TriangleMesh& m, double margin) {
    const auto box = bounding_box(m);
    double volume = 1;
    for (int c = 0; c < 3; ++c) volume *= std::max(box[1][c] - box[0][c], margin);
    return TriangleGrid(m, std::max(4 * margin, std::cbrt(volume / (16.0 * double(m.triangles.size())))),
                        margin);
  }

 private:
  template <class Visit>
  void each_cell_pair(Visit&& visit) const {
    for (std::uint32_t t = 0; t < m_.triangles.size(); ++t) {
      std::int64_t a[3], b[3];
      for (int c = 0; c < 3; ++c) {
        double lo = std::numeric_limits<double>::infinity(), hi = -lo;
        for (auto v : m_.triangles[t])
          lo = std::min(lo, double(m_.positions[v][c])), hi = std::max(hi, double(m_.positions[v][c]));
        a[c] =
            std::clamp(std::int64_t(std::floor((lo - margin_ - lo_[c]) / cell_)), std::int64_t(0), n_[c] - 1);
        b[c] =
            std::clamp(std::int64_t(std::floor((hi + margin_ - lo_[c]) / cell_)), std::int64_t(0), n_[c] - 1);
      }
      for (std::int64_t k = a[2]; k <= b[2]; ++k)
        for (std::int64_t j = a[1]; j <= b[1]; ++j)
          for (std::int64_t i = a[0]; i <= b[0]; ++i) visit(std::size_t((k * n_[1] + j) * n_[0] + i), t);
    }
  }

  const TriangleMesh& m_;
  double cell_, margin_;
  Vec3 lo_;
  std::int64_t n_[3];
  std::vector<std::uint32_t> start_, tris_;
};

// Step 1: every dense vertex on a triangle, with its area weight, matched to the closest point
// of the coarse surface (`grid` and `bvh` of its triangles).
std::vector<Sample> match(const TriangleMesh& dense, const TriangleGrid& grid, const TriangleBvh& bvh) {
  std::vector<double> weight(dense.positions.size(), 0.0);
  for (const auto& t : dense.triangles) {
    for (auto v : t) MLFE_CHECK(v < dense.positions.size());
    const Vec3 a = to_vec3(dense.positions[t[0]]), b = to_vec3(dense.positions[t[1]]),
               c = to_vec3(dense.positions[t[2]]);
    const Vec3 n = cross(sub(b, a), sub(c, a));
    const double third = norm(n) / 6.0;
    for (auto v : t) weight[v] += third;
  }
  std::vector<Sample> samples;
  for (std::size_t v = 0; v < dense.positions.size(); ++v)
    if (weight[v] > 0) samples.push_back({to_vec3(dense.positions[v]), weight[v]});

  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, samples.size(), 2048),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t i = r.begin(); i != r.end(); ++i) {
                        Sample& s = samples[i];
                        if (grid.closest(s.p, s.triangle, s.bary, s.distance)) continue;
                        const TriangleBvh::Hit h = bvh.closest(s.p);
                        s.triangle = h.triangle.value;
                        s.bary = h.bary;
                        s.distance = h.distance;
                      }
                    });
  return samples;
}

// The unique edges of a mesh (lower vertex first, sorted) and its boundary vertices, those on
// an edge of one triangle: they hold the surface to the volume's faces and stay.
struct Edges {
  std::vector<std::array<std::uint32_t, 2>> unique;
  std::vector<char> boundary;  // per vertex
};

Edges edges_of(const TriangleMesh& m) {
  std::vector<std::array<std::uint32_t, 2>> all;
  all.reserve(3 * m.triangles.size());
  for (const auto& t : m.triangles)
    for (int k = 0; k < 3; ++k)
      all.push_back({std::min(t[k], t[(k + 1) % 3]), std::max(t[k], t[(k + 1) % 3])});
  std::sort(all.begin(), all.end());
  Edges e;
  e.boundary.assign(m.positions.size(), 0);
  for (std::size_t i = 0; i < all.size();) {
    std::size_t j = i;
    while (j < all.size() && all[j] == all[i]) ++j;
    if (j - i == 1) e.boundary[all[i][0]] = e.boundary[all[i][1]] = 1;
    e.unique.push_back(all[i]);
    i = j;
  }
  return e;
}

// Steps 2 and 3: the normal equations of sum_s w_s |A_s x - p_s|^2 + k sum_(a,b) |x_a - x_b -
// (x0_a - x0_b)|^2 over the free vertices (boundary ones moved to the right-hand side), solved
// per axis by conjugate gradients from x0 (the current positions). Returns the new positions.
std::vector<Vec3> solve(const TriangleMesh& coarse, const std::vector<Sample>& samples,
                        const Edges& mesh_edges, const std::vector<Vec3>& x0, double spring) {
  const std::size_t n = x0.size();
  // Free vertices numbered 0..f-1.
  std::vector<int> slot(n, -1);
  int f = 0;
  for (std::size_t v = 0; v < n; ++v)
    if (!mesh_edges.boundary[v]) slot[v] = f++;
  if (f == 0) return x0;
  // The spring's weight is per unit of the data's area, so it means the same at any resolution.
  double area = 0;
  for (const auto& s : samples) area += s.weight;
  const auto& edges = mesh_edges.unique;
  const double k = spring * area / double(std::max<std::size_t>(1, edges.size()));
  // The data term couples the corners of each matched triangle only: summed per triangle
  // first (a 3x3 block and three right-hand sides), then scattered.
  std::vector<std::array<double, 9>> block(coarse.triangles.size(), std::array<double, 9>{});
  std::vector<std::array<double, 9>> side(coarse.triangles.size(), std::array<double, 9>{});
  for (const auto& s : samples) {
    auto& b = block[s.triangle];
    auto& r = side[s.triangle];
    for (int i = 0; i < 3; ++i) {
      const double wi = s.weight * s.bary[i];
      for (int j = 0; j < 3; ++j) b[3 * i + j] += wi * s.bary[j];
      for (int c = 0; c < 3; ++c) r[3 * i + c] += wi * s.p[c];
    }
  }
  std::vector<Eigen::Triplet<double>> entries;
  entries.reserve(9 * coarse.triangles.size() + 4 * edges.size());
  Eigen::MatrixXd rhs = Eigen::MatrixXd::Zero(f, 3);
  for (std::size_t t = 0; t < coarse.triangles.size(); ++t) {
    const auto& tri = coarse.triangles[t];
    for (int r = 0; r < 3; ++r) {
      const int i = slot[tri[r]];
      if (i < 0) continue;
      for (int c = 0; c < 3; ++c) rhs(i, c) += side[t][3 * r + c];
      for (int q = 0; q < 3; ++q) {
        const double a = block[t][3 * r + q];
        if (a == 0) continue;
        const int j = slot[tri[q]];
        if (j >= 0)
          entries.emplace_back(i, j, a);
        else
          for (int c = 0; c < 3; ++c) rhs(i, c) -= a * x0[tri[q]][c];
      }
    }
  }
  std::vector<std::array<double, 9>>().swap(block);
  std::vector<std::array<double, 9>>().swap(side);
  for (const auto& e : edges) {
    const int ia = slot[e[0]], ib = slot[e[1]];
    const Vec3 d = sub(x0[e[0]], x0[e[1]]);
    // k |x_a - x_b - d|^2: row a gets k (x_a - x_b) = k d, row b the negative.
    if (ia >= 0) {
      entries.emplace_back(ia, ia, k);
      if (ib >= 0) entries.emplace_back(ia, ib, -k);
      for (int c = 0; c < 3; ++c) rhs(ia, c) += k * d[c] + (ib < 0 ? k * x0[e[1]][c] : 0.0);
    }
    if (ib >= 0) {
      entries.emplace_back(ib, ib, k);
      if (ia >= 0) entries.emplace_back(ib, ia, -k);
      for (int c = 0; c < 3; ++c) rhs(ib, c) += -k * d[c] + (ia < 0 ? k * x0[e[0]][c] : 0.0);
    }
  }
  Eigen::SparseMatrix<double> m(f, f);
  m.setFromTriplets(entries.begin(), entries.end());
  std::vector<Eigen::Triplet<double>>().swap(entries);
  Eigen::ConjugateGradient<Eigen::SparseMatrix<double>, Eigen::Lower | Eigen::Upper> cg;
  // Relative residual 1e-6: positions to well below a thousandth of a voxel.
  cg.setTolerance(1e-6);
  cg.setMaxIterations(200);
  cg.compute(m);
  std::vector<Vec3> x = x0;
  for (int c = 0; c < 3; ++c) {
    Eigen::VectorXd guess(f);
    for (std::size_t v = 0; v < n; ++v)
      if (slot[v] >= 0) guess[slot[v]] = x0[v][c];
    const Eigen::VectorXd sol = cg.solveWithGuess(rhs.col(c), guess);
    for (std::size_t v = 0; v < n; ++v)
      if (slot[v] >= 0 && std::isfinite(sol[slot[v]])) x[v][c] = sol[slot[v]];
  }
  return x;
}

// The point of triangle t at barycentric weights b, with positions x.
Vec3 at(const std::vector<Vec3>& x, const std::array<std::uint32_t, 3>& t, const Vec3& b) {
  Vec3 p{};
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) p[c] += b[r] * x[t[r]][c];
  return p;
}

// Step 4: until nothing changes, the corners of every triangle that turns too far, and of
// every triangle a sample of which ends up beyond the bound, go back to x0. Returns how many
// vertices went back.
std::size_t guard(const TriangleMesh& coarse, const std::vector<Sample>& samples, const TriangleGrid& dense,
                  const std::vector<Vec3>& x0, std::vector<Vec3>& x, const SurfaceFitOptions& o) {
  const double min_cos = std::cos(o.max_normal_turn_degrees * M_PI / 180.0);
  const std::size_t nt = coarse.triangles.size(), nv = x.size();
  // Per triangle its samples and per vertex its triangles: after the first round only the
  // triangles around the vertices put back are looked at again.
  std::vector<std::uint32_t> by_tri(nt + 1, 0), tri_samples(samples.size()), by_vertex(nv + 1, 0),
      vertex_tris(3 * nt);
  for (const auto& s : samples) ++by_tri[s.triangle + 1];
  for (const auto& t : coarse.triangles)
    for (auto v : t) ++by_vertex[v + 1];
  std::partial_sum(by_tri.begin(), by_tri.end(), by_tri.begin());
  std::partial_sum(by_vertex.begin(), by_vertex.end(), by_vertex.begin());
  {
    std::vector<std::uint32_t> fill(by_tri.begin(), by_tri.end() - 1);
    for (std::uint32_t i = 0; i < samples.size(); ++i) tri_samples[fill[samples[i].triangle]++] = i;
    fill.assign(by_vertex.begin(), by_vertex.end() - 1);
    for (std::uint32_t t = 0; t < nt; ++t)
      for (auto v : coarse.triangles[t]) vertex_tris[fill[v]++] = t;
  }
  // A triangle that turns too far or leaves one of its samples beyond the bound.
  auto bad = [&](std::uint32_t ti) {
    const auto& t = coarse.triangles[ti];
    const Vec3 n0 = cross(sub(x0[t[1]], x0[t[0]]), sub(x0[t[2]], x0[t[0]]));
    const Vec3 n1 = cross(sub(x[t[1]], x[t[0]]), sub(x[t[2]], x[t[0]]));
    const double l0 = dot(n0, n0), l1 = dot(n1, n1);
    if (!(l1 > 0 && dot(n0, n1) >= min_cos * std::sqrt(l0 * l1)) && !(l0 == 0 && l1 == 0)) return true;
    for (std::uint32_t k = by_tri[ti]; k < by_tri[ti + 1]; ++k) {
      const Sample& s = samples[tri_samples[k]];
      if (distance(at(x, t, s.bary), s.p) > std::max(o.tolerance, s.distance)) return true;
    }
    return false;
  };
  std::size_t count = 0;
  std::vector<std::uint32_t> reverted;
  auto put_back = [&](std::uint32_t v) {
    if (x[v] == x0[v]) return;
    x[v] = x0[v], ++count;
    reverted.push_back(v);
  };
  // Round 1, flags computed in parallel on one state and applied in order: the bound the other
  // way (a moved vertex within the tolerance of the dense surface, as the simplifier's optimal
  // placement keeps it; it depends on the vertex alone), then every triangle.
  std::vector<char> flag(std::max(nv, nt), 0);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nv, 4096),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t v = r.begin(); v != r.end(); ++v) {
                        std::uint32_t tri = 0;
                        Vec3 bary;
                        double d = 0;
                        flag[v] = x[v] != x0[v] && !(dense.closest(x[v], tri, bary, d) && d <= o.tolerance);
                      }
                    });
  for (std::uint32_t v = 0; v < nv; ++v)
    if (flag[v]) put_back(v);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nt, 4096),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t t = r.begin(); t != r.end(); ++t) flag[t] = bad(std::uint32_t(t));
                    });
  for (std::uint32_t t = 0; t < nt; ++t)
    if (flag[t])
      for (auto v : coarse.triangles[t]) put_back(v);
  // Later rounds: the triangles around the vertices the round before put back, in order.
  std::vector<std::uint32_t> around;
  while (!reverted.empty()) {
    around.clear();
    for (auto v : reverted)
      around.insert(around.end(), vertex_tris.begin() + by_vertex[v], vertex_tris.begin() + by_vertex[v + 1]);
    reverted.clear();
    std::sort(around.begin(), around.end());
    around.erase(std::unique(around.begin(), around.end()), around.end());
    for (auto t : around)
      if (bad(t))
        for (auto v : coarse.triangles[t]) put_back(v);
  }
  return count;
}

double rms(const std::vector<Sample>& samples, const TriangleMesh& coarse, const std::vector<Vec3>* x) {
  double sum = 0, w = 0;
  for (const auto& s : samples) {
    const double d = x ? distance(at(*x, coarse.triangles[s.triangle], s.bary), s.p) : s.distance;
    sum += s.weight * d * d, w += s.weight;
  }
  return w > 0 ? std::sqrt(sum / w) : 0.0;
}

}  // namespace

SurfaceFitReport fit_surface(TriangleMesh& coarse, const TriangleMesh& dense, const SurfaceFitOptions& o) {
  if (!(o.tolerance > 0) || !std::isfinite(o.tolerance))
    throw Error("surface fit: tolerance must be positive and finite (got " + std::to_string(o.tolerance) +
                ")");
  SurfaceFitReport report;
  if (coarse.triangles.empty() || dense.triangles.empty()) return report;
  for (const auto& t : coarse.triangles)
    for (auto v : t) MLFE_CHECK(v < coarse.positions.size());
  // The searches the steps need, built at once (each is a sequential pass over its mesh). The
  // simplifier kept the dense vertices within the tolerance of the coarse surface: triangles
  // binned with that margin settle almost every match in the vertex's own cube; the guard
  // looks for moved vertices near the dense surface the same way.
  std::optional<TriangleGrid> coarse_grid, dense_grid;
  std::optional<TriangleBvh> coarse_bvh;
  tbb::parallel_invoke([&] { coarse_grid.emplace(TriangleGrid::within(coarse, o.tolerance)); },
                       [&] { coarse_bvh.emplace(coarse); },
                       [&] { dense_grid.emplace(TriangleGrid::within(dense, o.tolerance)); });
  const std::vector<Sample> samples = match(dense, *coarse_grid, *coarse_bvh);
  report.samples = samples.size();
  std::vector<Vec3> x0(coarse.positions.size());
  for (std::size_t v = 0; v < x0.size(); ++v) x0[v] = to_vec3(coarse.positions[v]);
  std::vector<Vec3> x = solve(coarse, samples, edges_of(coarse), x0, o.spring);
  // Positions are stored as floats: the guard checks what will be written.
  for (auto& p : x)
    for (auto& c : p) c = double(float(c));
  report.kept = guard(coarse, samples, *dense_grid, x0, x, o);
  report.rms_before = rms(samples, coarse, nullptr);
  report.rms_after = rms(samples, coarse, &x);
  for (std::size_t v = 0; v < x.size(); ++v) {
    if (x[v] == x0[v]) continue;
    ++report.moved;
    coarse.positions[v] = {float(x[v][0]), float(x[v][1]), float(x[v][2])};
  }
  return report;
}

}  // namespace mlfe
