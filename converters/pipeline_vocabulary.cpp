// The option vocabulary of mlfe::pipeline (include/mlfe/pipeline.h): one parse function per
// option type and one name table per enum, for the command line, the Python module and the
// provenance written into files.
#include <fmt/format.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/base/usage_error.h>
#include <mlfe/pipeline.h>

#include <cctype>
#include <cmath>
#include <cstdio>
#include <sstream>

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
    try {
      std::size_t used = 0;
      const double v = std::stod(item, &used);
      if (used != item.size() || !std::isfinite(v)) throw std::invalid_argument("bad");
      out.push_back(v);
    } catch (const std::exception&) {
      throw UsageError(fmt::format("{}: not a finite number: '{}'", option, item));
    }
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
    throw UsageError(option + ": expected a percentage of RAM (50%), bytes with K/M/G (6G), or 0; got '" +
                     text + "'");
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
    throw UsageError(option + ": expected one positive value, e.g. 0.5% or 2.0");
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
  throw UsageError(option + ": expected a percentage such as 2% (got '" + text + "')");
}

std::array<double, 3> parse_vector3(const std::string& text, const std::string& option) {
  const auto v = parse_values(text, option);
  if (v.size() != 3) throw UsageError(option + ": expected x,y,z, got '" + text + "'");
  return {v[0], v[1], v[2]};
}

std::array<int, 2> parse_image_size(const std::string& text, const std::string& option) {
  int w = 0, h = 0;
  char x = 0, rest = 0;
  if (std::sscanf(text.c_str(), "%d%c%d%c", &w, &x, &h, &rest) != 3 || (x != 'x' && x != 'X') || w < 1 ||
      h < 1 || w > 16384 || h > 16384)
    throw UsageError(option + ": expected WxH (1..16384), got '" + text + "'");
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
  static const std::vector<EnumName<Simplifier>> t = {{Simplifier::kAuto, "auto"},
                                                      {Simplifier::kFast, "fast"},
                                                      {Simplifier::kBounded, "bounded"},
                                                      {Simplifier::kMeshopt, "meshopt"}};
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

template <class E>
E parse_enum(const std::string& text, const std::string& option) {
  for (const auto& e : enum_names<E>())
    if (text == e.name) return e.value;
  std::string choices;
  for (const auto& e : enum_names<E>()) choices += (choices.empty() ? "" : ", ") + std::string(e.name);
  throw UsageError(fmt::format("{}: expected one of {}; got '{}'", option, choices, text));
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
