// Least squares at the samples applied from the samples (Grosso, Lürig & Ertl, IEEE Vis 1997,
// Sec. 3, in the samples' discrete L2 norm); see sampled_least_squares.h.
#include <mlfe/core/base/check.h>
#include <mlfe/core/fem/sampled_least_squares.h>
#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <cmath>
#include <limits>

namespace mlfe {

namespace {

constexpr std::uint32_t kNoOwner = ~std::uint32_t(0);

}  // namespace

template <int D>
SampledLeastSquares<D>::SampledLeastSquares(const SampleLattice& lattice, const ScalarGrid& grid)
    : lattice_(lattice), grid_(grid) {
  MLFE_CHECK(lattice.dim == D && grid.dim == D);
  MLFE_CHECK(static_cast<std::int64_t>(grid.values.size()) == lattice.samples());
}

template <int D>
std::int64_t SampledLeastSquares<D>::tile_at(std::int64_t y, std::int64_t z) const {
  // Lattice points beyond the data (the padding's vertices) go to the last tile of the axis.
  y = std::min(y, lattice_.dims[1] - 1);
  z = std::min(z, lattice_.dims[2] - 1);
  return y / tile_ + tiles_y_ * (D == 3 ? z / tile_ : 0);
}

template <int D>
void SampledLeastSquares<D>::update(const Hierarchy<D>& h, const std::vector<ElemId>& remap,
                                    std::vector<double> padding) {
  MLFE_CHECK(padding.size() == h.vertex_count());
  const std::size_t ns = static_cast<std::size_t>(lattice_.samples());
  // 0. The stored cells back in vertex ids (new vertices change the order).
  if (!order_.empty()) renumber_cells(order_);
  // 1. Carry: the samples and summed leaves that stayed follow their ids; the first call has
  // neither.
  std::size_t first_new = 0;
  if (h_ == nullptr) {
    owner_.assign(ns, kNoOwner);
    cells_.resize(ns);
    lambda_.resize(ns);
  } else if (!remap.empty()) {
    MLFE_CHECK(remap.size() == elements_seen_);
    for (ElemId r : remap) first_new += r.valid();
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, ns, 1 << 16), [&](const auto& range) {
      for (std::size_t s = range.begin(); s != range.end(); ++s) {
        const std::uint32_t o = owner_[s];
        owner_[s] = o == kNoOwner ? kNoOwner : remap[o].value;  // invalid: kNoOwner too
      }
    });
    for (SummedLeaf& b : summed_) b.id = remap[b.id.value];
  } else {
    first_new = elements_seen_;
  }
  summed_.erase(std::remove_if(summed_.begin(), summed_.end(),
                               [&](const SummedLeaf& b) { return !b.id.valid() || !h.is_leaf(b.id); }),
                summed_.end());
  h_ = &h;
  elements_seen_ = h.element_count();
  // 2. Find: the samples of the leaves created since, each sample written by its one owner.
  struct Found {
    std::int64_t extent = 0;
    std::vector<SummedLeaf> summed;
    std::vector<OwnedSample<D>> owned;
  };
  tbb::enumerable_thread_specific<Found> found;
  const double w = lattice_.sample_weight;
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(first_new, h.element_count(), 1024), [&](const auto& range) {
        Found& mine = found.local();
        for (std::size_t i = range.begin(); i != range.end(); ++i) {
          const ElemId e(static_cast<std::uint32_t>(i));
          if (!h.is_leaf(e)) continue;
          const auto p = h.corner_points(e);
          owned_samples<D>(p, lattice_, mine.owned);
          if (mine.owned.empty()) continue;
          const bool summed = mine.owned.size() >= kSummedLeaf;
          SummedLeaf b{
              e, static_cast<std::uint32_t>(mine.owned.size()), mine.owned[0].index, 0, h.cell(e), 0, {}, {}};
          for (const OwnedSample<D>& s : mine.owned) {
            const auto at = static_cast<std::size_t>(s.index);
            owner_[at] = e.value;
            if (summed) {
              cells_[at][0] = VertexId::invalid();
              add_sample_terms<D>(w, grid_.values[at], s.lambda, b.f2, b.fphi, b.mass);
            } else {
              cells_[at] = h.cell(e);
              for (int a = 0; a < D; ++a) lambda_[at][a] = float(s.lambda[a + 1]);
            }
          }
          if (summed) mine.summed.push_back(b);
          for (int a = 1; a < D; ++a) {  // the tiled axes
            double lo = p[0][a], hi = p[0][a];
            for (int k = 1; k <= D; ++k) {
              lo = std::min(lo, p[k][a]);
              hi = std::max(hi, p[k][a]);
            }
            mine.extent =
                std::max(mine.extent, static_cast<std::int64_t>((hi - lo) / lattice_.spacing[a] + 0.5));
          }
        }
      });
  for (Found& f : found) {
    extent_ = std::max(extent_, f.extent);
    summed_.insert(summed_.end(), f.summed.begin(), f.summed.end());
  }
  // 3. Tiles: T = 2 × the largest extent so far (an upper bound: leaves only get smaller), the
  // summed leaves sorted into theirs by (tile, id), a unique order.
  tile_ = 2 * extent_;
  tiles_y_ = (lattice_.dims[1] + tile_ - 1) / tile_;
  tiles_z_ = D == 3 ? (lattice_.dims[2] + tile_ - 1) / tile_ : 1;
  const std::int64_t nx = lattice_.dims[0], ny = lattice_.dims[1];
  for (SummedLeaf& b : summed_) b.tile = tile_at((b.first_sample / nx) % ny, b.first_sample / (nx * ny));
  tbb::parallel_sort(summed_.begin(), summed_.end(), [](const SummedLeaf& a, const SummedLeaf& b) {
    return a.tile != b.tile ? a.tile < b.tile : a.id < b.id;
  });
  summed_start_.assign(static_cast<std::size_t>(tiles_y_ * tiles_z_) + 1, 0);
  for (const SummedLeaf& b : summed_) ++summed_start_[static_cast<std::size_t>(b.tile) + 1];
  for (std::size_t t = 1; t < summed_start_.size(); ++t) summed_start_[t] += summed_start_[t - 1];
  // 4. The operator's vertex order, the cells and the padding in it.
  order_vertices(h);
  renumber_cells(rank_);
  padding_.assign(padding.size(), 0.0);
  for (std::size_t v = 0; v < padding.size(); ++v) padding_[rank_[v]] = padding[v];
  // 5. The rows with samples of their own (the others are all summed leaves' and skipped).
  const std::int64_t rows = lattice_.dims[1] * lattice_.dims[2];
  loose_rows_.assign(static_cast<std::size_t>(rows), 0);
  tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, rows, 256), [&](const auto& range) {
    for (std::int64_t r = range.begin(); r != range.end(); ++r) {
      const auto* c = cells_.data() + r * lattice_.dims[0];
      loose_rows_[static_cast<std::size_t>(r)] =
          std::any_of(c, c + lattice_.dims[0], [](const auto& cell) { return cell[0].valid(); });
    }
  });
  // 6. Every sample has a leaf (the rule gives each exactly one; a gap is a bug).
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
void SampledLeastSquares<D>::order_vertices(const Hierarchy<D>& h) {
  const std::size_t nv = h.vertex_count();
  struct Key {
    std::uint64_t hi, lo;  // (tile, z), (y, x)
    std::uint32_t id;
  };
  const auto coord = [&](double x, int a) {
    return static_cast<std::int64_t>(std::nearbyint(x / lattice_.spacing[a]));
  };
  // Bucketed by tile (a counting sort), then each tile sorted on its own.
  const std::size_t tiles = static_cast<std::size_t>(tiles_y_ * tiles_z_);
  std::vector<Key> keys(nv);
  std::vector<std::uint32_t> start(tiles + 1, 0);
  std::vector<std::uint32_t> tile(nv);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nv, 1 << 14), [&](const auto& range) {
    for (std::size_t v = range.begin(); v != range.end(); ++v) {
      const auto& p = h.point(VertexId(static_cast<std::uint32_t>(v)));
      const std::int64_t x = coord(p[0], 0), y = coord(p[1], 1), z = D == 3 ? coord(p[2], 2) : 0;
      tile[v] = static_cast<std::uint32_t>(tile_at(y, z));
      keys[v] = {static_cast<std::uint64_t>(z),
                 static_cast<std::uint64_t>(y) << 32 | static_cast<std::uint64_t>(x),
                 static_cast<std::uint32_t>(v)};
    }
  });
  for (std::size_t v = 0; v < nv; ++v) ++start[tile[v] + 1];
  for (std::size_t t = 0; t < tiles; ++t) start[t + 1] += start[t];
  std::vector<Key> sorted(nv);
  {
    std::vector<std::uint32_t> fill(start.begin(), start.end() - 1);
    for (std::size_t v = 0; v < nv; ++v) sorted[fill[tile[v]]++] = keys[v];
  }
  tbb::parallel_for(std::size_t(0), tiles, [&](std::size_t t) {
    std::sort(sorted.begin() + start[t], sorted.begin() + start[t + 1],
              [](const Key& a, const Key& b) { return a.hi != b.hi ? a.hi < b.hi : a.lo < b.lo; });
  });
  order_.resize(nv);
  rank_.resize(nv);
  for (std::size_t i = 0; i < nv; ++i) {
    order_[i] = sorted[i].id;
    rank_[sorted[i].id] = static_cast<std::uint32_t>(i);
  }
}

template <int D>
void SampledLeastSquares<D>::renumber_cells(const std::vector<std::uint32_t>& map) {
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, cells_.size(), 1 << 16), [&](const auto& range) {
    for (std::size_t s = range.begin(); s != range.end(); ++s) {
      auto& c = cells_[s];
      if (!c[0].valid()) continue;  // a summed leaf's sample
      for (auto& v : c) v = VertexId(map[v.value]);
    }
  });
  for (SummedLeaf& b : summed_)
    for (auto& v : b.cell) v = VertexId(map[v.value]);
}

template <int D>
void SampledLeastSquares<D>::to_operator_order(const std::vector<double>& by_vertex, Vector& out) const {
  to_operator_order(by_vertex.data(), by_vertex.size(), out);
}

template <int D>
void SampledLeastSquares<D>::to_operator_order(const double* by_vertex, std::size_t n, Vector& out) const {
  MLFE_CHECK(n == order_.size());
  out.resize(size());
  for (Eigen::Index i = 0; i < out.size(); ++i) out[i] = by_vertex[order_[static_cast<std::size_t>(i)]];
}

template <int D>
void SampledLeastSquares<D>::from_operator_order(const Vector& v, std::vector<double>& by_vertex) const {
  MLFE_CHECK(static_cast<std::size_t>(v.size()) == order_.size());
  by_vertex.resize(order_.size());
  for (std::size_t i = 0; i < order_.size(); ++i) by_vertex[order_[i]] = v[static_cast<Eigen::Index>(i)];
}

template <int D>
template <class Leaf, class Sample>
void SampledLeastSquares<D>::for_each(Leaf&& leaf, Sample&& sample) const {
  for (int colour = 0; colour < (D == 3 ? 4 : 2); ++colour) for_each_in_colour(colour, leaf, sample);
}

template <int D>
template <class Leaf, class Sample>
void SampledLeastSquares<D>::for_each_in_colour(int colour, Leaf& leaf, Sample& sample) const {
  MLFE_CHECK(h_ != nullptr);
  const std::int64_t nx = lattice_.dims[0], ny = lattice_.dims[1], nz = lattice_.dims[2];
  // Colour bit 0: y tile parity, bit 1: z tile parity.
  std::vector<std::int64_t> tiles;
  for (std::int64_t z = 0; z < tiles_z_; ++z)
    for (std::int64_t y = 0; y < tiles_y_; ++y)
      if ((y & 1) + 2 * (z & 1) == colour) tiles.push_back(y + tiles_y_ * z);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, tiles.size(), 1), [&](const auto& range) {
    for (std::size_t t = range.begin(); t != range.end(); ++t) {
      const auto tile = static_cast<std::size_t>(tiles[t]);
      for (std::size_t b = summed_start_[tile]; b < summed_start_[tile + 1]; ++b) leaf(summed_[b]);
      const std::int64_t y0 = (tiles[t] % tiles_y_) * tile_, z0 = (tiles[t] / tiles_y_) * tile_;
      const std::int64_t y1 = std::min(ny, y0 + tile_), z1 = D == 3 ? std::min(nz, z0 + tile_) : 1;
      for (std::int64_t z = D == 3 ? z0 : 0; z < z1; ++z)
        for (std::int64_t y = y0; y < y1; ++y) {
          if (!loose_rows_[static_cast<std::size_t>(y + ny * z)]) continue;
          const std::size_t row = static_cast<std::size_t>(nx * (y + ny * z));
          for (std::size_t s = row; s < row + static_cast<std::size_t>(nx); ++s) {
            const auto& c = cells_[s];
            if (!c[0].valid()) continue;  // a summed leaf's
            std::array<double, D + 1> lam;
            lam[0] = 1.0;
            for (int a = 0; a < D; ++a) {
              lam[a + 1] = lambda_[s][a];
              lam[0] -= lam[a + 1];
            }
            sample(s, c, lam);
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
  for_each(
      [&](const SummedLeaf& b) {
        std::array<double, D + 1> xs, ys{};
        for (int a = 0; a <= D; ++a) xs[a] = x[b.cell[a].value];
        for (int a = 0, m = 0; a <= D; ++a) {
          ys[a] += b.mass[m] * xs[a];
          for (int c = a + 1; c <= D; ++c) {
            ys[a] += b.mass[m + c - a] * xs[c];
            ys[c] += b.mass[m + c - a] * xs[a];
          }
          m += D + 1 - a;
        }
        for (int a = 0; a <= D; ++a) y[b.cell[a].value] += ys[a];
      },
      [&](std::size_t, const auto& c, const std::array<double, D + 1>& lam) {
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
  for_each(
      [&](const SummedLeaf& b) {
        for (int a = 0, m = 0; a <= D; m += D + 1 - a, ++a) {
          rhs[b.cell[a].value] += b.fphi[a];
          diagonal[b.cell[a].value] += b.mass[m];
        }
      },
      [&](std::size_t s, const auto& c, const std::array<double, D + 1>& lam) {
        const double wf = w * double(grid_.values[s]);
        for (int i = 0; i <= D; ++i) {
          rhs[c[i].value] += wf * lam[i];
          diagonal[c[i].value] += w * lam[i] * lam[i];
        }
      });
  for (Eigen::Index i = 0; i < size(); ++i) diagonal[i] += padding_[static_cast<std::size_t>(i)];
}

template <int D>
void SampledLeastSquares<D>::leaf_errors(const Vector& u, const std::vector<ElemId>& leaves,
                                         std::vector<double>& error,
                                         std::vector<std::uint32_t>& samples) const {
  MLFE_CHECK(u.size() == size());
  // Sums straight into the leaves' order. The leaves are in id order, so a leaf's index is its
  // rank among them: a bit per element id and a count per 64 of them (3 MB for 16 M elements,
  // where an id → index table was 64 MB at the build's peak).
  std::vector<std::uint64_t> bits((h_->element_count() + 63) / 64, 0);
  for (std::size_t i = 0; i < leaves.size(); ++i) {
    MLFE_CHECK(i == 0 || leaves[i - 1] < leaves[i]);
    bits[leaves[i].value >> 6] |= std::uint64_t(1) << (leaves[i].value & 63);
  }
  std::vector<std::uint32_t> before(bits.size() + 1, 0);
  for (std::size_t k = 0; k < bits.size(); ++k)
    before[k + 1] = before[k] + static_cast<std::uint32_t>(__builtin_popcountll(bits[k]));
  const auto index = [&](std::uint32_t e) {
    const std::uint64_t word = bits[e >> 6], below = (std::uint64_t(1) << (e & 63)) - 1;
    MLFE_CHECK((word >> (e & 63)) & 1);  // a leaf
    return before[e >> 6] + static_cast<std::uint32_t>(__builtin_popcountll(word & below));
  };
  error.assign(leaves.size(), 0.0);
  samples.assign(leaves.size(), 0);
  const double w = lattice_.sample_weight;
  for_each(
      [&](const SummedLeaf& b) {
        // Σ w f² − 2 U·F_T + Uᵀ M_T U; cancellation can leave a tiny negative.
        std::array<double, D + 1> us;
        for (int a = 0; a <= D; ++a) us[a] = u[b.cell[a].value];
        double cross = 0, quad = 0;
        for (int a = 0, m = 0; a <= D; ++a) {
          cross += us[a] * b.fphi[a];
          quad += us[a] * us[a] * b.mass[m];
          for (int c = a + 1; c <= D; ++c) quad += 2 * us[a] * us[c] * b.mass[m + c - a];
          m += D + 1 - a;
        }
        const std::uint32_t i = index(b.id.value);
        error[i] = std::max(0.0, b.f2 - 2 * cross + quad);
        samples[i] = b.samples;
      },
      [&](std::size_t s, const auto& c, const std::array<double, D + 1>& lam) {
        double v = 0;
        for (int a = 0; a <= D; ++a) v += lam[a] * u[c[a].value];
        const double d = double(grid_.values[s]) - v;
        const std::uint32_t i = index(owner_[s]);
        error[i] += w * d * d;
        ++samples[i];
      });
}

template class SampledLeastSquares<2>;
template class SampledLeastSquares<3>;

}  // namespace mlfe
