#include <mlfe/core/base/error.h>
#include <mlfe/formats/safe_read.h>
#include <mlfe/formats/transfer_function_io.h>

#include <nlohmann/json.hpp>

namespace mlfe {
namespace {
// ParaView presets are a few kilobytes; the cap keeps a wrong file from being read whole.
constexpr std::uint64_t kMaxPresetBytes = 64u << 20;
}  // namespace

TransferFunction read_paraview_transfer_function(const std::string& path, double unit_length) {
  auto fail = [&](const std::string& what) { throw Error(path + ": " + what); };
  nlohmann::json j =
      nlohmann::json::parse(read_regular_file(path, kMaxPresetBytes, "a transfer function"), nullptr, false);
  if (j.is_discarded()) fail("not valid JSON");
  if (j.is_array()) {
    if (j.empty()) fail("empty preset array");
    j = j.front();
  }
  if (!j.is_object()) fail("expected a ParaView preset object or an array of them");
  auto numbers = [&](const char* key, std::size_t group) {
    if (!j.contains(key)) fail(std::string("no \"") + key + "\" array");
    const auto& a = j[key];
    if (!a.is_array() || a.empty() || a.size() % group != 0)
      fail(std::string("\"") + key + "\" must be a non-empty array of " + std::to_string(group) + "-tuples");
    std::vector<double> v;
    for (const auto& x : a) {
      if (!x.is_number()) fail(std::string("\"") + key + "\" holds a non-number");
      v.push_back(x.get<double>());
    }
    return v;
  };
  TransferFunction tf;
  tf.unit_length = unit_length;
  tf.name = j.contains("Name") && j["Name"].is_string() ? j["Name"].get<std::string>() : path;
  const auto rgb = numbers("RGBPoints", 4);
  for (std::size_t i = 0; i < rgb.size(); i += 4)
    tf.color.push_back({rgb[i], rgb[i + 1], rgb[i + 2], rgb[i + 3]});
  const auto pts = numbers("Points", 4);
  for (std::size_t i = 0; i < pts.size(); i += 4) {
    if (pts[i + 2] != 0.5 || pts[i + 3] != 0.0)
      fail("opacity point " + std::to_string(i / 4) +
           " has midpoint/sharpness other than 0.5/0 (only linear segments are supported)");
    tf.opacity.push_back({pts[i], pts[i + 1]});
  }
  tf.validate(path);
  return tf;
}

std::string transfer_function_record(const TransferFunction& tf) {
  const nlohmann::json j = {{"name", tf.name},
                            {"RGBPoints", tf.color},
                            {"opacityPoints", tf.opacity},
                            {"opacityUnitLength", tf.unit_length}};
  return j.dump();
}

}  // namespace mlfe
