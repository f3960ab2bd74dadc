// Semantic comparison of two outputs (issue #17): the library behind `mlfe compare`, for golden
// tests in C++ suites. Decodes both files and compares what they mean, not their bytes:
//
//   meshes      .glb/.gltf (with or without Draco), .drc, .ply/.obj/.stl/.off: per primitive
//               (glTF, matched by node name or in node order) or per file — vertex and
//               triangle counts, bounding box, symmetric Hausdorff and mean distance by
//               fixed-seed sampling, angle between
//               the normals at matched points, handedness (signed volume), scale (units);
//               glTF also the structure: scene graph, names, materials, extensions, extras.
//   images      .exr, .png: size, channel names and types, header attributes, per channel max
//               and RMS difference and PSNR.
//   volumes     everything formats/volume_reader.h reads (.vdb, .nii[.gz], .nrrd, .mha, raw):
//               dims, transform, space, per-voxel max and RMS difference.
//   hierarchies .mlfeh: dim, counts per level, transform, value range, metadata (error
//               figures), the values of the vertices of each level.
//
// Example (GoogleTest):
//   mlfe::CompareOptions opt;
//   opt.tolerance = 1e-5;  // metres in a .glb
//   const mlfe::CompareResult r = mlfe::compare_files("golden/skull.glb", "out/skull.glb", opt);
//   EXPECT_TRUE(r.equal()) << r.summary();
//
// By default the comparison judges content, not provenance: the input's name, the generator and
// tool, timings and the encoding (Draco or not, quantization, the tolerance written) are not
// compared; CompareOptions::strict compares them too. A Draco-compressed side widens the
// distance tolerances by its quantization step, read from the file, and says so in `notes`.
//
// Results depend only on the files and the options (never on the thread count).
#pragma once
#include <mlfe/core/surface/triangle_mesh.h>
#include <mlfe/formats/asset_reader.h>

#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

namespace mlfe {

struct CompareOptions {
  // ---- meshes ----
  /// Largest allowed symmetric Hausdorff distance (and bounding-box corner difference per
  /// coordinate) in the files' units (glTF: metres). Unset: 1e-4 of the expected mesh's
  /// bounding-box diagonal.
  std::optional<double> tolerance;
  /// Largest allowed mean distance; unset: the Hausdorff tolerance.
  std::optional<double> mean_tolerance;
  /// Allowed difference of vertex and triangle counts in percent of the expected count
  /// (0: exact). Draco may split non-manifold vertices, so Draco copies may need a little.
  double count_tolerance_percent = 0.0;
  /// Largest allowed mean angle between the normals at matched points, degrees.
  double normal_angle_deg = 2.0;
  /// Area samples per mesh on top of every vertex (see core/surface/mesh_distance.h).
  std::size_t samples = 100000;
  // ---- images (values of PNG channels are scaled to [0, 1]) ----
  /// Largest allowed absolute difference of one channel value. Unset (and min_psnr unset): 0.
  std::optional<double> image_max;
  /// Smallest allowed PSNR in dB per channel (peak: the expected channel's max |value|, 1 for PNG).
  std::optional<double> min_psnr;
  // ---- volumes and hierarchy values ----
  /// Largest allowed absolute per-voxel (per-vertex for hierarchies) difference. Unset
  /// (and value_rms unset): 0.
  std::optional<double> value_max;
  /// Largest allowed RMS difference over all voxels (vertices).
  std::optional<double> value_rms;
  // ---- everything ----
  /// Relative tolerance for numbers in headers, transforms, materials and extras.
  double number_tolerance = 1e-6;
  /// JSON pointers (glTF structure, hierarchy metadata; e.g. "/asset/generator",
  /// "/asset/extras/mlfe/version") whose subtrees are not compared.
  std::vector<std::string> ignore;
  /// Compare provenance too (see is_provenance) and the glTF encoding (compression extensions,
  /// asset.extras.mlfe's encoding and tolerance_mm) and, for other meshes, the file format.
  bool strict = false;
};

/// Whether the JSON pointer names provenance, which only strict comparisons compare: the glTF
/// generator and tool (/asset/generator, /asset/extras/tool), the input (/asset/extras/input;
/// /input and /tool of hierarchy metadata), the tolerance write_asset records
/// (/asset/extras/tolerance_mm) and timings anywhere (a key "seconds", "timings" or ending in
/// "_seconds").
bool is_provenance(const std::string& pointer);

struct Difference {
  std::string item;    ///< what differs: "triangle count", "node 0 'iso 80' ... : Hausdorff", ...
  std::string reason;  ///< one line for people: values, tolerance, a likely cause when known
};

struct CompareResult {
  std::string kind;                     ///< "mesh", "gltf", "image", "volume", "hierarchy" or "mismatch"
  std::vector<Difference> differences;  ///< empty when equal within the tolerances
  nlohmann::json report;                ///< every measured figure, also for equal files
  /// How the comparison was adjusted, one line each for people (a tolerance widened by Draco's
  /// quantization, provenance differences not compared); empty when nothing was.
  std::vector<std::string> notes;

  bool equal() const { return differences.empty(); }
  /// "equal" or one line per difference, "item: reason".
  std::string summary() const;
};

/// Compares EXPECTED with ACTUAL by content, as described above; the kind comes from the
/// files' magic bytes and extensions. Two files of different kinds give one difference; two
/// meshes of which not both are glTF are compared by compare_assets. Mesh tolerances
/// (Hausdorff, bounding box and mean) widen to at least the sum of the two sides' Draco
/// quantization steps (a decoded coordinate lies within half a step of the encoder's input,
/// a point within sqrt(3)/2 steps), per glTF primitive or file, and the notes say so.
/// Throws mlfe::Error ("<path>: <problem>") when a file cannot be read or decoded, and
/// pipeline::OptionError (a usage error, <mlfe/pipeline.h>) for a negative or non-finite
/// tolerance, angle or figure, before reading.
CompareResult compare_files(const std::string& expected, const std::string& actual,
                            const CompareOptions& options = {});

/// The mesh comparison of compare_files for meshes already in memory; `label` prefixes the
/// difference items ("" for none). Meshes without triangles are compared by counts only.
/// Normals: the meshes' own when both have one per vertex, else area-weighted ones for both.
/// Triangle indices must be in range (CHECK: the readers guarantee it for files). Options are
/// checked as compare_files checks them.
CompareResult compare_meshes(const TriangleMesh& expected, const TriangleMesh& actual,
                             const CompareOptions& options = {}, const std::string& label = "");

/// The mesh comparison of two assets, files read with read_asset or meshes made in memory (the
/// Python module's Mesh): surface by surface when both hold several, with distinct names, and
/// the same names (label maps: names on either side), else all surfaces merged. Both in glTF's
/// frame when both are, else both in the scan's millimetres (to_scan_frame), so a .glb and a
/// .ply of one conversion compare equal. Each side's Draco quantization step widens the
/// tolerances (see compare_files). In strict mode, a different `format` is a difference. Checks
/// the options as compare_files does.
CompareResult compare_assets(AssetFile expected, AssetFile actual, const CompareOptions& options = {});

/// Writes result.report plus the differences as JSON (atomically). Throws mlfe::Error on I/O
/// failure.
void write_compare_report(const std::string& path, const std::string& expected, const std::string& actual,
                          const CompareResult& result);

}  // namespace mlfe
