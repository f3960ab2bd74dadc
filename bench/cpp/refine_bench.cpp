// Refinement throughput and memory of mlfe::Hierarchy<3> at ≥ 10 million leaf tetrahedra.
//
//   refine_bench [--quick]
//
// Scenarios (each in its own forked process, so the peak RSS is the scenario's own):
//   uniform  the 6-tetrahedron box red-refined uniformly to level 7 (12.6 M leaves)
//   plane    local refinement: leaves cutting the plane z = 0.37 refined, 10 rounds (25 M leaves)
// For 1 and 2 threads (tbb::global_control). Prints one table row per run:
//   leaves, child tetrahedra created, seconds in refine(), children / s / core,
//   Hierarchy::memory_bytes() / leaf, peak RSS / leaf.
// Targets: ≥ 5 M child tetrahedra / s / core; ≤ 120 bytes / leaf (hierarchy + links + edge map).
#include <mlfe/core/mesh/hierarchy.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <tbb/global_control.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

namespace {

using mlfe::ElemId;
using mlfe::Hierarchy;
using Clock = std::chrono::steady_clock;

struct Result {
  double leaves = 0, created = 0, seconds = 0, memory_bytes = 0, peak_rss = 0;
};

Result run_scenario(const std::string& name, bool quick) {
  Hierarchy<3> h = Hierarchy<3>::box({0, 0, 0}, {1, 1, 1});
  Result r;
  const std::size_t start_elems = h.element_count();
  double seconds = 0;
  if (name == "uniform") {
    const int levels = quick ? 5 : 7;
    for (int l = 0; l < levels; ++l) {
      const auto t0 = Clock::now();
      h.refine_uniform();
      seconds += std::chrono::duration<double>(Clock::now() - t0).count();
    }
  } else {
    const int rounds = quick ? 8 : 10;
    const double z = 0.37;
    for (int l = 0; l < rounds; ++l) {
      // Marking is the caller's work, not refinement: it is not timed.
      std::vector<ElemId> marked;
      for (ElemId e : h.leaves()) {
        double lo = 1e300, hi = -1e300;
        for (auto v : h.cell(e)) {
          lo = std::min(lo, h.point(v)[2]);
          hi = std::max(hi, h.point(v)[2]);
        }
        if (lo <= z && hi >= z) marked.push_back(e);
      }
      const auto t0 = Clock::now();
      h.refine(std::move(marked));
      seconds += std::chrono::duration<double>(Clock::now() - t0).count();
    }
  }
  r.leaves = static_cast<double>(h.leaves().size());
  // Elements created (net of green children removed again), i.e. the hierarchy's growth.
  r.created = static_cast<double>(h.element_count() - start_elems);
  r.seconds = seconds;
  r.memory_bytes = static_cast<double>(h.memory_bytes());
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  r.peak_rss = static_cast<double>(ru.ru_maxrss) * 1024.0;
  return r;
}

// Runs the scenario in a child process so that ru_maxrss is this scenario's peak alone.
bool run_forked(const std::string& name, int threads, bool quick, Result& out) {
  int fd[2];
  if (pipe(fd) != 0) return false;
  const pid_t pid = fork();
  if (pid < 0) return false;
  if (pid == 0) {
    close(fd[0]);
    tbb::global_control gc(tbb::global_control::max_allowed_parallelism, threads);
    const Result r = run_scenario(name, quick);
    const ssize_t n = write(fd[1], &r, sizeof r);
    _exit(n == sizeof r ? 0 : 1);
  }
  close(fd[1]);
  const ssize_t n = read(fd[0], &out, sizeof out);
  close(fd[0]);
  int status = 0;
  waitpid(pid, &status, 0);
  return n == sizeof out && WIFEXITED(status) && WEXITSTATUS(status) == 0;
}

}  // namespace

int main(int argc, char** argv) {
  const bool quick = argc > 1 && std::strcmp(argv[1], "--quick") == 0;
  std::printf(
      "| scenario | threads | leaves | child tets created | refine s | child tets/s/core | "
      "memory_bytes/leaf | peak RSS/leaf |\n");
  std::printf("|---|---:|---:|---:|---:|---:|---:|---:|\n");
  for (const char* name : {"uniform", "plane"}) {
    for (int threads : {1, 2}) {
      Result r;
      if (!run_forked(name, threads, quick, r)) {
        std::printf("| %s | %d | failed | | | | | |\n", name, threads);
        continue;
      }
      std::printf("| %s | %d | %.0f | %.0f | %.2f | %.2f M | %.1f | %.1f |\n", name, threads, r.leaves,
                  r.created, r.seconds, r.created / r.seconds / threads / 1e6, r.memory_bytes / r.leaves,
                  r.peak_rss / r.leaves);
      std::fflush(stdout);
    }
  }
  return 0;
}
