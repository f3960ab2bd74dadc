// Emission–absorption integration over linear segments: Röttger, Kraus & Ertl (IEEE Vis 2000)
// pre-integration in the partial form of Moreland & Angel (IEEE VolVis 2004), with the mean
// transmittance ψ in closed form or from Moreland & Angel's 2D table (see transfer_function.h).
#include <mlfe/core/base/check.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/render/transfer_function.h>

#include <algorithm>
#include <cmath>
#include <limits>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace mlfe {

namespace {

constexpr double kSqrtPi = 1.7724538509055160273;
constexpr double kMaxOpacity = 1.0 - 1e-6;

// m[n] = ∫₀¹ uⁿ e^{−a u} du for the even n = 0..8 (odd entries are not needed and may be left
// unset). The upward recurrence loses digits for small a (it divides by a: the error of m[n]
// grows like n! / aⁿ), the power series for large a (alternating terms of size e^a), so each is
// used where it is stable; the series shares its terms (−a)^j / j! between the five moments.
// The recurrence from a = 0.25 on: its worst loss (m[8], ~3e-7 relative at a = 0.25) is
// weighted by k⁴ / 384 ≤ 2.6e-7 in mean_transmittance, so ψ keeps ~1e-13; the series below
// that converges in ≤ 12 terms instead of up to 40 below a = 4.
void exp_moments(double a, double m[9]) {
  if (a < 0.25) {
    static const auto inv = [] {
      std::array<double, 128> r{};
      for (std::size_t i = 1; i < r.size(); ++i) r[i] = 1.0 / double(i);
      return r;
    }();
    double s0 = 0, s2 = 0, s4 = 0, s6 = 0, s8 = 0, term = 1.0;
    for (int j = 0; j < 110; ++j) {
      s0 += term * inv[j + 1];
      s2 += term * inv[j + 3];
      s4 += term * inv[j + 5];
      s6 += term * inv[j + 7];
      s8 += term * inv[j + 9];
      term *= -a * inv[j + 1];
      if (std::abs(term) < 1e-18) break;
    }
    m[0] = s0, m[2] = s2, m[4] = s4, m[6] = s6, m[8] = s8;
    return;
  }
  const double e = std::exp(-a);
  m[0] = -std::expm1(-a) / a;
  for (int n = 1; n <= 8; ++n) m[n] = (double(n) * m[n - 1] - e) / a;
}

// exp(x²) erfc(x) for x ≥ 0 without overflow.
double erfcx(double x) {
  if (x < 25.0) return std::exp(x * x) * std::erfc(x);
  const double r = 1.0 / (x * x);
  return (1.0 - 0.5 * r * (1.0 - 1.5 * r * (1.0 - 2.5 * r))) / (x * kSqrtPi);
}

// Dawson's integral F(x) = e^{−x²} ∫₀ˣ e^{t²} dt, x ≥ 0: Rybicki's method (Numerical Recipes
// 6.10) with step h = 0.2, whose truncation error exp(−(π / 2h)²) is below double rounding.
double dawson(double x) {
  constexpr double kH = 0.2;
  constexpr int kTerms = 25;
  static const auto coeff = [] {
    std::array<double, kTerms + 1> c{};
    for (int i = 1; i <= kTerms; ++i) c[i] = std::exp(-std::pow((2.0 * i - 1.0) * kH, 2));
    return c;
  }();
  if (x < 0.2) {
    const double x2 = x * x;
    return x * (1.0 - 2.0 / 3.0 * x2 * (1.0 - 0.4 * x2 * (1.0 - 2.0 / 7.0 * x2 * (1.0 - 2.0 / 9.0 * x2))));
  }
  const int n0 = 2 * int(0.5 * x / kH + 0.5);
  const double xp = x - n0 * kH;
  double e1 = std::exp(2.0 * xp * kH);
  const double e2 = e1 * e1;
  double d1 = n0 + 1, d2 = d1 - 2.0, sum = 0.0;
  for (int i = 1; i <= kTerms; ++i, d1 += 2.0, d2 -= 2.0, e1 *= e2)
    sum += coeff[i] * (e1 / d1 + 1.0 / (d2 * e1));
  return std::exp(-xp * xp) * sum / kSqrtPi;
}

// Value of a piecewise-linear list at s, constant beyond its ends; at a repeated value the
// left (side < 0) or right (side > 0) limit.
template <std::size_t N>
void eval_list(const std::vector<std::array<double, N>>& pts, double s, int side, double* out) {
  const std::size_t n = pts.size();
  auto copy = [&](std::size_t i) {
    for (std::size_t c = 1; c < N; ++c) out[c - 1] = pts[i][c];
  };
  if (s <= pts.front()[0] && (side < 0 || s < pts.front()[0])) return copy(0);
  if (s >= pts.back()[0] && (side > 0 || s > pts.back()[0])) return copy(n - 1);
  // First point with value > s (right side) or >= s (left side).
  std::size_t hi =
      side > 0
          ? std::upper_bound(pts.begin(), pts.end(), s, [](double v, const auto& p) { return v < p[0]; }) -
                pts.begin()
          : std::lower_bound(pts.begin(), pts.end(), s, [](const auto& p, double v) { return p[0] < v; }) -
                pts.begin();
  if (hi == 0) return copy(0);
  if (hi >= n) return copy(n - 1);
  const std::size_t lo = hi - 1;
  if (side < 0 && pts[hi][0] == s) return copy(hi);
  const double w = (s - pts[lo][0]) / (pts[hi][0] - pts[lo][0]);
  for (std::size_t c = 1; c < N; ++c) out[c - 1] = pts[lo][c] + w * (pts[hi][c] - pts[lo][c]);
}

}  // namespace

void TransferFunction::validate(const std::string& source) const {
  auto fail = [&](const std::string& what) { throw Error(source + ": " + what); };
  if (color.empty()) fail("transfer function has no colour points");
  if (opacity.empty()) fail("transfer function has no opacity points");
  if (!(unit_length > 0) || !std::isfinite(unit_length)) fail("opacity unit length must be positive");
  for (std::size_t i = 0; i < color.size(); ++i) {
    for (double v : color[i])
      if (!std::isfinite(v)) fail("colour point " + std::to_string(i) + " is not finite");
    for (int c = 1; c < 4; ++c)
      if (color[i][c] < 0 || color[i][c] > 1) fail("colour point " + std::to_string(i) + " outside [0, 1]");
    if (i > 0 && color[i][0] < color[i - 1][0]) fail("colour points are not sorted by value");
  }
  for (std::size_t i = 0; i < opacity.size(); ++i) {
    if (!std::isfinite(opacity[i][0]) || !std::isfinite(opacity[i][1]))
      fail("opacity point " + std::to_string(i) + " is not finite");
    if (opacity[i][1] < 0 || opacity[i][1] > 1)
      fail("opacity point " + std::to_string(i) + " outside [0, 1]");
    if (i > 0 && opacity[i][0] < opacity[i - 1][0]) fail("opacity points are not sorted by value");
  }
}

namespace {

// A preset: its points at fractions f of the value range, (f, r, g, b) and (f, opacity).
struct Preset {
  const char* name;
  std::vector<std::array<double, 4>> color;
  std::vector<std::array<double, 2>> opacity;
};

// The presets, the one list of them: a new preset is a new row (the command line's help and the
// unknown-name error list them through transfer_function_presets()).
const std::vector<Preset>& presets() {
  static const std::vector<Preset> table = {
      // A linear grey ramp, linear opacity.
      {"grey", {{0, 0, 0, 0}, {1, 1, 1, 1}}, {{0, 0}, {1, 0.2}}},
      // Transparent below 45 % of the range, then ivory (CT bone).
      {"bone",
       {{0, 0.3, 0.1, 0.05}, {0.45, 0.9, 0.6, 0.4}, {1, 1, 1, 0.95}},
       {{0, 0}, {0.45, 0}, {0.6, 0.3}, {1, 0.6}}},
      // Soft tissue in warm tones, the brightest values opaque.
      {"mri",
       {{0, 0, 0, 0}, {0.3, 0.6, 0.3, 0.2}, {0.6, 0.95, 0.8, 0.6}, {1, 1, 1, 1}},
       {{0, 0}, {0.15, 0}, {0.35, 0.05}, {0.7, 0.15}, {1, 0.4}}},
      // Black, red, yellow, white.
      {"hot", {{0, 0, 0, 0}, {0.4, 1, 0, 0}, {0.8, 1, 1, 0}, {1, 1, 1, 1}}, {{0, 0}, {1, 0.3}}},
  };
  return table;
}

}  // namespace

std::vector<std::string> transfer_function_presets() {
  std::vector<std::string> names;
  for (const Preset& p : presets()) names.push_back(p.name);
  return names;
}

TransferFunction transfer_function_preset(const std::string& name, double lo, double hi, double unit_length) {
  if (!(lo < hi) || !(unit_length > 0))
    throw Error("transfer function '" + name + "': needs a value range lo < hi and a positive unit length");
  const auto preset =
      std::find_if(presets().begin(), presets().end(), [&](const Preset& p) { return name == p.name; });
  if (preset == presets().end()) {
    std::string list;
    for (const auto& p : transfer_function_presets()) list += (list.empty() ? "" : ", ") + p;
    throw Error("unknown transfer function preset '" + name + "' (presets: " + list +
                "; or a ParaView .json)");
  }
  const double r = hi - lo;
  auto at = [&](double f) { return lo + f * r; };
  TransferFunction tf;
  tf.unit_length = unit_length;
  tf.name = name;
  for (const auto& c : preset->color) tf.color.push_back({at(c[0]), c[1], c[2], c[3]});
  for (const auto& o : preset->opacity) tf.opacity.push_back({at(o[0]), o[1]});
  return tf;
}

double mean_transmittance(double a, double b) {
  MLFE_CHECK(a >= 0 && b >= 0);
  const double k = b - a;
  if (std::abs(k) <= 0.1) {
    // Taylor series in the slope k: e^{−k u²/2} = 1 − k u²/2 + k² u⁴/8 − k³ u⁶/48 + k⁴ u⁸/384
    // − …; the first omitted term is below k⁵ / (3840 · 11) ≈ 2.4e-10 here, while the closed
    // forms below cancel digits as k → 0.
    double m[9];
    exp_moments(a, m);
    const double k2 = k * k;
    return m[0] - 0.5 * k * m[2] + k2 / 8.0 * m[4] - k2 * k / 48.0 * m[6] + k2 * k2 / 384.0 * m[8];
  }
  const double zeta = std::exp(-0.5 * (a + b));
  if (k > 0) {
    // Complete the square: ψ = √(π / 2k) (erfcx(x₀) − ζ erfcx(x₁)), x₀ = a / √(2k),
    // x₁ = x₀ + √(k/2) (x₁² − x₀² = (a + b) / 2).
    const double s = std::sqrt(0.5 * k);
    const double x0 = a / std::sqrt(2.0 * k);
    return std::sqrt(M_PI / (2.0 * k)) * (erfcx(x0) - zeta * erfcx(x0 + s));
  }
  // Decreasing τ: integrate from the back, which turns the Gaussian around;
  // ψ = √(2/k') (F(y₁) − ζ F(y₀)), k' = a − b, y₀ = b / √(2k'), y₁ = a / √(2k').
  const double kp = -k;
  const double y0 = b / std::sqrt(2.0 * kp), y1 = a / std::sqrt(2.0 * kp);
  return std::sqrt(2.0 / kp) * (dawson(y1) - zeta * dawson(y0));
}

namespace {

// The ψ table: kPsiN × kPsiN floats (256 KB: stays in L2) over γ = 1 − 1/√(1 + d) of the front
// and back depths, γ = 1 (d = ∞) holding ψ = 0. Moreland & Angel's γ = d / (1 + d) leaves
// ψ(0, b) ≈ √(π / 2b) with a square-root cusp at γ = 1 (errors ~1e-2 at b ~ 1000); in this γ it
// is linear there, and ψ(a, a) ≈ 1 / a is quadratic. Worst error measured over 2·10⁶ random
// pairs with depths 1e-4..1e3, on both axes and the diagonal: 2.5e-5 (6.4e-6 at 512²); with
// depths up to 1e8 (pairs of 0, 1e-9, 0.5, 3, 1e4, 1e8): 6.3e-5. The bound stated is 1e-4.
constexpr int kPsiN = 256;

struct PsiTable {
  std::vector<float> v;
  PsiTable() : v(std::size_t(kPsiN) * kPsiN) {
    auto depth = [](int i) {
      const double r = 1.0 - double(i) / (kPsiN - 1);
      return 1.0 / (r * r) - 1.0;
    };
    for (int i = 0; i < kPsiN; ++i)
      for (int j = 0; j < kPsiN; ++j)
        v[std::size_t(i) * kPsiN + std::size_t(j)] =
            i == kPsiN - 1 || j == kPsiN - 1 ? 0.0f : float(mean_transmittance(depth(i), depth(j)));
  }
};

const float* psi_table() {
  static const PsiTable table;
  return table.v.data();
}

// Two doubles in one SSE register (GCC / Clang vector extension): the square roots and
// divisions of both table coordinates as one packed instruction each, half the work of the
// divider, which every visible piece keeps busy (1-2 % of a frame measured). IEEE square root and
// division are correctly rounded in either form, so the values are those of the scalar code.
using Double2 = double __attribute__((vector_size(16)));

inline Double2 sqrt2(Double2 v) {
#if defined(__SSE2__)
  return _mm_sqrt_pd(v);
#else
  return Double2{std::sqrt(v[0]), std::sqrt(v[1])};
#endif
}

double psi_lookup(const float* t, double a, double b) {
  const Double2 one{1.0, 1.0};
  const Double2 xy = (one - one / sqrt2(one + Double2{a, b})) * double(kPsiN - 1);
  const double x = xy[0], y = xy[1];
  const int i = std::min(int(x), kPsiN - 2), j = std::min(int(y), kPsiN - 2);
  const double fx = x - i, fy = y - j;
  const float* p = t + std::size_t(i) * kPsiN + std::size_t(j);
  return (1.0 - fx) * ((1.0 - fy) * p[0] + fy * p[1]) + fx * ((1.0 - fy) * p[kPsiN] + fy * p[kPsiN + 1]);
}

}  // namespace

double mean_transmittance_table(double a, double b) {
  MLFE_CHECK(a >= 0 && b >= 0);
  return psi_lookup(psi_table(), a, b);
}

CompiledTransferFunction::CompiledTransferFunction(const TransferFunction& tf) {
  tf.validate(tf.name.empty() ? "transfer function" : tf.name);
  for (const auto& p : tf.color) x_.push_back(p[0]);
  for (const auto& p : tf.opacity) x_.push_back(p[0]);
  std::sort(x_.begin(), x_.end());
  x_.erase(std::unique(x_.begin(), x_.end()), x_.end());
  auto tau_of = [&](double o) { return -std::log1p(-std::min(o, kMaxOpacity)) / tf.unit_length; };
  auto sample = [&](double s, int side, double c[3], double& t) {
    eval_list(tf.color, s, side, c);
    double o;
    eval_list(tf.opacity, s, side, &o);
    t = tau_of(o);
  };
  const std::size_t m = x_.size();
  pieces_.resize(m + 1);
  for (std::size_t k = 0; k <= m; ++k) {
    Piece& p = pieces_[k];
    p.x0 = k == 0 ? -std::numeric_limits<double>::infinity() : x_[k - 1];
    p.x1 = k == m ? std::numeric_limits<double>::infinity() : x_[k];
    // Outer pieces are constant: both ends take the value at their finite end.
    sample(k == 0 ? x_[0] : p.x0, k == 0 ? -1 : 1, p.c0, p.t0);
    sample(k == m ? x_[m - 1] : p.x1, k == m ? 1 : -1, p.c1, p.t1);
    p.inner = std::isfinite(p.x0) && std::isfinite(p.x1);
  }
  // Runs of pieces with τ = 0 at both ends (τ is linear inside, so 0 throughout).
  for (std::size_t k = 0; k <= m; ++k) {
    if (pieces_[k].t0 != 0 || pieces_[k].t1 != 0) continue;
    if (!zero_.empty() && zero_.back()[1] == pieces_[k].x0)
      zero_.back()[1] = pieces_[k].x1;
    else
      zero_.push_back({pieces_[k].x0, pieces_[k].x1});
  }
}

double CompiledTransferFunction::max_tau(double lo, double hi) const {
  double rgb[3], t, best = 0;
  const int k0 = piece(lo), k1 = piece(hi);
  eval(k0, lo, rgb, t);
  best = std::max(best, t);
  eval(k1, hi, rgb, t);
  best = std::max(best, t);
  for (int k = k0; k < k1; ++k) {  // breakpoints x_k inside: both one-sided limits
    best = std::max({best, pieces_[k].t1, pieces_[k + 1].t0});
  }
  return best;
}

const float* RayAccumulator::psi_table_if(Rule rule) {
  return rule == Rule::kPreIntegrated ? psi_table() : nullptr;
}

void RayAccumulator::reset() {
  transmittance_ = 1.0;
  rgb_[0] = rgb_[1] = rgb_[2] = 0;
  depth_ = std::numeric_limits<double>::infinity();
}

void RayAccumulator::add_split(double sf, double sb, int k0, int k1, double t, double length, double shade) {
  double cf[3], cb[3], tf, tb;
  // Split at every breakpoint between sf and sb, in ray order.
  const auto& x = tf_.breakpoints();
  const double scale = length / (sb - sf);
  const int step = k1 > k0 ? 1 : -1;
  for (int k = k0;; k += step) {
    const double a = k == k0 ? sf : (step > 0 ? x[k - 1] : x[k]);
    const double b = k == k1 ? sb : (step > 0 ? x[k] : x[k - 1]);
    const double l = (b - a) * scale;
    tf_.eval(k, a, cf, tf);
    tf_.eval(k, b, cb, tb);
    add_piece(tf, tb, cf, cb, t, l, shade);
    t += l;
    if (k == k1 || done()) break;
  }
}

void RayAccumulator::add_opaque_piece(double tf, double tb, const double cf[3], const double cb[3], double t,
                                      double l, double shade) {
  const double a = tf * l, b = tb * l;
  const double zeta = std::exp(-0.5 * (a + b));
  if (std::isinf(depth_) && 1.0 - transmittance_ * zeta >= z_opacity_) {
    // Optical depth still needed to reach z_opacity; τ(x) = tf + (tb − tf) x / l, so solve
    // tf x + (tb − tf) x² / 2l = D with the cancellation-free root.
    const double D = std::log(transmittance_ / (1.0 - z_opacity_));
    const double A = 0.5 * (tb - tf) / l;
    double x = tf == tb ? D / tf : 2.0 * D / (tf + std::sqrt(std::max(0.0, tf * tf + 4.0 * A * D)));
    depth_ = t + std::clamp(x, 0.0, l);
  }
  double w_f, w_b;
  if (rule_ != Rule::kTrapezoid) {
    const double psi = rule_ == Rule::kPreIntegrated ? psi_lookup(psi_, a, b) : mean_transmittance(a, b);
    w_f = 1.0 - psi;
    w_b = psi - zeta;
  } else {
    w_f = (1.0 - zeta) * tf / (tf + tb);
    w_b = (1.0 - zeta) * tb / (tf + tb);
  }
  for (int c = 0; c < 3; ++c) rgb_[c] += transmittance_ * shade * (w_f * cf[c] + w_b * cb[c]);
  transmittance_ *= zeta;
}

}  // namespace mlfe
