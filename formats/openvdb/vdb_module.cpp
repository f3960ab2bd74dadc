// libmlfe_openvdb: OpenVDB volumes (.vdb) in and out, the only translation unit that includes
// OpenVDB headers. It is a module that libmlfe_formats loads on the first .vdb file
// (formats/vdb_module.h says why); the functions' contracts are those of read_vdb and
// list_vdb_grids (<mlfe/formats/vdb_reader.h>) and of write_volume.
#include "formats/vdb_module.h"

#include <fmt/format.h>
#include <mlfe/formats/atomic_file.h>
#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <cmath>
#include <cstring>
#include <mutex>

#include "formats/reader_helpers.h"

namespace mlfe {
using namespace volume_detail;

namespace {

void init_openvdb() {
  static std::once_flag once;
  std::call_once(once, [] { openvdb::initialize(); });
}

bool is_scalar_type(const std::string& t) {
  return t == "float" || t == "double" || t == "int32" || t == "int64" || t == "bool" || t == "half";
}
bool is_vector_type(const std::string& t) { return t == "vec3s" || t == "vec3d" || t == "vec3i"; }

// OpenVDB trusts every length field it reads: a corrupt string length makes it allocate (and
// fill) up to 4 GB before noticing the file is short. So the parts OpenVDB reads when it opens
// a file and a grid's metadata are walked here first, checking that every string, metadata
// blob and grid offset fits inside the file. The layout is that of io::Archive::readHeader,
// MetaMap::readMeta, GridDescriptor::read and Transform::read for file versions 220..224.
class VdbChecker {
 public:
  VdbChecker(const std::string& path, std::string bytes) : path_(path), b_(std::move(bytes)) {}

  void check() {
    if (b_.size() < 8 || std::memcmp(b_.data(), "\x20\x42\x44\x56\0\0\0\0", 8) != 0)
      fail(path_, "not an OpenVDB file (wrong magic number)");
    pos_ = 8;
    const std::uint32_t version = u32("file version");
    if (version < 220 || version > 224)
      fail(path_, fmt::format("unsupported OpenVDB file version {} (220..224 are read)", version));
    u32("library major version");
    u32("library minor version");
    const bool offsets = byte("grid offsets flag") != 0;
    if (!offsets) fail(path_, "OpenVDB stream without grid offsets (written by io::Stream) is not supported");
    if (version < 222) byte("compression flag");
    need(36, "file UUID");
    pos_ += 36;
    meta_map("file metadata");
    const std::int32_t grids = i32("grid count");
    if (grids < 0 || static_cast<std::uint64_t>(grids) > b_.size())
      fail(path_, fmt::format("bad OpenVDB grid count {}", grids));
    for (std::int32_t g = 0; g < grids; ++g) {
      string("grid name");
      string("grid type");
      string("instance parent name");
      const std::int64_t grid_pos = i64("grid offset"), block_pos = i64("block offset"),
                         end_pos = i64("end offset");
      const auto size = static_cast<std::int64_t>(b_.size());
      if (grid_pos < 0 || grid_pos > block_pos || block_pos > end_pos || end_pos > size)
        fail(path_, fmt::format("truncated or corrupt OpenVDB file: grid {} spans bytes {}..{} of {}", g,
                                grid_pos, end_pos, size));
      // Each grid's data follows its descriptor; the next descriptor starts at end_pos.
      pos_ = static_cast<std::size_t>(grid_pos);
      if (version >= 222) u32("grid compression");
      meta_map("grid metadata");
      string("transform type");
      pos_ = static_cast<std::size_t>(end_pos);
    }
  }

 private:
  void need(std::uint64_t n, const char* what) {
    if (n > b_.size() - pos_)
      fail(path_, fmt::format("truncated or corrupt OpenVDB file: {} at byte {} needs {} bytes, {} remain",
                              what, pos_, n, b_.size() - pos_));
  }
  template <typename T>
  T read(const char* what) {
    need(sizeof(T), what);
    T v;
    std::memcpy(&v, b_.data() + pos_, sizeof(T));
    pos_ += sizeof(T);
    return v;
  }
  std::uint32_t u32(const char* what) { return read<std::uint32_t>(what); }
  std::int32_t i32(const char* what) { return read<std::int32_t>(what); }
  std::int64_t i64(const char* what) { return read<std::int64_t>(what); }
  unsigned char byte(const char* what) { return read<unsigned char>(what); }
  void string(const char* what) {
    const std::uint32_t n = u32(what);
    need(n, what);
    pos_ += n;
  }
  void meta_map(const char* what) {
    const std::uint32_t count = u32(what);
    if (count > b_.size()) fail(path_, fmt::format("corrupt OpenVDB {}: {} entries", what, count));
    for (std::uint32_t i = 0; i < count; ++i) {
      string("metadata name");
      string("metadata type");
      string("metadata value");  // a byte count followed by the bytes, like a string
    }
  }

  const std::string& path_;
  std::string b_;
  std::size_t pos_ = 0;
};

void check_vdb_magic(const std::string& path) {
  std::string head = read_file_prefix(path, 8);
  if (head.size() < 8 || std::memcmp(head.data(), "\x20\x42\x44\x56\0\0\0\0", 8) != 0)
    fail(path, "not an OpenVDB file (wrong magic number)");
}

// Reads the file for VdbChecker; only the header and metadata are walked, but they are
// spread through the file (each grid's metadata sits before its tree).
void check_vdb_structure(const std::string& path, const VolumeReadOptions& opts) {
  check_vdb_magic(path);
  VdbChecker(path, read_regular_file(path, memory_limit(opts), "the file")).check();
}

template <typename GridT, typename Convert>
void densify(const GridT& g, const openvdb::CoordBBox& bb, ScalarGrid& out, Convert convert) {
  const std::int64_t nx = out.dims[0], ny = out.dims[1], nz = out.dims[2];
  tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, nz), [&](const tbb::blocked_range<std::int64_t>& r) {
    auto acc = g.getConstAccessor();
    for (std::int64_t k = r.begin(); k < r.end(); ++k)
      for (std::int64_t j = 0; j < ny; ++j) {
        float* row = out.values.data() + static_cast<std::size_t>(nx * (j + ny * k));
        for (std::int64_t i = 0; i < nx; ++i)
          row[i] = convert(acc.getValue(
              openvdb::Coord(bb.min().x() + int(i), bb.min().y() + int(j), bb.min().z() + int(k))));
      }
  });
}

template <typename GridT, typename Convert>
void read_typed(const std::string& path, const openvdb::GridBase::Ptr& base, const VolumeReadOptions& opts,
                ScalarGrid& out, Convert convert) {
  auto grid = openvdb::gridPtrCast<GridT>(base);
  if (!grid) fail(path, "grid type changed while reading");
  const openvdb::CoordBBox bb = grid->evalActiveVoxelBoundingBox();
  if (bb.empty() || grid->activeVoxelCount() == 0)
    fail(path, fmt::format("grid '{}' is empty (no active voxels)", base->getName()));
  const openvdb::Coord d = bb.dim();
  out.dims = {d.x(), d.y(), d.z()};
  const std::int64_t voxels = checked_voxel_count(path, out.dims);
  check_memory(
      path, checked_bytes(path, voxels, 4), opts,
      fmt::format("the dense {} x {} x {} float32 grid of the active bounding box", d.x(), d.y(), d.z()));
  allocate_values(out);
  densify(*grid, bb, out, convert);

  const openvdb::math::Transform& xf = grid->transform();
  if (!xf.isLinear())
    fail(path, fmt::format("grid '{}' has a non-linear (frustum) transform", base->getName()));
  const openvdb::Mat4d m = xf.baseMap()->getAffineMap()->getMat4();
  // OpenVDB maps row vectors: world = ijk * M, so row a is the step of index axis a.
  std::array<std::array<double, 3>, 3> axes{};
  for (int a = 0; a < 3; ++a)
    for (int r = 0; r < 3; ++r) axes[a][r] = m(a, r);
  set_axes(path, out.transform, axes);
  const openvdb::Vec3d o = xf.indexToWorld(bb.min());
  out.transform.origin = {o.x(), o.y(), o.z()};
}

std::vector<std::string> list_grids(const std::string& path) {
  check_vdb_structure(path, VolumeReadOptions{});
  init_openvdb();
  std::vector<std::string> names;
  try {
    openvdb::io::File file(path);
    file.open(false);
    auto grids = file.readAllGridMetadata();
    for (const auto& g : *grids)
      names.push_back(fmt::format("{} ({}, {})", g->getName(), g->valueType(),
                                  openvdb::GridBase::gridClassToString(g->getGridClass())));
    file.close();
  } catch (const openvdb::Exception& e) {
    fail(path, std::string("cannot read the OpenVDB file (truncated or corrupt?): ") + e.what());
  }
  return names;
}

ScalarGrid read_grid(const std::string& path, const VolumeReadOptions& opts) {
  check_vdb_structure(path, opts);
  init_openvdb();
  ScalarGrid out;
  try {
    openvdb::io::File file(path);
    file.open(false);  // no delayed loading: the file may change or vanish after reading
    auto metas = file.readAllGridMetadata();
    if (!metas || metas->empty()) fail(path, "OpenVDB file has no grids");
    openvdb::GridBase::Ptr chosen_meta;
    std::string all;
    for (const auto& g : *metas) {
      all += (all.empty() ? "" : ", ") + g->getName() + " (" + g->valueType() + ")";
      if (chosen_meta) continue;
      if (!opts.grid_name.empty()) {
        if (g->getName() == opts.grid_name) chosen_meta = g;
      } else if (is_scalar_type(g->valueType())) {
        chosen_meta = g;
      }
    }
    if (!chosen_meta && opts.grid_name.empty() && opts.vec_magnitude)
      for (const auto& g : *metas)
        if (!chosen_meta && is_vector_type(g->valueType())) chosen_meta = g;
    if (!chosen_meta) {
      if (!opts.grid_name.empty())
        fail(path, fmt::format("no grid named '{}' (grids: {})", opts.grid_name, all));
      fail(path, fmt::format("no scalar grid (grids: {}){}", all,
                             opts.vec_magnitude ? "" : "; use --vec-magnitude for vector grids"));
    }
    const std::string type = chosen_meta->valueType();
    const std::string name = chosen_meta->getName();
    if (is_vector_type(type) && !opts.vec_magnitude)
      fail(path, fmt::format("grid '{}' is a vector grid ({}); use --vec-magnitude to read its magnitude",
                             name, type));
    if (!is_scalar_type(type) && !is_vector_type(type))
      fail(path, fmt::format("grid '{}' has unsupported value type {}", name, type));
    // Grid statistics written by OpenVDB let us refuse huge boxes before reading the tree.
    if (auto mn = chosen_meta->getMetadata<openvdb::Vec3IMetadata>(openvdb::GridBase::META_FILE_BBOX_MIN)) {
      if (auto mx = chosen_meta->getMetadata<openvdb::Vec3IMetadata>(openvdb::GridBase::META_FILE_BBOX_MAX)) {
        std::array<std::int64_t, 3> d{};
        for (int a = 0; a < 3; ++a) d[a] = std::int64_t(mx->value()[a]) - mn->value()[a] + 1;
        if (d[0] >= 1 && d[1] >= 1 && d[2] >= 1)
          check_memory(path, checked_bytes(path, checked_voxel_count(path, d), 4), opts,
                       fmt::format("the dense {} x {} x {} float32 grid of the active bounding box", d[0],
                                   d[1], d[2]));
      }
    }
    openvdb::GridBase::Ptr base = file.readGrid(name);
    file.close();
    if (!base) fail(path, "cannot read grid '" + name + "'");
    if (type == "float") {
      read_typed<openvdb::FloatGrid>(path, base, opts, out, [](float v) { return v; });
      out.source_type = ScalarType::F32;
    } else if (type == "double") {
      read_typed<openvdb::DoubleGrid>(path, base, opts, out, [](double v) { return float(v); });
      out.source_type = ScalarType::F64;
    } else if (type == "int32") {
      read_typed<openvdb::Int32Grid>(path, base, opts, out, [](std::int32_t v) { return float(v); });
      out.source_type = ScalarType::I32;
      add_note(out, "int32 grid converted to float32");
    } else if (type == "int64") {
      read_typed<openvdb::Int64Grid>(path, base, opts, out, [](std::int64_t v) { return float(v); });
      out.source_type = ScalarType::F64;
      add_note(out, "int64 grid converted to float32 (large values lose precision)");
    } else if (type == "bool") {
      read_typed<openvdb::BoolGrid>(path, base, opts, out, [](bool v) { return v ? 1.0f : 0.0f; });
      out.source_type = ScalarType::U8;
      add_note(out, "bool grid converted to 0/1");
    } else if (type == "vec3s") {
      read_typed<openvdb::Vec3SGrid>(path, base, opts, out,
                                     [](const openvdb::Vec3s& v) { return float(v.length()); });
      add_note(out, "vector grid read as its magnitude");
    } else if (type == "vec3d") {
      read_typed<openvdb::Vec3DGrid>(path, base, opts, out,
                                     [](const openvdb::Vec3d& v) { return float(v.length()); });
      out.source_type = ScalarType::F64;
      add_note(out, "vector grid read as its magnitude");
    } else if (type == "vec3i") {
      read_typed<openvdb::Vec3IGrid>(
          path, base, opts, out, [](const openvdb::Vec3i& v) { return float(openvdb::Vec3d(v).length()); });
      out.source_type = ScalarType::I32;
      add_note(out, "vector grid read as its magnitude");
    } else {
      fail(path, fmt::format("grid '{}' has unsupported value type {}", name, type));
    }
    // mlfe's own writer (formats/volume_writer.h) records the frame's anatomical space.
    if (const auto sp = base->getMetadata<openvdb::StringMetadata>("space"))
      if (sp->value() == "RAS" || sp->value() == "LPS") out.space = sp->value();
    std::string cls = openvdb::GridBase::gridClassToString(base->getGridClass());
    add_note(out, fmt::format("grid '{}' ({} values, class {}); domain is the active-voxel bounding box",
                              name, type, cls));
    if (metas->size() > 1) add_note(out, "other grids: " + all);
  } catch (const openvdb::Exception& e) {
    fail(path, std::string("cannot read the OpenVDB file (truncated or corrupt?): ") + e.what());
  }
  return out;
}

// What openvdb::io::File::write does, on the shared writer's stream: File writes to its own
// std::ofstream and never looks at its state, so a full disk went unnoticed.
class VdbArchive : public openvdb::io::Archive {
 public:
  using openvdb::io::Archive::write;
};

void write_grid(const std::string& path, const ScalarGrid& g) {
  init_openvdb();
  auto grid = openvdb::FloatGrid::create(0.0f);
  grid->setName("density");
  grid->setGridClass(openvdb::GRID_FOG_VOLUME);
  openvdb::Mat4d m = openvdb::Mat4d::identity();
  // OpenVDB maps row vectors (world = ijk · M): row a is the step of index axis a, that is
  // spacing[a] times column a of the direction matrix.
  for (int a = 0; a < 3; ++a)
    for (int r = 0; r < 3; ++r) m(a, r) = g.transform.direction[3 * r + a] * g.transform.spacing[a];
  for (int r = 0; r < 3; ++r) m(3, r) = g.transform.origin[r];
  grid->setTransform(openvdb::math::Transform::createLinearTransform(m));
  auto acc = grid->getAccessor();
  std::size_t idx = 0;
  for (int k = 0; k < g.dims[2]; ++k)
    for (int j = 0; j < g.dims[1]; ++j)
      for (int i = 0; i < g.dims[0]; ++i) acc.setValueOn(openvdb::Coord(i, j, k), g.values[idx++]);
  if (!g.space.empty()) grid->insertMeta("space", openvdb::StringMetadata(g.space));
  write_file_atomically(path, [&](std::ostream& out) {
    try {
      VdbArchive().write(out, openvdb::GridCPtrVec{grid}, /*seekable=*/true);
    } catch (const openvdb::Exception& e) {
      fail(path, std::string("OpenVDB cannot write it: ") + e.what());
    }
  });
}

}  // namespace
}  // namespace mlfe

extern "C" __attribute__((visibility("default"))) const mlfe::volume_detail::VdbFunctions*
mlfe_openvdb_functions() {
  static const mlfe::volume_detail::VdbFunctions functions{mlfe::volume_detail::kVdbModuleAbi,
                                                           sizeof(mlfe::ScalarGrid),
                                                           sizeof(mlfe::VolumeReadOptions),
                                                           mlfe::read_grid,
                                                           mlfe::list_grids,
                                                           mlfe::write_grid};
  return &functions;
}
