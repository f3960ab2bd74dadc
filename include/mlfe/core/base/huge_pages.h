// Transparent huge pages for large, freshly allocated arrays.
//
// Building a hierarchy or a render mesh of millions of elements writes hundreds of megabytes
// of new memory; with 4 KiB pages every first touch is a page fault, and on the virtual
// machines measured (bench/RESULTS.md, render set-up) those faults cost more than the
// arithmetic. The kernel's default policy here is "madvise": huge pages only where asked for.
#pragma once
#include <cstddef>
#include <cstdint>

#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace mlfe {

/// Asks the kernel to back the whole 2 MiB pages inside [p, p + bytes) with transparent huge
/// pages when they are first touched. Call before writing a large allocation (a reserved
/// vector's storage). Only a hint: without effect elsewhere than Linux, for small ranges, or
/// when the kernel refuses; contents and results never depend on it.
inline void advise_huge_pages(const void* p, std::size_t bytes) {
#if defined(__linux__) && defined(MADV_HUGEPAGE)
  constexpr std::uintptr_t kHuge = std::uintptr_t(2) << 20;
  const auto begin = (reinterpret_cast<std::uintptr_t>(p) + kHuge - 1) & ~(kHuge - 1);
  const auto end = (reinterpret_cast<std::uintptr_t>(p) + bytes) & ~(kHuge - 1);
  if (p && end > begin) madvise(reinterpret_cast<void*>(begin), end - begin, MADV_HUGEPAGE);
#else
  (void)p;
  (void)bytes;
#endif
}

/// advise_huge_pages over a vector's whole capacity.
template <class V>
void advise_huge_pages(const V& v) {
  advise_huge_pages(v.data(), v.capacity() * sizeof(typename V::value_type));
}

}  // namespace mlfe
