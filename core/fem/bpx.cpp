// BPX preconditioner (Bramble, Pasciak & Xu 1990); see bpx.h.
#include <mlfe/core/base/check.h>
#include <mlfe/core/fem/bpx.h>
#include <mlfe/core/fem/p1_element.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>

namespace mlfe {

template <int D>
BpxPreconditioner<D>::BpxPreconditioner(const Hierarchy<D>& h, double gradient_weight) {
  n_ = static_cast<Eigen::Index>(h.vertex_count());
  fine_diag_.assign(h.vertex_count(), 0.0);
  const int levels = h.max_level() + 1;
  parents_.resize(h.vertex_count());
  new_vertices_.assign(levels, {});
  for (std::size_t v = 0; v < h.vertex_count(); ++v) {
    const VertexId id(static_cast<std::uint32_t>(v));
    parents_[v] = h.vertex_parents(id);
    const int lv = h.vertex_level(id);
    MLFE_CHECK(lv < levels);
    new_vertices_[lv].push_back(static_cast<std::uint32_t>(v));
  }
  // V_k = vertices of level-k elements; a(φ_v^k, φ_v^k) is summed over T_k (level-k elements
  // plus coarser leaves), on which φ_v^k is the exact hat function — a vertex on the rim of a
  // refined region has a hat reaching into the coarser leaves, and leaving those out would
  // over-weight it. One pass over the elements bucketed by level: the coarser leaves'
  // share is carried in running per-vertex sums instead of rescanning all elements per level.
  const std::size_t ne = h.element_count(), nv = h.vertex_count();
  std::vector<std::uint32_t> level_start(levels + 1, 0), by_level(ne);
  for (std::size_t i = 0; i < ne; ++i) ++level_start[h.level(ElemId(static_cast<std::uint32_t>(i))) + 1];
  for (int k = 0; k < levels; ++k) level_start[k + 1] += level_start[k];
  {
    std::vector<std::uint32_t> pos(level_start.begin(), level_start.end() - 1);
    for (std::size_t i = 0; i < ne; ++i)
      by_level[pos[h.level(ElemId(static_cast<std::uint32_t>(i)))]++] = static_cast<std::uint32_t>(i);
  }
  level_entries_.resize(levels);
  std::vector<double> dsum(nv, 0.0), ssum(nv, 0.0), coarse_d(nv, 0.0), coarse_s(nv, 0.0);
  std::vector<std::uint8_t> in_vk(nv, 0);
  std::vector<std::array<double, D + 1>> dm, ds;  // diagonal contributions of this level's elements
  for (int k = 0; k < levels; ++k) {
    const std::uint32_t* first = by_level.data() + level_start[k];
    const std::size_t count = level_start[k + 1] - level_start[k];
    dm.resize(count);
    ds.resize(count);
    // The element matrices in parallel (a 3×3 inverse each), the sums below in element order.
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count, 4096),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        for (std::size_t n = r.begin(); n != r.end(); ++n) {
                          const auto& c = h.cell(ElemId(first[n]));
                          std::array<std::array<double, D>, D + 1> p;
                          for (int j = 0; j <= D; ++j) p[j] = h.point(c[j]);
                          if (gradient_weight == 0) {  // pure L2: no gradients (a 3×3 inverse) needed
                            const double m = P1Element<D>::mass_of(P1Element<D>::measure_of(p), 0, 0);
                            for (int j = 0; j <= D; ++j) {
                              ds[n][j] = 0;
                              dm[n][j] = m;
                            }
                            continue;
                          }
                          const P1Element<D> el(p);
                          for (int j = 0; j <= D; ++j) {
                            ds[n][j] = gradient_weight * el.stiffness(j, j);
                            dm[n][j] = el.mass(j, j) + ds[n][j];
                          }
                        }
                      });
    std::vector<std::uint32_t> vk;
    for (std::size_t n = 0; n < count; ++n) {
      const auto& c = h.cell(ElemId(first[n]));
      for (int j = 0; j <= D; ++j) {
        const std::uint32_t v = c[j].value;
        if (!in_vk[v]) {
          in_vk[v] = 1;
          vk.push_back(v);
        }
        dsum[v] += dm[n][j];
        ssum[v] += ds[n][j];
      }
    }
    std::sort(vk.begin(), vk.end());
    for (std::uint32_t v : vk) {
      const double d = dsum[v] + coarse_d[v], s = ssum[v] + coarse_s[v];
      MLFE_CHECK(d > 0);
      // Only the stiffness part of a level needs the multilevel correction: where the mass
      // dominates (elements coarse against the gradient length scale), the level-k hat
      // functions would just add a multiple of the identity on smooth modes and slow CG down.
      const double weight = s / d;
      if (weight > 1e-3) level_entries_[k].push_back({v, weight / d});
      dsum[v] = ssum[v] = 0;
      in_vk[v] = 0;
    }
    for (std::size_t n = 0; n < count; ++n) {
      const ElemId e(first[n]);
      if (!h.is_leaf(e)) continue;
      const auto& c = h.cell(e);
      for (int j = 0; j <= D; ++j) {
        coarse_d[c[j].value] += dm[n][j];
        coarse_s[c[j].value] += ds[n][j];
        fine_diag_[c[j].value] += dm[n][j];
      }
    }
  }
  for (double& d : fine_diag_) {
    MLFE_CHECK(d > 0);
    d = 1.0 / d;
  }
}

template <int D>
void BpxPreconditioner<D>::apply(const Vector& x, Vector& y) const {
  MLFE_CHECK(x.size() == n_);
  const int levels = static_cast<int>(level_entries_.size());
  Vector w = x;
  std::vector<std::vector<double>> c(levels);
  // Restriction, finest to coarsest: after folding the vertices of levels > k into their
  // parents, w holds (r, φ_v^k) for every vertex of level ≤ k.
  for (int k = levels - 1; k >= 0; --k) {
    const auto& ent = level_entries_[k];
    c[k].resize(ent.size());
    for (std::size_t i = 0; i < ent.size(); ++i) c[k][i] = w[ent[i].vertex] * ent[i].inv_diag;
    if (k == 0) break;
    for (std::uint32_t v : new_vertices_[k]) {
      const double half = 0.5 * w[v];
      w[parents_[v][0].value] += half;
      w[parents_[v][1].value] += half;
    }
  }
  // Prolongation, coarsest to finest.
  y = Vector::Zero(n_);
  for (int k = 0; k < levels; ++k) {
    if (k > 0)
      for (std::uint32_t v : new_vertices_[k])
        y[v] = 0.5 * (y[parents_[v][0].value] + y[parents_[v][1].value]);
    const auto& ent = level_entries_[k];
    for (std::size_t i = 0; i < ent.size(); ++i) y[ent[i].vertex] += c[k][i];
  }
  // The finest level: Jacobi on the leaf matrix (all of C for the pure L2 mass matrix, whose
  // diagonally scaled condition number is bounded on any shape-regular mesh).
  for (Eigen::Index i = 0; i < n_; ++i) y[i] += fine_diag_[i] * x[i];
}

template class BpxPreconditioner<2>;
template class BpxPreconditioner<3>;

}  // namespace mlfe
