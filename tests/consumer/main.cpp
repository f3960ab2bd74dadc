// Uses the installed package: refines a box with mlfe::core and checks it tiles the box, then
// converts a volume to an asset with mlfe::pipeline (the caller validates the .glb).
// Usage: mlfe_consumer VOLUME OUT.glb
#include <mlfe/core/error.h>
#include <mlfe/core/hierarchy.h>
#include <mlfe/pipeline.h>
#include <mlfe/version.h>

#include <cmath>
#include <cstdio>
#include <vector>

int main(int argc, char** argv) {
  if (argc != 3) {
    std::fprintf(stderr, "usage: mlfe_consumer VOLUME OUT.glb\n");
    return 2;
  }
  auto h = mlfe::Hierarchy<3>::box({0, 0, 0}, {1, 2, 3});
  for (int i = 0; i < 4; ++i) {
    std::vector<mlfe::ElemId> corner;  // the leaves at corner vertex 0
    for (auto e : h.leaves())
      for (auto v : h.cell(e))
        if (v == mlfe::VertexId(0)) corner.push_back(e);
    h.refine(corner);
  }
  double vol = 0;
  for (auto e : h.leaves()) vol += h.measure(e);
  std::printf("consumer (mlfe %s): %zu leaves, %d levels, volume %.12f\n", MLFE_VERSION, h.leaves().size(),
              h.max_level() + 1, vol);
  if (std::abs(vol - 6.0) > 1e-9 || h.max_level() != 4) return 1;

  mlfe::ConvertOptions options;
  options.asset.iso = {1.5, 3.0};
  try {
    const mlfe::ConvertResult r = mlfe::convert(argv[1], argv[2], options);
    std::printf("consumer: %zu vertices, %zu triangles -> %s\n", r.built.vertices(),
                r.asset["triangles"].get<std::size_t>(), argv[2]);
    if (r.asset["triangles"].get<std::size_t>() == 0) return 1;
  } catch (const mlfe::Error& e) {
    std::fprintf(stderr, "consumer: %s\n", e.what());
    return 1;
  }
  // Bad input is an exception, not an abort.
  try {
    mlfe::Hierarchy<3>::box({0, 0, 0}, {1, 0, 1});
    return 1;
  } catch (const mlfe::Error&) {
  }
  return 0;
}
