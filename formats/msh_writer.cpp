#include <fmt/format.h>
#include <mlfe/core/error.h>
#include <mlfe/formats/atomic_file.h>
#include <mlfe/formats/msh_writer.h>

#include <algorithm>
#include <cstdint>
#include <ostream>

namespace mlfe {

template <int D>
void write_msh(const std::string& path, const Hierarchy<D>& h, const std::vector<ElemId>& elems,
               const std::vector<double>* point_values, const GridTransform* transform) {
  const std::size_t nv_all = h.vertex_count();
  if (point_values && point_values->size() != nv_all)
    throw Error(fmt::format("{}: {} point values for {} vertices", path, point_values->size(), nv_all));
  for (ElemId e : elems)
    if (!e.valid() || e.value >= h.element_count())
      throw Error(fmt::format("{}: element id {} out of range", path, e.value));

  // Step 1: the used vertices, tagged 1..n in VertexId order (independent of elems' order).
  std::vector<std::uint32_t> tag(nv_all, 0);
  for (ElemId e : elems)
    for (VertexId v : h.cell(e)) tag[v.value] = 1;
  std::vector<std::array<double, 3>> xyz;
  std::vector<std::uint32_t> used;
  for (std::size_t v = 0; v < nv_all; ++v) {
    if (!tag[v]) continue;
    used.push_back(static_cast<std::uint32_t>(v));
    tag[v] = static_cast<std::uint32_t>(used.size());
    std::array<double, 3> local{0.0, 0.0, 0.0};
    const auto& p = h.point(VertexId(static_cast<std::uint32_t>(v)));
    for (int i = 0; i < D; ++i) local[i] = p[i];
    xyz.push_back(transform ? transform->local_to_physical(local) : local);
  }
  std::array<double, 3> lo{0, 0, 0}, hi{0, 0, 0};
  if (!xyz.empty()) lo = hi = xyz[0];
  for (const auto& q : xyz)
    for (int i = 0; i < 3; ++i) lo[i] = std::min(lo[i], q[i]), hi[i] = std::max(hi[i], q[i]);

  write_file_atomically(path, [&](std::ostream& os) {
    fmt::memory_buffer b;
    auto out = std::back_inserter(b);
    const auto flush = [&] {
      os.write(b.data(), static_cast<std::streamsize>(b.size()));
      b.clear();
    };
    // Step 2: header and the one entity every node and element belongs to.
    fmt::format_to(out, "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Entities\n");
    fmt::format_to(out, "0 0 {} {}\n", D == 2 ? 1 : 0, D == 3 ? 1 : 0);
    fmt::format_to(out, "1 {:.17g} {:.17g} {:.17g} {:.17g} {:.17g} {:.17g} 0 0\n$EndEntities\n", lo[0], lo[1],
                   lo[2], hi[0], hi[1], hi[2]);
    // Step 3: nodes (tags first, then coordinates, as MSH 4.1 lays out a block).
    const std::size_t n = used.size();
    fmt::format_to(out, "$Nodes\n1 {} {} {}\n{} 1 0 {}\n", n, n ? 1 : 0, n, D, n);
    for (std::size_t i = 0; i < n; ++i) fmt::format_to(out, "{}\n", i + 1);
    flush();
    for (const auto& q : xyz) {
      fmt::format_to(out, "{:.17g} {:.17g} {:.17g}\n", q[0], q[1], q[2]);
      if (b.size() > (1 << 20)) flush();
    }
    fmt::format_to(out, "$EndNodes\n");
    // Step 4: elements, reordered to Gmsh's positive orientation in the physical frame.
    const std::size_t m = elems.size();
    fmt::format_to(out, "$Elements\n1 {} {} {}\n{} 1 {} {}\n", m, m ? 1 : 0, m, D, D == 2 ? 2 : 4, m);
    for (std::size_t i = 0; i < m; ++i) {
      std::array<std::uint32_t, D + 1> t{};
      const auto& c = h.cell(elems[i]);
      for (int k = 0; k <= D; ++k) t[k] = tag[c[k].value];
      const auto& a = xyz[t[0] - 1];
      std::array<std::array<double, 3>, 3> d{};
      for (int k = 0; k < D; ++k)
        for (int r = 0; r < 3; ++r) d[k][r] = xyz[t[k + 1] - 1][r] - a[r];
      double orient;
      if (D == 3) {
        orient = d[0][0] * (d[1][1] * d[2][2] - d[1][2] * d[2][1]) -
                 d[0][1] * (d[1][0] * d[2][2] - d[1][2] * d[2][0]) +
                 d[0][2] * (d[1][0] * d[2][1] - d[1][1] * d[2][0]);
      } else {
        orient = 1;  // a triangle in 3D space has no sign; keep the hierarchy's order
      }
      if (orient < 0) std::swap(t[D - 1], t[D]);
      fmt::format_to(out, "{}", i + 1);
      for (std::uint32_t v : t) fmt::format_to(out, " {}", v);
      fmt::format_to(out, "\n");
      if (b.size() > (1 << 20)) flush();
    }
    fmt::format_to(out, "$EndElements\n");
    // Step 5: the approximation's values and the refinement levels.
    if (point_values) {
      fmt::format_to(out, "$NodeData\n1\n\"u\"\n1\n0\n3\n0\n1\n{}\n", n);
      for (std::size_t i = 0; i < n; ++i) {
        fmt::format_to(out, "{} {:.17g}\n", i + 1, (*point_values)[used[i]]);
        if (b.size() > (1 << 20)) flush();
      }
      fmt::format_to(out, "$EndNodeData\n");
    }
    fmt::format_to(out, "$ElementData\n1\n\"level\"\n1\n0\n3\n0\n1\n{}\n", m);
    for (std::size_t i = 0; i < m; ++i) {
      fmt::format_to(out, "{} {}\n", i + 1, h.level(elems[i]));
      if (b.size() > (1 << 20)) flush();
    }
    fmt::format_to(out, "$EndElementData\n");
    flush();
  });
}

template void write_msh<2>(const std::string&, const Hierarchy<2>&, const std::vector<ElemId>&,
                           const std::vector<double>*, const GridTransform*);
template void write_msh<3>(const std::string&, const Hierarchy<3>&, const std::vector<ElemId>&,
                           const std::vector<double>*, const GridTransform*);

}  // namespace mlfe
