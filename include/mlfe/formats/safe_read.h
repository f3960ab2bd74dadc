// What every reader in formats/ does with the files its input names (issue 43): only regular
// files are read (a FIFO named by a header hung the run, a symlink to /dev/zero read 4 GB);
// decoded data grows with the bytes actually decoded, never with what a header claims (64 bytes
// of gzip claiming 1200^3 voxels allocated 1.7 GB); counts a file declares are weighed against
// its size before a loop or an allocation; and an index-to-physical frame must span three
// dimensions (a singular one gave flat assets).
#pragma once
#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace mlfe {

/// A regular file open for reading. The constructor opens `path` without blocking (a FIFO with
/// no writer would wait forever), asks fstat what it is, and throws
/// Error("<path>: not a regular file") for a FIFO, device, socket or folder, or
/// Error("<path>: cannot open (<reason>)"), before a byte is read.
class RegularFile {
 public:
  explicit RegularFile(const std::string& path);
  ~RegularFile();
  RegularFile(const RegularFile&) = delete;
  RegularFile& operator=(const RegularFile&) = delete;

  const std::string& path() const { return path_; }
  /// The size fstat reported at the open.
  std::uint64_t size() const { return size_; }
  /// Moves the read position to byte `offset` from the start.
  void seek(std::uint64_t offset);
  /// Reads up to `n` bytes at the read position: fewer only at the end of the file. Throws
  /// Error("<path>: read error (<reason>)").
  std::size_t read(void* dst, std::size_t n);
  /// Reads up to `n` bytes at byte `offset` without using the read position (pread), so several
  /// threads may read one file at once: fewer only at the end of the file. Throws as read().
  std::size_t read_at(std::uint64_t offset, void* dst, std::size_t n) const;

  /// An empty file that no folder lists (made in the temporary folder, TMPDIR or /tmp, and
  /// unlinked at once), open for append() and reading: its disk space returns when it is
  /// destroyed or the process ends, however it ends. `name` stands for it in messages.
  static std::unique_ptr<RegularFile> scratch(const std::string& name);
  /// Appends `n` bytes to a scratch file. Throws Error("<name>: cannot write its temporary copy
  /// (<reason>)"), e.g. when the disk is full.
  void append(const void* src, std::size_t n);

 private:
  RegularFile(std::string name, int fd);

  std::string path_;
  int fd_ = -1;
  std::uint64_t size_ = 0;
};

/// The size of the regular file at `path`, checked as RegularFile checks it. For the libraries
/// that open files by name (Teem, libnifti, OpenMesh, OpenEXR), called before they do.
std::uint64_t regular_file_size(const std::string& path);

/// Up to `n` leading bytes of the regular file at `path`.
std::string read_file_prefix(const std::string& path, std::size_t n);

/// The whole regular file at `path`. Throws Error("<path>: <what> has N bytes, more than the M
/// allowed") when it is larger than `limit`, before reading it.
std::string read_regular_file(const std::string& path, std::uint64_t limit, const std::string& what);

/// A stream of bytes: fills up to `n` bytes at `dst` and returns how many; 0 at its end.
using ByteSource = std::function<std::size_t(unsigned char* dst, std::size_t n)>;

/// The bytes of `file` from its read position on (`file` must outlive the source).
ByteSource file_source(RegularFile& file);
/// The `n` bytes at `data` (which must outlive the source).
ByteSource memory_source(const void* data, std::size_t n);

/// kGzip reads the members of a gzip file one after the other, as gzread does, and ends where
/// the bytes after a member are not another member.
enum class Compression { kZlib, kGzip, kBzip2 };

/// The decoded bytes of the compressed stream that `in` delivers, as a source that ends where
/// the stream ends or where `in` runs out inside it. Corrupt data throws
/// Error("<path>: corrupt compressed data (<reason>)").
ByteSource decoded_source(const std::string& path, Compression compression, ByteSource in);

/// Exactly `bytes` bytes of `in`, in a buffer that grows with the data that arrives (doubling,
/// capped at `bytes`), so a header that promises more than its data holds costs no memory.
/// Throws Error("<path>: truncated <what> (N of M bytes)") when `in` ends early; bytes after
/// the M are not read.
std::vector<unsigned char> read_exactly(const std::string& path, const ByteSource& in, std::uint64_t bytes,
                                        const std::string& what);

/// How many bytes `in` delivers, counting no further than `enough`: how a reader whose library
/// allocates what a header claims (Teem, libpng) first learns that the data can fill it.
std::uint64_t count_bytes(const ByteSource& in, std::uint64_t enough);

/// The zlib stream of `n` bytes at `data`, which must inflate to exactly `bytes` bytes, inflated
/// into a buffer that grows as read_exactly's. Throws Error("<path>: <problem>") for a stream
/// that is corrupt, ends early or holds more.
std::vector<unsigned char> inflate_exactly(const std::string& path, const void* data, std::size_t n,
                                           std::uint64_t bytes);

/// Throws Error("<path>: <what> declares N, more than its M bytes can hold") when `count` items
/// of at least `min_bytes_each` bytes each cannot fit in `available` bytes: checked before a
/// loop or an allocation sized by a count read from a file.
void check_declared_count(const std::string& path, const std::string& what, std::uint64_t count,
                          std::uint64_t min_bytes_each, std::uint64_t available);

/// Throws Error("<path>: <problem>") unless the index-to-physical `direction` (row-major 3x3,
/// column a the direction of index axis a) is finite and spans three dimensions: |det| at least
/// 1e-6 of the product of its column lengths (the spacing scales columns, so it cannot matter).
void check_frame(const std::string& path, const std::array<double, 9>& direction);

}  // namespace mlfe
