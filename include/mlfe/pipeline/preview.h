// The preview page (issue #42): one self-contained HTML file that shows a glTF asset in any
// browser opened from disk, no server and no network: three.js's viewer (third_party/three/,
// built into the library), the asset as base64, orbit controls, the list of its structures
// (one per glTF node with a mesh: name, colour, triangles, a visibility toggle), the report's
// figures and, when there is one, a ray-cast image. `mlfe convert --preview` and
// `mlfe.convert(preview=...)` write it.
#pragma once
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace mlfe::pipeline {

/// The extensions a previewed asset may have: the page embeds the glTF as it is.
inline const std::vector<std::string> kPreviewAssetExtensions{".glb", ".gltf"};

struct PreviewContent {
  std::string asset;  ///< the glTF asset (.glb, or .gltf with its buffer embedded), embedded as it is
  /// The figures shown (the convert report: build_report plus "asset"); the page lists the
  /// ones it knows (triangles, errors, timings) and the whole JSON in a fold.
  nlohmann::json report = nlohmann::json::object();
  std::string image;  ///< a PNG shown beside the asset (the ray-cast image); empty: none
  std::string title;  ///< the page's heading, e.g. the input's file name
};

/// Checks before any work that `page` can be written (.html or .htm, its folder exists) and that
/// `asset` is a glTF the page can show; throws mlfe::Error naming the path otherwise.
void check_preview_paths(const std::string& page, const std::string& asset);

/// Writes the preview page to `page` atomically. The page needs WebGL and nothing else; the
/// same content gives the same bytes. Throws mlfe::Error ("<path>: <problem>") when the asset
/// or the image cannot be read (or is not glTF/PNG) and for I/O errors.
void write_preview(const std::string& page, const PreviewContent& content);

}  // namespace mlfe::pipeline
