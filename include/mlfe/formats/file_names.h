// File-name helpers shared by the writers and the command line.
#pragma once
#include <string>

namespace mlfe {

/// The extension of the file name in `path`, with its dot, in lower case (".glb"); "" when the
/// name has none (a dot in a folder name does not count).
std::string lower_extension(const std::string& path);

}  // namespace mlfe
