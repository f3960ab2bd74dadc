// Least squares at the samples applied from the samples (Grosso, Lürig & Ertl, IEEE Vis 1997,
// Sec. 3, in the samples' discrete L2 norm); see sampled_least_squares.h.
#include <mlfe/core/check.h>
#include <mlfe/core/sampled_least_squares.h>
#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <limits>

namespace mlfe {

namespace {

constexpr std::uint32_t kNoOwner = ~std::uint32_t(0);

template <int D>
std::array<std::array<double, D>, D + 1> corners(const Hierarchy<D>& h, ElemId e) {
  std::array<std::array<double, D>, D + 1> p;
  for (int i = 0; i <= D; ++i) p[i] = h.point(h.cell(e)[i]);
  return p;
}

}  // namespace

template <int D>
SampledLeastSquares<D>::SampledLeastSquares(const SampleLattice& lattice, const ScalarGrid& grid)
    : lattice_(lattice), grid_(grid) {
  MLFE_CHECK(lattice.dim == D && grid.dim == D);
  MLFE_CHECK(static_cast<std::int64_t>(grid.values.size()) == lattice.samples());
}

template <int D>
void SampledLeastSquares<D>::update(const Hierarchy<D>& h, const std::vector<ElemId>& remap,
                                    std::vector<double> padding) {
  MLFE_CHECK(padding.size() == h.vertex_count());
  const std::size_t ns = static_cast<std::size_t>(lattice_.samples());
  // 1. Carry: the samples of leaves that stayed follow their ids; the first call owns nothing.
  std::size_t first_new = 0;
  if (h_ == nullptr) {
    owner_.assign(ns, kNoOwner);
    cells_.resize(ns);
    lambda_.resize(ns);
  } else if (remap.empty()) {
    first_new = elements_seen_;
  } else {
    MLFE_CHECK(remap.size() == elements_seen_);
    for (ElemId r : remap) first_new += r.valid();
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, ns, 1 << 16), [&](const auto& range) {
      for (std::size_t s = range.begin(); s != range.end(); ++s) {
        const std::uint32_t o = owner_[s];
        owner_[s] = o == kNoOwner ? kNoOwner : remap[o].value;  // invalid: kNoOwner too
      }
    });
  }
  h_ = &h;
  elements_seen_ = h.element_count();
  padding_ = std::move(padding);
  // 2. Find: the samples of the leaves created since, each sample written by its one owner.
  struct Extent {
    std::int64_t value = 0;
  };
  tbb::enumerable_thread_specific<std::vector<OwnedSample<D>>> scratch;
  tbb::enumerable_thread_specific<Extent> widest;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(first_new, h.element_count(), 1024), [&](const auto& range) {
    auto& owned = scratch.local();
    std::int64_t& ext = widest.local().value;
    for (std::size_t i = range.begin(); i != range.end(); ++i) {
      const ElemId e(static_cast<std::uint32_t>(i));
      if (!h.is_leaf(e)) continue;
      const auto p = corners(h, e);
      owned_samples<D>(p, lattice_, owned);
      if (owned.empty()) continue;
      for (const OwnedSample<D>& s : owned) {
        owner_[static_cast<std::size_t>(s.index)] = e.value;
        cells_[static_cast<std::size_t>(s.index)] = h.cell(e);
        for (int a = 0; a < D; ++a) lambda_[static_cast<std::size_t>(s.index)][a] = float(s.lambda[a + 1]);
      }
      for (int a = 1; a < D; ++a) {  // the tiled axes
        double lo = p[0][a], hi = p[0][a];
        for (int k = 1; k <= D; ++k) {
          lo = std::min(lo, p[k][a]);
          hi = std::max(hi, p[k][a]);
        }
        ext = std::max(ext, static_cast<std::int64_t>((hi - lo) / lattice_.spacing[a] + 0.5));
      }
    }
  });
  for (const Extent& x : widest) extent_ = std::max(extent_, x.value);
  tile_ = 2 * extent_;
  // 3. Every sample has a leaf (the rule gives each exactly one; a gap is a bug).
  const std::size_t orphans = tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, ns, 1 << 16), std::size_t(0),
      [&](const auto& range, std::size_t n) {
        for (std::size_t s = range.begin(); s != range.end(); ++s)
          n += owner_[s] == kNoOwner || !h.is_leaf(ElemId(owner_[s]));
        return n;
      },
      [](std::size_t a, std::size_t b) { return a + b; });
  MLFE_CHECK_MSG(orphans == 0, "samples without a leaf after update()");
}

template <int D>
template <class Visit>
void SampledLeastSquares<D>::for_each_sample(int colour, Visit&& visit) const {
  MLFE_CHECK(h_ != nullptr);
  const std::int64_t nx = lattice_.dims[0], ny = lattice_.dims[1], nz = lattice_.dims[2];
  // Tiles over (y, z) in 3D, over y in 2D; colour bit 0: y tile parity, bit 1: z tile parity.
  const std::int64_t ty = (ny + tile_ - 1) / tile_;
  const std::int64_t tz = D == 3 ? (nz + tile_ - 1) / tile_ : 1;
  std::vector<std::int64_t> tiles;
  for (std::int64_t z = 0; z < tz; ++z)
    for (std::int64_t y = 0; y < ty; ++y)
      if ((y & 1) + 2 * (z & 1) == colour) tiles.push_back(y + ty * z);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, tiles.size(), 1), [&](const auto& range) {
    for (std::size_t t = range.begin(); t != range.end(); ++t) {
      const std::int64_t y0 = (tiles[t] % ty) * tile_, z0 = (tiles[t] / ty) * tile_;
      const std::int64_t y1 = std::min(ny, y0 + tile_), z1 = D == 3 ? std::min(nz, z0 + tile_) : 1;
      for (std::int64_t z = D == 3 ? z0 : 0; z < z1; ++z)
        for (std::int64_t y = y0; y < y1; ++y) {
          const std::size_t row = static_cast<std::size_t>(nx * (y + ny * z));
          for (std::size_t s = row; s < row + static_cast<std::size_t>(nx); ++s) {
            const auto& c = cells_[s];
            std::array<double, D + 1> lam;
            lam[0] = 1.0;
            for (int a = 0; a < D; ++a) {
              lam[a + 1] = lambda_[s][a];
              lam[0] -= lam[a + 1];
            }
            visit(s, c, lam);
          }
        }
    }
  });
}

template <int D>
void SampledLeastSquares<D>::apply(const Vector& x, Vector& y) const {
  MLFE_CHECK(x.size() == size());
  y.setZero(size());
  const double w = lattice_.sample_weight;
  for (int colour = 0; colour < (D == 3 ? 4 : 2); ++colour)
    for_each_sample(colour, [&](std::size_t, const auto& c, const std::array<double, D + 1>& lam) {
      double u = 0;
      for (int i = 0; i <= D; ++i) u += lam[i] * x[c[i].value];
      u *= w;
      for (int i = 0; i <= D; ++i) y[c[i].value] += lam[i] * u;
    });
  for (Eigen::Index i = 0; i < size(); ++i) y[i] += padding_[static_cast<std::size_t>(i)] * x[i];
}

template <int D>
void SampledLeastSquares<D>::load(Vector& rhs, Vector& diagonal) const {
  rhs.setZero(size());
  diagonal.setZero(size());
  const double w = lattice_.sample_weight;
  for (int colour = 0; colour < (D == 3 ? 4 : 2); ++colour)
    for_each_sample(colour, [&](std::size_t s, const auto& c, const std::array<double, D + 1>& lam) {
      const double wf = w * double(grid_.values[s]);
      for (int i = 0; i <= D; ++i) {
        rhs[c[i].value] += wf * lam[i];
        diagonal[c[i].value] += w * lam[i] * lam[i];
      }
    });
  for (Eigen::Index i = 0; i < size(); ++i) diagonal[i] += padding_[static_cast<std::size_t>(i)];
}

template <int D>
void SampledLeastSquares<D>::leaf_errors(const Vector& u, std::vector<double>& error,
                                         std::vector<std::uint32_t>& samples) const {
  MLFE_CHECK(u.size() == size());
  error.assign(h_->element_count(), 0.0);
  samples.assign(h_->element_count(), 0);
  const double w = lattice_.sample_weight;
  for (int colour = 0; colour < (D == 3 ? 4 : 2); ++colour)
    for_each_sample(colour, [&](std::size_t s, const auto& c, const std::array<double, D + 1>& lam) {
      double v = 0;
      for (int i = 0; i <= D; ++i) v += lam[i] * u[c[i].value];
      const double d = double(grid_.values[s]) - v;
      const std::uint32_t o = owner_[s];
      error[o] += w * d * d;
      ++samples[o];
    });
}

template class SampledLeastSquares<2>;
template class SampledLeastSquares<3>;

}  // namespace mlfe
