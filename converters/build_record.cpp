// The build record a hierarchy file keeps in its metadata (key "build"), so that a loaded
// hierarchy tells what its build did: why it stopped, the per-iteration table, the noise and the
// target, the options. Times are left out: a file's bytes depend only on its input and options.
#include <fmt/format.h>
#include <mlfe/core/base/error.h>
#include <mlfe/pipeline.h>

#include <cmath>
#include <limits>

namespace mlfe {
namespace {

// A stored number; JSON has no infinity (a PSNR at RMS 0 is stored as null) nor NaN.
double number(const nlohmann::json& row, const char* key, double missing) {
  const auto it = row.find(key);
  return it != row.end() && it->is_number() ? it->get<double>() : missing;
}

template <class T>
T count(const nlohmann::json& row, const char* key) {
  const auto it = row.find(key);
  return it != row.end() && it->is_number_integer() ? it->get<T>() : T(0);
}

nlohmann::json iteration_row(const IterationStats& s) {
  return {{"iteration", s.iteration},    {"level", s.level},
          {"vertices", s.vertices},      {"elements", s.elements},
          {"marked", s.marked},          {"l2_error", s.l2_error},
          {"rms_error", s.rms_error},    {"rms_error_percent", s.rms_percent},
          {"psnr_db", s.psnr_db},        {"cg_iterations", s.cg_iterations},
          {"cg_residual", s.cg_residual}};
}

IterationStats iteration_of(const nlohmann::json& row) {
  IterationStats s;
  s.iteration = count<int>(row, "iteration");
  s.level = count<int>(row, "level");
  s.vertices = count<std::size_t>(row, "vertices");
  s.elements = count<std::size_t>(row, "elements");
  s.marked = count<std::size_t>(row, "marked");
  s.l2_error = number(row, "l2_error", 0);
  s.rms_error = number(row, "rms_error", 0);
  s.rms_percent = number(row, "rms_error_percent", 0);
  s.psnr_db = number(row, "psnr_db", std::numeric_limits<double>::infinity());
  s.cg_iterations = count<int>(row, "cg_iterations");
  s.cg_residual = number(row, "cg_residual", 0);
  return s;
}

template <int D>
void restore(const nlohmann::json& record, Approximation<D>& a) {
  a.stop_reason = record.value("stop_reason", std::string());
  a.memory_limited = record.value("memory_limited", false);
  a.iterations.clear();
  for (const auto& row : record.value("per_iteration", nlohmann::json::array()))
    if (row.is_object()) a.iterations.push_back(iteration_of(row));
  a.surface_passes.clear();
  for (const auto& row : record.value("surface_passes", nlohmann::json::array()))
    if (row.is_object())
      a.surface_passes.push_back({count<std::size_t>(row, "vertices"), count<std::size_t>(row, "elements"),
                                  count<std::size_t>(row, "candidates"), count<std::size_t>(row, "marked"),
                                  0.0});
}

}  // namespace

nlohmann::json build_options_record(const BuildOptions& p, const std::vector<double>& iso_values) {
  nlohmann::json o = {{"threshold", p.threshold},
                      {"max_vertices", p.max_vertices},
                      {"max_level", p.max_level},
                      {"start_level", p.start_level},
                      {"norm", pipeline::enum_name(p.norm)},
                      {"preconditioner", pipeline::enum_name(p.preconditioner)},
                      {"surface_tolerance", p.surface_tolerance},
                      {"check_u", p.check_against_u},
                      {"solve_u", p.solve_u},
                      {"max_memory", p.max_memory.text()},
                      {"iso", iso_values}};
  if (p.rms)
    o["rms"] = p.rms->percent_of_range ? nlohmann::json(fmt::format("{}%", p.rms->value))
                                       : nlohmann::json(p.rms->value);
  if (p.max_sample_error >= 0) o["max_error"] = p.max_sample_error;
  return o;
}

nlohmann::json build_record(const Built& b) {
  nlohmann::json r = {{"stop_reason", b.stop_reason()},
                      {"surface_driven", b.surface_driven},
                      {"memory_limited", b.memory_limited()},
                      {"rms_target", b.target_rms},
                      {"noise_sigma", b.noise_sigma},
                      {"target_from_noise", b.target_from_noise},
                      {"options", b.options}};
  nlohmann::json rows = nlohmann::json::array();
  for (const auto& s : b.iterations()) rows.push_back(iteration_row(s));
  r["per_iteration"] = std::move(rows);
  nlohmann::json passes = nlohmann::json::array();
  for (const auto& s : b.surface_passes())
    passes.push_back({{"vertices", s.vertices},
                      {"elements", s.elements},
                      {"candidates", s.candidates},
                      {"marked", s.marked}});
  r["surface_passes"] = std::move(passes);
  return r;
}

void restore_build_record(const std::string& path, const nlohmann::json& metadata, Built& b) {
  if (!metadata.is_object() || !metadata.contains("build")) return;
  const nlohmann::json& r = metadata["build"];
  try {
    if (!r.is_object()) throw Error("not a JSON object");
    b.surface_driven = r.value("surface_driven", b.surface_driven);
    b.target_rms = number(r, "rms_target", 0);
    b.noise_sigma = number(r, "noise_sigma", 0);
    b.target_from_noise = r.value("target_from_noise", false);
    b.options = r.value("options", nlohmann::json::object());
    std::visit([&r](auto& a) { restore(r, a); }, b.approximation);
  } catch (const std::exception& e) {  // a wrong type (json::type_error) as much as a wrong shape
    throw Error(path + ": the build record in the metadata is malformed (" + e.what() + ")");
  }
}

}  // namespace mlfe
