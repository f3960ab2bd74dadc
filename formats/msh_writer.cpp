#include <fmt/format.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/base/vec.h>
#include <mlfe/formats/atomic_file.h>
#include <mlfe/formats/msh_writer.h>

#include <algorithm>
#include <cstdint>
#include <ostream>

namespace mlfe {
namespace {

using Box = std::pair<std::array<double, 3>, std::array<double, 3>>;

// The elements' groups: one without regions; with regions one per label present (ascending),
// each with the box of its elements; element tags 1..m numbered group by group.
struct MshGroups {
  std::vector<std::uint16_t> labels;  ///< with regions: the labels present, ascending
  std::vector<Box> box;
  std::vector<std::size_t> block_size, element_tag;
};

template <int D>
MshGroups msh_groups(const Hierarchy<D>& h, const std::vector<ElemId>& elems, const ElementRegions* regions,
                     const std::vector<std::array<double, 3>>& xyz, const std::vector<std::uint32_t>& tag,
                     const Box& all) {
  MshGroups out;
  std::vector<std::uint16_t>& groups = out.labels;
  if (regions) {
    groups = regions->label;
    std::sort(groups.begin(), groups.end());
    groups.erase(std::unique(groups.begin(), groups.end()), groups.end());
  }
  const std::size_t n_groups = regions ? groups.size() : 1;
  out.box.assign(n_groups, all);
  std::vector<char> box_set(n_groups, 0);
  out.block_size.assign(n_groups, 0);
  out.element_tag.assign(elems.size(), 0);
  const auto group_of = [&](std::size_t i) {
    return regions ? std::size_t(std::lower_bound(groups.begin(), groups.end(), regions->label[i]) -
                                 groups.begin())
                   : std::size_t(0);
  };
  for (std::size_t i = 0; i < elems.size(); ++i) {
    const std::size_t g = group_of(i);
    ++out.block_size[g];
    if (!regions) continue;
    auto& [glo, ghi] = out.box[g];
    for (VertexId v : h.cell(elems[i])) {
      const auto& q = xyz[tag[v.value] - 1];
      if (!box_set[g]) glo = ghi = q, box_set[g] = 1;
      for (int r = 0; r < 3; ++r) glo[r] = std::min(glo[r], q[r]), ghi[r] = std::max(ghi[r], q[r]);
    }
  }
  std::vector<std::size_t> next(n_groups, 1);
  for (std::size_t g = 1; g < n_groups; ++g) next[g] = next[g - 1] + out.block_size[g - 1];
  for (std::size_t i = 0; i < elems.size(); ++i) out.element_tag[i] = next[group_of(i)]++;
  return out;
}

}  // namespace

template <int D>
void write_msh(const std::string& path, const Hierarchy<D>& h, const std::vector<ElemId>& elems,
               const std::vector<double>* point_values, const GridTransform* transform,
               const ElementRegions* regions) {
  const std::size_t nv_all = h.vertex_count();
  if (point_values && point_values->size() != nv_all)
    throw Error(fmt::format("{}: {} point values for {} vertices", path, point_values->size(), nv_all));
  for (ElemId e : elems)
    if (!e.valid() || e.value >= h.element_count())
      throw Error(fmt::format("{}: element id {} out of range", path, e.value));
  if (regions && regions->label.size() != elems.size())
    throw Error(
        fmt::format("{}: {} region labels for {} elements", path, regions->label.size(), elems.size()));

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

  // Step 1b: the regions' groups (labels present, ascending), their boxes, the element tags.
  const MshGroups mg = msh_groups(h, elems, regions, xyz, tag, Box{lo, hi});
  const std::vector<std::uint16_t>& groups = mg.labels;
  const auto& group_box = mg.box;
  const auto& block_size = mg.block_size;
  const auto& element_tag = mg.element_tag;
  const auto physical_tag = [](std::uint16_t l) { return l == 0 ? 65536 : int(l); };
  // An element's node tags, ordered to positive volume in the physical frame.
  const auto oriented = [&](std::size_t i) {
    std::array<std::uint32_t, D + 1> t{};
    const auto& c = h.cell(elems[i]);
    for (int k = 0; k <= D; ++k) t[k] = tag[c[k].value];
    if constexpr (D == 3) {
      if (signed_volume6(xyz[t[0] - 1], xyz[t[1] - 1], xyz[t[2] - 1], xyz[t[3] - 1]) < 0)
        std::swap(t[2], t[3]);
    }  // a triangle in 3D space has no sign; keep the hierarchy's order
    return t;
  };

  write_file_atomically(path, [&](std::ostream& os) {
    fmt::memory_buffer b;
    auto out = std::back_inserter(b);
    const auto flush = [&] {
      os.write(b.data(), static_cast<std::streamsize>(b.size()));
      b.clear();
    };
    // Step 2: header and the entities: one (tag 1) without regions; with regions one per label
    // present, in ascending label order, each in the physical group of its label (tag = the
    // label; the background 0 gets tag 65536, beyond every label) named from the table.
    fmt::format_to(out, "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n");
    if (regions) {
      fmt::format_to(out, "$PhysicalNames\n{}\n", groups.size());
      for (std::uint16_t l : groups)
        fmt::format_to(out, "{} {} \"{}\"\n", D, physical_tag(l),
                       l == 0 && !regions->names.count(0) ? std::string("background") : regions->name(l));
      fmt::format_to(out, "$EndPhysicalNames\n");
    }
    const std::size_t n_entities = regions ? groups.size() : 1;
    fmt::format_to(out, "$Entities\n0 0 {} {}\n", D == 2 ? n_entities : 0, D == 3 ? n_entities : 0);
    for (std::size_t g = 0; g < n_entities; ++g) {
      const auto& [glo, ghi] = regions ? group_box[g] : std::pair{lo, hi};
      fmt::format_to(out, "{} {:.17g} {:.17g} {:.17g} {:.17g} {:.17g} {:.17g} ", g + 1, glo[0], glo[1],
                     glo[2], ghi[0], ghi[1], ghi[2]);
      if (regions)
        fmt::format_to(out, "1 {} 0\n", physical_tag(groups[g]));
      else
        fmt::format_to(out, "0 0\n");
    }
    fmt::format_to(out, "$EndEntities\n");
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
    // Step 4: elements, reordered to Gmsh's positive orientation in the physical frame; one
    // block per entity, element tags 1..m in block order (the given order without regions).
    const std::size_t m = elems.size();
    fmt::format_to(out, "$Elements\n{} {} {} {}\n", n_entities, m, m ? 1 : 0, m);
    for (std::size_t g = 0; g < n_entities; ++g) {
      fmt::format_to(out, "{} {} {} {}\n", D, g + 1, D == 2 ? 2 : 4, block_size[g]);
      for (std::size_t i = 0; i < m; ++i) {
        if (regions && regions->label[i] != groups[g]) continue;
        fmt::format_to(out, "{}", element_tag[i]);
        for (std::uint32_t v : oriented(i)) fmt::format_to(out, " {}", v);
        fmt::format_to(out, "\n");
        if (b.size() > (1 << 20)) flush();
      }
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
      fmt::format_to(out, "{} {}\n", element_tag[i], h.level(elems[i]));
      if (b.size() > (1 << 20)) flush();
    }
    fmt::format_to(out, "$EndElementData\n");
    flush();
  });
}

template void write_msh<2>(const std::string&, const Hierarchy<2>&, const std::vector<ElemId>&,
                           const std::vector<double>*, const GridTransform*, const ElementRegions*);
template void write_msh<3>(const std::string&, const Hierarchy<3>&, const std::vector<ElemId>&,
                           const std::vector<double>*, const GridTransform*, const ElementRegions*);

}  // namespace mlfe
