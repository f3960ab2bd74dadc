// End-to-end tests of `mlfe convert --labels` and `mlfe info --labels`: a label phantom with
// exact answers (nested spheres, two touching boxes, a one-voxel island) and the JHU atlas
// through the command line; validator verdicts, names, colours and label extras, closed and
// outward surfaces, shared interfaces, the same bytes with 1 and 2 threads, bad input.
#include <gtest/gtest.h>
#include <mlfe/core/labels/label_surface.h>
#include <mlfe/formats/gltf_reader.h>
#include <mlfe/formats/openmesh_io.h>
#include <mlfe/formats/volume_writer.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <random>
#include <set>

#include "tests/test_paths.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace mlfe {
namespace {

using test::run_mlfe;

std::string scratch() { return test::scratch_dir("labels"); }

std::string slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

bool validator_accepts(const std::string& path, std::string* report) {
  const std::string out = scratch() + "/validator.txt";
  const int rc = std::system(
      ("node " + std::string(MLFE_SOURCE_DIR) + "/tools/validate_gltf.js " + path + " > " + out + " 2>&1")
          .c_str());
  *report = slurp(out);
  return rc == 0;
}

// The phantom of tests/core/label_surface_test.cpp as a NRRD with a JSON table beside it
// (names for 1, 2, 3 and 7; none for the island 5; 9 absent from the volume).
std::string write_phantom(const std::string& name, float island = 5) {
  ScalarGrid g;
  const int n = 28;
  g.dims = {n, n, n};
  g.transform.spacing = {0.8, 0.8, 1.0};
  g.space = "RAS";
  g.values.resize(std::size_t(n) * n * n);
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const double r = std::sqrt((i - 9.0) * (i - 9.0) + (j - 9.0) * (j - 9.0) + (k - 9.0) * (k - 9.0));
        float v = 0;
        if (i == 3 && j == 9 && k == 9)
          v = island;
        else if (r < 3.5)
          v = 2;
        else if (r < 7.5)
          v = 1;
        else if (i >= 18 && i < 22 && j >= 17 && j < 25 && k >= 17 && k < 25)
          v = 3;
        else if (i >= 22 && i < 26 && j >= 17 && j < 25 && k >= 17 && k < 25)
          v = 7;
        g.values[std::size_t(i + n * (j + n * k))] = v;
      }
  const std::string path = scratch() + "/" + name + ".nrrd";
  write_volume(path, g);
  std::ofstream(scratch() + "/" + name + ".json") << R"({"labels": [
    {"value": 1, "name": "shell", "color": [255, 0, 0]}, {"value": 2, "name": "core", "color": [0, 255, 0]},
    {"value": 3, "name": "left box", "color": [0, 0, 255]}, {"value": 7, "name": "right box"},
    {"value": 9, "name": "absent"}]})";
  return path;
}

// Vertices identified by position (Draco and the writers may split a vertex).
TriangleMesh welded(const TriangleMesh& m) {
  std::map<std::array<float, 3>, std::uint32_t> id;
  TriangleMesh w;
  std::vector<std::uint32_t> to(m.positions.size());
  for (std::size_t v = 0; v < m.positions.size(); ++v) {
    auto [it, added] = id.try_emplace(m.positions[v], std::uint32_t(w.positions.size()));
    if (added) w.positions.push_back(m.positions[v]);
    to[v] = it->second;
  }
  for (const auto& t : m.triangles) w.triangles.push_back({to[t[0]], to[t[1]], to[t[2]]});
  return w;
}

double signed_volume(const TriangleMesh& m) {
  double v = 0;
  for (const auto& t : m.triangles) {
    const auto &a = m.positions[t[0]], &b = m.positions[t[1]], &c = m.positions[t[2]];
    v += (double(a[0]) * (double(b[1]) * c[2] - double(b[2]) * c[1]) -
          double(a[1]) * (double(b[0]) * c[2] - double(b[2]) * c[0]) +
          double(a[2]) * (double(b[0]) * c[1] - double(b[1]) * c[0])) /
         6.0;
  }
  return v;
}

TEST(LabelsCommand, PhantomGivesNamedClosedStructuresSharingTheirInterfaces) {
  const std::string in = write_phantom("phantom");
  const std::string glb = scratch() + "/phantom.glb", report = scratch() + "/phantom.json.report";
  const auto r = run_mlfe("convert " + in + " --labels --no-draco -o " + glb + " --report " + report);
  ASSERT_EQ(r.status, 0) << r.err;
  // The table's label 9 is absent: a warning, not an error.
  EXPECT_NE(r.err.find("warning"), std::string::npos) << r.err;
  std::string v;
  EXPECT_TRUE(validator_accepts(glb, &v)) << v;
  const GltfAsset a = read_gltf(glb);
  // Every structure, in label order, named from the table (label_5 without a name there).
  std::vector<std::string> names;
  std::map<std::string, TriangleMesh> mesh;
  for (const auto& p : a.primitives) {
    const std::string node = a.structure["nodes"][p.node]["name"];
    names.push_back(node);
    mesh[node] = welded(p.mesh_data);
    const std::map<std::string, int> label_of{
        {"shell", 1}, {"core", 2}, {"left box", 3}, {"label_5", 5}, {"right box", 7}};
    EXPECT_EQ(a.structure["nodes"][p.node]["extras"]["label"].get<int>(), label_of.at(node));
  }
  EXPECT_EQ(names, (std::vector<std::string>{"shell", "core", "left box", "label_5", "right box"}));
  // Colours: the table's sRGB red is linear red.
  EXPECT_EQ(a.structure["materials"][0]["pbrMetallicRoughness"]["baseColorFactor"],
            json({1.0, 0.0, 0.0, 1.0}));
  for (const auto& [name, m] : mesh) {
    EXPECT_EQ(unmatched_edges(m), 0u) << name;
    EXPECT_GT(signed_volume(m), 0.0) << name;  // outward (glTF keeps the winding's handedness)
  }
  EXPECT_EQ(connected_pieces(mesh["label_5"]), 1u);
  // Touching structures share their interface: the boxes' common vertices are every vertex of
  // the left box on its right face, and likewise for the core inside the shell.
  for (const auto& [inner, outer] : std::vector<std::pair<std::string, std::string>>{
           {"left box", "right box"}, {"core", "shell"}, {"label_5", "shell"}}) {
    std::set<std::array<float, 3>> po(mesh[outer].positions.begin(), mesh[outer].positions.end());
    std::size_t common = 0;
    for (const auto& p : mesh[inner].positions) common += po.count(p);
    EXPECT_GT(common, 0u) << inner;
    if (inner != "left box") {
      // Enclosed structures: every vertex of theirs is on the surrounding one.
      EXPECT_EQ(common, mesh[inner].positions.size()) << inner;
    }
  }
  const json rep = json::parse(slurp(report));
  EXPECT_EQ(rep["asset"]["structure_count"], 5);
  for (const auto& s : rep["asset"]["structures"]) EXPECT_TRUE(s["closed"].get<bool>()) << s.dump();
}

TEST(LabelsCommand, PickedLabelsMinComponentAndSingleMeshFormats) {
  const std::string in = write_phantom("picked");
  const std::string glb = scratch() + "/picked.glb";
  auto r = run_mlfe("convert " + in + " --labels 3,5-7 -o " + glb + " --quiet");
  ASSERT_EQ(r.status, 0) << r.err;
  const GltfAsset a = read_gltf(glb);
  ASSERT_EQ(a.primitives.size(), 3u);  // 3, 5 and 7 (6 absent: a warning)
  EXPECT_NE(r.err.find("label 6 is absent"), std::string::npos) << r.err;
  std::string v;
  EXPECT_TRUE(validator_accepts(glb, &v)) << v;
  // The island goes with --min-component 2, counted.
  r = run_mlfe("convert " + in + " --labels --min-component 2 -o " + scratch() + "/min.glb");
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.err.find("1 islands removed"), std::string::npos) << r.err;
  EXPECT_EQ(read_gltf(scratch() + "/min.glb").primitives.size(), 4u);
  // One label: any mesh format.
  const std::string ply = scratch() + "/island.ply";
  r = run_mlfe("convert " + in + " --labels 5 -o " + ply);
  ASSERT_EQ(r.status, 0) << r.err;
  const TriangleMesh island = welded(read_mesh_file(ply));
  EXPECT_EQ(unmatched_edges(island), 0u);
  EXPECT_GT(signed_volume(island), 0.0);
  // Two labels into one mesh: refused before any output.
  r = run_mlfe("convert " + in + " --labels 3,7 -o " + scratch() + "/two.ply");
  EXPECT_EQ(r.status, 2);
  EXPECT_FALSE(fs::exists(scratch() + "/two.ply"));
}

TEST(LabelsCommand, CompareMatchesStructuresByName) {
  const std::string in = write_phantom("compare");
  const std::string all = scratch() + "/all.glb", some = scratch() + "/some.glb";
  ASSERT_EQ(run_mlfe("convert " + in + " --labels -o " + all + " --quiet").status, 0);
  ASSERT_EQ(run_mlfe("convert " + in + " --labels 1,3,7 -o " + some + " --quiet").status, 0);
  EXPECT_EQ(run_mlfe("compare " + all + " " + all).status, 0);
  // Structures missing from ACTUAL are named; the others are matched by name, not position.
  const auto r = run_mlfe("compare " + all + " " + some + " --report " + scratch() + "/cmp.json");
  EXPECT_EQ(r.status, 1);
  EXPECT_NE(r.out.find("node 'core' primitive 0 of EXPECTED is not in ACTUAL"), std::string::npos) << r.out;
  const json rep = json::parse(slurp(scratch() + "/cmp.json"));
  EXPECT_EQ(rep["figures"]["primitives_matched_by"], "node name");
  EXPECT_EQ(rep["figures"]["primitives"].size(), 3u);
}

TEST(LabelsCommand, SameBytesWithOneAndTwoThreads) {
  const std::string in = write_phantom("threads");
  ASSERT_EQ(run_mlfe("--threads 1 convert " + in + " --labels -o " + scratch() + "/t1.glb").status, 0);
  ASSERT_EQ(run_mlfe("--threads 2 convert " + in + " --labels -o " + scratch() + "/t2.glb").status, 0);
  EXPECT_EQ(slurp(scratch() + "/t1.glb"), slurp(scratch() + "/t2.glb"));
}

TEST(LabelsCommand, BadLabelsAndTablesAreExit2WithoutOutput) {
  for (float bad : {2.5f, -1.0f, 70000.0f}) {
    const std::string in = write_phantom("bad", bad), out = scratch() + "/bad.glb";
    const auto r = run_mlfe("convert " + in + " --labels -o " + out);
    EXPECT_EQ(r.status, 2) << bad;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_FALSE(fs::exists(out));
  }
  const std::string in = write_phantom("table");
  std::ofstream(scratch() + "/bad_table.txt") << "1 shell\nnot-a-label core\n";
  const auto r = run_mlfe("convert " + in + " --labels --label-table " + scratch() + "/bad_table.txt -o " +
                          scratch() + "/t.glb");
  EXPECT_EQ(r.status, 2);
  EXPECT_NE(r.err.find("line 2"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(scratch() + "/t.glb"));
  EXPECT_EQ(run_mlfe("convert " + in + " --labels 3-x -o " + scratch() + "/t.glb").status, 2);
  // An explicit brick size is refused rather than ignored (usage: exit 1).
  const auto b = run_mlfe("convert " + in + " --labels --bricks 16 -o " + scratch() + "/t.glb");
  EXPECT_EQ(b.status, 1);
  EXPECT_NE(b.err.find("--bricks"), std::string::npos) << b.err;
  EXPECT_FALSE(fs::exists(scratch() + "/t.glb"));
}

// Interfaces scale with their area, not the volume's size: a noisy label map that reads well
// within the budget would need far more for its interfaces, and is refused before they are built.
TEST(LabelsCommand, InterfacesOverTheMemoryBudgetAreExit2WithoutOutput) {
  ScalarGrid g;
  const int n = 48;
  g.dims = {n, n, n};
  g.values.resize(std::size_t(n) * n * n);
  std::mt19937 rng(40);
  for (auto& v : g.values) v = float(rng() % 8);
  const std::string noise = scratch() + "/noise.nrrd", out = scratch() + "/noise.glb";
  write_volume(noise, g);
  const auto r = run_mlfe("convert " + noise + " --labels --max-memory 64M -o " + out);
  EXPECT_EQ(r.status, 2);
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  EXPECT_NE(r.err.find(noise + ": its label interfaces"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("--max-memory 64M"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(out));
  // The phantom's interfaces fit the same budget.
  EXPECT_EQ(run_mlfe("convert " + write_phantom("budget") + " --labels --max-memory 64M -o " + out).status,
            0);
  EXPECT_TRUE(fs::exists(out));
}

TEST(LabelsCommand, InfoListsLabelsWithVoxelsAndVolumes) {
  const std::string in = write_phantom("info");
  const auto r = run_mlfe("info " + in + " --labels --json");
  ASSERT_EQ(r.status, 0) << r.err;
  const json j = json::parse(r.out);
  ASSERT_EQ(j["labels"].size(), 6u);  // background, 1, 2, 3, 5, 7
  EXPECT_EQ(j["labels"][3]["label"], 3);
  EXPECT_EQ(j["labels"][3]["name"], "left box");
  EXPECT_EQ(j["labels"][3]["voxels"], 4 * 8 * 8);
  EXPECT_NEAR(j["labels"][3]["volume_mm3"].get<double>(), 4 * 8 * 8 * 0.64, 1e-9);
  EXPECT_EQ(j["labels"][4]["voxels"], 1);
  EXPECT_EQ(j["labels"][4]["name"], "label_5");
}

// Per physical group of a Gmsh 4.1 file as mlfe writes it (one node block, one element block
// per entity, one physical tag per entity): name -> total tetrahedron volume and count.
std::map<std::string, std::pair<double, std::size_t>> msh_region_volumes(const std::string& path) {
  std::ifstream in(path);
  std::string line;
  std::map<int, std::string> physical_name;
  std::map<int, int> entity_physical;
  std::vector<std::array<double, 3>> xyz;
  std::map<std::string, std::pair<double, std::size_t>> out;
  while (std::getline(in, line)) {
    if (line == "$PhysicalNames") {
      int n;
      in >> n;
      for (int i = 0; i < n; ++i) {
        int dim, tag;
        std::string name;
        in >> dim >> tag;
        std::getline(in >> std::ws, name);
        physical_name[tag] = name.substr(1, name.size() - 2);
      }
    } else if (line == "$Entities") {
      std::size_t np, nc, ns, nv;
      in >> np >> nc >> ns >> nv;
      for (std::size_t e = 0; e < nv; ++e) {
        int tag, nphys, phys, nbound;
        double box[6];
        in >> tag;
        for (double& b : box) in >> b;
        in >> nphys >> phys >> nbound;
        entity_physical[tag] = phys;
      }
    } else if (line == "$Nodes") {
      std::size_t blocks, n, lo, hi, dim, ent, param, count;
      in >> blocks >> n >> lo >> hi >> dim >> ent >> param >> count;
      std::size_t tag;
      for (std::size_t i = 0; i < count; ++i) in >> tag;
      xyz.resize(count);
      for (auto& p : xyz) in >> p[0] >> p[1] >> p[2];
    } else if (line == "$Elements") {
      std::size_t blocks, n, lo, hi;
      in >> blocks >> n >> lo >> hi;
      for (std::size_t b = 0; b < blocks; ++b) {
        std::size_t dim, ent, type, count;
        in >> dim >> ent >> type >> count;
        auto& [volume, elements] = out[physical_name[entity_physical[int(ent)]]];
        for (std::size_t i = 0; i < count; ++i) {
          std::size_t tag, v[4];
          in >> tag >> v[0] >> v[1] >> v[2] >> v[3];
          double d[3][3];
          for (int k = 0; k < 3; ++k)
            for (int r = 0; r < 3; ++r) d[k][r] = xyz[v[k + 1] - 1][r] - xyz[v[0] - 1][r];
          volume += (d[0][0] * (d[1][1] * d[2][2] - d[1][2] * d[2][1]) -
                     d[0][1] * (d[1][0] * d[2][2] - d[1][2] * d[2][0]) +
                     d[0][2] * (d[1][0] * d[2][1] - d[1][1] * d[2][0])) /
                    6.0;
          ++elements;
        }
      }
    }
  }
  return out;
}

// mlfe build --labels stores the labels (exactly) and the table; info lists them as from the
// volume, convert from the file gives the volume's surfaces, export gives regions whose volumes
// are the labels' voxel volumes to within the lattice cells where labels meet.
TEST(LabelsCommand, HierarchyStoresLabelsAndTableAndExportsRegions) {
  const std::string in = write_phantom("hier"), h = scratch() + "/hier.mlfeh";
  auto r = run_mlfe("build " + in + " --labels -o " + h + " --quiet");
  ASSERT_EQ(r.status, 0) << r.err;
  r = run_mlfe("--threads 2 build " + in + " --labels -o " + scratch() + "/hier2.mlfeh --quiet");
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_EQ(slurp(h), slurp(scratch() + "/hier2.mlfeh"));
  // Refined only where labels meet: far fewer leaves than the 6 Kuhn tetrahedra per voxel.
  r = run_mlfe("info " + h + " --json");
  ASSERT_EQ(r.status, 0) << r.err;
  const json hi = json::parse(r.out);
  EXPECT_LT(hi["leaves"].get<std::size_t>(), 6u * 27 * 27 * 27 / 2);
  r = run_mlfe("info " + in + " --labels --json");
  ASSERT_EQ(r.status, 0) << r.err;
  const json vi = json::parse(r.out);
  EXPECT_EQ(hi["labels"], vi["labels"]);  // values, names (the stored table), voxels, mm3
  // convert --labels --hierarchy writes the same label map beside the surfaces.
  r = run_mlfe("convert " + in + " --labels --hierarchy " + scratch() + "/conv.mlfeh -o " + scratch() +
               "/conv.glb --quiet");
  ASSERT_EQ(r.status, 0) << r.err;
  r = run_mlfe("info " + scratch() + "/conv.mlfeh --json");
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_EQ(json::parse(r.out)["labels"], vi["labels"]);
  // The same surfaces from the file as from the volume.
  ASSERT_EQ(run_mlfe("convert " + h + " --labels -o " + scratch() + "/from_h.glb --quiet").status, 0);
  ASSERT_EQ(run_mlfe("convert " + in + " --labels -o " + scratch() + "/from_v.glb --quiet").status, 0);
  const GltfAsset a = read_gltf(scratch() + "/from_h.glb"), b = read_gltf(scratch() + "/from_v.glb");
  ASSERT_EQ(a.primitives.size(), b.primitives.size());
  for (std::size_t p = 0; p < a.primitives.size(); ++p) {
    EXPECT_EQ(a.primitives[p].mesh_data.positions, b.primitives[p].mesh_data.positions);
    EXPECT_EQ(a.primitives[p].mesh_data.triangles, b.primitives[p].mesh_data.triangles);
    EXPECT_EQ(a.structure["nodes"][a.primitives[p].node]["name"],
              b.structure["nodes"][b.primitives[p].node]["name"]);
  }
  // Regions: named groups; volumes near the voxel volumes; all of them fill the data box.
  r = run_mlfe("export " + h + " -o " + scratch() + "/hier.msh");
  ASSERT_EQ(r.status, 0) << r.err;
  const auto regions = msh_region_volumes(scratch() + "/hier.msh");
  double total = 0;
  for (const auto& [name, v] : regions) total += v.first;
  EXPECT_NEAR(total, 27 * 0.8 * 27 * 0.8 * 27 * 1.0, 1e-6);
  const double voxel = 0.8 * 0.8 * 1.0;
  for (const auto& row : vi["labels"]) {
    const std::string name = row["name"];
    const double expected = row["voxels"].get<double>() * voxel;
    // The island is thinner than a cell; the background's voxels at the box's faces are cut by
    // it (the total above accounts for the box).
    if (row["voxels"].get<int>() < 100 || row["label"].get<int>() == 0) continue;
    ASSERT_TRUE(regions.count(name)) << name;
    EXPECT_NEAR(regions.at(name).first / expected, 1.0, 0.1) << name;
  }
  r = run_mlfe("export " + h + " -o " + scratch() + "/hier.vtu");
  ASSERT_EQ(r.status, 0) << r.err;
  const std::string vtu = slurp(scratch() + "/hier.vtu");
  EXPECT_NE(vtu.find(R"(Name="label")"), std::string::npos);
  // Bad input: values that are not labels; a hierarchy without labels.
  const std::string bad = write_phantom("hier_bad", 2.5f);
  r = run_mlfe("build " + bad + " --labels -o " + scratch() + "/bad.mlfeh");
  EXPECT_EQ(r.status, 2);
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  EXPECT_FALSE(fs::exists(scratch() + "/bad.mlfeh"));
  ASSERT_EQ(run_mlfe("build " + in + " --max-error 0.5 -o " + scratch() + "/plain.mlfeh --quiet").status, 0);
  r = run_mlfe("convert " + scratch() + "/plain.mlfeh --labels -o " + scratch() + "/plain.glb");
  EXPECT_EQ(r.status, 2);
  EXPECT_NE(r.err.find("not a label map"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(scratch() + "/plain.glb"));
}

TEST(LabelsCommand, JhuAtlasConvertsWithItsNamesAndColours) {
  const std::string in = test::test_data_path("labels/atlas_jhu_wm_labels_1mm.nii.gz");
  const std::string glb = scratch() + "/jhu.glb", report = scratch() + "/jhu.report.json";
  const auto r = run_mlfe("convert " + in + " --labels -o " + glb + " --report " + report);
  ASSERT_EQ(r.status, 0) << r.err;
  std::string v;
  EXPECT_TRUE(validator_accepts(glb, &v)) << v;
  const GltfAsset a = read_gltf(glb);
  ASSERT_EQ(a.primitives.size(), 48u);
  EXPECT_EQ(a.structure["nodes"][a.primitives[2].node]["name"], "Genu_of_corpus_callosum");
  EXPECT_EQ(a.structure["nodes"][a.primitives[2].node]["extras"]["label"], 3);
  const json rep = json::parse(slurp(report));
  EXPECT_EQ(rep["asset"]["structure_count"], 48);
  for (const auto& s : rep["asset"]["structures"]) EXPECT_TRUE(s["closed"].get<bool>()) << s.dump();
  // The colour of label 3 is the .lut's.
  const std::string lut = slurp(test::test_data_path("labels/atlas_jhu_wm_labels_1mm.lut"));
  EXPECT_EQ(rep["asset"]["structures"][2]["color"],
            json({std::uint8_t(lut[3]), std::uint8_t(lut[256 + 3]), std::uint8_t(lut[512 + 3])}));
}

}  // namespace
}  // namespace mlfe
