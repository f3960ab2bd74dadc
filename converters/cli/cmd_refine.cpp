// mlfe refine: builds the red-green hierarchy of a box refined toward a point, a plane or a
// sphere's surface, without any volume data. For looking at (and benchmarking) the refinement
// itself: mesh quality, level transitions, green closure.
#include <fmt/format.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/base/usage_error.h>
#include <mlfe/core/base/vec.h>
#include <mlfe/core/mesh/hierarchy.h>
#include <mlfe/core/mesh/mesh_quality.h>
#include <mlfe/formats/hierarchy_io.h>
#include <mlfe/formats/vtu_writer.h>
#include <mlfe/pipeline.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "converters/cli/commands.h"

namespace mlfe::cli {
namespace {

constexpr int kMaxLevels = 24;

struct RefineArgs {
  std::string dim, box, toward, at, normal, radius, levels, output, hierarchy;
  std::string max_memory = "50%";
};

// "a,b,c" -> exactly n finite numbers; the option name goes into the message.
std::vector<double> parse_list(const std::string& option, const std::string& text, std::size_t n) {
  std::vector<double> out;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) {
    std::size_t used = 0;
    double v = 0;
    try {
      v = std::stod(item, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    while (used < item.size() && item[used] == ' ') ++used;
    if (used == 0 || used != item.size() || !std::isfinite(v))
      throw UsageError(fmt::format("{}: '{}' is not a finite number", option, item));
    out.push_back(v);
  }
  if (!text.empty() && text.back() == ',')
    throw UsageError(fmt::format("{}: trailing comma in '{}'", option, text));
  if (out.size() != n)
    throw UsageError(
        fmt::format("{}: expected {} comma-separated numbers, got {} ('{}')", option, n, out.size(), text));
  return out;
}

int parse_int(const std::string& option, const std::string& text, int lo, int hi) {
  std::size_t used = 0;
  long v = 0;
  try {
    v = std::stol(text, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used == 0 || used != text.size() || v < lo || v > hi)
    throw UsageError(fmt::format("{}: '{}' is not an integer in [{}, {}]", option, text, lo, hi));
  return static_cast<int>(v);
}

// Squared distance from x to the simplex spanned by p[0..k): the projection onto the affine
// hull if it lies inside, else the nearest of the facets (k ≤ 4, so the recursion is tiny).
double dist2_to_simplex(const Vec3* p, int k, const Vec3& x) {
  if (k == 1) {
    const Vec3 d = sub(x, p[0]);
    return dot(d, d);
  }
  // Normal equations G λ = r for x ≈ p0 + Σ λ_i (p_i − p0), solved by Gaussian elimination.
  const int m = k - 1;
  double g[3][4];
  for (int i = 0; i < m; ++i) {
    const Vec3 ei = sub(p[i + 1], p[0]);
    for (int j = 0; j < m; ++j) g[i][j] = dot(ei, sub(p[j + 1], p[0]));
    g[i][m] = dot(ei, sub(x, p[0]));
  }
  bool solved = true;
  for (int c = 0; c < m && solved; ++c) {
    int piv = c;
    for (int r = c + 1; r < m; ++r)
      if (std::abs(g[r][c]) > std::abs(g[piv][c])) piv = r;
    if (std::abs(g[piv][c]) < 1e-300) solved = false;
    if (!solved) break;
    for (int j = 0; j <= m; ++j) std::swap(g[c][j], g[piv][j]);
    for (int r = 0; r < m; ++r) {
      if (r == c) continue;
      const double f = g[r][c] / g[c][c];
      for (int j = c; j <= m; ++j) g[r][j] -= f * g[c][j];
    }
  }
  if (solved) {
    double lam0 = 1;
    bool inside = true;
    Vec3 q = p[0];
    for (int i = 0; i < m; ++i) {
      const double l = g[i][m] / g[i][i];
      inside = inside && l >= 0;
      lam0 -= l;
      q = axpy(q, l, sub(p[i + 1], p[0]));
    }
    if (inside && lam0 >= 0) {
      const Vec3 d = sub(x, q);
      return dot(d, d);
    }
  }
  double best = std::numeric_limits<double>::infinity();
  for (int drop = 0; drop < k; ++drop) {
    Vec3 f[4];
    int n = 0;
    for (int i = 0; i < k; ++i)
      if (i != drop) f[n++] = p[i];
    best = std::min(best, dist2_to_simplex(f, k - 1, x));
  }
  return best;
}

enum class Target { kPoint, kPlane, kSphere };

struct Goal {
  Target target;
  Vec3 at{0, 0, 0};
  Vec3 normal{0, 0, 0};
  double radius = 0;
};

template <int D>
bool wanted(const Hierarchy<D>& h, ElemId e, const Goal& g) {
  Vec3 p[D + 1];
  for (int i = 0; i <= D; ++i) {
    p[i] = {0, 0, 0};
    for (int a = 0; a < D; ++a) p[i][a] = h.point(h.cell(e)[i])[a];
  }
  // A relative tolerance so that points on shared faces select the elements on both sides.
  double scale = 0;
  for (int i = 1; i <= D; ++i) scale = std::max(scale, distance(p[i], p[0]));
  const double eps = 1e-12 * scale;
  switch (g.target) {
    case Target::kPoint:
      return dist2_to_simplex(p, D + 1, g.at) <= eps * eps;
    case Target::kPlane: {
      double lo = std::numeric_limits<double>::infinity(), hi = -lo;
      for (const Vec3& q : p) {
        const double s = dot(g.normal, sub(q, g.at));
        lo = std::min(lo, s);
        hi = std::max(hi, s);
      }
      return lo <= eps && hi >= -eps;
    }
    case Target::kSphere: {
      double far = 0;
      for (const Vec3& q : p) far = std::max(far, distance(q, g.at));
      return far >= g.radius - eps && std::sqrt(dist2_to_simplex(p, D + 1, g.at)) <= g.radius + eps;
    }
  }
  return false;
}

// Refuses a round the memory budget cannot hold before it allocates (level 12 toward a plane
// took 2.5 GB, then ran out of memory): each marked element gains 2^D red children and its
// closure about 2 green ones, at the hierarchy's present bytes per element, and a growing array
// holds twice its elements for a moment.
template <int D>
void check_round_memory(const Hierarchy<D>& h, std::size_t marked, const MemoryBudget& budget, int round) {
  const std::size_t limit = budget.bytes();
  if (limit == 0) return;
  const double per_element = double(h.memory_bytes()) / double(h.element_count());
  const double after = 2.0 * per_element * double(h.element_count() + marked * ((1u << D) + 2));
  if (after > double(limit))
    throw Error(
        fmt::format("refine: level {} would split {} elements and take about {:.0f} MB, more than "
                    "--max-memory {} (fewer --levels)",
                    round + 1, marked, after / 1048576.0, budget.text()));
}

template <int D>
void run(const RefineArgs& a, const Goal& goal, const std::vector<double>& box, int levels,
         const MemoryBudget& budget) {
  typename Hierarchy<D>::Point lo, hi;
  for (int i = 0; i < D; ++i) {
    lo[i] = box[i];
    hi[i] = box[D + i];
  }
  Hierarchy<D> h = Hierarchy<D>::box(lo, hi);
  for (int round = 0; round < levels; ++round) {
    std::vector<ElemId> marked;
    for (ElemId e : h.leaves())
      if (wanted(h, e, goal)) marked.push_back(e);
    if (marked.empty()) break;
    check_round_memory(h, marked.size(), budget, round);
    h.refine(std::move(marked));
  }
  const std::vector<ElemId> leaves = h.leaves();
  double min_angle = 180;
  for (ElemId e : leaves) {
    std::array<std::array<double, D>, D + 1> p;
    for (int i = 0; i <= D; ++i) p[i] = h.point(h.cell(e)[i]);
    if constexpr (D == 2)
      min_angle = std::min(min_angle, min_angle_deg(p));
    else
      min_angle = std::min(min_angle, min_dihedral_deg(p));
  }

  // Nothing is written until everything is computed; a failed second file removes the first.
  write_vtu<D>(a.output, h, leaves, nullptr, nullptr);
  if (!a.hierarchy.empty()) {
    HierarchyFileInfo info;
    info.metadata = {{"command", "refine"}, {"toward", a.toward}, {"levels", levels}};
    try {
      write_hierarchy<D>(a.hierarchy, h, {}, info);
    } catch (...) {
      std::remove(a.output.c_str());
      throw;
    }
  }
  fmt::print(stderr, "refine: {}D, {} levels, {} vertices, {} leaf elements, min {} {:.2f} deg\n", D,
             h.max_level(), h.vertex_count(), leaves.size(), D == 2 ? "angle" : "dihedral", min_angle);
}

void run_refine(const RefineArgs& a) {
  const int dim = parse_int("--dim", a.dim, 2, 3);
  const std::vector<double> box = parse_list("--box", a.box, 2 * dim);
  for (int i = 0; i < dim; ++i)
    if (!(box[i] < box[dim + i]))
      throw UsageError(fmt::format("--box: the lower corner must be below the upper corner on axis {}", i));
  Goal goal;
  if (a.toward == "point")
    goal.target = Target::kPoint;
  else if (a.toward == "plane")
    goal.target = Target::kPlane;
  else if (a.toward == "sphere")
    goal.target = Target::kSphere;
  else
    throw UsageError(fmt::format("--toward: '{}' is not one of point, plane, sphere", a.toward));
  const std::vector<double> at = parse_list("--at", a.at, dim);
  std::copy(at.begin(), at.end(), goal.at.begin());
  if (goal.target == Target::kPlane) {
    if (a.normal.empty()) throw UsageError("--normal is required with --toward plane");
    const std::vector<double> n = parse_list("--normal", a.normal, dim);
    std::copy(n.begin(), n.end(), goal.normal.begin());
    const double len = std::sqrt(dot(goal.normal, goal.normal));
    if (!(len > 0)) throw UsageError("--normal must not be zero");
    for (double& c : goal.normal) c /= len;
  } else if (!a.normal.empty()) {
    throw UsageError("--normal is only used with --toward plane");
  }
  if (goal.target == Target::kSphere) {
    if (a.radius.empty()) throw UsageError("--radius is required with --toward sphere");
    goal.radius = parse_list("--radius", a.radius, 1)[0];
    if (!(goal.radius > 0)) throw UsageError("--radius must be positive");
  } else if (!a.radius.empty()) {
    throw UsageError("--radius is only used with --toward sphere");
  }
  const int levels = parse_int("--levels", a.levels, 0, kMaxLevels);
  const MemoryBudget budget = pipeline::parse_memory_budget(a.max_memory, "max_memory");
  if (!a.hierarchy.empty() && a.hierarchy == a.output)
    throw UsageError("-o and --hierarchy name the same file");
  if (dim == 2)
    run<2>(a, goal, box, levels, budget);
  else
    run<3>(a, goal, box, levels, budget);
}

void add_refine_command(CLI::App& app) {
  auto args = std::make_shared<RefineArgs>();
  CLI::App* cmd = app.add_subcommand(
      "refine",
      "red-green refine a box toward a point, plane or sphere surface and write the leaf mesh (.vtu)");
  cmd->add_option("--dim", args->dim, "2 (triangles) or 3 (tetrahedra)")->required();
  cmd->add_option("--box", args->box, "x0,y0[,z0],x1,y1[,z1]: lower and upper corner")->required();
  cmd->add_option("--toward", args->toward, "point | plane | sphere")->required();
  cmd->add_option("--at", args->at, "x,y[,z]: the point, a point on the plane, or the sphere's centre")
      ->required();
  cmd->add_option("--normal", args->normal, "nx,ny[,nz]: plane normal (--toward plane)");
  cmd->add_option("--radius", args->radius, "sphere radius (--toward sphere)");
  cmd->add_option("--levels", args->levels, fmt::format("refinement rounds, 0..{}", kMaxLevels))->required();
  cmd->add_option("-o,--output", args->output, "leaf mesh, VTK XML UnstructuredGrid (.vtu)")->required();
  cmd->add_option("--hierarchy", args->hierarchy, "also write the whole hierarchy (.mlfeh)");
  cmd->add_option("--max-memory", args->max_memory,
                  "memory budget: a percentage of RAM (\"50%\"), bytes with K/M/G, or 0 for none; a level "
                  "that would exceed it is refused before it is built")
      ->capture_default_str();
  cmd->callback([args] { run_refine(*args); });
}

}  // namespace

MLFE_REGISTER_COMMAND(10, add_refine_command);

}  // namespace mlfe::cli
