// Large allocations of the command line on transparent huge pages.
//
// Every command writes hundreds of megabytes of fresh memory (volumes, meshes, hierarchies),
// and on the virtual machines measured a first touch of a 4 KiB page costs about 15 µs: 60 000
// page faults were a third of `convert --labels` on the JHU atlas (bench/RESULTS.md). The
// kernel's policy here is "madvise", so a block only gets 2 MiB pages when asked for; this
// replacement of the global operator new asks for every block of at least kLarge bytes (its
// 2 MiB pages, see advise_huge_pages) before anyone writes it. Only the command line does so:
// a library should not decide its host's paging. Results never depend on it.
#include <mlfe/core/huge_pages.h>

#include <cstdlib>
#include <new>

namespace {
// Below this a block rarely holds a whole aligned 2 MiB page, and small blocks come from
// malloc's arenas, already touched.
constexpr std::size_t kLarge = std::size_t(4) << 20;
}  // namespace

void* operator new(std::size_t bytes) {
  void* p = std::malloc(bytes == 0 ? 1 : bytes);
  if (!p) throw std::bad_alloc();
  if (bytes >= kLarge) mlfe::advise_huge_pages(p, bytes);
  return p;
}

void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
