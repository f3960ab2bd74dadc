// input_files (<mlfe/formats/input_files.h>): a volume's companions from the table of volume
// formats, a glTF's buffer files, an MRIcron table's colours.
#include <mlfe/formats/file_names.h>
#include <mlfe/formats/gltf_reader.h>
#include <mlfe/formats/input_files.h>
#include <mlfe/formats/label_table.h>
#include <mlfe/formats/volume_reader.h>
#include <sys/stat.h>

#include "formats/volume_formats_detail.h"

namespace mlfe {

std::vector<std::string> input_files(const std::string& path) {
  std::vector<std::string> files{path};
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return files;
  const std::string ext = lower_extension(path);
  std::vector<std::string> more;
  if (ext == ".gltf" || ext == ".glb") {
    more = gltf_buffer_files(path);
  } else if (ext == ".txt") {
    if (const std::string lut = mricron_colours_file(path); !lut.empty()) more = {lut};
  } else if (const auto* row = volume_detail::volume_format(detect_volume_format(path));
             row && row->companions) {
    more = row->companions(path);
  }
  files.insert(files.end(), more.begin(), more.end());
  return files;
}

}  // namespace mlfe
