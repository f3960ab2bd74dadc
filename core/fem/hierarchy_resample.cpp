// Leaf mesh → voxel grid by barycentric interpolation (see hierarchy_resample.h).
#include <mlfe/core/base/check.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/fem/hierarchy_resample.h>
#include <mlfe/core/fem/p1_element.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <string>

namespace mlfe {

template <int D>
std::array<std::int64_t, 3> hierarchy_grid_dims(const Hierarchy<D>& h, const std::array<double, 3>& spacing) {
  std::array<std::int64_t, 3> dims{1, 1, 1};
  for (int a = 0; a < D; ++a) {
    double lo = std::numeric_limits<double>::infinity(), hi = -lo;
    for (const auto& p : h.points()) lo = std::min(lo, p[a]), hi = std::max(hi, p[a]);
    const double n = hi / spacing[a];
    if (std::fabs(lo) > 1e-6 * spacing[a] || !(n >= 1) || n > 1e7 ||
        std::fabs(n - std::round(n)) > 1e-6 * std::max(1.0, n))
      throw Error("the hierarchy's domain is not a voxel grid's box (axis " + std::to_string(a) + ")");
    dims[a] = static_cast<std::int64_t>(std::round(n)) + 1;
  }
  return dims;
}

template <int D>
std::vector<float> resample_to_grid(const Hierarchy<D>& h, const std::vector<double>& values,
                                    const std::array<std::int64_t, 3>& dims,
                                    const std::array<double, 3>& spacing) {
  MLFE_CHECK(values.size() == h.vertex_count());
  const std::int64_t nx = dims[0], ny = dims[1], nz = dims[2];
  std::vector<float> out(static_cast<std::size_t>(nx * ny * nz), std::numeric_limits<float>::quiet_NaN());
  const std::vector<ElemId> leaves = h.leaves();
  constexpr double kTol = 1e-9;

  // A leaf's box in grid indices (lower corners, then upper), clamped to the grid; recomputed
  // where needed: kept for every leaf, the boxes were 48 bytes a leaf (0.66 GB for a full head
  // at its noise level, a build's peak).
  const auto leaf_box = [&](std::size_t l) {
    std::array<std::int64_t, 2 * D> box;
    const auto& c = h.cell(leaves[l]);
    for (int a = 0; a < D; ++a) {
      double lo = h.point(c[0])[a], hi = lo;
      for (int i = 1; i <= D; ++i) lo = std::min(lo, h.point(c[i])[a]), hi = std::max(hi, h.point(c[i])[a]);
      box[a] = std::max<std::int64_t>(0, static_cast<std::int64_t>(std::ceil(lo / spacing[a] - kTol)));
      box[D + a] =
          std::min<std::int64_t>(dims[a] - 1, static_cast<std::int64_t>(std::floor(hi / spacing[a] + kTol)));
    }
    return box;
  };
  // Step 1: bucket the leaves by the slabs (along the last axis) their boxes touch, in leaf
  // order, so each slab is filled by one task in a fixed order.
  constexpr int A = D - 1;  // slab axis
  const std::int64_t n_slab_axis = dims[A];
  const std::int64_t slab = std::max<std::int64_t>(1, n_slab_axis / 64);
  const std::int64_t n_slabs = (n_slab_axis + slab - 1) / slab;
  // Chunks of leaves in parallel, each into its own buckets, joined in chunk order: the same
  // lists as one pass in leaf order.
  constexpr std::size_t kChunk = 1 << 16;
  const std::size_t n_chunks = (leaves.size() + kChunk - 1) / kChunk;
  std::vector<std::vector<std::vector<std::uint32_t>>> part(n_chunks);
  tbb::parallel_for(std::size_t(0), n_chunks, [&](std::size_t k) {
    part[k].resize(static_cast<std::size_t>(n_slabs));
    for (std::size_t l = k * kChunk, end = std::min(leaves.size(), l + kChunk); l < end; ++l) {
      const auto box = leaf_box(l);
      if (box[A] > box[D + A]) continue;
      for (std::int64_t s = box[A] / slab; s <= box[D + A] / slab; ++s)
        part[k][static_cast<std::size_t>(s)].push_back(static_cast<std::uint32_t>(l));
    }
  });
  std::vector<std::vector<std::uint32_t>> buckets(static_cast<std::size_t>(n_slabs));
  tbb::parallel_for(std::size_t(0), buckets.size(), [&](std::size_t s) {
    std::size_t n = 0;
    for (const auto& p : part) n += p[s].size();
    buckets[s].reserve(n);
    for (auto& p : part) {
      buckets[s].insert(buckets[s].end(), p[s].begin(), p[s].end());
      std::vector<std::uint32_t>().swap(p[s]);
    }
  });
  // Step 2: per slab, barycentric coordinates of every grid point in each leaf's box.
  tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, n_slabs),
                    [&](const tbb::blocked_range<std::int64_t>& r) {
                      for (std::int64_t s = r.begin(); s < r.end(); ++s) {
                        const std::int64_t s_lo = s * slab, s_hi = std::min(n_slab_axis - 1, s_lo + slab - 1);
                        for (std::uint32_t l : buckets[s]) {
                          const auto box = leaf_box(l);
                          const std::int64_t k_lo = D == 3 ? std::max(box[2], s_lo) : 0,
                                             k_hi = D == 3 ? std::min(box[5], s_hi) : 0;
                          const std::int64_t j_lo = D == 2 ? std::max(box[1], s_lo) : box[1];
                          const std::int64_t j_hi = D == 2 ? std::min(box[3], s_hi) : box[1 + D];
                          // Every point of the box already has its value (from an earlier
                          // leaf sharing it): skip the element's set-up.
                          bool open = false;
                          for (std::int64_t k = k_lo; k <= k_hi && !open; ++k)
                            for (std::int64_t j = j_lo; j <= j_hi && !open; ++j)
                              for (std::int64_t i = box[0]; i <= box[D] && !open; ++i)
                                open = std::isnan(out[static_cast<std::size_t>(i + nx * (j + ny * k))]);
                          if (!open) continue;
                          const auto& c = h.cell(leaves[l]);
                          // Barycentric map: λ_{1..D} = ∇λ_{1..D} · (x − p0), λ_0 = 1 − Σ.
                          std::array<std::array<double, D>, D + 1> p;
                          for (int i = 0; i <= D; ++i) p[i] = h.point(c[i]);
                          const P1Element<D> el(p);
                          MLFE_CHECK(el.measure > 0);  // hierarchies have no flat simplices
                          const auto& p0 = p[0];
                          double u[D + 1];
                          for (int i = 0; i <= D; ++i) u[i] = values[c[i].value];
                          for (std::int64_t k = k_lo; k <= k_hi; ++k)
                            for (std::int64_t j = j_lo; j <= j_hi; ++j)
                              for (std::int64_t i = box[0]; i <= box[D]; ++i) {
                                float& o = out[static_cast<std::size_t>(i + nx * (j + ny * k))];
                                if (!std::isnan(o)) continue;
                                const double x[3] = {i * spacing[0] - p0[0], j * spacing[1] - p0[1],
                                                     D == 3 ? k * spacing[2] - p0[2] : 0.0};
                                double lam[D + 1], sum = 0;
                                bool inside = true;
                                for (int a = 0; a < D; ++a) {
                                  double t = 0;
                                  for (int b = 0; b < D; ++b) t += el.grad[a + 1][b] * x[b];
                                  lam[a + 1] = t;
                                  sum += t;
                                  inside = inside && t >= -kTol;
                                }
                                lam[0] = 1 - sum;
                                if (!inside || lam[0] < -kTol) continue;
                                double v = 0;
                                for (int a = 0; a <= D; ++a) v += lam[a] * u[a];
                                o = static_cast<float>(v);
                              }
                        }
                      }
                    });
  return out;
}

GridErrors grid_errors(const std::vector<float>& a, const std::vector<float>& b, double range,
                       const std::string& what) {
  MLFE_CHECK(a.size() == b.size());
  double sum = 0, mx = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    if (std::isnan(a[i]) || std::isnan(b[i])) throw Error(what + ": a grid point has no value (NaN)");
    const double d = static_cast<double>(a[i]) - static_cast<double>(b[i]);
    sum += d * d;
    mx = std::max(mx, std::fabs(d));
  }
  GridErrors e;
  e.rms = a.empty() ? 0.0 : std::sqrt(sum / static_cast<double>(a.size()));
  e.max = mx;
  e.psnr = e.rms > 0 ? 20 * std::log10((range > 0 ? range : 1.0) / e.rms)
                     : std::numeric_limits<double>::infinity();
  return e;
}

template std::array<std::int64_t, 3> hierarchy_grid_dims<2>(const Hierarchy<2>&,
                                                            const std::array<double, 3>&);
template std::array<std::int64_t, 3> hierarchy_grid_dims<3>(const Hierarchy<3>&,
                                                            const std::array<double, 3>&);
template std::vector<float> resample_to_grid<2>(const Hierarchy<2>&, const std::vector<double>&,
                                                const std::array<std::int64_t, 3>&,
                                                const std::array<double, 3>&);
template std::vector<float> resample_to_grid<3>(const Hierarchy<3>&, const std::vector<double>&,
                                                const std::array<std::int64_t, 3>&,
                                                const std::array<double, 3>&);

}  // namespace mlfe
