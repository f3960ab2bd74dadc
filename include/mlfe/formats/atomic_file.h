// Output files appear whole or not at all: writers write to a temporary ".tmp-mlfe-<pid>-<name>"
// beside the output and rename it onto the output only after everything was written, flushed and
// fsync'ed (a full disk or a file size limit is an mlfe::Error, whatever library wrote the file).
// On any error the temporary is removed and mlfe::Error is thrown, so a failed command leaves no
// partial output. While an OutputBatch is alive the renames wait for its commit(), so the outputs
// of one command appear together or not at all.
//
// The output path: a symbolic link is followed (the file it points to is replaced, the link
// stays); an existing output keeps its permission bits; an output that exists and is not a
// regular file (a folder, a device) is refused. Temporaries left by a process that no longer
// exists (kill -9) are removed the next time mlfe writes into that folder.
#pragma once
#include <cstdint>
#include <functional>
#include <ostream>
#include <string>

namespace mlfe {

/// Calls write(stream) on a binary stream for a temporary file next to `path`, then renames
/// it onto `path`. Throws mlfe::Error naming `path` when the file cannot be created or written,
/// and rethrows whatever `write` throws (after removing the temporary).
void write_file_atomically(const std::string& path, const std::function<void(std::ostream&)>& write);

/// For writers whose library insists on writing a path itself (libnifti, Teem):
/// calls write(tmp_path) and renames tmp_path onto `path` when it returns true.
/// A false return or an exception removes the temporary; false throws mlfe::Error. The library
/// must report its own write errors (false or an exception); what it wrote is then fsync'ed.
void write_path_atomically(const std::string& path, const std::function<bool(const std::string&)>& write);

/// The temporary name used for `path` (same folder, so rename is atomic). The extension is kept
/// at the end so that libraries which pick a format by extension still see it. A name that would
/// pass 255 bytes becomes ".tmp-mlfe-<pid>-<hash of the name>-<end of the name>", 255 bytes.
std::string temporary_path_for(const std::string& path);

/// The file a write to `path` replaces: `path` with symbolic links followed. Throws mlfe::Error
/// when that exists and is not a regular file.
std::string output_target(const std::string& path);

/// Where the file just written to `path` is: while a batch holds it back, its temporary; else
/// `path` with symbolic links followed.
std::string written_file_path(const std::string& path);

/// The size in bytes of the file just written to `path` (written_file_path's).
std::uint64_t written_file_size(const std::string& path);

/// Holds back the renames of every file written while it is alive (in any thread) until
/// commit(); destroyed without commit(), it removes the temporaries. One at a time.
class OutputBatch {
 public:
  OutputBatch();
  ~OutputBatch();
  OutputBatch(const OutputBatch&) = delete;
  OutputBatch& operator=(const OutputBatch&) = delete;

  /// Renames every temporary onto its output, in the order written.
  void commit();

  /// Whether a batch is collecting renames now.
  static bool active();
};

}  // namespace mlfe
