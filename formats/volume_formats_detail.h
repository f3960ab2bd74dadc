// The one table of volume formats: name, file name extensions, magic bytes, reader and writer.
// read_volume (formats/volume_reader.cpp) detects a file's format from it, write_volume
// (formats/volume_writer.cpp) picks the writer from it, and scan_extensions()
// (<mlfe/formats/volume_formats.h>) answers mlfe.batch and the label tables from it. A new format
// is its reader (formats/<name>_reader.cpp and include/mlfe/formats/<name>_reader.h) and one row
// in formats/volume_formats.cpp. Not part of the public API.
#pragma once
#include <mlfe/core/field/scalar_grid.h>
#include <mlfe/formats/raw_reader.h>
#include <mlfe/formats/volume_read_options.h>

#include <optional>
#include <string>
#include <vector>

namespace mlfe::volume_detail {

struct VolumeFormatRow {
  const char* name;  ///< ScalarGrid::format: "nrrd", "nifti", ...
  /// Extensions read_volume recognises (lower case, after dropping a trailing ".gz").
  std::vector<const char*> read_extensions;
  /// The endings (lower case, matched whole, a ".gz" included) of this format's files that are a
  /// scan by themselves, for scan_extensions(); not the halves of a pair (.hdr/.img), raw data
  /// that needs a sidecar, or 2D images.
  std::vector<const char*> scan_extensions;
  /// Extensions write_volume writes (lower case, matched at the end of the name); empty: none.
  std::vector<const char*> write_extensions;
  /// Whether a file's first bytes (up to 512) are this format's; nullptr: no magic (raw).
  bool (*magic)(const std::string& head);
  ScalarGrid (*read)(const std::string& path, const VolumeReadOptions& options);
  /// Where the voxels of the file at `path` lie, when VolumeWindows can read boxes of them with
  /// read_raw_box (nullopt: only `read` reads it); the frame is the one `read` gives. nullptr: no
  /// file of this format is read so.
  std::optional<RawLayout> (*layout)(const std::string& path, const VolumeReadOptions& options);
  void (*write)(const std::string& path, const ScalarGrid& grid);  ///< nullptr: not written
  /// The other files a read of `path` opens (input_files()), found as the reader finds them;
  /// nullptr: none.
  std::vector<std::string> (*companions)(const std::string& path);
};

/// Every volume format, in the order magic bytes are tried.
const std::vector<VolumeFormatRow>& volume_formats();

/// The row named `name`, or nullptr.
const VolumeFormatRow* volume_format(const std::string& name);

// The companions of the table's rows, each beside its reader: a detached NRRD's data files
// (checked as regular files), the other halves of a NIfTI/Analyze .hdr/.img pair present, a
// MetaImage's ElementDataFile when not LOCAL, a raw volume's sidecar when there is one.
std::vector<std::string> nrrd_companions(const std::string& path);
std::vector<std::string> nifti_companions(const std::string& path);
std::vector<std::string> metaimage_companions(const std::string& path);
std::vector<std::string> raw_companions(const std::string& path);

// The writers of the table's rows (formats/volume_writer.cpp; write_vdb: formats/vdb_module.h);
// each writes atomically.
void write_nifti(const std::string& path, const ScalarGrid& grid);
void write_nrrd(const std::string& path, const ScalarGrid& grid);
void write_raw(const std::string& path, const ScalarGrid& grid);

}  // namespace mlfe::volume_detail
