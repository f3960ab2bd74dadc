// Uses the installed mlfe::core: refine the box toward a corner and check it tiles the box.
#include <core/hierarchy.h>

#include <cmath>
#include <cstdio>

int main() {
  auto h = mlfe::Hierarchy<3>::box({0, 0, 0}, {1, 2, 3});
  for (int i = 0; i < 4; ++i) h.refine({h.leaves().front()});
  double vol = 0;
  for (auto e : h.leaves()) vol += h.measure(e);
  std::printf("consumer: %zu leaves, volume %.12f\n", h.leaves().size(), vol);
  return std::abs(vol - 6.0) < 1e-9 && h.max_level() == 4 ? 0 : 1;
}
