// Draco compression of triangle meshes (.drc files and the payload of glTF's
// KHR_draco_mesh_compression). Positions are quantized on an explicit grid so that several
// surfaces encoded with the same DracoOptions box land on the same grid points: shared
// boundaries stay crack-free after decoding.
#pragma once
#include <mlfe/core/surface/triangle_mesh.h>

#include <array>
#include <cstddef>
#include <string>
#include <vector>

namespace mlfe {

struct DracoOptions {
  /// Largest allowed distance per coordinate between an input and a decoded position, in the
  /// mesh's units (millimetres for .drc files, metres inside glTF). Must be > 0.
  double tolerance = 0.01;
  /// Octahedral quantization bits for normals (Draco accepts 1..30; 10 is visually lossless).
  int normal_bits = 10;
  /// Draco speed 0 (smallest) .. 10 (fastest, sequential coding), for encoder and decoder.
  /// 3 is Draco's own default (draco_encoder -cl 7): its predictive edgebreaker made the
  /// skull's simplified surfaces 25 % smaller than speed 5 did, at a still fast decode.
  int speed = 3;
  /// Quantization box shared by every mesh of a scene: the cube [box_min, box_min + box_range].
  /// Every position must lie inside it. box_range <= 0 means "use the mesh's own bounding box".
  std::array<float, 3> box_min{0.0f, 0.0f, 0.0f};
  float box_range = 0.0f;
};

/// Smallest number of quantization bits in [8, 30] such that the rounding error of a grid of
/// 2^bits-1 steps over box_range, box_range / (2^bits - 1) / 2, is <= tolerance; 30 when even
/// 30 bits are not enough (encode_draco then fails its verification). Throws mlfe::Error when
/// tolerance <= 0 or either argument is not finite.
int quantization_bits_for(double tolerance, double box_range);

/// A verified encoding plus what glTF needs to describe it.
struct DracoEncoding {
  std::vector<char> bytes;
  int position_unique_id = -1;  ///< Draco attribute unique id of POSITION
  int normal_unique_id = -1;    ///< of NORMAL; -1 when the mesh has no normals
  int quantization_bits = 0;    ///< position bits actually used
  /// The mesh as a decoder returns it. Draco reorders vertices and triangles and may split
  /// non-manifold vertices, so counts and order differ from the input; glTF accessors must
  /// describe this mesh, not the input.
  TriangleMesh decoded;
};

/// Encodes `mesh` and decodes the result again to verify it: same triangle count (after
/// dropping degenerate triangles, see below) and every decoded triangle lies within
/// `tolerance` of an input triangle, corner by corner. Triangles with two equal corner
/// positions are dropped before encoding, because Draco's Edgebreaker drops them itself and the
/// count check would otherwise be meaningless. Throws mlfe::Error ("Draco encoding: ...") on
/// invalid options, indices out of range, non-finite coordinates, positions outside an explicit
/// box, a mesh without non-degenerate triangles, an encoder failure or a failed verification.
DracoEncoding encode_draco_verified(const TriangleMesh& mesh, const DracoOptions& options);

/// The same, consuming `mesh` (left empty): its arrays are released as the encoder takes them,
/// so a big mesh is not held beside the encoder's tables (several times its size).
DracoEncoding encode_draco_verified(TriangleMesh&& mesh, const DracoOptions& options);

/// encode_draco_verified(mesh, options).bytes.
std::vector<char> encode_draco(const TriangleMesh& mesh, const DracoOptions& options);

/// The grid a Draco payload quantized its positions on, as the payload states it: 2^bits - 1
/// steps of range / (2^bits - 1) per axis from `min`.
struct DracoQuantization {
  int bits = 0;  ///< 0: positions stored as they are (not quantized)
  std::array<float, 3> min{0.0f, 0.0f, 0.0f};
  float range = 0.0f;
  /// The grid step in the positions' units, 0 when not quantized. A decoded coordinate lies
  /// within step() / 2 of the encoder's input.
  double step() const;
};

/// Decodes a Draco mesh. Normals are returned when the payload has a 3-component NORMAL
/// attribute. `quantization` (optional) receives the positions' grid. Throws
/// mlfe::Error("<what_for_errors>: ...") for truncated or corrupt data, point clouds, missing
/// positions or indices out of range; never reads outside [data, data+size).
TriangleMesh decode_draco(const char* data, std::size_t size, const std::string& what_for_errors,
                          DracoQuantization* quantization = nullptr);

/// Writes encode_draco(mesh, options) to `path` atomically (no file is left on failure).
/// A .drc file is one Draco mesh: the encoder's tables (about 5 times the mesh, beside Draco's
/// own copy of it) cannot be cut down the way write_gltf cuts a big level into pieces.
/// Errors are mlfe::Error prefixed with `path`.
/// `mesh` is taken by value: a temporary is consumed rather than copied (as the && overload).
void write_draco_file(const std::string& path, TriangleMesh mesh, const DracoOptions& options);

/// Reads a .drc file written by write_draco_file or draco_encoder; `quantization` as in
/// decode_draco. Throws mlfe::Error on unreadable or corrupt files.
TriangleMesh read_draco_file(const std::string& path, DracoQuantization* quantization = nullptr);

}  // namespace mlfe
