// mlfe::pipeline::write_preview (<mlfe/pipeline/preview.h>): the preview page. The viewer's
// scripts (third_party/three/, see scripts/vendor_three.sh) are compiled into the library by
// cmake/embed_files.cmake; the page carries them, the asset and the image as base64, so it
// opens from disk (file://), where a browser fetches nothing beside the page.
#include <mlfe/core/base/error.h>
#include <mlfe/formats/atomic_file.h>
#include <mlfe/formats/file_names.h>
#include <mlfe/formats/safe_read.h>
#include <mlfe/pipeline.h>
#include <mlfe/pipeline/preview.h>
#include <mlfe/version.h>

#include <algorithm>
#include <cstddef>
#include <cstring>
#include <ostream>
#include <string_view>

namespace mlfe::pipeline {
namespace detail {
// Defined in the source generated from third_party/three/ (converters/CMakeLists.txt).
extern const unsigned char kThreeViewerJs[], kThreeLicense[], kThreeVersions[], kDracoWrapperJs[],
    kDracoDecoderWasm[];
extern const std::size_t kThreeViewerJs_size, kThreeLicense_size, kThreeVersions_size, kDracoWrapperJs_size,
    kDracoDecoderWasm_size;
}  // namespace detail

namespace {

// Larger assets would make a page no browser opens comfortably.
constexpr std::uint64_t kMaxEmbeddedBytes = std::uint64_t(1) << 30;

std::string base64(std::string_view bytes) {
  static constexpr char kDigits[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  std::size_t i = 0;
  for (; i + 3 <= bytes.size(); i += 3) {
    const auto v = std::uint32_t(std::uint8_t(bytes[i])) << 16 |
                   std::uint32_t(std::uint8_t(bytes[i + 1])) << 8 | std::uint32_t(std::uint8_t(bytes[i + 2]));
    for (int s = 18; s >= 0; s -= 6) out += kDigits[(v >> s) & 63];
  }
  if (const std::size_t left = bytes.size() - i; left > 0) {
    std::uint32_t v = std::uint32_t(std::uint8_t(bytes[i])) << 16;
    if (left == 2) v |= std::uint32_t(std::uint8_t(bytes[i + 1])) << 8;
    out += kDigits[(v >> 18) & 63];
    out += kDigits[(v >> 12) & 63];
    out += left == 2 ? kDigits[(v >> 6) & 63] : '=';
    out += '=';
  }
  return out;
}

std::string_view embedded(const unsigned char* data, std::size_t size) {
  return {reinterpret_cast<const char*>(data), size};
}

// Text inside an HTML comment: "--" cannot end it early.
std::string html_comment(std::string_view text) {
  std::string out(text);
  for (std::size_t i = out.find("--"); i != std::string::npos; i = out.find("--", i))
    out.replace(i, 2, "- -");
  return out;
}

// Text inside an HTML element: nothing the parser could read as markup.
std::string html_text(const std::string& s) {
  std::string out;
  for (char c : s) {
    if (c == '<')
      out += "&lt;";
    else if (c == '>')
      out += "&gt;";
    else if (c == '&')
      out += "&amp;";
    else
      out += c;
  }
  return out;
}

// JSON inside <script type="application/json">: "</" written as the JSON escape "<\/", so no
// string in it (a file name) can close the element.
std::string script_json(const nlohmann::json& j) {
  const std::string text = j.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
  std::string out;
  for (std::size_t i = 0; i < text.size(); ++i) {
    out += text[i];
    if (text[i] == '<' && i + 1 < text.size() && text[i + 1] == '/') out += '\\';
  }
  return out;
}

// The page: styles, the side panel, the data blocks (filled by write_preview) and the script
// that shows them. Figures the report lacks are left out, so one page serves iso-surfaces and
// label maps.
constexpr std::string_view kPageHead = R"PAGE(<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<style>
html, body { margin: 0; height: 100%; font: 13px system-ui, sans-serif; background: #1e1f22; color: #ddd; }
#side { position: absolute; left: 0; top: 0; bottom: 0; width: 320px; overflow: auto; padding: 10px;
  box-sizing: border-box; background: #27282c; }
#view { position: absolute; left: 320px; right: 0; top: 0; bottom: 0; }
h1 { font-size: 15px; margin: 0 0 6px; word-break: break-all; }
h2 { font-size: 13px; margin: 14px 0 6px; color: #aab; }
table { border-collapse: collapse; width: 100%; }
td { padding: 2px 4px; vertical-align: top; }
td.v { text-align: right; font-variant-numeric: tabular-nums; }
.swatch { display: inline-block; width: 12px; height: 12px; border: 1px solid #0008; vertical-align: middle; }
#status.bad { color: #f88; }
img { max-width: 100%; }
pre { font-size: 11px; white-space: pre-wrap; word-break: break-all; }
.note { color: #889; }
</style>
)PAGE";

constexpr std::string_view kPageBody = R"PAGE(</head>
<body>
<div id="side">
<h1 id="title"></h1>
<div id="status">loading the asset…</div>
<h2>Structures</h2>
<div><button id="show-all">show all</button> <button id="hide-all">hide all</button></div>
<table id="structures"></table>
<h2>Figures</h2>
<table id="figures"></table>
<div id="image-box" hidden><h2>Ray-cast image</h2><img id="image" alt="ray-cast image"></div>
<details><summary>Report (JSON)</summary><pre id="report"></pre></details>
<p class="note">Drag to orbit, wheel to zoom, right-drag to pan. glTF frame: metres, +Y up.</p>
</div>
<div id="view"></div>
)PAGE";

constexpr std::string_view kPageScript = R"PAGE(<script>
"use strict";
(function () {
  const M = window.MLFE3;
  const $ = (id) => document.getElementById(id);
  const block = (id) => $(id).textContent.trim();
  const status = (text, bad) => { $("status").textContent = text; $("status").className = bad ? "bad" : ""; };
  const bytes = (b64) => Uint8Array.from(atob(b64), (c) => c.charCodeAt(0));
  const report = JSON.parse(block("mlfe-report"));
  $("title").textContent = document.title;
  $("report").textContent = JSON.stringify(report, null, 1);
  showFigures(report);
  if (block("mlfe-image")) {
    $("image").src = "data:image/png;base64," + block("mlfe-image");
    $("image-box").hidden = false;
  }

  function showFigures(r) {
    const a = r.asset || {};
    const n = (x, digits) => (typeof x === "number" ? x.toLocaleString("en", { maximumFractionDigits: digits }) : null);
    const rows = [
      ["triangles", n(a.triangles, 0)],
      ["structures", n(a.structure_count, 0)],
      ["asset bytes", n(a.bytes, 0)],
      ["tolerance (mm)", n(a.tolerance_mm, 4)],
      ["hierarchy vertices", n(r.vertices, 0)],
      ["hierarchy elements", n(r.elements, 0)],
      ["levels", n(r.levels, 0)],
      ["RMS error", n(r.rms_error, 6)],
      ["RMS error (% of range)", n(r.rms_error_percent, 4)],
      ["PSNR (dB)", n(r.psnr_db, 2)],
      ["noise σ", n(r.noise_sigma, 6)],
      ["stop reason", r.stop_reason || null],
      ["build (s)", n(r.seconds, 3)],
      ["asset (s)", n(a.seconds, 3)],
    ];
    for (const [stage, s] of Object.entries(a.stage_seconds || {})) rows.push(["  " + stage + " (s)", n(s, 3)]);
    rows.push(["peak memory (MB)", n(r.peak_rss_mb, 0)]);
    for (const [name, value] of rows) {
      if (value === null || value === undefined) continue;
      const tr = $("figures").insertRow();
      tr.insertCell().textContent = name;
      const v = tr.insertCell();
      v.className = "v";
      v.textContent = value;
    }
  }

  const view = $("view");
  const renderer = new M.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
  renderer.setPixelRatio(window.devicePixelRatio);
  renderer.setSize(view.clientWidth, view.clientHeight);
  view.appendChild(renderer.domElement);
  const scene = new M.Scene();
  scene.background = new M.Color(0x1e1f22);
  const camera = new M.PerspectiveCamera(35, view.clientWidth / view.clientHeight, 1e-4, 1e3);
  const light = new M.DirectionalLight(0xffffff, 2.2);
  light.position.set(0.5, 1, 2);
  camera.add(light);
  scene.add(camera, new M.AmbientLight(0xffffff, 0.7));
  const controls = new M.OrbitControls(camera, renderer.domElement);
  const draw = () => renderer.render(scene, camera);
  controls.addEventListener("change", draw);
  window.addEventListener("resize", () => {
    renderer.setSize(view.clientWidth, view.clientHeight);
    camera.aspect = view.clientWidth / view.clientHeight;
    camera.updateProjectionMatrix();
    draw();
  });

  const draco = new M.DRACOLoader();
  draco.setDecoderPath({
    js: "data:text/javascript;base64," + block("mlfe-draco-js"),
    wasm: "data:application/wasm;base64," + block("mlfe-draco-wasm"),
  });
  const loader = new M.GLTFLoader();
  loader.setDRACOLoader(draco);
  loader.parse(bytes(block("mlfe-asset")).buffer, "", (gltf) => {
    scene.add(gltf.scene);
    const box = new M.Box3().setFromObject(gltf.scene);
    const centre = box.getCenter(new M.Vector3());
    const radius = Math.max(box.getSize(new M.Vector3()).length() / 2, 1e-6);
    camera.near = radius / 100;
    camera.far = radius * 100;
    camera.position.copy(centre).add(new M.Vector3(0, 0, radius / Math.sin((camera.fov * Math.PI) / 360)));
    camera.updateProjectionMatrix();
    controls.target.copy(centre);
    controls.update();
    const meshes = [];
    gltf.scene.traverse((o) => { if (o.isMesh) meshes.push(o); });
    listStructures(meshes, gltf.parser);
    draw();
    const triangles = meshes.reduce((t, m) => t + triangleCount(m), 0);
    status(meshes.length + " structures, " + triangles.toLocaleString("en") + " triangles");
    document.body.dataset.state = "ready";
    draco.dispose();
  }, (error) => {
    status("could not show the asset: " + (error && error.message ? error.message : error), true);
    document.body.dataset.state = "failed";
  });

  function triangleCount(mesh) {
    const g = mesh.geometry;
    return (g.index ? g.index.count : g.attributes.position.count) / 3;
  }

  // The glTF node's own name (three.js renames objects: spaces become underscores).
  function nodeName(object, parser) {
    for (let o = object; o; o = o.parent) {
      const a = parser.associations.get(o);
      if (a && a.nodes !== undefined && parser.json.nodes[a.nodes].name) return parser.json.nodes[a.nodes].name;
    }
    return object.name || "(unnamed)";
  }

  function listStructures(meshes, parser) {
    const boxes = [];
    for (const mesh of meshes) {
      const tr = $("structures").insertRow();
      tr.className = "structure";
      const toggle = document.createElement("input");
      toggle.type = "checkbox";
      toggle.checked = true;
      toggle.addEventListener("change", () => { mesh.visible = toggle.checked; draw(); });
      boxes.push(toggle);
      tr.insertCell().appendChild(toggle);
      const swatch = document.createElement("span");
      swatch.className = "swatch";
      const material = Array.isArray(mesh.material) ? mesh.material[0] : mesh.material;
      swatch.style.background = "#" + material.color.getHexString();
      tr.insertCell().appendChild(swatch);
      tr.insertCell().textContent = nodeName(mesh, parser);
      const count = tr.insertCell();
      count.className = "v";
      count.textContent = triangleCount(mesh).toLocaleString("en");
    }
    const all = (on) => { boxes.forEach((b, i) => { b.checked = on; meshes[i].visible = on; }); draw(); };
    $("show-all").onclick = () => all(true);
    $("hide-all").onclick = () => all(false);
  }
})();
</script>
</body>
</html>
)PAGE";

}  // namespace

void check_preview_paths(const std::string& page, const std::string& asset) {
  check_output_path(page, {".html", ".htm"});
  const std::string ext = lower_extension(asset);
  if (std::find(kPreviewAssetExtensions.begin(), kPreviewAssetExtensions.end(), ext) ==
      kPreviewAssetExtensions.end())
    throw Error(page + ": the preview page shows a glTF asset; " + asset + " is not .glb or .gltf");
}

void write_preview(const std::string& page, const PreviewContent& c) {
  // The files may have been written within an OutputBatch (the command line): read what was written.
  const std::string asset = read_regular_file(written_file_path(c.asset), kMaxEmbeddedBytes, "the asset");
  if (lower_extension(c.asset) == ".glb" ? asset.compare(0, 4, "glTF") != 0
                                         : asset.find('{') == std::string::npos)
    throw Error(c.asset + ": not a glTF asset (the preview page shows .glb and .gltf)");
  std::string image;
  if (!c.image.empty()) {
    image = read_regular_file(written_file_path(c.image), kMaxEmbeddedBytes, "the image");
    if (image.compare(0, 8, "\x89PNG\r\n\x1a\n") != 0) throw Error(c.image + ": not a PNG image");
  }
  write_file_atomically(page, [&](std::ostream& out) {
    // The notices the embedded code's licences ask for.
    out << "<!DOCTYPE html>\n<!--\nThis page embeds "
        << html_comment(embedded(detail::kThreeVersions, detail::kThreeVersions_size))
        << "three.js: MIT licence, below. Draco decoder: Copyright Google LLC, Apache License 2.0,\n"
        << "https://github.com/google/draco.\n\n"
        << html_comment(embedded(detail::kThreeLicense, detail::kThreeLicense_size)) << "-->\n";
    out << kPageHead << "<title>" << html_text(c.title) << "</title>\n"
        << "<meta name=\"generator\" content=\"mlfe " << MLFE_VERSION << "\">\n"
        << kPageBody;
    out << "<script type=\"application/json\" id=\"mlfe-report\">" << script_json(c.report) << "</script>\n";
    out << "<script type=\"text/plain\" id=\"mlfe-asset\">" << base64(asset) << "</script>\n";
    out << "<script type=\"text/plain\" id=\"mlfe-image\">" << base64(image) << "</script>\n";
    out << "<script type=\"text/plain\" id=\"mlfe-draco-js\">"
        << base64(embedded(detail::kDracoWrapperJs, detail::kDracoWrapperJs_size)) << "</script>\n";
    out << "<script type=\"text/plain\" id=\"mlfe-draco-wasm\">"
        << base64(embedded(detail::kDracoDecoderWasm, detail::kDracoDecoderWasm_size)) << "</script>\n";
    // three.js as a data: URL, so its text is never parsed as part of the page.
    out << "<script src=\"data:text/javascript;base64,"
        << base64(embedded(detail::kThreeViewerJs, detail::kThreeViewerJs_size)) << "\"></script>\n";
    out << kPageScript;
  });
}

}  // namespace mlfe::pipeline
