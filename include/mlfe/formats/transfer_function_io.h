// ParaView colour map / opacity exports (File → Export in the Color Map Editor: a JSON array
// of presets) read as mlfe transfer functions, so users bring the ones they already have.
//
// Read from the first preset of the array (or a single object): "RGBPoints" = [x, r, g, b, …]
// (data values, linear RGB in [0, 1]) and "Points" = [x, opacity, midpoint, sharpness, …].
// Only linear opacity segments (midpoint 0.5, sharpness 0, ParaView's default) are accepted:
// other values would need ParaView's Hermite-shaped segments. "Name" becomes the name.
//
// Written: the record of a transfer function that rendered images carry, beside the reader so
// that a new field of TransferFunction is read and recorded in one file.
#pragma once
#include <mlfe/core/render/transfer_function.h>

#include <string>

namespace mlfe {

/// Reads `path` as above; opacities refer to slabs `unit_length` thick (ParaView's "scalar
/// opacity unit distance", 1 by default). Throws mlfe::Error ("<path>: <problem>") for
/// unreadable files, invalid JSON, missing or malformed arrays, non-linear opacity segments,
/// or values that fail TransferFunction::validate.
TransferFunction read_paraview_transfer_function(const std::string& path, double unit_length = 1.0);

/// The record of `tf` that rendered images carry (OpenEXR attribute mlfe/transferFunction):
/// compact JSON {"RGBPoints": [[value, r, g, b], ...], "name": ..., "opacityPoints": [[value,
/// opacity], ...], "opacityUnitLength": ...}, keys sorted, so the same function gives the same text.
std::string transfer_function_record(const TransferFunction& tf);

}  // namespace mlfe
