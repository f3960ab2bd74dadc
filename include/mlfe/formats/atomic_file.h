// Output files appear whole or not at all: writers write to "<path>.tmp-<pid>" and rename
// onto <path> only after everything was written and flushed. On any error the temporary is
// removed and mlfe::Error is thrown, so a failed command leaves no partial output.
#pragma once
#include <functional>
#include <ostream>
#include <string>

namespace mlfe {

/// Calls write(stream) on a binary stream for a temporary file next to `path`, then renames
/// it onto `path`. Throws mlfe::Error naming `path` when the file cannot be created or written,
/// and rethrows whatever `write` throws (after removing the temporary).
void write_file_atomically(const std::string& path, const std::function<void(std::ostream&)>& write);

/// For writers whose library insists on writing a path itself (OpenMesh, OpenEXR):
/// calls write(tmp_path) and renames tmp_path onto `path` when it returns true.
/// A false return or an exception removes the temporary; false throws mlfe::Error.
void write_path_atomically(const std::string& path, const std::function<bool(const std::string&)>& write);

/// The temporary name used for `path` (same folder, so rename is atomic). The extension is kept
/// at the end so that libraries which pick a format by extension still see it.
std::string temporary_path_for(const std::string& path);

}  // namespace mlfe
