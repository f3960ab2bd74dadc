// Uses the installed package: refines a box with mlfe::core and checks it tiles the box, then
// converts a volume to an asset with mlfe::pipeline (the caller validates the .glb), renders the
// hierarchy it kept twice (a file and in memory) and compares the images with
// mlfe::pipeline::compare. Writes OUT.glb, OUT.mlfeh, OUT.exr and OUT_again.exr.
// Usage: mlfe_consumer VOLUME OUT.glb
#include <mlfe/core/base/error.h>
#include <mlfe/core/mesh/hierarchy.h>
#include <mlfe/pipeline.h>
#include <mlfe/version.h>

#include <cmath>
#include <cstdio>
#include <string>
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
  // Render the kept hierarchy and compare two renders of it: equal images.
  const std::string stem = std::string(argv[2]).substr(0, std::string(argv[2]).rfind('.'));
  try {
    mlfe::pipeline::ConvertFileOptions c;
    c.asset.iso = {1.5};
    c.hierarchy = stem + ".mlfeh";
    mlfe::pipeline::convert(argv[1], stem + "_hier.glb", c);
    mlfe::pipeline::RenderFileOptions ro;
    ro.size = {64, 48};
    ro.keep_images = true;
    double last = -1;
    ro.progress = [&last](double f, const std::string&) {
      const bool ordered = f >= last;
      last = f;
      return ordered;
    };
    // Each call reports fractions from 0 up to 1 (a returned false would cancel it).
    const mlfe::pipeline::RenderResult a = mlfe::pipeline::render(stem + ".mlfeh", stem + ".exr", ro);
    const bool first_done = last == 1.0;
    last = -1;
    const mlfe::pipeline::RenderResult b = mlfe::pipeline::render(a.built, stem + "_memory.exr", ro);
    last = -1;
    mlfe::pipeline::render(stem + ".mlfeh", stem + "_again.exr", ro);
    const mlfe::CompareResult same = mlfe::pipeline::compare(stem + ".exr", stem + "_again.exr");
    const mlfe::CompareResult other = mlfe::pipeline::compare(stem + ".exr", argv[2]);
    std::printf("consumer: %dx%d image of %zu tetrahedra, compare: %s, against the asset: %s\n",
                a.frames.at(0).width, a.frames.at(0).height, a.tetrahedra,
                same.equal() ? "equal" : "different", other.kind.c_str());
    if (!first_done || last != 1.0 || !same.equal() || other.equal() ||
        b.frames.at(0).image.rgba != a.frames.at(0).image.rgba)
      return 1;
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
