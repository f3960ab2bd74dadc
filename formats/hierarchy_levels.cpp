// Level-by-level rebuild and hierarchical-basis quantization of the .mlfeh v2 file (Grosso,
// Lürig & Ertl 1997; Yserentant 1986; Di & Cappello 2016); see hierarchy_levels.h.
#include <mlfe/core/base/check.h>
#include <mlfe/core/base/error.h>
#include <mlfe/formats/hierarchy_levels.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <string>

namespace mlfe {
namespace {

// An element as the sorted ids of its vertices, through `map` if given (rebuilt → original).
template <int D>
using Key = std::array<std::uint32_t, D + 1>;

template <int D>
Key<D> key_of(const typename Hierarchy<D>::Cell& c, const std::vector<VertexId>* map) {
  Key<D> k;
  for (int i = 0; i <= D; ++i) k[i] = map ? (*map)[c[i].value].value : c[i].value;
  std::sort(k.begin(), k.end());
  return k;
}

template <int D>
std::uint64_t key_hash(const Key<D>& k) {
  std::uint64_t x = 0x9E3779B97F4A7C15ULL;
  for (std::uint32_t v : k) {
    x = (x ^ v) * 0xff51afd7ed558ccdULL;
    x ^= x >> 33;
  }
  return x;
}

// The vertex sets of a hierarchy's red-refined elements (open addressing, load ≤ 1/2). In a
// nested hierarchy no two elements have the same vertices, so a set identifies an element.
template <int D>
class KeySet {
 public:
  // The keys of several lists (distinct keys).
  explicit KeySet(const std::vector<std::vector<Key<D>>>& lists) {
    std::size_t n = 0, cap = 64;
    for (const auto& l : lists) n += l.size();
    while (cap < 2 * n) cap *= 2;
    slots_.assign(cap, empty());
    for (const auto& l : lists)
      for (const Key<D>& k : l) {
        std::size_t i = key_hash<D>(k) & (cap - 1);
        while (slots_[i][0] != kEmpty) i = (i + 1) & (cap - 1);
        slots_[i] = k;
      }
  }
  bool contains(const Key<D>& k) const {
    for (std::size_t i = key_hash<D>(k) & (slots_.size() - 1);; i = (i + 1) & (slots_.size() - 1)) {
      if (same(slots_[i], k)) return true;
      if (slots_[i][0] == kEmpty) return false;  // vertex ids are below kEmpty
    }
  }

 private:
  static constexpr std::uint32_t kEmpty = ~std::uint32_t(0);
  static Key<D> empty() {
    Key<D> k;
    k.fill(kEmpty);
    return k;
  }
  static bool same(const Key<D>& a, const Key<D>& b) {
    bool eq = true;
    for (int i = 0; i <= D; ++i) eq &= a[i] == b[i];
    return eq;
  }
  std::vector<Key<D>> slots_;
};

// What the rebuild needs of the hierarchy it follows, so a caller can free that hierarchy
// first: T0, the edge → midpoint map, the vertex sets of the red-refined elements, the counts,
// and a fingerprint of the leaves (the sum of their vertex sets' hashes).
template <int D>
struct Followed {
  std::vector<typename Hierarchy<D>::Point> coarse_points;
  std::vector<typename Hierarchy<D>::Cell> coarse_cells;  // ids into coarse_points
  std::vector<VertexId> coarse_vertices;                  // coarse point → vertex id
  EdgeMap edges;
  KeySet<D> red;
  std::size_t vertices = 0, elements = 0, leaves = 0;
  int max_level = 0;
  std::uint64_t leaf_print = 0;
};

template <int D>
Followed<D> followed(const Hierarchy<D>& h) {
  // Chunks in parallel: each lists its red-refined elements' keys and sums its leaves' hashes.
  constexpr std::size_t kChunk = 1 << 16;
  const std::size_t ne = h.element_count(), nchunks = (ne + kChunk - 1) / kChunk;
  std::vector<std::vector<Key<D>>> red(nchunks);
  std::vector<std::uint64_t> print(nchunks, 0);
  std::vector<std::size_t> leaves(nchunks, 0);
  tbb::parallel_for(std::size_t(0), nchunks, [&](std::size_t k) {
    for (std::size_t e = k * kChunk, end = std::min(ne, e + kChunk); e < end; ++e) {
      const ElemId id(static_cast<std::uint32_t>(e));
      if (h.is_leaf(id)) {
        print[k] += key_hash<D>(key_of<D>(h.cell(id), nullptr));
        ++leaves[k];
      } else if (h.kind(h.first_child(id)) == ElemKind::kRed) {
        red[k].push_back(key_of<D>(h.cell(id), nullptr));
      }
    }
  });
  Followed<D> f{{}, {}, {}, h.edge_midpoints(), KeySet<D>(red), h.vertex_count(), ne, 0, h.max_level(), 0};
  for (std::size_t k = 0; k < nchunks; ++k) f.leaf_print += print[k], f.leaves += leaves[k];
  // T0 with its vertices renumbered densely in id order.
  std::vector<VertexId> coarse_id(h.vertex_count(), VertexId::invalid());
  for (std::uint32_t v = 0; v < h.vertex_count(); ++v)
    if (!h.vertex_parents(VertexId(v))[0].valid()) {
      coarse_id[v] = VertexId(static_cast<std::uint32_t>(f.coarse_points.size()));
      f.coarse_points.push_back(h.point(VertexId(v)));
      f.coarse_vertices.push_back(VertexId(v));
    }
  for (std::uint32_t e = 0; e < h.coarse_count(); ++e) {
    typename Hierarchy<D>::Cell c = h.cell(ElemId(e));
    for (auto& v : c) v = coarse_id[v.value];
    f.coarse_cells.push_back(c);
  }
  return f;
}

// The canonical rebuild of the followed hierarchy up to `levels` (see hierarchy_levels.h).
template <int D>
LevelEncoding<D> rebuild(const Followed<D>& f, int levels) {
  LevelEncoding<D> enc;
  enc.coarse_points = f.coarse_points;
  enc.coarse_cells = f.coarse_cells;
  enc.to_original = f.coarse_vertices;
  enc.rebuilt = Hierarchy<D>::from_coarse(enc.coarse_points, enc.coarse_cells);
  // The rebuild reaches the counts (or fails): no array or map grows by copies on the way.
  enc.rebuilt.reserve(f.vertices, f.elements, true);
  enc.vertex_end.push_back(enc.rebuilt.vertex_count());
  // Per level: mark the candidates whose vertex set is red-refined in the followed hierarchy,
  // refine, and map the new vertices to its own through its edge → midpoint map.
  for (int k = 1; k <= levels; ++k) {
    const std::vector<ElemId> cand = refinement_candidates(enc.rebuilt, k);
    std::vector<std::uint8_t> marks(cand.size());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, cand.size(), 4096), [&](const auto& r) {
      for (std::size_t i = r.begin(); i != r.end(); ++i)
        marks[i] = f.red.contains(key_of<D>(enc.rebuilt.cell(cand[i]), &enc.to_original)) ? 1 : 0;
    });
    apply_refinement_marks(enc.rebuilt, cand, marks);
    for (std::size_t v = enc.to_original.size(); v < enc.rebuilt.vertex_count(); ++v) {
      const auto& p = enc.rebuilt.vertex_parents(VertexId(static_cast<std::uint32_t>(v)));
      const VertexId o = f.edges.find(enc.to_original[p[0].value], enc.to_original[p[1].value]);
      if (!o.valid())
        throw LevelRebuildError("the hierarchy cannot be rebuilt level by level (step " + std::to_string(k) +
                                " creates a vertex it does not have)");
      enc.to_original.push_back(o);
    }
    enc.marks.push_back(std::move(marks));
    enc.vertex_end.push_back(enc.rebuilt.vertex_count());
  }
  // The full rebuild is the followed hierarchy (the file format relies on it): as many
  // vertices, elements and leaves, and the same leaves (their vertex sets' fingerprint).
  if (levels == f.max_level) {
    std::uint64_t print = 0;
    const std::vector<ElemId> leaves = enc.rebuilt.leaves();
    for (ElemId e : leaves) print += key_hash<D>(key_of<D>(enc.rebuilt.cell(e), &enc.to_original));
    if (enc.rebuilt.vertex_count() != f.vertices || enc.rebuilt.element_count() != f.elements ||
        leaves.size() != f.leaves || print != f.leaf_print)
      throw LevelRebuildError("the hierarchy cannot be rebuilt level by level (the rebuild has " +
                              std::to_string(enc.rebuilt.vertex_count()) + " vertices and " +
                              std::to_string(enc.rebuilt.element_count()) + " elements, it has " +
                              std::to_string(f.vertices) + " and " + std::to_string(f.elements) +
                              (print != f.leaf_print ? ", other leaves" : "") + ")");
  }
  return enc;
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
  const Followed<D> f = followed(h);
  return rebuild(f, max_level < 0 ? f.max_level : std::min(max_level, f.max_level));
}

template <int D>
LevelDescription<D> renumber_canonically(Hierarchy<D>& h,
                                         const std::vector<std::vector<double>*>& per_vertex) {
  for (const std::vector<double>* a : per_vertex) MLFE_CHECK(a->empty() || a->size() == h.vertex_count());
  // h is freed before the rebuild: only what the rebuild follows stays.
  LevelEncoding<D> enc;
  {
    const Followed<D> f = followed(h);
    h = Hierarchy<D>();
    enc = rebuild(f, f.max_level);
  }
  for (std::vector<double>* a : per_vertex) {
    if (a->empty()) continue;
    std::vector<double> p(a->size());
    for (std::size_t v = 0; v < p.size(); ++v) p[v] = (*a)[enc.to_original[v].value];
    a->swap(p);
  }
  h = std::move(enc.rebuilt);
  return std::move(static_cast<LevelDescription<D>&>(enc));
}

double quantize_value(double u, double pred, double max_error, std::int64_t* code) {
  const double step = 2 * max_error;
  constexpr double kMaxCode = 4503599627370496.0;  // 2^52: q·step stays exact enough
  const double x = std::nearbyint((u - pred) / step);
  if (!(std::fabs(x) < kMaxCode))
    throw Error("max error " + std::to_string(max_error) + " is too small for values of magnitude " +
                std::to_string(std::fabs(u)));
  auto q = static_cast<std::int64_t>(x);
  double dv = pred + static_cast<double>(q) * step;
  if (std::fabs(dv - u) > max_error) {
    // Rounding of the product or the sum: the neighbouring code is within the bound.
    const std::int64_t alt = dv > u ? q - 1 : q + 1;
    const double da = pred + static_cast<double>(alt) * step;
    // A value exactly between two codes (u = 0 under a prediction that is an odd multiple of
    // E, common over a zero background) is E from both; rounding of the product can put
    // either an ulp beyond E.
    if (!(std::fabs(da - u) <= max_error) && std::fabs(dv - u) <= max_error * (1 + 1e-12)) {
      *code = q;
      return dv;
    }
    if (!(std::fabs(da - u) <= max_error * (1 + 1e-12)))
      throw Error("max error " + std::to_string(max_error) +
                  " is below the rounding of values of magnitude " + std::to_string(std::fabs(u)));
    q = alt;
    dv = da;
  }
  *code = q;
  return dv;
}

std::int64_t quantize_integer_value(double u, std::int64_t pred, std::int64_t max_error, std::int64_t* code) {
  constexpr double kMax = 4503599627370496.0;  // 2^52
  if (!(std::fabs(u) < kMax) || u != std::nearbyint(u))
    throw Error("value " + std::to_string(u) + " is not an integer of magnitude below 2^52");
  const auto x = static_cast<std::int64_t>(u);
  const std::int64_t step = 2 * max_error + 1;
  // Floor division of r + E by the step (r + E may be negative).
  const std::int64_t r = x - pred + max_error;
  const std::int64_t q = r >= 0 ? r / step : -((-r + step - 1) / step);
  const std::int64_t d = pred + q * step;
  MLFE_CHECK(std::llabs(d - x) <= max_error);
  *code = q;
  return d;
}

template <int D>
std::vector<double> quantize_hierarchical(const Hierarchy<D>& h, const std::vector<double>& u,
                                          double max_error, std::vector<std::int64_t>* codes) {
  MLFE_CHECK(u.size() == h.vertex_count());
  MLFE_CHECK(max_error > 0 && std::isfinite(max_error));
  std::vector<double> d(u.size());
  if (codes) codes->assign(u.size(), 0);
  for (std::size_t v = 0; v < u.size(); ++v) {
    const auto& p = h.vertex_parents(VertexId(static_cast<std::uint32_t>(v)));
    const double pred = p[0].valid() ? 0.5 * (d[p[0].value] + d[p[1].value]) : 0.0;
    std::int64_t q;
    d[v] = quantize_value(u[v], pred, max_error, &q);
    if (codes) (*codes)[v] = q;
  }
  return d;
}

template <int D>
std::vector<double> quantize_integer(const Hierarchy<D>& h, const std::vector<double>& u,
                                     std::int64_t max_error, std::vector<std::int64_t>* codes) {
  MLFE_CHECK(u.size() == h.vertex_count());
  MLFE_CHECK(max_error >= 0 && max_error < (std::int64_t(1) << 31));
  std::vector<std::int64_t> d(u.size());
  if (codes) codes->assign(u.size(), 0);
  for (std::size_t v = 0; v < u.size(); ++v) {
    const auto& p = h.vertex_parents(VertexId(static_cast<std::uint32_t>(v)));
    const std::int64_t pred = p[0].valid() ? integer_prediction(d[p[0].value], d[p[1].value]) : 0;
    std::int64_t q;
    d[v] = quantize_integer_value(u[v], pred, max_error, &q);
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
