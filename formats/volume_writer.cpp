#include <fmt/format.h>
#include <fmt/ranges.h>
#include <mlfe/core/base/error.h>
#include <mlfe/formats/atomic_file.h>
#include <mlfe/formats/volume_writer.h>
#include <nifti2_io.h>
#include <teem/nrrd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "formats/volume_formats_detail.h"

namespace mlfe {
namespace {

// The table's row whose write extension ends `path` (case-insensitive), or nullptr.
const volume_detail::VolumeFormatRow* writer_of(const std::string& path) {
  std::string p = path;
  std::transform(p.begin(), p.end(), p.begin(), [](unsigned char c) { return std::tolower(c); });
  for (const auto& row : volume_detail::volume_formats())
    for (const char* ext : row.write_extensions) {
      const std::size_t n = std::strlen(ext);
      if (p.size() > n && p.compare(p.size() - n, n, ext) == 0) return &row;
    }
  return nullptr;
}

[[noreturn]] void fail(const std::string& path, const std::string& what) { throw Error(path + ": " + what); }

// Physical step of index axis a: spacing[a] times column a of the direction matrix.
std::array<double, 3> axis_step(const GridTransform& t, int a) {
  return {t.direction[0 + a] * t.spacing[a], t.direction[3 + a] * t.spacing[a],
          t.direction[6 + a] * t.spacing[a]};
}

}  // namespace

namespace volume_detail {

void write_nifti(const std::string& path, const ScalarGrid& g) {
  // NIfTI coordinates are RAS: an LPS frame flips x and y.
  const double flip = g.space == "LPS" ? -1.0 : 1.0;
  nifti_dmat44 m{};
  for (int a = 0; a < 3; ++a) {
    const auto s = axis_step(g.transform, a);
    for (int r = 0; r < 3; ++r) m.m[r][a] = (r < 2 ? flip : 1.0) * s[r];
  }
  for (int r = 0; r < 3; ++r) m.m[r][3] = (r < 2 ? flip : 1.0) * g.transform.origin[r];
  m.m[3][3] = 1;
  write_path_atomically(path, [&](const std::string& tmp) {
    const std::int64_t dims[8] = {3, g.dims[0], g.dims[1], g.dims[2], 1, 1, 1, 1};
    std::unique_ptr<nifti_image, void (*)(nifti_image*)> nim(nifti_make_new_nim(dims, NIFTI_TYPE_FLOAT32, 0),
                                                             nifti_image_free);
    if (!nim) return false;
    nim->data = const_cast<float*>(g.values.data());
    for (int a = 0; a < 3; ++a) nim->pixdim[a + 1] = g.transform.spacing[a];
    nim->dx = g.transform.spacing[0];
    nim->dy = g.transform.spacing[1];
    nim->dz = g.transform.spacing[2];
    nim->sform_code = NIFTI_XFORM_SCANNER_ANAT;
    nim->sto_xyz = m;
    nim->qform_code = NIFTI_XFORM_SCANNER_ANAT;
    double dx, dy, dz;
    nifti_dmat44_to_quatern(m, &nim->quatern_b, &nim->quatern_c, &nim->quatern_d, &nim->qoffset_x,
                            &nim->qoffset_y, &nim->qoffset_z, &dx, &dy, &dz, &nim->qfac);
    nim->qto_xyz = m;
    nim->xyz_units = NIFTI_UNITS_MM;
    nim->nifti_type = NIFTI_FTYPE_NIFTI1_1;
    // nifti_image_write only prints "wrote only 0 of ..." when the disk is full; the header and
    // the data are written here through its pieces, whose results are checked.
    const bool named = nifti_set_filenames(nim.get(), tmp.c_str(), 0, 1) == 0;
    znzFile fp = named ? nifti_image_write_hdr_img(nim.get(), 2, "wb") : nullptr;
    nim->data = nullptr;  // owned by g
    if (znz_isnull(fp)) fail(path, "cannot write the NIfTI header");
    const auto bytes = static_cast<std::int64_t>(g.values.size() * sizeof(float));
    const std::int64_t wrote = nifti_write_buffer(fp, g.values.data(), bytes);
    const int closed = znzclose(fp);
    if (wrote != bytes || closed != 0)
      fail(path, fmt::format("write failed after {} of {} voxel bytes (disk full?)", wrote, bytes));
    return true;
  });
}

void write_nrrd(const std::string& path, const ScalarGrid& g) {
  std::unique_ptr<Nrrd, Nrrd* (*)(Nrrd*)> n(nrrdNew(), nrrdNix);
  if (nrrdWrap_va(n.get(), const_cast<float*>(g.values.data()), nrrdTypeFloat, 3,
                  static_cast<size_t>(g.dims[0]), static_cast<size_t>(g.dims[1]),
                  static_cast<size_t>(g.dims[2])) != 0)
    fail(path, "cannot describe the grid to Teem");
  if (g.space == "RAS")
    nrrdSpaceSet(n.get(), nrrdSpaceRightAnteriorSuperior);
  else if (g.space == "LPS")
    nrrdSpaceSet(n.get(), nrrdSpaceLeftPosteriorSuperior);
  else
    nrrdSpaceDimensionSet(n.get(), 3);
  double dirs[3][NRRD_SPACE_DIM_MAX] = {};
  for (int a = 0; a < 3; ++a) {
    const auto s = axis_step(g.transform, a);
    std::copy(s.begin(), s.end(), dirs[a]);
  }
  nrrdAxisInfoSet_va(n.get(), nrrdAxisInfoSpaceDirection, dirs[0], dirs[1], dirs[2]);
  const double* o = g.transform.origin.data();
  if (nrrdSpaceOriginSet(n.get(), const_cast<double*>(o)) != 0)
    fail(path, "cannot set the NRRD space origin");
  write_path_atomically(path, [&](const std::string& tmp) {
    std::unique_ptr<NrrdIoState, NrrdIoState* (*)(NrrdIoState*)> nio(nrrdIoStateNew(), nrrdIoStateNix);
    nio->encoding = nrrdEncodingGzip->available() ? nrrdEncodingGzip : nrrdEncodingRaw;
    // Teem closes the files nrrdSave opens without looking at the result, so the last buffered
    // bytes could be lost unnoticed; on our own FILE the error flag and fclose are checked.
    std::FILE* file = std::fopen(tmp.c_str(), "wb");
    if (!file) fail(path, std::string("cannot create file (") + std::strerror(errno) + ")");
    const int status = nrrdWrite(file, n.get(), nio.get());
    const bool stream_ok = !std::ferror(file) && std::fflush(file) == 0;
    const bool closed = std::fclose(file) == 0;
    if (status != 0) {
      char* err = biffGetDone(NRRD);
      const std::string msg = err ? err : "";
      std::free(err);
      fail(path, "Teem cannot write it: " + msg.substr(0, msg.find('\n')));
    }
    if (!stream_ok || !closed) fail(path, "write failed (disk full?)");
    return true;
  });
}

void write_raw(const std::string& path, const ScalarGrid& g) {
  static_assert(sizeof(float) == 4, "float32");
  const std::uint16_t one = 1;
  unsigned char first;
  std::memcpy(&first, &one, 1);
  const bool little = first == 1;
  write_file_atomically(path, [&](std::ostream& os) {
    if (little) {
      os.write(reinterpret_cast<const char*>(g.values.data()),
               static_cast<std::streamsize>(g.values.size() * 4));
    } else {
      for (float v : g.values) {
        char b[4];
        std::memcpy(b, &v, 4);
        std::reverse(b, b + 4);
        os.write(b, 4);
      }
    }
  });
  nlohmann::json j = {{"dims", g.dims},
                      {"dtype", "float32"},
                      {"endian", "little"},
                      {"spacing", g.transform.spacing},
                      {"origin", g.transform.origin},
                      {"direction", g.transform.direction}};
  if (!g.space.empty()) j["space"] = g.space;
  try {
    write_file_atomically(path + ".json", [&](std::ostream& os) { os << j.dump(2) << "\n"; });
  } catch (...) {
    // In a batch nothing was renamed yet (and `path` may be an older file to keep).
    if (!OutputBatch::active()) std::remove(path.c_str());
    throw;
  }
}

}  // namespace volume_detail

bool is_volume_output(const std::string& path) { return writer_of(path) != nullptr; }

void write_volume(const std::string& path, const ScalarGrid& g) {
  if (g.voxel_count() <= 0 || g.values.size() != static_cast<std::size_t>(g.voxel_count()))
    fail(path,
         fmt::format("{} values for a {} x {} x {} grid", g.values.size(), g.dims[0], g.dims[1], g.dims[2]));
  if (const auto* row = writer_of(path)) return row->write(path, g);
  std::vector<std::string> written;
  for (const auto& row : volume_detail::volume_formats())
    written.insert(written.end(), row.write_extensions.begin(), row.write_extensions.end());
  std::sort(written.begin(), written.end());
  fail(path, fmt::format("unknown volume type ({})", fmt::join(written, ", ")));
}

}  // namespace mlfe
