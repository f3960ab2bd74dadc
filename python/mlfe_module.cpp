// The extension `mlfe._mlfe`: the pipeline library (include/mlfe/pipeline.h) for the Python
// package `mlfe` (python/mlfe/__init__.py), which checks and names the keywords, wraps the
// results in documented classes and is the public interface. Volumes are NumPy arrays indexed [i, j, k] (x,
// y, z; 2D height fields [i, j]); spacing, origin and direction follow the same axes. Arrays handed out
// (volumes read, surfaces extracted, hierarchy values) are views of the C++ buffers, kept alive by their
// owner; a volume passed in is copied once into the grid the library samples. The GIL is released while the
// library works. Bad input raises mlfe.Error (a ValueError) carrying the library's message.
#include <fmt/format.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/base/vec.h>
#include <mlfe/core/simplify/bricked_iso_surface.h>
#include <mlfe/formats/asset_reader.h>
#include <mlfe/formats/asset_writer.h>
#include <mlfe/formats/image_reader.h>
#include <mlfe/formats/input_files.h>
#include <mlfe/formats/label_table.h>
#include <mlfe/formats/volume_formats.h>
#include <mlfe/pipeline.h>
#include <mlfe/pipeline/compare.h>
#include <mlfe/pipeline/preview.h>
#include <mlfe/version.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <type_traits>
#include <variant>
#include <vector>

namespace py = pybind11;

namespace mlfe::python {
namespace {

// A NumPy array viewing `data` (owned by `owner`, moved into a capsule).
template <class T, class Owner>
py::array_t<T> view(std::shared_ptr<Owner> owner, const T* data, std::vector<py::ssize_t> shape,
                    std::vector<py::ssize_t> strides) {
  auto* keep = new std::shared_ptr<Owner>(std::move(owner));
  py::capsule base(keep, [](void* p) { delete static_cast<std::shared_ptr<Owner>*>(p); });
  return py::array_t<T>(std::move(shape), std::move(strides), data, base);
}

std::array<double, 3> triple(const py::handle& h, const char* what, double fill) {
  std::array<double, 3> out{fill, fill, fill};
  const auto v = h.cast<std::vector<double>>();
  if (v.size() < 2 || v.size() > 3) throw Error(std::string(what) + ": expected 2 or 3 numbers");
  for (std::size_t a = 0; a < v.size(); ++a) out[a] = v[a];
  return out;
}

// Whether h names a file (a str or an os.PathLike), and that file name as os.fspath gives it.
bool is_path(const py::handle& h) { return py::isinstance<py::str>(h) || py::hasattr(h, "__fspath__"); }
std::string fspath(const py::handle& p) { return py::str(py::module_::import("os").attr("fspath")(p)); }

py::object to_python(const nlohmann::json& j) { return py::module_::import("json").attr("loads")(j.dump()); }

// "; did you mean 'x'?" for a misspelt keyword: the nearest of the option table's Python
// spellings (difflib's ratio, as the command line suggests the nearest flag), or "".
std::string did_you_mean(const std::string& name) {
  std::vector<std::string> keywords;
  for (const auto& spec : pipeline::option_table())
    keywords.push_back(spec.spelled(pipeline::Spelling::kPython));
  const auto close = py::module_::import("difflib").attr("get_close_matches")(name, keywords, 1, 0.7);
  return py::len(close) ? "; did you mean '" + close[py::int_(0)].cast<std::string>() + "'?" : "";
}

// The keyword options of build/convert/extract, consumed as they are read so that unknown
// names can be reported.
class Options {
 public:
  explicit Options(const py::kwargs& kw) {
    for (auto item : kw)
      left_[item.first.cast<std::string>()] = py::reinterpret_borrow<py::object>(item.second);
  }
  template <class T>
  void get(const char* name, T& out) {
    auto it = left_.find(name);
    if (it == left_.end() || it->second.is_none()) return;
    try {
      out = it->second.cast<T>();
    } catch (const py::cast_error&) {
      throw Error(std::string(name) + ": wrong type (" + std::string(py::str(it->second.get_type())) + ")");
    }
    left_.erase(it);
  }
  bool has(const char* name) const { return left_.count(name) && !left_.at(name).is_none(); }
  py::object take(const char* name) {
    py::object o = left_.at(name);
    left_.erase(name);
    return o;
  }
  /// A file name or text: a str or an os.PathLike, as os.fspath gives it.
  std::string path(const char* name) {
    const py::object o = take(name);
    if (!is_path(o))
      throw Error(std::string(name) + ": wrong type (" + std::string(py::str(o.get_type())) + ")");
    return fspath(o);
  }
  void finish() const {
    if (left_.empty()) return;
    const std::string& name = left_.begin()->first;
    // A real option this call does not take (bricks with labels) is not a misspelling of itself.
    for (const auto& spec : pipeline::option_table())
      if (spec.spelled(pipeline::Spelling::kPython) == name)
        throw Error("option '" + name + "' does not apply to this call");
    throw Error("unknown option '" + name + "'" + did_you_mean(name));
  }

 private:
  std::map<std::string, py::object> left_;
};

// Text options through the pipeline's vocabulary (the command line's parse functions), named
// by their Python keyword; numbers are taken as they are.
template <class E>
void get_enum(Options& kw, const char* name, E& out) {
  std::string text;
  kw.get(name, text);
  if (!text.empty()) out = pipeline::parse_enum<E>(text, name);
}

// A Python object as option text: str as it is, numbers in their shortest exact spelling.
std::string option_text(const py::object& o) {
  if (py::isinstance<py::str>(o)) return o.cast<std::string>();
  if (py::isinstance<py::bool_>(o) || !(py::isinstance<py::int_>(o) || py::isinstance<py::float_>(o)))
    return std::string(py::str(py::repr(o)));  // fails in the parser with the value shown
  return py::str(o);
}

// Numbers as "a,b,c" for the vocabulary's parsers (shortest round-trip spelling).
std::string fmt_vector(const std::vector<double>& v) {
  std::string text;
  for (double x : v) text += (text.empty() ? "" : ",") + std::string(py::str(py::float_(x)));
  return text;
}

BuildOptions build_options(Options& kw) {
  BuildOptions o;
  if (kw.has("rms")) o.rms = pipeline::parse_rms(option_text(kw.take("rms")), "rms");
  kw.get("threshold", o.threshold);
  kw.get("max_vertices", o.max_vertices);
  kw.get("max_level", o.max_level);
  kw.get("start_level", o.start_level);
  get_enum(kw, "norm", o.norm);
  get_enum(kw, "preconditioner", o.preconditioner);
  kw.get("surface_tolerance", o.surface_tolerance);
  kw.get("check_u", o.check_against_u);
  if (kw.has("max_memory"))
    o.max_memory = pipeline::parse_memory_budget(option_text(kw.take("max_memory")), "max_memory");
  return o;
}

// The keywords iso-surface and label assets share (AssetOptions and LabelOptions name them alike).
template <class O>
void get_asset_keywords(Options& kw, O& o) {
  kw.get("tolerance", o.tolerance);
  kw.get("draco", o.draco);
  kw.get("quantize", o.quantize);
  kw.get("simplify", o.simplify);
  kw.get("min_component", o.min_component);
}

AssetOptions asset_options(Options& kw) {
  AssetOptions o;
  get_asset_keywords(kw, o);
  kw.get("lod", o.lod);
  kw.get("decimate", o.decimate);
  kw.get("ratio", o.ratio);
  get_enum(kw, "simplifier", o.simplifier);
  kw.get("snap", o.snap);
  kw.get("normals_toward_higher", o.normals_toward_higher);
  get_enum(kw, "normals", o.normals);
  get_enum(kw, "placement", o.placement);
  get_enum(kw, "surface", o.surface);
  kw.get("z_scale", o.z_scale);
  kw.get("level", o.level);
  kw.get("bricks", o.bricks);
  return o;
}

// progress=: a Python callable (fraction, stage) -> None/True to go on, False to cancel, as a
// pipeline Progress. Reports come on the calling thread while the GIL is released; the
// callback takes it. Ctrl-C (a pending signal) and an exception raised by the callback cancel
// the call too; with_progress then raises that exception instead of mlfe.Cancelled.
struct ProgressState {
  py::object callback;  // None: only signals are checked
  std::unique_ptr<py::error_already_set> error;
};

Progress make_progress(const std::shared_ptr<ProgressState>& state) {
  return [state](double fraction, const std::string& stage) -> bool {
    py::gil_scoped_acquire gil;
    if (state->error) return false;
    try {
      if (PyErr_CheckSignals() != 0) throw py::error_already_set();
      if (state->callback.is_none()) return true;
      const py::object r = state->callback(fraction, stage);
      return r.is_none() || PyObject_IsTrue(r.ptr()) == 1;
    } catch (py::error_already_set& e) {
      state->error = std::make_unique<py::error_already_set>(std::move(e));
      return false;
    }
  };
}

// Runs work(progress) without the GIL; a cancel caused by Python re-raises its exception.
template <class F>
auto with_progress(const py::object& callback, F&& work) {
  if (!callback.is_none() && !PyCallable_Check(callback.ptr()))
    throw Error("progress: expected a callable (fraction, stage), got " +
                std::string(py::str(callback.get_type())));
  auto state = std::make_shared<ProgressState>();
  state->callback = callback;
  const Progress progress = make_progress(state);
  try {
    py::gil_scoped_release release;
    return work(progress);
  } catch (const Cancelled&) {
    if (state->error) {
      py::error_already_set e = std::move(*state->error);
      state->error.reset();
      throw e;
    }
    throw;
  }
}

// A grid from an array indexed [i, j(, k)]: one copy into the library's x-fastest layout.
std::shared_ptr<ScalarGrid> grid_from_array(const py::array& in, const py::object& spacing,
                                            const py::object& origin, const py::object& direction,
                                            const std::string& space) {
  auto values = py::array_t<float, py::array::f_style | py::array::forcecast>::ensure(in);
  if (!values) throw Error("volume: expected a numeric array");
  if (values.ndim() != 2 && values.ndim() != 3)
    throw Error("volume: expected a 2D or 3D array, got " + std::to_string(values.ndim()) + " dimensions");
  auto g = std::make_shared<ScalarGrid>();
  g->dim = int(values.ndim());
  g->dims = {values.shape(0), values.shape(1), g->dim == 3 ? values.shape(2) : 1};
  g->source = "array";
  g->format = "numpy";
  g->values.resize(std::size_t(g->voxel_count()));
  if (!g->values.empty()) std::memcpy(g->values.data(), values.data(), g->values.size() * sizeof(float));
  for (float v : g->values)
    if (!std::isfinite(v)) throw Error("volume: NaN or infinite values (replace them first)");
  if (!spacing.is_none()) g->transform.spacing = triple(spacing, "spacing", 1.0);
  if (!origin.is_none()) g->transform.origin = triple(origin, "origin", 0.0);
  if (!direction.is_none()) {
    const auto d = direction.cast<std::vector<std::vector<double>>>();
    if (d.size() != 3 || d[0].size() != 3 || d[1].size() != 3 || d[2].size() != 3)
      throw Error("direction: expected a 3x3 matrix (rows)");
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) g->transform.direction[r * 3 + c] = d[r][c];
  }
  g->space = space;
  return g;
}

std::shared_ptr<ScalarGrid> grid_from(const py::object& volume, const py::object& spacing,
                                      const py::object& origin, const py::object& direction,
                                      const std::string& space) {
  if (is_path(volume)) {
    if (!spacing.is_none() || !origin.is_none() || !direction.is_none())
      throw Error("spacing, origin and direction are for arrays; a file brings its own");
    const std::string path = fspath(volume);
    py::gil_scoped_release release;
    return std::make_shared<ScalarGrid>(read_volume(path));
  }
  return grid_from_array(py::array::ensure(volume), spacing, origin, direction, space);
}

// The keywords of a volume file's read, the command line's read options: grid, vec_magnitude,
// nan_as, space, raw_dims, raw_type, raw_endian, raw_spacing, raw_origin, raw_offset, zarr_level.
VolumeReadOptions read_options(Options& kw) {
  VolumeReadOptions o;
  kw.get("grid", o.grid_name);
  kw.get("vec_magnitude", o.vec_magnitude);
  if (kw.has("nan_as")) {
    double v = 0;
    kw.get("nan_as", v);
    o.nan_as = v;
  }
  kw.get("space", o.space);
  if (kw.has("raw_dims")) {
    std::vector<std::int64_t> d;
    kw.get("raw_dims", d);
    if (d.size() < 2 || d.size() > 3) throw Error("raw_dims: expected 2 or 3 numbers");
    o.raw_dims = std::array<std::int64_t, 3>{d[0], d[1], d.size() > 2 ? d[2] : 1};
  }
  kw.get(pipeline::option_spec("raw_dtype").spelled(pipeline::Spelling::kPython), o.raw_dtype);
  kw.get("raw_endian", o.raw_endian);
  if (kw.has("raw_spacing")) o.raw_spacing = triple(kw.take("raw_spacing"), "raw_spacing", 1.0);
  if (kw.has("raw_origin")) o.raw_origin = triple(kw.take("raw_origin"), "raw_origin", 0.0);
  kw.get("raw_offset", o.raw_offset);
  kw.get("zarr_level", o.zarr_level);
  pipeline::check_options(o);
  return o;
}

py::tuple read_volume_py(const py::object& path, const py::kwargs& kwargs) {
  const std::string p = fspath(path);
  Options kw(kwargs);
  const VolumeReadOptions read = read_options(kw);
  kw.finish();
  std::shared_ptr<ScalarGrid> g;
  {
    py::gil_scoped_release release;
    g = std::make_shared<ScalarGrid>(read_volume(p, read));
  }
  const auto s = py::ssize_t(sizeof(float));
  std::vector<py::ssize_t> shape{g->dims[0], g->dims[1]}, strides{s, s * g->dims[0]};
  if (g->dim == 3) {
    shape.push_back(g->dims[2]);
    strides.push_back(s * g->dims[0] * g->dims[1]);
  }
  py::array_t<float> values = view<float>(g, g->values.data(), shape, strides);
  const auto& t = g->transform;
  py::dict info;
  info["direction"] = py::make_tuple(py::make_tuple(t.direction[0], t.direction[1], t.direction[2]),
                                     py::make_tuple(t.direction[3], t.direction[4], t.direction[5]),
                                     py::make_tuple(t.direction[6], t.direction[7], t.direction[8]));
  info["space"] = g->space;
  info["format"] = g->format;
  info["source_type"] = scalar_type_name(g->source_type);
  info["notes"] = g->notes;
  const int n = g->dim;
  py::tuple spacing(n), origin(n);
  for (int a = 0; a < n; ++a) {
    spacing[a] = t.spacing[a];
    origin[a] = t.origin[a];
  }
  return py::make_tuple(values, spacing, origin, info);
}

// A built hierarchy with the grid it came from (for extraction from the data's interpolant and
// snapping, as `mlfe convert` does); no grid for a tetrahedral mesh input.
struct PyBuilt {
  std::shared_ptr<const Built> built;
  std::shared_ptr<const ScalarGrid> grid;
  std::string source;  // the input, for reports and provenance
  // A loaded hierarchy file's error figures and metadata (null for a build).
  nlohmann::json file_info;
};

// ---- Meshes in and out (issue 42): extracted, read from any asset file, or made from arrays ----

// Surfaces with what writing and comparing them needs: the asset (its frame, space, provenance
// and Draco grid), all surfaces merged (the arrays Python sees) and the tolerance writing uses
// by default.
struct PyMesh {
  AssetFile asset;
  TriangleMesh merged;           // merged_mesh(asset.surfaces): what the single-mesh formats store
  double default_tolerance = 0;  // millimetres
};

std::shared_ptr<PyMesh> make_mesh(AssetFile asset, double default_tolerance) {
  auto m = std::make_shared<PyMesh>();
  asset.quantization_steps.resize(asset.surfaces.size(), 0.0);
  m->merged = merged_mesh(asset.surfaces);
  m->asset = std::move(asset);
  m->default_tolerance = default_tolerance;
  return m;
}

// A file's surfaces; writing them again uses the tolerance they were written with: the one a
// glTF records, half a Draco file's grid step, else write_asset's default.
std::shared_ptr<PyMesh> read_mesh_py(const std::string& path) {
  AssetFile a;
  {
    py::gil_scoped_release release;
    a = read_asset(path);
  }
  double tolerance = a.tolerance_mm;
  if (a.format == "drc") tolerance = a.quantization_steps[0] / 2;
  return make_mesh(std::move(a), tolerance > 0 ? tolerance : AssetWriteOptions{}.tolerance_mm);
}

// An (n, 3) array of `T` copied from `h` (any numeric array), named `what` in errors.
template <class T>
std::vector<std::array<T, 3>> rows3(const py::handle& h, const char* what) {
  const auto a = py::array_t<T, py::array::c_style | py::array::forcecast>::ensure(h);
  if (!a || a.ndim() != 2 || a.shape(1) != 3)
    throw Error(std::string(what) + ": expected an (n, 3) array of numbers");
  std::vector<std::array<T, 3>> out(std::size_t(a.shape(0)));
  if (!out.empty()) std::memcpy(out.data(), a.data(), out.size() * sizeof(out[0]));
  return out;
}

// Mesh(positions, triangles, normals, name, label, color, iso): one surface in the scan's
// millimetres, checked as write_asset will need it.
std::shared_ptr<PyMesh> mesh_from_arrays(const py::object& positions, const py::object& triangles,
                                         const py::object& normals, const std::string& name,
                                         const py::object& label, const std::vector<float>& color,
                                         double iso) {
  GltfSurface s;
  s.name = s.node_name = name;
  s.iso_value = iso;
  s.mesh.positions = rows3<float>(positions, "positions");
  for (const auto& p : s.mesh.positions)
    if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2]))
      throw Error("positions: NaN or infinite coordinates");
  const py::array t = py::array::ensure(triangles);
  if (!t || !(t.dtype().kind() == 'i' || t.dtype().kind() == 'u' || t.size() == 0))
    throw Error("triangles: expected an (m, 3) array of integer vertex indices");
  for (const auto& tri : rows3<std::int64_t>(t, "triangles")) {
    for (std::int64_t v : tri)
      if (v < 0 || std::uint64_t(v) >= s.mesh.positions.size())
        throw Error(fmt::format("triangles: vertex index {} outside 0..{}", v, s.mesh.positions.size() - 1));
    s.mesh.triangles.push_back({std::uint32_t(tri[0]), std::uint32_t(tri[1]), std::uint32_t(tri[2])});
  }
  if (!normals.is_none()) {
    s.mesh.normals = rows3<float>(normals, "normals");
    if (s.mesh.normals.size() != s.mesh.positions.size())
      throw Error(
          fmt::format("normals: {} rows for {} positions", s.mesh.normals.size(), s.mesh.positions.size()));
  }
  if (color.size() != 3 && color.size() != 4)
    throw Error("color: expected 3 or 4 numbers (RGB[A] in [0, 1])");
  for (std::size_t k = 0; k < color.size(); ++k) {
    if (!(color[k] >= 0.0f && color[k] <= 1.0f)) throw Error("color: expected numbers in [0, 1]");
    s.color[k] = color[k];
  }
  if (!label.is_none()) {
    if (!py::isinstance<py::int_>(label) || py::isinstance<py::bool_>(label))
      throw Error("label: expected an integer, got " + std::string(py::str(label.get_type())));
    s.node_extras = {{"label", label.cast<std::int64_t>()}};
  }
  AssetFile a;
  a.surfaces.push_back(std::move(s));
  return make_mesh(std::move(a), AssetWriteOptions{}.tolerance_mm);
}

// The surfaces of several meshes in one (all in the same frame), in order.
std::shared_ptr<PyMesh> join_meshes(const std::vector<std::shared_ptr<PyMesh>>& parts) {
  if (parts.empty()) throw Error("meshes: expected at least one Mesh");
  AssetFile a = parts[0]->asset;
  a.surfaces.clear();
  a.quantization_steps.clear();
  double tolerance = 0;
  for (const auto& p : parts) {
    if (p->asset.gltf_frame != a.gltf_frame)
      throw Error("meshes: some are in glTF's frame and some in the scan's (use to_scan_frame() first)");
    a.surfaces.insert(a.surfaces.end(), p->asset.surfaces.begin(), p->asset.surfaces.end());
    a.quantization_steps.insert(a.quantization_steps.end(), p->asset.quantization_steps.begin(),
                                p->asset.quantization_steps.end());
    tolerance = std::max(tolerance, p->default_tolerance);
  }
  return make_mesh(std::move(a), tolerance);
}

// Surface `i` alone, with the asset's frame, space and provenance.
std::shared_ptr<PyMesh> surface_of(const PyMesh& m, std::size_t i) {
  if (i >= m.asset.surfaces.size()) throw py::index_error("surface index out of range");
  AssetFile a = m.asset;
  a.surfaces = {m.asset.surfaces[i]};
  a.quantization_steps = {m.asset.quantization_steps[i]};
  return make_mesh(std::move(a), m.default_tolerance);
}

std::shared_ptr<PyMesh> in_scan_frame(const PyMesh& m) {
  AssetFile a = m.asset;
  to_scan_frame(a);
  return make_mesh(std::move(a), m.default_tolerance);
}

// Writes the surfaces as write_assets does (write_asset), from the scan's millimetres, with the
// mesh's default tolerance unless one is given.
void write_mesh(const PyMesh& m, const std::string& path, bool draco, bool quantize, double tolerance) {
  check_output_path(path, kAssetExtensions);
  if (!(tolerance >= 0)) throw Error("tolerance: expected a value >= 0");
  const double tol = tolerance > 0 ? tolerance : m.default_tolerance;
  AssetFile a = m.asset;
  to_scan_frame(a);
  write_asset(a.surfaces, path, {draco, quantize, tol, a.space, a.extras});
}

// A side of mlfe.compare that is not a file pair: a Mesh, or a mesh file read as one.
AssetFile compared_asset(const py::handle& side) {
  if (is_path(side)) return read_asset(fspath(side));
  return side.cast<const PyMesh&>().asset;
}

// A hierarchy point (local frame, 2 or 3 coordinates) in the physical frame (millimetres).
template <class P>
Vec3 physical_point(const GridTransform& t, const P& p) {
  Vec3 local{0, 0, 0};
  for (std::size_t c = 0; c < p.size(); ++c) local[c] = p[c];
  return t.local_to_physical(local);
}

// Leaf simplices of `b` as an (m, dim + 1) array of vertex indices; tetrahedra positively
// oriented in the physical frame (signed_volume6), as the .vtu and .msh writers order them.
py::array_t<std::int64_t> leaf_cells(const Built& b) {
  return b.visit([&b](const auto& a) {
    constexpr int kCorners = std::tuple_size_v<typename std::decay_t<decltype(a.hierarchy)>::Cell>;
    const auto leaves = a.hierarchy.leaves();
    std::vector<Vec3> at;
    if constexpr (kCorners == 4)
      for (const auto& p : a.hierarchy.points()) at.push_back(physical_point(b.transform, p));
    py::array_t<std::int64_t> out({py::ssize_t(leaves.size()), py::ssize_t(kCorners)});
    auto w = out.template mutable_unchecked<2>();
    for (std::size_t e = 0; e < leaves.size(); ++e) {
      std::array<std::int64_t, kCorners> c;
      for (int k = 0; k < kCorners; ++k) c[k] = std::int64_t(a.hierarchy.cell(leaves[e])[k].value);
      if constexpr (kCorners == 4)
        if (signed_volume6(at[c[0]], at[c[1]], at[c[2]], at[c[3]]) < 0) std::swap(c[2], c[3]);
      for (int k = 0; k < kCorners; ++k) w(py::ssize_t(e), k) = c[k];
    }
    return out;
  });
}

// Vertex positions of `b` in the physical frame (millimetres), (n, 3) float64.
py::array_t<double> physical_positions(const Built& b) {
  return b.visit([&b](const auto& a) {
    const auto& pts = a.hierarchy.points();
    py::array_t<double> out({py::ssize_t(pts.size()), py::ssize_t(3)});
    auto w = out.template mutable_unchecked<2>();
    for (std::size_t v = 0; v < pts.size(); ++v) {
      const Vec3 q = physical_point(b.transform, pts[v]);
      for (int c = 0; c < 3; ++c) w(py::ssize_t(v), c) = q[c];
    }
    return out;
  });
}

py::array_t<std::uint8_t> vertex_levels(const Built& b) {
  return b.visit([](const auto& a) {
    const auto& l = a.hierarchy.vertex_level_array();
    py::array_t<std::uint8_t> out(py::ssize_t(l.size()));
    if (!l.empty()) std::memcpy(out.mutable_data(), l.data(), l.size());
    return out;
  });
}

// mlfe.load: the hierarchy file as a Built, with the error figures and metadata of its header
// (read again on its coarsest level only).
PyBuilt load_py(const py::object& path_like) {
  const std::string path = fspath(path_like);
  PyBuilt out;
  out.source = path;
  HierarchyFile header;
  {
    py::gil_scoped_release release;
    out.built = std::make_shared<const Built>(built_from_file(path));
    header = read_hierarchy(path, 0);
  }
  auto figure = [](double v) { return std::isnan(v) ? nlohmann::json() : nlohmann::json(v); };
  out.file_info = {{"norm", header.norm},
                   {"rms", figure(header.rms_error)},
                   {"max", figure(header.max_error)},
                   {"psnr_db", figure(header.psnr_db)},
                   {"sample_error_bound", figure(header.sample_error_bound)},
                   {"value_bound", header.value_bound},
                   {"version", header.version},
                   {"metadata", header.metadata}};
  return out;
}

// Refuses, before `volume` (a file or an array) is read, an output that is a file its read
// opens or the label table `table` (pipeline::check_distinct_files, as every command checks).
void check_files(const py::object& volume, const std::string& table, const pipeline::NamedFiles& outputs) {
  pipeline::check_distinct_files(
      {{"volume", is_path(volume) ? fspath(volume) : ""}, {pipeline::option_ref("label_table"), table}},
      outputs);
}

// The path of a .vtu/.msh tetrahedral mesh, or "" for anything else (arrays, volume files).
std::string tet_mesh_path(const py::object& volume) {
  if (!is_path(volume)) return "";
  const std::string path = fspath(volume);
  return detect_tet_mesh_format(path).empty() ? "" : path;
}

PyBuilt build_py(const py::object& volume, const py::object& iso, const py::object& spacing,
                 const py::object& origin, const py::object& direction, const std::string& space,
                 const py::object& progress, const py::kwargs& kwargs) {
  Options kw(kwargs);
  BuildOptions options = build_options(kw);
  kw.finish();
  const std::vector<double> isos = iso.is_none() ? std::vector<double>{} : iso.cast<std::vector<double>>();
  PyBuilt out;
  if (const std::string mesh = tet_mesh_path(volume); !mesh.empty()) {
    out.built = with_progress(progress, [&](const Progress& p) {
      options.fraction_progress = p;
      return std::make_shared<const Built>(build(read_tet_mesh(mesh), options, isos));
    });
    out.source = mesh;
    return out;
  }
  auto grid = grid_from(volume, spacing, origin, direction, space);
  out.built = with_progress(progress, [&](const Progress& p) {
    options.fraction_progress = p;
    return std::make_shared<const Built>(build(*grid, options, isos));
  });
  out.source = grid->source;
  out.grid = std::move(grid);
  return out;
}

// convert(preview=...): the page showing the asset just written (<mlfe/pipeline/preview.h>);
// nothing without a page path.
void write_convert_preview(const std::string& page, const std::string& asset, const nlohmann::json& report,
                           const std::string& source) {
  if (page.empty()) return;
  py::gil_scoped_release release;
  pipeline::write_preview(page, {asset, report, "", std::filesystem::path(source).filename().string()});
}

// The labels= of convert's keywords when it asks for a label conversion (True, a list or text;
// not False), taken out of kw.
std::optional<py::object> picked_labels(Options& kw) {
  if (!kw.has("labels")) return std::nullopt;
  py::object picked = kw.take("labels");
  if (py::isinstance<py::bool_>(picked) && !picked.cast<bool>()) return std::nullopt;
  return picked;
}

// A label conversion's options from `picked` (picked_labels) and the rest of convert's keywords
// (all of them read: unknown ones raise); iso= and hierarchy= are refused.
LabelOptions label_keywords(const py::object& picked, bool iso, bool hierarchy, Options& kw) {
  if (iso) throw Error("labels and iso exclude each other");
  if (hierarchy) throw Error("labels writes surfaces only (no hierarchy yet)");
  LabelOptions o;
  if (py::isinstance<py::str>(picked))
    o.labels = parse_label_list(picked.cast<std::string>());
  else if (!py::isinstance<py::bool_>(picked))
    for (auto l : picked.cast<std::vector<long long>>()) {
      if (l < 0 || l > 65535) throw Error("labels: " + std::to_string(l) + " is not a label 0..65535");
      o.labels.push_back(static_cast<std::uint16_t>(l));
    }
  if (kw.has("label_table")) o.table = fspath(kw.take("label_table"));
  get_asset_keywords(kw, o);
  kw.get("smooth_iterations", o.smoothing_iterations);
  kw.get("max_offset", o.max_offset);
  kw.finish();
  return o;
}

// An iso-surface conversion's options from convert's keywords (all of them read: unknown ones
// raise) and iso.
ConvertOptions convert_keywords(const py::object& iso, Options& kw) {
  ConvertOptions c;
  c.build = build_options(kw);
  c.asset = asset_options(kw);
  kw.finish();
  if (!iso.is_none()) c.asset.iso = iso.cast<std::vector<double>>();
  return c;
}

// mlfe.batch's check before any scan is sent: convert's keywords read and checked as convert
// reads and checks them before it reads a volume (a misspelt keyword raises with the nearest).
void check_convert_keywords(const py::object& iso, bool hierarchy, const py::kwargs& kwargs) {
  Options kw(kwargs);
  if (const auto picked = picked_labels(kw)) {
    pipeline::check_options(label_keywords(*picked, !iso.is_none(), hierarchy, kw));
    return;
  }
  const ConvertOptions c = convert_keywords(iso, kw);
  pipeline::check_options(c.build);
  pipeline::check_options(c.asset);
}

// convert(..., labels=True or [3, 7] or "3,7-9", label_table=..., min_component=...): a label map
// in, one surface per structure out (convert_labels), as `mlfe convert --labels`.
py::object convert_labels_py(const py::object& volume, const py::object& out, const py::object& iso,
                             const py::object& spacing, const py::object& origin, const py::object& direction,
                             const std::string& space, const py::object& hierarchy, const py::object& report,
                             const std::string& preview, const py::object& picked, Options& kw) {
  LabelOptions o = label_keywords(picked, !iso.is_none(), !hierarchy.is_none(), kw);
  const std::string out_path = fspath(out);
  // The table read is the one named, else the one beside a volume file (find_label_table).
  const std::string table = o.table.empty() && is_path(volume) ? find_label_table(fspath(volume)) : o.table;
  check_files(volume, table, {{"output", out_path}, {"report", report.is_none() ? "" : fspath(report)}});
  check_output_path(out_path, kAssetExtensions);
  if (!preview.empty()) pipeline::check_preview_paths(preview, out_path);
  auto grid = grid_from(volume, spacing, origin, direction, space);
  // Warnings (absent labels) are collected without the GIL and raised as Python warnings.
  std::vector<std::string> warnings;
  o.warn = [&warnings](const std::string& w) { warnings.push_back(w); };
  nlohmann::json summary;
  {
    py::gil_scoped_release release;
    summary =
        convert_labels(*grid, out_path, o, {{"tool", std::string("mlfe ") + MLFE_VERSION + " (python)"}});
  }
  for (const auto& w : warnings) PyErr_WarnEx(PyExc_UserWarning, w.c_str(), 1);
  if (!report.is_none()) write_json(fspath(report), {{"asset", summary}});
  write_convert_preview(preview, out_path, {{"asset", summary}}, grid->source);
  return to_python(summary);
}

py::object convert_py(const py::object& volume, const py::object& out, const py::object& iso,
                      const py::object& spacing, const py::object& origin, const py::object& direction,
                      const std::string& space, const py::object& hierarchy, const py::object& report,
                      const py::object& preview_path, const py::object& progress, const py::kwargs& kwargs) {
  Options kw(kwargs);
  const std::string preview = preview_path.is_none() ? "" : fspath(preview_path);
  if (const auto picked = picked_labels(kw))
    return convert_labels_py(volume, out, iso, spacing, origin, direction, space, hierarchy, report, preview,
                             *picked, kw);
  ConvertOptions c = convert_keywords(iso, kw);
  if (!hierarchy.is_none()) c.hierarchy = fspath(hierarchy);
  if (!report.is_none()) c.report = fspath(report);
  const std::string out_path = fspath(out);
  c.provenance["tool"] = std::string("mlfe ") + MLFE_VERSION + " (python)";
  // Checked before reading or copying the volume.
  check_files(volume, "", {{"output", out_path}, {"hierarchy", c.hierarchy}, {"report", c.report}});
  check_output_path(out_path, kAssetExtensions);
  if (!preview.empty()) pipeline::check_preview_paths(preview, out_path);
  if (const std::string mesh = tet_mesh_path(volume); !mesh.empty()) {
    const ConvertResult r = with_progress(progress, [&](const Progress& p) {
      c.progress = p;
      return convert(mesh, out_path, c);
    });
    write_convert_preview(preview, out_path, r.report, mesh);
    return to_python(r.asset);
  }
  auto grid = grid_from(volume, spacing, origin, direction, space);
  const ConvertResult r = with_progress(progress, [&](const Progress& p) {
    c.progress = p;
    return convert(*grid, out_path, c);
  });
  write_convert_preview(preview, out_path, r.report, grid->source);
  return to_python(r.asset);
}

// A conversion of a volume file read in bricks, split for mlfe.distributed: convert()'s options
// resolved as convert() resolves them (open_in_bricks: auto's brick edge), the volume opened.
// Workers each open one to compute their bricks' parts; the client opens one to write the asset.
struct PyBricks {
  std::string input;
  pipeline::ConvertFileOptions options;
  std::shared_ptr<const VolumeWindows> volume;
  std::size_t count = 0, slabs = 0, slab_bricks = 0;
};

// mlfe.convert's keywords, read options and iso for `input`; with `output`, that path is checked
// first, as convert() checks it. Throws for any option convert would refuse, and for options
// with which convert reads the volume whole (nothing to distribute).
PyBricks open_bricks_py(const py::object& input, const py::object& output, const py::object& iso,
                        const py::kwargs& kwargs) {
  Options kw(kwargs);
  PyBricks b;
  b.options.build = build_options(kw);
  b.options.asset = asset_options(kw);
  b.options.read = read_options(kw);
  kw.finish();
  if (!iso.is_none()) b.options.asset.iso = iso.cast<std::vector<double>>();
  pipeline::check_options(b.options.build);
  pipeline::check_options(b.options.asset);
  b.input = fspath(input);
  if (!output.is_none()) {
    pipeline::check_distinct_files({{"input", b.input}}, {{"output", fspath(output)}});
    check_output_path(fspath(output), kAssetExtensions);
  }
  py::gil_scoped_release release;
  std::optional<VolumeWindows> v = pipeline::open_in_bricks(b.input, b.options);
  if (!v)
    throw pipeline::OptionError(
        pipeline::option_ref("bricks") + ": " + b.input +
        " would be converted whole, not in bricks (auto bricks raw and OME-Zarr volumes over 2^27 "
        "samples; give bricks=N, without lod, level, min_component, simplify=0 or a global target)");
  b.count = brick_count(*v, b.options.asset);
  const BrickLayout layout = brick_layout(v->frame().dims, b.options.asset.bricks);
  b.slabs = layout.slabs();
  b.slab_bricks = layout.slab_bricks();
  b.volume = std::make_shared<const VolumeWindows>(std::move(*v));
  return b;
}

// The bytes of `parts`, taken out (its items become None) so that they are held once, not
// twice, while joined.
std::vector<std::string> take_parts(py::list parts) {
  std::vector<std::string> taken;
  taken.reserve(parts.size());
  for (std::size_t k = 0; k < parts.size(); ++k) {
    taken.push_back(parts[k].cast<std::string>());
    parts[k] = py::none();
  }
  return taken;
}

// mlfe._mlfe.Bricks: the pieces of mlfe.distributed.convert.
void bind_bricks(py::module_& m) {
  py::class_<PyBricks>(m, "Bricks")
      .def_property_readonly("count", [](const PyBricks& b) { return b.count; })
      .def_property_readonly("edge", [](const PyBricks& b) { return b.options.asset.bricks; })
      .def_property_readonly("streamed", [](const PyBricks& b) { return b.volume->streamed(); })
      .def("parts",
           [](const PyBricks& b, std::size_t first, std::size_t last) {
             std::vector<std::string> parts;
             {
               py::gil_scoped_release release;
               for (std::size_t k = first; k < last; ++k)
                 parts.push_back(brick_parts(*b.volume, b.options.asset, k));
             }
             py::list out;
             for (const std::string& p : parts) out.append(py::bytes(p));
             return out;
           })
      .def_property_readonly("slabs", [](const PyBricks& b) { return b.slabs; })
      .def_property_readonly("slab_bricks", [](const PyBricks& b) { return b.slab_bricks; })
      .def("split",
           [](const PyBricks& b, std::size_t first, std::size_t end) {
             if (!(first + 1 < end && end <= b.slabs))
               throw Error(fmt::format("bricks: slabs [{}, {}) of {} have no halves", first, end, b.slabs));
             return slab_split(first, end);
           })
      .def("join",
           [](const PyBricks& b, std::size_t first, std::size_t end, const py::list& parts) {
             std::vector<std::string> in = take_parts(parts);
             std::string out;
             {
               py::gil_scoped_release release;
               out = join_parts(*b.volume, b.options.asset, first, end, std::move(in));
             }
             return py::bytes(out);
           })
      .def("write", [](const PyBricks& b, const py::object& output, py::list parts) {
        const std::string path = fspath(output);
        std::vector<std::string> taken = take_parts(parts);
        nlohmann::json summary;
        {
          py::gil_scoped_release release;
          summary = write_bricks(path, *b.volume, b.options.asset, std::move(taken),
                                 bricks_provenance(b.input, b.options.asset));
        }
        return to_python(summary);
      });
  m.def("open_bricks", &open_bricks_py, py::arg("input"), py::arg("output"), py::arg("iso"));
}

// "x,y,z" or three numbers, as text for the vocabulary's parser.
std::string vector_text(const py::object& o, const std::string& name) {
  if (py::isinstance<py::str>(o)) return o.cast<std::string>();
  std::vector<double> v;
  try {
    v = o.cast<std::vector<double>>();
  } catch (const py::cast_error&) {
    throw Error(name + ": expected three numbers or 'x,y,z'");
  }
  if (v.size() != 3) throw Error(name + ": expected three numbers, got " + std::to_string(v.size()));
  return fmt_vector(v);
}

// (width, height) or "WxH", as text for the vocabulary's parser.
std::string size_text(const py::object& o, const std::string& name) {
  if (py::isinstance<py::str>(o)) return o.cast<std::string>();
  std::vector<py::object> wh;
  try {
    wh = o.cast<std::vector<py::object>>();
  } catch (const py::cast_error&) {
  }
  if (wh.size() != 2) throw Error(name + ": expected (width, height) or 'WxH'");
  return std::string(py::str(wh[0])) + "x" + std::string(py::str(wh[1]));
}

// One keyword of a field table (pipeline::render_fields()), converted by the member's type:
// bools and numbers cast as they are, text from a str or a path, the rest through the
// library's parse functions.
template <class O>
void get_field(Options& kw, const pipeline::OptionField<O>& f, O& o) {
  const std::string key = f.spec.spelled(pipeline::Spelling::kPython);
  if (!kw.has(key.c_str())) return;
  std::visit(
      [&](const auto& m) {
        using M = std::decay_t<decltype(m)>;
        if constexpr (std::is_same_v<M, bool O::*> || std::is_same_v<M, int O::*> ||
                      std::is_same_v<M, double O::*>) {
          kw.get(key.c_str(), o.*m);
        } else if constexpr (std::is_same_v<M, std::string O::*>) {
          o.*m = kw.path(key.c_str());
        } else if constexpr (std::is_same_v<M, pipeline::EnumMember<O>>) {
          std::string text;
          kw.get(key.c_str(), text);
          pipeline::set_option_text(f, o, text);
        } else if constexpr (std::is_same_v<M, std::array<int, 2> O::*>) {
          pipeline::set_option_text(f, o, size_text(kw.take(key.c_str()), key));
        } else {
          pipeline::set_option_text(f, o, vector_text(kw.take(key.c_str()), key));
        }
      },
      f.member);
}

pipeline::RenderFileOptions render_options(Options& kw) {
  pipeline::RenderFileOptions o;
  for (const auto& f : pipeline::render_fields()) get_field(kw, f, o);
  return o;
}

py::array_t<double> matrix4(const std::array<double, 16>& m) {
  py::array_t<double> a({4, 4});
  std::memcpy(a.mutable_data(), m.data(), sizeof(double) * 16);
  return a;
}

// The frames of a render: per frame its files, size, seconds, camera matrices and, when kept,
// RGBA (h, w, 4) and Z (h, w) float32 arrays (rows from the top, as the EXR).
py::list render_frames(pipeline::RenderResult&& r) {
  auto owner = std::make_shared<pipeline::RenderResult>(std::move(r));
  py::list frames;
  const auto f = py::ssize_t(sizeof(float));
  for (const auto& fr : owner->frames) {
    py::dict d;
    d["exr"] = fr.exr;
    d["png"] = fr.png;
    d["width"] = fr.width;
    d["height"] = fr.height;
    d["seconds"] = fr.seconds;
    d["world_to_camera"] = matrix4(fr.camera.world_to_camera());
    d["world_to_ndc"] = matrix4(fr.camera.world_to_ndc());
    d["rays"] = fr.stats.rays;
    d["segments"] = fr.stats.segments;
    const RenderImage& img = fr.image;
    const py::ssize_t w = img.width, h = img.height;
    if (!img.rgba.empty()) {
      d["rgba"] = view<float>(owner, img.rgba.data(), {h, w, 4}, {4 * f * w, 4 * f, f});
      d["z"] = view<float>(owner, img.z.data(), {h, w}, {f * w, f});
    }
    frames.append(d);
  }
  return frames;
}

// What mlfe.render returns: the render's figures and its frames.
py::dict render_result(pipeline::RenderResult&& r) {
  py::dict result;
  result["tetrahedra"] = r.tetrahedra;
  result["level"] = r.level;
  result["mesh_bytes"] = r.mesh_bytes;
  result["written"] = r.written;
  result["frames"] = render_frames(std::move(r));
  return result;
}

CompareOptions compare_options(const py::kwargs& kwargs) {
  Options kw(kwargs);
  CompareOptions o;
  auto optional = [&kw](const char* name, std::optional<double>& out) {
    if (!kw.has(name)) return;
    double v = 0;
    kw.get(name, v);
    out = v;
  };
  optional("tolerance", o.tolerance);
  optional("mean_tolerance", o.mean_tolerance);
  optional("image_max", o.image_max);
  optional("psnr", o.min_psnr);
  optional("value_max", o.value_max);
  optional("value_rms", o.value_rms);
  if (kw.has("count_tolerance"))
    o.count_tolerance_percent =
        pipeline::parse_percent(option_text(kw.take("count_tolerance")), "count_tolerance");
  kw.get("normal_angle", o.normal_angle_deg);
  kw.get("samples", o.samples);
  kw.get("number_tolerance", o.number_tolerance);
  kw.get("ignore", o.ignore);
  kw.get("strict", o.strict);
  kw.finish();
  return o;
}

py::tuple compare_result(const CompareResult& r) {
  py::list differences;
  for (const auto& d : r.differences) differences.append(py::make_tuple(d.item, d.reason));
  return py::make_tuple(r.kind, differences, to_python(r.report), r.summary(), r.notes);
}

// A read-only (n, 3) view of one of the merged mesh's arrays.
template <class T>
py::array_t<T> rows_view(const std::shared_ptr<PyMesh>& s, const std::vector<std::array<T, 3>>& rows) {
  auto a = view<T>(s, rows.empty() ? nullptr : rows[0].data(), {py::ssize_t(rows.size()), 3},
                   {py::ssize_t(3 * sizeof(T)), py::ssize_t(sizeof(T))});
  py::detail::array_proxy(a.ptr())->flags &= ~py::detail::npy_api::NPY_ARRAY_WRITEABLE_;
  return a;
}

// mlfe._mlfe.Mesh: surfaces extracted, read or made from arrays, and their writer.
void bind_mesh(py::module_& m) {
  py::class_<PyMesh, std::shared_ptr<PyMesh>>(m, "Mesh")
      .def_property_readonly("vertices",
                             [](std::shared_ptr<PyMesh> s) { return rows_view(s, s->merged.positions); })
      .def_property_readonly("normals",
                             [](std::shared_ptr<PyMesh> s) { return rows_view(s, s->merged.normals); })
      .def_property_readonly("triangles",
                             [](std::shared_ptr<PyMesh> s) { return rows_view(s, s->merged.triangles); })
      .def_property_readonly("iso",
                             [](const PyMesh& s) {
                               std::vector<double> v;
                               for (const auto& x : s.asset.surfaces) v.push_back(x.iso_value);
                               return v;
                             })
      .def_property_readonly("surface_triangles",
                             [](const PyMesh& s) {
                               std::vector<std::size_t> v;
                               for (const auto& x : s.asset.surfaces) v.push_back(x.mesh.triangles.size());
                               return v;
                             })
      .def_property_readonly("names",
                             [](const PyMesh& s) {
                               std::vector<std::string> v;
                               for (const auto& x : s.asset.surfaces)
                                 v.push_back(x.node_name.empty() ? x.name : x.node_name);
                               return v;
                             })
      .def_property_readonly("colors",
                             [](const PyMesh& s) {
                               std::vector<std::array<float, 4>> v;
                               for (const auto& x : s.asset.surfaces) v.push_back(x.color);
                               return v;
                             })
      .def_property_readonly("node_extras",
                             [](const PyMesh& s) {
                               nlohmann::json v = nlohmann::json::array();
                               for (const auto& x : s.asset.surfaces) v.push_back(x.node_extras);
                               return to_python(v);
                             })
      .def_property_readonly("quantization_steps", [](const PyMesh& s) { return s.asset.quantization_steps; })
      .def_property_readonly("gltf_frame", [](const PyMesh& s) { return s.asset.gltf_frame; })
      .def_property_readonly("format", [](const PyMesh& s) { return s.asset.format; })
      .def_property_readonly("extras", [](const PyMesh& s) { return to_python(s.asset.extras); })
      .def_property_readonly("space", [](const PyMesh& s) { return s.asset.space; })
      .def_property_readonly("size", [](const PyMesh& s) { return s.asset.surfaces.size(); })
      .def("surface", &surface_of)
      .def("to_scan_frame", &in_scan_frame)
      .def("write",
           [](const PyMesh& s, const std::string& path, bool draco, bool quantize, double tolerance) {
             py::gil_scoped_release release;
             write_mesh(s, path, draco, quantize, tolerance);
           });
  m.def("read_mesh", &read_mesh_py, py::arg("path"));
  m.def("make_mesh", &mesh_from_arrays);
  m.def("join_meshes", &join_meshes);
}

// threads=: the library's worker threads while one call runs (0: every core), as the command
// line's --threads; outputs do not depend on the count. A context manager: the limit holds from
// __enter__ to __exit__ (TBB keeps the smallest of the limits alive, so nested calls keep it).
struct ThreadLimit {
  int threads = 0;
  std::unique_ptr<tbb::global_control> control;
};

void bind_thread_limit(py::module_& m) {
  py::class_<ThreadLimit>(m, "ThreadLimit")
      .def("__enter__",
           [](ThreadLimit& t) -> ThreadLimit& {
             if (t.threads > 0)
               t.control = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                                 std::size_t(t.threads));
             return t;
           })
      .def("__exit__", [](ThreadLimit& t, const py::args&) { t.control.reset(); });
  m.def("thread_limit", [](int threads) {
    pipeline::check_option("threads", threads);
    auto t = std::make_unique<ThreadLimit>();
    t->threads = threads;
    return t;
  });
}

// mlfe._mlfe.Hierarchy: a built or loaded approximation.
void bind_hierarchy(py::module_& m) {
  py::class_<PyBuilt>(m, "Hierarchy")
      .def_property_readonly("dim", [](const PyBuilt& b) { return b.built->dim(); })
      .def_property_readonly("levels", [](const PyBuilt& b) { return b.built->levels(); })
      .def_property_readonly("vertex_count", [](const PyBuilt& b) { return b.built->vertices(); })
      .def_property_readonly("leaf_count", [](const PyBuilt& b) { return b.built->leaves(); })
      .def_property_readonly("stop_reason", [](const PyBuilt& b) { return b.built->stop_reason(); })
      .def_property_readonly("surface_driven", [](const PyBuilt& b) { return b.built->surface_driven; })
      .def_property_readonly("memory_limited", [](const PyBuilt& b) { return b.built->memory_limited(); })
      .def_property_readonly("seconds", [](const PyBuilt& b) { return b.built->seconds; })
      .def_property_readonly("source", [](const PyBuilt& b) { return b.source; })
      .def_property_readonly("space", [](const PyBuilt& b) { return b.built->space; })
      .def_property_readonly(
          "value_range",
          [](const PyBuilt& b) { return py::make_tuple(b.built->value_min, b.built->value_max); })
      .def_property_readonly("transform",
                             [](const PyBuilt& b) {
                               const auto& t = b.built->transform;
                               return py::make_tuple(t.spacing, t.origin, t.direction);
                             })
      .def_property_readonly("has_volume", [](const PyBuilt& b) { return bool(b.grid); })
      .def_property_readonly("file_info", [](const PyBuilt& b) { return to_python(b.file_info); })
      .def_property_readonly("build_record",
                             [](const PyBuilt& b) { return to_python(build_record(*b.built)); })
      .def_property_readonly("positions", [](const PyBuilt& b) { return physical_positions(*b.built); })
      .def_property_readonly("cells", [](const PyBuilt& b) { return leaf_cells(*b.built); })
      .def_property_readonly("vertex_levels", [](const PyBuilt& b) { return vertex_levels(*b.built); })
      .def_property_readonly("errors",
                             [](const PyBuilt& b) {
                               py::dict d;
                               if (b.built->iterations().empty()) return d;  // u not solved
                               const auto& last = b.built->iterations().back();
                               d["rms"] = last.rms_error;
                               d["rms_percent"] = last.rms_percent;
                               d["l2"] = last.l2_error;
                               d["psnr_db"] = last.psnr_db;
                               return d;
                             })
      .def_property_readonly(
          "report",
          [](const PyBuilt& b) { return to_python(build_report(b.source, b.grid.get(), *b.built)); })
      .def_property_readonly(
          "values",
          [](const PyBuilt& b) {
            const auto& v = b.built->values();
            auto a = view<double>(b.built, v.data(), {py::ssize_t(v.size())}, {py::ssize_t(sizeof(double))});
            py::detail::array_proxy(a.ptr())->flags &= ~py::detail::npy_api::NPY_ARRAY_WRITEABLE_;
            return a;
          })
      .def("extract",
           [](const PyBuilt& b, const std::vector<double>& iso, const py::object& progress,
              const py::kwargs& kwargs) {
             Options kw(kwargs);
             AssetOptions o = asset_options(kw);
             kw.finish();
             o.iso = iso;
             Surfaces s = with_progress(progress, [&](const Progress& p) {
               o.progress = p;
               return extract(*b.built, o, b.grid.get());
             });
             AssetFile a;
             a.extras = {{"input", b.source},
                         {"tool", std::string("mlfe ") + MLFE_VERSION + " (python)"},
                         {"iso_values", s.iso_values},
                         {"normals", pipeline::enum_name(s.normals)}};
             a.surfaces = std::move(s.surfaces);
             a.space = b.built->space;
             const auto& sp = b.built->transform.spacing;
             return make_mesh(
                 std::move(a),
                 (b.built->dim() == 2 ? std::min(sp[0], sp[1]) : std::min({sp[0], sp[1], sp[2]})) / 10.0);
           })
      .def("write",
           [](const PyBuilt& b, const std::string& path, const std::vector<double>& iso,
              const py::object& progress, const py::kwargs& kwargs) {
             Options kw(kwargs);
             AssetOptions o = asset_options(kw);
             kw.finish();
             o.iso = iso;
             const nlohmann::json prov = {{"input", b.source},
                                          {"tool", std::string("mlfe ") + MLFE_VERSION + " (python)"}};
             return to_python(with_progress(progress, [&](const Progress& p) {
               o.progress = p;
               return write_assets(path, *b.built, o, prov, b.grid.get());
             }));
           })
      .def("save", [](const PyBuilt& b, const std::string& path) {
        check_output_path(path, {".mlfeh"});
        std::string warning;
        {
          py::gil_scoped_release release;
          warning = write_built(path, *b.built, {{"input", b.source}});
        }
        if (!warning.empty()) PyErr_WarnEx(PyExc_UserWarning, warning.c_str(), 1);
      });
}

// The module functions: the pipeline calls and the comparisons.
void bind_calls(py::module_& m) {
  m.def("render",
        [](const PyBuilt& b, const py::object& out, const py::object& progress, const py::kwargs& kwargs) {
          Options kw(kwargs);
          pipeline::RenderFileOptions o = render_options(kw);
          kw.finish();
          o.keep_images = true;
          const std::string path = out.is_none() ? "" : fspath(out);
          pipeline::RenderResult r = with_progress(progress, [&](const Progress& p) {
            o.progress = p;
            return path.empty() ? pipeline::render_images(*b.built, o, b.grid.get(), b.source)
                                : pipeline::render(*b.built, path, o, b.grid.get(), b.source);
          });
          return render_result(std::move(r));
        });
  // A .vtu/.msh mesh rendered as it is (pipeline::render(TetMesh)); `grid` names the array.
  m.def("render_mesh", [](const std::string& mesh_path, const py::object& out, const py::object& progress,
                          const py::kwargs& kwargs) {
    Options kw(kwargs);
    TetMeshReadOptions read;
    kw.get("grid", read.array_name);
    pipeline::RenderFileOptions o = render_options(kw);
    kw.finish();
    o.keep_images = true;
    const std::string path = out.is_none() ? "" : fspath(out);
    pipeline::RenderResult r = with_progress(progress, [&](const Progress& p) {
      o.progress = p;
      const TetMesh mesh = read_tet_mesh(mesh_path, read);
      return path.empty() ? pipeline::render_images(mesh, o) : pipeline::render(mesh, path, o);
    });
    return render_result(std::move(r));
  });
  m.def("info", [](const std::string& path, bool labels, const std::string& label_table) {
    pipeline::InfoOptions o;
    o.labels = labels;
    o.label_table = label_table;
    nlohmann::json j;
    {
      py::gil_scoped_release release;
      j = pipeline::info(path, o).to_json();
    }
    return to_python(j);
  });
  m.def("export_hierarchy",
        [](const std::string& input, const std::string& output, int level, const py::object& progress) {
          pipeline::ExportOptions o;
          o.level = level;
          const pipeline::ExportResult r = with_progress(progress, [&](const Progress& p) {
            o.progress = p;
            return pipeline::export_hierarchy(input, output, o);
          });
          py::dict d;
          d["mesh"] = r.mesh;
          d["elements"] = r.elements;
          d["vertices"] = r.vertices;
          d["level"] = r.level;
          d["dims"] = r.dims;
          d["seconds"] = r.resample_seconds;
          d["written"] = r.written;
          return d;
        });

  m.def("compare_files", [](const std::string& expected, const std::string& actual, const py::kwargs& kw) {
    const CompareOptions o = compare_options(kw);
    CompareResult r;
    {
      py::gil_scoped_release release;
      r = compare_files(expected, actual, o);
    }
    return compare_result(r);
  });
  // A Mesh against a Mesh or a mesh file (compare_assets).
  m.def("compare_meshes", [](const py::object& expected, const py::object& actual, const py::kwargs& kw) {
    const CompareOptions o = compare_options(kw);
    AssetFile e = compared_asset(expected), a = compared_asset(actual);
    CompareResult r;
    {
      py::gil_scoped_release release;
      r = compare_assets(std::move(e), std::move(a), o);
    }
    return compare_result(r);
  });

  m.def("read_image", [](const std::string& path) {
    std::shared_ptr<Image> img;
    {
      py::gil_scoped_release release;
      img = std::make_shared<Image>(read_image(path));
    }
    py::dict channels, types;
    const auto s = py::ssize_t(sizeof(float));
    for (const auto& c : img->channels) {
      channels[py::str(c.name)] =
          view<float>(img, c.values.data(), {img->height, img->width}, {s * img->width, s});
      types[py::str(c.name)] = c.type;
    }
    return py::make_tuple(img->format, channels, types, img->attributes);
  });

  m.def("build", &build_py, py::arg("volume"), py::kw_only(), py::arg("iso") = py::none(),
        py::arg("spacing") = py::none(), py::arg("origin") = py::none(), py::arg("direction") = py::none(),
        py::arg("space") = "", py::arg("progress") = py::none());
  m.def("convert", &convert_py, py::arg("volume"), py::arg("out"), py::kw_only(), py::arg("iso") = py::none(),
        py::arg("spacing") = py::none(), py::arg("origin") = py::none(), py::arg("direction") = py::none(),
        py::arg("space") = "", py::arg("hierarchy") = py::none(), py::arg("report") = py::none(),
        py::arg("preview") = py::none(), py::arg("progress") = py::none());
}

}  // namespace
}  // namespace mlfe::python

PYBIND11_MODULE(_mlfe, m) {
  using namespace mlfe;
  using namespace mlfe::python;
  m.doc() =
      "The compiled core of the mlfe package; use the package `mlfe`, which documents and checks its "
      "arguments.";
  m.attr("__version__") = MLFE_VERSION;
  m.attr("asset_extensions") = py::tuple(py::cast(kAssetExtensions));  // for mlfe.batch's checks
  static PyObject* const error = py::register_exception<Error>(m, "Error", PyExc_ValueError).ptr();
  // Registered after Error (pybind11 tries the later translators first): messages that name
  // options name them by their keywords, from the library's table.
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      std::rethrow_exception(p);
    } catch (const pipeline::OptionMessage& e) {
      PyErr_SetString(error, e.spelled(pipeline::Spelling::kPython).c_str());
    }
  });
  py::register_exception<Cancelled>(m, "Cancelled", m.attr("Error"));

  m.def("read_volume", &read_volume_py, py::arg("path"));
  // mlfe.render's keywords and their documentation, from the library's table.
  m.def("render_fields", [] {
    py::list fields;
    for (const auto& f : pipeline::render_fields()) {
      const std::string values = f.spec.values();
      const bool clears = std::string(f.spec.flag).rfind("--no-", 0) == 0;
      fields.append(
          py::make_tuple(f.spec.spelled(pipeline::Spelling::kPython),
                         (clears ? "False: " : "") + f.help + (values.empty() ? "" : " (" + values + ")")));
    }
    return fields;
  });
  m.def("load", &load_py, py::arg("path"));
  // mlfe.batch's record of a scan: the files its read opens.
  m.def("input_files", [](const std::string& path) { return input_files(path); });
  m.def("check_convert_keywords", &check_convert_keywords, py::arg("iso"), py::arg("hierarchy"));
  bind_thread_limit(m);
  // mlfe.batch's scans in a folder: the endings of the table of volume formats.
  m.def("scan_extensions", [] { return scan_extensions(); });

  bind_mesh(m);
  bind_hierarchy(m);
  bind_calls(m);
  bind_bricks(m);
}
