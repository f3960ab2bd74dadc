// compare_bench: `mlfe compare` on two 1-million-triangle meshes (issue #17 target: <= 2 s on
// 2 cores). The meshes are synthetic so the benchmark needs no data: a torus of 1000 x 500
// quads (1 000 000 triangles, 500 000 vertices) and a copy with every vertex moved along its
// normal by a fixed-seed noise of at most 0.05 % of the torus size, vertices shuffled.
//
//   compare_bench [--mlfe PATH/TO/mlfe] [--dir DIR] [--threads N] [--repeat R]
// Times, per run: the library call on meshes in memory (compare_meshes), the library call on
// files (compare_files: reading two binary PLYs included) and, with --mlfe, the command end to
// end (process start, reading, comparing). Prints one JSON line per measurement.
#include <mlfe/formats/openmesh_io.h>
#include <mlfe/pipeline/compare.h>
#include <sys/resource.h>
#include <tbb/global_control.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <numeric>
#include <random>
#include <string>

namespace {

mlfe::TriangleMesh torus(int nu, int nv, double R, double r) {
  mlfe::TriangleMesh m;
  for (int i = 0; i < nu; ++i)
    for (int j = 0; j < nv; ++j) {
      const double u = 2 * M_PI * i / nu, v = 2 * M_PI * j / nv;
      m.positions.push_back({float((R + r * std::cos(v)) * std::cos(u)),
                             float((R + r * std::cos(v)) * std::sin(u)), float(r * std::sin(v))});
      m.normals.push_back(
          {float(std::cos(v) * std::cos(u)), float(std::cos(v) * std::sin(u)), float(std::sin(v))});
    }
  auto id = [&](int i, int j) { return std::uint32_t(((i + nu) % nu) * nv + (j + nv) % nv); };
  for (int i = 0; i < nu; ++i)
    for (int j = 0; j < nv; ++j) {
      m.triangles.push_back({id(i, j), id(i + 1, j), id(i + 1, j + 1)});
      m.triangles.push_back({id(i, j), id(i + 1, j + 1), id(i, j + 1)});
    }
  return m;
}

/// CPU seconds (user + system) of this process and its finished children: with the machine
/// shared, wall time alone does not say how much work a run was.
double cpu_seconds() {
  double s = 0;
  for (int who : {RUSAGE_SELF, RUSAGE_CHILDREN}) {
    rusage u{};
    getrusage(who, &u);
    s += double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) +
         1e-6 * double(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
  }
  return s;
}

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

int main(int argc, char** argv) {
  std::string mlfe_binary, dir = (std::filesystem::temp_directory_path() / "mlfe_compare_bench").string();
  int threads = 0, repeat = 3;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--mlfe" && i + 1 < argc)
      mlfe_binary = argv[++i];
    else if (a == "--dir" && i + 1 < argc)
      dir = argv[++i];
    else if (a == "--threads" && i + 1 < argc)
      threads = std::atoi(argv[++i]);
    else if (a == "--repeat" && i + 1 < argc)
      repeat = std::atoi(argv[++i]);
    else {
      std::fprintf(stderr, "usage: compare_bench [--mlfe PATH] [--dir DIR] [--threads N] [--repeat R]\n");
      return 1;
    }
  }
  std::unique_ptr<tbb::global_control> limit;
  if (threads > 0)
    limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, threads);
  std::filesystem::create_directories(dir);

  // Step 1: the two meshes, written once as binary PLY.
  const mlfe::TriangleMesh a = torus(1000, 500, 1.0, 0.3);
  mlfe::TriangleMesh b;
  {
    std::mt19937_64 rng(17);
    std::vector<std::uint32_t> perm(a.vertex_count());
    std::iota(perm.begin(), perm.end(), 0u);
    std::shuffle(perm.begin(), perm.end(), rng);
    b.positions.resize(a.vertex_count());
    b.normals.resize(a.vertex_count());
    for (std::size_t v = 0; v < perm.size(); ++v) {
      const double d = 0.00065 * (double(rng() >> 11) / 9007199254740992.0 * 2 - 1);  // <= 0.05 % of 1.3
      for (int k = 0; k < 3; ++k) b.positions[perm[v]][k] = float(a.positions[v][k] + d * a.normals[v][k]);
      b.normals[perm[v]] = a.normals[v];
    }
    for (const auto& t : a.triangles) b.triangles.push_back({perm[t[0]], perm[t[1]], perm[t[2]]});
  }
  const std::string pa = dir + "/torus_a.ply", pb = dir + "/torus_b.ply";
  mlfe::write_mesh_file(pa, a);
  mlfe::write_mesh_file(pb, b);

  mlfe::CompareOptions o;
  o.tolerance = 0.001;
  double cpu0 = 0;
  auto emit = [&](const char* what, double s, const mlfe::CompareResult& r) {
    nlohmann::json j{{"measure", what},
                     {"seconds", s},
                     {"cpu_seconds", cpu_seconds() - cpu0},
                     {"threads", threads},
                     {"triangles", {a.triangle_count(), b.triangle_count()}},
                     {"equal", r.equal()},
                     {"hausdorff", r.report.value("hausdorff", -1.0)},
                     {"mean_distance", r.report.value("mean_distance", -1.0)}};
    std::printf("%s\n", j.dump().c_str());
    std::fflush(stdout);
  };
  // Step 2: the measurements.
  for (int rep = 0; rep < repeat; ++rep) {
    cpu0 = cpu_seconds();
    auto t0 = std::chrono::steady_clock::now();
    const mlfe::CompareResult mem = mlfe::compare_meshes(a, b, o);
    emit("compare_meshes (in memory)", seconds_since(t0), mem);
    cpu0 = cpu_seconds();
    t0 = std::chrono::steady_clock::now();
    const mlfe::CompareResult files = mlfe::compare_files(pa, pb, o);
    emit("compare_files (2 PLY files)", seconds_since(t0), files);
    if (!mlfe_binary.empty()) {
      const std::string cmd = mlfe_binary +
                              (threads > 0 ? " --threads " + std::to_string(threads) : std::string()) +
                              " compare " + pa + " " + pb + " --tolerance 0.001 --quiet";
      cpu0 = cpu_seconds();
      t0 = std::chrono::steady_clock::now();
      const int rc = std::system(cmd.c_str());
      const double s = seconds_since(t0);
      nlohmann::json j{{"measure", "mlfe compare (end to end)"},
                       {"seconds", s},
                       {"cpu_seconds", cpu_seconds() - cpu0},
                       {"threads", threads},
                       {"exit_status", WIFEXITED(rc) ? WEXITSTATUS(rc) : -1}};
      std::printf("%s\n", j.dump().c_str());
      std::fflush(stdout);
    }
  }
  return 0;
}
