// `mlfe export`: the approximation on the source grid in every volume format reads back with
// mlfe's own readers to the same values and physical frame, its RMS against the input is the
// file's reported error, and the leaf mesh is a valid .vtu (read by VTK) and Gmsh .msh.
#include <gtest/gtest.h>
#include <mlfe/core/fem/hierarchy_resample.h>
#include <mlfe/core/fem/sample_lattice.h>
#include <mlfe/formats/hierarchy_io.h>
#include <mlfe/formats/volume_reader.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>
#include <string>

#include "tests/test_meshes.h"
#include "tests/test_paths.h"

namespace fs = std::filesystem;

namespace mlfe {
namespace {

const std::string kSkull = std::string(MLFE_SOURCE_DIR) + "/samples/ct_skull_64.nrrd";
const std::string kMri = std::string(MLFE_SOURCE_DIR) + "/tests/data/mri_small_bigendian.nii";

using RunResult = test::CliResult;
using test::read_bytes;

std::string scratch() { return test::scratch_dir("export"); }
RunResult run(const std::string& args) { return test::run_mlfe(args); }

// Physical position of voxel (i, j, k) in RAS (NIfTI's frame), whatever the grid's space.
std::array<double, 3> ras(const ScalarGrid& g, double i, double j, double k) {
  auto p = g.transform.index_to_physical(i, j, k);
  if (g.space == "LPS") p[0] = -p[0], p[1] = -p[1];
  return p;
}

void expect_same_frame(const ScalarGrid& a, const ScalarGrid& b, const std::string& what) {
  ASSERT_EQ(a.dims, b.dims) << what;
  const double n0 = a.dims[0] - 1, n1 = a.dims[1] - 1, n2 = a.dims[2] - 1;
  for (const auto& c : {std::array<double, 3>{0, 0, 0}, {n0, 0, 0}, {0, n1, 0}, {0, 0, n2}, {n0, n1, n2}}) {
    const auto p = ras(a, c[0], c[1], c[2]), q = ras(b, c[0], c[1], c[2]);
    for (int r = 0; r < 3; ++r)
      EXPECT_NEAR(p[r], q[r], 1e-4 * (1 + std::fabs(p[r]))) << what << " axis " << r;
  }
}

// The CT voxels as raw float32 in an oblique LPS frame (NIfTI output must convert it to RAS).
std::string oblique_lps_skull() {
  const std::string raw = scratch() + "/oblique.raw";
  fs::copy_file(std::string(MLFE_SOURCE_DIR) + "/tests/data/ct_skull_64.raw", raw,
                fs::copy_options::overwrite_existing);
  const double c = std::cos(0.5), s = std::sin(0.5);
  std::ofstream(raw + ".json") << "{\"dims\":[64,64,64],\"dtype\":\"float32\",\"spacing\":[1.5,2,2.5],"
                               << "\"origin\":[10,-20,5],\"space\":\"LPS\",\"direction\":[" << c << "," << -s
                               << ",0," << s << "," << c << ",0,0,0,1]}";
  return raw;
}

TEST(ExportCommand, VolumesReadBackWithTheSameValuesAndFrame) {
  for (const std::string& input : {kSkull, kMri, oblique_lps_skull()}) {
    const std::string h = scratch() + "/vol.mlfeh";
    ASSERT_EQ(run("build " + input + " -o " + h + " --max-vertices 3000").status, 0) << input;
    const HierarchyFile f = read_hierarchy(h);
    const auto& hh = std::get<Hierarchy<3>>(f.hierarchy);
    const ScalarGrid src = read_volume(input);
    // On the lattice (v3) the grid is the data's, inside T0's padded cube.
    ASSERT_TRUE(f.on_lattice);
    const std::vector<float> want = resample_to_grid(hh, f.values, f.data_dims, f.transform.spacing);
    for (const std::string ext : {".nii.gz", ".nrrd", ".raw", ".vdb"}) {
      const std::string out = scratch() + "/vol" + ext;
      const RunResult r = run("export " + h + " -o " + out);
      ASSERT_EQ(r.status, 0) << ext << r.err;
      const ScalarGrid g = read_volume(out);
      expect_same_frame(src, g, input + " " + ext);
      ASSERT_EQ(g.values.size(), want.size()) << ext;
      EXPECT_EQ(g.values, want) << ext;
      if (ext == std::string(".nrrd") || ext == std::string(".raw")) {
        EXPECT_EQ(g.space, src.space) << ext;
      }
      // The export against the input is the error the file reports (values as decoded).
      const double range = f.value_max - f.value_min;
      const GridErrors e = grid_errors(g.values, src.values, range, input);
      EXPECT_NEAR(e.rms, f.rms_error, 0.02 * f.rms_error) << input << ext;
      EXPECT_NEAR(e.max, f.max_error, 0.02 * f.max_error) << input << ext;
    }
  }
}

TEST(ExportCommand, LevelKIsTheCoarserApproximation) {
  const std::string h = scratch() + "/lvl.mlfeh", full = scratch() + "/lvl_full.raw",
                    one = scratch() + "/lvl_1.raw";
  ASSERT_EQ(run("build " + kSkull + " -o " + h + " --max-vertices 3000").status, 0);
  ASSERT_EQ(run("export " + h + " -o " + full).status, 0);
  ASSERT_EQ(run("export " + h + " --level 1 -o " + one).status, 0);
  const HierarchyFile f1 = read_hierarchy(h, 1);
  const auto& h1 = std::get<Hierarchy<3>>(f1.hierarchy);
  const ScalarGrid a = read_volume(full), b = read_volume(one);
  EXPECT_EQ(b.values, resample_to_grid(h1, f1.values, b.dims, f1.transform.spacing));
  EXPECT_NE(a.values, b.values);
  const ScalarGrid src = read_volume(kSkull);
  const double range = f1.value_max - f1.value_min;
  EXPECT_GT(grid_errors(b.values, src.values, range, "level 1").rms,
            grid_errors(a.values, src.values, range, "all levels").rms);
  const RunResult r = run("export " + h + " --level 99 -o " + scratch() + "/lvl_99.raw");
  EXPECT_EQ(r.status, 1);  // an option out of range: a usage error
  EXPECT_NE(r.err.find("--level"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(scratch() + "/lvl_99.raw"));
}

// The leaves an export writes, and how many vertices they use: on the samples' lattice the
// data's box (padding left out, leaves across its faces refined), else every leaf.
struct Exported {
  std::size_t leaves = 0, vertices = 0;
  int max_level = 0;
  std::vector<double> values;  ///< of the used vertices, in VertexId order (the writers' order)
};
Exported exported(const HierarchyFile& f) {
  Hierarchy<3> h = std::get<Hierarchy<3>>(f.hierarchy);
  std::vector<double> values = f.values;
  std::vector<ElemId> leaves = h.leaves();
  if (f.on_lattice) {
    leaves = leaves_in_data(h, values, sample_lattice(3, f.data_dims, f.transform.spacing, f.lattice_level));
  }
  std::vector<char> used(h.vertex_count(), 0);
  int max_level = 0;
  for (ElemId e : leaves) {
    max_level = std::max(max_level, h.level(e));
    for (VertexId v : h.cell(e)) used[v.value] = 1;
  }
  Exported out{
      leaves.size(), static_cast<std::size_t>(std::count(used.begin(), used.end(), 1)), max_level, {}};
  for (std::size_t v = 0; v < used.size(); ++v)
    if (used[v] && !values.empty()) out.values.push_back(values[v]);
  return out;
}

TEST(ExportCommand, VtuReadsInVtk) {
  const std::string h = scratch() + "/mesh.mlfeh", vtu = scratch() + "/mesh.vtu";
  ASSERT_EQ(run("build " + kMri + " -o " + h + " --max-vertices 2000").status, 0);
  ASSERT_EQ(run("export " + h + " -o " + vtu).status, 0);
  const HierarchyFile f = read_hierarchy(h);
  const std::string script = std::string(MLFE_SOURCE_DIR) + "/tests/converters/vtu_summary.py";
  const std::string summary = scratch() + "/vtu.txt";
  ASSERT_EQ(std::system(("/usr/bin/python3 " + script + " " + vtu + " > " + summary).c_str()), 0)
      << "python3-vtk9 (scripts/install_deps.sh) reads " << vtu;
  std::istringstream in(read_bytes(summary));
  std::size_t cells = 0, points = 0, tets = 0;
  double umin = 0, umax = 0, vol = 0;
  int lmax = -1;
  in >> cells >> points >> tets >> umin >> umax >> lmax >> vol;
  ASSERT_TRUE(in) << read_bytes(summary);
  const Exported want = exported(f);
  EXPECT_TRUE(f.on_lattice);
  EXPECT_EQ(cells, want.leaves);
  EXPECT_EQ(tets, cells);
  EXPECT_EQ(points, want.vertices);
  EXPECT_EQ(lmax, want.max_level);
  double lo = f.values[0], hi = f.values[0];
  for (double v : f.values) lo = std::min(lo, v), hi = std::max(hi, v);
  EXPECT_DOUBLE_EQ(umin, lo);
  EXPECT_DOUBLE_EQ(umax, hi);
  // The leaves tile the physical box: their volumes sum to its volume.
  const ScalarGrid src = read_volume(kMri);
  const auto e = src.local_extent();
  double det = 0;
  const auto& d = src.transform.direction;
  det = d[0] * (d[4] * d[8] - d[5] * d[7]) - d[1] * (d[3] * d[8] - d[5] * d[6]) +
        d[2] * (d[3] * d[7] - d[4] * d[6]);
  EXPECT_NEAR(vol, std::fabs(det) * e[0] * e[1] * e[2], 1e-6 * vol);
}

TEST(ExportCommand, MshIsAValidGmsh41Mesh) {
  const std::string h = scratch() + "/msh.mlfeh", msh = scratch() + "/msh.msh";
  ASSERT_EQ(run("build " + kSkull + " -o " + h + " --max-vertices 1500").status, 0);
  ASSERT_EQ(run("export " + h + " -o " + msh).status, 0);
  const HierarchyFile f = read_hierarchy(h);
  std::istringstream in(read_bytes(msh));
  std::string tok;
  in >> tok;
  ASSERT_EQ(tok, "$MeshFormat");
  double version = 0;
  int binary = -1, dsize = 0;
  in >> version >> binary >> dsize >> tok;
  EXPECT_EQ(version, 4.1);
  EXPECT_EQ(binary, 0);
  EXPECT_EQ(tok, "$EndMeshFormat");
  while (in >> tok && tok != "$Nodes") {
  }
  std::size_t blocks = 0, nn = 0, lo = 0, hi = 0, edim = 0, etag = 0, param = 0, nb = 0;
  in >> blocks >> nn >> lo >> hi >> edim >> etag >> param >> nb;
  ASSERT_EQ(blocks, 1u);
  ASSERT_EQ(nn, exported(f).vertices);
  EXPECT_EQ(nb, nn);
  std::vector<std::array<double, 3>> xyz(nn);
  for (std::size_t i = 0; i < nn; ++i) {
    std::size_t t = 0;
    in >> t;
    ASSERT_EQ(t, i + 1);
  }
  for (auto& p : xyz) in >> p[0] >> p[1] >> p[2];
  in >> tok;
  ASSERT_EQ(tok, "$EndNodes");
  in >> tok;
  ASSERT_EQ(tok, "$Elements");
  std::size_t ne = 0, type = 0;
  in >> blocks >> ne >> lo >> hi >> edim >> etag >> type >> nb;
  ASSERT_EQ(ne, exported(f).leaves);
  EXPECT_EQ(type, 4u);  // 4-node tetrahedron
  double volume = 0;
  for (std::size_t i = 0; i < ne; ++i) {
    std::size_t t = 0, v[4];
    in >> t >> v[0] >> v[1] >> v[2] >> v[3];
    ASSERT_EQ(t, i + 1);
    for (auto x : v) ASSERT_TRUE(x >= 1 && x <= nn);
    std::array<std::array<double, 3>, 3> d{};
    for (int k = 0; k < 3; ++k)
      for (int r = 0; r < 3; ++r) d[k][r] = xyz[v[k + 1] - 1][r] - xyz[v[0] - 1][r];
    const double det = d[0][0] * (d[1][1] * d[2][2] - d[1][2] * d[2][1]) -
                       d[0][1] * (d[1][0] * d[2][2] - d[1][2] * d[2][0]) +
                       d[0][2] * (d[1][0] * d[2][1] - d[1][1] * d[2][0]);
    ASSERT_GT(det, 0) << "element " << i + 1 << " is not positively oriented";
    volume += det / 6;
  }
  in >> tok;
  EXPECT_EQ(tok, "$EndElements");
  const ScalarGrid src = read_volume(kSkull);
  const auto e = src.local_extent();
  EXPECT_NEAR(volume, e[0] * e[1] * e[2], 1e-6 * volume);
  in >> tok;
  ASSERT_EQ(tok, "$NodeData");
  int nstr = 0;
  std::string name;
  in >> nstr >> name;
  EXPECT_EQ(name, "\"u\"");
  int nreal = 0, nint = 0, step = 0, comps = 0;
  double time = 0;
  std::size_t count = 0;
  in >> nreal >> time >> nint >> step >> comps >> count;
  ASSERT_EQ(count, nn);
  const std::vector<double> want = exported(f).values;
  ASSERT_EQ(want.size(), nn);
  for (std::size_t i = 0; i < nn; ++i) {
    std::size_t t = 0;
    double u = 0;
    in >> t >> u;
    ASSERT_EQ(u, want[i]);  // the writer's vertex order is the used vertices' VertexId order
  }
  in >> tok;
  EXPECT_EQ(tok, "$EndNodeData");
  in >> tok;
  EXPECT_EQ(tok, "$ElementData");
}

TEST(ExportCommand, BadRequestsExit2AndWriteNothing) {
  const std::string h = scratch() + "/bad.mlfeh";
  ASSERT_EQ(run("build " + kSkull + " -o " + h + " --max-vertices 1000").status, 0);
  for (const std::string& out : {scratch() + "/bad.png", scratch() + "/no_such_dir/x.nrrd"}) {
    const RunResult r = run("export " + h + " -o " + out);
    EXPECT_EQ(r.status, 2) << out;
    EXPECT_NE(r.err.find(out), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(out));
  }
  // A truncated file: the error names it, and no output appears.
  const std::string cut = scratch() + "/cut.mlfeh", out = scratch() + "/cut.nii.gz";
  const std::string bytes = read_bytes(h);
  std::ofstream(cut, std::ios::binary) << bytes.substr(0, bytes.size() - 7);
  const RunResult r = run("export " + cut + " -o " + out);
  EXPECT_EQ(r.status, 2);
  EXPECT_NE(r.err.find("cut.mlfeh"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(out));
}

}  // namespace
}  // namespace mlfe
