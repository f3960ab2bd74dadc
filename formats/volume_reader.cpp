// read_volume: detects a file's format with the table of volume formats
// (formats/volume_formats.cpp) and calls that row's reader, then checks what every reader
// returns.
#include <fmt/format.h>
#include <mlfe/core/base/vec.h>
#include <mlfe/formats/tet_mesh_reader.h>
#include <mlfe/formats/volume_reader.h>
#include <mlfe/formats/zarr_reader.h>
#include <sys/stat.h>

#include <cctype>
#include <cmath>
#include <new>

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

void check_finite_values(ScalarGrid& grid, const VolumeReadOptions& opts) {
  std::int64_t bad = 0, first = -1;
  for (std::size_t i = 0; i < grid.values.size(); ++i) {
    if (!std::isfinite(grid.values[i])) {
      if (first < 0) first = static_cast<std::int64_t>(i);
      ++bad;
      if (opts.nan_as) grid.values[i] = static_cast<float>(*opts.nan_as);
    }
  }
  if (bad == 0) return;
  const std::int64_t nx = grid.dims[0], ny = grid.dims[1];
  std::int64_t fi = first % nx, fj = (first / nx) % ny, fk = first / (nx * ny);
  if (!opts.nan_as)
    throw Error(
        fmt::format("{}: {} voxels are NaN or infinite (first at index {},{},{}); use --nan-as VALUE "
                    "to replace them",
                    grid.source, bad, fi, fj, fk));
  add_note(grid, fmt::format("{} NaN/Inf voxels replaced by {}", bad, *opts.nan_as));
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
  try {
    const VolumeFormatRow* row = volume_format(format);
    if (!row) fail(path, "unsupported format " + format);
    grid = row->read(path, opts);
  } catch (const Error&) {
    throw;
  } catch (const std::bad_alloc&) {
    fail(path, "out of memory while reading");
  } catch (const std::exception& e) {
    fail(path, e.what());
  }
  grid.format = format;
  grid.source = path;
  if (grid.dims[2] == 1) grid.dim = 2;
  if (static_cast<std::int64_t>(grid.values.size()) != grid.voxel_count())
    fail(path, "internal error: voxel count does not match dimensions");
  check_transform(grid);
  check_finite_values(grid, opts);
  convert_space(grid, opts.space);
  return grid;
}

}  // namespace mlfe
