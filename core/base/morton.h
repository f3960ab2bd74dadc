// Internal to mlfe::core: Morton (Z-curve) codes, shared by the orders that put points near each
// other in memory (surface samples for distances, a simplified surface's vertices, the
// render order of tetrahedra).
#pragma once
#include <cstdint>

namespace mlfe::detail {

/// The 10 low bits of x spread so that two zero bits follow each: shifted by 0, 1 and 2 and
/// or-ed, three coordinates give a 30-bit Morton code.
inline std::uint32_t spread_bits(std::uint32_t x) {
  x &= 0x3ffu;
  x = (x | (x << 16)) & 0x030000ffu;
  x = (x | (x << 8)) & 0x0300f00fu;
  x = (x | (x << 4)) & 0x030c30c3u;
  x = (x | (x << 2)) & 0x09249249u;
  return x;
}

/// The 21 low bits of x spread likewise: three coordinates give a 63-bit Morton code.
inline std::uint64_t spread_bits(std::uint64_t x) {
  x &= 0x1FFFFF;
  x = (x | x << 32) & 0x1F00000000FFFFull;
  x = (x | x << 16) & 0x1F0000FF0000FFull;
  x = (x | x << 8) & 0x100F00F00F00F00Full;
  x = (x | x << 4) & 0x10C30C30C30C30C3ull;
  x = (x | x << 2) & 0x1249249249249249ull;
  return x;
}

}  // namespace mlfe::detail
