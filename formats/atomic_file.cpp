#include <fcntl.h>
#include <mlfe/core/base/check.h>
#include <mlfe/core/base/error.h>
#include <mlfe/formats/atomic_file.h>
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <set>
#include <utility>
#include <vector>

namespace mlfe {
namespace {

namespace fs = std::filesystem;

constexpr const char* kPrefix = ".tmp-mlfe-";

struct BatchState {
  std::mutex mutex;
  bool active = false;
  std::vector<std::pair<std::string, std::string>> pending;  // temporary, target
  std::set<std::string> swept;                               // folders already cleaned
};

BatchState& state() {
  static BatchState s;
  return s;
}

// A temporary whose writer was killed (kill -9, power loss) stays; the pid in its name tells
// whether that writer can still be running. A reused pid only delays the clean-up.
void remove_stale_temporaries(const fs::path& folder) {
  {
    std::lock_guard<std::mutex> lock(state().mutex);
    if (!state().swept.insert(folder.string()).second) return;
  }
  std::error_code ec;
  fs::directory_iterator it(folder.empty() ? fs::path(".") : folder, ec);
  if (ec) return;
  for (const auto& entry : it) {
    const std::string name = entry.path().filename().string();
    if (name.rfind(kPrefix, 0) != 0) continue;
    const char* digits = name.c_str() + std::strlen(kPrefix);
    char* end = nullptr;
    const long pid = std::strtol(digits, &end, 10);
    if (end == digits || *end != '-' || pid <= 0 || pid == ::getpid()) continue;
    if (::kill(static_cast<pid_t>(pid), 0) == -1 && errno == ESRCH) fs::remove(entry.path(), ec);
  }
}

std::string errno_text(int e) { return std::strerror(e); }

// Whatever the library reported, the data must reach the disk: a write-back error (ENOSPC on a
// full disk, EIO) shows up in fsync or close at the latest.
void sync_file(const std::string& path, const std::string& tmp) {
  const int fd = ::open(tmp.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw Error(path + ": cannot write file (" + errno_text(errno) + ")");
  const bool synced = ::fsync(fd) == 0 || errno == EINVAL;  // EINVAL: a file system without fsync
  const int sync_errno = errno;
  const bool closed = ::close(fd) == 0;
  if (!synced) throw Error(path + ": write failed (" + errno_text(sync_errno) + ")");
  if (!closed) throw Error(path + ": write failed (" + errno_text(errno) + ")");
}

void rename_onto(const std::string& path, const std::string& tmp, const std::string& target) {
  struct stat st {};
  // An existing output keeps its permission bits (a private 600 file stays private).
  if (::stat(target.c_str(), &st) == 0) ::chmod(tmp.c_str(), st.st_mode & 07777);
  std::error_code ec;
  fs::rename(tmp, target, ec);
  if (ec) {
    std::remove(tmp.c_str());
    throw Error(path + ": cannot create file (" + ec.message() + ")");
  }
}

void finish(const std::string& path, const std::string& tmp, const std::string& target) {
  try {
    sync_file(path, tmp);
  } catch (...) {
    std::remove(tmp.c_str());
    throw;
  }
  {
    std::lock_guard<std::mutex> lock(state().mutex);
    if (state().active) {
      for (const auto& p : state().pending)
        if (p.second == target) {
          std::remove(tmp.c_str());
          throw Error(path + ": written twice in one run (two outputs on one path)");
        }
      state().pending.emplace_back(tmp, target);
      return;
    }
  }
  rename_onto(path, tmp, target);
}

}  // namespace

std::string output_target(const std::string& path) {
  fs::path p(path);
  for (int hops = 0; hops < 40; ++hops) {
    std::error_code ec;
    const fs::file_status st = fs::symlink_status(p, ec);
    if (!fs::is_symlink(st)) {
      if (fs::exists(st) && !fs::is_regular_file(st))
        throw Error(path + ": exists and is not a regular file");
      return p.string();
    }
    const fs::path to = fs::read_symlink(p, ec);
    if (ec) throw Error(path + ": cannot read the symbolic link (" + ec.message() + ")");
    p = to.is_absolute() ? to : p.parent_path() / to;
  }
  throw Error(path + ": too many levels of symbolic links");
}

std::string written_file_path(const std::string& path) {
  const std::string target = output_target(path);
  std::lock_guard<std::mutex> lock(state().mutex);
  for (const auto& p : state().pending)
    if (p.second == target) return p.first;
  return target;
}

std::uint64_t written_file_size(const std::string& path) { return fs::file_size(written_file_path(path)); }

std::string temporary_path_for(const std::string& path) {
  fs::path p(path);
  const std::string file = p.filename().string();
  const std::string start = kPrefix + std::to_string(::getpid()) + "-";
  // A name may have 255 bytes (NAME_MAX): a valid output name of 250 could not be written under
  // the prefix. A long name is replaced by its hash and as much of its end (the extension the
  // libraries look at) as fits.
  constexpr std::size_t kNameMax = 255, kHashDigits = 16;
  if (start.size() + file.size() <= kNameMax) return (p.parent_path() / (start + file)).string();
  std::uint64_t hash = 14695981039346656037ull;  // FNV-1a
  for (const char c : file) hash = (hash ^ static_cast<unsigned char>(c)) * 1099511628211ull;
  std::size_t from = file.size() - (kNameMax - start.size() - kHashDigits - 1);
  while (from < file.size() && (static_cast<unsigned char>(file[from]) & 0xC0) == 0x80) ++from;  // UTF-8
  char digits[kHashDigits + 1];
  std::snprintf(digits, sizeof digits, "%016llx", static_cast<unsigned long long>(hash));
  return (p.parent_path() / (start + digits + "-" + file.substr(from))).string();
}

void write_path_atomically(const std::string& path, const std::function<bool(const std::string&)>& write) {
  const std::string target = output_target(path);
  remove_stale_temporaries(fs::path(target).parent_path());
  const std::string tmp = temporary_path_for(target);
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
  finish(path, tmp, target);
}

void write_file_atomically(const std::string& path, const std::function<void(std::ostream&)>& write) {
  write_path_atomically(path, [&](const std::string& tmp) {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) throw Error(path + ": cannot create file (" + errno_text(errno) + ")");
    write(out);
    out.flush();
    if (!out) throw Error(path + ": write failed (disk full?)");
    out.close();
    if (out.fail()) throw Error(path + ": write failed (disk full?)");
    return true;
  });
}

OutputBatch::OutputBatch() {
  std::lock_guard<std::mutex> lock(state().mutex);
  MLFE_CHECK(!state().active);
  state().active = true;
  state().pending.clear();
}

OutputBatch::~OutputBatch() {
  std::lock_guard<std::mutex> lock(state().mutex);
  for (const auto& p : state().pending) std::remove(p.first.c_str());
  state().pending.clear();
  state().active = false;
}

bool OutputBatch::active() {
  std::lock_guard<std::mutex> lock(state().mutex);
  return state().active;
}

void OutputBatch::commit() {
  std::vector<std::pair<std::string, std::string>> pending;
  {
    std::lock_guard<std::mutex> lock(state().mutex);
    pending.swap(state().pending);
    state().active = false;
  }
  for (std::size_t i = 0; i < pending.size(); ++i) {
    try {
      rename_onto(pending[i].second, pending[i].first, pending[i].second);
    } catch (...) {
      for (std::size_t j = i + 1; j < pending.size(); ++j) std::remove(pending[j].first.c_str());
      throw;
    }
  }
}

}  // namespace mlfe
