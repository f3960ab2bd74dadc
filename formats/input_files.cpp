// input_files (<mlfe/formats/input_files.h>): the table's companions of a volume, a glTF's
// buffer files.
#include <mlfe/formats/gltf_reader.h>
#include <mlfe/formats/input_files.h>
#include <mlfe/formats/volume_reader.h>
#include <sys/stat.h>

#include <algorithm>
#include <cctype>

#include "formats/volume_formats_detail.h"

namespace mlfe {

std::vector<std::string> input_files(const std::string& path) {
  std::vector<std::string> files{path};
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return files;
  std::string lower = path;
  std::transform(lower.begin(), lower.end(), lower.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  const auto ends = [&lower](const std::string& e) {
    return lower.size() >= e.size() && lower.compare(lower.size() - e.size(), e.size(), e) == 0;
  };
  std::vector<std::string> more;
  if (ends(".gltf") || ends(".glb")) {
    more = gltf_buffer_files(path);
  } else if (const auto* row = volume_detail::volume_format(detect_volume_format(path));
             row && row->companions) {
    more = row->companions(path);
  }
  files.insert(files.end(), more.begin(), more.end());
  return files;
}

}  // namespace mlfe
