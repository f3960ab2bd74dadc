#include <bzlib.h>
#include <fcntl.h>
#include <fmt/format.h>
#include <mlfe/core/base/error.h>
#include <mlfe/formats/safe_read.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <cerrno>
#include <climits>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <new>

namespace mlfe {
namespace {

[[noreturn]] void fail(const std::string& path, const std::string& problem) {
  throw Error(path + ": " + problem);
}

// The unit in which decoded data is read and buffers first grow.
constexpr std::size_t kChunk = std::size_t(1) << 20;

}  // namespace

RegularFile::RegularFile(const std::string& path) : path_(path) {
  do {
    fd_ = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
  } while (fd_ < 0 && errno == EINTR);
  if (fd_ < 0) fail(path, fmt::format("cannot open ({})", std::strerror(errno)));
  struct stat st {};
  if (::fstat(fd_, &st) != 0 || !S_ISREG(st.st_mode)) {
    ::close(fd_);
    fail(path, "not a regular file");
  }
  size_ = static_cast<std::uint64_t>(st.st_size);
  // Regular files never block; clearing the flag keeps reads plain.
  ::fcntl(fd_, F_SETFL, ::fcntl(fd_, F_GETFL) & ~O_NONBLOCK);
}

RegularFile::~RegularFile() { ::close(fd_); }

void RegularFile::seek(std::uint64_t offset) {
  if (offset > static_cast<std::uint64_t>(INT64_MAX) ||
      ::lseek(fd_, static_cast<off_t>(offset), SEEK_SET) < 0)
    fail(path_, fmt::format("cannot seek to byte {}", offset));
}

std::size_t RegularFile::read(void* dst, std::size_t n) {
  auto* p = static_cast<unsigned char*>(dst);
  std::size_t done = 0;
  while (done < n) {
    const ssize_t got = ::read(fd_, p + done, std::min<std::size_t>(n - done, std::size_t(1) << 30));
    if (got < 0 && errno == EINTR) continue;
    if (got < 0) fail(path_, fmt::format("read error ({})", std::strerror(errno)));
    if (got == 0) break;
    done += static_cast<std::size_t>(got);
  }
  return done;
}

std::size_t RegularFile::read_at(std::uint64_t offset, void* dst, std::size_t n) const {
  auto* p = static_cast<unsigned char*>(dst);
  std::size_t done = 0;
  while (done < n) {
    if (offset + done > static_cast<std::uint64_t>(INT64_MAX)) break;
    const ssize_t got = ::pread(fd_, p + done, std::min<std::size_t>(n - done, std::size_t(1) << 30),
                                static_cast<off_t>(offset + done));
    if (got < 0 && errno == EINTR) continue;
    if (got < 0) fail(path_, fmt::format("read error ({})", std::strerror(errno)));
    if (got == 0) break;
    done += static_cast<std::size_t>(got);
  }
  return done;
}

RegularFile::RegularFile(std::string name, int fd) : path_(std::move(name)), fd_(fd) {}

std::unique_ptr<RegularFile> RegularFile::scratch(const std::string& name) {
  const char* dir = std::getenv("TMPDIR");
  std::string pattern = std::string(dir && *dir ? dir : "/tmp") + "/.mlfe-scratch-XXXXXX";
  const int fd = ::mkostemp(pattern.data(), O_CLOEXEC);
  if (fd < 0)
    fail(name, fmt::format("cannot create its temporary copy in {} ({})", pattern, std::strerror(errno)));
  // Unlinked at once: the space is freed when the descriptor closes, even after kill -9.
  ::unlink(pattern.c_str());
  return std::unique_ptr<RegularFile>(new RegularFile(name, fd));
}

void RegularFile::append(const void* src, std::size_t n) {
  const auto* p = static_cast<const unsigned char*>(src);
  for (std::size_t done = 0; done < n;) {
    const ssize_t put = ::write(fd_, p + done, std::min<std::size_t>(n - done, std::size_t(1) << 30));
    if (put < 0 && errno == EINTR) continue;
    if (put <= 0) fail(path_, fmt::format("cannot write its temporary copy ({})", std::strerror(errno)));
    done += static_cast<std::size_t>(put);
    size_ += static_cast<std::uint64_t>(put);
  }
}

std::uint64_t regular_file_size(const std::string& path) { return RegularFile(path).size(); }

std::string read_file_prefix(const std::string& path, std::size_t n) {
  RegularFile f(path);
  std::string s(static_cast<std::size_t>(std::min<std::uint64_t>(n, f.size())), '\0');
  s.resize(f.read(s.data(), s.size()));
  return s;
}

std::string read_regular_file(const std::string& path, std::uint64_t limit, const std::string& what) {
  RegularFile f(path);
  if (f.size() > limit)
    fail(path, fmt::format("{} has {} bytes, more than the {} allowed", what, f.size(), limit));
  std::string s(static_cast<std::size_t>(f.size()), '\0');
  if (f.read(s.data(), s.size()) != s.size()) fail(path, "read error (file changed while reading?)");
  return s;
}

ByteSource file_source(RegularFile& file) {
  return [&file](unsigned char* dst, std::size_t n) { return file.read(dst, n); };
}

ByteSource memory_source(const void* data, std::size_t n) {
  auto at = std::make_shared<std::size_t>(0);
  const auto* p = static_cast<const unsigned char*>(data);
  return [p, n, at](unsigned char* dst, std::size_t want) {
    const std::size_t m = std::min(want, n - *at);
    std::memcpy(dst, p + *at, m);
    *at += m;
    return m;
  };
}

namespace {

// One decompressor behind decoded_source: zlib's and libbz2's streams have the same shape.
class Decoder {
 public:
  Decoder(std::string path, Compression c, ByteSource in)
      : path_(std::move(path)), c_(c), in_(std::move(in)), buf_(kChunk) {
    constexpr int kGzipWindow = 16 + MAX_WBITS;  // zlib's code for a gzip header and trailer
    const bool ok = c_ == Compression::kZlib   ? inflateInit(&z_) == Z_OK
                    : c_ == Compression::kGzip ? inflateInit2(&z_, kGzipWindow) == Z_OK
                                               : BZ2_bzDecompressInit(&b_, 0, 0) == BZ_OK;
    if (!ok) throw std::bad_alloc();  // the one way the init fails with the library it was built with
  }
  ~Decoder() {
    if (c_ != Compression::kBzip2)
      inflateEnd(&z_);
    else
      BZ2_bzDecompressEnd(&b_);
  }
  Decoder(const Decoder&) = delete;
  Decoder& operator=(const Decoder&) = delete;

  std::size_t read(unsigned char* dst, std::size_t n) {
    std::size_t made = 0;
    while (made < n && !ended_) {
      if (avail_ == 0 && !input_done_) refill();
      const std::size_t out = std::min<std::size_t>(n - made, UINT_MAX);
      std::size_t used = 0, produced = 0;
      step(dst + made, out, used, produced);
      next_ += used;
      avail_ -= used;
      made += produced;
      if (used == 0 && produced == 0 && (input_done_ || avail_ > 0)) break;  // no progress possible
      if (member_ended_) next_member();
    }
    return made;
  }

 private:
  // Keeps the unused input at the front of the buffer and reads more after it.
  void refill() {
    if (avail_ > 0) std::memmove(buf_.data(), next_, avail_);
    next_ = buf_.data();
    const std::size_t got = in_(buf_.data() + avail_, buf_.size() - avail_);
    input_done_ = got == 0;
    avail_ += got;
  }

  // After a gzip member: the next one starts where gzip's magic bytes follow, else the data ends.
  void next_member() {
    member_ended_ = false;
    if (avail_ < 2 && !input_done_) refill();
    if (avail_ >= 2 && next_[0] == 0x1f && next_[1] == 0x8b && inflateReset(&z_) == Z_OK) return;
    ended_ = true;
  }

  void step(unsigned char* dst, std::size_t out, std::size_t& used, std::size_t& produced) {
    const auto in = static_cast<unsigned>(std::min<std::size_t>(avail_, UINT_MAX));
    const auto room = static_cast<unsigned>(out);
    if (c_ != Compression::kBzip2) {
      z_.next_in = next_;
      z_.avail_in = in;
      z_.next_out = dst;
      z_.avail_out = room;
      const int rc = inflate(&z_, Z_NO_FLUSH);
      used = in - z_.avail_in;
      produced = room - z_.avail_out;
      if (rc == Z_STREAM_END) (c_ == Compression::kGzip ? member_ended_ : ended_) = true;
      if (rc != Z_OK && rc != Z_STREAM_END && rc != Z_BUF_ERROR)
        fail(path_, std::string("corrupt compressed data") + (z_.msg ? fmt::format(" ({})", z_.msg) : ""));
      return;
    }
    b_.next_in = reinterpret_cast<char*>(next_);
    b_.avail_in = in;
    b_.next_out = reinterpret_cast<char*>(dst);
    b_.avail_out = room;
    const int rc = BZ2_bzDecompress(&b_);
    used = in - b_.avail_in;
    produced = room - b_.avail_out;
    if (rc == BZ_STREAM_END) ended_ = true;
    if (rc != BZ_OK && rc != BZ_STREAM_END)
      fail(path_, fmt::format("corrupt compressed data (bzip2 error {})", rc));
  }

  std::string path_;
  Compression c_;
  ByteSource in_;
  std::vector<unsigned char> buf_;
  unsigned char* next_ = nullptr;
  std::size_t avail_ = 0;
  bool input_done_ = false, ended_ = false, member_ended_ = false;
  z_stream z_{};
  bz_stream b_{};
};

}  // namespace

ByteSource decoded_source(const std::string& path, Compression compression, ByteSource in) {
  auto d = std::make_shared<Decoder>(path, compression, std::move(in));
  return [d](unsigned char* dst, std::size_t n) { return d->read(dst, n); };
}

std::vector<unsigned char> read_exactly(const std::string& path, const ByteSource& in, std::uint64_t bytes,
                                        const std::string& what) {
  std::vector<unsigned char> out;
  std::uint64_t done = 0;
  while (done < bytes) {
    if (done == out.size())
      out.resize(static_cast<std::size_t>(
          std::min<std::uint64_t>(bytes, std::max<std::uint64_t>(kChunk, 2 * done))));
    const std::size_t asked = out.size() - static_cast<std::size_t>(done);
    const std::size_t got = in(out.data() + done, asked);
    if (got == 0) fail(path, fmt::format("truncated {} ({} of {} bytes)", what, done, bytes));
    // More than asked is a library's error code cast to size_t (znzread passes gzread's -1 on).
    if (got > asked) fail(path, fmt::format("corrupt {} (decoding failed after {} bytes)", what, done));
    done += got;
  }
  return out;
}

std::uint64_t count_bytes(const ByteSource& in, std::uint64_t enough) {
  std::vector<unsigned char> scratch(kChunk);
  std::uint64_t seen = 0;
  while (seen < enough) {
    const std::size_t asked = std::min<std::uint64_t>(scratch.size(), enough - seen);
    const std::size_t got = in(scratch.data(), asked);
    if (got == 0 || got > asked) break;  // the end, or an error code cast to size_t
    seen += got;
  }
  return seen;
}

std::vector<unsigned char> inflate_exactly(const std::string& path, const void* data, std::size_t n,
                                           std::uint64_t bytes) {
  const ByteSource in = decoded_source(path, Compression::kZlib, memory_source(data, n));
  std::vector<unsigned char> out = read_exactly(path, in, bytes, "compressed data");
  unsigned char extra = 0;
  if (in(&extra, 1) != 0)
    fail(path, fmt::format("compressed data does not inflate to the {} bytes of the dimensions", bytes));
  return out;
}

void check_declared_count(const std::string& path, const std::string& what, std::uint64_t count,
                          std::uint64_t min_bytes_each, std::uint64_t available) {
  if (min_bytes_each != 0 && count > available / min_bytes_each)
    fail(path, fmt::format("{} declares {}, more than its {} bytes can hold", what, count, available));
}

void check_frame(const std::string& path, const std::array<double, 9>& d) {
  double lengths = 1;
  for (int a = 0; a < 3; ++a) lengths *= std::sqrt(d[a] * d[a] + d[3 + a] * d[3 + a] + d[6 + a] * d[6 + a]);
  const double det = d[0] * (d[4] * d[8] - d[5] * d[7]) - d[1] * (d[3] * d[8] - d[5] * d[6]) +
                     d[2] * (d[3] * d[7] - d[4] * d[6]);
  if (!std::isfinite(det) || !std::isfinite(lengths)) fail(path, "the direction matrix is not finite");
  if (!(lengths > 0) || !(std::fabs(det) >= 1e-6 * lengths))
    fail(path, fmt::format("the direction matrix is singular (determinant {:.3g}): its axes do not span "
                           "three dimensions",
                           det));
}

}  // namespace mlfe
