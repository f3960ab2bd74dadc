// Assembly and error estimation for the L2 / H1 best approximation (Grosso, Lürig & Ertl 1997).
#include "core/fe_assembly.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>

#include "core/check.h"
#include "core/p1_element.h"

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
std::vector<ElementIntegrals<D>> compute_element_integrals(const Hierarchy<D>& h,
                                                           const std::vector<ElemId>& elems,
                                                           const Field& f, double max_sub_edge,
                                                           bool gradients) {
  std::vector<ElementIntegrals<D>> out(elems.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, elems.size(), 16),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t i = r.begin(); i != r.end(); ++i)
                        out[i] = integrate_element<D>(element_points(h, elems[i]), f, max_sub_edge, gradients);
                    });
  return out;
}

template <int D>
SparseMatrix assemble_matrix(const Hierarchy<D>& h, const std::vector<ElemId>& leaves,
                             double gradient_weight) {
  constexpr int kLocal = (D + 1) * (D + 1);
  std::vector<Eigen::Triplet<double, int>> trip(leaves.size() * kLocal);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, leaves.size(), 1024),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t i = r.begin(); i != r.end(); ++i) {
                        const auto& c = h.cell(leaves[i]);
                        const P1Element<D> el(element_points(h, leaves[i]));
                        for (int a = 0; a <= D; ++a)
                          for (int b = 0; b <= D; ++b) {
                            double v = el.mass(a, b);
                            if (gradient_weight != 0) v += gradient_weight * el.stiffness(a, b);
                            trip[i * kLocal + a * (D + 1) + b] = {int(c[a].value), int(c[b].value), v};
                          }
                      }
                    });
  const int n = static_cast<int>(h.vertex_count());
  SparseMatrix m(n, n);
  m.setFromTriplets(trip.begin(), trip.end());  // sums duplicates in list order: deterministic
  return m;
}

template <int D>
Vector assemble_load(const Hierarchy<D>& h, const std::vector<ElemId>& leaves,
                     const std::vector<ElementIntegrals<D>>& integrals, double gradient_weight) {
  MLFE_CHECK(integrals.size() == leaves.size());
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
                                   const std::vector<ElementIntegrals<D>>& integrals,
                                   const Vector& u, double gradient_weight) {
  MLFE_CHECK(integrals.size() == leaves.size());
  std::vector<double> err(leaves.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, leaves.size(), 1024),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t i = r.begin(); i != r.end(); ++i) {
                        const auto& c = h.cell(leaves[i]);
                        const auto& in = integrals[i];
                        const P1Element<D> el(element_points(h, leaves[i]));
                        double uu[D + 1];
                        for (int a = 0; a <= D; ++a) uu[a] = u[c[a].value];
                        double cross = 0, quad = 0;
                        for (int a = 0; a <= D; ++a) {
                          cross += uu[a] * in.fphi[a];
                          for (int b = 0; b <= D; ++b) quad += uu[a] * uu[b] * el.mass(a, b);
                        }
                        // ∫(f-u)² = ∫f² - 2∫fu + ∫u²; cancellation can leave a tiny negative.
                        double e = in.f2 - 2 * cross + quad;
                        if (gradient_weight != 0) {
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

template std::vector<ElementIntegrals<2>> compute_element_integrals<2>(const Hierarchy<2>&, const std::vector<ElemId>&, const Field&, double, bool);
template std::vector<ElementIntegrals<3>> compute_element_integrals<3>(const Hierarchy<3>&, const std::vector<ElemId>&, const Field&, double, bool);
template SparseMatrix assemble_matrix<2>(const Hierarchy<2>&, const std::vector<ElemId>&, double);
template SparseMatrix assemble_matrix<3>(const Hierarchy<3>&, const std::vector<ElemId>&, double);
template Vector assemble_load<2>(const Hierarchy<2>&, const std::vector<ElemId>&, const std::vector<ElementIntegrals<2>>&, double);
template Vector assemble_load<3>(const Hierarchy<3>&, const std::vector<ElemId>&, const std::vector<ElementIntegrals<3>>&, double);
template std::vector<double> element_errors<2>(const Hierarchy<2>&, const std::vector<ElemId>&, const std::vector<ElementIntegrals<2>>&, const Vector&, double);
template std::vector<double> element_errors<3>(const Hierarchy<3>&, const std::vector<ElemId>&, const std::vector<ElementIntegrals<3>>&, const Vector&, double);

}  // namespace mlfe
