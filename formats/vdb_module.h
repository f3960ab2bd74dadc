// The boundary between libmlfe_formats and libmlfe_openvdb, the module that holds everything
// that touches OpenVDB (formats/openvdb/vdb_module.cpp). OpenVDB is loaded only when a .vdb
// file is read or written: binding libopenvdb's ~57 000 symbols took most of every command's
// start-up (77 ms of `mlfe --version`) whether or not it ever saw a VDB file. Not public API.
#pragma once
#include <mlfe/core/field/scalar_grid.h>
#include <mlfe/formats/volume_read_options.h>

#include <cstddef>
#include <string>
#include <vector>

namespace mlfe::volume_detail {

/// What the module offers. `abi` and the struct sizes guard against a module built from other
/// sources than the library that loads it (both are installed side by side).
struct VdbFunctions {
  int abi;
  std::size_t grid_size, options_size;
  ScalarGrid (*read)(const std::string& path, const VolumeReadOptions& options);
  std::vector<std::string> (*list)(const std::string& path);
  void (*write)(const std::string& path, const ScalarGrid& grid);
};

constexpr int kVdbModuleAbi = 1;

/// The module's file name; it lies beside libmlfe_formats.
constexpr const char* kVdbModuleName = "libmlfe_openvdb.so";

/// Writes `grid` as a .vdb file through the module (formats/vdb_reader.cpp loads it), for the
/// table of volume formats; throws mlfe::Error naming `path` when the module cannot be loaded.
void write_vdb(const std::string& path, const ScalarGrid& grid);

}  // namespace mlfe::volume_detail

/// The module's one exported symbol.
extern "C" const mlfe::volume_detail::VdbFunctions* mlfe_openvdb_functions();
