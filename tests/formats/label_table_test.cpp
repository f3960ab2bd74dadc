// Label tables: one small file per format (tests/data/labels), the JHU atlas' MRIcron pair,
// the table found beside a volume, and bad tables as one-line errors.
#include <gtest/gtest.h>
#include <mlfe/core/base/error.h>
#include <mlfe/formats/label_table.h>

#include <filesystem>
#include <fstream>
#include <set>

namespace mlfe {
namespace {

const std::string kDir = std::string(MLFE_SOURCE_DIR) + "/tests/data/labels/";

using Rgba = std::array<std::uint8_t, 4>;

TEST(LabelTable, ItkSnap) {
  const LabelTable t = read_label_table(kDir + "table_itksnap.txt");
  EXPECT_EQ(t.format, "itksnap");
  ASSERT_EQ(t.entries.size(), 3u);
  EXPECT_EQ(t.name(1), "Left hippocampus");
  EXPECT_EQ(t.entries.at(1).rgba, (Rgba{255, 0, 0, 255}));
  EXPECT_EQ(t.entries.at(7).rgba, (Rgba{0, 255, 0, 128}));
  EXPECT_EQ(t.name(0), "Clear Label");
}

TEST(LabelTable, FreeSurferColorLut) {
  const LabelTable t = read_label_table(kDir + "table_freesurfer_ColorLUT.txt");
  EXPECT_EQ(t.format, "freesurfer");
  ASSERT_EQ(t.entries.size(), 3u);
  EXPECT_EQ(t.name(17), "Left-Hippocampus");
  // FreeSurfer's A column is 0 and drawn opaque.
  EXPECT_EQ(t.entries.at(17).rgba, (Rgba{220, 216, 20, 255}));
}

TEST(LabelTable, SlicerColorTable) {
  const LabelTable a = read_label_table(kDir + "table_slicer.ctbl");
  EXPECT_EQ(a.format, "slicer");
  EXPECT_EQ(a.name(3), "tissue");
  EXPECT_EQ(a.entries.at(7).rgba, (Rgba{241, 214, 145, 200}));
  // A .txt with Slicer's header is Slicer's too.
  const LabelTable b = read_label_table(kDir + "table_slicer_header.txt");
  EXPECT_EQ(b.format, "slicer");
  EXPECT_EQ(b.entries.at(9).rgba, (Rgba{192, 104, 88, 128}));
}

TEST(LabelTable, MricronTextIgnoresExtraColumns) {
  const LabelTable t = read_label_table(kDir + "table_mricron.txt");
  EXPECT_EQ(t.format, "mricron");
  ASSERT_EQ(t.entries.size(), 3u);
  EXPECT_EQ(t.name(3), "Genu_of_corpus_callosum");
  EXPECT_FALSE(t.entries.at(3).has_color);
  EXPECT_EQ(t.color(3), default_label_color(3));
}

TEST(LabelTable, Json) {
  const LabelTable t = read_label_table(kDir + "table.json");
  EXPECT_EQ(t.format, "json");
  EXPECT_EQ(t.name(3), "Genu of corpus callosum");
  EXPECT_EQ(t.color(3), (std::array<std::uint8_t, 3>{255, 0, 0}));
  EXPECT_EQ(t.entries.at(7).rgba, (Rgba{0, 0, 255, 128}));
  EXPECT_EQ(t.name(300), "label_300");
  EXPECT_EQ(t.color(300), default_label_color(300));
}

TEST(LabelTable, JhuAtlasNamesWithColoursFromTheLutBeside) {
  const LabelTable t = read_label_table(kDir + "atlas_jhu_wm_labels_1mm.txt");
  EXPECT_EQ(t.format, "mricron");
  EXPECT_EQ(t.entries.size(), 49u);
  EXPECT_EQ(t.name(3), "Genu_of_corpus_callosum");
  // The .lut's planar bytes: red at l, green at 256 + l, blue at 512 + l.
  std::ifstream in(kDir + "atlas_jhu_wm_labels_1mm.lut", std::ios::binary);
  std::string lut((std::istreambuf_iterator<char>(in)), {});
  ASSERT_EQ(lut.size(), 768u);
  for (int l : {1, 3, 48})
    EXPECT_EQ(t.color(std::uint16_t(l)),
              (std::array<std::uint8_t, 3>{std::uint8_t(lut[l]), std::uint8_t(lut[256 + l]),
                                           std::uint8_t(lut[512 + l])}));
  EXPECT_TRUE(t.entries.at(48).has_color);
  // The .lut alone: colours for 0..255, no names.
  const LabelTable c = read_label_table(kDir + "atlas_jhu_wm_labels_1mm.lut");
  EXPECT_EQ(c.format, "mricron-lut");
  EXPECT_EQ(c.entries.size(), 256u);
  EXPECT_EQ(c.name(3), "label_3");
}

TEST(LabelTable, FoundBesideTheVolumeByStem) {
  EXPECT_EQ(find_label_table(kDir + "atlas_jhu_wm_labels_1mm.nii.gz"), kDir + "atlas_jhu_wm_labels_1mm.txt");
  // The compound ending whole, in any case (scan_extensions()).
  EXPECT_EQ(find_label_table(kDir + "atlas_jhu_wm_labels_1mm.NII.GZ"), kDir + "atlas_jhu_wm_labels_1mm.txt");
  EXPECT_EQ(find_label_table(kDir + "no_such_volume.nrrd"), "");
}

TEST(LabelTable, DefaultPaletteIsDistinctAndFixed) {
  std::set<std::array<std::uint8_t, 3>> seen;
  for (int l = 1; l <= 200; ++l) seen.insert(default_label_color(std::uint16_t(l)));
  EXPECT_EQ(seen.size(), 200u);
  EXPECT_EQ(default_label_color(5), default_label_color(5));
}

TEST(LabelTable, BadTablesAreOneLineErrors) {
  const std::vector<std::pair<std::string, std::string>> bad = {
      {"a.txt", "1 left\nx right\n"},                   // label not an integer
      {"a.txt", "70000 big\n"},                         // label out of range
      {"a.txt", "-1 negative\n"},                       // negative
      {"a.txt", "1 a\n1 b\n"},                          // listed twice
      {"a.txt", "# only comments\n\n"},                 // no labels
      {"a.txt", "1\n"},                                 // no name
      {"a.txt", "1 a 1 2 3 4\n2 b\n"},                  // six columns, then two
      {"a.ctbl", "1 a 1 2 300 255\n"},                  // component out of range
      {"a.txt", "1 255 0 0 1 1 1 \"unterminated\n"},    // ITK-SNAP quote
      {"a.txt", "1 255 0 0 2 1 1 \"opacity 2\"\n"},     // ITK-SNAP opacity
      {"a.txt", std::string("1 a\0b\n", 6)},            // binary
      {"a.json", "{\"labels\": [{\"name\": \"x\"}]}"},  // no value
      {"a.json", "{\"labels\": [{\"value\": 1, \"color\": [1, 2]}]}"},
      {"a.json", "[1, 2]"},
      {"a.json", "{not json"},
      {"a.lut", std::string(767, 'x')},
  };
  for (const auto& [name, bytes] : bad) {
    try {
      parse_label_table(bytes, name);
      ADD_FAILURE() << "accepted: " << bytes;
    } catch (const Error& e) {
      const std::string m = e.what();
      EXPECT_EQ(m.find('\n'), std::string::npos) << m;
      EXPECT_EQ(m.rfind(name, 0), 0u) << m;
    }
  }
  EXPECT_THROW(read_label_table(kDir + "missing.txt"), Error);
}

}  // namespace
}  // namespace mlfe
