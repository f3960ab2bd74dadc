// read_volume: detects a file's format with the table of volume formats
// (formats/volume_formats.cpp) and calls that row's reader, then checks what every reader
// returns.
#include <fmt/format.h>
#include <mlfe/core/base/check.h>
#include <mlfe/core/base/vec.h>
#include <mlfe/formats/raw_reader.h>
#include <mlfe/formats/tet_mesh_reader.h>
#include <mlfe/formats/volume_reader.h>
#include <mlfe/formats/zarr_reader.h>
#include <sys/stat.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <exception>
#include <mutex>
#include <new>
#include <optional>

#include "formats/reader_helpers.h"
#include "formats/volume_formats_detail.h"

namespace mlfe {

namespace {
using namespace volume_detail;

std::string lower(std::string s) {
  for (auto& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

bool ends_with(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

bool file_exists(const std::string& p) {
  struct stat st {};
  return ::stat(p.c_str(), &st) == 0 && S_ISREG(st.st_mode);
}

std::string format_by_extension(const std::string& path) {
  std::string p = lower(path);
  if (ends_with(p, ".gz")) p.resize(p.size() - 3);
  for (const auto& row : volume_formats())
    for (const char* ext : row.read_extensions)
      if (ends_with(p, ext)) return row.name;
  return "";
}

std::string format_by_magic(const std::string& head) {
  for (const auto& row : volume_formats())
    if (row.magic && row.magic(head)) return row.name;
  return "";
}

void convert_space(ScalarGrid& grid, const std::string& requested) {
  std::string want = lower(requested);
  if (want.empty()) return;
  if (want != "ras" && want != "lps")
    throw Error(grid.source + ": unknown space '" + requested + "' (use ras or lps)");
  std::string target = want == "ras" ? "RAS" : "LPS";
  if (grid.space.empty()) {
    add_note(grid, "the file names no space; its coordinates are taken as " + target);
  } else if (grid.space != target) {
    // RAS and LPS differ by the sign of x and y.
    // "+ 0.0" keeps zeros positive, so output does not show "-0".
    for (int c = 0; c < 6; ++c) grid.transform.direction[c] = -grid.transform.direction[c] + 0.0;
    grid.transform.origin[0] = -grid.transform.origin[0] + 0.0;
    grid.transform.origin[1] = -grid.transform.origin[1] + 0.0;
    add_note(grid, "converted " + grid.space + " to " + target + " (x and y negated)");
  }
  grid.space = target;
}

// Replaces or refuses NaN/Inf values; `at` is the grid's first sample's index in the volume
// (a window's), for the message. Returns how many there were.
std::int64_t check_finite_values(ScalarGrid& grid, const VolumeReadOptions& opts,
                                 const std::array<std::int64_t, 3>& at = {0, 0, 0}) {
  std::int64_t bad = 0, first = -1;
  for (std::size_t i = 0; i < grid.values.size(); ++i) {
    if (!std::isfinite(grid.values[i])) {
      if (first < 0) first = static_cast<std::int64_t>(i);
      ++bad;
      if (opts.nan_as) grid.values[i] = static_cast<float>(*opts.nan_as);
    }
  }
  if (bad == 0 || opts.nan_as) return bad;
  const std::int64_t nx = grid.dims[0], ny = grid.dims[1];
  std::int64_t fi = first % nx, fj = (first / nx) % ny, fk = first / (nx * ny);
  throw Error(
      fmt::format("{}: {} voxels {}are NaN or infinite (first at index {},{},{}); use --nan-as VALUE "
                  "to replace them",
                  grid.source, bad, at == std::array<std::int64_t, 3>{0, 0, 0} ? "" : "of a box ", fi + at[0],
                  fj + at[1], fk + at[2]));
}

void check_transform(const ScalarGrid& grid) {
  const auto& t = grid.transform;
  bool ok = true;
  for (double v : t.spacing) ok = ok && std::isfinite(v) && v > 0;
  for (double v : t.origin) ok = ok && std::isfinite(v);
  for (double v : t.direction) ok = ok && std::isfinite(v);
  if (!ok)
    throw Error(grid.source + ": the index-to-physical transform has zero, negative or non-finite entries");
  check_frame(grid.source, t.direction);
}

// Runs a reader's work on `path`: mlfe::Error passes, anything else a library or the allocator
// throws becomes one naming the file.
template <class Read>
void as_read_of(const std::string& path, Read&& read) {
  try {
    read();
  } catch (const Error&) {
    throw;
  } catch (const std::bad_alloc&) {
    fail(path, "out of memory while reading");
  } catch (const std::exception& e) {
    fail(path, e.what());
  }
}

}  // namespace

std::string detect_volume_format(const std::string& path) {
  if (is_zarr_store(path)) return "zarr";
  std::string head = read_file_prefix(path, 512);
  std::string by_magic = format_by_magic(head);
  if (!by_magic.empty()) return by_magic;
  if (file_exists(path + ".json")) return "raw";
  std::string by_ext = format_by_extension(path);
  // A gzip stream: only the extension can say what is inside.
  return by_ext;
}

ScalarGrid read_volume(const std::string& path, const VolumeReadOptions& opts) {
  std::string format = detect_volume_format(path);
  if (format.empty() && (opts.raw_dims || !opts.raw_dtype.empty())) format = "raw";
  if (format.empty() && !detect_tet_mesh_format(path).empty())
    fail(path,
         "a tetrahedral mesh (.vtu/.msh): build, convert, iso and render read it; this needs a voxel volume");
  if (format.empty()) {
    std::string head = read_file_prefix(path, 8);
    std::string hex;
    for (unsigned char c : head) hex += fmt::format("{:02x}", c);
    fail(path, fmt::format("unrecognised volume format (magic bytes {}; extension unknown); give --raw-dims "
                           "and --raw-type for headerless raw data",
                           hex.empty() ? "none: empty file" : hex));
  }
  ScalarGrid grid;
  as_read_of(path, [&] {
    const VolumeFormatRow* row = volume_format(format);
    if (!row) fail(path, "unsupported format " + format);
    grid = row->read(path, opts);
  });
  grid.format = format;
  grid.source = path;
  if (grid.dims[2] == 1) grid.dim = 2;
  if (static_cast<std::int64_t>(grid.values.size()) != grid.voxel_count())
    fail(path, "internal error: voxel count does not match dimensions");
  check_transform(grid);
  if (const std::int64_t bad = check_finite_values(grid, opts))
    add_note(grid, fmt::format("{} NaN/Inf voxels replaced by {}", bad, *opts.nan_as));
  convert_space(grid, opts.space);
  return grid;
}

struct VolumeWindows::Impl {
  ScalarGrid frame;
  VolumeReadOptions opts;
  std::optional<ZarrVolume> zarr;
  std::optional<RawLayout> raw;
  ScalarGrid whole;  // the formats without box reads

  // The file read_raw_box reads: the data file, or a packed layout's decoded copy, made by the
  // first read that needs it (opening a volume only to weigh it decodes nothing). A failure is
  // kept and thrown again to every later read.
  mutable std::mutex data_mutex;
  mutable std::unique_ptr<RegularFile> data;
  mutable std::exception_ptr data_failure;

  const RegularFile& data_file() const {
    const std::lock_guard<std::mutex> lock(data_mutex);
    if (data_failure) std::rethrow_exception(data_failure);
    if (!data) {
      try {
        as_read_of(frame.source, [&] {
          data =
              raw->packing ? unpack_raw(frame.source, *raw) : std::make_unique<RegularFile>(raw->data_file);
        });
      } catch (...) {
        data_failure = std::current_exception();
        throw;
      }
    }
    return *data;
  }
};

namespace {

// The row of the format whose layout VolumeWindows reads `path` by, or nullptr (a zarr store,
// or a file only its reader reads whole).
const VolumeFormatRow* layout_row(const std::string& path, const VolumeReadOptions& opts) {
  std::string format = detect_volume_format(path);
  if (format.empty() && (opts.raw_dims || !opts.raw_dtype.empty())) format = "raw";
  const VolumeFormatRow* row = volume_format(format);
  return row && row->layout ? row : nullptr;
}

}  // namespace

VolumeWindows::VolumeWindows(const std::string& path, const VolumeReadOptions& opts)
    : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.opts = opts;
  // The header is read once: the layout found here is both the test (reads_in_windows) and
  // the one used.
  as_read_of(path, [&] {
    if (is_zarr_store(path)) {
      m.zarr.emplace(path, opts.zarr_level);
      m.frame.dims = m.zarr->dims();
      m.frame.transform = m.zarr->transform();
      m.frame.source_type = m.zarr->type();
      m.frame.notes = m.zarr->notes();
      m.frame.format = "zarr";
    } else if (const VolumeFormatRow* row = layout_row(path, opts)) {
      m.raw = row->layout(path, opts);
      if (m.raw) {
        m.frame = m.raw->frame;
        m.frame.format = row->name;
      }
    }
  });
  if (!m.zarr && !m.raw) {
    m.whole = read_volume(path, opts);
    // The frame without the values: they are held once, in `whole`.
    std::vector<float> values = std::move(m.whole.values);
    m.frame = m.whole;
    m.whole.values = std::move(values);
    return;
  }
  m.frame.source = path;
  if (m.frame.dims[2] == 1) m.frame.dim = 2;
  check_transform(m.frame);
  convert_space(m.frame, opts.space);
}

VolumeWindows::~VolumeWindows() = default;
VolumeWindows::VolumeWindows(VolumeWindows&&) noexcept = default;
VolumeWindows& VolumeWindows::operator=(VolumeWindows&&) noexcept = default;

const ScalarGrid& VolumeWindows::frame() const { return impl_->frame; }

bool VolumeWindows::streamed() const { return impl_->zarr || impl_->raw; }

bool reads_in_windows(const std::string& path, const VolumeReadOptions& opts) {
  if (is_zarr_store(path)) return true;
  const VolumeFormatRow* row = layout_row(path, opts);
  bool in_boxes = false;
  if (row) as_read_of(path, [&] { in_boxes = row->layout(path, opts).has_value(); });
  return in_boxes;
}

ScalarGrid VolumeWindows::read(const std::array<std::int64_t, 3>& lo,
                               const std::array<std::int64_t, 3>& hi) const {
  const Impl& m = *impl_;
  for (int a = 0; a < 3; ++a) MLFE_CHECK(0 <= lo[a] && lo[a] < hi[a] && hi[a] <= m.frame.dims[a]);
  ScalarGrid w;
  if (m.zarr) {
    w = m.zarr->read_box(lo, hi, m.opts);
  } else if (m.raw) {
    w.dims = {hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]};
    w.values.resize(std::size_t(w.voxel_count()));
    read_raw_box(m.data_file(), *m.raw, lo, hi, w.values.data());
  } else {
    w = window_of(m.whole, lo, hi);
  }
  w.dim = 3;
  w.transform = m.frame.transform;
  w.space = m.frame.space;
  w.source = m.frame.source;
  w.source_type = m.frame.source_type;
  if (streamed()) check_finite_values(w, m.opts, lo);  // read_volume checked `whole`
  return w;
}

}  // namespace mlfe
