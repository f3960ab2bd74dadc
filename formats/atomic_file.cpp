#include <mlfe/core/error.h>
#include <mlfe/formats/atomic_file.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>

namespace mlfe {

std::string temporary_path_for(const std::string& path) {
  std::filesystem::path p(path);
  std::string name = ".tmp-" + std::to_string(::getpid()) + "-" + p.filename().string();
  return (p.parent_path() / name).string();
}

void write_path_atomically(const std::string& path, const std::function<bool(const std::string&)>& write) {
  const std::string tmp = temporary_path_for(path);
  bool ok = false;
  try {
    ok = write(tmp);
  } catch (...) {
    std::remove(tmp.c_str());
    throw;
  }
  if (!ok) {
    std::remove(tmp.c_str());
    throw Error(path + ": cannot write file");
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    std::remove(tmp.c_str());
    throw Error(path + ": cannot create file (" + ec.message() + ")");
  }
}

void write_file_atomically(const std::string& path, const std::function<void(std::ostream&)>& write) {
  write_path_atomically(path, [&](const std::string& tmp) {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) throw Error(path + ": cannot create file");
    write(out);
    out.flush();
    if (!out) throw Error(path + ": write failed (disk full?)");
    return true;
  });
}

}  // namespace mlfe
