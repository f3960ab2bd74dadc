// mlfe::pipeline's calls (include/mlfe/pipeline.h): the option vocabulary, progress fractions and
// cancelling. A cancelled call throws pipeline::Cancelled (an mlfe::Error) and leaves no output
// file and no temporary behind, whichever stage it was cancelled in; the calls give the command
// line's bytes.
#include <gtest/gtest.h>
#include <mlfe/core/base/usage_error.h>
#include <mlfe/pipeline.h>

#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "tests/test_meshes.h"
#include "tests/test_paths.h"

namespace fs = std::filesystem;

namespace mlfe {
namespace {

using test::read_bytes;

const std::string kSkull = test::sample_path("ct_skull_64.nrrd");

std::string scratch(const std::string& sub) { return test::scratch_dir("pipeline_calls/" + sub); }

// Files in `dir` (outputs and temporaries alike).
std::vector<std::string> files_in(const std::string& dir) {
  std::vector<std::string> names;
  for (const auto& e : fs::directory_iterator(dir)) names.push_back(e.path().filename().string());
  return names;
}

// A Progress that records every report and returns false at the first report in `stage`
// (never when empty).
struct Recorder {
  std::string cancel_in;
  std::vector<std::pair<double, std::string>> reports;
  pipeline::Progress progress() {
    return [this](double f, const std::string& stage) {
      reports.emplace_back(f, stage);
      return cancel_in.empty() || stage != cancel_in;
    };
  }
  bool saw(const std::string& stage) const {
    for (const auto& r : reports)
      if (r.second == stage) return true;
    return false;
  }
};

void expect_fractions_ordered(const Recorder& r) {
  ASSERT_FALSE(r.reports.empty());
  double last = 0;
  for (const auto& [f, stage] : r.reports) {
    EXPECT_GE(f, last) << stage;
    EXPECT_LE(f, 1.0) << stage;
    last = f;
  }
}

TEST(PipelineVocabulary, SizesPercentagesListsAndEnumsParseOneWay) {
  const MemoryBudget g = pipeline::parse_memory_budget("6G", "max_memory");
  EXPECT_EQ(g.bytes(), std::size_t(6) << 30);
  EXPECT_EQ(pipeline::parse_memory_budget("512m").bytes(), std::size_t(512) << 20);
  EXPECT_TRUE(pipeline::parse_memory_budget("50%").percent_of_ram);
  EXPECT_EQ(pipeline::parse_memory_budget("0").bytes(), 0u);
  const RmsTarget r = pipeline::parse_rms("0.5%");
  EXPECT_TRUE(r.percent_of_range);
  EXPECT_DOUBLE_EQ(r.value, 0.5);
  EXPECT_FALSE(pipeline::parse_rms("2").percent_of_range);
  EXPECT_DOUBLE_EQ(pipeline::parse_percent("2%", "count_tolerance"), 2.0);
  EXPECT_EQ(pipeline::parse_values("80,150", "iso"), (std::vector<double>{80, 150}));
  EXPECT_EQ(pipeline::parse_image_size("640x480"), (std::array<int, 2>{640, 480}));
  EXPECT_EQ(pipeline::parse_enum<Simplifier>("meshopt", "simplifier"), Simplifier::kMeshopt);
  EXPECT_STREQ(pipeline::enum_name(Preconditioner::kJacobi), "jacobi");
  EXPECT_EQ(pipeline::enum_name_list<pipeline::Projection>(),
            (std::vector<std::string>{"ortho", "perspective"}));
  for (const auto& e : pipeline::enum_names<Normals>())
    EXPECT_EQ(pipeline::parse_enum<Normals>(e.name, "normals"), e.value);
  // Bad text names the option as the caller spells it.
  const auto message = [](auto&& f) {
    try {
      f();
    } catch (const UsageError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_EQ(message([] { pipeline::parse_memory_budget("6T", "max_memory"); }).rfind("max_memory:", 0), 0u);
  EXPECT_EQ(message([] { pipeline::parse_rms("-1%", "rms"); }).rfind("rms:", 0), 0u);
  EXPECT_EQ(message([] { pipeline::parse_values("1,x", "iso"); }).rfind("iso:", 0), 0u);
  EXPECT_EQ(message([] { pipeline::parse_vector3("1,2", "up"); }).rfind("up:", 0), 0u);
  EXPECT_EQ(message([] { pipeline::parse_image_size("0x3"); }).rfind("size:", 0), 0u);
  EXPECT_NE(message([] { pipeline::parse_enum<Norm>("l3", "norm"); }).find("l2, h1"), std::string::npos);
}

// One table names every option: the library's messages use its names, and each front end reads
// them in its own spelling.
TEST(PipelineCalls, OptionMessagesInEachFrontEndsSpelling) {
  LabelOptions o;
  o.smoothing_iterations = 1001;
  try {
    pipeline::check_options(o);
    ADD_FAILURE() << "no error";
  } catch (const UsageError& e) {
    EXPECT_STREQ(e.what(), "smoothing_iterations: expected 0..1000, got 1001");
    EXPECT_EQ(pipeline::message(e, pipeline::Spelling::kCommandLine),
              "--smooth-iterations: expected 0..1000, got 1001");
    EXPECT_EQ(pipeline::message(e, pipeline::Spelling::kPython),
              "smooth_iterations: expected 0..1000, got 1001");
  }
  pipeline::RenderFileOptions r;
  r.build.surface_tolerance = 0;
  try {
    pipeline::check_options(r);
    ADD_FAILURE() << "no error";
  } catch (const UsageError& e) {
    EXPECT_EQ(pipeline::message(e, pipeline::Spelling::kCommandLine),
              "--surface-tolerance: expected a finite value > 0, got 0");
  }
  for (const auto& spec : pipeline::option_table()) {
    EXPECT_EQ(&pipeline::option_spec(spec.name), &spec) << spec.name << " is named twice";
    EXPECT_EQ(std::string(spec.flag).rfind("--", 0), 0u) << spec.flag;
  }
  EXPECT_EQ(pipeline::option_spec("quantization_share").values(), "a value in [0, 1)");
  EXPECT_EQ(pipeline::option_spec("norm").values(), "one of l2, h1");
}

TEST(PipelineCalls, ConvertReportsOrderedFractionsAndGivesTheCommandLinesBytes) {
  const std::string dir = scratch("convert");
  Recorder rec;
  pipeline::ConvertFileOptions o;
  o.asset.iso = {1.5, 3.0};
  o.hierarchy = dir + "/api.mlfeh";
  o.progress = rec.progress();
  const pipeline::ConvertFileResult r = pipeline::convert(kSkull, dir + "/api.glb", o);
  expect_fractions_ordered(rec);
  EXPECT_EQ(rec.reports.front().first, 0.0);
  EXPECT_EQ(rec.reports.back().first, 1.0);
  for (const char* stage : {"reading", "building", "extracting", "simplifying", "writing"})
    EXPECT_TRUE(rec.saw(stage)) << stage;
  EXPECT_EQ(r.written, (std::vector<std::string>{dir + "/api.glb", dir + "/api.mlfeh"}));
  const std::string cmd = std::string(MLFE_BINARY) + " convert " + kSkull + " --iso 1.5,3 --quiet -o " + dir +
                          "/cli.glb --hierarchy " + dir + "/cli.mlfeh > /dev/null 2>&1";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
  EXPECT_TRUE(read_bytes(dir + "/api.glb") == read_bytes(dir + "/cli.glb"));
  EXPECT_TRUE(read_bytes(dir + "/api.mlfeh") == read_bytes(dir + "/cli.mlfeh"));
}

TEST(PipelineCalls, CancellingInAnyStageThrowsCancelledAndLeavesNoFile) {
  for (const std::string stage : {"reading", "building", "extracting", "simplifying", "writing"}) {
    const std::string dir = scratch("cancel_" + stage);
    Recorder rec;
    rec.cancel_in = stage;
    pipeline::ConvertFileOptions o;
    o.asset.iso = {1.5};
    o.hierarchy = dir + "/out.mlfeh";
    o.report = dir + "/out.json";
    o.progress = rec.progress();
    EXPECT_THROW(pipeline::convert(kSkull, dir + "/out.glb", o), pipeline::Cancelled) << stage;
    EXPECT_EQ(rec.reports.back().second, stage);
    EXPECT_TRUE(files_in(dir).empty()) << stage << ": " << files_in(dir).front();
  }
}

TEST(PipelineCalls, BuildRenderExportAndIsoCancelCleanly) {
  const std::string dir = scratch("others");
  // Files to start from.
  pipeline::BuildFileOptions b;
  b.build.max_vertices = 3000;
  const pipeline::BuildFileResult built = pipeline::build(kSkull, dir + "/h.mlfeh", b);
  EXPECT_EQ(built.written, std::vector<std::string>{dir + "/h.mlfeh"});
  EXPECT_EQ(built.file.bytes, fs::file_size(dir + "/h.mlfeh"));
  const std::string out = scratch("others_out");

  Recorder rec;
  rec.cancel_in = "writing";
  b.progress = rec.progress();
  EXPECT_THROW(pipeline::build(kSkull, out + "/h.mlfeh", b), Cancelled);
  EXPECT_TRUE(rec.saw("building"));

  pipeline::RenderFileOptions ro;
  ro.size = {32, 32};
  ro.frames = 2;
  ro.png = out + "/r.png";
  rec = Recorder{"writing", {}};
  ro.progress = rec.progress();
  EXPECT_THROW(pipeline::render(dir + "/h.mlfeh", out + "/r.exr", ro), Cancelled);
  EXPECT_TRUE(rec.saw("rendering"));

  pipeline::ExportOptions eo;
  rec = Recorder{"resampling", {}};
  eo.progress = rec.progress();
  EXPECT_THROW(pipeline::export_hierarchy(dir + "/h.mlfeh", out + "/g.nrrd", eo), Cancelled);

  pipeline::IsoOptions io;
  io.asset.iso = {2.5};
  rec = Recorder{"simplifying", {}};
  io.progress = rec.progress();
  EXPECT_THROW(pipeline::iso(dir + "/h.mlfeh", out + "/s.ply", io), Cancelled);
  EXPECT_TRUE(files_in(out).empty()) << files_in(out).front();

  // A token cancelled from elsewhere stops the next call at its first report.
  CancelToken token;
  token.cancel();
  io.progress = token.progress();
  EXPECT_THROW(pipeline::iso(dir + "/h.mlfeh", out + "/s.ply", io), Cancelled);
  EXPECT_TRUE(files_in(out).empty());
}

TEST(PipelineCalls, RenderImagesMatchTheWrittenFramesAndCompareSeesThem) {
  const std::string dir = scratch("render");
  pipeline::BuildFileOptions b;
  b.build.max_vertices = 3000;
  pipeline::build(kSkull, dir + "/h.mlfeh", b);
  pipeline::RenderFileOptions o;
  o.size = {40, 30};
  o.keep_images = true;
  const pipeline::RenderResult r = pipeline::render(dir + "/h.mlfeh", dir + "/a.exr", o);
  ASSERT_EQ(r.frames.size(), 1u);
  EXPECT_EQ(r.frames[0].image.width, 40);
  EXPECT_EQ(r.frames[0].image.rgba.size(), 40u * 30u * 4u);
  EXPECT_GT(r.tetrahedra, 0u);
  const pipeline::RenderResult mem = pipeline::render_images(r.built, o, nullptr, dir + "/h.mlfeh");
  EXPECT_EQ(mem.frames[0].image.rgba, r.frames[0].image.rgba);
  EXPECT_TRUE(mem.written.empty());
  const std::string cmd = std::string(MLFE_BINARY) + " render " + dir + "/h.mlfeh --size 40x30 --quiet -o " +
                          dir + "/b.exr > /dev/null";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
  const CompareResult c = pipeline::compare(dir + "/a.exr", dir + "/b.exr", {}, dir + "/cmp.json");
  EXPECT_TRUE(c.equal()) << c.summary();
  EXPECT_TRUE(fs::exists(dir + "/cmp.json"));
  // Info of what was written.
  const pipeline::InfoResult i = pipeline::info(dir + "/h.mlfeh");
  EXPECT_TRUE(i.hierarchy);
  EXPECT_EQ(i.vertices, r.built.vertices());
  EXPECT_EQ(i.to_json()["format"], "mlfeh");
}

}  // namespace
}  // namespace mlfe
