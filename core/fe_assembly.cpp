// Assembly and error estimation for the L2 / H1 best approximation (Grosso, Lürig & Ertl 1997).
#include <mlfe/core/check.h>
#include <mlfe/core/fe_assembly.h>
#include <mlfe/core/p1_element.h>
#include <mlfe/core/sample_lattice.h>
#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <limits>
#include <utility>

namespace mlfe {

namespace {
template <int D>
std::array<std::array<double, D>, D + 1> element_points(const Hierarchy<D>& h, ElemId e) {
  std::array<std::array<double, D>, D + 1> p;
  const auto& c = h.cell(e);
  for (int i = 0; i <= D; ++i) p[i] = h.point(c[i]);
  return p;
}
}  // namespace

template <int D>
void compute_element_integrals_into(const Hierarchy<D>& h, const std::vector<ElemId>& elems, const Field& f,
                                    double max_sub_edge, bool gradients, const SampleLattice* lattice,
                                    ElementIntegrals<D>* out, IntegralIndex index) {
  const ScalarGrid* grid = lattice ? f.samples() : nullptr;
  MLFE_CHECK(!lattice || grid);
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, elems.size(), 16), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i)
          out[index == IntegralIndex::kLeafOrder ? i : elems[i].value] =
              grid ? sample_integrals<D>(element_points(h, elems[i]), *lattice, *grid, f, gradients)
                   : integrate_element<D>(element_points(h, elems[i]), f, max_sub_edge, gradients);
      });
}

template <int D>
std::vector<ElementIntegrals<D>> compute_element_integrals(const Hierarchy<D>& h,
                                                           const std::vector<ElemId>& elems, const Field& f,
                                                           double max_sub_edge, bool gradients,
                                                           const SampleLattice* lattice) {
  std::vector<ElementIntegrals<D>> out(elems.size());
  compute_element_integrals_into(h, elems, f, max_sub_edge, gradients, lattice, out.data(),
                                 IntegralIndex::kLeafOrder);
  return out;
}

template <int D>
SparseMatrix assemble_matrix(const Hierarchy<D>& h, const std::vector<ElemId>& leaves, double gradient_weight,
                             const std::vector<ElementIntegrals<D>>* integrals, IntegralIndex index) {
  // Row by row from a vertex → incident-element table instead of (D+1)² triplets per element:
  // 16 bytes per element instead of 256, and every row is summed by one thread in element
  // order, so the values do not depend on the thread count.
  const std::size_t nv = h.vertex_count(), ne = leaves.size();
  MLFE_CHECK(ne * (D + 1) < std::size_t(std::numeric_limits<std::uint32_t>::max()));
  std::vector<std::uint32_t> start(nv + 1, 0);
  for (ElemId e : leaves)
    for (VertexId v : h.cell(e)) ++start[v.value + 1];
  for (std::size_t v = 0; v < nv; ++v) start[v + 1] += start[v];
  std::vector<std::uint32_t> inc(start[nv]);  // leaf index * (D+1) + local corner
  {
    std::vector<std::uint32_t> pos(start.begin(), start.end() - 1);
    for (std::size_t i = 0; i < ne; ++i) {
      const auto& c = h.cell(leaves[i]);
      for (int a = 0; a <= D; ++a) inc[pos[c[a].value]++] = static_cast<std::uint32_t>(i * (D + 1) + a);
    }
  }
  // Element data once per element (not once per corner row), in leaf order so the row pass
  // reads it without going through the hierarchy: the corners, and for the pure mass matrix
  // only |T|, with a gradient term the (D+1)² entries.
  constexpr int kLocal = (D + 1) * (D + 1);
  // Least squares at the samples: the element matrices are the sampled ones.
  const bool sampled =
      integrals && !leaves.empty() &&
      (index == IntegralIndex::kLeafOrder ? (*integrals)[0] : (*integrals)[leaves[0].value]).sampled;
  auto sampled_at = [&](std::size_t i) -> const ElementIntegrals<D>& {
    return index == IntegralIndex::kLeafOrder ? (*integrals)[i] : (*integrals)[leaves[i].value];
  };
  // Sampled mass without a gradient term is read from the integrals in place (a copy would
  // be 128 bytes per leaf).
  const bool in_place = sampled && gradient_weight == 0;
  const bool with_grad = gradient_weight != 0 || sampled;
  std::vector<double> local(in_place ? 0 : with_grad ? ne * kLocal : ne);
  std::vector<std::array<std::uint32_t, D + 1>> corners(ne);
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, ne, 4096), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
          const auto& c = h.cell(leaves[i]);
          for (int a = 0; a <= D; ++a) corners[i][a] = c[a].value;
          if (!with_grad) {
            local[i] = P1Element<D>::measure_of(element_points(h, leaves[i]));
            continue;
          }
          if (in_place) {
            MLFE_CHECK(sampled_at(i).sampled);
            continue;
          }
          const P1Element<D> el(element_points(h, leaves[i]));
          for (int a = 0; a <= D; ++a)
            for (int b = 0; b <= D; ++b)
              local[i * kLocal + a * (D + 1) + b] = (sampled ? sampled_at(i).mass_at(a, b) : el.mass(a, b)) +
                                                    gradient_weight * el.stiffness(a, b);
        }
      });
  // Rows in blocks, one pass: a per-thread slot array maps a column to its place in the
  // current row (no sort of all incidences, no binary search per entry); the blocks' rows are
  // then copied into the matrix in order.
  constexpr std::size_t kBlock = 2048;
  constexpr std::uint32_t kNone = std::numeric_limits<std::uint32_t>::max();
  const std::size_t nblocks = (nv + kBlock - 1) / kBlock;
  struct Block {
    std::vector<int> cols;
    std::vector<double> vals;
  };
  std::vector<Block> blocks(nblocks);
  std::vector<int> row_len(nv, 0);
  tbb::enumerable_thread_specific<std::vector<std::uint32_t>> slots_tls;
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, nblocks, 1), [&](const tbb::blocked_range<std::size_t>& r) {
        auto& slot = slots_tls.local();
        if (slot.size() != nv) slot.assign(nv, kNone);
        std::vector<std::pair<int, double>> row;
        for (std::size_t b = r.begin(); b != r.end(); ++b) {
          auto& blk = blocks[b];
          for (std::size_t v = b * kBlock, vend = std::min(nv, v + kBlock); v < vend; ++v) {
            row.clear();
            for (std::uint32_t k = start[v]; k < start[v + 1]; ++k) {
              const std::size_t i = inc[k] / (D + 1);
              const int a = static_cast<int>(inc[k] % (D + 1));
              const auto& c = corners[i];
              for (int bb = 0; bb <= D; ++bb) {
                const double x = in_place    ? sampled_at(i).mass_at(a, bb)
                                 : with_grad ? local[i * kLocal + a * (D + 1) + bb]
                                             : P1Element<D>::mass_of(local[i], a, bb);
                std::uint32_t& s = slot[c[bb]];
                if (s == kNone) {
                  s = static_cast<std::uint32_t>(row.size());
                  row.emplace_back(int(c[bb]), x);
                } else {
                  row[s].second += x;
                }
              }
            }
            for (const auto& e : row) slot[e.first] = kNone;
            std::sort(row.begin(), row.end(), [](const auto& p, const auto& q) { return p.first < q.first; });
            for (const auto& e : row) {
              blk.cols.push_back(e.first);
              blk.vals.push_back(e.second);
            }
            row_len[v] = static_cast<int>(row.size());
          }
        }
      });
  const int n = static_cast<int>(nv);
  SparseMatrix m(n, n);
  int* outer = m.outerIndexPtr();
  outer[0] = 0;
  for (std::size_t v = 0; v < nv; ++v) outer[v + 1] = outer[v] + row_len[v];
  m.resizeNonZeros(outer[nv]);
  int* inner = m.innerIndexPtr();
  double* val = m.valuePtr();
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nblocks, 1),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t b = r.begin(); b != r.end(); ++b) {
                        const int at = outer[b * kBlock];
                        std::copy(blocks[b].cols.begin(), blocks[b].cols.end(), inner + at);
                        std::copy(blocks[b].vals.begin(), blocks[b].vals.end(), val + at);
                        std::vector<int>().swap(blocks[b].cols);
                        std::vector<double>().swap(blocks[b].vals);
                      }
                    });
  m.finalize();
  return m;
}

namespace {
// integrals[i] or integrals[leaves[i]], after checking that every index is in range.
template <int D>
struct IntegralAccess {
  const std::vector<ElementIntegrals<D>>& integrals;
  const std::vector<ElemId>& leaves;
  IntegralIndex index;
  IntegralAccess(const std::vector<ElementIntegrals<D>>& in, const std::vector<ElemId>& l, IntegralIndex ix,
                 std::size_t element_count)
      : integrals(in), leaves(l), index(ix) {
    if (index == IntegralIndex::kLeafOrder)
      MLFE_CHECK(integrals.size() == leaves.size());
    else
      MLFE_CHECK(integrals.size() >= element_count);
  }
  const ElementIntegrals<D>& operator[](std::size_t i) const {
    return integrals[index == IntegralIndex::kLeafOrder ? i : leaves[i].value];
  }
};
}  // namespace

template <int D>
Vector assemble_load(const Hierarchy<D>& h, const std::vector<ElemId>& leaves,
                     const std::vector<ElementIntegrals<D>>& integrals_in, double gradient_weight,
                     IntegralIndex index) {
  const IntegralAccess<D> integrals(integrals_in, leaves, index, h.element_count());
  Vector f = Vector::Zero(static_cast<Eigen::Index>(h.vertex_count()));
  for (std::size_t i = 0; i < leaves.size(); ++i) {
    const auto& c = h.cell(leaves[i]);
    const auto& in = integrals[i];
    if (gradient_weight != 0) {
      const P1Element<D> el(element_points(h, leaves[i]));
      for (int a = 0; a <= D; ++a) {
        double g = 0;
        for (int k = 0; k < D; ++k) g += el.grad[a][k] * in.grad[k];
        f[c[a].value] += in.fphi[a] + gradient_weight * g;
      }
    } else {
      for (int a = 0; a <= D; ++a) f[c[a].value] += in.fphi[a];
    }
  }
  return f;
}

template <int D>
std::vector<double> element_errors(const Hierarchy<D>& h, const std::vector<ElemId>& leaves,
                                   const std::vector<ElementIntegrals<D>>& integrals_in, const Vector& u,
                                   double gradient_weight, IntegralIndex index) {
  const IntegralAccess<D> integrals(integrals_in, leaves, index, h.element_count());
  std::vector<double> err(leaves.size());
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, leaves.size(), 1024), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
          const auto& c = h.cell(leaves[i]);
          const auto& in = integrals[i];
          const auto pts = element_points(h, leaves[i]);
          // The gradients (a 3×3 inverse) only for the H1 term.
          const double measure = P1Element<D>::measure_of(pts);
          double uu[D + 1];
          for (int a = 0; a <= D; ++a) uu[a] = u[c[a].value];
          double cross = 0, quad = 0;
          for (int a = 0; a <= D; ++a) {
            cross += uu[a] * in.fphi[a];
            for (int b = 0; b <= D; ++b)
              quad += uu[a] * uu[b] * (in.sampled ? in.mass_at(a, b) : P1Element<D>::mass_of(measure, a, b));
          }
          // ∫(f-u)² = ∫f² - 2∫fu + ∫u²; cancellation can leave a tiny negative.
          double e = in.f2 - 2 * cross + quad;
          if (gradient_weight != 0) {
            const P1Element<D> el(pts);
            double gu[D] = {};
            for (int a = 0; a <= D; ++a)
              for (int k = 0; k < D; ++k) gu[k] += uu[a] * el.grad[a][k];
            double g = in.grad2;
            for (int k = 0; k < D; ++k) g += -2 * gu[k] * in.grad[k] + gu[k] * gu[k] * el.measure;
            e += gradient_weight * std::max(g, 0.0);
          }
          err[i] = std::max(e, 0.0);
        }
      });
  return err;
}

template std::vector<ElementIntegrals<2>> compute_element_integrals<2>(const Hierarchy<2>&,
                                                                       const std::vector<ElemId>&,
                                                                       const Field&, double, bool,
                                                                       const SampleLattice*);
template std::vector<ElementIntegrals<3>> compute_element_integrals<3>(const Hierarchy<3>&,
                                                                       const std::vector<ElemId>&,
                                                                       const Field&, double, bool,
                                                                       const SampleLattice*);
template void compute_element_integrals_into<2>(const Hierarchy<2>&, const std::vector<ElemId>&, const Field&,
                                                double, bool, const SampleLattice*, ElementIntegrals<2>*,
                                                IntegralIndex);
template void compute_element_integrals_into<3>(const Hierarchy<3>&, const std::vector<ElemId>&, const Field&,
                                                double, bool, const SampleLattice*, ElementIntegrals<3>*,
                                                IntegralIndex);
template SparseMatrix assemble_matrix<2>(const Hierarchy<2>&, const std::vector<ElemId>&, double,
                                         const std::vector<ElementIntegrals<2>>*, IntegralIndex);
template SparseMatrix assemble_matrix<3>(const Hierarchy<3>&, const std::vector<ElemId>&, double,
                                         const std::vector<ElementIntegrals<3>>*, IntegralIndex);
template Vector assemble_load<2>(const Hierarchy<2>&, const std::vector<ElemId>&,
                                 const std::vector<ElementIntegrals<2>>&, double, IntegralIndex);
template Vector assemble_load<3>(const Hierarchy<3>&, const std::vector<ElemId>&,
                                 const std::vector<ElementIntegrals<3>>&, double, IntegralIndex);
template std::vector<double> element_errors<2>(const Hierarchy<2>&, const std::vector<ElemId>&,
                                               const std::vector<ElementIntegrals<2>>&, const Vector&, double,
                                               IntegralIndex);
template std::vector<double> element_errors<3>(const Hierarchy<3>&, const std::vector<ElemId>&,
                                               const std::vector<ElementIntegrals<3>>&, const Vector&, double,
                                               IntegralIndex);

}  // namespace mlfe
