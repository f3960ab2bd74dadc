// 1D transfer functions and exact emission–absorption integration of a segment along which the
// scalar varies linearly (as it does inside a P1 tetrahedron, or between two samples of a
// reference ray caster).
//
//   S. Röttger, M. Kraus, T. Ertl, "Hardware-accelerated volume and isosurface rendering based
//   on cell-projection", IEEE Visualization 2000 (pre-integration: integrate the transfer
//   function over the segment, not at samples, so narrow features are not missed);
//   K. Moreland, E. Angel, "A fast high accuracy volume renderer for unstructured data",
//   IEEE VolVis 2004 (partial pre-integration: with colour c and extinction τ linear along a
//   segment of length l, C = c_f (1 − ψ) + c_b (ψ − ζ), ζ = exp(−(τ_f + τ_b) l / 2), where
//   ψ is the mean transmittance over the segment).
//
// ψ is available two ways: in closed form (erfcx for increasing τ, Dawson's integral for
// decreasing τ, a Taylor series in the slope when τ is nearly constant), exact to ~1e-12; and,
// as Moreland & Angel do, from a 2D table over the front and back optical depths d (mapped to
// γ = 1 − 1/√(1 + d) ∈ [0, 1), bilinear), which is several times cheaper per segment and within
// the bound stated at mean_transmittance_table of the exact value. ζ (so the opacity) is exact
// either way. A segment is split at every control point of the transfer function it crosses,
// and on each piece both c and τ are linear in the distance.
#pragma once
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

namespace mlfe {

/// A piecewise-linear transfer function over data values, constant beyond its end points
/// (ParaView's convention). Two points at one value make a step.
struct TransferFunction {
  /// (value, r, g, b): linear RGB in [0, 1], values non-decreasing.
  std::vector<std::array<double, 4>> color;
  /// (value, opacity): opacity in [0, 1] of a slab `unit_length` thick, values non-decreasing.
  std::vector<std::array<double, 2>> opacity;
  /// Thickness (local/physical length units) that the opacities refer to (> 0).
  double unit_length = 1.0;
  /// Free text recorded in outputs (preset name or file).
  std::string name;

  /// Throws mlfe::Error("<source>: <problem>") unless both lists are non-empty, finite,
  /// non-decreasing in value, colours in [0, 1], opacities in [0, 1] and unit_length > 0.
  void validate(const std::string& source) const;
};

/// The preset `name` (one of transfer_function_presets(); transfer_function.cpp's table says
/// what each shows) spanning the value range [lo, hi], opacities referring to `unit_length`.
/// Throws mlfe::Error unless lo < hi, unit_length > 0 and the name is known.
TransferFunction transfer_function_preset(const std::string& name, double lo, double hi, double unit_length);
/// Names accepted by transfer_function_preset.
std::vector<std::string> transfer_function_presets();

/// ψ(a, b) = ∫₀¹ exp(−(a u + (b − a) u² / 2)) du for a, b ≥ 0: the mean transmittance over a
/// segment whose optical depth density goes linearly from a to b (in units of its length).
double mean_transmittance(double a, double b);

/// ψ(a, b) from a table built once per process (first call; thread-safe), bilinear in
/// γ = 1 − 1/√(1 + d) of both depths d: |error| ≤ kMeanTransmittanceTableError for all a, b ≥ 0.
/// An image's colours then differ from the exact integration by at most that much per piece
/// integrated (weighted by the transmittance in front); its opacity does not change.
double mean_transmittance_table(double a, double b);
inline constexpr double kMeanTransmittanceTableError = 1e-4;

/// The transfer function prepared for integration: the union of its control points, with the
/// colour and the extinction τ = −ln(1 − opacity) / unit_length interpolated linearly between
/// them (τ, not opacity, is linear, so integration stays exact; an opacity of 1 is taken as
/// 1 − 1e-6).
class CompiledTransferFunction {
 public:
  explicit CompiledTransferFunction(const TransferFunction& tf);

  /// Piece of value s, 0..m for m breakpoints x: piece 0 is (−∞, x_0], piece k is
  /// (x_{k−1}, x_k], piece m is (x_{m−1}, ∞). At a step, each piece carries its own side.
  int piece(double s) const {
    // A linear scan: transfer functions have a handful of breakpoints, and this runs twice per
    // segment.
    int k = 0;
    const int m = int(x_.size());
    while (k < m && x_[std::size_t(k)] < s) ++k;
    return k;
  }
  /// Colour and τ of piece k at value s (linear inside it; constant on the outer ones).
  void eval(int k, double s, double rgb[3], double& tau) const {
    const Piece& p = pieces_[std::size_t(k)];
    double w = 0;
    if (p.inner) w = std::clamp((s - p.x0) / (p.x1 - p.x0), 0.0, 1.0);
    for (int c = 0; c < 3; ++c) rgb[c] = p.c0[c] + w * (p.c1[c] - p.c0[c]);
    tau = p.t0 + w * (p.t1 - p.t0);
  }
  /// Largest τ over the closed value range [lo, hi] (0 means fully transparent there).
  double max_tau(double lo, double hi) const;
  const std::vector<double>& breakpoints() const { return x_; }
  /// True when τ is zero on all of [lo, hi] (a few comparisons: used per element crossed).
  bool transparent(double lo, double hi) const {
    for (const auto& z : zero_)
      if (z[0] < lo && hi <= z[1]) return true;
    return false;
  }

 private:
  std::vector<double> x_;
  std::vector<std::array<double, 2>> zero_;  // maximal value intervals (z0, z1] with τ ≡ 0
  // Per piece: its value range and (rgb, τ) at both ends (one-sided limits at steps).
  struct Piece {
    double x0, x1;
    double c0[3], c1[3];
    double t0, t1;
    bool inner;  // both ends finite (the outer pieces are constant)
  };
  std::vector<Piece> pieces_;
};

/// Front-to-back emission–absorption accumulator along one ray.
class RayAccumulator {
 public:
  /// kPreIntegrated: ψ from the table (mean_transmittance_table); kExact: ψ in closed form;
  /// kTrapezoid: the paper's rule.
  enum class Rule { kPreIntegrated, kExact, kTrapezoid };
  /// `stop_opacity`: early termination once accumulated opacity reaches it (≤ 1);
  /// `z_opacity`: the opacity at which the depth is recorded.
  RayAccumulator(const CompiledTransferFunction& tf, Rule rule, double stop_opacity, double z_opacity)
      : tf_(tf), rule_(rule), psi_(psi_table_if(rule)), stop_(stop_opacity), z_opacity_(z_opacity) {
    reset();
  }
  RayAccumulator(const RayAccumulator&) = delete;
  RayAccumulator& operator=(const RayAccumulator&) = delete;
  /// Back to an empty ray (transparent, no depth).
  void reset();

  /// Adds the segment [t, t + length] of the ray along which the scalar goes linearly from
  /// sf to sb; colours are scaled by `shade`. Pre-integrated: split at every transfer-function
  /// breakpoint between sf and sb, each piece integrated exactly. Trapezoid (the paper): one
  /// piece, τ and c·τ averaged from the ends.
  /// Inline: ray casting calls it once per segment.
  void add(double sf, double sb, double t, double length, double shade = 1.0) {
    if (!(length > 0)) return;
    double cf[3], cb[3], tf, tb;
    const int k0 = tf_.piece(sf), k1 = tf_.piece(sb);
    if (rule_ == Rule::kTrapezoid || k0 == k1) {
      tf_.eval(k0, sf, cf, tf);
      tf_.eval(k1, sb, cb, tb);
      add_piece(tf, tb, cf, cb, t, length, shade);
      return;
    }
    add_split(sf, sb, k0, k1, t, length, shade);
  }
  /// True once the accumulated opacity reached the stop opacity.
  bool done() const { return 1.0 - transmittance_ >= stop_; }
  double transmittance() const { return transmittance_; }
  const double* rgb() const { return rgb_; }  ///< premultiplied
  /// Distance at which the opacity first reached z_opacity, or +infinity.
  double depth() const { return depth_; }

 private:
  void add_split(double sf, double sb, int k0, int k1, double t, double length, double shade);
  void add_piece(double tf, double tb, const double cf[3], const double cb[3], double t, double l,
                 double shade) {
    if (!(l > 0) || (tf == 0 && tb == 0)) return;
    add_opaque_piece(tf, tb, cf, cb, t, l, shade);
  }
  void add_opaque_piece(double tf, double tb, const double cf[3], const double cb[3], double t, double l,
                        double shade);
  static const float* psi_table_if(Rule rule);
  const CompiledTransferFunction& tf_;
  Rule rule_;
  const float* psi_;  // the ψ table (kPreIntegrated only)
  double stop_, z_opacity_;
  double transmittance_ = 1.0;
  double rgb_[3] = {0, 0, 0};
  double depth_ = 0;
};

}  // namespace mlfe
