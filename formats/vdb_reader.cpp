// OpenVDB files through libmlfe_openvdb, loaded on first use (formats/vdb_module.h).
#include <dlfcn.h>
#include <mlfe/formats/vdb_reader.h>

#include <string>

#include "formats/reader_helpers.h"
#include "formats/vdb_module.h"

namespace mlfe {
namespace {

struct LoadedModule {
  const volume_detail::VdbFunctions* functions = nullptr;
  std::string problem;  ///< why it could not be loaded
};

#ifndef MLFE_OPENVDB_LINKED
// This library's own folder: the module is installed beside it (lib/, the build tree's
// formats/, or the Python package), so neither the executable's RPATH nor LD_LIBRARY_PATH has
// to name it.
std::string own_folder() {
  Dl_info info{};
  if (dladdr(reinterpret_cast<void*>(&own_folder), &info) == 0 || info.dli_fname == nullptr) return "";
  const std::string self = info.dli_fname;
  const auto slash = self.rfind('/');
  return slash == std::string::npos ? "" : self.substr(0, slash + 1);
}
#endif

LoadedModule load_module() {
  LoadedModule m;
#ifdef MLFE_OPENVDB_LINKED
  // Linked in (the fuzzers): no module file.
  m.functions = mlfe_openvdb_functions();
#else
  const std::string beside = own_folder() + volume_detail::kVdbModuleName;
  // RTLD_LOCAL: OpenVDB's symbols serve the module only.
  void* handle = dlopen(beside.c_str(), RTLD_NOW | RTLD_LOCAL);
  if (!handle) handle = dlopen(volume_detail::kVdbModuleName, RTLD_NOW | RTLD_LOCAL);
  if (!handle) {
    const char* why = dlerror();
    m.problem =
        std::string("OpenVDB support is not installed (") + (why ? why : volume_detail::kVdbModuleName) + ")";
    return m;
  }
  using Entry = const volume_detail::VdbFunctions* (*)();
  const auto entry = reinterpret_cast<Entry>(dlsym(handle, "mlfe_openvdb_functions"));
  if (!entry) {
    m.problem = std::string("OpenVDB support is broken: ") + beside + " has no entry point";
    return m;
  }
  m.functions = entry();
#endif
  const auto* f = m.functions;
  if (f->abi != volume_detail::kVdbModuleAbi || f->grid_size != sizeof(ScalarGrid) ||
      f->options_size != sizeof(VolumeReadOptions)) {
    m.functions = nullptr;
    m.problem = "OpenVDB support is broken: libmlfe_openvdb.so is from another build of mlfe";
  }
  return m;
}

// The module, loaded once (the handle stays open for the process); names `path` if it cannot be.
const volume_detail::VdbFunctions& module_for(const std::string& path) {
  static const LoadedModule module = load_module();
  if (!module.functions) volume_detail::fail(path, module.problem);
  return *module.functions;
}

}  // namespace

ScalarGrid read_vdb(const std::string& path, const VolumeReadOptions& opts) {
  return module_for(path).read(path, opts);
}

std::vector<std::string> list_vdb_grids(const std::string& path) { return module_for(path).list(path); }

namespace volume_detail {
void write_vdb(const std::string& path, const ScalarGrid& grid) { module_for(path).write(path, grid); }
}  // namespace volume_detail

}  // namespace mlfe
