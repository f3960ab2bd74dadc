#include <fmt/format.h>
#include <mlfe/core/base/vec.h>
#include <mlfe/formats/nifti_reader.h>
#include <mlfe/formats/raw_reader.h>
#include <nifti2_io.h>
#include <sys/stat.h>
#include <zlib.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <mutex>
#include <vector>

#include "formats/reader_helpers.h"
#include "formats/volume_formats_detail.h"

namespace mlfe {
using namespace volume_detail;

namespace {

std::mutex& nifti_mutex() {
  static std::mutex m;
  return m;
}

struct NiftiDeleter {
  void operator()(nifti_image* n) const { nifti_image_free(n); }
};

bool ends_with_ci(const std::string& s, const std::string& suffix) {
  if (s.size() < suffix.size()) return false;
  for (std::size_t i = 0; i < suffix.size(); ++i)
    if (std::tolower(static_cast<unsigned char>(s[s.size() - suffix.size() + i])) != suffix[i]) return false;
  return true;
}

// The file that holds the header: the .hdr for an .img path.
std::string header_file(const std::string& path) {
  for (const char* ext : {".img", ".img.gz"}) {
    if (ends_with_ci(path, ext)) {
      std::string base = path.substr(0, path.size() - std::strlen(ext));
      return base + (std::strlen(ext) == 4 ? ".hdr" : ".hdr.gz");
    }
  }
  return path;
}

// The first bytes of the (possibly gzipped) header file, decompressed.
std::string header_bytes(const std::string& file, std::size_t n) {
  regular_file_size(file);
  gzFile gz = gzopen(file.c_str(), "rb");
  if (!gz) fail(file, "cannot open");
  std::string s(n, '\0');
  int got = gzread(gz, s.data(), static_cast<unsigned>(n));
  int errnum = 0;
  const char* msg = gzerror(gz, &errnum);
  std::string err = (got < 0 && msg) ? msg : "";
  gzclose(gz);
  if (got < 0) fail(file, "corrupt gzip data in header (" + err + ")");
  s.resize(static_cast<std::size_t>(got));
  return s;
}

std::optional<ScalarType> nifti_type(int dt) {
  switch (dt) {
    case DT_UINT8:
      return ScalarType::U8;
    case DT_INT8:
      return ScalarType::I8;
    case DT_UINT16:
      return ScalarType::U16;
    case DT_INT16:
      return ScalarType::I16;
    case DT_UINT32:
      return ScalarType::U32;
    case DT_INT32:
      return ScalarType::I32;
    case DT_FLOAT32:
      return ScalarType::F32;
    case DT_FLOAT64:
      return ScalarType::F64;
    default:
      return std::nullopt;
  }
}

// libnifti opens the image file of a .hdr/.img pair (and looks for one beside a .nii) while it
// reads the header: the halves of a pair that exist beside `path`.
std::vector<std::string> pair_files(const std::string& path) {
  std::string base = path;
  for (const char* ext : {".hdr.gz", ".img.gz", ".hdr", ".img", ".nii.gz", ".nii"})
    if (ends_with_ci(path, ext)) {
      base = path.substr(0, path.size() - std::strlen(ext));
      break;
    }
  std::vector<std::string> files;
  for (const char* ext : {".img", ".img.gz", ".IMG", ".IMG.GZ", ".hdr", ".hdr.gz", ".HDR", ".HDR.GZ"}) {
    struct stat st {};
    if (base + ext != path && ::stat((base + ext).c_str(), &st) == 0) files.push_back(base + ext);
  }
  return files;
}

// Every half of a pair present must be a regular file before libnifti opens it.
void check_image_files(const std::string& path) {
  regular_file_size(path);
  for (const std::string& f : pair_files(path)) regular_file_size(f);
}

// Checks the header ourselves before libnifti sees it, so that arbitrary files are refused with a
// clear message instead of whatever libnifti guesses; returns the header's vox_offset.
double checked_vox_offset(const std::string& path) {
  const std::string hfile = header_file(path);
  const std::string hb = header_bytes(hfile, 540);
  if (hb.size() < 348)
    fail(hfile, fmt::format("truncated NIfTI header ({} of at least 348 bytes)", hb.size()));
  std::int32_t sz = 0;
  std::memcpy(&sz, hb.data(), 4);
  const std::int32_t sz_swapped =
      static_cast<std::int32_t>(__builtin_bswap32(static_cast<std::uint32_t>(sz)));
  const bool v1 = sz == 348 || sz_swapped == 348;
  const bool v2 = sz == 540 || sz_swapped == 540;
  if (!v1 && !v2)
    fail(hfile, fmt::format("not a NIfTI/Analyze header (sizeof_hdr is {}, expected 348 or 540)", sz));
  if (v2 && hb.size() < 540)
    fail(hfile, fmt::format("truncated NIfTI-2 header ({} of 540 bytes)", hb.size()));

  // libnifti prints "** ERROR" lines for bad datatypes and dims even at debug level 0, so
  // those fields are checked here first (NIfTI-1: dim int16[8] at 40, datatype int16 at 70;
  // NIfTI-2: datatype int16 at 12, dim int64[8] at 16).
  double vox_offset = 0;
  {
    const bool swap = (v1 && sz != 348) || (v2 && sz != 540);
    auto field = [&](std::size_t at, std::size_t bytes) -> std::int64_t {
      unsigned char b[8];
      std::memcpy(b, hb.data() + at, bytes);
      if (swap) std::reverse(b, b + bytes);
      if (bytes == 2) {
        std::int16_t v;
        std::memcpy(&v, b, 2);
        return v;
      }
      std::int64_t v;
      std::memcpy(&v, b, 8);
      return v;
    };
    const std::int64_t datatype = v1 ? field(70, 2) : field(12, 2);
    if (!nifti_type(static_cast<int>(datatype)))
      fail(path, fmt::format("unsupported NIfTI datatype {} (uint8..float64 are read)", datatype));
    std::int64_t dim[8];
    for (int a = 0; a < 8; ++a) dim[a] = v1 ? field(40 + 2 * a, 2) : field(16 + 8 * a, 8);
    if (dim[0] < 1 || dim[0] > 7) fail(path, fmt::format("invalid NIfTI dim[0] = {} (1..7)", dim[0]));
    for (int a = 1; a <= dim[0]; ++a)
      if (dim[a] < 1) fail(path, fmt::format("invalid NIfTI dimensions: dim[{}] = {}", a, dim[a]));
    // vox_offset (NIfTI-1: float32 at 108; NIfTI-2: int64 at 168). libnifti moves an offset
    // inside the header to its end and truncates huge ones, reading voxels from somewhere else.
    if (v1) {
      unsigned char b[4];
      std::memcpy(b, hb.data() + 108, 4);
      if (swap) std::reverse(b, b + 4);
      float f;
      std::memcpy(&f, b, 4);
      vox_offset = f;
    } else {
      vox_offset = static_cast<double>(field(168, 8));
    }
    const bool single_file = hb.compare(v1 ? 344 : 4, 3, v1 ? "n+1" : "n+2") == 0;
    const double header_end = v1 ? 352 : 544;
    if (!std::isfinite(vox_offset) || vox_offset < (single_file ? header_end : 0) || vox_offset > 1e15 ||
        vox_offset != std::floor(vox_offset))
      fail(path, fmt::format("invalid NIfTI vox_offset {} (expected a whole number of bytes{})", vox_offset,
                             single_file ? fmt::format(" after the {}-byte header", header_end) : ""));
  }
  return vox_offset;
}

// The voxels are read here, not by libnifti's loader, which silently turns NaN and Inf into 0:
// the shared rule (an error unless --nan-as) must see them. The first 3D volume is the first
// `bytes` bytes of the data.
void read_voxels(const std::string& path, const RawLayout& layout, std::uint64_t bytes, ScalarGrid& grid) {
  znzFile fp = znzopen(layout.data_file.c_str(), "rb", layout.packing ? 1 : 0);
  if (znz_isnull(fp)) fail(layout.data_file, "cannot open the NIfTI voxel data");
  struct Closer {
    znzFile& fp;
    ~Closer() { znzclose(fp); }
  } closer{fp};
  // fseek returns 0, gzseek the new offset; both -1 on failure.
  if (znzseek(fp, static_cast<znz_off_t>(layout.offset), SEEK_SET) < 0)
    fail(path, "unreadable NIfTI voxel data (cannot seek to vox_offset)");
  // Read as it decodes: a few bytes of gzip claiming a huge grid end early without the claim
  // ever being allocated.
  const std::vector<unsigned char> data = read_exactly(
      path, [fp](unsigned char* dst, std::size_t n) { return znzread(dst, 1, n, fp); }, bytes,
      "or unreadable NIfTI voxel data");
  allocate_values(grid);
  convert_to_float(data.data(), grid.source_type, layout.swap, grid.values.data(), grid.values.size());
  scale_values(path, layout, grid.values.data(), grid.values.size());
}

// The transform: the sform, else the qform (RAS), else pixdim spacing alone.
void read_transform(const std::string& path, const nifti_image* nim, ScalarGrid& grid) {
  const auto& dims = grid.dims;
  const nifti_dmat44* m = nullptr;
  if (nim->sform_code > 0)
    m = &nim->sto_xyz;
  else if (nim->qform_code > 0)
    m = &nim->qto_xyz;
  GridTransform& t = grid.transform;
  if (m) {
    std::array<std::array<double, 3>, 3> axes{};
    for (int a = 0; a < 3; ++a)
      for (int r = 0; r < 3; ++r) axes[a][r] = m->m[r][a];
    if (dims[2] == 1) {
      const auto& u = axes[0];
      const auto& v = axes[1];
      double len2 = axes[2][0] * axes[2][0] + axes[2][1] * axes[2][1] + axes[2][2] * axes[2][2];
      if (!(len2 > 0) || !std::isfinite(len2)) {
        const Vec3 n = cross(u, v);
        axes[2] = norm(n) > 0 ? normalized(n) : Vec3{0, 0, 1};
      }
    }
    set_axes(path, t, axes);
    for (int r = 0; r < 3; ++r) t.origin[r] = m->m[r][3];
    grid.space = "RAS";
    if (nim->sform_code <= 0) add_note(grid, "transform from the qform (no sform)");
  } else {
    for (int a = 0; a < 3; ++a) {
      double s = std::fabs(static_cast<double>(nim->pixdim[a + 1]));
      t.spacing[a] = (std::isfinite(s) && s > 0) ? s : 1.0;
    }
    add_note(grid, "no qform or sform: pixdim spacing, origin 0, orientation unknown");
  }
}

}  // namespace

namespace volume_detail {

std::vector<std::string> nifti_companions(const std::string& path) { return pair_files(path); }

}  // namespace volume_detail

RawLayout nifti_layout(const std::string& path, const VolumeReadOptions&) {
  const double vox_offset = checked_vox_offset(path);
  check_image_files(path);

  std::lock_guard<std::mutex> lock(nifti_mutex());
  nifti_set_debug_level(0);
  std::unique_ptr<nifti_image, NiftiDeleter> nim(nifti_image_read(path.c_str(), 0));
  if (!nim) fail(path, "libnifti cannot read the NIfTI header (invalid header fields or missing image file)");

  auto type = nifti_type(nim->datatype);
  if (!type)
    fail(path, fmt::format("unsupported NIfTI datatype {} ({})", nim->datatype,
                           nifti_datatype_to_string(nim->datatype)));
  if (nim->dim[0] < 1 || nim->dim[0] > 7) fail(path, fmt::format("invalid NIfTI dim[0] = {}", nim->dim[0]));
  std::array<std::int64_t, 3> dims{1, 1, 1};
  for (int a = 0; a < 3 && a < nim->dim[0]; ++a) dims[a] = nim->dim[a + 1];
  const std::int64_t voxels = checked_voxel_count(path, dims);
  std::int64_t volumes = 1;
  for (int a = 4; a <= nim->dim[0]; ++a) {
    if (nim->dim[a] < 1 || nim->dim[a] > INT32_MAX)
      fail(path, fmt::format("invalid NIfTI dim[{}] = {}", a, nim->dim[a]));
    if (__builtin_mul_overflow(volumes, nim->dim[a], &volumes)) fail(path, "NIfTI dimensions overflow");
  }
  const int esize = scalar_type_size(*type);
  if (nim->nbyper != esize) fail(path, "NIfTI bytes per voxel do not match the datatype");
  const std::uint64_t bytes = checked_bytes(path, voxels, static_cast<std::uint64_t>(esize));

  // Only uncompressed data can be compared with the file size without decompressing it.
  if (nim->iname && !ends_with_ci(nim->iname, ".gz")) {
    const std::string iname = nim->iname;
    const std::uint64_t isize = regular_file_size(iname);
    std::uint64_t total = 0, end = 0;
    if (nim->iname_offset < 0 || __builtin_mul_overflow(bytes, static_cast<std::uint64_t>(volumes), &total) ||
        __builtin_add_overflow(total, static_cast<std::uint64_t>(nim->iname_offset), &end))
      fail(path, "NIfTI data size overflows");
    if (end > isize)
      fail(iname,
           fmt::format("truncated: {} x {} x {} {} voxels{} at offset {} need {} bytes, the file has {}",
                       dims[0], dims[1], dims[2], scalar_type_name(*type),
                       volumes > 1 ? fmt::format(" x {} volumes", volumes) : "", nim->iname_offset, end,
                       isize));
  }
  if (!nim->iname || nim->iname_offset < 0) fail(path, "NIfTI header names no voxel data");
  if (static_cast<double>(nim->iname_offset) != vox_offset)
    fail(path, fmt::format("invalid NIfTI vox_offset {} (libnifti would read the voxels at offset {})",
                           vox_offset, nim->iname_offset));
  regular_file_size(nim->iname);

  RawLayout layout;
  ScalarGrid& grid = layout.frame;
  grid.dims = dims;
  grid.source_type = *type;
  layout.data_file = nim->iname;
  layout.offset = static_cast<std::uint64_t>(nim->iname_offset);
  layout.swap = nim->byteorder != nifti_short_order();
  if (ends_with_ci(nim->iname, ".gz")) layout.packing = Compression::kGzip;
  if (volumes > 1) add_note(grid, fmt::format("NIfTI has {} volumes; read the first", volumes));

  const double slope = nim->scl_slope, inter = nim->scl_inter;
  if (slope != 0.0 && std::isfinite(slope) && std::isfinite(inter) && !(slope == 1.0 && inter == 0.0)) {
    layout.scaling = std::array<double, 2>{slope, inter};
    add_note(grid, fmt::format("scl_slope {} and scl_inter {} applied", slope, inter));
  }

  read_transform(path, nim.get(), grid);
  if (nim->nifti_type == NIFTI_FTYPE_ANALYZE) add_note(grid, "Analyze 7.5 header (no NIfTI magic)");
  return layout;
}

ScalarGrid read_nifti(const std::string& path, const VolumeReadOptions& opts) {
  RawLayout layout = nifti_layout(path, opts);
  check_memory_for_copy(path, layout, opts, "the NIfTI data and the float32 grid");
  read_voxels(path, layout, stored_bytes(path, layout), layout.frame);
  return std::move(layout.frame);
}

}  // namespace mlfe
