// mlfe::pipeline's calls (include/mlfe/pipeline.h): the option vocabulary, progress fractions and
// cancelling. A cancelled call throws pipeline::Cancelled (an mlfe::Error) and leaves no output
// file and no temporary behind, whichever stage it was cancelled in; the calls give the command
// line's bytes.
#include <gtest/gtest.h>
#include <mlfe/core/base/usage_error.h>
#include <mlfe/pipeline.h>

#include <cmath>
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
  EXPECT_EQ(pipeline::option_spec("quantization_share").values(), "0..1");
  EXPECT_EQ(pipeline::option_spec("norm").values(), "one of l2, h1");
}

// The message of the usage error f() throws, as `s` spells options ("no error" when none).
template <class F>
std::string usage_message(F&& f, pipeline::Spelling s) {
  try {
    f();
  } catch (const UsageError& e) {
    return pipeline::message(e, s);
  }
  return "no error";
}

// compare's and the reads' ranges are the library's, as the other options' are: each front end
// gets the one message in its spelling.
TEST(PipelineCalls, CompareAndReadOptionsAreCheckedByTheLibrary) {
  using pipeline::Spelling;
  CompareOptions c;
  c.normal_angle_deg = -1;
  const auto files = [&c] { compare_files(kSkull, kSkull, c); };
  EXPECT_EQ(usage_message(files, Spelling::kCommandLine),
            "--normal-angle: expected a finite value >= 0, got -1");
  EXPECT_EQ(usage_message(files, Spelling::kPython), "normal_angle: expected a finite value >= 0, got -1");
  c = {};
  c.min_psnr = -3;
  EXPECT_EQ(usage_message(files, Spelling::kCommandLine), "--psnr: expected a finite value >= 0, got -3");
  c = {};
  c.count_tolerance_percent = -2;
  EXPECT_EQ(usage_message([&c] { compare_meshes(TriangleMesh{}, TriangleMesh{}, c); }, Spelling::kLibrary),
            "count_tolerance: expected a percentage such as 2% (got -2)");

  pipeline::InfoOptions info;
  info.read.raw_dtype = "int3";
  const auto read = [&info] { pipeline::info(kSkull, info); };
  const std::string types = "one of uint8, int8, uint16, int16, uint32, int32, float32, float64";
  EXPECT_EQ(usage_message(read, Spelling::kCommandLine), "--raw-type: expected " + types + "; got 'int3'");
  EXPECT_EQ(usage_message(read, Spelling::kPython), "raw_type: expected " + types + "; got 'int3'");
  info.read.raw_dtype = "F32";  // the readers' other spellings, in any case
  info.read.space = "LPS";
  EXPECT_EQ(pipeline::info(kSkull, info).space, "LPS");
  VolumeReadOptions r;
  r.raw_endian = "middle";
  EXPECT_EQ(usage_message([&r] { pipeline::check_options(r); }, Spelling::kLibrary),
            "raw_endian: expected one of little, big; got 'middle'");
  r = {};
  r.zarr_level = -1;
  EXPECT_EQ(usage_message([&r] { pipeline::check_options(r); }, Spelling::kCommandLine),
            "--zarr-level: expected a finite value >= 0, got -1");
}

const pipeline::OptionField<pipeline::RenderFileOptions>& render_field(const std::string& name) {
  for (const auto& f : pipeline::render_fields())
    if (name == f.spec.name) return f;
  ADD_FAILURE() << name;
  return pipeline::render_fields().front();
}

// Render's options are one table: each field a row of option_table(), set from the text its
// flag takes and shown as that text, its range checked by the library.
TEST(PipelineCalls, RenderFieldsAreTableRowsThatTheLibraryChecks) {
  for (const auto& f : pipeline::render_fields()) {
    EXPECT_STREQ(pipeline::option_spec(f.spec.name).flag, f.spec.flag);
    EXPECT_FALSE(f.help.empty()) << f.spec.name;
  }
  const pipeline::RenderFileOptions defaults;
  EXPECT_EQ(pipeline::option_text(render_field("background"), defaults), "0,0,0");
  EXPECT_EQ(pipeline::option_text(render_field("size"), defaults), "500x500");
  EXPECT_EQ(pipeline::option_text(render_field("stop_opacity"), defaults), "0.99");
  EXPECT_EQ(pipeline::option_text(render_field("target"), defaults), "");
  EXPECT_EQ(pipeline::option_text(render_field("integration"), defaults), "preintegrated");
  pipeline::RenderFileOptions o;
  for (const auto& [name, text] : std::vector<std::pair<std::string, std::string>>{
           {"size", "64x48"}, {"camera", "perspective"}, {"up", "0,1,0.5"}, {"tf", "bone"}}) {
    pipeline::set_option_text(render_field(name), o, text);
    EXPECT_EQ(pipeline::option_text(render_field(name), o), text);
  }
  EXPECT_EQ(o.size, (std::array<int, 2>{64, 48}));
  EXPECT_EQ(o.camera, pipeline::Projection::kPerspective);
  EXPECT_EQ(usage_message([&o] { pipeline::set_option_text(render_field("size"), o, "0x3"); },
                          pipeline::Spelling::kCommandLine),
            "--size: expected WxH (1..16384), got '0x3'");
  o = {};
  o.azimuth = std::nan("");
  EXPECT_EQ(usage_message([&o] { pipeline::check_options(o); }, pipeline::Spelling::kLibrary),
            "azimuth: expected a finite number, got nan");
  o = {};
  o.frames = 0;
  EXPECT_EQ(usage_message([&o] { pipeline::check_options(o); }, pipeline::Spelling::kCommandLine),
            "--frames: expected 1..3600, got 0");
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
