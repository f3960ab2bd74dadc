// The value codings of the hierarchy file compared on one hierarchy (issue #44): reads a .mlfeh
// (v2 or later, coding quantized or integer) and writes it again at another format version with
// the same bound, so the decoded values, the hierarchy and the marks are the same and only the
// coding differs; then reads the result back, checks the values are identical and prints the
// bytes per section kind and the seconds of each step.
//   mlfeh_recode_bench IN.mlfeh OUT.mlfeh [VERSION (default 4)]
#include <mlfe/formats/hierarchy_io.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: %s IN.mlfeh OUT.mlfeh [VERSION]\n", argv[0]);
    return 2;
  }
  using Clock = std::chrono::steady_clock;
  const auto secs = [](Clock::time_point t) {
    return std::chrono::duration<double>(Clock::now() - t).count();
  };
  try {
    auto t = Clock::now();
    const mlfe::HierarchyFile in = mlfe::read_hierarchy(argv[1]);
    const double read_in = secs(t);
    mlfe::HierarchyWriteOptions o;
    o.version = argc > 3 ? std::atoi(argv[3]) : 4;
    o.max_error = in.value_bound;
    o.integer_values = in.integer_values;
    o.zstd_level = 19;
    t = Clock::now();
    mlfe::write_hierarchy(argv[2], in, o);
    const double write = secs(t);
    t = Clock::now();
    const mlfe::HierarchyFile out = mlfe::read_hierarchy(argv[2]);
    const double read_out = secs(t);
    if (out.values != in.values) {
      std::fprintf(stderr, "decoded values differ\n");
      return 1;
    }
    std::uint64_t mesh = 0, levels = 0, head = 0;
    for (const auto& s : out.sections) (s.level > 0 ? levels : s.name == "T0" ? mesh : head) += s.file_bytes;
    std::printf(
        "v%d -> v%d: header %llu, T0 %llu, levels %llu bytes; read in %.3f s, write %.3f s, "
        "read out %.3f s\n",
        in.version, out.version, static_cast<unsigned long long>(head), static_cast<unsigned long long>(mesh),
        static_cast<unsigned long long>(levels), read_in, write, read_out);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s\n", e.what());
    return 2;
  }
  return 0;
}
