// NRRD volumes and height fields (.nrrd with attached data, .nhdr with detached data) via Teem.
#pragma once
#include <mlfe/core/field/scalar_grid.h>
#include <mlfe/formats/raw_reader.h>
#include <mlfe/formats/volume_read_options.h>

#include <optional>
#include <string>

namespace mlfe {

/// Reads a 2D or 3D scalar NRRD (raw, gzip, bzip2, ascii, hex encodings as Teem supports them).
/// The transform comes from "space directions"/"space origin" when present (space
/// right-anterior-superior / left-posterior-superior set ScalarGrid::space; left-anterior-
/// superior is converted to RAS), otherwise from "spacings" and "axis mins". The header is read
/// first without data, so dims, type and sizes are checked against the file size and the memory
/// limit before Teem allocates. Teem's messages (biff) become the mlfe::Error text.
ScalarGrid read_nrrd(const std::string& path, const VolumeReadOptions& opts);

/// read_nrrd's header checks (all but the memory limit) without reading the voxels, and where
/// they lie when read_raw_box can read them: raw or gzip data in the file itself or in one data
/// file, no "line skip" (nor a "byte skip" for gzip), a header whose lines end with '\n' only.
/// nullopt for the rest (bzip2, ascii, hex, several data files), which read_nrrd reads whole.
std::optional<RawLayout> nrrd_layout(const std::string& path, const VolumeReadOptions& opts);

}  // namespace mlfe
