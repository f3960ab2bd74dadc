// jpegls_slices: JPEG-LS (CharLS 2.x, libcharls-dev) of a volume slice by slice, the lossless and
// near-lossless peer of bench/py/file_bench.py (issue 44). JPEG-LS is a 2D coder; each z slice
// (x fastest) is one JPEG-LS image, so the figure is what a DICOM/PACS user of JPEG-LS gets.
// NEAR > 0 is JPEG-LS near-lossless: every sample within NEAR, the equal-max-error peer.
//
//   jpegls_slices encode IN.raw NX NY NZ BITS NEAR OUT.jlss   (BITS 8: uint8, 9..16: uint16 LE)
//   jpegls_slices decode IN.jlss OUT.raw
//
// OUT.jlss: "JLSS", uint32 slice count, then per slice a uint32 byte count and the JPEG-LS stream
// (each stream carries its own width, height and bit depth). Prints one JSON line with the bytes
// and the coding's CPU seconds (file I/O excluded; CPU rather than wall time because the benchmark
// machines are shared). Errors: a message on stderr, exit 2.
#include <charls/charls.h>

#include <cstdint>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <fstream>
#include <iterator>
#include <stdexcept>
#include <string>
#include <vector>

namespace {

std::vector<uint8_t> read_all(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw std::runtime_error(path + ": cannot open");
  return std::vector<uint8_t>(std::istreambuf_iterator<char>(f), {});
}

void write_all(const std::string& path, const std::vector<uint8_t>& bytes) {
  std::ofstream f(path, std::ios::binary);
  f.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  if (!f) throw std::runtime_error(path + ": cannot write");
}

void put_u32(std::vector<uint8_t>& out, uint32_t v) {
  for (int i = 0; i < 4; ++i) out.push_back(static_cast<uint8_t>(v >> (8 * i)));
}

uint32_t get_u32(const std::vector<uint8_t>& in, size_t& pos) {
  if (pos + 4 > in.size()) throw std::runtime_error("truncated .jlss");
  uint32_t v = 0;
  for (int i = 0; i < 4; ++i) v |= static_cast<uint32_t>(in[pos + i]) << (8 * i);
  pos += 4;
  return v;
}

double cpu_seconds_since(std::clock_t t) { return static_cast<double>(std::clock() - t) / CLOCKS_PER_SEC; }

int encode(char** argv) {
  const uint32_t nx = std::stoul(argv[3]), ny = std::stoul(argv[4]), nz = std::stoul(argv[5]);
  const int bits = std::stoi(argv[6]), near = std::stoi(argv[7]);
  if (bits < 2 || bits > 16) throw std::runtime_error("BITS must be 2..16");
  const size_t sample = bits > 8 ? 2 : 1, slice = size_t{nx} * ny * sample;
  const std::vector<uint8_t> in = read_all(argv[2]);
  if (in.size() != slice * nz)
    throw std::runtime_error(std::string(argv[2]) + ": size is not NX*NY*NZ samples");
  std::vector<uint8_t> out = {'J', 'L', 'S', 'S'};
  put_u32(out, nz);
  const std::clock_t t = std::clock();
  for (uint32_t z = 0; z < nz; ++z) {
    charls::jpegls_encoder enc;
    enc.frame_info({nx, ny, bits, 1}).near_lossless(near);
    std::vector<uint8_t> dst(enc.estimated_destination_size());
    enc.destination(dst);
    const size_t n = enc.encode(in.data() + z * slice, slice);
    put_u32(out, static_cast<uint32_t>(n));
    out.insert(out.end(), dst.begin(), dst.begin() + static_cast<std::ptrdiff_t>(n));
  }
  const double s = cpu_seconds_since(t);
  write_all(argv[8], out);
  std::printf("{\"bytes\": %zu, \"encode_s\": %.6f}\n", out.size(), s);
  return 0;
}

int decode(char** argv) {
  const std::vector<uint8_t> in = read_all(argv[2]);
  if (in.size() < 8 || std::memcmp(in.data(), "JLSS", 4) != 0) throw std::runtime_error("not a .jlss file");
  size_t pos = 4;
  const uint32_t nz = get_u32(in, pos);
  std::vector<uint8_t> out;
  const std::clock_t t = std::clock();
  for (uint32_t z = 0; z < nz; ++z) {
    const uint32_t n = get_u32(in, pos);
    if (n > in.size() - pos) throw std::runtime_error("truncated .jlss");
    charls::jpegls_decoder dec(in.data() + pos, n, true);
    const size_t old = out.size();
    out.resize(old + dec.destination_size());
    dec.decode(out.data() + old, out.size() - old);
    pos += n;
  }
  const double s = cpu_seconds_since(t);
  write_all(argv[3], out);
  std::printf("{\"bytes\": %zu, \"decode_s\": %.6f}\n", out.size(), s);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    if (argc == 9 && std::strcmp(argv[1], "encode") == 0) return encode(argv);
    if (argc == 4 && std::strcmp(argv[1], "decode") == 0) return decode(argv);
    std::fprintf(stderr,
                 "usage: jpegls_slices encode IN.raw NX NY NZ BITS NEAR OUT.jlss\n"
                 "       jpegls_slices decode IN.jlss OUT.raw\n");
  } catch (const std::exception& e) {
    std::fprintf(stderr, "jpegls_slices: %s\n", e.what());
  }
  return 2;
}
