// The bytes a worker of a distributed bricked conversion sends back (mlfe.distributed): one
// brick's parts (core/simplify/bricked_iso_surface.h), one per iso-value, and the range of the
// samples its window held.
//
// Layout, little-endian: "MLFEBRK2", u64 brick, f32 lo, f32 hi, u32 surfaces; per surface: u64
// extracted_triangles, u32 vertices, u32 triangles, u8 has_normals, u32 points, u32 face
// vertices, then positions (3 f32 per vertex), normals (likewise, when present), triangles
// (3 u32), the face vertices (u32, ascending), their places (3 i32 and an i32 axis each), points
// (3 f32) and their faces (u32). ("MLFEBRK1" gave every vertex a place.)
#pragma once
#include <mlfe/core/simplify/bricked_iso_surface.h>

#include <cstddef>
#include <string>
#include <vector>

namespace mlfe {

/// One brick's passes as a worker returns them.
struct BrickParts {
  std::size_t brick = 0;
  float lo = 0, hi = 0;             ///< the range of the window's samples
  std::vector<BrickPart> surfaces;  ///< one per iso-value, in the order asked
};

/// The bytes of `p`; decode_brick_parts(encode_brick_parts(p)) equals p to the bit.
std::string encode_brick_parts(const BrickParts& p);

/// The parts encoded in `bytes`. Throws mlfe::Error("brick parts: ...") for bytes that are not
/// exactly one encoding (wrong magic, truncated, trailing bytes, counts that do not fit, a
/// triangle or point-face index out of range, face vertices not ascending vertices).
BrickParts decode_brick_parts(const std::string& bytes);

}  // namespace mlfe
