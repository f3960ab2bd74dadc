// Large allocations of the command line on transparent huge pages.
//
// Every command writes hundreds of megabytes of fresh memory (volumes, meshes, hierarchies),
// and on the virtual machines measured a first touch of a 4 KiB page costs about 15 µs: 60 000
// page faults were a third of `convert --labels` on the JHU atlas (bench/RESULTS.md). The
// kernel's policy here is "madvise", so a block only gets 2 MiB pages when asked for; this
// replacement of the global operator new asks for every block of at least kLarge bytes (its
// 2 MiB pages, see advise_huge_pages) before anyone writes it. Only the command line does so:
// a library should not decide its host's paging. Results never depend on it.
//
// For the same reason freed memory is kept for reuse: by default glibc maps blocks from 128 KiB
// up (the threshold grows with use) afresh and unmaps them when freed, and gives the top of the
// heap back beyond 128 KiB, so an algorithm that allocates and frees per step touches new pages
// every time (refine() per level of a hierarchy file: page faults were the largest kernel cost
// of `render H.mlfeh` at 1x1; with the policy below its system time fell from 0.2-0.5 s to
// 0.1 s, and `build` kept its time with 2-3 % more peak memory, bench/RESULTS.md).
#include <malloc.h>
#include <mlfe/core/base/huge_pages.h>

#include <cstdlib>
#include <new>

namespace {
// Below this a block rarely holds a whole aligned 2 MiB page, and small blocks come from
// malloc's arenas, already touched.
constexpr std::size_t kLarge = std::size_t(4) << 20;

// Blocks below kLarge from the heap, whose freed memory is kept (trimmed only beyond 1 GiB free
// at its top) and grown 64 MiB at a time (address space); from kLarge on, mapped on huge pages
// and returned when freed. With the heap up to 32 MiB (glibc's largest threshold), vectors of a
// few million entries (a solve's vectors, per-leaf figures) were freed into it and held as
// garbage under a build's later peak: the full head's default build peaked 4-5 % higher and
// ran no faster (bench/RESULTS.md, session 18).
const bool kKeepFreedMemory = [] {
  mallopt(M_MMAP_THRESHOLD, static_cast<int>(kLarge));
  mallopt(M_TRIM_THRESHOLD, 1 << 30);
  mallopt(M_TOP_PAD, 64 << 20);
  return true;
}();
}  // namespace

void* operator new(std::size_t bytes) {
  void* p = std::malloc(bytes == 0 ? 1 : bytes);
  if (!p) throw std::bad_alloc();
  if (bytes >= kLarge) mlfe::advise_huge_pages(p, bytes);
  return p;
}

void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
