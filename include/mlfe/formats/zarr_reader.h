// OME-Zarr 0.4 images (Zarr v2 arrays in a folder), read box by box.
//
// OME-NGFF 0.4 (https://ngff.openmicroscopy.org/0.4/): the image folder's `.zattrs` holds
// "multiscales" (axes, and per resolution level a dataset path with its coordinate
// transformations, scale then optional translation); each level is a Zarr v2 array (`.zarray`:
// shape, chunks, dtype, compressor, fill_value, order, dimension_separator) whose chunks are files
// named by their chunk indices ("0.1.2" or "0/1/2"). A plain Zarr v2 array folder (`.zarray`
// only) reads as one level with unit scale.
//
// What mlfe takes from it:
//   - axes: the last two or three are space axes (y, x or z, y, x); time and channel axes before
//     them must have size 1 (mlfe approximates one scalar field);
//   - frame: physical = scale * index + translation per axis (level's transformations, then the
//     multiscale's), converted to millimetres from the axes' units (micrometer, nanometer, ...;
//     none or unknown: taken as millimetres, with a note); the direction is the identity and the
//     space unnamed (OME-Zarr names no anatomical orientation);
//   - dtypes: |b1 is refused; u1 i1 u2 i2 u4 i4 f4 f8 in either byte order;
//   - compressors: none, blosc (lz4, lz4hc, blosclz, zstd, zlib inside; libblosc), zlib, gzip and
//     zstd; filters are refused;
//   - order "C" only; missing chunk files read as fill_value (the Zarr rule for chunks a writer
//     skipped because they held only fill_value), and a store without a fill_value refuses them.
// Every chunk is checked before use: its file is regular and bounded, its decoded size is exactly
// the chunk's (a lying shape or truncated chunk is an error naming the chunk file).
#pragma once
#include <mlfe/core/field/scalar_grid.h>
#include <mlfe/formats/volume_read_options.h>

#include <array>
#include <cstdint>
#include <memory>
#include <string>

namespace mlfe {

/// True when `path` is a folder holding a `.zattrs` with "multiscales" or a `.zarray`.
bool is_zarr_store(const std::string& path);

/// One resolution level of an OME-Zarr image, open for reading boxes of it. Reading holds only
/// the box's values and the chunks being decoded, never the whole level. Thread-safe for
/// concurrent read_box calls.
class ZarrVolume {
 public:
  /// Opens resolution level `level` (0 = full resolution) of the image at `path`. Throws
  /// mlfe::Error naming the store (or its metadata file) and the problem for a bad store.
  explicit ZarrVolume(const std::string& path, int level = 0);
  ~ZarrVolume();
  ZarrVolume(ZarrVolume&&) noexcept;
  ZarrVolume& operator=(ZarrVolume&&) noexcept;

  /// nx, ny, nz of the level (nz == 1 for a 2D image).
  const std::array<std::int64_t, 3>& dims() const;
  /// The level's index-to-physical transform in millimetres.
  const GridTransform& transform() const;
  /// The stored value type.
  ScalarType type() const;
  /// How many resolution levels the image has.
  int levels() const;
  /// Lines saying what was assumed or converted (units), for ScalarGrid::notes.
  const std::string& notes() const;

  /// The values of the voxel box [lo, hi) as a grid whose transform places it where it lies in
  /// the level (origin moved to lo). Decodes only the chunks the box meets (in parallel; the
  /// result does not depend on the thread count). Throws mlfe::Error for a box outside the level,
  /// a bad chunk, or when the box would need more memory than opts allows.
  ScalarGrid read_box(const std::array<std::int64_t, 3>& lo, const std::array<std::int64_t, 3>& hi,
                      const VolumeReadOptions& opts) const;

  struct Impl;  ///< the parsed metadata (formats/zarr_reader.cpp)

 private:
  std::unique_ptr<Impl> impl_;
};

/// The whole level opts.zarr_level of the store at `path` as read_volume's reader.
ScalarGrid read_zarr(const std::string& path, const VolumeReadOptions& opts);

}  // namespace mlfe
