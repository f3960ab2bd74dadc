// The bytes a worker of a distributed bricked conversion sends back (mlfe.distributed): one
// brick's parts (core/simplify/bricked_iso_surface.h), or the pieces of a join of slabs
// (join_slabs), one per iso-value, and the range of the samples their windows held.
//
// Layout, little-endian: "MLFEBRK3", u64 brick, u64 first_slab, u64 end_slab, f32 lo, f32 hi,
// u32 surfaces; per surface: u64
// extracted_triangles, u32 vertices, u32 triangles, u8 has_normals, u32 points, u32 face
// vertices, then positions (3 f32 per vertex), normals (likewise, when present), triangles
// (3 u32), the face vertices (u32, ascending), their places (3 i32 and an i32 axis each), points
// (3 f32) and their faces (u32). ("MLFEBRK1" gave every vertex a place; "MLFEBRK2" held bricks
// only.)
#pragma once
#include <mlfe/core/simplify/bricked_iso_surface.h>

#include <cstddef>
#include <string>
#include <vector>

namespace mlfe {

/// One brick's passes, or one join's pieces, as a worker returns them.
struct BrickParts {
  std::size_t brick = 0;  ///< the brick's index (0 for a join's pieces)
  /// A join's pieces: the slabs [first_slab, end_slab) joined; 0, 0 for a brick's passes.
  std::size_t first_slab = 0, end_slab = 0;
  float lo = 0, hi = 0;             ///< the range of the windows' samples
  std::vector<BrickPart> surfaces;  ///< one per iso-value, in the order asked
};

/// The bytes of `p`; decode_brick_parts(encode_brick_parts(p)) equals p to the bit.
std::string encode_brick_parts(const BrickParts& p);

/// The parts encoded in `bytes`. Throws mlfe::Error("brick parts: ...") for bytes that are not
/// exactly one encoding (wrong magic, truncated, trailing bytes, counts that do not fit, a slab
/// range that is backwards or a join's with a brick index, a
/// triangle or point-face index out of range, face vertices not ascending vertices).
BrickParts decode_brick_parts(const std::string& bytes);

}  // namespace mlfe
