// The .mlfeh v4 value and mark streams; see lattice_values.h and docs/mlfeh-v4.md.
#include "lattice_values.h"

#include <mlfe/core/base/check.h>
#include <mlfe/core/base/error.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>

namespace mlfe {
namespace {

constexpr std::int64_t kMaxDensePoints = std::int64_t(1) << 26;
constexpr int kMaxHashLevel = 21;
// Contexts: class (odd axes, 0..3) × spread of the prediction's inputs in steps (bit length,
// 0..11) × codes of those inputs (bit length of their sum, 0..3).
constexpr int kSpreadBuckets = 16, kActivityBuckets = 6, kLevelBuckets = 3,
              kContexts = 4 * kSpreadBuckets * kActivityBuckets * kLevelBuckets;
constexpr std::uint32_t kMaxMagnitude = 1u << 16;

int bit_length(std::uint64_t x, int cap) {
  const int n = x == 0 ? 0 : 64 - __builtin_clzll(x);
  return std::min(n, cap);
}

// Half-octave buckets: 0, 1, 2, 3, 4–5, 6–7, 8–11, 12–15, …
int log_bucket(std::uint64_t x, int cap) {
  if (x < 4) return std::min(static_cast<int>(x), cap);
  const int n = 64 - __builtin_clzll(x);
  return std::min(2 * n - 2 + static_cast<int>((x >> (n - 2)) & 1u), cap);
}

// Floor division by a positive divisor.
std::int64_t floor_div(std::int64_t a, std::int64_t b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

// The nearest code to x steps (real coding), within the codes' range ±2^52.
std::int64_t code_of(double x) {
  constexpr double kMaxCode = 4503599627370496.0;
  return static_cast<std::int64_t>(std::clamp(std::nearbyint(x), -kMaxCode, kMaxCode));
}

}  // namespace

LatticeIndex::LatticeIndex(int dim, int level) : dim_(dim), side_(0) {
  if (level < 0 || level > 24) return;
  side_ = (std::int64_t(1) << level) + 1;
  std::int64_t points = 1;
  for (int a = 0; a < dim; ++a) points *= side_;
  if (points <= kMaxDensePoints) {
    mode_ = Mode::kDense;
    dense_.assign(static_cast<std::size_t>(points), kNone);
  } else if (level <= kMaxHashLevel) {
    mode_ = Mode::kHash;
  }
}

bool LatticeIndex::key(const std::array<std::int64_t, 3>& i, std::uint64_t* k) const {
  std::uint64_t key = 0;
  for (int a = dim_ - 1; a >= 0; --a) {
    if (i[a] < 0 || i[a] >= side_) return false;
    key = key * static_cast<std::uint64_t>(side_) + static_cast<std::uint64_t>(i[a]);
  }
  *k = key;
  return true;
}

void LatticeIndex::insert(const std::array<std::int64_t, 3>& i, std::uint32_t v) {
  std::uint64_t k;
  if (mode_ == Mode::kNone || !key(i, &k)) return;
  if (mode_ == Mode::kDense) {
    if (dense_[k] == kNone) dense_[k] = v;
  } else {
    hash_.emplace(k, v);
  }
}

std::uint32_t LatticeIndex::find(const std::array<std::int64_t, 3>& i) const {
  std::uint64_t k;
  if (mode_ == Mode::kNone || !key(i, &k)) return kNone;
  if (mode_ == Mode::kDense) return dense_[k];
  const auto it = hash_.find(k);
  return it == hash_.end() ? kNone : it->second;
}

template <int D>
PredictedValues<D>::PredictedValues(const Coding& coding)
    : coding_(coding),
      index_(D, coding.on_lattice ? coding.lattice_level : -1),
      models_(kContexts),
      cost_(static_cast<std::size_t>(kContexts), {0, 0}) {}

template <int D>
std::array<std::int64_t, 3> PredictedValues<D>::lattice_point(const Hierarchy<D>& h, std::uint32_t v) const {
  std::array<std::int64_t, 3> i{0, 0, 0};
  for (int a = 0; a < D; ++a) i[a] = std::llround(h.point(VertexId(v))[a] / coding_.spacing[a]);
  return i;
}

// Records the step's vertices in the index and their classes, and returns them in coding
// order: by class (edge midpoints, then face centres, then cube centres of the step's
// lattice), each class in id order, so every class reads only classes before it.
template <int D>
std::vector<std::uint32_t> PredictedValues<D>::order(const Hierarchy<D>& h, int step, std::size_t from,
                                                     std::size_t to) {
  class_.resize(to, 0);
  magnitude_.resize(to, 0);
  const bool lattice = coding_.on_lattice && step <= coding_.lattice_level;
  const std::int64_t spacing = lattice ? std::int64_t(1) << (coding_.lattice_level - step) : 1;
  std::array<std::vector<std::uint32_t>, D + 1> by_class;
  for (std::size_t v = from; v < to; ++v) {
    const auto id = static_cast<std::uint32_t>(v);
    int c = 0;
    if (lattice && step > 0) {
      const auto i = lattice_point(h, id);
      index_.insert(i, id);
      for (int a = 0; a < D; ++a) {
        if (i[a] % spacing != 0) {
          c = 0;
          break;
        }
        c += static_cast<int>((i[a] / spacing) & 1);
      }
    } else if (lattice) {
      index_.insert(lattice_point(h, id), id);
    }
    class_[v] = static_cast<std::uint8_t>(c);
    by_class[static_cast<std::size_t>(c)].push_back(id);
  }
  std::vector<std::uint32_t> out;
  out.reserve(to - from);
  for (const auto& ids : by_class) out.insert(out.end(), ids.begin(), ids.end());
  return out;
}

// The prediction of v (a vertex of `step`) from decoded values. The linear one (the coding's): 0
// for T0, else the mean of v's parents (integers: its floor). The higher-order one: on the
// lattice, the mean over the axes on which v lies between two decoded lattice neighbours h
// apart of the cubic (−1, 9, 9, −1)/16 through the four at ±h and ±3h, or of the linear
// (1, 1)/2 through the two at ±h (integers: in sixteenths); `expected` is its distance from
// the linear one in steps of the code, rounded (half down).
template <int D>
typename PredictedValues<D>::Prediction PredictedValues<D>::predict(const Hierarchy<D>& h, int step,
                                                                    std::uint32_t v,
                                                                    const std::vector<double>& d) const {
  Prediction p;
  if (step == 0) return p;
  const int c = class_[v];
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  std::uint64_t activity = 0;
  const auto use = [&](std::uint32_t w) {
    lo = std::min(lo, d[w]);
    hi = std::max(hi, d[w]);
    activity += magnitude_[w];
  };
  const auto& par = h.vertex_parents(VertexId(v));
  const double da = d[par[0].value], db = d[par[1].value];
  p.real = 0.5 * (da + db);
  if (coding_.integer)
    p.integer = integer_prediction(static_cast<std::int64_t>(da), static_cast<std::int64_t>(db));
  double real = 0;
  std::int64_t sixteenths = 0;
  int terms = 0;
  if (c > 0 && index_.usable()) {
    const std::int64_t spacing = std::int64_t(1) << (coding_.lattice_level - step);
    const auto i = lattice_point(h, v);
    for (int a = 0; a < D; ++a) {
      if (((i[a] / spacing) & 1) == 0) continue;
      std::array<std::uint32_t, 4> n;
      std::array<double, 4> x{};
      for (int j = 0; j < 4; ++j) {
        auto q = i;
        q[a] += (2 * j - 3) * spacing;
        n[static_cast<std::size_t>(j)] = index_.find(q);
        if (n[static_cast<std::size_t>(j)] != LatticeIndex::kNone) x[static_cast<std::size_t>(j)] = d[n[j]];
      }
      if (n[1] == LatticeIndex::kNone || n[2] == LatticeIndex::kNone) continue;
      use(n[1]);
      use(n[2]);
      ++terms;
      const bool cubic = n[0] != LatticeIndex::kNone && n[3] != LatticeIndex::kNone;
      real += cubic ? (9.0 * (x[1] + x[2]) - (x[0] + x[3])) / 16.0 : 0.5 * (x[1] + x[2]);
      if (!coding_.integer) continue;
      std::array<std::int64_t, 4> y;
      for (int j = 0; j < 4; ++j) y[j] = static_cast<std::int64_t>(x[j]);
      sixteenths += cubic ? 9 * (y[1] + y[2]) - (y[0] + y[3]) : 8 * (y[1] + y[2]);
    }
  }
  p.high_real = p.real;
  p.high_integer = p.integer;
  if (terms == 0) {
    use(par[0].value);
    use(par[1].value);
  } else if (coding_.integer) {
    const std::int64_t den = 16 * terms * static_cast<std::int64_t>(2 * coding_.bound + 1);
    p.expected = floor_div(2 * (sixteenths - 16 * terms * p.integer) + den - 1, 2 * den);
    p.high_integer = floor_div(2 * sixteenths + 16 * terms - 1, 32 * terms);
  } else {
    p.high_real = real / terms;
    p.expected = code_of((p.high_real - p.real) / (2 * coding_.bound));
  }
  const double step_width = coding_.integer ? 2 * coding_.bound + 1 : 2 * coding_.bound;
  const double spread = std::min((hi - lo) / step_width, 1e18);
  const int s = log_bucket(static_cast<std::uint64_t>(spread), kSpreadBuckets - 1);
  const int act = log_bucket(activity, kActivityBuckets - 1);
  // The finest levels (noise) apart from the coarser ones (structure).
  const int lv = std::min(coding_.on_lattice ? coding_.lattice_level - step : 2, kLevelBuckets - 1);
  p.context = ((lv * 4 + c) * kSpreadBuckets + s) * kActivityBuckets + act;
  return p;
}

// Per context, the prediction whose codes were smaller so far: the higher-order one where the
// data is smooth, the coding's own where it is not (label maps, edges).
template <int D>
bool PredictedValues<D>::higher_order(const Prediction& p) const {
  const auto& c = cost_[static_cast<std::size_t>(p.context)];
  return c[1] <= c[0];
}

// The code the chosen prediction expects against the linear one (form 0's offset).
template <int D>
std::int64_t PredictedValues<D>::chosen(const Prediction& p) const {
  return higher_order(p) ? p.expected : 0;
}

// What the coding of later vertices learns from v's decoded value: its code against both
// predictions (for higher_order()) and the magnitude of the coded integer (for the contexts).
// The codes are recomputed from the decoded value, so a level stored in the v3 form (observe())
// teaches the same as one range coded. With `residual` (form 2) the decoded value is the chosen
// prediction plus a multiple of the step, so its codes against the two are rounded.
template <int D>
void PredictedValues<D>::learn(std::uint32_t v, const Prediction& p, const std::vector<double>& d,
                               bool residual) {
  constexpr std::uint64_t kCap = 1u << 16, kHalve = 1u << 24;
  std::int64_t linear, high;
  if (coding_.integer) {
    const auto x = static_cast<std::int64_t>(d[v]), w = static_cast<std::int64_t>(2 * coding_.bound + 1);
    linear = residual ? floor_div(2 * (x - p.integer) + w, 2 * w) : (x - p.integer) / w;
    high = residual ? floor_div(2 * (x - p.high_integer) + w, 2 * w) : linear - p.expected;
  } else {
    linear = code_of((d[v] - p.real) / (2 * coding_.bound));
    high = residual ? code_of((d[v] - p.high_real) / (2 * coding_.bound)) : linear - p.expected;
  }
  const std::int64_t r = higher_order(p) ? high : linear;
  magnitude_[v] = static_cast<std::uint32_t>(std::min<std::uint64_t>(std::llabs(r), kMaxMagnitude));
  auto& c = cost_[static_cast<std::size_t>(p.context)];
  c[0] += std::min<std::uint64_t>(static_cast<std::uint64_t>(std::llabs(linear)), kCap);
  c[1] += std::min<std::uint64_t>(static_cast<std::uint64_t>(std::llabs(high)), kCap);
  if (c[0] > kHalve || c[1] > kHalve) c = {c[0] / 2, c[1] / 2};
}

template <int D>
void PredictedValues<D>::observe(const Hierarchy<D>& h, int step, std::size_t from, std::size_t to,
                                 const std::vector<double>& d) {
  MLFE_CHECK(d.size() >= to);
  for (std::uint32_t v : order(h, step, from, to)) learn(v, predict(h, step, v, d), d, false);
}

template <int D>
std::vector<std::uint8_t> PredictedValues<D>::encode(const Hierarchy<D>& h, int step, std::size_t from,
                                                     std::size_t to, const std::vector<double>& u,
                                                     std::vector<double>& d, bool residual) {
  MLFE_CHECK(u.size() >= to && d.size() >= to);
  rc::Encoder e;
  models_ = rc::IntegerModels(kContexts);
  for (std::uint32_t v : order(h, step, from, to)) {
    const Prediction p = predict(h, step, v, d);
    const bool high = residual && higher_order(p);
    std::int64_t q;
    d[v] = coding_.integer
               ? static_cast<double>(quantize_integer_value(u[v], high ? p.high_integer : p.integer,
                                                            static_cast<std::int64_t>(coding_.bound), &q))
               : quantize_value(u[v], high ? p.high_real : p.real, coding_.bound, &q);
    models_.encode(e, p.context, residual ? q : q - chosen(p));
    learn(v, p, d, residual);
  }
  return e.finish();
}

template <int D>
void PredictedValues<D>::decode(const std::string& path, const char* what, const Hierarchy<D>& h, int step,
                                std::size_t from, std::size_t to, const std::uint8_t* bytes, std::size_t n,
                                std::vector<double>& d, bool residual) {
  MLFE_CHECK(d.size() >= to);
  rc::Decoder dec(path, what, bytes, n);
  models_ = rc::IntegerModels(kContexts);
  constexpr std::int64_t kMax = std::int64_t(1) << 52;
  for (std::uint32_t v : order(h, step, from, to)) {
    const Prediction p = predict(h, step, v, d);
    const bool high = residual && higher_order(p);
    const std::int64_t r = models_.decode(dec, p.context);
    // |r| < 2^62 and |expected| ≤ 2^53: the sum cannot overflow.
    const std::int64_t q = residual ? r : r + chosen(p);
    if (coding_.integer) {
      // Decoded values stay integers below 2^52 in magnitude, so the f64 values are exact and
      // the prediction's integer arithmetic cannot overflow (the cubic's stays below 2^53).
      const auto width = static_cast<std::int64_t>(2 * coding_.bound + 1);
      const std::int64_t base = high ? p.high_integer : p.integer;
      if (q > kMax / width || q < -kMax / width || std::llabs(base + q * width) >= kMax)
        throw Error(path + ": value of a vertex in " + what + " is out of range");
      d[v] = static_cast<double>(base + q * width);
    } else {
      d[v] = (high ? p.high_real : p.real) + static_cast<double>(q) * (2 * coding_.bound);
      if (!std::isfinite(d[v])) throw Error(path + ": value of a vertex in " + what + " is not finite");
    }
    learn(v, p, d, residual);
  }
  if (!dec.done()) throw Error(path + ": trailing bytes in the values of " + std::string(what));
}

std::vector<std::uint8_t> encode_marks(const std::vector<std::uint8_t>& marks) {
  rc::Encoder e;
  std::array<rc::BitModel, 256> m;
  unsigned ctx = 0;
  for (std::uint8_t b : marks) {
    e.bit(m[ctx], b);
    ctx = ((ctx << 1) | b) & 255u;
  }
  return e.finish();
}

std::vector<std::uint8_t> decode_marks(const std::string& path, const char* what, std::size_t n,
                                       const std::uint8_t* p, std::size_t bytes) {
  rc::Decoder d(path, what, p, bytes);
  std::array<rc::BitModel, 256> m;
  std::vector<std::uint8_t> marks(n);
  unsigned ctx = 0;
  for (std::uint8_t& b : marks) {
    b = static_cast<std::uint8_t>(d.bit(m[ctx]));
    ctx = ((ctx << 1) | b) & 255u;
  }
  if (!d.done()) throw Error(path + ": trailing bytes in the marks of " + std::string(what));
  return marks;
}

template class PredictedValues<2>;
template class PredictedValues<3>;

}  // namespace mlfe
