// The option vocabulary of mlfe::pipeline (include/mlfe/pipeline.h): one parse function per
// option type and one name table per enum, for the command line, the Python module and the
// provenance written into files.
#include <fmt/format.h>
#include <mlfe/core/base/check.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/base/usage_error.h>
#include <mlfe/core/render/transfer_function.h>
#include <mlfe/pipeline.h>

#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <sstream>
#include <type_traits>

namespace mlfe {

Progress CancelToken::progress(Progress inner) const {
  return [flag = flag_, inner = std::move(inner)](double fraction, const std::string& stage) {
    if (inner && !inner(fraction, stage)) return false;
    return !flag->load();
  };
}

namespace pipeline {

std::vector<double> parse_values(const std::string& text, const std::string& option) {
  std::vector<double> out;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) {
    // strtod, not stod: stod refuses a value below the normal doubles (1e-320), a finite number.
    char* end = nullptr;
    const double v = std::strtod(item.c_str(), &end);
    if (item.empty() || end != item.c_str() + item.size() || !std::isfinite(v))
      throw OptionError(fmt::format("{}: not a finite number: '{}'", option_ref(option), item));
    out.push_back(v);
  }
  return out;
}

MemoryBudget parse_memory_budget(const std::string& text, const std::string& option) {
  std::string t = text;
  MemoryBudget m;
  m.percent_of_ram = false;
  if (!t.empty()) {
    const char c = static_cast<char>(std::toupper(static_cast<unsigned char>(t.back())));
    if (c == '%') m.percent_of_ram = true;
    if (c == 'K') m.unit_power = 1;
    if (c == 'M') m.unit_power = 2;
    if (c == 'G') m.unit_power = 3;
    if (m.percent_of_ram || m.unit_power > 0) t.pop_back();
  }
  std::vector<double> v;
  try {
    v = parse_values(t, option);
  } catch (const UsageError&) {
    v.clear();
  }
  if (v.size() != 1 || v[0] < 0 || (m.percent_of_ram && v[0] > 100))
    throw OptionError(option_ref(option) +
                      ": expected a percentage of RAM (50%), bytes with K/M/G (6G), or 0; got '" + text +
                      "'");
  m.amount = v[0];
  return m;
}

RmsTarget parse_rms(const std::string& text, const std::string& option) {
  std::string r = text;
  const bool percent = !r.empty() && r.back() == '%';
  if (percent) r.pop_back();
  std::vector<double> v;
  try {
    v = parse_values(r, option);
  } catch (const UsageError&) {
    v.clear();
  }
  if (v.size() != 1 || v[0] <= 0)
    throw OptionError(option_ref(option) + ": expected one positive value, e.g. 0.5% or 2.0");
  return RmsTarget{v[0], percent};
}

double parse_percent(const std::string& text, const std::string& option) {
  std::string s = text;
  if (!s.empty() && s.back() == '%') s.pop_back();
  try {
    std::size_t used = 0;
    const double v = std::stod(s, &used);
    if (used == s.size() && v >= 0 && std::isfinite(v)) return v;
  } catch (const std::exception&) {
  }
  throw OptionError(option_ref(option) + ": expected a percentage such as 2% (got '" + text + "')");
}

std::array<double, 3> parse_vector3(const std::string& text, const std::string& option) {
  const auto v = parse_values(text, option);
  if (v.size() != 3) throw OptionError(option_ref(option) + ": expected x,y,z, got '" + text + "'");
  return {v[0], v[1], v[2]};
}

std::array<int, 2> parse_image_size(const std::string& text, const std::string& option) {
  int w = 0, h = 0;
  char x = 0, rest = 0;
  if (std::sscanf(text.c_str(), "%d%c%d%c", &w, &x, &h, &rest) != 3 || (x != 'x' && x != 'X') || w < 1 ||
      h < 1 || w > 16384 || h > 16384)
    throw OptionError(option_ref(option) + ": expected WxH (1..16384), got '" + text + "'");
  return {w, h};
}

template <>
const std::vector<EnumName<Norm>>& enum_names<Norm>() {
  static const std::vector<EnumName<Norm>> t = {{Norm::kL2, "l2"}, {Norm::kH1, "h1"}};
  return t;
}
template <>
const std::vector<EnumName<Preconditioner>>& enum_names<Preconditioner>() {
  static const std::vector<EnumName<Preconditioner>> t = {{Preconditioner::kAuto, "auto"},
                                                          {Preconditioner::kBpx, "bpx"},
                                                          {Preconditioner::kJacobi, "jacobi"},
                                                          {Preconditioner::kNone, "none"}};
  return t;
}
template <>
const std::vector<EnumName<Simplifier>>& enum_names<Simplifier>() {
  // core/simplify names its kinds; a new one appears here without an edit.
  static const std::vector<EnumName<Simplifier>> t = [] {
    std::vector<EnumName<Simplifier>> names;
    for (const auto& [kind, name] : simplifier_names()) names.push_back({kind, name});
    return names;
  }();
  return t;
}
template <>
const std::vector<EnumName<VertexPlacement>>& enum_names<VertexPlacement>() {
  static const std::vector<EnumName<VertexPlacement>> t = {{VertexPlacement::kAuto, "auto"},
                                                           {VertexPlacement::kInput, "input"},
                                                           {VertexPlacement::kOptimal, "optimal"}};
  return t;
}
template <>
const std::vector<EnumName<Normals>>& enum_names<Normals>() {
  static const std::vector<EnumName<Normals>> t = {
      {Normals::kAuto, "auto"}, {Normals::kGradient, "gradient"}, {Normals::kSurface, "surface"}};
  return t;
}
template <>
const std::vector<EnumName<SurfaceSource>>& enum_names<SurfaceSource>() {
  static const std::vector<EnumName<SurfaceSource>> t = {{SurfaceSource::kAuto, "auto"},
                                                         {SurfaceSource::kSamples, "samples"},
                                                         {SurfaceSource::kHierarchy, "hierarchy"}};
  return t;
}
template <>
const std::vector<EnumName<Projection>>& enum_names<Projection>() {
  static const std::vector<EnumName<Projection>> t = {{Projection::kOrtho, "ortho"},
                                                      {Projection::kPerspective, "perspective"}};
  return t;
}
template <>
const std::vector<EnumName<RayAccumulator::Rule>>& enum_names<RayAccumulator::Rule>() {
  static const std::vector<EnumName<RayAccumulator::Rule>> t = {
      {RayAccumulator::Rule::kPreIntegrated, "preintegrated"},
      {RayAccumulator::Rule::kExact, "exact"},
      {RayAccumulator::Rule::kTrapezoid, "trapezoid"}};
  return t;
}

namespace {

// `text` is none of the values of the row `name`, which has choices.
OptionError not_a_choice(const std::string& name, const std::string& text) {
  return OptionError(
      fmt::format("{}: expected {}; got '{}'", option_ref(name), option_spec(name).values(), text));
}

}  // namespace

template <class E>
E parse_enum(const std::string& text, const std::string& option) {
  for (const auto& e : enum_names<E>())
    if (text == e.name) return e.value;
  throw not_a_choice(option, text);
}

template <class E>
const char* enum_name(E value) {
  for (const auto& e : enum_names<E>())
    if (e.value == value) return e.name;
  throw Error(fmt::format("no name for value {} of an option enum", static_cast<int>(value)));
}

template <class E>
std::vector<std::string> enum_name_list() {
  std::vector<std::string> names;
  for (const auto& e : enum_names<E>()) names.emplace_back(e.name);
  return names;
}

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr char kMark = '\x1f';  // around an option's name in a message (option_ref)

OptionSpec choice_option(const char* name, const char* flag, std::vector<std::string> (*choices)(),
                         const char* keyword = nullptr) {
  OptionSpec o{name, flag};
  o.choices = choices;
  o.keyword = keyword;
  return o;
}

template <class E>
OptionSpec enum_option(const char* name, const char* flag) {
  return choice_option(name, flag, &enum_name_list<E>);
}

std::vector<std::string> space_names() { return {"ras", "lps"}; }
std::vector<std::string> endian_names() { return {"little", "big"}; }
std::vector<std::string> raw_type_names() {
  std::vector<std::string> names;
  for (ScalarType t : {ScalarType::U8, ScalarType::I8, ScalarType::U16, ScalarType::I16, ScalarType::U32,
                       ScalarType::I32, ScalarType::F32, ScalarType::F64})
    names.emplace_back(scalar_type_name(t));
  return names;
}

std::string lower(std::string text) {
  for (char& c : text) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return text;
}

// A field of O at member m with the row `spec`; an enum member is reached by its names, which
// are the row's choices.
template <class O, class M>
OptionField<O> field(OptionSpec spec, M O::*m, std::string help, bool show_default = false) {
  if constexpr (std::is_enum_v<M>) {
    spec.choices = &enum_name_list<M>;
    const char* name = spec.name;
    EnumMember<O> e{[m, name](O& o, const std::string& text) { o.*m = parse_enum<M>(text, name); },
                    [m](const O& o) { return std::string(enum_name(o.*m)); }};
    return {spec, std::move(help), show_default, e};
  } else {
    return {spec, std::move(help), show_default, m};
  }
}

constexpr bool kShowDefault = true;

std::string preset_list() {
  std::string presets;
  for (const auto& n : transfer_function_presets()) presets += (presets.empty() ? "" : ", ") + n;
  return presets;
}

void check_image_size(const std::string& name, const std::array<int, 2>& size) {
  for (int s : size)
    if (s < 1 || s > 16384)
      throw OptionError(
          fmt::format("{}: expected WxH (1..16384), got {}x{}", option_ref(name), size[0], size[1]));
}

}  // namespace

const std::vector<OptionField<RenderFileOptions>>& render_fields() {
  using R = RenderFileOptions;
  static const std::vector<OptionField<R>> t = {
      field({"tf", "--tf"}, &R::tf,
            "transfer function: a preset (" + preset_list() + ") or a ParaView colour map .json",
            kShowDefault),
      field(
          {"tf_unit", "--tf-unit", 0, kInf}, &R::tf_unit,
          "length (mm) the opacities refer to (0: one voxel for presets, a mesh's fine edge for presets on a "
          ".vtu/.msh, 1 for ParaView files)"),
      field({"camera", "--camera"}, &R::camera, "projection", kShowDefault),
      field({"azimuth", "--azimuth"}, &R::azimuth, "degrees about +z (0: looking along +y)"),
      field({"elevation", "--elevation", -90, 90}, &R::elevation, "degrees above the horizontal plane"),
      field({"position", "--position"}, &R::position,
            "camera position x,y,z (physical frame; replaces the orbit)"),
      field({"target", "--target"}, &R::target, "point looked at, x,y,z (default: the volume's centre)"),
      field({"up", "--up"}, &R::up, "up direction x,y,z (default 0,0,1)"),
      field({"size", "--size"}, &R::size, "image size WxH", kShowDefault),
      field({"level", "--level", -1, 40}, &R::level,
            "render the approximation on this hierarchy level (-1: finest); a .mlfeh file is read only up to "
            "it"),
      field({"reference", "--reference"}, &R::reference,
            "ray-cast the original voxels instead (volume input)"),
      field(
          {"integration", "--integration"}, &R::integration,
          "segment integration: pre-integrated with the tabulated mean transmittance, with the exact one, or "
          "the trapezoid rule",
          kShowDefault),
      field({"shading", "--shading"}, &R::shading, "shade with the per-tetrahedron gradient (headlight)"),
      field({"skip_empty", "--no-skip"}, &R::skip_empty, "no empty-space skipping"),
      field({"png", "--png"}, &R::png, "also write an sRGB PNG preview over the background"),
      field({"frames", "--frames", 1, 3600}, &R::frames,
            "turntable: this many frames around +z, numbered files"),
      field({"background", "--background", 0, 1}, &R::background, "PNG background, linear r,g,b in [0,1]",
            kShowDefault),
      field({"stop_opacity", "--stop-opacity", 0, 1}, &R::stop_opacity, "early ray termination",
            kShowDefault),
      field({"z_opacity", "--z-opacity", 0, 1}, &R::z_opacity,
            "Z is where the accumulated opacity reaches this", kShowDefault),
  };
  return t;
}

template <class O>
void set_option_text(const OptionField<O>& f, O& o, const std::string& text) {
  std::visit(
      [&](const auto& m) {
        using M = std::decay_t<decltype(m)>;
        if constexpr (std::is_same_v<M, EnumMember<O>>) {
          m.set(o, text);
        } else if constexpr (std::is_same_v<M, std::string O::*>) {
          o.*m = text;
        } else if constexpr (std::is_same_v<M, std::array<int, 2> O::*>) {
          o.*m = parse_image_size(text, f.spec.name);
        } else if constexpr (std::is_same_v<M, std::array<double, 3> O::*> ||
                             std::is_same_v<M, std::optional<std::array<double, 3>> O::*>) {
          o.*m = parse_vector3(text, f.spec.name);
        } else {
          MLFE_CHECK_MSG(false, f.spec.name);
        }
      },
      f.member);
}

template <class O>
std::string option_text(const OptionField<O>& f, const O& o) {
  const auto join = [](const auto& values, const char* separator) {
    std::string text;
    for (const auto& v : values) text += (text.empty() ? "" : separator) + fmt::format("{}", v);
    return text;
  };
  return std::visit(
      [&](const auto& m) -> std::string {
        using M = std::decay_t<decltype(m)>;
        if constexpr (std::is_same_v<M, EnumMember<O>>) {
          return m.get(o);
        } else if constexpr (std::is_same_v<M, std::array<int, 2> O::*>) {
          return join(o.*m, "x");
        } else if constexpr (std::is_same_v<M, std::array<double, 3> O::*>) {
          return join(o.*m, ",");
        } else if constexpr (std::is_same_v<M, std::optional<std::array<double, 3>> O::*>) {
          return o.*m ? join(*(o.*m), ",") : std::string();
        } else {
          return fmt::format("{}", o.*m);
        }
      },
      f.member);
}

template <class O>
void check_fields(const std::vector<OptionField<O>>& fields, const O& o) {
  for (const OptionField<O>& f : fields)
    std::visit(
        [&](const auto& m) {
          using M = std::decay_t<decltype(m)>;
          if constexpr (std::is_same_v<M, int O::*> || std::is_same_v<M, double O::*>)
            check_option(f.spec.name, o.*m);
          else if constexpr (std::is_same_v<M, std::array<int, 2> O::*>)
            check_image_size(f.spec.name, o.*m);
          else if constexpr (std::is_same_v<M, std::array<double, 3> O::*>)
            for (double c : o.*m) check_option(f.spec.name, c);  // each component in the row's range
        },
        f.member);
}

template void set_option_text(const OptionField<RenderFileOptions>&, RenderFileOptions&, const std::string&);
template std::string option_text(const OptionField<RenderFileOptions>&, const RenderFileOptions&);
template void check_fields(const std::vector<OptionField<RenderFileOptions>>&, const RenderFileOptions&);

const std::vector<OptionSpec>& option_table() {
  static const std::vector<OptionSpec> t = [] {
    std::vector<OptionSpec> rows = {
        // BuildOptions
        {"rms", "--rms"},
        {"threshold", "--threshold", 0, kInf},
        {"max_vertices", "--max-vertices"},
        {"max_level", "--max-level", 0, 40},
        {"start_level", "--start-level", -1, 12},
        enum_option<Norm>("norm", "--norm"),
        enum_option<Preconditioner>("preconditioner", "--preconditioner"),
        {"surface_tolerance", "--surface-tolerance", 0, kInf, true},
        {"max_sample_error", "--max-error", 0, kInf, false, false, "max_error"},
        {"max_memory", "--max-memory"},
        // AssetOptions
        {"iso", "--iso"},
        {"tolerance", "--tolerance", 0, kInf},
        {"lod", "--lod", 0, 8},
        {"simplify", "--simplify", 0, kInf},
        {"ratio", "--ratio", 0, 1},
        enum_option<Simplifier>("simplifier", "--simplifier"),
        enum_option<VertexPlacement>("placement", "--placement"),
        {"snap", "--snap", 0, 8},
        {"min_component", "--min-component"},
        enum_option<Normals>("normals", "--normals"),
        {"bricks", "--bricks", -1, 1 << 20},
        enum_option<SurfaceSource>("surface", "--surface"),
        // LabelOptions
        {"labels", "--labels"},
        {"label_table", "--label-table"},
        {"smoothing_iterations", "--smooth-iterations", 0, 1000, false, false, "smooth_iterations"},
        {"max_offset", "--max-offset", 0, kInf},
        // BuildFileOptions, ConvertFileOptions, IsoOptions
        {"max_error", "--max-error", 0, kInf},
        {"psnr", "--psnr", 0, kInf},
        {"quantization_share", "--quantization-share", 0, 1},
        {"output", "--output", -kInf, kInf, false, false, "out"},
        {"report", "--report"},
        {"hierarchy", "--hierarchy"},
        {"render", "--render"},
        {"preview", "--preview"},
        {"volume", "--volume"},
        // VolumeReadOptions
        choice_option("space", "--space", &space_names),
        choice_option("raw_dtype", "--raw-type", &raw_type_names, "raw_type"),
        choice_option("raw_endian", "--raw-endian", &endian_names),
        {"raw_offset", "--raw-offset", 0, kInf},
        {"zarr_level", "--zarr-level", 0, kInf},
        {"nan_as", "--nan-as"},
        // CompareOptions (tolerance is AssetOptions')
        {"count_tolerance", "--count-tolerance"},
        {"mean_tolerance", "--mean-tolerance", 0, kInf},
        {"normal_angle_deg", "--normal-angle", 0, kInf, false, false, "normal_angle"},
        {"image_max", "--image-max", 0, kInf},
        {"min_psnr", "--psnr", 0, kInf, false, false, "psnr"},
        {"value_max", "--value-max", 0, kInf},
        {"value_rms", "--value-rms", 0, kInf},
        {"number_tolerance", "--number-tolerance", 0, kInf},
        // The command line's own (checked there with check_option)
        {"threads", "--threads", 0, kInf},
    };
    // RenderFileOptions (level is AssetOptions' too)
    for (const auto& f : render_fields()) rows.push_back(f.spec);
    return rows;
  }();
  return t;
}

const OptionSpec& option_spec(const std::string& name) {
  for (const OptionSpec& o : option_table())
    if (name == o.name) return o;
  MLFE_CHECK_MSG(false, name.c_str());
  std::abort();
}

const OptionSpec* option_by_flag(const std::string& flag) {
  for (const OptionSpec& o : option_table())
    if (flag == o.flag) return &o;
  return nullptr;
}

const char* OptionSpec::spelled(Spelling s) const {
  switch (s) {
    case Spelling::kCommandLine:
      return flag;
    case Spelling::kPython:
      return keyword ? keyword : name;
    case Spelling::kLibrary:
      break;
  }
  return name;
}

std::string OptionSpec::values() const {
  if (choices) {
    std::string list;
    for (const std::string& c : choices()) list += (list.empty() ? "" : ", ") + c;
    return "one of " + list;
  }
  if (min > -kInf && max < kInf) {
    if (!min_excluded && !max_excluded) return fmt::format("{}..{}", min, max);
    return fmt::format("a value in {}{}, {}{}", min_excluded ? "(" : "[", min, max, max_excluded ? ")" : "]");
  }
  if (min > -kInf) return fmt::format("a finite value {} {}", min_excluded ? ">" : ">=", min);
  return "";
}

std::string option_ref(const std::string& name) {
  return kMark + std::string(option_spec(name).name) + kMark;
}

std::string OptionError::spell_marked(const std::string& marked, Spelling s) {
  std::string out;
  std::size_t at = 0;
  for (std::size_t open = marked.find(kMark); open != std::string::npos; open = marked.find(kMark, at)) {
    const std::size_t close = marked.find(kMark, open + 1);
    MLFE_CHECK(close != std::string::npos);
    out += marked.substr(at, open - at);
    out += option_spec(marked.substr(open + 1, close - open - 1)).spelled(s);
    at = close + 1;
  }
  return out + marked.substr(at);
}

std::string OptionMessage::spelled(Spelling s) const { return OptionError::spell_marked(marked_, s); }

std::string message(const std::exception& e, Spelling s) {
  if (const auto* m = dynamic_cast<const OptionMessage*>(&e)) return m->spelled(s);
  return e.what();
}

void check_option(const std::string& name, double value) {
  const OptionSpec& o = option_spec(name);
  MLFE_CHECK(!o.choices);
  const bool low_ok = o.min_excluded ? value > o.min : value >= o.min;
  const bool high_ok = o.max_excluded ? value < o.max : value <= o.max;
  if (!(std::isfinite(value) && low_ok && high_ok)) {
    const std::string values = o.values();
    throw OptionError(fmt::format("{}: expected {}, got {}", option_ref(name),
                                  values.empty() ? "a finite number" : values, value));
  }
}

void check_choice(const std::string& name, const std::string& text, bool ignore_case) {
  const OptionSpec& o = option_spec(name);
  MLFE_CHECK(o.choices);
  for (const std::string& c : o.choices())
    if ((ignore_case ? lower(text) : text) == c) return;
  throw not_a_choice(name, text);
}

void check_options(const BuildOptions& o) {
  if (o.rms && !(o.rms->value > 0 && std::isfinite(o.rms->value)))
    throw OptionError(option_ref("rms") + ": expected one positive value, e.g. 0.5% or 2.0");
  check_option("threshold", o.threshold);
  check_option("max_level", o.max_level);
  check_option("start_level", o.start_level);
  check_option("surface_tolerance", o.surface_tolerance);
  if (!(o.max_sample_error < 0)) check_option("max_sample_error", o.max_sample_error);  // < 0: off
}

void check_options(const AssetOptions& o) {
  for (double v : o.iso)
    if (!std::isfinite(v)) throw OptionError(option_ref("iso") + ": iso-values must be finite numbers");
  check_option("tolerance", o.tolerance);
  check_option("lod", o.lod);
  check_option("simplify", o.simplify);
  check_option("ratio", o.ratio);
  check_option("snap", o.snap);
  check_option("level", o.level);
  check_option("bricks", o.bricks);
  if (o.bricks == 1 || (o.bricks > 0 && (o.bricks & (o.bricks - 1)) != 0))
    throw OptionError(fmt::format("{}: expected -1 (auto), 0 or a power of two of at least 2, got {}",
                                  option_ref("bricks"), o.bricks));
}

void check_options(const LabelOptions& o) {
  check_option("simplify", o.simplify);
  check_option("max_offset", o.max_offset);
  check_option("smoothing_iterations", o.smoothing_iterations);
  check_option("tolerance", o.tolerance);
}

void check_options(const RenderFileOptions& o) {
  check_fields(render_fields(), o);
  // The orbit camera has its own target and up; silently dropping them would render another view.
  if (!o.position && (o.target || o.up))
    throw OptionError(option_ref(o.up ? "up" : "target") + ": needs " + option_ref("position"));
  check_options(o.build);
  check_options(o.read);
}

void check_options(const BuildFileOptions& o) {
  if (!(o.max_error < 0)) check_option("max_error", o.max_error);  // < 0: off
  check_option("psnr", o.psnr);
  check_option("quantization_share", o.quantization_share);
  check_options(o.build);
  check_options(o.read);
}

void check_options(const VolumeReadOptions& o) {
  if (!o.space.empty()) check_choice("space", o.space, true);
  // The readers take the raw type's other spellings too (u8, f32, double, ...).
  if (!o.raw_dtype.empty() && !parse_scalar_type(o.raw_dtype)) throw not_a_choice("raw_dtype", o.raw_dtype);
  if (!o.raw_endian.empty()) check_choice("raw_endian", o.raw_endian);
  check_option("raw_offset", static_cast<double>(o.raw_offset));
  check_option("zarr_level", o.zarr_level);
  if (o.nan_as) check_option("nan_as", *o.nan_as);
}

void check_options(const CompareOptions& o) {
  const std::pair<const char*, const std::optional<double>*> bounds[] = {
      {"tolerance", &o.tolerance}, {"mean_tolerance", &o.mean_tolerance}, {"image_max", &o.image_max},
      {"min_psnr", &o.min_psnr},   {"value_max", &o.value_max},           {"value_rms", &o.value_rms}};
  for (const auto& [name, value] : bounds)
    if (*value) check_option(name, **value);
  if (!(o.count_tolerance_percent >= 0 && std::isfinite(o.count_tolerance_percent)))
    throw OptionError(fmt::format("{}: expected a percentage such as 2% (got {})",
                                  option_ref("count_tolerance"), o.count_tolerance_percent));
  check_option("normal_angle_deg", o.normal_angle_deg);
  check_option("number_tolerance", o.number_tolerance);
}

#define MLFE_PIPELINE_ENUM(E)                                                   \
  template E parse_enum<E>(const std::string& text, const std::string& option); \
  template const char* enum_name<E>(E value);                                   \
  template std::vector<std::string> enum_name_list<E>();
MLFE_PIPELINE_ENUM(Norm)
MLFE_PIPELINE_ENUM(Preconditioner)
MLFE_PIPELINE_ENUM(Simplifier)
MLFE_PIPELINE_ENUM(VertexPlacement)
MLFE_PIPELINE_ENUM(Normals)
MLFE_PIPELINE_ENUM(SurfaceSource)
MLFE_PIPELINE_ENUM(Projection)
MLFE_PIPELINE_ENUM(RayAccumulator::Rule)
#undef MLFE_PIPELINE_ENUM

}  // namespace pipeline

const char* to_string(Simplifier s) { return pipeline::enum_name(s); }
const char* to_string(VertexPlacement p) { return pipeline::enum_name(p); }
const char* to_string(Normals n) { return pipeline::enum_name(n); }
const char* to_string(SurfaceSource s) { return pipeline::enum_name(s); }

}  // namespace mlfe
