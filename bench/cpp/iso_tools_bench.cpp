// iso_tools_bench: the C++ side of bench/py/iso_bench.py. All meshes are written in voxel index
// coordinates (x = i, y = j, z = k), the frame in which iso_bench.py measures distances.
//
//   iso_tools_bench dump VOL OUT.raw             float32 voxels (x fastest) + prints JSON
//                                                {dims, spacing, range}
//   iso_tools_bench vdb VOL ISO ADAPTIVITY OUT.ply
//       OpenVDB: dense volume -> FloatGrid (copyFromDense, all voxels active) ->
//       tools::volumeToMesh(grid, points, triangles, quads, ISO, ADAPTIVITY); quads split in two.
//   iso_tools_bench mlfe VOL ISO OUT.ply [--max-vertices N] [--rms P%] [--surface-tolerance S]
//       The in-process mlfe convert pipeline: read, approximate<3> with iso-aware refinement
//       (iso_values = {ISO}), IsoExtractor::extract on the finest level.
//   iso_tools_bench extract HIER.mlfeh ISO OUT.ply [SIMPLIFY_VOXELS [VOLUME SNAP_VOXELS [input|optimal]]]
//       Extraction only, from a stored hierarchy (IsoExtractor construction and extract timed
//       separately; extract repeated 5 times, best reported); optionally snapped onto the
//       volume's iso-surface and simplified as `mlfe convert --snap S --simplify S` does.
//   iso_tools_bench meshopt IN.ply TARGET_TRIANGLES OUT.ply
//       meshoptimizer (Debian libmeshoptimizer-dev): meshopt_simplify to TARGET_TRIANGLES with
//       no error limit (target_error 1: the count decides), unused vertices dropped; what users
//       pair with VTK flying edges. Only the simplification is timed.
// Every mode prints one JSON line on stdout with counts and seconds. --threads N (default 2)
// may precede the mode.
#include <meshoptimizer.h>
#include <mlfe/core/fem/approximation.h>
#include <mlfe/core/field/field.h>
#include <mlfe/core/simplify/simplifier.h>
#include <mlfe/core/surface/iso_surface.h>
#include <mlfe/core/surface/surface_fitting.h>
#include <mlfe/formats/hierarchy_io.h>
#include <mlfe/formats/openmesh_io.h>
#include <mlfe/formats/volume_reader.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/Dense.h>
#include <openvdb/tools/VolumeToMesh.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

using namespace mlfe;
using Clock = std::chrono::steady_clock;
static double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }
// CPU seconds of the whole process (all threads) since `c0`: on the shared, loaded machine the
// stages' wall times swing with the load, their CPU time much less.
static double cpu_since(std::clock_t c0) { return double(std::clock() - c0) / CLOCKS_PER_SEC; }

static double peak_rss_mb() {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("VmHWM:", 0) == 0) return std::atof(line.c_str() + 6) / 1024.0;
  return 0;
}

// Local frame (index .* spacing) -> index coordinates.
static void to_index(TriangleMesh& m, const std::array<double, 3>& sp) {
  for (auto& p : m.positions)
    for (int a = 0; a < 3; ++a) p[a] = float(p[a] / sp[a]);
}

static int usage() {
  std::fprintf(stderr,
               "usage: iso_tools_bench [--threads N] dump VOL OUT.raw\n"
               "       iso_tools_bench [--threads N] vdb VOL ISO ADAPTIVITY OUT.ply\n"
               "       iso_tools_bench [--threads N] mlfe VOL ISO OUT.ply [--max-vertices N] [--rms P%%] "
               "[--surface-tolerance S]\n"
               "       iso_tools_bench [--threads N] extract HIER.mlfeh ISO OUT.ply [SIMPLIFY_VOXELS [VOLUME "
               "SNAP_VOXELS [input|optimal]]]\n"
               "       iso_tools_bench [--threads N] cubes VOL ISO OUT.ply\n"
               "       iso_tools_bench [--threads N] stages VOL ISO SIMPLIFY_VOXELS [OUT.ply]\n"
               "       iso_tools_bench meshopt IN.ply TARGET_TRIANGLES OUT.ply\n");
  return 1;
}

int main(int argc, char** argv) {
  std::vector<std::string> args(argv + 1, argv + argc);
  int threads = 2;
  if (args.size() >= 2 && args[0] == "--threads") {
    threads = std::atoi(args[1].c_str());
    args.erase(args.begin(), args.begin() + 2);
  }
  if (args.empty()) return usage();
  tbb::global_control gc(tbb::global_control::max_allowed_parallelism, std::size_t(std::max(1, threads)));
  nlohmann::json out;
  try {
    const std::string mode = args[0];
    if (mode == "dump" && args.size() == 3) {
      ScalarGrid g = read_volume(args[1]);
      std::ofstream f(args[2], std::ios::binary);
      f.write(reinterpret_cast<const char*>(g.values.data()),
              std::streamsize(g.values.size() * sizeof(float)));
      if (!f) throw std::runtime_error(args[2] + ": write failed");
      const auto r = g.value_range();
      out = {{"dims", g.dims},
             {"spacing", g.transform.spacing},
             {"range", {r[0], r[1]}},
             {"dim", g.dim},
             {"space", g.space},
             {"direction", g.transform.direction},
             {"origin", g.transform.origin}};
    } else if (mode == "vdb" && args.size() == 5) {
      ScalarGrid g = read_volume(args[1]);
      const double iso = std::atof(args[2].c_str());
      const double adaptivity = std::atof(args[3].c_str());
      openvdb::initialize();
      const auto t0 = Clock::now();
      const auto r = g.value_range();
      openvdb::FloatGrid::Ptr grid = openvdb::FloatGrid::create(r[0]);
      const openvdb::CoordBBox bbox(
          openvdb::Coord(0, 0, 0),
          openvdb::Coord(int(g.dims[0] - 1), int(g.dims[1] - 1), int(g.dims[2] - 1)));
      openvdb::tools::Dense<float, openvdb::tools::LayoutXYZ> dense(bbox, g.values.data());
      openvdb::tools::copyFromDense(dense, *grid, /*tolerance=*/-1.0f);  // keep every voxel active
      const double t_grid = since(t0);
      std::vector<openvdb::Vec3s> pts;
      std::vector<openvdb::Vec3I> tris;
      std::vector<openvdb::Vec4I> quads;
      const auto t1 = Clock::now();
      openvdb::tools::volumeToMesh(*grid, pts, tris, quads, iso, adaptivity);
      const double t_mesh = since(t1);
      TriangleMesh m;
      m.positions.reserve(pts.size());
      for (const auto& p : pts) m.positions.push_back({p[0], p[1], p[2]});
      for (const auto& t : tris) m.triangles.push_back({t[0], t[1], t[2]});
      for (const auto& q : quads) {
        m.triangles.push_back({q[0], q[1], q[2]});
        m.triangles.push_back({q[0], q[2], q[3]});
      }
      write_mesh_file(args[4], m);
      out = {{"method", "openvdb"},
             {"adaptivity", adaptivity},
             {"iso", iso},
             {"active_voxels", grid->activeVoxelCount()},
             {"grid_seconds", t_grid},
             {"mesh_seconds", t_mesh},
             {"seconds", t_grid + t_mesh},
             {"vertices", m.positions.size()},
             {"triangles", m.triangles.size()},
             {"quads", quads.size()},
             {"peak_rss_mb", peak_rss_mb()}};
    } else if (mode == "mlfe" && args.size() >= 4) {
      ApproximationOptions o;
      std::string rms = "0.5%";
      for (std::size_t i = 4; i + 1 < args.size(); i += 2) {
        if (args[i] == "--max-vertices")
          o.max_vertices = std::size_t(std::atoll(args[i + 1].c_str()));
        else if (args[i] == "--rms")
          rms = args[i + 1];
        else if (args[i] == "--surface-tolerance")
          o.surface_tolerance = std::atof(args[i + 1].c_str());
        else
          return usage();
      }
      const auto t0 = Clock::now();
      ScalarGrid g = read_volume(args[1]);
      const double t_read = since(t0);
      const double iso = std::atof(args[2].c_str());
      const auto r = g.value_range();
      const double span = double(r[1]) - double(r[0]);
      const bool pct = !rms.empty() && rms.back() == '%';
      o.target_rms =
          pct ? std::atof(rms.substr(0, rms.size() - 1).c_str()) / 100.0 * span : std::atof(rms.c_str());
      o.iso_values = {iso};
      const auto t1 = Clock::now();
      GridField f(g);
      Approximation<3> a = approximate<3>(f, o);
      const double t_build = since(t1);
      const auto t2 = Clock::now();
      IsoExtractor x(a.hierarchy, a.values);
      GridTransform local;  // identity: positions stay in the local frame
      TriangleMesh m = x.extract(iso, local);
      const double t_extract = since(t2);
      to_index(m, g.transform.spacing);
      write_mesh_file(args[3], m);
      out = {{"method", "mlfe"},
             {"iso", iso},
             {"read_seconds", t_read},
             {"build_seconds", t_build},
             {"extract_seconds", t_extract},
             {"seconds", t_read + t_build + t_extract},
             {"hierarchy_vertices", a.hierarchy.vertex_count()},
             {"iterations", a.iterations.size()},
             {"stop", a.stop_reason},
             {"psnr_db", a.iterations.back().psnr_db},
             {"vertices", m.positions.size()},
             {"triangles", m.triangles.size()},
             {"peak_rss_mb", peak_rss_mb()}};
    } else if (mode == "extract" &&
               (args.size() == 4 || args.size() == 5 || args.size() == 7 || args.size() == 8)) {
      HierarchyFile hf = read_hierarchy(args[1]);
      if (hf.dim != 3 || hf.values.empty())
        throw std::runtime_error(args[1] + ": needs a 3D hierarchy with values");
      const Hierarchy<3>& h = std::get<Hierarchy<3>>(hf.hierarchy);
      const double iso = std::atof(args[2].c_str());
      const auto t0 = Clock::now();
      IsoExtractor x(h, hf.values);
      const double t_setup = since(t0);
      GridTransform local;
      // As `mlfe convert --snap S`: vertices moved onto the volume's iso-surface.
      std::optional<ScalarGrid> volume;
      std::optional<GridField> field;
      IsoOptions io;
      if (args.size() >= 7 && std::atof(args[6].c_str()) > 0) {
        volume = read_volume(args[5]);
        field.emplace(*volume);
        const auto& sp = hf.transform.spacing;
        io.snap_to = &*field;
        io.snap_distance = std::atof(args[6].c_str()) * std::min({sp[0], sp[1], sp[2]});
      }
      TriangleMesh m;
      double best = 1e300;
      for (int rep = 0; rep < 5; ++rep) {
        const auto t1 = Clock::now();
        m = x.extract(iso, local, io);
        best = std::min(best, since(t1));
      }
      // As `mlfe convert --simplify S`: S voxels of the smallest spacing, in the local frame.
      double t_simplify = 0;
      const std::size_t extracted = m.triangles.size();
      if (args.size() >= 5 && std::atof(args[4].c_str()) > 0) {
        const double s = std::atof(args[4].c_str());
        const auto& sp = hf.transform.spacing;
        const auto t3 = Clock::now();
        SimplifyOptions so;
        so.tolerance = s * std::min({sp[0], sp[1], sp[2]});
        if (args.size() == 8 && args[7] == "optimal") so.placement = Placement::kOptimal;
        m = simplify_within(m, so);
        t_simplify = since(t3);
      }
      to_index(m, hf.transform.spacing);
      write_mesh_file(args[3], m);
      out = {{"method", "mlfe-extract"},
             {"iso", iso},
             {"setup_seconds", t_setup},
             {"extract_seconds", best},
             {"simplify_seconds", t_simplify},
             {"extracted_triangles", extracted},
             {"hierarchy_vertices", h.vertex_count()},
             {"leaves", h.leaves().size()},
             {"vertices", m.positions.size()},
             {"triangles", m.triangles.size()}};
    } else if (mode == "meshopt" && args.size() == 4) {
      const TriangleMesh in = read_mesh_file(args[1]);
      const std::size_t target = std::strtoull(args[2].c_str(), nullptr, 10);
      const auto t0 = Clock::now();
      std::vector<unsigned> idx(in.triangles.size() * 3), dst(idx.size());
      for (std::size_t t = 0; t < in.triangles.size(); ++t)
        for (int k = 0; k < 3; ++k) idx[3 * t + k] = in.triangles[t][k];
      float err = 0;
      const std::size_t n =
          meshopt_simplify(dst.data(), idx.data(), idx.size(), &in.positions[0][0], in.positions.size(),
                           sizeof(float) * 3, target * 3, 1.0f, 0, &err);
      dst.resize(n);
      std::vector<std::array<float, 3>> pos(in.positions.size());
      const std::size_t nv = meshopt_optimizeVertexFetch(
          pos.data(), dst.data(), dst.size(), in.positions.data(), in.positions.size(), sizeof(float) * 3);
      const double t_simplify = since(t0);
      TriangleMesh m;
      m.positions.assign(pos.begin(), pos.begin() + static_cast<std::ptrdiff_t>(nv));
      for (std::size_t i = 0; i < dst.size(); i += 3) m.triangles.push_back({dst[i], dst[i + 1], dst[i + 2]});
      write_mesh_file(args[3], m);
      out = {{"method", "meshopt_simplify"},
             {"simplify_seconds", t_simplify},
             {"relative_error", err},
             {"absolute_error", err * meshopt_simplifyScale(&in.positions[0][0], in.positions.size(), 12)},
             {"vertices", m.positions.size()},
             {"triangles", m.triangles.size()}};
    } else if (mode == "stages" && (args.size() == 4 || args.size() == 5)) {
      // stages VOL ISO VOXELS [OUT.ply]: the default simplification's runs timed one by one (auto,
      // ratio 0.1, optimal placement) on the lattice surface, for where convert's time goes.
      const ScalarGrid g = read_volume(args[1]);
      auto t0 = Clock::now();
      std::clock_t c0 = std::clock();
      const TriangleMesh m = lattice_iso_surface(g, std::atof(args[2].c_str()));
      out = {
          {"extract_seconds", since(t0)}, {"extract_cpu", cpu_since(c0)}, {"triangles", m.triangles.size()}};
      SimplifierOptions so;
      so.tolerance = std::atof(args[3].c_str()) *
                     std::min({g.transform.spacing[0], g.transform.spacing[1], g.transform.spacing[2]});
      so.ratio = 0.1;
      so.placement = Placement::kOptimal;
      const auto stages = simplify_stages(so, m.triangles.size());
      TriangleMesh s = m;
      for (std::size_t k = 0; k < stages.size(); ++k) {
        t0 = Clock::now();
        c0 = std::clock();                    // the stage's CPU includes its ordering
        if (k > 0) s = spatially_ordered(s);  // as simplify() does
        const double t_order = since(t0);
        t0 = Clock::now();
        s = simplify_within(s, stages[k]);
        out["stage" + std::to_string(k)] = {{"order_seconds", t_order},
                                            {"seconds", since(t0)},
                                            {"cpu", cpu_since(c0)},
                                            {"triangles", s.triangles.size()}};
      }
      t0 = Clock::now();
      c0 = std::clock();
      SurfaceFitOptions fo;
      fo.tolerance = so.tolerance;
      fit_surface(s, m, fo);
      out["fit_seconds"] = since(t0);
      out["fit_cpu"] = cpu_since(c0);
      if (args.size() == 5) write_mesh_file(args[4], s);
    } else if (mode == "cubes" && args.size() == 4) {
      // cubes VOL ISO OUT.ply: mlfe's marching cubes on the samples' lattice
      const ScalarGrid g = read_volume(args[1]);
      const auto t0 = Clock::now();
      const TriangleMesh m = lattice_iso_surface(g, std::atof(args[2].c_str()));
      const double secs = since(t0);
      write_mesh_file(args[3], m);
      out = {{"method", "lattice marching cubes"},
             {"seconds", secs},
             {"triangles", m.triangles.size()},
             {"vertices", m.positions.size()}};
    } else if (mode == "kuhn" && args.size() == 4) {
      // kuhn VOL ISO OUT.ply: marching tetrahedra on the Kuhn triangulation of every voxel cube
      // (the finest level of the samples' lattice), index coordinates, welded.
      const ScalarGrid g = read_volume(args[1]);
      const double iso = std::atof(args[2].c_str());
      const auto t0 = Clock::now();
      TriangleMesh m;
      std::map<std::pair<std::int64_t, std::int64_t>, unsigned> welded;
      static const int kPaths[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
      for (std::int64_t k = 0; k + 1 < g.dims[2]; ++k)
        for (std::int64_t j = 0; j + 1 < g.dims[1]; ++j)
          for (std::int64_t i = 0; i + 1 < g.dims[0]; ++i)
            for (const auto& path : kPaths) {
              std::array<std::array<std::int64_t, 3>, 4> c;
              c[0] = {i, j, k};
              for (int s = 0; s < 3; ++s) {
                c[s + 1] = c[s];
                ++c[s + 1][path[s]];
              }
              std::array<double, 4> v;
              int inside = 0;
              for (int q = 0; q < 4; ++q) {
                v[q] = g.at(c[q][0], c[q][1], c[q][2]) - iso;
                inside += v[q] > 0;
              }
              if (inside == 0 || inside == 4) continue;
              // Welded: one vertex per cut lattice edge (keyed by its two samples).
              auto cut = [&](int a, int b) {
                auto lin = [&](int q) { return c[q][0] + g.dims[0] * (c[q][1] + g.dims[1] * c[q][2]); };
                const std::int64_t la = lin(a), lb = lin(b);
                const auto key = std::make_pair(std::min(la, lb), std::max(la, lb));
                const auto found = welded.find(key);
                if (found != welded.end()) return found->second;
                const double t = v[a] / (v[a] - v[b]);
                std::array<float, 3> p;
                for (int x = 0; x < 3; ++x) p[x] = float(c[a][x] + t * double(c[b][x] - c[a][x]));
                m.positions.push_back(p);
                welded.emplace(key, unsigned(m.positions.size() - 1));
                return unsigned(m.positions.size() - 1);
              };
              std::vector<int> in, out;
              for (int q = 0; q < 4; ++q) (v[q] > 0 ? in : out).push_back(q);
              // Oriented toward lower values (from an inside corner to an outside one).
              const std::size_t first = m.triangles.size();
              if (in.size() == 1 || out.size() == 1) {
                const auto& one = in.size() == 1 ? in : out;
                const auto& rest = in.size() == 1 ? out : in;
                m.triangles.push_back({cut(one[0], rest[0]), cut(one[0], rest[1]), cut(one[0], rest[2])});
              } else {
                const unsigned a = cut(in[0], out[0]), b = cut(in[0], out[1]), cc = cut(in[1], out[1]),
                               d = cut(in[1], out[0]);
                m.triangles.push_back({a, b, cc});
                m.triangles.push_back({a, cc, d});
              }
              for (std::size_t t = first; t < m.triangles.size(); ++t) {
                auto& tri = m.triangles[t];
                const auto& p0 = m.positions[tri[0]];
                const auto& p1 = m.positions[tri[1]];
                const auto& p2 = m.positions[tri[2]];
                const double e1[3] = {p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]};
                const double e2[3] = {p2[0] - p0[0], p2[1] - p0[1], p2[2] - p0[2]};
                const double n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                                     e1[0] * e2[1] - e1[1] * e2[0]};
                double dot = 0;
                for (int x = 0; x < 3; ++x) dot += n[x] * double(c[in[0]][x] - c[out[0]][x]);
                if (dot > 0) std::swap(tri[1], tri[2]);
              }
            }
      const double secs = since(t0);
      write_mesh_file(args[3], m);
      out = {{"method", "kuhn marching tetrahedra"}, {"seconds", secs}, {"triangles", m.triangles.size()}};
    } else if (mode == "simplify" && args.size() >= 4) {
      // simplify IN.ply TOLERANCE OUT.ply [MIN_TRIANGLES [optimal|input [verify|estimate [flip|noflip]]]]
      const TriangleMesh in = read_mesh_file(args[1]);
      SimplifyOptions so;
      so.tolerance = std::atof(args[2].c_str());
      if (args.size() > 4) so.min_triangles = std::strtoull(args[4].c_str(), nullptr, 10);
      so.placement = args.size() > 5 && args[5] == "input" ? Placement::kInputVertex : Placement::kOptimal;
      so.verify_bound = args.size() > 6 && args[6] == "verify";
      so.flip_edges = !(args.size() > 7 && args[7] == "noflip");
      const auto t0 = Clock::now();
      SimplifyStats st;
      const TriangleMesh m = simplify_within(in, so, &st);
      const double t_simplify = since(t0);
      write_mesh_file(args[3], m);
      out = {{"method", "simplify_within"},
             {"simplify_seconds", t_simplify},
             {"passes", st.passes},
             {"collapses", st.collapses},
             {"flips", st.flips},
             {"vertices", m.positions.size()},
             {"triangles", m.triangles.size()}};
    } else {
      return usage();
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "iso_tools_bench: %s\n", e.what());
    return 2;
  }
  std::printf("%s\n", out.dump().c_str());
  return 0;
}
