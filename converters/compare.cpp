#include <fmt/format.h>
#include <fmt/ranges.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/surface/mesh_distance.h>
#include <mlfe/core/surface/triangle_mesh.h>
#include <mlfe/formats/asset_reader.h>
#include <mlfe/formats/asset_writer.h>
#include <mlfe/formats/atomic_file.h>
#include <mlfe/formats/gltf_reader.h>
#include <mlfe/formats/hierarchy_io.h>
#include <mlfe/formats/image_reader.h>
#include <mlfe/formats/safe_read.h>
#include <mlfe/formats/volume_reader.h>
#include <mlfe/pipeline.h>
#include <mlfe/pipeline/compare.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstring>
#include <map>

namespace mlfe {
namespace {

using Box = std::array<std::array<double, 3>, 2>;

constexpr std::size_t kMaxStructureDifferences = 20;

std::string lower_extension(const std::string& path) {
  const auto slash = path.find_last_of('/');
  const std::string name = slash == std::string::npos ? path : path.substr(slash + 1);
  std::string lower = name;
  std::transform(lower.begin(), lower.end(), lower.begin(),
                 [](unsigned char c) { return char(std::tolower(c)); });
  if (lower.size() > 7 && lower.compare(lower.size() - 7, 7, ".nii.gz") == 0) return ".nii.gz";
  const auto dot = lower.find_last_of('.');
  return dot == std::string::npos ? "" : lower.substr(dot);
}

enum class Kind { kGltf, kMesh, kImage, kVolume, kHierarchy };

const char* kind_name(Kind k) {
  switch (k) {
    case Kind::kGltf:
      return "gltf";
    case Kind::kMesh:
      return "mesh";
    case Kind::kImage:
      return "image";
    case Kind::kVolume:
      return "volume";
    case Kind::kHierarchy:
      return "hierarchy";
  }
  return "?";
}

/// Magic bytes first (they cannot lie), extension second, volume as the fallback because
/// read_volume has its own detection (and its own error for what it does not know).
Kind detect_kind(const std::string& path) {
  const std::string head = read_file_prefix(path, 8);
  if (head.size() >= 4 && std::memcmp(head.data(), "glTF", 4) == 0) return Kind::kGltf;
  if (head.size() >= 5 && std::memcmp(head.data(), "DRACO", 5) == 0) return Kind::kMesh;
  if (is_hierarchy_file(path)) return Kind::kHierarchy;
  if (is_image_file(path)) return Kind::kImage;
  const std::string ext = lower_extension(path);
  if (ext == ".gltf") return Kind::kGltf;
  if (ext == ".drc" || ext == ".ply" || ext == ".obj" || ext == ".stl" || ext == ".off") return Kind::kMesh;
  return Kind::kVolume;
}

/// Reads `path` as a file of kind `k`, for the reader's error on what is not one.
void read_as(const std::string& path, Kind k) {
  switch (k) {
    case Kind::kGltf:
      read_gltf(path);
      return;
    case Kind::kMesh:
      read_asset(path);
      return;
    case Kind::kImage:
      read_image(path);
      return;
    case Kind::kVolume:
      read_volume(path);
      return;
    case Kind::kHierarchy:
      read_hierarchy(path);
      return;
  }
}

bool close(double a, double b, double rel) {
  return std::abs(a - b) <= rel * std::max({1.0, std::abs(a), std::abs(b)});
}

std::string fmt_g(double v) { return fmt::format("{:.6g}", v); }

std::string item(const std::string& label, const std::string& what) {
  return label.empty() ? what : label + ": " + what;
}

/// "ACTUAL is N times the size of EXPECTED" with the unit mix-up it most likely is.
std::string scale_cause(double ratio) {
  struct Known {
    double factor;
    const char* text;
  };
  static const Known known[] = {
      {1000.0, "millimetres instead of metres?"},    {0.001, "metres instead of millimetres?"},
      {100.0, "centimetres instead of metres?"},     {0.01, "metres instead of centimetres?"},
      {10.0, "millimetres instead of centimetres?"}, {0.1, "centimetres instead of millimetres?"},
      {25.4, "millimetres instead of inches?"},      {1.0 / 25.4, "inches instead of millimetres?"}};
  for (const Known& k : known)
    if (std::abs(ratio / k.factor - 1.0) < 0.02)
      return fmt::format("ACTUAL is {} times the size of EXPECTED: {}", fmt_g(ratio), k.text);
  return fmt::format("ACTUAL is {} times the size of EXPECTED", fmt_g(ratio));
}

double diagonal(const Box& b) {
  return std::sqrt(std::pow(b[1][0] - b[0][0], 2) + std::pow(b[1][1] - b[0][1], 2) +
                   std::pow(b[1][2] - b[0][2], 2));
}

bool count_differs(std::size_t expected, std::size_t actual, double percent) {
  const double allowed = double(expected) * percent / 100.0;
  return std::abs(double(actual) - double(expected)) > allowed;
}

/// The axis (0..2) along which `actual` mirrored about its box centre and moved onto the
/// expected box centre lies within `tolerance` of `expected`, or -1.
int mirrored_axis(const TriangleMesh& expected, const TriangleMesh& actual, double tolerance) {
  const Box be = bounding_box(expected), ba = bounding_box(actual);
  SurfaceSamplingOptions vertices_only;
  vertices_only.area_samples = 0;
  for (int axis = 0; axis < 3; ++axis) {
    TriangleMesh m = actual;
    for (auto& p : m.positions)
      for (int k = 0; k < 3; ++k) {
        const double ce = 0.5 * (be[0][k] + be[1][k]), ca = 0.5 * (ba[0][k] + ba[1][k]);
        p[k] = float(k == axis ? ce - (p[k] - ca) : p[k] - ca + ce);
      }
    m.normals.clear();
    for (auto& t : m.triangles) std::swap(t[1], t[2]);
    if (mesh_distance(expected, m, vertices_only).hausdorff() <= tolerance) return axis;
  }
  return -1;
}

// ---------------------------------------------------------------- JSON structure

bool ignored(const std::string& pointer, const CompareOptions& options) {
  for (const std::string& p : options.ignore)
    if (pointer == p ||
        (pointer.size() > p.size() && pointer.compare(0, p.size(), p) == 0 && pointer[p.size()] == '/'))
      return true;
  return false;
}

std::string short_json(const nlohmann::json& j) {
  std::string s = j.dump();
  return s.size() > 80 ? s.substr(0, 77) + "..." : s;
}

std::string escape_pointer(const std::string& key) {
  std::string out;
  for (char c : key) out += c == '~' ? std::string("~0") : c == '/' ? std::string("~1") : std::string(1, c);
  return out;
}

void diff_json(const nlohmann::json& e, const nlohmann::json& a, const std::string& pointer,
               const CompareOptions& options, std::vector<std::pair<std::string, std::string>>& out) {
  if (ignored(pointer, options)) return;
  if (e.is_number() && a.is_number()) {
    if (!close(e.get<double>(), a.get<double>(), options.number_tolerance))
      out.push_back({pointer, fmt::format("{} in EXPECTED, {} in ACTUAL", short_json(e), short_json(a))});
    return;
  }
  if (e.type() != a.type()) {
    out.push_back({pointer, fmt::format("{} in EXPECTED, {} in ACTUAL", short_json(e), short_json(a))});
    return;
  }
  if (e.is_object()) {
    for (auto it = e.begin(); it != e.end(); ++it) {
      const std::string p = pointer + "/" + escape_pointer(it.key());
      if (!a.contains(it.key())) {
        if (!ignored(p, options))
          out.push_back({p, "missing in ACTUAL (EXPECTED: " + short_json(it.value()) + ")"});
      } else {
        diff_json(it.value(), a[it.key()], p, options, out);
      }
    }
    for (auto it = a.begin(); it != a.end(); ++it) {
      const std::string p = pointer + "/" + escape_pointer(it.key());
      if (!e.contains(it.key()) && !ignored(p, options))
        out.push_back({p, "only in ACTUAL: " + short_json(it.value())});
    }
    return;
  }
  if (e.is_array()) {
    if (e.size() != a.size()) {
      out.push_back({pointer, fmt::format("{} entries in EXPECTED, {} in ACTUAL", e.size(), a.size())});
      return;
    }
    for (std::size_t i = 0; i < e.size(); ++i)
      diff_json(e[i], a[i], pointer + "/" + std::to_string(i), options, out);
    return;
  }
  if (e != a)
    out.push_back({pointer, fmt::format("{} in EXPECTED, {} in ACTUAL", short_json(e), short_json(a))});
}

void add_json_differences(const nlohmann::json& e, const nlohmann::json& a, const std::string& what,
                          const CompareOptions& options, CompareResult& r) {
  std::vector<std::pair<std::string, std::string>> all, diffs;
  diff_json(e, a, "", options, all);
  std::vector<std::string> provenance;
  for (auto& d : all) {
    if (!options.strict && is_provenance(d.first))
      provenance.push_back(d.first);
    else
      diffs.push_back(std::move(d));
  }
  for (std::size_t i = 0; i < diffs.size() && i < kMaxStructureDifferences; ++i)
    r.differences.push_back({what + " " + (diffs[i].first.empty() ? "/" : diffs[i].first), diffs[i].second});
  if (diffs.size() > kMaxStructureDifferences)
    r.differences.push_back(
        {what, fmt::format("{} more differences not listed", diffs.size() - kMaxStructureDifferences)});
  r.report[what + "_differences"] = diffs.size();
  if (!provenance.empty()) {
    r.report[what + "_provenance_not_compared"] = provenance;
    r.notes.push_back(fmt::format("{}: provenance not compared ({}; --strict compares it)", what,
                                  fmt::join(provenance, ", ")));
  }
}

/// Index pairs (expected, actual) matched by key when every key is non-empty and distinct on
/// both sides and both hold the same keys, or `by_name_anyway` (the structures of label maps may
/// come in another order or be missing on one side; unmatched keys are differences). Returns
/// false, with no pairs, when the keys cannot match that way.
bool pair_by_name(const std::vector<std::string>& ek, const std::vector<std::string>& ak, bool by_name_anyway,
                  const std::string& what, std::vector<std::pair<std::size_t, std::size_t>>& pairs,
                  CompareResult& r) {
  auto sorted = [](std::vector<std::string> k) {
    std::sort(k.begin(), k.end());
    return k;
  };
  auto distinct = [&](const std::vector<std::string>& k) {
    const std::vector<std::string> s = sorted(k);
    return std::adjacent_find(s.begin(), s.end()) == s.end() && (s.empty() || !s.front().empty());
  };
  if (!distinct(ek) || !distinct(ak) || !(sorted(ek) == sorted(ak) || by_name_anyway)) return false;
  std::map<std::string, std::size_t> in_actual;
  for (std::size_t i = 0; i < ak.size(); ++i) in_actual[ak[i]] = i;
  for (std::size_t i = 0; i < ek.size(); ++i) {
    const auto it = in_actual.find(ek[i]);
    if (it == in_actual.end()) {
      r.differences.push_back({what, "node " + ek[i] + " of EXPECTED is not in ACTUAL"});
      continue;
    }
    pairs.emplace_back(i, it->second);
    in_actual.erase(it);
  }
  for (const auto& [k, i] : in_actual)
    r.differences.push_back({what, "node " + k + " of ACTUAL is not in EXPECTED"});
  return true;
}

/// compare_meshes with each side's Draco quantization step (0: none), which widens the
/// distance tolerances (see compare_files).
CompareResult compare_quantized_meshes(const TriangleMesh& expected, const TriangleMesh& actual,
                                       const CompareOptions& options, const std::string& label, double step_e,
                                       double step_a);

// ---------------------------------------------------------------- kinds

CompareResult compare_gltf(const std::string& expected, const std::string& actual,
                           const CompareOptions& options) {
  const GltfAsset e = read_gltf(expected), a = read_gltf(actual);
  CompareResult r;
  r.kind = "gltf";
  // Step 1: the scene graph, names, materials, extensions and extras; strict: the encoding.
  add_json_differences(e.structure, a.structure, "structure", options, r);
  if (options.strict) add_json_differences(e.encoding, a.encoding, "encoding", options, r);
  // Step 2: the geometry of each primitive, matched by node name (and primitive index) when
  // every node with a mesh has a distinct name in both files (structures of a label map may
  // come in another order or be missing), else in node order.
  if (e.primitives.size() != a.primitives.size())
    r.differences.push_back({"primitives", fmt::format("{} triangle primitives in EXPECTED, {} in ACTUAL",
                                                       e.primitives.size(), a.primitives.size())});
  auto keys = [](const GltfAsset& g) {
    std::vector<std::string> k;
    for (const auto& p : g.primitives) {
      const auto& node = g.structure["nodes"][p.node];
      const std::string name =
          node.contains("name") && node["name"].is_string() ? node["name"].get<std::string>() : "";
      k.push_back(name.empty() ? std::string() : fmt::format("'{}' primitive {}", name, p.primitive));
    }
    return k;
  };
  const std::vector<std::string> ek = keys(e), ak = keys(a);
  // Label maps (nodes with a "label" extra) are matched by name even when a structure is
  // missing on one side; other assets only when both hold the same names.
  auto label_map = [](const GltfAsset& g) {
    for (const auto& p : g.primitives) {
      const auto& node = g.structure["nodes"][p.node];
      if (!node.contains("extras") || !node["extras"].contains("label")) return false;
    }
    return !g.primitives.empty();
  };
  std::vector<std::pair<std::size_t, std::size_t>> pairs;
  const bool by_name = pair_by_name(ek, ak, label_map(e) && label_map(a), "primitives", pairs, r);
  if (!by_name)
    for (std::size_t i = 0; i < std::min(e.primitives.size(), a.primitives.size()); ++i)
      pairs.emplace_back(i, i);
  r.report["primitives_matched_by"] = by_name ? "node name" : "node order";
  nlohmann::json prims = nlohmann::json::array();
  for (const auto& [i, j] : pairs) {
    const GltfPrimitive &pe = e.primitives[i], &pa = a.primitives[j];
    CompareResult m = compare_quantized_meshes(pe.mesh_data, pa.mesh_data, options, pe.label,
                                               pe.quantization_step, pa.quantization_step);
    m.report["label"] = pe.label;
    prims.push_back(m.report);
    for (auto& d : m.differences) r.differences.push_back(std::move(d));
    for (auto& n : m.notes) r.notes.push_back(std::move(n));
  }
  r.report["primitives"] = prims;
  return r;
}

CompareResult compare_images(const std::string& expected, const std::string& actual,
                             const CompareOptions& options) {
  const Image e = read_image(expected), a = read_image(actual);
  CompareResult r;
  r.kind = "image";
  r.report["format"] = {e.format, a.format};
  if (e.width != a.width || e.height != a.height) {
    r.differences.push_back(
        {"size", fmt::format("{}x{} in EXPECTED, {}x{} in ACTUAL", e.width, e.height, a.width, a.height)});
    return r;
  }
  r.report["size"] = {e.width, e.height};
  // Header attributes, then channels by name.
  for (const auto& [name, value] : e.attributes) {
    const auto it = a.attributes.find(name);
    if (it == a.attributes.end())
      r.differences.push_back({"attribute " + name, "missing in ACTUAL (EXPECTED: " + value + ")"});
    else if (it->second != value)
      r.differences.push_back(
          {"attribute " + name, "'" + value + "' in EXPECTED, '" + it->second + "' in ACTUAL"});
  }
  for (const auto& [name, value] : a.attributes)
    if (!e.attributes.count(name)) r.differences.push_back({"attribute " + name, "only in ACTUAL: " + value});
  const bool exact = !options.image_max && !options.min_psnr;
  const double max_allowed = options.image_max.value_or(0.0);
  nlohmann::json channels = nlohmann::json::object();
  for (const ImageChannel& ec : e.channels) {
    const auto ac = std::find_if(a.channels.begin(), a.channels.end(),
                                 [&](const ImageChannel& c) { return c.name == ec.name; });
    if (ac == a.channels.end()) {
      r.differences.push_back({"channel " + ec.name, "missing in ACTUAL"});
      continue;
    }
    if (ac->type != ec.type)
      r.differences.push_back(
          {"channel " + ec.name, "type " + ec.type + " in EXPECTED, " + ac->type + " in ACTUAL"});
    double max = 0, sum2 = 0, peak = 0;
    std::size_t nan_mismatch = 0;
    for (std::size_t i = 0; i < ec.values.size(); ++i) {
      const double x = ec.values[i], y = ac->values[i];
      if (std::isnan(x) || std::isnan(y)) {
        nan_mismatch += std::isnan(x) != std::isnan(y);
        continue;
      }
      if (std::isinf(x) || std::isinf(y)) {
        nan_mismatch += x != y;
        continue;
      }
      const double d = std::abs(x - y);
      max = std::max(max, d);
      sum2 += d * d;
      peak = std::max(peak, std::abs(x));
    }
    if (e.format == "png") peak = 1.0;
    const double rms = ec.values.empty() ? 0.0 : std::sqrt(sum2 / double(ec.values.size()));
    const double psnr = rms > 0 && peak > 0 ? 20.0 * std::log10(peak / rms) : INFINITY;
    channels[ec.name] = {{"max", max},
                         {"rms", rms},
                         {"psnr_db", std::isinf(psnr) ? nlohmann::json("inf") : nlohmann::json(psnr)}};
    if (nan_mismatch > 0)
      r.differences.push_back(
          {"channel " + ec.name, fmt::format("{} pixels are NaN/Inf in one file only", nan_mismatch)});
    if ((exact || options.image_max) && max > max_allowed)
      r.differences.push_back(
          {"channel " + ec.name, fmt::format("max difference {} > {} (RMS {}, PSNR {} dB)", fmt_g(max),
                                             fmt_g(max_allowed), fmt_g(rms), fmt_g(psnr))});
    if (options.min_psnr && psnr < *options.min_psnr)
      r.differences.push_back(
          {"channel " + ec.name, fmt::format("PSNR {} dB < {} dB (max difference {}, RMS {})", fmt_g(psnr),
                                             fmt_g(*options.min_psnr), fmt_g(max), fmt_g(rms))});
  }
  for (const ImageChannel& ac : a.channels)
    if (std::none_of(e.channels.begin(), e.channels.end(),
                     [&](const ImageChannel& c) { return c.name == ac.name; }))
      r.differences.push_back({"channel " + ac.name, "only in ACTUAL"});
  r.report["channels"] = channels;
  return r;
}

void compare_transforms(const GridTransform& e, const GridTransform& a, double rel, CompareResult& r) {
  auto check = [&](const char* name, const double* x, const double* y, int n) {
    for (int i = 0; i < n; ++i)
      if (!close(x[i], y[i], rel)) {
        std::string ex, ac;
        for (int k = 0; k < n; ++k) {
          ex += (k ? " " : "") + fmt_g(x[k]);
          ac += (k ? " " : "") + fmt_g(y[k]);
        }
        r.differences.push_back(
            {std::string("transform ") + name, "(" + ex + ") in EXPECTED, (" + ac + ") in ACTUAL"});
        return;
      }
  };
  check("spacing", e.spacing.data(), a.spacing.data(), 3);
  check("origin", e.origin.data(), a.origin.data(), 3);
  check("direction", e.direction.data(), a.direction.data(), 9);
}

/// Max and RMS of the differences, reduced in index order.
template <class T>
void compare_values(const std::string& what, const T* e, const T* a, std::size_t n,
                    const CompareOptions& options, CompareResult& r, nlohmann::json& report) {
  double max = 0, sum2 = 0;
  std::size_t at = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const double d = std::abs(double(e[i]) - double(a[i]));
    if (d > max) {
      max = d;
      at = i;
    }
    sum2 += d * d;
  }
  const double rms = n ? std::sqrt(sum2 / double(n)) : 0.0;
  report = {{"max", max}, {"rms", rms}, {"max_at", at}};
  const bool exact = !options.value_max && !options.value_rms;
  if ((exact || options.value_max) && max > options.value_max.value_or(0.0))
    r.differences.push_back({what, fmt::format("max difference {} > {} (at index {}; RMS {})", fmt_g(max),
                                               fmt_g(options.value_max.value_or(0.0)), at, fmt_g(rms))});
  if (options.value_rms && rms > *options.value_rms)
    r.differences.push_back({what, fmt::format("RMS difference {} > {} (max {})", fmt_g(rms),
                                               fmt_g(*options.value_rms), fmt_g(max))});
}

CompareResult compare_volumes(const std::string& expected, const std::string& actual,
                              const CompareOptions& options) {
  const ScalarGrid e = read_volume(expected), a = read_volume(actual);
  CompareResult r;
  r.kind = "volume";
  r.report["dims"] = {e.dims, a.dims};
  if (e.dims != a.dims) {
    r.differences.push_back(
        {"dims", fmt::format("{} x {} x {} in EXPECTED, {} x {} x {} in ACTUAL", e.dims[0], e.dims[1],
                             e.dims[2], a.dims[0], a.dims[1], a.dims[2])});
    return r;
  }
  compare_transforms(e.transform, a.transform, options.number_tolerance, r);
  if (e.space != a.space)
    r.differences.push_back({"space", "'" + e.space + "' in EXPECTED, '" + a.space + "' in ACTUAL"});
  nlohmann::json values;
  compare_values("voxels", e.values.data(), a.values.data(), e.values.size(), options, r, values);
  r.report["voxels"] = values;
  return r;
}

template <int D>
std::vector<std::size_t> histogram(const std::vector<std::uint8_t>& levels) {
  std::vector<std::size_t> h;
  for (std::uint8_t l : levels) {
    if (l >= h.size()) h.resize(l + 1u, 0);
    ++h[l];
  }
  return h;
}

template <int D>
void compare_hierarchy_arrays(const HierarchyFile& ef, const HierarchyFile& af, const CompareOptions& options,
                              CompareResult& r) {
  const auto& e = std::get<Hierarchy<D>>(ef.hierarchy);
  const auto& a = std::get<Hierarchy<D>>(af.hierarchy);
  const auto ev = histogram<D>(e.vertex_level_array()), av = histogram<D>(a.vertex_level_array());
  const auto ee = histogram<D>(e.level_array()), ae = histogram<D>(a.level_array());
  r.report["vertices_per_level"] = {ev, av};
  r.report["elements_per_level"] = {ee, ae};
  if (ev.size() != av.size() || ee.size() != ae.size())
    r.differences.push_back(
        {"levels", fmt::format("{} levels in EXPECTED, {} in ACTUAL", ee.size(), ae.size())});
  for (std::size_t k = 0; k < std::min(ee.size(), ae.size()); ++k)
    if (ee[k] != ae[k] || (k < ev.size() && k < av.size() && ev[k] != av[k]))
      r.differences.push_back(
          {fmt::format("level {}", k),
           fmt::format("{} elements / {} new vertices in EXPECTED, {} / {} in ACTUAL", ee[k],
                       k < ev.size() ? ev[k] : 0, ae[k], k < av.size() ? av[k] : 0)});
  if (e.vertex_count() != a.vertex_count() || e.element_count() != a.element_count()) {
    r.differences.push_back(
        {"counts", fmt::format("{} vertices, {} elements in EXPECTED; {}, {} in ACTUAL", e.vertex_count(),
                               e.element_count(), a.vertex_count(), a.element_count())});
    return;
  }
  // Same counts: positions and cells must match one to one (the hierarchy's order is canonical).
  double point_max = 0;
  for (std::size_t v = 0; v < e.vertex_count(); ++v)
    for (int k = 0; k < D; ++k)
      point_max = std::max(point_max, std::abs(e.points()[v][k] - a.points()[v][k]));
  r.report["point_max_difference"] = point_max;
  const double point_tol = options.tolerance.value_or(0.0);
  if (point_max > point_tol)
    r.differences.push_back(
        {"vertex positions", fmt::format("max difference {} > {}", fmt_g(point_max), fmt_g(point_tol))});
  if (e.cells() != a.cells()) r.differences.push_back({"elements", "the element vertex lists differ"});
  if (ef.values.size() != af.values.size()) {
    r.differences.push_back(
        {"values", fmt::format("{} values in EXPECTED, {} in ACTUAL", ef.values.size(), af.values.size())});
    return;
  }
  // Values level by level: the vertices introduced at level k carry the hierarchical detail of
  // that level, so a difference there says which refinement step changed.
  nlohmann::json per_level = nlohmann::json::array();
  for (std::size_t k = 0; k < ev.size(); ++k) {
    std::vector<double> x, y;
    for (std::size_t v = 0; v < ef.values.size(); ++v)
      if (e.vertex_level_array()[v] == k) {
        x.push_back(ef.values[v]);
        y.push_back(af.values[v]);
      }
    nlohmann::json figures;
    compare_values(fmt::format("values at level {}", k), x.data(), y.data(), x.size(), options, r, figures);
    per_level.push_back(figures);
  }
  r.report["values_per_level"] = per_level;
}

CompareResult compare_hierarchies(const std::string& expected, const std::string& actual,
                                  const CompareOptions& options) {
  const HierarchyFile e = read_hierarchy(expected), a = read_hierarchy(actual);
  CompareResult r;
  r.kind = "hierarchy";
  if (e.dim != a.dim) {
    r.differences.push_back({"dim", fmt::format("{}D in EXPECTED, {}D in ACTUAL", e.dim, a.dim)});
    return r;
  }
  compare_transforms(e.transform, a.transform, options.number_tolerance, r);
  if (e.space != a.space)
    r.differences.push_back({"space", "'" + e.space + "' in EXPECTED, '" + a.space + "' in ACTUAL"});
  if (!close(e.value_min, a.value_min, options.number_tolerance) ||
      !close(e.value_max, a.value_max, options.number_tolerance))
    r.differences.push_back(
        {"value range", fmt::format("{} .. {} in EXPECTED, {} .. {} in ACTUAL", fmt_g(e.value_min),
                                    fmt_g(e.value_max), fmt_g(a.value_min), fmt_g(a.value_max))});
  // Where the data lies in T0 (v3): a different lattice is a different grid.
  const auto lattice_text = [](const HierarchyFile& f) {
    return f.on_lattice ? fmt::format("lattice level {}, data {}x{}x{}", f.lattice_level, f.data_dims[0],
                                      f.data_dims[1], f.data_dims[2])
                        : std::string("no lattice");
  };
  r.report["lattice"] = {lattice_text(e), lattice_text(a)};
  if (lattice_text(e) != lattice_text(a))
    r.differences.push_back({"lattice", lattice_text(e) + " in EXPECTED, " + lattice_text(a) + " in ACTUAL"});
  const auto bound_text = [](const HierarchyFile& f) {
    return std::isnan(f.sample_error_bound) ? std::string("none") : fmt_g(f.sample_error_bound);
  };
  r.report["sample_error_bound"] = {bound_text(e), bound_text(a)};
  if (bound_text(e) != bound_text(a))
    r.differences.push_back(
        {"sample error bound", bound_text(e) + " in EXPECTED, " + bound_text(a) + " in ACTUAL"});
  // Error figures and provenance live in the metadata.
  add_json_differences(e.metadata, a.metadata, "metadata", options, r);
  if (e.dim == 2)
    compare_hierarchy_arrays<2>(e, a, options, r);
  else
    compare_hierarchy_arrays<3>(e, a, options, r);
  return r;
}

}  // namespace

std::string CompareResult::summary() const {
  if (differences.empty()) return "equal";
  std::string s;
  for (const Difference& d : differences) s += d.item + ": " + d.reason + "\n";
  return s;
}

namespace {

CompareResult compare_quantized_meshes(const TriangleMesh& expected, const TriangleMesh& actual,
                                       const CompareOptions& options, const std::string& label, double step_e,
                                       double step_a) {
  pipeline::check_options(options);
  CompareResult r;
  r.kind = "mesh";
  // Step 1: counts.
  r.report["vertices"] = {expected.vertex_count(), actual.vertex_count()};
  r.report["triangles"] = {expected.triangle_count(), actual.triangle_count()};
  if (count_differs(expected.vertex_count(), actual.vertex_count(), options.count_tolerance_percent))
    r.differences.push_back(
        {item(label, "vertex count"),
         fmt::format("{} in EXPECTED, {} in ACTUAL (allowed: {}%)", expected.vertex_count(),
                     actual.vertex_count(), options.count_tolerance_percent)});
  if (count_differs(expected.triangle_count(), actual.triangle_count(), options.count_tolerance_percent))
    r.differences.push_back(
        {item(label, "triangle count"),
         fmt::format("{} in EXPECTED, {} in ACTUAL (allowed: {}%)", expected.triangle_count(),
                     actual.triangle_count(), options.count_tolerance_percent)});
  if (expected.triangles.empty() || actual.triangles.empty()) {
    if (expected.triangles.empty() != actual.triangles.empty())
      r.differences.push_back({item(label, "geometry"), "only one of the meshes has triangles"});
    return r;
  }

  // Step 2: bounding box and scale.
  const Box be = bounding_box(expected), ba = bounding_box(actual);
  const double diag_e = diagonal(be), diag_a = diagonal(ba);
  // A Draco side moved every coordinate by up to half its grid step, a point by up to
  // sqrt(3)/2 steps: the sum of both sides' steps bounds what quantization alone can do.
  const double asked = options.tolerance.value_or(1e-4 * diag_e);
  const double step = step_e + step_a;
  const double tol = std::max(asked, step);
  const double mean_tol = std::max(options.mean_tolerance.value_or(asked), step);
  r.report["tolerance"] = tol;
  if (step > 0) r.report["quantization_step"] = {step_e, step_a};
  if (step > asked)
    r.notes.push_back(fmt::format("{}tolerance {} widened to {}: the Draco quantization step of {}",
                                  label.empty() ? "" : label + ": ", fmt_g(asked), fmt_g(step),
                                  step_e > 0 && step_a > 0 ? "both sides"
                                  : step_e > 0             ? "EXPECTED"
                                                           : "ACTUAL"));
  r.report["bounding_box"] = {be, ba};
  double corner = 0;
  for (int c = 0; c < 2; ++c)
    for (int k = 0; k < 3; ++k) corner = std::max(corner, std::abs(be[c][k] - ba[c][k]));
  const double ratio = diag_e > 0 ? diag_a / diag_e : 1.0;
  // Only a clear change of size is named as such; a few percent is just a different surface.
  const bool scaled = diag_e > 0 && std::abs(diag_a - diag_e) > 2 * tol && std::abs(ratio - 1.0) > 0.05;
  std::string scale_note = scaled ? "; " + scale_cause(ratio) : "";
  if (corner > tol)
    r.differences.push_back(
        {item(label, "bounding box"),
         fmt::format("corners differ by up to {} > {}{}", fmt_g(corner), fmt_g(tol), scale_note)});

  // Step 3: handedness. A mirror image has the opposite signed volume; the check only means
  // something for (nearly) closed meshes, whose volume is not tiny against the box.
  const double vol_e = signed_volume(expected), vol_a = signed_volume(actual);
  r.report["signed_volume"] = {vol_e, vol_a};
  const double tiny = 1e-6 * std::pow(std::max(diag_e, diag_a), 3);
  const bool flipped = std::abs(vol_e) > tiny && std::abs(vol_a) > tiny && (vol_e > 0) != (vol_a > 0);
  if (flipped)
    r.differences.push_back(
        {item(label, "handedness"),
         fmt::format("signed volume {} in EXPECTED, {} in ACTUAL: ACTUAL is mirrored (wrong "
                     "handedness) or turned inside out",
                     fmt_g(vol_e), fmt_g(vol_a))});

  // Step 4: distances and normals by sampling.
  SurfaceSamplingOptions sampling;
  sampling.area_samples = options.samples;
  const MeshDistance d = mesh_distance(expected, actual, sampling);
  const double angle =
      std::max(d.expected_to_actual.normal_angle_mean_deg, d.actual_to_expected.normal_angle_mean_deg);
  const double angle_max =
      std::max(d.expected_to_actual.normal_angle_max_deg, d.actual_to_expected.normal_angle_max_deg);
  r.report["hausdorff"] = d.hausdorff();
  r.report["mean_distance"] = d.mean();
  r.report["expected_to_actual"] = {{"samples", d.expected_to_actual.samples},
                                    {"max", d.expected_to_actual.max},
                                    {"mean", d.expected_to_actual.mean},
                                    {"max_at", d.expected_to_actual.max_at}};
  r.report["actual_to_expected"] = {{"samples", d.actual_to_expected.samples},
                                    {"max", d.actual_to_expected.max},
                                    {"mean", d.actual_to_expected.mean},
                                    {"max_at", d.actual_to_expected.max_at}};
  r.report["normal_angle_mean_deg"] = angle;
  r.report["normal_angle_max_deg"] = angle_max;
  if (d.hausdorff() > tol) {
    std::string cause = scale_note;
    if (cause.empty() && flipped) {
      const int axis = mirrored_axis(expected, actual, tol);
      if (axis >= 0) cause = fmt::format("; ACTUAL is EXPECTED mirrored along {}", "xyz"[axis]);
    }
    const auto& worst =
        d.expected_to_actual.max >= d.actual_to_expected.max ? d.expected_to_actual : d.actual_to_expected;
    r.differences.push_back(
        {item(label, "Hausdorff distance"),
         fmt::format("{} > {} (worst at {} {} {} in {}){}", fmt_g(d.hausdorff()), fmt_g(tol),
                     fmt_g(worst.max_at[0]), fmt_g(worst.max_at[1]), fmt_g(worst.max_at[2]),
                     &worst == &d.expected_to_actual ? "EXPECTED" : "ACTUAL", cause)});
  }
  if (d.mean() > mean_tol)
    r.differences.push_back({item(label, "mean distance"),
                             fmt::format("{} > {}{}", fmt_g(d.mean()), fmt_g(mean_tol), scale_note)});
  if (angle > options.normal_angle_deg) {
    const double flipped_fraction =
        std::max(d.expected_to_actual.flipped_fraction, d.actual_to_expected.flipped_fraction);
    r.differences.push_back(
        {item(label, "normals"),
         fmt::format("mean angle {}° > {}° (max {}°){}", fmt_g(angle), fmt_g(options.normal_angle_deg),
                     fmt_g(angle_max),
                     flipped_fraction > 0.5
                         ? fmt::format("; {:.0f}% point the opposite way", 100 * flipped_fraction)
                         : std::string())});
  }
  return r;
}

}  // namespace

bool is_provenance(const std::string& pointer) {
  for (const char* p : {"/asset/generator", "/asset/extras/tool", "/asset/extras/input",
                        "/asset/extras/tolerance_mm", "/input", "/tool"})
    if (pointer == p) return true;
  // Timings, wherever a record keeps them.
  std::size_t at = 0;
  while (at < pointer.size()) {
    const std::size_t next = std::min(pointer.find('/', at + 1), pointer.size());
    const std::string key = pointer.substr(at + 1, next - at - 1);
    if (key == "seconds" || key == "timings" ||
        (key.size() > 8 && key.compare(key.size() - 8, 8, "_seconds") == 0))
      return true;
    at = next;
  }
  return false;
}

CompareResult compare_meshes(const TriangleMesh& expected, const TriangleMesh& actual,
                             const CompareOptions& options, const std::string& label) {
  return compare_quantized_meshes(expected, actual, options, label, 0.0, 0.0);
}

CompareResult compare_assets(AssetFile expected, AssetFile actual, const CompareOptions& options) {
  pipeline::check_options(options);
  if (expected.gltf_frame != actual.gltf_frame) {
    to_scan_frame(expected);
    to_scan_frame(actual);
  }
  CompareResult r;
  r.kind = "mesh";
  r.report["frame"] = expected.gltf_frame ? "glTF metres" : "scan millimetres";
  r.report["format"] = {expected.format, actual.format};
  if (options.strict && expected.format != actual.format)
    r.differences.push_back({"format", expected.format + " in EXPECTED, " + actual.format + " in ACTUAL"});
  auto keys = [](const AssetFile& f) {
    std::vector<std::string> k;
    for (const GltfSurface& s : f.surfaces) {
      const std::string& name = s.node_name.empty() ? s.name : s.node_name;
      k.push_back(name.empty() ? std::string() : "'" + name + "'");
    }
    return k;
  };
  auto label_map = [](const AssetFile& f) {
    return !f.surfaces.empty() && std::all_of(f.surfaces.begin(), f.surfaces.end(), [](const GltfSurface& s) {
      return s.node_extras.is_object() && s.node_extras.contains("label");
    });
  };
  std::vector<std::pair<std::size_t, std::size_t>> pairs;
  CompareResult matched;
  const bool per_surface = (expected.surfaces.size() > 1 || actual.surfaces.size() > 1) &&
                           pair_by_name(keys(expected), keys(actual),
                                        label_map(expected) && label_map(actual), "surfaces", pairs, matched);
  r.report["surfaces_matched_by"] = per_surface ? "name" : "all merged";
  auto step = [](const AssetFile& f) {
    return f.quantization_steps.empty()
               ? 0.0
               : *std::max_element(f.quantization_steps.begin(), f.quantization_steps.end());
  };
  if (!per_surface) {
    pairs.clear();
    CompareResult m = compare_quantized_meshes(merged_mesh(expected.surfaces), merged_mesh(actual.surfaces),
                                               options, "", step(expected), step(actual));
    r.report.update(m.report);
    for (auto& d : m.differences) r.differences.push_back(std::move(d));
    for (auto& n : m.notes) r.notes.push_back(std::move(n));
    return r;
  }
  for (auto& d : matched.differences) r.differences.push_back(std::move(d));
  nlohmann::json surfaces = nlohmann::json::array();
  for (const auto& [i, j] : pairs) {
    const std::string label = "surface " + keys(expected)[i];
    CompareResult m =
        compare_quantized_meshes(expected.surfaces[i].mesh, actual.surfaces[j].mesh, options, label,
                                 expected.quantization_steps[i], actual.quantization_steps[j]);
    m.report["label"] = label;
    surfaces.push_back(m.report);
    for (auto& d : m.differences) r.differences.push_back(std::move(d));
    for (auto& n : m.notes) r.notes.push_back(std::move(n));
  }
  r.report["surfaces"] = surfaces;
  return r;
}

CompareResult compare_files(const std::string& expected, const std::string& actual,
                            const CompareOptions& options) {
  pipeline::check_options(options);
  const Kind ke = detect_kind(expected), ka = detect_kind(actual);
  const bool both_meshes =
      (ke == Kind::kMesh || ke == Kind::kGltf) && (ka == Kind::kMesh || ka == Kind::kGltf);
  CompareResult r;
  if (ke != ka && !both_meshes) {
    // Different kinds are a difference only between two readable files: garbage with another
    // file's extension is unreadable input (exit 2), not a different asset.
    read_as(expected, ke);
    read_as(actual, ka);
    r.kind = "mismatch";
    r.differences.push_back(
        {"kind", std::string("EXPECTED is a ") + kind_name(ke) + ", ACTUAL a " + kind_name(ka)});
    return r;
  }
  switch (ke == ka ? ke : Kind::kMesh) {
    case Kind::kGltf:
      r = compare_gltf(expected, actual, options);
      break;
    case Kind::kImage:
      r = compare_images(expected, actual, options);
      break;
    case Kind::kVolume:
      r = compare_volumes(expected, actual, options);
      break;
    case Kind::kHierarchy:
      r = compare_hierarchies(expected, actual, options);
      break;
    case Kind::kMesh:
      r = compare_assets(read_asset(expected), read_asset(actual), options);
      break;
  }
  r.report["kind"] = r.kind;
  return r;
}

void write_compare_report(const std::string& path, const std::string& expected, const std::string& actual,
                          const CompareResult& result) {
  nlohmann::json j;
  j["expected"] = expected;
  j["actual"] = actual;
  j["equal"] = result.equal();
  j["kind"] = result.kind;
  j["differences"] = nlohmann::json::array();
  for (const auto& d : result.differences)
    j["differences"].push_back({{"item", d.item}, {"reason", d.reason}});
  j["notes"] = result.notes;
  j["figures"] = result.report;
  write_file_atomically(path, [&](std::ostream& os) { os << j.dump(2) << "\n"; });
}

}  // namespace mlfe
