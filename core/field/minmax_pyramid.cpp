#include <mlfe/core/base/check.h>
#include <mlfe/core/field/minmax_pyramid.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

namespace mlfe {

MinMaxPyramid::MinMaxPyramid(const ScalarGrid& grid) {
  const auto& d = grid.dims;
  for (int a = 0; a < 3; ++a) cells_[a] = std::max<std::int64_t>(1, d[a] - 1);
  // Level 0: blocks of 2x2x2 cells, i.e. the samples [2b, 2b + 2] along each axis.
  Level l0;
  for (int a = 0; a < 3; ++a) l0.n[a] = (cells_[a] + 1) / 2;
  l0.lo.resize(static_cast<std::size_t>(l0.n[0] * l0.n[1] * l0.n[2]));
  l0.hi.resize(l0.lo.size());
  const float* v = grid.values.data();
  tbb::parallel_for(
      tbb::blocked_range<std::int64_t>(0, l0.n[2]), [&](const tbb::blocked_range<std::int64_t>& r) {
        for (std::int64_t bz = r.begin(); bz != r.end(); ++bz)
          for (std::int64_t by = 0; by < l0.n[1]; ++by)
            for (std::int64_t bx = 0; bx < l0.n[0]; ++bx) {
              float lo = v[0], hi = v[0];
              bool first = true;
              for (std::int64_t k = 2 * bz; k <= std::min(2 * bz + 2, d[2] - 1); ++k)
                for (std::int64_t j = 2 * by; j <= std::min(2 * by + 2, d[1] - 1); ++j) {
                  const float* row = v + d[0] * (j + d[1] * k);
                  for (std::int64_t i = 2 * bx; i <= std::min(2 * bx + 2, d[0] - 1); ++i) {
                    if (first) lo = hi = row[i], first = false;
                    lo = std::min(lo, row[i]);
                    hi = std::max(hi, row[i]);
                  }
                }
              const std::size_t at = static_cast<std::size_t>(bx + l0.n[0] * (by + l0.n[1] * bz));
              l0.lo[at] = lo;
              l0.hi[at] = hi;
            }
      });
  levels_.push_back(std::move(l0));
  while (levels_.back().n[0] > 1 || levels_.back().n[1] > 1 || levels_.back().n[2] > 1) {
    const Level& c = levels_.back();
    Level p;
    for (int a = 0; a < 3; ++a) p.n[a] = (c.n[a] + 1) / 2;
    p.lo.resize(static_cast<std::size_t>(p.n[0] * p.n[1] * p.n[2]));
    p.hi.resize(p.lo.size());
    for (std::int64_t z = 0; z < p.n[2]; ++z)
      for (std::int64_t y = 0; y < p.n[1]; ++y)
        for (std::int64_t x = 0; x < p.n[0]; ++x) {
          float lo = 0, hi = 0;
          bool first = true;
          for (std::int64_t k = 2 * z; k < std::min(2 * z + 2, c.n[2]); ++k)
            for (std::int64_t j = 2 * y; j < std::min(2 * y + 2, c.n[1]); ++j)
              for (std::int64_t i = 2 * x; i < std::min(2 * x + 2, c.n[0]); ++i) {
                const std::size_t at = static_cast<std::size_t>(i + c.n[0] * (j + c.n[1] * k));
                if (first) lo = c.lo[at], hi = c.hi[at], first = false;
                lo = std::min(lo, c.lo[at]);
                hi = std::max(hi, c.hi[at]);
              }
          const std::size_t at = static_cast<std::size_t>(x + p.n[0] * (y + p.n[1] * z));
          p.lo[at] = lo;
          p.hi[at] = hi;
        }
    levels_.push_back(std::move(p));
  }
}

std::array<float, 2> MinMaxPyramid::range(const std::array<double, 3>& i0,
                                          const std::array<double, 3>& i1) const {
  // Cells overlapping the box, then the level whose blocks (2^(k+1) cells) are at least as
  // wide as that cell span, so at most 2 blocks per axis cover it.
  std::array<std::int64_t, 3> c0, c1;
  std::int64_t span = 1;
  for (int a = 0; a < 3; ++a) {
    const double lo = std::clamp(std::min(i0[a], i1[a]), 0.0, double(cells_[a]));
    const double hi = std::clamp(std::max(i0[a], i1[a]), 0.0, double(cells_[a]));
    c0[a] = std::min<std::int64_t>(cells_[a] - 1, static_cast<std::int64_t>(std::floor(lo)));
    // A box ending exactly on a sample also touches the cell beyond it only in that sample,
    // which the cell below holds too.
    c1[a] = std::max<std::int64_t>(
        c0[a], std::min<std::int64_t>(cells_[a] - 1, static_cast<std::int64_t>(std::ceil(hi)) - 1));
    span = std::max(span, c1[a] - c0[a] + 1);
  }
  std::size_t k = 0;
  while (k + 1 < levels_.size() && (std::int64_t(2) << k) < span) ++k;
  const Level& l = levels_[k];
  const int shift = static_cast<int>(k) + 1;
  float lo = 0, hi = 0;
  bool first = true;
  for (std::int64_t z = c0[2] >> shift; z <= (c1[2] >> shift); ++z)
    for (std::int64_t y = c0[1] >> shift; y <= (c1[1] >> shift); ++y)
      for (std::int64_t x = c0[0] >> shift; x <= (c1[0] >> shift); ++x) {
        const std::size_t at = static_cast<std::size_t>(x + l.n[0] * (y + l.n[1] * z));
        MLFE_CHECK(at < l.lo.size());
        if (first) lo = l.lo[at], hi = l.hi[at], first = false;
        lo = std::min(lo, l.lo[at]);
        hi = std::max(hi, l.hi[at]);
      }
  return {lo, hi};
}

std::size_t MinMaxPyramid::memory_bytes() const {
  std::size_t b = 0;
  for (const auto& l : levels_) b += (l.lo.capacity() + l.hi.capacity()) * sizeof(float);
  return b;
}

}  // namespace mlfe
