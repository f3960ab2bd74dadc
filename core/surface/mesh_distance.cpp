#include <mlfe/core/base/check.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/base/vec.h>
#include <mlfe/core/surface/mesh_distance.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <optional>
#include <random>

#include "base/morton.h"

namespace mlfe {
namespace {

double box_distance2(const Vec3& lo, const Vec3& hi, const Vec3& p) {
  double d2 = 0;
  for (int k = 0; k < 3; ++k) {
    const double d = std::max(std::max(lo[k] - p[k], 0.0), p[k] - hi[k]);
    d2 += d * d;
  }
  return d2;
}

constexpr std::uint32_t kLeafSize = 4;

/// Interpolated unit normal at barycentric `bary` of triangle t (vertex normals), or the
/// zero vector when the interpolation cancels out.
Vec3 interpolated_normal(const TriangleMesh& m, std::uint32_t t, const Vec3& bary) {
  const auto& tri = m.triangles[t];
  Vec3 n{0, 0, 0};
  for (int c = 0; c < 3; ++c) n = add(n, scale(to_vec3(m.normals[tri[c]]), bary[c]));
  const double len = norm(n);
  return len > 0 ? scale(n, 1.0 / len) : Vec3{0, 0, 0};
}

/// Sample indices sorted by the Morton code of their point on a 1024^3 grid over their box
/// (ties by index, so the order is unique).
std::vector<std::uint32_t> morton_order(const std::vector<SurfaceSample>& samples) {
  std::vector<std::uint32_t> order(samples.size());
  std::iota(order.begin(), order.end(), 0u);
  if (samples.empty()) return order;
  Vec3 lo = samples[0].point, hi = lo;
  for (const auto& s : samples)
    for (int k = 0; k < 3; ++k) {
      lo[k] = std::min(lo[k], s.point[k]);
      hi[k] = std::max(hi[k], s.point[k]);
    }
  std::vector<std::uint32_t> code(samples.size());
  for (std::size_t i = 0; i < samples.size(); ++i) {
    std::uint32_t c = 0;
    for (int k = 0; k < 3; ++k) {
      const double extent = hi[k] - lo[k];
      const double q = extent > 0 ? (samples[i].point[k] - lo[k]) / extent * 1023.0 : 0.0;
      c |= detail::spread_bits(std::uint32_t(std::clamp(q, 0.0, 1023.0))) << k;
    }
    code[i] = c;
  }
  std::sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) {
    return code[a] < code[b] || (code[a] == code[b] && a < b);
  });
  return order;
}

}  // namespace

// Ericson, Real-Time Collision Detection 5.1.5: the region tests avoid a division for the
// common vertex/edge cases. An edge's divisor is its squared length, so an edge region is only
// taken for an edge of positive length: a zero-length edge (two corners that coincide, as
// Draco's quantization makes them) would otherwise give 0/0, and the NaN distance would lose
// every comparison in TriangleBvh::closest, hiding the triangle. The remaining tests then find
// the closest point on the other edges.
Vec3 closest_point_on_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c, Vec3& bary) {
  const Vec3 ab = sub(b, a), ac = sub(c, a), ap = sub(p, a);
  const double d1 = dot(ab, ap), d2 = dot(ac, ap);
  if (d1 <= 0 && d2 <= 0) {
    bary = {1, 0, 0};
    return a;
  }
  const Vec3 bp = sub(p, b);
  const double d3 = dot(ab, bp), d4 = dot(ac, bp);
  if (d3 >= 0 && d4 <= d3) {
    bary = {0, 1, 0};
    return b;
  }
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0 && d1 > d3) {
    const double v = d1 / (d1 - d3);
    bary = {1 - v, v, 0};
    return add(a, scale(ab, v));
  }
  const Vec3 cp = sub(p, c);
  const double d5 = dot(ab, cp), d6 = dot(ac, cp);
  if (d6 >= 0 && d5 <= d6) {
    bary = {0, 0, 1};
    return c;
  }
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0 && d2 > d6) {
    const double w = d2 / (d2 - d6);
    bary = {1 - w, 0, w};
    return add(a, scale(ac, w));
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0 && (d4 - d3) + (d5 - d6) > 0) {
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    bary = {0, 1 - w, w};
    return add(b, scale(sub(c, b), w));
  }
  const double denom = va + vb + vc;
  if (!(denom > 0)) {  // degenerate triangle whose corners tests above did not catch
    bary = {1, 0, 0};
    return a;
  }
  const double v = vb / denom, w = vc / denom;
  bary = {1 - v - w, v, w};
  return add(a, add(scale(ab, v), scale(ac, w)));
}

TriangleBvh::TriangleBvh(const TriangleMesh& mesh) {
  const std::size_t nt = mesh.triangles.size();
  std::vector<std::array<float, 3>> centroid(nt);
  for (std::size_t t = 0; t < nt; ++t)
    for (int k = 0; k < 3; ++k) {
      double c = 0;
      for (int i = 0; i < 3; ++i) {
        const std::uint32_t v = mesh.triangles[t][i];
        MLFE_CHECK(v < mesh.positions.size());
        c += mesh.positions[v][k];
      }
      centroid[t][k] = float(c / 3.0);
    }
  id_.resize(nt);
  std::iota(id_.begin(), id_.end(), 0u);
  if (nt == 0) return;
  nodes_.reserve(2 * (nt / kLeafSize + 1));

  // Step 1: top-down split of triangle ranges at the median centroid along the longest axis of
  // the centroids' box (nth_element with an index tie-break is deterministic). Children are
  // stored next to each other and after their parent.
  struct Task {
    std::uint32_t node, begin, end;
  };
  std::vector<Task> stack;
  nodes_.push_back({});
  stack.push_back({0, 0, std::uint32_t(nt)});
  while (!stack.empty()) {
    const Task task = stack.back();
    stack.pop_back();
    Node& node = nodes_[task.node];
    if (task.end - task.begin <= kLeafSize) {
      node.first = task.begin;
      node.count = task.end - task.begin;
      continue;
    }
    std::array<float, 3> lo = centroid[id_[task.begin]], hi = lo;
    for (std::uint32_t i = task.begin; i < task.end; ++i)
      for (int k = 0; k < 3; ++k) {
        lo[k] = std::min(lo[k], centroid[id_[i]][k]);
        hi[k] = std::max(hi[k], centroid[id_[i]][k]);
      }
    int axis = 0;
    for (int k = 1; k < 3; ++k)
      if (hi[k] - lo[k] > hi[axis] - lo[axis]) axis = k;
    const std::uint32_t mid = task.begin + (task.end - task.begin) / 2;
    std::nth_element(id_.begin() + task.begin, id_.begin() + mid, id_.begin() + task.end,
                     [&](std::uint32_t a, std::uint32_t b) {
                       return centroid[a][axis] < centroid[b][axis] ||
                              (centroid[a][axis] == centroid[b][axis] && a < b);
                     });
    const auto left = std::uint32_t(nodes_.size());
    node.first = left;
    node.count = 0;
    nodes_.push_back({});  // invalidates `node`
    nodes_.push_back({});
    stack.push_back({left, task.begin, mid});
    stack.push_back({left + 1, mid, task.end});
  }

  // Step 2: corners in leaf order (a leaf's triangles adjacent in memory for the queries).
  tri_.resize(nt);
  for (std::size_t slot = 0; slot < nt; ++slot)
    for (int c = 0; c < 3; ++c) tri_[slot][c] = to_vec3(mesh.positions[mesh.triangles[id_[slot]][c]]);

  // Step 3: boxes bottom-up; children come after their parent, so a reverse sweep sees them
  // first. Double precision boxes contain the double corners exactly.
  for (std::size_t n = nodes_.size(); n-- > 0;) {
    Node& node = nodes_[n];
    if (node.count > 0) {
      node.lo = node.hi = tri_[node.first][0];
      for (std::uint32_t s = node.first; s < node.first + node.count; ++s)
        for (const Vec3& p : tri_[s])
          for (int k = 0; k < 3; ++k) {
            node.lo[k] = std::min(node.lo[k], p[k]);
            node.hi[k] = std::max(node.hi[k], p[k]);
          }
    } else {
      const Node& l = nodes_[node.first];
      const Node& r = nodes_[node.first + 1];
      for (int k = 0; k < 3; ++k) {
        node.lo[k] = std::min(l.lo[k], r.lo[k]);
        node.hi[k] = std::max(l.hi[k], r.hi[k]);
      }
    }
  }
}

TriangleBvh::Hit TriangleBvh::closest(const Vec3& p) const {
  Hit hit;
  if (nodes_.empty()) return hit;
  double best2 = std::numeric_limits<double>::infinity();
  std::uint32_t best_tri = 0;
  Vec3 best_point{}, best_bary{};
  std::uint32_t stack[128];
  int top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const Node& node = nodes_[stack[--top]];
    if (box_distance2(node.lo, node.hi, p) > best2) continue;
    if (node.count > 0) {
      for (std::uint32_t s = node.first; s < node.first + node.count; ++s) {
        Vec3 bary;
        const Vec3 q = closest_point_on_triangle(p, tri_[s][0], tri_[s][1], tri_[s][2], bary);
        const Vec3 d = sub(p, q);
        const double d2 = dot(d, d);
        if (d2 < best2 || (d2 == best2 && id_[s] < best_tri)) {
          best2 = d2;
          best_tri = id_[s];
          best_point = q;
          best_bary = bary;
        }
      }
      continue;
    }
    // Nearer child last on the stack so it is visited first and tightens best2 early.
    const double dl = box_distance2(nodes_[node.first].lo, nodes_[node.first].hi, p);
    const double dr = box_distance2(nodes_[node.first + 1].lo, nodes_[node.first + 1].hi, p);
    MLFE_CHECK(top + 2 <= 128);
    if (dl <= dr) {
      if (dr <= best2) stack[top++] = node.first + 1;
      stack[top++] = node.first;
    } else {
      if (dl <= best2) stack[top++] = node.first;
      stack[top++] = node.first + 1;
    }
  }
  hit.triangle = TriId(best_tri);
  hit.distance = std::sqrt(best2);
  hit.point = best_point;
  hit.bary = best_bary;
  return hit;
}

std::vector<SurfaceSample> sample_surface(const TriangleMesh& mesh, const SurfaceSamplingOptions& options) {
  std::vector<SurfaceSample> samples;
  // Step 1: every vertex used by a triangle, with the lowest triangle that uses it.
  std::vector<std::uint32_t> first_tri(mesh.positions.size(), TriId::kInvalidValue);
  std::vector<std::uint8_t> corner(mesh.positions.size(), 0);
  for (std::size_t t = mesh.triangles.size(); t-- > 0;)
    for (int c = 0; c < 3; ++c) {
      const std::uint32_t v = mesh.triangles[t][c];
      MLFE_CHECK(v < mesh.positions.size());
      first_tri[v] = std::uint32_t(t);
      corner[v] = std::uint8_t(c);
    }
  for (std::size_t v = 0; v < mesh.positions.size(); ++v)
    if (first_tri[v] != TriId::kInvalidValue) {
      Vec3 bary{0, 0, 0};
      bary[corner[v]] = 1;
      samples.push_back({to_vec3(mesh.positions[v]), TriId(first_tri[v]), bary});
    }

  // Step 2: area-weighted random points; the cumulative area table makes the choice of triangle
  // a binary search, and one std::mt19937_64 stream drawn in order keeps it reproducible
  // (its output is specified by the standard, unlike the distributions', so the mapping to
  // [0, 1) is done here).
  std::vector<double> cumulative(mesh.triangles.size());
  double total = 0;
  for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
    const auto& tri = mesh.triangles[t];
    const Vec3 a = to_vec3(mesh.positions[tri[0]]);
    const Vec3 n = cross(sub(to_vec3(mesh.positions[tri[1]]), a), sub(to_vec3(mesh.positions[tri[2]]), a));
    total += 0.5 * norm(n);
    cumulative[t] = total;
  }
  if (!(total > 0) || options.area_samples == 0) return samples;
  std::mt19937_64 rng(options.seed);
  auto uniform = [&] { return double(rng() >> 11) * (1.0 / 9007199254740992.0); };
  samples.reserve(samples.size() + options.area_samples);
  for (std::size_t s = 0; s < options.area_samples; ++s) {
    const double r = uniform() * total;
    const std::size_t t =
        std::min<std::size_t>(std::upper_bound(cumulative.begin(), cumulative.end(), r) - cumulative.begin(),
                              cumulative.size() - 1);
    double u = uniform(), v = uniform();
    if (u + v > 1) {
      u = 1 - u;
      v = 1 - v;
    }
    const auto& tri = mesh.triangles[t];
    const Vec3 a = to_vec3(mesh.positions[tri[0]]);
    const Vec3 p = add(a, add(scale(sub(to_vec3(mesh.positions[tri[1]]), a), u),
                              scale(sub(to_vec3(mesh.positions[tri[2]]), a), v)));
    samples.push_back({p, TriId(std::uint32_t(t)), {1 - u - v, u, v}});
  }
  return samples;
}

OneSidedDistance one_sided_distance(const TriangleMesh& from, const std::vector<SurfaceSample>& samples,
                                    const TriangleMesh& to, const TriangleBvh& to_bvh) {
  if (from.triangles.empty() || to.triangles.empty()) throw Error("mesh distance: a mesh has no triangles");
  if (from.normals.size() != from.positions.size() || to.normals.size() != to.positions.size())
    throw Error("mesh distance: the meshes need one normal per vertex");
  struct Slot {
    double distance;
    double angle_deg;  ///< < 0 when either normal is undefined
  };
  std::vector<Slot> slots(samples.size());

  // Step 1: queries in Morton order. Neighbouring queries then walk the same BVH nodes, which
  // stay in cache; vertex order in a file is arbitrary (Draco shuffles it). The order does not
  // change any result: each sample still writes only its own slot.
  const std::vector<std::uint32_t> order = morton_order(samples);

  // Step 2 (parallel): closest point and normal angle per sample.
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, samples.size(), 1024), [&](const auto& range) {
    for (std::size_t j = range.begin(); j != range.end(); ++j) {
      const std::size_t i = order[j];
      const SurfaceSample& s = samples[i];
      const TriangleBvh::Hit hit = to_bvh.closest(s.point);
      const Vec3 n0 = interpolated_normal(from, s.triangle.value, s.bary);
      const Vec3 n1 = interpolated_normal(to, hit.triangle.value, hit.bary);
      double angle = -1;
      if (dot(n0, n0) > 0 && dot(n1, n1) > 0)
        angle = std::acos(std::clamp(dot(n0, n1), -1.0, 1.0)) * (180.0 / M_PI);
      slots[i] = {hit.distance, angle};
    }
  });

  // Step 3 (sequential): reductions in sample order, so sums do not depend on scheduling.
  OneSidedDistance r;
  r.samples = samples.size();
  double sum = 0, angle_sum = 0;
  std::size_t angle_count = 0, flipped = 0;
  for (std::size_t i = 0; i < slots.size(); ++i) {
    sum += slots[i].distance;
    if (slots[i].distance > r.max) {
      r.max = slots[i].distance;
      r.max_at = samples[i].point;
    }
    if (slots[i].angle_deg >= 0) {
      angle_sum += slots[i].angle_deg;
      ++angle_count;
      r.normal_angle_max_deg = std::max(r.normal_angle_max_deg, slots[i].angle_deg);
      if (slots[i].angle_deg > 90) ++flipped;
    }
  }
  if (!slots.empty()) r.mean = sum / double(slots.size());
  if (angle_count > 0) {
    r.normal_angle_mean_deg = angle_sum / double(angle_count);
    r.flipped_fraction = double(flipped) / double(angle_count);
  }
  return r;
}

double MeshDistance::hausdorff() const { return std::max(expected_to_actual.max, actual_to_expected.max); }
double MeshDistance::mean() const { return std::max(expected_to_actual.mean, actual_to_expected.mean); }

MeshDistance mesh_distance(const TriangleMesh& expected, const TriangleMesh& actual,
                           const SurfaceSamplingOptions& options) {
  if (expected.triangles.empty() || actual.triangles.empty())
    throw Error("mesh distance: a mesh has no triangles");
  // Normals: the meshes' own when both have them (what an asset stores is what is compared),
  // otherwise area-weighted ones for both so that they are computed the same way.
  TriangleMesh e = expected, a = actual;
  if (e.normals.size() != e.positions.size() || a.normals.size() != a.positions.size()) {
    compute_area_weighted_normals(e);
    compute_area_weighted_normals(a);
  }
  // The two sides are independent until the queries: build and sample them side by side.
  std::optional<TriangleBvh> e_bvh, a_bvh;
  std::vector<SurfaceSample> e_samples, a_samples;
  tbb::parallel_invoke(
      [&] {
        e_bvh.emplace(e);
        e_samples = sample_surface(e, options);
      },
      [&] {
        a_bvh.emplace(a);
        a_samples = sample_surface(a, options);
      });
  MeshDistance d;
  d.expected_to_actual = one_sided_distance(e, e_samples, a, *a_bvh);
  d.actual_to_expected = one_sided_distance(a, a_samples, e, *e_bvh);
  return d;
}

std::array<std::array<double, 3>, 2> bounding_box(const TriangleMesh& mesh) {
  std::array<std::array<double, 3>, 2> box{};
  bool first = true;
  auto extend = [&](const std::array<float, 3>& p) {
    for (int k = 0; k < 3; ++k) {
      if (first || p[k] < box[0][k]) box[0][k] = p[k];
      if (first || p[k] > box[1][k]) box[1][k] = p[k];
    }
    first = false;
  };
  if (mesh.triangles.empty()) {
    for (const auto& p : mesh.positions) extend(p);
  } else {
    for (const auto& t : mesh.triangles)
      for (std::uint32_t v : t) {
        MLFE_CHECK(v < mesh.positions.size());
        extend(mesh.positions[v]);
      }
  }
  return box;
}

double signed_volume(const TriangleMesh& mesh) {
  const auto box = bounding_box(mesh);
  // About the box centre: the sum is origin-independent for closed meshes, but far from the
  // origin each term is large and cancellation would eat the precision.
  const Vec3 c = scale(add(box[0], box[1]), 0.5);
  double v = 0;
  for (const auto& t : mesh.triangles) {
    const Vec3 a = sub(to_vec3(mesh.positions[t[0]]), c), b = sub(to_vec3(mesh.positions[t[1]]), c),
               d = sub(to_vec3(mesh.positions[t[2]]), c);
    v += dot(a, cross(b, d));
  }
  return v / 6.0;
}

double surface_area(const TriangleMesh& mesh) {
  double area = 0;
  for (const auto& t : mesh.triangles) {
    const Vec3 a = to_vec3(mesh.positions[t[0]]);
    const Vec3 n = cross(sub(to_vec3(mesh.positions[t[1]]), a), sub(to_vec3(mesh.positions[t[2]]), a));
    area += 0.5 * norm(n);
  }
  return area;
}

}  // namespace mlfe
