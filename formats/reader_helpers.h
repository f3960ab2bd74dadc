// Helpers shared by the readers in formats/*_reader.cpp (formats/reader_helpers.cpp): errors,
// bounded file reading, overflow and memory checks, value conversion. Not part of the public API.
#pragma once
#include <mlfe/core/base/error.h>
#include <mlfe/core/field/scalar_grid.h>
#include <mlfe/formats/safe_read.h>
#include <mlfe/formats/volume_read_options.h>

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace mlfe::volume_detail {

/// Throws mlfe::Error("<path>: <problem>"), with line breaks in `problem` turned into "; ".
[[noreturn]] void fail(const std::string& path, const std::string& problem);

bool host_is_little_endian();

/// nx*ny*nz after checking every dim is in 1..2^31-1 and the product does not overflow a
/// 63-bit byte count even for 8-byte voxels; throws naming the offending dims otherwise.
std::int64_t checked_voxel_count(const std::string& path, const std::array<std::int64_t, 3>& dims);
/// voxels * element_size, overflow-checked (throws).
std::uint64_t checked_bytes(const std::string& path, std::int64_t voxels, std::uint64_t element_size);
/// The limit for opts (max_bytes or default_memory_limit()).
std::uint64_t memory_limit(const VolumeReadOptions& opts);
/// Throws "<path>: needs N bytes for WHAT but only M bytes of memory are available" when
/// `bytes` exceeds `limit`.
void check_memory(const std::string& path, std::uint64_t bytes, std::uint64_t limit, const std::string& what);
/// The same against the memory limit of opts.
void check_memory(const std::string& path, std::uint64_t bytes, const VolumeReadOptions& opts,
                  const std::string& what);

/// Converts n values of type t (native order unless swap) from src into dst.
void convert_to_float(const void* src, ScalarType t, bool swap, float* dst, std::size_t n);

/// Sets spacing (column lengths) and direction (unit columns) from three axis vectors, each
/// the physical step of one index axis. Throws for zero or non-finite axes.
void set_axes(const std::string& path, GridTransform& t, const std::array<std::array<double, 3>, 3>& axes);

/// Allocates grid.values for dims (which must already be checked).
void allocate_values(ScalarGrid& grid);

/// Appends a line to grid.notes.
void add_note(ScalarGrid& grid, const std::string& note);

/// Joins a path relative to the folder of `base` (absolute `name` is returned unchanged).
std::string sibling_path(const std::string& base, const std::string& name);

}  // namespace mlfe::volume_detail
