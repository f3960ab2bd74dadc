// Random hierarchies on the samples' lattice for the .mlfeh v3 and v4 tests, one definition
// for both so that the two versions are tested over the same kind of meshes.
#pragma once
#include <mlfe/formats/hierarchy_io.h>

#include <array>
#include <cstdint>
#include <random>
#include <vector>

namespace mlfe::test {

/// T0 as the lattice's cube 2^level samples wide (spacing 0.5, 2, 1.25), refined `level` times,
/// each leaf marked with probability `marked` (so some level-`level` vertices exist).
inline Hierarchy<3> random_lattice_hierarchy(int level, double marked, unsigned seed) {
  const double cube = double(1 << level);
  Hierarchy<3> h = Hierarchy<3>::box({0, 0, 0}, {cube * 0.5, cube * 2.0, cube * 1.25});
  std::mt19937 rng(seed);
  for (int r = 0; r < level; ++r) {
    std::vector<ElemId> to_refine;
    for (ElemId e : h.leaves())
      if (std::uniform_real_distribution<double>(0, 1)(rng) < marked) to_refine.push_back(e);
    h.refine(to_refine);
  }
  return h;
}

/// The file info of random_lattice_hierarchy(level, ...) over data of `dims` samples, values in
/// [-300, 300].
inline HierarchyFileInfo lattice_file_info(int level, const std::array<std::int64_t, 3>& dims) {
  HierarchyFileInfo info;
  info.transform.spacing = {0.5, 2.0, 1.25};
  info.value_min = -300;
  info.value_max = 300;
  info.on_lattice = true;
  info.lattice_level = level;
  info.data_dims = dims;
  return info;
}

}  // namespace mlfe::test
