// Segment integration: the mean transmittance (closed form and table) and the pre-integrated
// accumulator (both) against fine numerical integration, the table against the closed form,
// constant opacity against the analytic transmittance, narrow spikes, early termination.
#include <gtest/gtest.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/render/transfer_function.h>

#include <algorithm>
#include <cmath>
#include <cstdint>

namespace mlfe {
namespace {

// Front-to-back midpoint-rule integration of the emission–absorption model in n steps.
struct Numeric {
  double rgb[3] = {0, 0, 0};
  double alpha = 0;
};
Numeric integrate_numerically(const CompiledTransferFunction& tf, double sf, double sb, double length,
                              int n) {
  Numeric r;
  double T = 1;
  const double h = length / n;
  for (int i = 0; i < n; ++i) {
    const double s = sf + (sb - sf) * (i + 0.5) / n;
    double c[3], tau;
    tf.eval(tf.piece(s), s, c, tau);
    const double a = 1 - std::exp(-tau * h);
    for (int k = 0; k < 3; ++k) r.rgb[k] += T * a * c[k];
    T *= 1 - a;
  }
  r.alpha = 1 - T;
  return r;
}

TEST(MeanTransmittance, MatchesQuadratureOnAllBranches) {
  // Small slope (Taylor), increasing (erfcx), decreasing (Dawson), large depths.
  const double cases[][2] = {{0, 0},  {0.3, 0.3}, {0.5, 0.55}, {0.2, 3.0}, {3.0, 0.2}, {0, 40},
                             {40, 0}, {12, 13},   {7, 0.01},   {0.01, 7},  {100, 120}, {1e-4, 0}};
  for (const auto& c : cases) {
    const double a = c[0], b = c[1];
    const int n = 200000;
    double sum = 0;
    for (int i = 0; i < n; ++i) {
      const double u = (i + 0.5) / n;
      sum += std::exp(-(a * u + 0.5 * (b - a) * u * u));
    }
    EXPECT_NEAR(mean_transmittance(a, b), sum / n, 1e-9) << "a=" << a << " b=" << b;
  }
}

TEST(MeanTransmittance, SmallSlopeAcrossTheMomentBranches) {
  // The Taylor branch takes the moments from a power series below a = 0.25 and from the
  // upward recurrence above: both sides of the switch, at the largest slopes it serves.
  for (double a : {0.0, 0.1, 0.249, 0.25, 0.26, 0.5, 1.0, 2.0, 3.9, 4.1, 9.0})
    for (double k : {-0.1, -0.03, 0.0, 0.05, 0.1}) {
      const double b = std::max(0.0, a + k);
      const int n = 200000;
      double sum = 0;
      for (int i = 0; i < n; ++i) {
        const double u = (i + 0.5) / n;
        sum += std::exp(-(a * u + 0.5 * (b - a) * u * u));
      }
      // The series in k is cut after k⁴: its truncation, k⁵ / 42240, bounds the error.
      const double tol = std::abs(b - a) <= 0.05 ? 2e-11 : 5e-10;
      EXPECT_NEAR(mean_transmittance(a, b), sum / n, tol) << "a=" << a << " b=" << b;
    }
}

TEST(RayAccumulator, ConstantOpacityGivesAnalyticTransmittance) {
  TransferFunction tf;
  tf.color = {{0, 1, 0.5, 0.25}};
  tf.opacity = {{0, 0.3}};
  tf.unit_length = 2.0;
  const CompiledTransferFunction ctf(tf);
  for (double length : {1e-6, 0.01, 1.0, 3.7, 25.0}) {
    RayAccumulator acc(ctf, RayAccumulator::Rule::kPreIntegrated, 1.0, 0.5);
    // Split in uneven pieces, as a ray crossing tetrahedra would be.
    const double cuts[] = {0.0, 0.13, 0.5, 0.51, 1.0};
    for (int i = 0; i < 4; ++i) acc.add(5, 5, cuts[i] * length, (cuts[i + 1] - cuts[i]) * length);
    const double expected = std::pow(1 - 0.3, length / 2.0);
    EXPECT_NEAR(acc.transmittance(), expected, 1e-12);
    EXPECT_NEAR(acc.rgb()[0], 1 - expected, 1e-12);
    EXPECT_NEAR(acc.rgb()[2], 0.25 * (1 - expected), 1e-12);
  }
}

TEST(RayAccumulator, PreIntegrationMatchesFineNumericalIntegration) {
  TransferFunction tf;
  tf.color = {{0, 0, 0, 1}, {40, 1, 0, 0}, {60, 0.2, 1, 0.3}, {100, 1, 1, 1}};
  tf.opacity = {{10, 0}, {30, 0.4}, {50, 0.05}, {80, 0.9}, {90, 0.2}};
  tf.unit_length = 1.5;
  const CompiledTransferFunction ctf(tf);
  const double segments[][3] = {{0, 100, 4},  {100, 0, 4}, {20, 35, 0.7},
                                {85, 45, 10}, {55, 55, 2}, {5, 95, 0.1}};
  for (auto rule : {RayAccumulator::Rule::kPreIntegrated, RayAccumulator::Rule::kExact})
    for (const auto& s : segments) {
      RayAccumulator acc(ctf, rule, 1.0, 0.5);
      acc.add(s[0], s[1], 0, s[2]);
      const Numeric num = integrate_numerically(ctf, s[0], s[1], s[2], 100000);
      EXPECT_NEAR(1 - acc.transmittance(), num.alpha, 1e-4) << s[0] << "->" << s[1];
      for (int c = 0; c < 3; ++c) EXPECT_NEAR(acc.rgb()[c], num.rgb[c], 1e-4) << s[0] << "->" << s[1];
    }
}

TEST(MeanTransmittance, TableWithinItsBoundOfTheClosedForm) {
  // Random depth pairs over seven decades, plus both axes and the diagonal (where ψ has its
  // steepest parts), plus zero and very large depths.
  std::uint32_t state = 12345;
  auto uniform = [&] {
    state = state * 1664525u + 1013904223u;
    return double(state >> 8) / 16777216.0;
  };
  double worst = 0;
  for (int k = 0; k < 200000; ++k) {
    double a = std::pow(10.0, -4 + 7 * uniform()), b = std::pow(10.0, -4 + 7 * uniform());
    if (k % 5 == 1) b = 0;
    if (k % 5 == 2) a = 0;
    if (k % 5 == 3) b = a;
    worst = std::max(worst, std::abs(mean_transmittance_table(a, b) - mean_transmittance(a, b)));
  }
  for (double d : {0.0, 1e-9, 0.5, 3.0, 1e4, 1e8})
    for (double e : {0.0, 1e-9, 0.5, 3.0, 1e4, 1e8})
      worst = std::max(worst, std::abs(mean_transmittance_table(d, e) - mean_transmittance(d, e)));
  EXPECT_LE(worst, kMeanTransmittanceTableError);
  EXPECT_GT(worst, 0.0);  // it is a table, not the closed form again
}

TEST(RayAccumulator, TabulatedAgainstExactWithinTheTableBound) {
  // A ray of many short and long pieces through every kind of piece of the transfer function:
  // opacity identical (ζ is exact either way), colours within the table's bound times the
  // colour change per piece, summed over the pieces.
  TransferFunction tf;
  tf.color = {{0, 0, 0, 1}, {40, 1, 0, 0}, {60, 0.2, 1, 0.3}, {100, 1, 1, 1}};
  tf.opacity = {{10, 0}, {30, 0.4}, {50, 0.05}, {80, 0.9}, {90, 0.2}};
  const CompiledTransferFunction ctf(tf);
  RayAccumulator table(ctf, RayAccumulator::Rule::kPreIntegrated, 1.0, 0.5);
  RayAccumulator exact(ctf, RayAccumulator::Rule::kExact, 1.0, 0.5);
  double s = 50, t = 0, bound = 0;
  for (int i = 0; i < 400; ++i) {
    const double next = 50 + 49 * std::sin(0.37 * i), length = 0.01 + 0.3 * (1 + std::cos(1.3 * i));
    table.add(s, next, t, length);
    exact.add(s, next, t, length);
    bound += kMeanTransmittanceTableError * 4;  // ≤ 4 pieces per segment, |c_b − c_f| ≤ 1
    s = next, t += length;
  }
  EXPECT_EQ(table.transmittance(), exact.transmittance());
  double diff = 0;
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(table.rgb()[c], exact.rgb()[c], bound);
    diff = std::max(diff, std::abs(table.rgb()[c] - exact.rgb()[c]));
  }
  EXPECT_GT(diff, 0.0);
  EXPECT_LT(diff, 1e-4);
}

TEST(RayAccumulator, NarrowOpacitySpikeIsFound) {
  TransferFunction tf;
  tf.color = {{0, 1, 1, 1}};
  tf.opacity = {{0, 0}, {49.9, 0}, {50, 0.9}, {50.1, 0}};
  const CompiledTransferFunction ctf(tf);
  // One segment from 0 to 100: the spike lies strictly inside it.
  RayAccumulator pre(ctf, RayAccumulator::Rule::kPreIntegrated, 1.0, 0.5);
  pre.add(0, 100, 0, 10);
  const Numeric num = integrate_numerically(ctf, 0, 100, 10, 100000);
  EXPECT_GT(num.alpha, 0.01);
  EXPECT_NEAR(1 - pre.transmittance(), num.alpha, 1e-4);
  // The trapezoid rule only looks at the ends and misses it.
  RayAccumulator trap(ctf, RayAccumulator::Rule::kTrapezoid, 1.0, 0.5);
  trap.add(0, 100, 0, 10);
  EXPECT_EQ(trap.transmittance(), 1.0);
}

TEST(RayAccumulator, DepthIsWhereOpacityReachesThreshold) {
  TransferFunction tf;
  tf.color = {{0, 1, 1, 1}};
  tf.opacity = {{0, 0}, {10, 0.5}};
  tf.unit_length = 1;
  const CompiledTransferFunction ctf(tf);
  RayAccumulator acc(ctf, RayAccumulator::Rule::kPreIntegrated, 1.0, 0.5);
  acc.add(0, 10, 3.0, 20.0);  // τ(x) = τ1 x / 20 from t = 3
  // ∫₀ˣ τ = τ1 x² / 40 = ln 2  →  x = sqrt(40 ln 2 / τ1), τ1 = ln 2.
  EXPECT_NEAR(acc.depth(), 3.0 + std::sqrt(40.0), 1e-9);
  RayAccumulator none(ctf, RayAccumulator::Rule::kPreIntegrated, 1.0, 0.5);
  none.add(0, 0, 0, 5);
  EXPECT_TRUE(std::isinf(none.depth()));
}

TEST(RayAccumulator, EarlyTerminationChangesAlphaByAtMostOneMinusThreshold) {
  TransferFunction tf;
  tf.color = {{0, 0.8, 0.6, 0.4}};
  tf.opacity = {{0, 0.05}, {1, 0.6}};
  const CompiledTransferFunction ctf(tf);
  for (double stop : {0.9, 0.99}) {
    RayAccumulator full(ctf, RayAccumulator::Rule::kPreIntegrated, 1.0, 0.5);
    RayAccumulator early(ctf, RayAccumulator::Rule::kPreIntegrated, stop, 0.5);
    for (int i = 0; i < 400; ++i) {
      const double s0 = 0.5 + 0.5 * std::sin(0.1 * i), s1 = 0.5 + 0.5 * std::sin(0.1 * (i + 1));
      full.add(s0, s1, 0.3 * i, 0.3);
      if (!early.done()) early.add(s0, s1, 0.3 * i, 0.3);
    }
    EXPECT_TRUE(early.done());
    const double da = (1 - full.transmittance()) - (1 - early.transmittance());
    EXPECT_GE(da, 0);
    EXPECT_LE(da, 1 - stop);
  }
}

TEST(TransferFunction, ValidationAndPresets) {
  TransferFunction tf;
  tf.color = {{1, 0, 0, 0}, {0, 1, 1, 1}};
  tf.opacity = {{0, 0.5}};
  EXPECT_THROW(tf.validate("x"), Error);
  for (const auto& name : transfer_function_presets()) {
    const TransferFunction p = transfer_function_preset(name, -5, 20, 0.5);
    EXPECT_NO_THROW(p.validate(name));
  }
  EXPECT_THROW(transfer_function_preset("nope", 0, 1, 1), Error);
  // Zero-opacity intervals drive empty-space skipping.
  const CompiledTransferFunction bone(transfer_function_preset("bone", 0, 100, 1));
  EXPECT_TRUE(bone.transparent(-50, 44));
  EXPECT_FALSE(bone.transparent(30, 46));
  EXPECT_GT(bone.max_tau(30, 46), 0);
  EXPECT_EQ(bone.max_tau(0, 45), 0);
}

}  // namespace
}  // namespace mlfe
