// approximation_bench: the adaptive L2 approximation (Grosso, Lürig & Ertl, IEEE Vis 1997)
// against uniform downsampling, plus the paper's Table 1 experiment on a 2D DEM.
//
// Usage:
//   approximation_bench [options] [VOLUME...]
//     VOLUME          3D volumes (default: ct_skull_64.nrrd and mri_colin27_brain.nii.gz from
//                     MLFE_SHARED_DATA_DIR); a 2D grid runs the Table 1 experiment instead
//     --dem PATH      2D height field for Table 1 (default: dem_jacksboro.nrrd); "none" skips it
//     --threshold T   Table 1 threshold in data units (metres; default 0.3)
//     --dem-start-level L  uniform levels before the Table 1 loop (default 0: T0 = 2 triangles,
//                     as in the paper; -1: mlfe's default, edges <= 16 samples)
//     --budgets a,b   vertex budgets as fractions of the voxel count (default 1/512,1/128,1/64,1/32,1/16)
//     --rms a,b       additional --rms targets in % of the value range (default 1,0.5)
//     --threads N     worker threads (default: 2)
//
// For every run it prints build time, the time per iteration split into assembly / solve /
// estimate / refine, peak RSS (VmHWM, reset before each run), CG iterations per solve, and the
// error: the solver's continuous RMS (‖f−u‖_L2 / sqrt|Ω|) and the discrete RMS over the voxels
// (u evaluated at every voxel centre by rasterizing the leaf tetrahedra), both as PSNR over the
// value range. Uniform downsampling keeps every s-th voxel (s = 2, 3, 4; the last sample of each
// axis is always kept) and reconstructs the full grid trilinearly; its PSNR uses the same
// discrete voxel RMS.
#include <mlfe/core/fem/approximation.h>
#include <mlfe/core/fem/p1_element.h>
#include <mlfe/core/field/field.h>
#include <mlfe/core/field/scalar_grid.h>
#include <mlfe/core/mesh/hierarchy.h>
#include <mlfe/formats/volume_reader.h>
#include <sys/resource.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

using namespace mlfe;

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// Peak RSS of this process (VmHWM) in MiB; reset_peak_rss() sets it back to the current RSS.
double peak_rss_mb() {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("VmHWM:", 0) == 0) return std::atof(line.c_str() + 6) / 1024.0;
  return 0;
}
double current_rss_mb() {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("VmRSS:", 0) == 0) return std::atof(line.c_str() + 6) / 1024.0;
  return 0;
}
bool reset_peak_rss() {
  std::ofstream out("/proc/self/clear_refs");
  out << "5";
  return static_cast<bool>(out);
}

std::vector<double> parse_list(const std::string& s) {
  std::vector<double> v;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, ',')) {
    const auto slash = item.find('/');
    if (slash != std::string::npos)
      v.push_back(std::atof(item.substr(0, slash).c_str()) / std::atof(item.substr(slash + 1).c_str()));
    else
      v.push_back(std::atof(item.c_str()));
  }
  return v;
}

double cpu_seconds() {
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  return ru.ru_utime.tv_sec + ru.ru_stime.tv_sec + 1e-6 * (ru.ru_utime.tv_usec + ru.ru_stime.tv_usec);
}

double psnr(double range, double rms) { return rms > 0 ? 20.0 * std::log10(range / rms) : 999.0; }

// Discrete RMS of u − f over all voxels: u is rasterized from the leaf tetrahedra (each voxel
// centre inside a leaf gets the linear interpolant of that leaf; the mesh is conforming, so
// voxels on shared faces get the same value from either side).
double voxel_rms_3d(const ScalarGrid& g, const Hierarchy<3>& h, const std::vector<double>& u) {
  const auto& sp = g.transform.spacing;
  const std::int64_t nx = g.dims[0], ny = g.dims[1], nz = g.dims[2];
  std::vector<float> approx(g.values.size(), std::numeric_limits<float>::quiet_NaN());
  const auto leaves = h.leaves();
  const double eps = 1e-9;
  for (ElemId e : leaves) {
    const auto& c = h.cell(e);
    std::array<std::array<double, 3>, 4> p;  // in voxel index units
    for (int k = 0; k < 4; ++k)
      for (int a = 0; a < 3; ++a) p[k][a] = h.point(c[k])[a] / sp[a];
    double lo[3], hi[3];
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min({p[0][a], p[1][a], p[2][a], p[3][a]});
      hi[a] = std::max({p[0][a], p[1][a], p[2][a], p[3][a]});
    }
    // Barycentric coordinates: λ_{i+1}(x) = ∇λ_{i+1} · (x - p0), from the P1 element.
    const P1Element<3> el(p);
    if (el.measure == 0) continue;
    const auto& inv = el.grad;  // rows 1..3 are the rows of [p1-p0 p2-p0 p3-p0]⁻¹
    const double u0 = u[c[0].value], u1 = u[c[1].value], u2 = u[c[2].value], u3 = u[c[3].value];
    const std::int64_t i0 = std::max<std::int64_t>(0, std::int64_t(std::ceil(lo[0] - eps)));
    const std::int64_t i1 = std::min<std::int64_t>(nx - 1, std::int64_t(std::floor(hi[0] + eps)));
    const std::int64_t j0 = std::max<std::int64_t>(0, std::int64_t(std::ceil(lo[1] - eps)));
    const std::int64_t j1 = std::min<std::int64_t>(ny - 1, std::int64_t(std::floor(hi[1] + eps)));
    const std::int64_t k0 = std::max<std::int64_t>(0, std::int64_t(std::ceil(lo[2] - eps)));
    const std::int64_t k1 = std::min<std::int64_t>(nz - 1, std::int64_t(std::floor(hi[2] + eps)));
    for (std::int64_t k = k0; k <= k1; ++k)
      for (std::int64_t j = j0; j <= j1; ++j)
        for (std::int64_t i = i0; i <= i1; ++i) {
          const double d[3] = {i - p[0][0], j - p[0][1], k - p[0][2]};
          const double l1 = inv[1][0] * d[0] + inv[1][1] * d[1] + inv[1][2] * d[2];
          const double l2 = inv[2][0] * d[0] + inv[2][1] * d[1] + inv[2][2] * d[2];
          const double l3 = inv[3][0] * d[0] + inv[3][1] * d[1] + inv[3][2] * d[2];
          const double l0 = 1.0 - l1 - l2 - l3;
          if (l0 < -1e-7 || l1 < -1e-7 || l2 < -1e-7 || l3 < -1e-7) continue;
          approx[std::size_t(i + nx * (j + ny * k))] = float(l0 * u0 + l1 * u1 + l2 * u2 + l3 * u3);
        }
  }
  double sum = 0;
  std::size_t missing = 0;
  for (std::size_t v = 0; v < approx.size(); ++v) {
    if (std::isnan(approx[v])) {
      ++missing;
      continue;
    }
    const double d = double(approx[v]) - double(g.values[v]);
    sum += d * d;
  }
  if (missing) std::fprintf(stderr, "warning: %zu voxels not covered by leaf tetrahedra\n", missing);
  return std::sqrt(sum / double(approx.size() - missing));
}

// Uniform downsampling by s (keep index 0, s, 2s, ... and always the last one) and trilinear
// reconstruction back to full resolution. Returns {coarse samples, discrete RMS}.
std::pair<std::size_t, double> downsample_rms(const ScalarGrid& g, int s) {
  std::array<std::vector<std::int64_t>, 3> keep;
  for (int a = 0; a < 3; ++a) {
    const std::int64_t n = g.dims[a];
    for (std::int64_t i = 0; i < n; i += s) keep[a].push_back(i);
    if (n > 1 && keep[a].back() != n - 1) keep[a].push_back(n - 1);
  }
  // For every fine index: the coarse interval and the weight.
  std::array<std::vector<std::int64_t>, 3> lo_idx;
  std::array<std::vector<double>, 3> w;
  for (int a = 0; a < 3; ++a) {
    const std::int64_t n = g.dims[a];
    lo_idx[a].resize(n);
    w[a].resize(n);
    std::size_t c = 0;
    for (std::int64_t i = 0; i < n; ++i) {
      while (c + 2 < keep[a].size() && keep[a][c + 1] <= i) ++c;
      if (keep[a].size() == 1) {
        lo_idx[a][i] = keep[a][0];
        w[a][i] = 0;
        continue;
      }
      const std::int64_t x0 = keep[a][c], x1 = keep[a][c + 1];
      lo_idx[a][i] = std::int64_t(c);
      w[a][i] = double(i - x0) / double(x1 - x0);
    }
  }
  const std::int64_t nx = g.dims[0], ny = g.dims[1];
  auto at = [&](std::size_t ci, std::size_t cj, std::size_t ck) {
    return double(g.at(keep[0][std::min(ci, keep[0].size() - 1)], keep[1][std::min(cj, keep[1].size() - 1)],
                       keep[2][std::min(ck, keep[2].size() - 1)]));
  };
  double sum = 0;
  for (std::int64_t k = 0; k < g.dims[2]; ++k)
    for (std::int64_t j = 0; j < ny; ++j)
      for (std::int64_t i = 0; i < nx; ++i) {
        const std::size_t ci = lo_idx[0][i], cj = lo_idx[1][j], ck = lo_idx[2][k];
        const double tx = w[0][i], ty = w[1][j], tz = w[2][k];
        double v = 0;
        for (int dz = 0; dz < 2; ++dz)
          for (int dy = 0; dy < 2; ++dy)
            for (int dx = 0; dx < 2; ++dx) {
              const double wt = (dx ? tx : 1 - tx) * (dy ? ty : 1 - ty) * (dz ? tz : 1 - tz);
              if (wt != 0) v += wt * at(ci + dx, cj + dy, ck + dz);
            }
        const double d = v - double(g.at(i, j, k));
        sum += d * d;
      }
  return {keep[0].size() * keep[1].size() * keep[2].size(), std::sqrt(sum / double(g.voxel_count()))};
}

struct RunResult {
  std::string label;
  std::size_t vertices = 0, elements = 0;
  int iterations = 0;
  double cpu = 0;  ///< process CPU seconds (user + sys) of the build: wall × cores actually received
  double seconds = 0, assembly = 0, solve = 0, estimate = 0, refine = 0;
  int cg_max = 0;
  double cg_mean = 0;
  int cg_solves = 0, direct_solves = 0;
  double peak_mb = 0;
  double rms_cont = 0, psnr_cont = 0, rms_vox = 0, psnr_vox = 0;
  std::string stop;
  std::vector<IterationStats> its;
};

RunResult run_3d(const ScalarGrid& g, const std::string& label, ApproximationOptions o) {
  RunResult r;
  r.label = label;
  const auto range = g.value_range();
  const double span = double(range[1]) - double(range[0]);
  reset_peak_rss();
  const double c0 = cpu_seconds();
  const auto t0 = Clock::now();
  GridField f(g);
  Approximation<3> a = approximate<3>(f, o);
  r.seconds = since(t0);
  r.cpu = cpu_seconds() - c0;
  r.peak_mb = peak_rss_mb();
  r.vertices = a.hierarchy.vertex_count();
  r.elements = a.hierarchy.leaves().size();
  r.iterations = int(a.iterations.size());
  r.its = a.iterations;
  r.stop = a.stop_reason;
  long cg_sum = 0;
  for (const auto& s : a.iterations) {
    r.assembly += s.assembly_seconds;
    r.solve += s.solve_seconds;
    r.estimate += s.estimate_seconds;
    r.refine += s.refine_seconds;
    if (s.cg_iterations > 0) {
      ++r.cg_solves;
      cg_sum += s.cg_iterations;
      r.cg_max = std::max(r.cg_max, s.cg_iterations);
    } else {
      ++r.direct_solves;
    }
  }
  r.cg_mean = r.cg_solves ? double(cg_sum) / r.cg_solves : 0;
  r.rms_cont = a.iterations.back().rms_error;
  r.psnr_cont = psnr(span, r.rms_cont);
  r.rms_vox = voxel_rms_3d(g, a.hierarchy, a.values);
  r.psnr_vox = psnr(span, r.rms_vox);
  return r;
}

void bench_volume(const std::string& path, const std::vector<double>& budgets,
                  const std::vector<double>& rms_pct) {
  const auto t_read = Clock::now();
  ScalarGrid g = read_volume(path);
  const double read_s = since(t_read);
  const auto range = g.value_range();
  const double span = double(range[1]) - double(range[0]);
  const std::size_t N = std::size_t(g.voxel_count());
  std::printf("\n=== %s ===\n", path.c_str());
  std::printf(
      "dims %lldx%lldx%lld = %zu voxels, spacing %.4g x %.4g x %.4g, value range [%g, %g], read %.2f s, RSS "
      "%.0f MiB\n",
      (long long)g.dims[0], (long long)g.dims[1], (long long)g.dims[2], N, g.transform.spacing[0],
      g.transform.spacing[1], g.transform.spacing[2], range[0], range[1], read_s, current_rss_mb());

  // Uniform downsampling.
  std::printf("\nUniform downsampling + trilinear reconstruction (PSNR over the value range, voxel RMS)\n");
  std::printf("| factor | samples | samples/voxels | RMS | PSNR dB |\n|---|---|---|---|---|\n");
  std::size_t v2 = 0;
  double psnr2 = 0;
  for (int s : {2, 3, 4}) {
    const auto [n, rms] = downsample_rms(g, s);
    if (s == 2) {
      v2 = n;
      psnr2 = psnr(span, rms);
    }
    std::printf("| %dx | %zu | 1/%.1f | %.5g | %.2f |\n", s, n, double(N) / double(n), rms, psnr(span, rms));
  }
  std::fflush(stdout);

  std::vector<RunResult> runs;
  std::vector<double> all_budgets = budgets;
  for (double b : all_budgets) {
    ApproximationOptions o;
    o.max_vertices = std::size_t(b * double(N));
    o.target_rms = 1e-12 * span;  // never reached: the budget stops the loop
    char label[64];
    std::snprintf(label, sizeof label, "max-vertices %zu (N/%.0f)", o.max_vertices, 1.0 / b);
    std::fprintf(stderr, "running %s ...\n", label);
    runs.push_back(run_3d(g, label, o));
  }
  // The headline budget: a quarter of the 2x-downsampling samples.
  {
    ApproximationOptions o;
    o.max_vertices = v2 / 4;
    o.target_rms = 1e-12 * span;
    char label[64];
    std::snprintf(label, sizeof label, "max-vertices %zu (2x samples/4)", o.max_vertices);
    std::fprintf(stderr, "running %s ...\n", label);
    runs.push_back(run_3d(g, label, o));
  }
  for (double p : rms_pct) {
    ApproximationOptions o;
    o.target_rms = p / 100.0 * span;
    char label[64];
    std::snprintf(label, sizeof label, "rms %.3g%%", p);
    std::fprintf(stderr, "running %s ...\n", label);
    runs.push_back(run_3d(g, label, o));
  }

  std::printf("\nAdaptive L2 approximation: vertices vs error (PSNR over the value range)\n");
  std::printf(
      "| run | vertices | vertices/voxels | leaf tets | iterations | RMS (L2) | PSNR L2 dB | RMS voxels | "
      "PSNR voxels dB | stop |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|\n");
  for (const auto& r : runs)
    std::printf("| %s | %zu | 1/%.1f | %zu | %d | %.5g | %.2f | %.5g | %.2f | %s |\n", r.label.c_str(),
                r.vertices, double(N) / double(r.vertices), r.elements, r.iterations, r.rms_cont, r.psnr_cont,
                r.rms_vox, r.psnr_vox, r.stop.c_str());

  std::printf("\nTiming (seconds; per-iteration = total / iterations), peak RSS, CG\n");
  std::printf(
      "| run | build s | CPU s | Mvoxel/s | iter | assembly/it | solve/it | estimate/it | refine/it | "
      "assembly | solve | estimate | refine | peak RSS MiB | direct solves | CG solves | CG it mean | CG it "
      "max |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  for (const auto& r : runs) {
    const double it = std::max(1, r.iterations);
    std::printf(
        "| %s | %.2f | %.2f | %.2f | %d | %.3f | %.3f | %.3f | %.3f | %.2f | %.2f | %.2f | %.2f | %.0f | %d "
        "| %d | %.1f | %d |\n",
        r.label.c_str(), r.seconds, r.cpu, double(N) / r.seconds / 1e6, r.iterations, r.assembly / it,
        r.solve / it, r.estimate / it, r.refine / it, r.assembly, r.solve, r.estimate, r.refine, r.peak_mb,
        r.direct_solves, r.cg_solves, r.cg_mean, r.cg_max);
  }

  // Per-iteration detail of the headline run.
  const RunResult* head = nullptr;
  for (const auto& r : runs)
    if (r.label.find("2x samples/4") != std::string::npos) head = &r;
  if (head) {
    std::printf("\nPer iteration, %s\n", head->label.c_str());
    std::printf(
        "| it | level | vertices | leaf tets | marked | RMS | PSNR dB | CG it | assembly s | solve s | "
        "estimate s | refine s |\n");
    std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for (const auto& s : head->its)
      std::printf("| %d | %d | %zu | %zu | %zu | %.5g | %.2f | %d | %.3f | %.3f | %.3f | %.3f |\n",
                  s.iteration, s.level, s.vertices, s.elements, s.marked, s.rms_error, s.psnr_db,
                  s.cg_iterations, s.assembly_seconds, s.solve_seconds, s.estimate_seconds, s.refine_seconds);

    std::printf("\nTargets (%s):\n", path.c_str());
    const bool t1 = head->psnr_vox >= psnr2 && head->vertices * 4 <= v2;
    std::printf(
        "- PSNR of 2x downsampling (%.2f dB, %zu samples) with <= 1/4 of its samples (%zu): %s — %zu "
        "vertices, "
        "voxel PSNR %.2f dB (%+.2f dB)\n",
        psnr2, v2, v2 / 4, t1 ? "MET" : "NOT MET", head->vertices, head->psnr_vox, head->psnr_vox - psnr2);
    // Smallest vertex count among runs that reach psnr2.
    const RunResult* best = nullptr;
    for (const auto& r : runs)
      if (r.psnr_vox >= psnr2 && (!best || r.vertices < best->vertices)) best = &r;
    if (best)
      std::printf("  smallest run reaching it: %s, %zu vertices = 1/%.1f of the 2x samples\n",
                  best->label.c_str(), best->vertices, double(v2) / double(best->vertices));
    else
      std::printf("  no run reached %.2f dB\n", psnr2);
    const double mvs = double(N) / head->seconds / 1e6;
    std::printf(
        "- >= 3 Mvoxel/s at that budget: %s — %.2f Mvoxel/s (%.2f s wall, %.2f s CPU for %zu voxels; "
        "%.2f Mvoxel/s even with 2 full cores = CPU s / 2)\n",
        mvs >= 3 ? "MET" : "NOT MET", mvs, head->seconds, head->cpu, N, double(N) / (head->cpu / 2) / 1e6);
    double peak = 0;
    int cg_max = 0;
    double cg_mean_max = 0;
    for (const auto& r : runs) {
      peak = std::max(peak, r.peak_mb);
      cg_max = std::max(cg_max, r.cg_max);
      cg_mean_max = std::max(cg_mean_max, r.cg_mean);
    }
    std::printf(
        "- peak memory <= 1.5 GB (1536 MiB): %s — max peak RSS over all runs %.0f MiB (headline %.0f MiB)\n",
        peak <= 1536 ? "MET" : "NOT MET", peak, head->peak_mb);
    std::printf("- BPX-PCG <= 30 iterations per solve: %s — max %d, largest per-run mean %.1f\n",
                cg_max <= 30 ? "MET" : "NOT MET", cg_max, cg_mean_max);
  }
  std::fflush(stdout);
}

void bench_dem(const std::string& path, double threshold, int start_level) {
  ScalarGrid g = read_volume(path);
  const auto range = g.value_range();
  std::printf("\n=== Table 1 (2D): %s ===\n", path.c_str());
  std::printf("dims %lldx%lld = %lld samples, spacing %.4g x %.4g, value range [%g, %g], threshold %g\n",
              (long long)g.dims[0], (long long)g.dims[1], (long long)g.voxel_count(), g.transform.spacing[0],
              g.transform.spacing[1], range[0], range[1], threshold);
  ApproximationOptions o;
  o.threshold = threshold;
  o.start_level = start_level;
  std::printf("start level %d%s\n", start_level,
              start_level == 0 ? " (T0 = 2 triangles, as in the paper)" : "");
  const auto t0 = Clock::now();
  GridField f(g);
  Approximation<2> a = approximate<2>(f, o);
  const double total = since(t0);
  std::printf(
      "| it | level | vertices | triangles | solve s | CG it | RMS m | growth "
      "|\n|---|---|---|---|---|---|---|---|\n");
  std::size_t prev = 0;
  for (const auto& s : a.iterations) {
    char growth[32] = "-";
    if (prev) std::snprintf(growth, sizeof growth, "%.2f", double(s.vertices) / double(prev));
    std::printf("| %d | %d | %zu | %zu | %.4f | %d | %.4g | %s |\n", s.iteration, s.level, s.vertices,
                s.elements, s.solve_seconds, s.cg_iterations, s.rms_error, growth);
    prev = s.vertices;
  }
  std::printf("total %.2f s, %zu iterations, stop: %s\n", total, a.iterations.size(), a.stop_reason.c_str());
  std::fflush(stdout);
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> volumes;
  std::string dem = std::string(MLFE_SHARED_DATA_DIR) + "/dem_jacksboro.nrrd";
  double threshold = 0.3;
  int dem_start_level = 0;
  std::vector<double> budgets = {1.0 / 512, 1.0 / 128, 1.0 / 64, 1.0 / 32, 1.0 / 16};
  std::vector<double> rms = {1.0, 0.5};
  int threads = 2;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "%s needs a value\n", a.c_str());
        std::exit(1);
      }
      return argv[++i];
    };
    if (a == "--dem")
      dem = next();
    else if (a == "--threshold")
      threshold = std::atof(next().c_str());
    else if (a == "--dem-start-level")
      dem_start_level = std::atoi(next().c_str());
    else if (a == "--budgets")
      budgets = next() == "none" ? std::vector<double>{} : parse_list(argv[i]);
    else if (a == "--rms")
      rms = next() == "none" ? std::vector<double>{} : parse_list(argv[i]);
    else if (a == "--threads")
      threads = std::atoi(next().c_str());
    else if (a == "-h" || a == "--help") {
      std::printf(
          "usage: approximation_bench [--dem PATH|none] [--threshold T] [--dem-start-level L] [--budgets "
          "f,..] [--rms p,..|none] "
          "[--threads N] [VOLUME...]\n");
      return 0;
    } else
      volumes.push_back(a);
  }
  if (volumes.empty())
    volumes = {std::string(MLFE_SHARED_DATA_DIR) + "/ct_skull_64.nrrd",
               std::string(MLFE_SHARED_DATA_DIR) + "/mri_colin27_brain.nii.gz"};
  tbb::global_control gc(tbb::global_control::max_allowed_parallelism, std::size_t(std::max(1, threads)));
  std::printf("approximation_bench: %d threads, peak RSS reset per run: %s\n", threads,
              reset_peak_rss() ? "yes" : "no (VmHWM is the process peak)");
  try {
    for (const auto& v : volumes) {
      ScalarGrid probe = read_volume(v);
      if (probe.dim == 2)
        bench_dem(v, threshold, dem_start_level);
      else {
        probe = ScalarGrid{};
        bench_volume(v, budgets, rms);
      }
    }
    if (dem != "none") bench_dem(dem, threshold, dem_start_level);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "approximation_bench: %s\n", e.what());
    return 2;
  }
  return 0;
}
