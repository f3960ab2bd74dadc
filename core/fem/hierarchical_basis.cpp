// Hierarchical basis (Yserentant 1986); see hierarchical_basis.h.
#include <mlfe/core/base/check.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/fem/hierarchical_basis.h>

namespace mlfe {

template <int D>
std::vector<double> hierarchical_decompose(const Hierarchy<D>& h, const std::vector<double>& nodal) {
  if (nodal.size() != h.vertex_count())
    throw Error("hierarchical_decompose: " + std::to_string(nodal.size()) + " values for " +
                std::to_string(h.vertex_count()) + " vertices");
  std::vector<double> s(nodal.size());
  for (std::size_t v = 0; v < nodal.size(); ++v) {
    const auto& p = h.vertex_parents(VertexId(static_cast<std::uint32_t>(v)));
    s[v] = p[0].valid() ? nodal[v] - 0.5 * (nodal[p[0].value] + nodal[p[1].value]) : nodal[v];
  }
  return s;
}

template <int D>
std::vector<double> hierarchical_reconstruct(const Hierarchy<D>& h, const std::vector<double>& surplus,
                                             int max_level) {
  if (surplus.size() != h.vertex_count())
    throw Error("hierarchical_reconstruct: " + std::to_string(surplus.size()) + " values for " +
                std::to_string(h.vertex_count()) + " vertices");
  std::vector<double> u(surplus.size());
  // Parents always have smaller ids than their midpoint, so one pass in id order suffices.
  for (std::size_t v = 0; v < u.size(); ++v) {
    const VertexId id(static_cast<std::uint32_t>(v));
    const auto& p = h.vertex_parents(id);
    if (!p[0].valid()) {
      u[v] = surplus[v];
      continue;
    }
    const double base = 0.5 * (u[p[0].value] + u[p[1].value]);
    u[v] = h.vertex_level(id) <= max_level ? base + surplus[v] : base;
  }
  return u;
}

template <int D>
void prolongate_to_new_vertices(const Hierarchy<D>& h, std::vector<double>& values) {
  const std::size_t old = values.size();
  values.resize(h.vertex_count());
  for (std::size_t v = old; v < values.size(); ++v) {
    const auto& p = h.vertex_parents(VertexId(static_cast<std::uint32_t>(v)));
    MLFE_CHECK(p[0].valid());
    values[v] = 0.5 * (values[p[0].value] + values[p[1].value]);
  }
}

template std::vector<double> hierarchical_decompose<2>(const Hierarchy<2>&, const std::vector<double>&);
template std::vector<double> hierarchical_decompose<3>(const Hierarchy<3>&, const std::vector<double>&);
template std::vector<double> hierarchical_reconstruct<2>(const Hierarchy<2>&, const std::vector<double>&,
                                                         int);
template std::vector<double> hierarchical_reconstruct<3>(const Hierarchy<3>&, const std::vector<double>&,
                                                         int);
template void prolongate_to_new_vertices<2>(const Hierarchy<2>&, std::vector<double>&);
template void prolongate_to_new_vertices<3>(const Hierarchy<3>&, std::vector<double>&);

}  // namespace mlfe
