// Level-by-level rebuild and hierarchical-basis quantization of the .mlfeh v2 file (Grosso,
// Lürig & Ertl 1997; Yserentant 1986; Di & Cappello 2016); see hierarchy_levels.h.
#include <mlfe/core/check.h>
#include <mlfe/core/error.h>
#include <mlfe/formats/hierarchy_levels.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <string>

namespace mlfe {
namespace {

// An element as the sorted ids of its vertices (in the input hierarchy's numbering).
template <int D>
std::array<std::uint32_t, D + 1> key_of(const typename Hierarchy<D>::Cell& c,
                                        const std::vector<VertexId>* map) {
  std::array<std::uint32_t, D + 1> k;
  for (int i = 0; i <= D; ++i) k[i] = map ? (*map)[c[i].value].value : c[i].value;
  std::sort(k.begin(), k.end());
  return k;
}

// Counterparts carried across a refine(): old element e is remap[e] now (invalid: a removed
// green child); elements created by the call have none yet.
inline std::vector<ElemId> carried_counterparts(const std::vector<ElemId>& remap, std::size_t old_count,
                                                std::size_t new_count, const std::vector<ElemId>& orig) {
  if (remap.empty()) {  // nothing refined: ids unchanged
    std::vector<ElemId> out = orig;
    out.resize(new_count, ElemId::invalid());
    return out;
  }
  MLFE_CHECK(remap.size() == old_count);
  std::vector<ElemId> out(new_count, ElemId::invalid());
  for (std::size_t e = 0; e < old_count; ++e)
    if (remap[e].valid()) out[remap[e].value] = orig[e];
  return out;
}

// Gives each element of `rebuilt` without a counterpart the child of its parent's counterpart
// in h with the same vertices (through to_original), trying the same child slot first.
template <int D>
void match_children(const Hierarchy<D>& h, const Hierarchy<D>& rebuilt,
                    const std::vector<VertexId>& to_original, std::vector<ElemId>& orig) {
  for (std::uint32_t e = 0; e < rebuilt.element_count(); ++e) {
    if (orig[e].valid()) continue;
    const ElemId p = rebuilt.parent(ElemId(e));
    if (!p.valid() || !orig[p.value].valid()) continue;
    const ElemId op = orig[p.value];
    const int n = h.num_children(op);
    if (n != rebuilt.num_children(p)) continue;
    const auto key = key_of<D>(rebuilt.cell(ElemId(e)), &to_original);
    const int slot = static_cast<int>(e - rebuilt.first_child(p).value);
    for (int j = 0; j < n; ++j) {
      const ElemId c(h.first_child(op).value + static_cast<std::uint32_t>((slot + j) % n));
      if (key_of<D>(h.cell(c), nullptr) == key) {
        orig[e] = c;
        break;
      }
    }
  }
}

}  // namespace

template <int D>
std::vector<ElemId> refinement_candidates(const Hierarchy<D>& h, int level) {
  MLFE_CHECK(level >= 1);
  // Chunks in parallel, concatenated in order (a reader calls this once per level over the
  // whole hierarchy so far).
  constexpr std::size_t kChunk = 1 << 16;
  const std::size_t ne = h.element_count(), nchunks = (ne + kChunk - 1) / kChunk;
  std::vector<std::vector<ElemId>> found(nchunks);
  tbb::parallel_for(std::size_t(0), nchunks, [&](std::size_t k) {
    for (std::size_t e = k * kChunk, end = std::min(ne, e + kChunk); e < end; ++e) {
      const ElemId id(static_cast<std::uint32_t>(e));
      if (h.level(id) == level - 1 && h.kind(id) != ElemKind::kGreen) found[k].push_back(id);
    }
  });
  std::size_t n = 0;
  for (const auto& f : found) n += f.size();
  std::vector<ElemId> out;
  out.reserve(n);
  for (const auto& f : found) out.insert(out.end(), f.begin(), f.end());
  return out;
}

template <int D>
std::vector<ElemId> apply_refinement_marks(Hierarchy<D>& h, const std::vector<ElemId>& candidates,
                                           const std::vector<std::uint8_t>& marks) {
  MLFE_CHECK(candidates.size() == marks.size());
  std::vector<ElemId> marked;
  for (std::size_t i = 0; i < candidates.size(); ++i) {
    if (!marks[i]) continue;
    const ElemId e = candidates[i];
    if (h.is_leaf(e))
      marked.push_back(e);
    else if (h.kind(h.first_child(e)) == ElemKind::kGreen)
      marked.push_back(h.first_child(e));
    // else: already red-refined by an earlier closure; nothing to do.
  }
  if (marked.empty()) return {};
  return h.refine(std::move(marked));
}

template <int D>
LevelEncoding<D> encode_levels(const Hierarchy<D>& h, int max_level) {
  const int levels = max_level < 0 ? h.max_level() : std::min(max_level, h.max_level());
  LevelEncoding<D> enc;

  // Step 1: T0 with its vertices renumbered densely in id order.
  std::vector<VertexId> coarse_id(h.vertex_count(), VertexId::invalid());
  for (std::uint32_t v = 0; v < h.vertex_count(); ++v)
    if (!h.vertex_parents(VertexId(v))[0].valid()) {
      coarse_id[v] = VertexId(static_cast<std::uint32_t>(enc.coarse_points.size()));
      enc.coarse_points.push_back(h.point(VertexId(v)));
      enc.to_original.push_back(VertexId(v));
    }
  for (std::uint32_t e = 0; e < h.coarse_count(); ++e) {
    typename Hierarchy<D>::Cell c = h.cell(ElemId(e));
    for (auto& v : c) v = coarse_id[v.value];
    enc.coarse_cells.push_back(c);
  }
  enc.rebuilt = Hierarchy<D>::from_coarse(enc.coarse_points, enc.coarse_cells);
  // The rebuild reaches h's counts (or fails): no array or map grows by copies on the way.
  enc.rebuilt.reserve(h.vertex_count(), h.element_count(), true);
  enc.vertex_end.push_back(enc.rebuilt.vertex_count());

  // Step 2: every rebuilt element's counterpart in h (same vertex set), element by element:
  // T0 is h's T0, and a rebuilt child's counterpart is the child of its parent's counterpart
  // with the same vertices. Candidates are red children, so each has one while the rebuild
  // follows h; a candidate's mark is whether its counterpart is red-refined in h.
  std::vector<ElemId> orig(enc.rebuilt.element_count(), ElemId::invalid());
  for (std::uint32_t e = 0; e < h.coarse_count(); ++e) orig[e] = ElemId(e);
  const auto red_refined = [&h](ElemId o) {
    return o.valid() && !h.is_leaf(o) && h.kind(h.first_child(o)) == ElemKind::kRed;
  };

  // Step 3: per level, mark the candidates h red-refined, refine, map the new vertices to h's
  // through its edge→midpoint map and the new elements to h's children.
  for (int k = 1; k <= levels; ++k) {
    const std::vector<ElemId> cand = refinement_candidates(enc.rebuilt, k);
    std::vector<std::uint8_t> marks(cand.size());
    for (std::size_t i = 0; i < cand.size(); ++i) marks[i] = red_refined(orig[cand[i].value]) ? 1 : 0;
    const std::size_t old_count = enc.rebuilt.element_count();
    const std::vector<ElemId> remap = apply_refinement_marks(enc.rebuilt, cand, marks);
    for (std::size_t v = enc.to_original.size(); v < enc.rebuilt.vertex_count(); ++v) {
      const auto& p = enc.rebuilt.vertex_parents(VertexId(static_cast<std::uint32_t>(v)));
      const VertexId o = h.edge_midpoints().find(enc.to_original[p[0].value], enc.to_original[p[1].value]);
      if (!o.valid())
        throw LevelRebuildError("the hierarchy cannot be rebuilt level by level (step " + std::to_string(k) +
                                " creates a vertex it does not have)");
      enc.to_original.push_back(o);
    }
    orig = carried_counterparts(remap, old_count, enc.rebuilt.element_count(), orig);
    match_children(h, enc.rebuilt, enc.to_original, orig);
    enc.marks.push_back(std::move(marks));
    enc.vertex_end.push_back(enc.rebuilt.vertex_count());
  }

  // Step 4: the full rebuild is h (the file format relies on it): as many vertices, elements
  // and leaves, and every rebuilt leaf has a leaf of h as its counterpart (distinct leaves of a
  // conforming mesh have distinct vertex sets, so the counterparts are distinct).
  if (levels == h.max_level()) {
    bool same =
        enc.rebuilt.vertex_count() == h.vertex_count() && enc.rebuilt.element_count() == h.element_count();
    const std::vector<ElemId> rebuilt_leaves = enc.rebuilt.leaves();
    same = same && rebuilt_leaves.size() == h.leaves().size();
    for (std::size_t i = 0; same && i < rebuilt_leaves.size(); ++i) {
      const ElemId o = orig[rebuilt_leaves[i].value];
      same = o.valid() && h.is_leaf(o);
    }
    if (!same)
      throw LevelRebuildError("the hierarchy cannot be rebuilt level by level (the rebuild has " +
                              std::to_string(enc.rebuilt.vertex_count()) + " vertices and " +
                              std::to_string(enc.rebuilt.element_count()) + " elements, it has " +
                              std::to_string(h.vertex_count()) + " and " + std::to_string(h.element_count()) +
                              ")");
  }
  return enc;
}

template <int D>
LevelDescription<D> renumber_canonically(Hierarchy<D>& h,
                                         const std::vector<std::vector<double>*>& per_vertex) {
  for (const std::vector<double>* a : per_vertex) MLFE_CHECK(a->empty() || a->size() == h.vertex_count());
  LevelEncoding<D> enc = encode_levels(h);
  h = Hierarchy<D>();  // freed before the arrays below are permuted
  for (std::vector<double>* a : per_vertex) {
    if (a->empty()) continue;
    std::vector<double> p(a->size());
    for (std::size_t v = 0; v < p.size(); ++v) p[v] = (*a)[enc.to_original[v].value];
    a->swap(p);
  }
  h = std::move(enc.rebuilt);
  return std::move(static_cast<LevelDescription<D>&>(enc));
}

template <int D>
std::vector<double> quantize_hierarchical(const Hierarchy<D>& h, const std::vector<double>& u,
                                          double max_error, std::vector<std::int64_t>* codes) {
  MLFE_CHECK(u.size() == h.vertex_count());
  MLFE_CHECK(max_error > 0 && std::isfinite(max_error));
  const double step = 2 * max_error;
  constexpr double kMaxCode = 4503599627370496.0;  // 2^52: q·step stays exact enough
  std::vector<double> d(u.size());
  if (codes) codes->assign(u.size(), 0);
  for (std::size_t v = 0; v < u.size(); ++v) {
    const auto& p = h.vertex_parents(VertexId(static_cast<std::uint32_t>(v)));
    const double pred = p[0].valid() ? 0.5 * (d[p[0].value] + d[p[1].value]) : 0.0;
    const double x = std::nearbyint((u[v] - pred) / step);
    if (!(std::fabs(x) < kMaxCode))
      throw Error("max error " + std::to_string(max_error) + " is too small for values of magnitude " +
                  std::to_string(std::fabs(u[v])));
    auto q = static_cast<std::int64_t>(x);
    double dv = pred + static_cast<double>(q) * step;
    if (std::fabs(dv - u[v]) > max_error) {
      // Rounding of the product or the sum: the neighbouring code is within the bound.
      const std::int64_t alt = dv > u[v] ? q - 1 : q + 1;
      const double da = pred + static_cast<double>(alt) * step;
      // A value exactly between two codes (u = 0 under a prediction that is an odd multiple of
      // E, common over a zero background) is E from both; rounding of the product can put
      // either an ulp beyond E.
      if (!(std::fabs(da - u[v]) <= max_error) && std::fabs(dv - u[v]) <= max_error * (1 + 1e-12)) {
        d[v] = dv;
        if (codes) (*codes)[v] = q;
        continue;
      }
      if (!(std::fabs(da - u[v]) <= max_error * (1 + 1e-12)))
        throw Error("max error " + std::to_string(max_error) +
                    " is below the rounding of values of magnitude " + std::to_string(std::fabs(u[v])));
      q = alt;
      dv = da;
    }
    d[v] = dv;
    if (codes) (*codes)[v] = q;
  }
  return d;
}

template <int D>
std::vector<double> quantize_integer(const Hierarchy<D>& h, const std::vector<double>& u,
                                     std::int64_t max_error, std::vector<std::int64_t>* codes) {
  MLFE_CHECK(u.size() == h.vertex_count());
  MLFE_CHECK(max_error >= 0 && max_error < (std::int64_t(1) << 31));
  constexpr double kMax = 4503599627370496.0;  // 2^52
  const std::int64_t step = 2 * max_error + 1;
  std::vector<std::int64_t> d(u.size());
  if (codes) codes->assign(u.size(), 0);
  for (std::size_t v = 0; v < u.size(); ++v) {
    if (!(std::fabs(u[v]) < kMax) || u[v] != std::nearbyint(u[v]))
      throw Error("value " + std::to_string(u[v]) + " is not an integer of magnitude below 2^52");
    const auto x = static_cast<std::int64_t>(u[v]);
    const auto& p = h.vertex_parents(VertexId(static_cast<std::uint32_t>(v)));
    const std::int64_t pred = p[0].valid() ? integer_prediction(d[p[0].value], d[p[1].value]) : 0;
    // Floor division of r + E by the step (r + E may be negative).
    const std::int64_t r = x - pred + max_error;
    const std::int64_t q = r >= 0 ? r / step : -((-r + step - 1) / step);
    d[v] = pred + q * step;
    MLFE_CHECK(std::llabs(d[v] - x) <= max_error);
    if (codes) (*codes)[v] = q;
  }
  return std::vector<double>(d.begin(), d.end());
}

template std::vector<double> quantize_integer<2>(const Hierarchy<2>&, const std::vector<double>&,
                                                 std::int64_t, std::vector<std::int64_t>*);
template std::vector<double> quantize_integer<3>(const Hierarchy<3>&, const std::vector<double>&,
                                                 std::int64_t, std::vector<std::int64_t>*);
template struct LevelDescription<2>;
template struct LevelDescription<3>;
template struct LevelEncoding<2>;
template struct LevelEncoding<3>;
template std::vector<ElemId> refinement_candidates<2>(const Hierarchy<2>&, int);
template std::vector<ElemId> refinement_candidates<3>(const Hierarchy<3>&, int);
template std::vector<ElemId> apply_refinement_marks<2>(Hierarchy<2>&, const std::vector<ElemId>&,
                                                       const std::vector<std::uint8_t>&);
template std::vector<ElemId> apply_refinement_marks<3>(Hierarchy<3>&, const std::vector<ElemId>&,
                                                       const std::vector<std::uint8_t>&);
template LevelEncoding<2> encode_levels<2>(const Hierarchy<2>&, int);
template LevelEncoding<3> encode_levels<3>(const Hierarchy<3>&, int);
template LevelDescription<2> renumber_canonically<2>(Hierarchy<2>&, const std::vector<std::vector<double>*>&);
template LevelDescription<3> renumber_canonically<3>(Hierarchy<3>&, const std::vector<std::vector<double>*>&);
template std::vector<double> quantize_hierarchical<2>(const Hierarchy<2>&, const std::vector<double>&, double,
                                                      std::vector<std::int64_t>*);
template std::vector<double> quantize_hierarchical<3>(const Hierarchy<3>&, const std::vector<double>&, double,
                                                      std::vector<std::int64_t>*);

}  // namespace mlfe
