// Uses the installed mlfe::core: refine the box toward a corner and check it tiles the box.
#include <core/hierarchy.h>

#include <cmath>
#include <cstdio>
#include <vector>

int main() {
  auto h = mlfe::Hierarchy<3>::box({0, 0, 0}, {1, 2, 3});
  for (int i = 0; i < 4; ++i) {
    std::vector<mlfe::ElemId> corner;  // the leaves at corner vertex 0
    for (auto e : h.leaves())
      for (auto v : h.cell(e))
        if (v == mlfe::VertexId(0)) corner.push_back(e);
    h.refine(corner);
  }
  double vol = 0;
  for (auto e : h.leaves()) vol += h.measure(e);
  std::printf("consumer: %zu leaves, %d levels, volume %.12f\n", h.leaves().size(), h.max_level() + 1, vol);
  return std::abs(vol - 6.0) < 1e-9 && h.max_level() == 4 ? 0 : 1;
}
