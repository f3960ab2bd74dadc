// Noise level from local medians of absolute second differences; see noise_estimate.h.
#include <mlfe/core/field/noise_estimate.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

namespace mlfe {

namespace {

constexpr std::int64_t kBlock = 8;  // samples per block edge (3D); 2D blocks are 16 wide

// The block's estimate: per axis the median of the non-zero |d| / (0.6745 √6), the smallest
// over the axes; NaN when too few second differences are non-zero (constant data).
double block_sigma(const ScalarGrid& g, const std::int64_t lo[3], const std::int64_t hi[3],
                   std::vector<float>& d) {
  const std::int64_t n[3] = {g.dims[0], g.dims[1], g.dims[2]};
  const std::int64_t stride[3] = {1, n[0], n[0] * n[1]};
  double best = std::numeric_limits<double>::quiet_NaN();
  std::int64_t count = 1;
  for (int a = 0; a < g.dim; ++a) count *= hi[a] - lo[a];
  for (int a = 0; a < g.dim; ++a) {
    if (n[a] < 3) continue;
    d.clear();
    for (std::int64_t k = lo[2]; k < hi[2]; ++k)
      for (std::int64_t j = lo[1]; j < hi[1]; ++j)
        for (std::int64_t i = lo[0]; i < hi[0]; ++i) {
          const std::int64_t q[3] = {i, j, k};
          if (q[a] == 0 || q[a] == n[a] - 1) continue;
          const std::int64_t at = i + n[0] * (j + n[1] * k);
          const float v = std::fabs(g.values[static_cast<std::size_t>(at - stride[a])] -
                                    2.0f * g.values[static_cast<std::size_t>(at)] +
                                    g.values[static_cast<std::size_t>(at + stride[a])]);
          if (v > 0 && std::isfinite(v)) d.push_back(v);
        }
    // Mostly constant blocks (a zero background) say nothing about the noise.
    if (std::int64_t(d.size()) * 2 < count) continue;
    auto mid = d.begin() + static_cast<std::ptrdiff_t>(d.size() / 2);
    std::nth_element(d.begin(), mid, d.end());
    const double s = double(*mid) / (0.6745 * std::sqrt(6.0));
    best = std::isnan(best) ? s : std::min(best, s);
  }
  return best;
}

}  // namespace

double estimate_noise_sigma(const ScalarGrid& g) {
  const std::int64_t b = g.dim == 3 ? kBlock : 2 * kBlock;
  std::int64_t nb[3] = {1, 1, 1};
  for (int a = 0; a < g.dim; ++a) nb[a] = (g.dims[a] + b - 1) / b;
  const std::size_t blocks = static_cast<std::size_t>(nb[0] * nb[1] * nb[2]);
  std::vector<double> sigma(blocks, std::numeric_limits<double>::quiet_NaN());
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, blocks, 16), [&](const tbb::blocked_range<std::size_t>& r) {
        std::vector<float> d;
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
          const std::int64_t bi[3] = {std::int64_t(i) % nb[0], (std::int64_t(i) / nb[0]) % nb[1],
                                      std::int64_t(i) / (nb[0] * nb[1])};
          std::int64_t lo[3] = {0, 0, 0}, hi[3] = {1, 1, 1};
          for (int a = 0; a < g.dim; ++a) {
            lo[a] = bi[a] * b;
            hi[a] = std::min(g.dims[a], lo[a] + b);
          }
          sigma[i] = block_sigma(g, lo, hi, d);
        }
      });
  std::vector<double> s;
  for (double x : sigma)
    if (!std::isnan(x)) s.push_back(x);
  if (s.empty()) return 0.0;
  // The median block: edges and texture raise a minority of the blocks, and noise that varies
  // over the scan (Rician noise is weaker in air than in tissue) is taken at its middle.
  auto q = s.begin() + static_cast<std::ptrdiff_t>(s.size() / 2);
  std::nth_element(s.begin(), q, s.end());
  return *q;
}

}  // namespace mlfe
