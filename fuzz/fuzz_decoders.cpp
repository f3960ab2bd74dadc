// libFuzzer entry point for mlfe's own decoders: the hierarchy file reader (read_hierarchy),
// the glTF reader (read_gltf, .glb) and the EXR/PNG reader (read_image, .exr), each through a
// temporary file, the Draco payload decoder (decode_draco) and the bricks' parts a distributed
// worker returns (decode_brick_parts, which must encode back to the same bytes). mlfe::Error is the expected
// outcome for bad input; anything else is a finding.
#include <mlfe/core/base/error.h>
#include <mlfe/formats/brick_parts.h>
#include <mlfe/formats/draco_io.h>
#include <mlfe/formats/gltf_reader.h>
#include <mlfe/formats/hierarchy_io.h>
#include <mlfe/formats/image_reader.h>
#include <unistd.h>

#include <cstdint>
#include <cstdlib>
#include <fstream>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string kind = MLFE_FUZZ_KIND;
  try {
    if (kind == "draco") {
      mlfe::decode_draco(reinterpret_cast<const char*>(data), size, "fuzz input");
    } else if (kind == "brick_parts") {
      const std::string bytes(reinterpret_cast<const char*>(data), size);
      if (mlfe::encode_brick_parts(mlfe::decode_brick_parts(bytes)) != bytes) std::abort();
    } else {
      const std::string ext = kind == "gltf" ? ".glb" : kind == "exr" ? ".exr" : ".mlfeh";
      static const std::string path = "/tmp/mlfe_fuzz_" + kind + "_" + std::to_string(::getpid()) + ext;
      {
        std::ofstream out(path, std::ios::binary | std::ios::trunc);
        out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
      }
      if (kind == "gltf")
        mlfe::read_gltf(path);
      else if (kind == "exr")
        mlfe::read_image(path);
      else {
        // v2 files also decode level prefixes: the reader stops after the sections level k needs.
        const int level = size > 0 ? data[size - 1] % 4 : 0;
        try {
          mlfe::read_hierarchy(path, level);
        } catch (const mlfe::Error&) {
        }
        mlfe::read_hierarchy(path);
      }
    }
  } catch (const mlfe::Error&) {
  }
  return 0;
}
