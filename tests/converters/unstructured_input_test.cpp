// The paper's Poisson example as unstructured input: the L-shape solution around the
// re-entrant edge of a cube with a corner cut away, as point values on a tetrahedral mesh
// (.vtu), reduced by mlfe::build and `mlfe build` / `mlfe convert`.
#include <gtest/gtest.h>
#include <mlfe/core/mesh/hierarchy.h>
#include <mlfe/formats/tet_mesh_reader.h>
#include <mlfe/formats/vtu_writer.h>
#include <mlfe/pipeline.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>

#include "tests/test_meshes.h"
#include "tests/test_paths.h"
#include "tests/tet_meshes.h"

namespace mlfe {
namespace {

namespace fs = std::filesystem;
using V3 = std::array<double, 3>;

std::string scratch(const std::string& name) { return test::scratch_dir("unstructured") + "/" + name; }

// The Poisson example written with the repo's .vtu writer (the mesh as a coarse hierarchy).
const std::string& poisson_vtu() {
  static const std::string path = [] {
    const TetMesh m = test::kuhn_mesh(24, test::poisson_u, test::in_cut_corner);
    std::vector<Hierarchy<3>::Point> pts;
    for (const auto& p : m.points) pts.push_back({p[0], p[1], p[2]});
    std::vector<Hierarchy<3>::Cell> cells;
    for (const auto& t : m.tets)
      cells.push_back({VertexId(std::uint32_t(t[0])), VertexId(std::uint32_t(t[1])),
                       VertexId(std::uint32_t(t[2])), VertexId(std::uint32_t(t[3]))});
    const Hierarchy<3> h = Hierarchy<3>::from_coarse(pts, cells);
    const std::string p = scratch("poisson.vtu");
    write_vtu(p, h, h.leaves(), &m.values, nullptr);
    return p;
  }();
  return path;
}

// The approximation's function (linear on every leaf), located with a TetMeshField of the leaves.
TetMeshField leaf_function(const Built& b) {
  const auto& a = b.get<3>();
  return TetMeshField(leaf_mesh(a.hierarchy, a.values));
}

// RMS of (approximation − u) at random points of the mesh (not in the cut corner).
double rms_error_against_u(const Built& b) {
  const TetMeshField approx = leaf_function(b);
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  double sum = 0;
  int n = 0;
  while (n < 20000) {
    const V3 x{u(rng), u(rng), u(rng)};
    if (test::in_cut_corner(x)) continue;
    const double d = approx.value(x) - test::poisson_u(x);  // the frame starts at 0: no offset
    sum += d * d;
    ++n;
  }
  return std::sqrt(sum / n);
}

// Leaves per unit volume within 0.08 of the re-entrant edge (x = y = 0.5, z > 0.5) and far
// from every edge of the cut (at least 0.3 from x = 0.5 and y = 0.5).
std::pair<double, double> leaf_density_near_and_far(const Built& b) {
  const auto& h = b.get<3>().hierarchy;
  double near_count = 0, near_volume = 0, far_count = 0, far_volume = 0;
  for (ElemId e : h.leaves()) {
    V3 c{0, 0, 0};
    for (VertexId v : h.cell(e))
      for (int a = 0; a < 3; ++a) c[a] += h.point(v)[a] / 4;
    if (test::in_cut_corner(c)) continue;
    const double r = std::hypot(c[0] - 0.5, c[1] - 0.5);
    if (r < 0.08 && c[2] > 0.55) {
      near_count += 1;
      near_volume += h.measure(e);
    } else if (std::abs(c[0] - 0.5) > 0.3 && std::abs(c[1] - 0.5) > 0.3) {
      far_count += 1;
      far_volume += h.measure(e);
    }
  }
  return {near_count / near_volume, far_count / far_volume};
}

TEST(UnstructuredInput, PoissonExampleRefinesAtTheReentrantEdgeAndConverges) {
  const TetMesh mesh = read_tet_mesh(poisson_vtu());
  EXPECT_EQ(mesh.tets.size(), std::size_t(6 * 24 * 24 * 24 * 7 / 8));
  std::vector<double> errors;
  for (double percent : {0.5, 0.2, 0.1}) {
    BuildOptions o;
    o.rms = RmsTarget{percent, true};
    o.max_memory = MemoryBudget{0, false, 0};
    const Built b = build(mesh, o);
    SCOPED_TRACE(percent);
    EXPECT_EQ(b.transform.origin, (V3{0, 0, 0}));
    const auto [near, far] = leaf_density_near_and_far(b);
    // At 0.5% the mesh is still about the uniform start (a few levels); the tighter targets
    // refine at the edge.
    if (percent < 0.5) {
      EXPECT_GT(near, 10 * far) << "near " << near << " far " << far;
    }
    errors.push_back(rms_error_against_u(b));
  }
  EXPECT_LT(errors[1], 0.7 * errors[0]) << errors[0] << " " << errors[1];
  EXPECT_LT(errors[2], 0.85 * errors[1]) << errors[1] << " " << errors[2];
}

// An ASCII .vtu of `m` with every point, used or not (readers keep them: VTK files may carry
// points no cell uses): its values as the point-data array "u", then `w`, when given, as "w".
std::string ascii_vtu(const TetMesh& m, const std::vector<double>* w = nullptr) {
  std::ostringstream s;
  s.precision(17);
  s << "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"1.0\">\n<UnstructuredGrid>\n"
    << "<Piece NumberOfPoints=\"" << m.points.size() << "\" NumberOfCells=\"" << m.tets.size() << "\">\n"
    << "<PointData>\n<DataArray type=\"Float64\" Name=\"u\" format=\"ascii\">";
  for (double v : m.values) s << v << " ";
  s << "</DataArray>\n";
  if (w) {
    s << "<DataArray type=\"Float64\" Name=\"w\" format=\"ascii\">";
    for (double v : *w) s << v << " ";
    s << "</DataArray>\n";
  }
  s << "</PointData>\n<Points>\n"
    << "<DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"ascii\">";
  for (const auto& p : m.points) s << p[0] << " " << p[1] << " " << p[2] << " ";
  s << "</DataArray>\n</Points>\n<Cells>\n<DataArray type=\"Int32\" Name=\"connectivity\" format=\"ascii\">";
  for (const auto& t : m.tets) s << t[0] << " " << t[1] << " " << t[2] << " " << t[3] << " ";
  s << "</DataArray>\n<DataArray type=\"Int32\" Name=\"offsets\" format=\"ascii\">";
  for (std::size_t c = 1; c <= m.tets.size(); ++c) s << 4 * c << " ";
  s << "</DataArray>\n<DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">";
  for (std::size_t c = 0; c < m.tets.size(); ++c) s << "10 ";
  s << "</DataArray>\n</Cells>\n</Piece>\n</UnstructuredGrid>\n</VTKFile>\n";
  return s.str();
}

// The file's error figures are at the input's samples: the points of its tetrahedra. Points no
// tetrahedron uses (here the lattice points inside the cut corner, carrying the linear
// function's values, which the closest-point extension does not take) are not samples: the
// figures equal those of the same mesh without them.
TEST(UnstructuredInput, FileErrorsAreMeasuredAtThePointsTheTetrahedraUse) {
  const auto linear = [](const V3& p) { return 1 + 2 * p[0] - p[1] + 0.5 * p[2]; };
  const TetMesh all = test::kuhn_mesh(6, linear, test::in_cut_corner);
  TetMesh used = all;
  used.points.clear();
  used.values.clear();
  std::vector<std::int32_t> renumber(all.points.size(), -1);
  for (auto& t : used.tets)
    for (auto& v : t) {
      if (renumber[std::size_t(v)] < 0) {
        renumber[std::size_t(v)] = std::int32_t(used.points.size());
        used.points.push_back(all.points[std::size_t(v)]);
        used.values.push_back(all.values[std::size_t(v)]);
      }
      v = renumber[std::size_t(v)];
    }
  ASSERT_LT(used.points.size(), all.points.size());
  const auto file_errors = [](const TetMesh& m, const std::string& name) {
    const std::string vtu = scratch(name + ".vtu"), report = scratch(name + ".json");
    test::write_bytes(vtu, ascii_vtu(m));
    const auto r = test::run_mlfe("build " + vtu + " -o " + scratch(name + ".mlfeh") + " --report " + report +
                                  " --quiet");
    EXPECT_EQ(r.status, 0) << r.err;
    const nlohmann::json j = nlohmann::json::parse(test::read_bytes(report));
    return std::pair{j["file"]["rms_error"].get<double>(), j["file"]["max_error"].get<double>()};
  };
  const auto with_unused = file_errors(all, "with_unused"), without = file_errors(used, "without_unused");
  EXPECT_EQ(with_unused, without);
  EXPECT_LT(without.second, 0.01);  // range 3.5: the linear function is nearly exact on the mesh
}

// The library's convert from a path reads the point-data array VolumeReadOptions::grid_name
// names, as the command line's --grid does: the same surface as from a file holding that array
// alone.
TEST(UnstructuredInput, ConvertFromAPathReadsTheNamedArray) {
  const TetMesh m = test::kuhn_mesh(6, [](const V3& p) { return p[0] + p[1]; });
  TetMesh only_w = m;
  for (std::size_t i = 0; i < m.points.size(); ++i) only_w.values[i] = test::poisson_u(m.points[i]) + 1;
  const std::string both = scratch("two_arrays.vtu"), single = scratch("w_only.vtu");
  test::write_bytes(both, ascii_vtu(m, &only_w.values));
  test::write_bytes(single, ascii_vtu(only_w));
  ConvertOptions o;
  o.asset.iso = {1.2};
  VolumeReadOptions w;
  w.grid_name = "w";
  const std::string from_both = scratch("from_both.ply"), from_single = scratch("from_single.ply"),
                    from_u = scratch("from_u.ply");
  convert(both, from_both, o, w);
  convert(single, from_single, o);
  convert(both, from_u, o);
  EXPECT_EQ(test::read_bytes(from_single).find("element face 0\n"), std::string::npos);  // a surface
  EXPECT_EQ(test::read_bytes(from_both), test::read_bytes(from_single));
  EXPECT_NE(test::read_bytes(from_u), test::read_bytes(from_single));
}

TEST(UnstructuredInput, CommandLineBuildsAndConvertsAMesh) {
  const std::string h = scratch("poisson.mlfeh"), report = scratch("poisson.json"),
                    glb = scratch("poisson.glb");
  auto r =
      test::run_mlfe("build " + poisson_vtu() + " -o " + h + " --rms 1% --report " + report + " --quiet");
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_TRUE(fs::exists(h));
  std::ifstream in(report);
  const nlohmann::json j = nlohmann::json::parse(in);
  EXPECT_EQ(j["tetrahedra"], 6 * 24 * 24 * 24 * 7 / 8);
  EXPECT_LT(j["file"]["rms_error"].get<double>(), 0.02);  // at the mesh's points, in data units
  EXPECT_GT(j["vertices"].get<double>(), 100);
  // The hierarchy is in the input's frame and reads back.
  const Built back = built_from_file(h);
  EXPECT_EQ(back.leaves(), j["elements"].get<std::size_t>());

  r = test::run_mlfe("convert " + poisson_vtu() + " -o " + glb + " --iso 0.3 --quiet");
  ASSERT_EQ(r.status, 0) << r.err;
  // The same bytes with one thread (point location is sequential per point, ties by index).
  const std::string h1 = scratch("poisson_t1.mlfeh"), glb1 = scratch("poisson_t1.glb");
  ASSERT_EQ(test::run_mlfe("--threads 1 build " + poisson_vtu() + " -o " + h1 + " --rms 1% --quiet").status,
            0);
  ASSERT_EQ(
      test::run_mlfe("--threads 1 convert " + poisson_vtu() + " -o " + glb1 + " --iso 0.3 --quiet").status,
      0);
  EXPECT_EQ(test::read_bytes(h1), test::read_bytes(h));
  EXPECT_EQ(test::read_bytes(glb1), test::read_bytes(glb));
  EXPECT_GT(fs::file_size(glb), 1000u);
  r = test::run_mlfe("iso " + poisson_vtu() + " -o " + scratch("iso.ply") + " --iso 0.3 --quiet");
  ASSERT_EQ(r.status, 0) << r.err;

  // What needs a voxel volume says so; bad input exits 2 and writes nothing.
  r = test::run_mlfe("render " + poisson_vtu() + " --reference -o " + scratch("r.exr"));
  EXPECT_EQ(r.status, 2);
  EXPECT_NE(r.err.find("--reference needs a volume"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(scratch("r.exr")));
  const std::string cut = scratch("cut.vtu"), out = scratch("cut.mlfeh");
  {
    std::ifstream src(poisson_vtu(), std::ios::binary);
    std::string bytes((std::istreambuf_iterator<char>(src)), {});
    std::ofstream(cut, std::ios::binary) << bytes.substr(0, bytes.size() / 2);
  }
  r = test::run_mlfe("build " + cut + " -o " + out);
  EXPECT_EQ(r.status, 2);
  EXPECT_NE(r.err.find(cut + ": "), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(out));
}

// ---- mlfe render on the mesh itself (no build) ----

// A constant field on the cube with the corner [0.5, 1]^3 cut away, and a transfer function of
// constant opacity 0.3 per 0.25 (ParaView JSON, so it does not depend on the value range).
struct ConstantCutCube {
  TetMesh mesh = test::kuhn_mesh(
      8, [](const V3&) { return 1.0; }, test::in_cut_corner);
  std::string tf = scratch("constant_tf.json");
  ConstantCutCube() {
    mesh.source = "cut_cube.vtu";
    std::ofstream(tf) << R"([{"Name": "constant", "RGBPoints": [0, 1, 1, 1, 2, 1, 1, 1],
                             "Points": [0, 0.3, 0.5, 0, 2, 0.3, 0.5, 0]}])";
  }
};

TEST(UnstructuredRender, ImageIsTheIntegralThroughTheNonConvexMesh) {
  // Every pixel's opacity against 1 − (1 − 0.3)^(length in the mesh / 0.25), the length being
  // the chord in the cube minus the chord in the cut corner: rays that cross the material, the
  // cut and the material again must get both parts. The view looks across the cut.
  const ConstantCutCube c;
  pipeline::RenderFileOptions o;
  o.tf = c.tf;
  o.tf_unit = 0.25;
  o.size = {40, 32};
  o.azimuth = 225;
  o.elevation = 30;
  o.stop_opacity = 1;
  const pipeline::RenderResult r = pipeline::render_images(c.mesh, o);
  ASSERT_EQ(r.frames.size(), 1u);
  const pipeline::RenderFrame& f = r.frames[0];
  EXPECT_EQ(r.tetrahedra, c.mesh.tets.size());
  EXPECT_GT(f.stats.reentries, 0u);
  EXPECT_EQ(f.stats.step_bound_hits, 0u);
  int covered = 0;
  for (int y = 0; y < f.height; ++y)
    for (int x = 0; x < f.width; ++x) {
      V3 ro, rd;
      f.camera.ray(x, y, ro, rd);
      const double len =
          test::box_chord({0, 0, 0}, {1, 1, 1}, ro, rd) - test::box_chord({0.5, 0.5, 0.5}, {1, 1, 1}, ro, rd);
      covered += len > 0;
      EXPECT_NEAR(f.image.rgba[4 * (y * f.width + x) + 3], 1 - std::pow(0.7, len / 0.25), 1e-5)
          << x << "," << y;
    }
  EXPECT_GT(covered, 300);
}

TEST(UnstructuredRender, CommandLineRendersVtuAndMshSameBytesWithOneAndTwoThreads) {
  const std::string a = scratch("mesh1.exr"), b = scratch("mesh2.exr");
  const std::string opts =
      " --tf hot --size 64x48 --azimuth 225 --elevation 20 --camera perspective --shading";
  auto r = test::run_mlfe("--threads 1 render " + poisson_vtu() + " -o " + a + opts);
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.err.find("re-entries"), std::string::npos) << r.err;  // the view crosses the cut
  ASSERT_EQ(test::run_mlfe("--threads 2 render " + poisson_vtu() + " -o " + b + opts).status, 0);
  EXPECT_GT(fs::file_size(a), 1000u);
  EXPECT_EQ(test::read_bytes(a), test::read_bytes(b));
  // The repository's small meshes, .msh and .vtu, with the array named.
  for (const char* name : {"small_tets_bin22.msh", "small_tets_raw.vtu"}) {
    const std::string out = scratch(std::string(name) + ".exr");
    r = test::run_mlfe("render " + test::test_data_path(name) + " -o " + out + " --size 32x32 --quiet");
    EXPECT_EQ(r.status, 0) << name << ": " << r.err;
    EXPECT_TRUE(fs::exists(out)) << name;
  }
}

TEST(UnstructuredRender, BadMeshesExitTwoWithOneLineAndNoOutput) {
  const std::string out = scratch("bad_mesh.exr");
  const auto expect_rejected = [&](const std::string& mesh, const std::string& why) {
    const auto r = test::run_mlfe("render " + mesh + " -o " + out + " --quiet");
    EXPECT_EQ(r.status, 2) << r.err;
    EXPECT_NE(r.err.find(mesh + ": "), std::string::npos) << r.err;
    EXPECT_NE(r.err.find(why), std::string::npos) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_FALSE(fs::exists(out));
  };
  // A tetrahedron listed twice: its inner faces belong to three tetrahedra.
  {
    const ConstantCutCube c;
    const Hierarchy<3> h = test::coarse_hierarchy(c.mesh);
    std::vector<ElemId> elems = h.leaves();
    elems.push_back(elems[7]);
    const std::string twice = scratch("twice.vtu");
    write_vtu(twice, h, elems, &c.mesh.values, nullptr);
    expect_rejected(twice, "more than two tetrahedra");
  }
  // Only a flat tetrahedron.
  const std::string flat = scratch("flat.vtu");
  std::ofstream(flat) << R"(<?xml version="1.0"?>
<VTKFile type="UnstructuredGrid" version="0.1"><UnstructuredGrid><Piece NumberOfPoints="4" NumberOfCells="1">
<PointData Scalars="u"><DataArray type="Float64" Name="u" format="ascii">0 1 2 3</DataArray></PointData>
<Points><DataArray type="Float64" NumberOfComponents="3" format="ascii">0 0 0 1 0 0 2 0 0 3 0 0</DataArray></Points>
<Cells><DataArray type="Int32" Name="connectivity" format="ascii">0 1 2 3</DataArray>
<DataArray type="Int32" Name="offsets" format="ascii">4</DataArray>
<DataArray type="UInt8" Name="types" format="ascii">10</DataArray></Cells>
</Piece></UnstructuredGrid></VTKFile>
)";
  expect_rejected(flat, "no tetrahedron of positive volume");
  // A truncated file.
  const std::string cut = scratch("cut_render.vtu");
  {
    std::ifstream src(poisson_vtu(), std::ios::binary);
    std::string bytes((std::istreambuf_iterator<char>(src)), {});
    std::ofstream(cut, std::ios::binary) << bytes.substr(0, bytes.size() / 2);
  }
  expect_rejected(cut, "");
  // A level the mesh does not have is a usage error (1).
  EXPECT_EQ(test::run_mlfe("render " + poisson_vtu() + " -o " + out + " --level 1").status, 1);
  EXPECT_FALSE(fs::exists(out));
}

}  // namespace
}  // namespace mlfe
