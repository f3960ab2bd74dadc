// Regions of a tetrahedral (or triangular) mesh for simulation: one region label per written
// element and a name per label (a label map's structures, `mlfe export` of a label hierarchy).
#pragma once
#include <cstdint>
#include <map>
#include <string>
#include <vector>

namespace mlfe {

struct ElementRegions {
  std::vector<std::uint16_t> label;            ///< per written element, in the writer's order
  std::map<std::uint16_t, std::string> names;  ///< region names; label_N where a label has none
  /// The name of `l`'s region.
  std::string name(std::uint16_t l) const {
    const auto it = names.find(l);
    return it != names.end() ? it->second : "label_" + std::to_string(l);
  }
};

}  // namespace mlfe
