// libFuzzer entry point for one reader: writes the input to a temporary file with the
// extension of MLFE_FUZZ_EXT and reads it with mlfe::read_volume (mlfe::read_tet_mesh for vtu, msh;
// for zarr, a store folder made from the input).
// mlfe::Error is the expected outcome for bad input; anything else (a crash, a sanitizer report, another
// exception, an exit from inside a library) is a finding.
#include <mlfe/core/base/error.h>
#include <mlfe/formats/tet_mesh_reader.h>
#include <mlfe/formats/volume_reader.h>
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>

namespace {

const std::string& work_dir() {
  static const std::string dir = [] {
    char tmpl[] = "/tmp/mlfe_fuzz_XXXXXX";
    if (!mkdtemp(tmpl)) std::abort();
    return std::string(tmpl) + "/";
  }();
  return dir;
}

void write_file(const std::string& path, const std::uint8_t* data, std::size_t size) {
  std::remove(path.c_str());
  std::ofstream out(path, std::ios::binary);
  out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string kind = MLFE_FUZZ_KIND;
  std::string ext = MLFE_FUZZ_EXT;
  // One target covers both variants where the first bytes tell them apart.
  if (kind == "nifti" && size >= 2 && data[0] == 0x1f && data[1] == 0x8b) ext = ".nii.gz";
  if (kind == "image" && size >= 1 && data[0] == 0x89) ext = ".png";
  const std::string path = work_dir() + "input" + ext;
  mlfe::VolumeReadOptions opts;
  opts.max_bytes = std::size_t(256) << 20;  // well below the fuzzer's RSS limit
  if (kind == "raw") {
    // The input is the JSON sidecar of a fixed 512-byte data file.
    static const std::string raw = [] {
      const std::string p = work_dir() + "input.raw";
      std::string bytes(512, '\0');
      for (std::size_t i = 0; i < bytes.size(); ++i) bytes[i] = static_cast<char>(i * 37);
      write_file(p, reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size());
      return p;
    }();
    write_file(raw + ".json", data, size);
    try {
      mlfe::read_volume(raw, opts);
    } catch (const mlfe::Error&) {
    }
    return 0;
  }
  if (kind == "zarr") {
    // The input is a plain Zarr array: its .zarray JSON, a NUL byte, then the bytes of chunk
    // 0.0.0 (also as 0/0/0, for stores with "/" as separator). Other chunks are missing.
    const std::uint8_t* nul = static_cast<const std::uint8_t*>(std::memchr(data, 0, size));
    const std::size_t meta = nul ? static_cast<std::size_t>(nul - data) : size;
    const std::string store = work_dir() + "input.zarr";
    std::filesystem::remove_all(store);
    std::filesystem::create_directories(store + "/0/0");
    write_file(store + "/.zarray", data, meta);
    const std::size_t rest = nul ? size - meta - 1 : 0;
    write_file(store + "/0.0.0", nul ? nul + 1 : data, rest);
    write_file(store + "/0/0/0", nul ? nul + 1 : data, rest);
    try {
      mlfe::read_volume(store, opts);
    } catch (const mlfe::Error&) {
    }
    return 0;
  }
  write_file(path, data, size);
  if (kind == "vtu" || kind == "msh") {
    // A mesh the reader accepts goes on to the field, which checks what the reader leaves to it
    // (flat tetrahedra, a flat box).
    mlfe::TetMeshReadOptions mesh_opts;
    mesh_opts.max_bytes = opts.max_bytes;
    try {
      const mlfe::TetMesh mesh = mlfe::read_tet_mesh(path, mesh_opts);
      const mlfe::TetMeshField field(mesh);
      field.value({0.5, 0.5, 0.5});
      field.range_in_box({0, 0, 0}, field.extent());
    } catch (const mlfe::Error&) {
    }
    return 0;
  }
  try {
    mlfe::read_volume(path, opts);
  } catch (const mlfe::Error&) {
  }
  return 0;
}
