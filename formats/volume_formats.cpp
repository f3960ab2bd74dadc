// The table of volume formats (formats/volume_formats_detail.h), their magic bytes, and what it
// tells the rest of mlfe (<mlfe/formats/volume_formats.h>).
#include <mlfe/formats/metaimage_reader.h>
#include <mlfe/formats/nifti_reader.h>
#include <mlfe/formats/nrrd_reader.h>
#include <mlfe/formats/pgm_reader.h>
#include <mlfe/formats/png_reader.h>
#include <mlfe/formats/raw_reader.h>
#include <mlfe/formats/vdb_reader.h>
#include <mlfe/formats/volume_formats.h>
#include <mlfe/formats/zarr_reader.h>

#include <cctype>
#include <cstdint>
#include <cstring>

#include "formats/tet_mesh_reader_detail.h"
#include "formats/vdb_module.h"
#include "formats/volume_formats_detail.h"

namespace mlfe::volume_detail {
namespace {

bool starts(const std::string& head, const char* magic, std::size_t n) {
  return head.size() >= n && std::memcmp(head.data(), magic, n) == 0;
}

std::int32_t le32(const std::string& s, std::size_t at) {
  std::uint32_t v = 0;
  for (int b = 3; b >= 0; --b) v = (v << 8) | static_cast<unsigned char>(s[at + b]);
  return static_cast<std::int32_t>(v);
}

bool nrrd_magic(const std::string& head) { return starts(head, "NRRD000", 7); }
// OpenVDB's magic 0x56444220 as a little-endian int64.
bool vdb_magic(const std::string& head) { return starts(head, "\x20\x42\x44\x56\0\0\0\0", 8); }
bool png_magic(const std::string& head) { return starts(head, "\x89PNG\r\n\x1a\n", 8); }
bool pgm_magic(const std::string& head) {
  return head.size() >= 3 && head[0] == 'P' && head[1] == '5' &&
         std::isspace(static_cast<unsigned char>(head[2]));
}

// NIfTI-1 ("n+1"/"ni1" at 344 after sizeof_hdr 348) or NIfTI-2 ("n+2"/"ni2" at 4 after 540),
// either byte order.
bool nifti_magic(const std::string& head) {
  if (head.size() < 348) return false;
  const std::int32_t sz = le32(head, 0);
  const bool n1 = (sz == 348 || sz == 0x5c010000) && (std::memcmp(head.data() + 344, "n+1\0", 4) == 0 ||
                                                      std::memcmp(head.data() + 344, "ni1\0", 4) == 0);
  const bool n2 = (sz == 540 || sz == 0x1c020000) && (std::memcmp(head.data() + 4, "n+2\0", 4) == 0 ||
                                                      std::memcmp(head.data() + 4, "ni2\0", 4) == 0);
  return n1 || n2;
}

// MetaImage headers are "Key = Value" lines that begin with one of a few keys.
bool metaimage_magic(const std::string& head) {
  std::size_t i = 0;
  while (i < head.size() && std::isspace(static_cast<unsigned char>(head[i]))) ++i;
  for (const char* key : {"ObjectType", "NDims", "Comment", "ObjectSubType", "DimSize"}) {
    const std::size_t n = std::strlen(key);
    if (head.compare(i, n, key) == 0) {
      std::size_t j = i + n;
      while (j < head.size() && (head[j] == ' ' || head[j] == '\t')) ++j;
      if (j < head.size() && head[j] == '=') return true;
    }
  }
  return false;
}

// The rows' layouts, for the readers whose every file has one.
template <RawLayout (*Layout)(const std::string&, const VolumeReadOptions&)>
std::optional<RawLayout> always(const std::string& path, const VolumeReadOptions& opts) {
  return Layout(path, opts);
}

}  // namespace

const std::vector<VolumeFormatRow>& volume_formats() {
  static const std::vector<VolumeFormatRow> rows = {
      // name, read extensions, scan endings, write extensions, magic, reader, layout, writer,
      // companions
      {"nrrd",
       {".nrrd", ".nhdr"},
       {".nrrd", ".nhdr"},
       {".nrrd"},
       nrrd_magic,
       read_nrrd,
       nrrd_layout,
       write_nrrd,
       nrrd_companions},
      {"vdb", {".vdb"}, {".vdb"}, {".vdb"}, vdb_magic, read_vdb, nullptr, write_vdb, nullptr},
      {"png", {".png"}, {}, {}, png_magic, read_png, nullptr, nullptr, nullptr},
      {"pgm", {".pgm"}, {}, {}, pgm_magic, read_pgm, nullptr, nullptr, nullptr},
      {"nifti",
       {".nii", ".hdr", ".img"},
       {".nii.gz", ".nii"},
       {".nii.gz", ".nii"},
       nifti_magic,
       read_nifti,
       always<nifti_layout>,
       write_nifti,
       nifti_companions},
      {"metaimage",
       {".mha", ".mhd"},
       {".mha", ".mhd"},
       {},
       metaimage_magic,
       read_metaimage,
       always<metaimage_layout>,
       nullptr,
       metaimage_companions},
      // Headerless: by extension, a "<file>.json" sidecar, or --raw-dims/--raw-type.
      {"raw",
       {".raw", ".bin", ".dat"},
       {},
       {".raw"},
       nullptr,
       read_raw,
       always<raw_layout>,
       write_raw,
       raw_companions},
      // A folder: recognised by its metadata files (is_zarr_store), not by magic bytes; read in
      // boxes by chunks (ZarrVolume), not by a layout.
      {"zarr", {".zarr"}, {}, {}, nullptr, read_zarr, nullptr, nullptr, nullptr},
  };
  return rows;
}

const VolumeFormatRow* volume_format(const std::string& name) {
  for (const auto& row : volume_formats())
    if (name == row.name) return &row;
  return nullptr;
}

}  // namespace mlfe::volume_detail

namespace mlfe {

const std::vector<std::string>& scan_extensions() {
  static const std::vector<std::string> endings = [] {
    std::vector<std::string> e;
    for (const auto& row : volume_detail::volume_formats())
      e.insert(e.end(), row.scan_extensions.begin(), row.scan_extensions.end());
    e.insert(e.end(), tet_mesh_detail::kTetMeshExtensions.begin(), tet_mesh_detail::kTetMeshExtensions.end());
    return e;
  }();
  return endings;
}

}  // namespace mlfe
