// Internal to mlfe::core: the offsets of a counting sort whose items were counted in fixed
// chunks, each chunk with its own counters (the parallel, thread-count-independent counting
// sorts of the assembly's incidence table and the renderer's face matching and Morton order).
#pragma once
#include <cstddef>
#include <cstdint>

namespace mlfe::detail {

/// `at[k * buckets + b]` holds chunk k's count of bucket b and becomes where chunk k's first
/// item of bucket b goes: bucket after bucket, chunk after chunk within one, so filling chunk
/// by chunk keeps the items of a bucket in chunk order whatever the threads. `start[b]` (buckets
/// + 1 entries) receives each bucket's first place; returns the total (also start[buckets]).
inline std::uint32_t chunked_offsets(std::uint32_t* at, std::size_t chunks, std::size_t buckets,
                                     std::uint32_t* start) {
  std::uint32_t sum = 0;
  for (std::size_t b = 0; b < buckets; ++b) {
    start[b] = sum;
    for (std::size_t k = 0; k < chunks; ++k) {
      const std::uint32_t count = at[k * buckets + b];
      at[k * buckets + b] = sum;
      sum += count;
    }
  }
  start[buckets] = sum;
  return sum;
}

}  // namespace mlfe::detail
