// Importer benchmark (issue: reading is I/O and decompression bound).
//   read_bench make-vdb FILE N       writes an N^3 float fog volume with OpenVDB (dense, smooth)
//   read_bench vdb-native FILE       OpenVDB's own read of every grid (what vdb_print -l does)
//   read_bench mlfe FILE             mlfe::read_volume of the same file (dense float grid)
//   read_bench windows FILE [EDGE]   mlfe::VolumeWindows: every EDGE^3 box (default 64) read in
//                                    turn, as `convert --bricks` reads them (compressed data is
//                                    inflated to a temporary file by the first read)
// Each mode prints seconds and the process's peak RSS, so run each in its own process.
#include <mlfe/formats/volume_reader.h>
#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>
#include <sys/resource.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

namespace {
double peak_rss_mb() {
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  return ru.ru_maxrss / 1024.0;
}
}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: read_bench make-vdb|vdb-native|mlfe|windows FILE [N]\n");
    return 1;
  }
  const std::string mode = argv[1], path = argv[2];
  openvdb::initialize();
  const auto t0 = std::chrono::steady_clock::now();
  double voxels = 0;
  if (mode == "make-vdb") {
    const int n = argc > 3 ? std::atoi(argv[3]) : 512;
    auto grid = openvdb::FloatGrid::create(0.0f);
    grid->setName("density");
    grid->setGridClass(openvdb::GRID_FOG_VOLUME);
    auto acc = grid->getAccessor();
    for (int k = 0; k < n; ++k)
      for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i)
          acc.setValue({i, j, k}, 1.0f + std::sin(i * 0.05f) * std::cos(j * 0.04f) * std::sin(k * 0.03f));
    openvdb::io::File(path).write({grid});
    voxels = double(n) * n * n;
  } else if (mode == "vdb-native") {
    openvdb::io::File file(path);
    file.open();
    for (auto it = file.beginName(); it != file.endName(); ++it) {
      auto g = file.readGrid(it.gridName());
      // Delayed loading maps the file; touch every leaf buffer so the voxels are really read.
      if (auto fg = openvdb::gridPtrCast<openvdb::FloatGrid>(g)) {
        double sum = 0;
        for (auto leaf = fg->tree().cbeginLeaf(); leaf; ++leaf) sum += leaf->buffer().data()[0];
        if (sum == -1.2345) std::printf("(unlikely)\n");
      }
      voxels += double(g->activeVoxelCount());
    }
    file.close();
  } else if (mode == "mlfe") {
    const mlfe::ScalarGrid g = mlfe::read_volume(path);
    voxels = double(g.voxel_count());
  } else if (mode == "windows") {
    const std::int64_t edge = argc > 3 ? std::atoll(argv[3]) : 64;
    const mlfe::VolumeWindows v(path, {});
    const auto& d = v.frame().dims;
    double sum = 0;
    std::array<std::int64_t, 3> lo{}, hi{};
    for (lo[2] = 0; lo[2] < d[2]; lo[2] += edge)
      for (lo[1] = 0; lo[1] < d[1]; lo[1] += edge)
        for (lo[0] = 0; lo[0] < d[0]; lo[0] += edge) {
          for (int a = 0; a < 3; ++a) hi[a] = std::min(d[a], lo[a] + edge);
          const mlfe::ScalarGrid w = v.read(lo, hi);
          sum += w.values[0];
          voxels += double(w.voxel_count());
        }
    if (sum == -1.2345) std::printf("(unlikely)\n");
    if (!v.streamed()) std::fprintf(stderr, "%s: read whole, not in windows\n", path.c_str());
  } else {
    std::fprintf(stderr, "unknown mode %s\n", mode.c_str());
    return 1;
  }
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("| %s | %s | %.0f | %.3f | %.0f | %.2f |\n", mode.c_str(), path.c_str(), voxels, s,
              peak_rss_mb(), peak_rss_mb() * 1048576.0 / (voxels * 4.0));
  return 0;
}
