// Assembly and error estimation for the L2 / H1 best approximation (Grosso, Lürig & Ertl 1997).
#include <mlfe/core/base/check.h>
#include <mlfe/core/fem/fe_assembly.h>
#include <mlfe/core/fem/p1_element.h>
#include <mlfe/core/fem/sample_lattice.h>
#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <limits>
#include <utility>

#include "base/counting_sort.h"

namespace mlfe {

template <int D>
void compute_element_integrals_into(const Hierarchy<D>& h, const std::vector<ElemId>& elems, const Field& f,
                                    double max_sub_edge, ElementGradients<D>* gradients,
                                    const SampleLattice* lattice, ElementIntegrals<D>* out,
                                    IntegralIndex index) {
  const ScalarGrid* grid = lattice ? f.samples() : nullptr;
  MLFE_CHECK(!lattice || grid);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, elems.size(), 16),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t i = r.begin(); i != r.end(); ++i) {
                        const std::size_t at = index == IntegralIndex::kLeafOrder ? i : elems[i].value;
                        ElementGradients<D>* g = gradients ? gradients + at : nullptr;
                        out[at] = grid ? sample_integrals<D>(h.corner_points(elems[i]), *lattice, *grid, f, g)
                                       : integrate_element<D>(h.corner_points(elems[i]), f, max_sub_edge, g);
                      }
                    });
}

template <int D>
std::vector<ElementIntegrals<D>> compute_element_integrals(const Hierarchy<D>& h,
                                                           const std::vector<ElemId>& elems, const Field& f,
                                                           double max_sub_edge,
                                                           std::vector<ElementGradients<D>>* gradients,
                                                           const SampleLattice* lattice) {
  std::vector<ElementIntegrals<D>> out(elems.size());
  if (gradients) gradients->assign(elems.size(), ElementGradients<D>());
  compute_element_integrals_into(h, elems, f, max_sub_edge, gradients ? gradients->data() : nullptr, lattice,
                                 out.data(), IntegralIndex::kLeafOrder);
  return out;
}

namespace {
constexpr std::uint32_t kNone = std::numeric_limits<std::uint32_t>::max();
constexpr std::size_t kBlock = 2048;  // rows per task of the row pass

// The vertex → incidence table (ws.start, ws.inc): per vertex, key(i) * (D+1) + corner for the
// leaves i it is a corner of, in leaf order. A counting sort over contiguous chunks of leaves,
// each counted and filled by one task with its own counters; a vertex's incidences come chunk
// by chunk, so their order (the leaves') does not depend on the chunking or the thread count.
template <int D, class Key>
void build_incidences(const Hierarchy<D>& h, const std::vector<ElemId>& leaves, Key key,
                      AssemblyWorkspace& ws) {
  const std::size_t nv = h.vertex_count(), ne = leaves.size();
  const std::size_t chunks = std::clamp<std::size_t>(ne / 65536, 1, 4);
  const std::size_t per = (ne + chunks - 1) / chunks;
  ws.counts.resize(chunks * nv);
  tbb::parallel_for(std::size_t(0), chunks, [&](std::size_t c) {
    std::uint32_t* cnt = ws.counts.data() + c * nv;
    std::fill(cnt, cnt + nv, 0u);
    for (std::size_t i = c * per, end = std::min(ne, i + per); i < end; ++i)
      for (VertexId v : h.cell(leaves[i])) ++cnt[v.value];
  });
  // Per vertex, chunk by chunk: the counts become each chunk's first slot.
  ws.start.resize(nv + 1);
  const std::uint32_t at = detail::chunked_offsets(ws.counts.data(), chunks, nv, ws.start.data());
  if (ws.inc.capacity() < at) {
    ws.inc = AssemblyWorkspace::Array<std::uint32_t>();
    ws.inc.reserve(2 * std::size_t(at));  // the next iteration's table in the same pages
  }
  ws.inc.resize(at);
  tbb::parallel_for(std::size_t(0), chunks, [&](std::size_t c) {
    std::uint32_t* pos = ws.counts.data() + c * nv;
    for (std::size_t i = c * per, end = std::min(ne, i + per); i < end; ++i) {
      const auto& cell = h.cell(leaves[i]);
      for (int a = 0; a <= D; ++a)
        ws.inc[pos[cell[a].value]++] = static_cast<std::uint32_t>(key(i) * (D + 1) + std::size_t(a));
    }
  });
}

// Sorts a short row by column (insertion sort: rows hold 7-30 entries; columns are distinct,
// so the result is the same as any sort's).
void sort_row(std::vector<std::pair<int, double>>& row) {
  for (std::size_t j = 1; j < row.size(); ++j) {
    const auto x = row[j];
    std::size_t k = j;
    for (; k > 0 && row[k - 1].first > x.first; --k) row[k] = row[k - 1];
    row[k] = x;
  }
}

// One pass over the rows from the incidence table, in blocks of kBlock vertices. A
// per-thread slot array maps a column to its place in the current row (no sort of all
// incidences, no binary search per entry). kValues false: each row's length into outer[v + 1].
// kValues true: each row summed in leaf order by one thread (the values do not depend on the
// thread count), sorted by column and written at outer[v]. `src` gives an incidence key's
// corners, entries and load, and prefetches them a few incidences ahead (the element data is
// read at random; waiting for it was most of this pass).
template <bool kValues, int D, class Source>
void row_pass(std::size_t nv, const Source& src, const AssemblyWorkspace& ws, int* outer, int* inner,
              double* val, double* rhs) {
  const std::size_t nblocks = (nv + kBlock - 1) / kBlock;
  tbb::enumerable_thread_specific<std::vector<std::uint32_t>> slots_tls;
  const std::uint32_t* start = ws.start.data();
  const std::uint32_t* inc = ws.inc.data();
  constexpr std::uint32_t kAhead = 6;
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, nblocks, 1), [&](const tbb::blocked_range<std::size_t>& r) {
        auto& slot = slots_tls.local();
        if (slot.size() != nv) slot.assign(nv, kNone);
        std::vector<std::pair<int, double>> row;  // (column, value); only the columns in pass 1
        for (std::size_t b = r.begin(); b != r.end(); ++b) {
          const std::size_t vend = std::min(nv, (b + 1) * kBlock);
          const std::uint32_t kend = start[vend];
          for (std::uint32_t k = start[b * kBlock]; k < std::min(kend, start[b * kBlock] + kAhead); ++k)
            src.prefetch(inc[k] / (D + 1), kValues);
          for (std::size_t v = b * kBlock; v < vend; ++v) {
            row.clear();
            double load = 0;
            for (std::uint32_t k = start[v]; k < start[v + 1]; ++k) {
              if (k + kAhead < kend) src.prefetch(inc[k + kAhead] / (D + 1), kValues);
              const std::uint32_t key = inc[k] / (D + 1);
              const int a = static_cast<int>(inc[k] % (D + 1));
              const auto& c = src.corners(key);
              if (kValues && rhs) load += src.load(key, a);
              for (int bb = 0; bb <= D; ++bb) {
                const double x = kValues ? src.entry(key, a, bb) : 0.0;
                std::uint32_t& s = slot[c[bb].value];
                if (s == kNone) {
                  s = static_cast<std::uint32_t>(row.size());
                  row.emplace_back(int(c[bb].value), x);
                } else if (kValues) {
                  row[s].second += x;
                }
              }
            }
            for (const auto& e : row) slot[e.first] = kNone;
            if (!kValues) {
              outer[v + 1] = static_cast<int>(row.size());
              continue;
            }
            sort_row(row);
            MLFE_CHECK(row.size() == std::size_t(outer[v + 1] - outer[v]));
            for (std::size_t j = 0; j < row.size(); ++j) {
              inner[std::size_t(outer[v]) + j] = row[j].first;
              val[std::size_t(outer[v]) + j] = row[j].second;
            }
            if (rhs) rhs[v] = load;
          }
        }
      });
}

// M (and F when rhs is given) in two row passes: the first counts each row's columns, the
// second, with the rows' places known, writes them into m's storage directly (no copy of the
// whole matrix in between). m's storage is reused when it has room.
template <int D, class Source>
void row_passes(std::size_t nv, const Source& src, const AssemblyWorkspace& ws, SparseMatrix& m,
                double* rhs) {
  const int n = static_cast<int>(nv);
  m.resize(n, n);  // keeps the non-zeros' storage
  int* outer = m.outerIndexPtr();
  row_pass<false, D>(nv, src, ws, outer, nullptr, nullptr, nullptr);
  outer[0] = 0;
  for (std::size_t v = 0; v < nv; ++v) outer[v + 1] += outer[v];
  const auto nnz = static_cast<Eigen::Index>(outer[nv]);
  if (m.data().allocatedSize() < nnz) m.data().reserve(2 * nnz);  // next time in the same pages
  m.resizeNonZeros(nnz);
  row_pass<true, D>(nv, src, ws, outer, m.innerIndexPtr(), m.valuePtr(), rhs);
  m.finalize();
}

// Row pass sources. Sampled: the element's sampled mass and load read from the integrals in
// place (by element id: keys are element ids and the leaves are not looked up; by leaf order:
// keys are leaf indices).
template <int D, bool kById>
struct SampledSource {
  const Hierarchy<D>& h;
  const std::vector<ElemId>& leaves;
  const ElementIntegrals<D>* in;
  ElemId elem(std::uint32_t key) const { return kById ? ElemId(key) : leaves[key]; }
  const typename Hierarchy<D>::Cell& corners(std::uint32_t key) const { return h.cell(elem(key)); }
  double entry(std::uint32_t key, int a, int b) const {
    MLFE_CHECK(b != 0 || in[key].sampled);  // every leaf's, not only the first's
    return in[key].mass_at(a, b);
  }
  double load(std::uint32_t key, int a) const { return in[key].fphi[a]; }
  void prefetch(std::uint32_t key, bool values) const {
    __builtin_prefetch(&h.cell(elem(key)));
    if (!values) return;
    __builtin_prefetch(&in[key].fphi[0]);  // the 112 bytes of fphi and mass: 2-3 lines
    __builtin_prefetch(&in[key].mass[3]);
    __builtin_prefetch(&in[key].mass.back());
  }
};

// Exact P1 matrices, keys are leaf indices: `local` holds |T| per leaf (pure mass) or its
// (D+1)² entries; the load, if any, comes from the integrals.
template <int D, bool kMeasureOnly>
struct LocalSource {
  static constexpr int kLocal = (D + 1) * (D + 1);
  const Hierarchy<D>& h;
  const std::vector<ElemId>& leaves;
  const std::vector<double>& local;
  const std::vector<ElementIntegrals<D>>* integrals;
  IntegralIndex index;
  const typename Hierarchy<D>::Cell& corners(std::uint32_t key) const { return h.cell(leaves[key]); }
  double entry(std::uint32_t key, int a, int b) const {
    return kMeasureOnly ? P1Element<D>::mass_of(local[key], a, b)
                        : local[std::size_t(key) * kLocal + std::size_t(a * (D + 1) + b)];
  }
  double load(std::uint32_t key, int a) const {
    return (*integrals)[index == IntegralIndex::kLeafOrder ? key : leaves[key].value].fphi[a];
  }
  void prefetch(std::uint32_t key, bool) const { __builtin_prefetch(&h.cell(leaves[key])); }
};

// Assembly from the element data: the sampled integrals in place, or the exact P1 matrices
// (with the gradient term and/or sampled masses copied per leaf).
template <int D>
void assemble_rows(const Hierarchy<D>& h, const std::vector<ElemId>& leaves, double gradient_weight,
                   const std::vector<ElementIntegrals<D>>* integrals, IntegralIndex index,
                   AssemblyWorkspace& ws, SparseMatrix& m, double* rhs) {
  const std::size_t nv = h.vertex_count(), ne = leaves.size();
  MLFE_CHECK(ne * (D + 1) < std::size_t(std::numeric_limits<std::uint32_t>::max()));
  constexpr int kLocal = (D + 1) * (D + 1);
  // Least squares at the samples: the element matrices are the sampled ones.
  const bool by_id = index == IntegralIndex::kElementId;
  const bool sampled = integrals && !leaves.empty() && (*integrals)[by_id ? leaves[0].value : 0].sampled;
  auto sampled_at = [&](std::size_t i) -> const ElementIntegrals<D>& {
    return by_id ? (*integrals)[leaves[i].value] : (*integrals)[i];
  };
  if (sampled && gradient_weight == 0) {
    // Sampled mass without a gradient term, read in place (a copy would be 128 bytes per leaf).
    if (by_id) {
      MLFE_CHECK(h.element_count() * (D + 1) < std::size_t(std::numeric_limits<std::uint32_t>::max()));
      build_incidences(
          h, leaves, [&](std::size_t i) { return std::size_t(leaves[i].value); }, ws);
      row_passes<D>(nv, SampledSource<D, true>{h, leaves, integrals->data()}, ws, m, rhs);
    } else {
      build_incidences(
          h, leaves, [](std::size_t i) { return i; }, ws);
      row_passes<D>(nv, SampledSource<D, false>{h, leaves, integrals->data()}, ws, m, rhs);
    }
    return;
  }
  // Element data once per element (not once per corner row), in leaf order: for the pure mass
  // matrix only |T|, with a gradient term (or sampled masses) the (D+1)² entries.
  const bool with_grad = gradient_weight != 0 || sampled;
  std::vector<double> local(with_grad ? ne * kLocal : ne);
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, ne, 4096), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
          if (!with_grad) {
            local[i] = P1Element<D>::measure_of(h.corner_points(leaves[i]));
            continue;
          }
          const P1Element<D> el(h.corner_points(leaves[i]));
          for (int a = 0; a <= D; ++a)
            for (int b = 0; b <= D; ++b)
              local[i * kLocal + a * (D + 1) + b] = (sampled ? sampled_at(i).mass_at(a, b) : el.mass(a, b)) +
                                                    gradient_weight * el.stiffness(a, b);
        }
      });
  build_incidences(
      h, leaves, [](std::size_t i) { return i; }, ws);
  if (with_grad)
    row_passes<D>(nv, LocalSource<D, false>{h, leaves, local, integrals, index}, ws, m, rhs);
  else
    row_passes<D>(nv, LocalSource<D, true>{h, leaves, local, integrals, index}, ws, m, rhs);
}

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
  // The H1 sums of leaves[i], from `gradients` (indexed like the integrals; CHECKed to be there).
  static const ElementGradients<D>* gradients_of(const std::vector<ElementGradients<D>>* gradients,
                                                 const std::vector<ElementIntegrals<D>>& in) {
    MLFE_CHECK_MSG(gradients && gradients->size() == in.size(), "the H1 term needs the gradient sums");
    return gradients->data();
  }
  std::size_t at(std::size_t i) const { return index == IntegralIndex::kLeafOrder ? i : leaves[i].value; }
};
}  // namespace

template <int D>
SparseMatrix assemble_matrix(const Hierarchy<D>& h, const std::vector<ElemId>& leaves, double gradient_weight,
                             const std::vector<ElementIntegrals<D>>* integrals, IntegralIndex index) {
  AssemblyWorkspace ws;
  SparseMatrix m;
  assemble_rows(h, leaves, gradient_weight, integrals, index, ws, m, nullptr);
  return m;
}

template <int D>
void assemble_system(const Hierarchy<D>& h, const std::vector<ElemId>& leaves, double gradient_weight,
                     const std::vector<ElementIntegrals<D>>& integrals, IntegralIndex index,
                     AssemblyWorkspace& ws, SparseMatrix& m, Vector& rhs,
                     const std::vector<ElementGradients<D>>* gradients) {
  const IntegralAccess<D> checked(integrals, leaves, index, h.element_count());  // CHECKs the indices
  const bool load_in_rows = gradient_weight == 0;
  if (load_in_rows) rhs.resize(static_cast<Eigen::Index>(h.vertex_count()));
  assemble_rows(h, leaves, gradient_weight, &integrals, index, ws, m, load_in_rows ? rhs.data() : nullptr);
  if (!load_in_rows) rhs = assemble_load(h, leaves, integrals, gradient_weight, index, gradients);
}

template <int D>
Vector assemble_load(const Hierarchy<D>& h, const std::vector<ElemId>& leaves,
                     const std::vector<ElementIntegrals<D>>& integrals_in, double gradient_weight,
                     IntegralIndex index, const std::vector<ElementGradients<D>>* gradients) {
  const IntegralAccess<D> integrals(integrals_in, leaves, index, h.element_count());
  const ElementGradients<D>* grads =
      gradient_weight != 0 ? IntegralAccess<D>::gradients_of(gradients, integrals_in) : nullptr;
  Vector f = Vector::Zero(static_cast<Eigen::Index>(h.vertex_count()));
  for (std::size_t i = 0; i < leaves.size(); ++i) {
    const auto& c = h.cell(leaves[i]);
    const auto& in = integrals[i];
    if (gradient_weight != 0) {
      const P1Element<D> el(h.corner_points(leaves[i]));
      const auto& gs = grads[integrals.at(i)];
      for (int a = 0; a <= D; ++a) {
        double g = 0;
        for (int k = 0; k < D; ++k) g += el.grad[a][k] * gs.grad[k];
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
                                   double gradient_weight, IntegralIndex index,
                                   const std::vector<ElementGradients<D>>* gradients) {
  const IntegralAccess<D> integrals(integrals_in, leaves, index, h.element_count());
  const ElementGradients<D>* grads =
      gradient_weight != 0 ? IntegralAccess<D>::gradients_of(gradients, integrals_in) : nullptr;
  std::vector<double> err(leaves.size());
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, leaves.size(), 1024), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
          const auto& c = h.cell(leaves[i]);
          const auto& in = integrals[i];
          const auto pts = h.corner_points(leaves[i]);
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
            const auto& gs = grads[integrals.at(i)];
            double g = gs.grad2;
            for (int k = 0; k < D; ++k) g += -2 * gu[k] * gs.grad[k] + gu[k] * gu[k] * el.measure;
            e += gradient_weight * std::max(g, 0.0);
          }
          err[i] = std::max(e, 0.0);
        }
      });
  return err;
}

template std::vector<ElementIntegrals<2>> compute_element_integrals<2>(const Hierarchy<2>&,
                                                                       const std::vector<ElemId>&,
                                                                       const Field&, double,
                                                                       std::vector<ElementGradients<2>>*,
                                                                       const SampleLattice*);
template std::vector<ElementIntegrals<3>> compute_element_integrals<3>(const Hierarchy<3>&,
                                                                       const std::vector<ElemId>&,
                                                                       const Field&, double,
                                                                       std::vector<ElementGradients<3>>*,
                                                                       const SampleLattice*);
template void compute_element_integrals_into<2>(const Hierarchy<2>&, const std::vector<ElemId>&, const Field&,
                                                double, ElementGradients<2>*, const SampleLattice*,
                                                ElementIntegrals<2>*, IntegralIndex);
template void compute_element_integrals_into<3>(const Hierarchy<3>&, const std::vector<ElemId>&, const Field&,
                                                double, ElementGradients<3>*, const SampleLattice*,
                                                ElementIntegrals<3>*, IntegralIndex);
template SparseMatrix assemble_matrix<2>(const Hierarchy<2>&, const std::vector<ElemId>&, double,
                                         const std::vector<ElementIntegrals<2>>*, IntegralIndex);
template SparseMatrix assemble_matrix<3>(const Hierarchy<3>&, const std::vector<ElemId>&, double,
                                         const std::vector<ElementIntegrals<3>>*, IntegralIndex);
template void assemble_system<2>(const Hierarchy<2>&, const std::vector<ElemId>&, double,
                                 const std::vector<ElementIntegrals<2>>&, IntegralIndex, AssemblyWorkspace&,
                                 SparseMatrix&, Vector&, const std::vector<ElementGradients<2>>*);
template void assemble_system<3>(const Hierarchy<3>&, const std::vector<ElemId>&, double,
                                 const std::vector<ElementIntegrals<3>>&, IntegralIndex, AssemblyWorkspace&,
                                 SparseMatrix&, Vector&, const std::vector<ElementGradients<3>>*);
template Vector assemble_load<2>(const Hierarchy<2>&, const std::vector<ElemId>&,
                                 const std::vector<ElementIntegrals<2>>&, double, IntegralIndex,
                                 const std::vector<ElementGradients<2>>*);
template Vector assemble_load<3>(const Hierarchy<3>&, const std::vector<ElemId>&,
                                 const std::vector<ElementIntegrals<3>>&, double, IntegralIndex,
                                 const std::vector<ElementGradients<3>>*);
template std::vector<double> element_errors<2>(const Hierarchy<2>&, const std::vector<ElemId>&,
                                               const std::vector<ElementIntegrals<2>>&, const Vector&, double,
                                               IntegralIndex, const std::vector<ElementGradients<2>>*);
template std::vector<double> element_errors<3>(const Hierarchy<3>&, const std::vector<ElemId>&,
                                               const std::vector<ElementIntegrals<3>>&, const Vector&, double,
                                               IntegralIndex, const std::vector<ElementGradients<3>>*);

}  // namespace mlfe
