// libFuzzer entry point for the label table parser (formats/label_table.h): every input is
// parsed as each kind the file name chooses (JSON, MRIcron .lut, Slicer .ctbl, and the text
// formats MRIcron, ITK-SNAP, FreeSurfer and Slicer that the content chooses among).
// mlfe::Error is the expected outcome for bad input; anything else is a finding.
#include <mlfe/core/base/error.h>
#include <mlfe/formats/label_table.h>

#include <cstdint>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string bytes(reinterpret_cast<const char*>(data), size);
  for (const char* name : {"fuzz.json", "fuzz.lut", "fuzz.ctbl", "fuzz.txt"}) {
    try {
      const mlfe::LabelTable t = mlfe::parse_label_table(bytes, name);
      // A parsed table answers for every label.
      for (const auto& [value, entry] : t.entries) {
        (void)t.name(value);
        (void)t.color(value);
      }
    } catch (const mlfe::Error&) {
    }
  }
  return 0;
}
