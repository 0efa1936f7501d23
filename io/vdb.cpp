// io/vdb.cpp: OpenVDB float grids handed to C as NanoVDB buffers (io.h, IoVolumeGrid).
//
// OpenVDB reads the file (and validates it: a corrupt or truncated file throws); the grid is
// converted with NanoVDB's openToNanoVDB into one flat buffer, which C code reads with
// PNanoVDB.h. No OpenVDB or NanoVDB type crosses io.h.
#include "io.h"
#include "io_internal.hpp"

#include <openvdb/openvdb.h>
#include <nanovdb/util/OpenToNanoVDB.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <mutex>
#include <string>
#include <sys/stat.h>
#include <unistd.h>

namespace {

// Largest extent of a grid's active bounding box per axis, in voxels: far beyond any
// production volume, and small enough that index arithmetic stays exact in float.
constexpr int kMaxGridExtent = 1 << 20;

void openvdb_init_once() {
    static std::once_flag flag;
    std::call_once(flag, [] { openvdb::initialize(); });
}

// Fills everything but name and buffer from the OpenVDB grid; false with a problem.
bool describe(const openvdb::FloatGrid &grid, IoVolumeGrid *out, std::string *problem) {
    if (!grid.transform().isLinear()) {
        *problem = "grid '" + grid.getName() + "' has a non-linear (frustum) transform, which is not supported";
        return false;
    }
    openvdb::CoordBBox bbox = grid.evalActiveVoxelBoundingBox();
    if (grid.activeVoxelCount() == 0 || bbox.empty()) {
        *problem = "grid '" + grid.getName() + "' is empty (no active voxels)";
        return false;
    }
    for (int k = 0; k < 3; ++k) {
        long long extent = (long long)bbox.max()[k] - (long long)bbox.min()[k] + 1;
        if (extent > kMaxGridExtent || std::llabs((long long)bbox.min()[k]) > kMaxGridExtent ||
            std::llabs((long long)bbox.max()[k]) > kMaxGridExtent) {
            *problem = "grid '" + grid.getName() + "' has absurd bounds (more than 2^20 voxels along an axis)";
            return false;
        }
        out->index_min[k] = bbox.min()[k];
        out->index_max[k] = bbox.max()[k];
    }
    // OpenVDB maps row vectors: world_j = sum_i index_i m[i][j] + m[3][j]
    openvdb::math::Mat4d m = grid.transform().baseMap()->getAffineMap()->getMat4();
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) {
            double v = m[i][j];
            if (!std::isfinite(v)) {
                *problem = "grid '" + grid.getName() + "' has a non-finite transform";
                return false;
            }
            out->index_to_world[i * 4 + j] = (float)v;
        }
    float lo = INFINITY, hi = -INFINITY;
    uint64_t nonfinite = 0;
    for (auto it = grid.cbeginValueOn(); it; ++it) {
        float v = *it;
        if (!std::isfinite(v)) { nonfinite += it.isVoxelValue() ? 1 : it.getVoxelCount(); continue; }
        lo = v < lo ? v : lo;
        hi = v > hi ? v : hi;
    }
    out->value_min = lo <= hi ? lo : 0.0f;
    out->value_max = lo <= hi ? hi : 0.0f;
    out->active_voxels = grid.activeVoxelCount();
    out->nonfinite_voxels = nonfinite;
    return true;
}

bool to_nanovdb(const openvdb::FloatGrid &grid, IoVolumeGrid *out, std::string *problem) {
    auto handle = nanovdb::openToNanoVDB(grid);
    uint64_t size = handle.size();
    if (!handle.data() || size == 0) {
        *problem = "NanoVDB conversion of grid '" + grid.getName() + "' failed";
        return false;
    }
    void *buffer = std::aligned_alloc(32, (size + 31) / 32 * 32);
    if (!buffer) {
        *problem = "out of memory converting grid '" + grid.getName() + "'";
        return false;
    }
    std::memcpy(buffer, handle.data(), size);
    out->buffer = buffer;
    out->size = size;
    return true;
}

void set_name(IoVolumeGrid *out, const std::string &name) {
    std::snprintf(out->name, sizeof out->name, "%s", name.c_str());
}

}  // namespace

extern "C" int io_load_vdb_grid(const char *path, const char *grid_name, IoVolumeGrid *out, char err[IO_ERR_LEN]) {
    std::memset(out, 0, sizeof *out);
    struct stat st;
    if (stat(path, &st) != 0) {
        candela_io::set_err(err, path, "cannot open: no such file");
        return 1;
    }
    if (!S_ISREG(st.st_mode)) {
        candela_io::set_err(err, path, "not a regular file");
        return 1;
    }
    try {
        openvdb_init_once();
        openvdb::io::File file(path);
        file.open(false);  // no delayed loading: the whole grid is read (and checked) now
        if (!file.hasGrid(grid_name)) {
            std::string names;
            for (auto it = file.beginName(); it != file.endName(); ++it) names += (names.empty() ? "" : ", ") + *it;
            file.close();
            candela_io::set_err(err, path, std::string("no grid named '") + grid_name + "' (grids: " +
                                               (names.empty() ? "none" : names) + ")");
            return 1;
        }
        openvdb::GridBase::Ptr base = file.readGrid(grid_name);
        file.close();
        openvdb::FloatGrid::Ptr grid = openvdb::gridPtrCast<openvdb::FloatGrid>(base);
        if (!grid) {
            candela_io::set_err(err, path, std::string("grid '") + grid_name + "' is a " + base->valueType() +
                                               " grid, not a float grid");
            return 1;
        }
        std::string problem;
        if (!describe(*grid, out, &problem) || !to_nanovdb(*grid, out, &problem)) {
            candela_io::set_err(err, path, problem);
            std::memset(out, 0, sizeof *out);
            return 1;
        }
        set_name(out, grid_name);
        return 0;
    } catch (const std::exception &e) {
        candela_io::set_err(err, path, std::string("not a readable VDB file: ") + e.what());
    } catch (...) {
        candela_io::set_err(err, path, "not a readable VDB file");
    }
    io_volume_grid_free(out);
    return 1;
}

namespace {

openvdb::FloatGrid::Ptr dense_grid(const float *values, int nx, int ny, int nz, const float index_to_world[16],
                                   const char *name) {
    openvdb::FloatGrid::Ptr grid = openvdb::FloatGrid::create(0.0f);
    grid->setName(name);
    grid->setGridClass(openvdb::GRID_FOG_VOLUME);
    openvdb::math::Mat4d m;
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) m[i][j] = index_to_world[i * 4 + j];
    grid->setTransform(openvdb::math::Transform::createLinearTransform(m));
    auto acc = grid->getAccessor();
    for (int z = 0; z < nz; ++z)
        for (int y = 0; y < ny; ++y)
            for (int x = 0; x < nx; ++x) {
                float v = values[(size_t)x + (size_t)nx * ((size_t)y + (size_t)ny * (size_t)z)];
                if (v != 0.0f) acc.setValue(openvdb::Coord(x, y, z), v);
            }
    return grid;
}

bool dense_size_ok(int nx, int ny, int nz) {
    return nx > 0 && ny > 0 && nz > 0 && nx <= kMaxGridExtent && ny <= kMaxGridExtent && nz <= kMaxGridExtent;
}

}  // namespace

extern "C" int io_write_vdb_dense(const char *path, const char *const *names, const float *const *values, int num_grids,
                                  int nx, int ny, int nz, const float index_to_world[16], char err[IO_ERR_LEN]) {
    if (!dense_size_ok(nx, ny, nz) || num_grids < 1) {
        candela_io::set_err(err, path, "invalid dense grid size");
        return 1;
    }
    std::string tmp = std::string(path) + ".tmp-" + std::to_string((long)getpid());
    try {
        openvdb_init_once();
        openvdb::GridPtrVec grids;
        for (int g = 0; g < num_grids; ++g) grids.push_back(dense_grid(values[g], nx, ny, nz, index_to_world, names[g]));
        openvdb::io::File file(tmp);
        file.write(grids);
        file.close();
        if (std::rename(tmp.c_str(), path) != 0) {
            std::remove(tmp.c_str());
            candela_io::set_err(err, path, "cannot rename the written file into place");
            return 1;
        }
        return 0;
    } catch (const std::exception &e) {
        std::remove(tmp.c_str());
        candela_io::set_err(err, path, std::string("cannot write: ") + e.what());
    }
    return 1;
}

extern "C" int io_volume_grid_from_dense(const float *values, int nx, int ny, int nz, const float index_to_world[16],
                                         const char *name, IoVolumeGrid *out, char err[IO_ERR_LEN]) {
    std::memset(out, 0, sizeof *out);
    if (!dense_size_ok(nx, ny, nz)) {
        candela_io::set_err(err, name, "invalid dense grid size");
        return 1;
    }
    try {
        openvdb_init_once();
        openvdb::FloatGrid::Ptr grid = dense_grid(values, nx, ny, nz, index_to_world, name);
        std::string problem;
        if (!describe(*grid, out, &problem) || !to_nanovdb(*grid, out, &problem)) {
            candela_io::set_err(err, name, problem);
            std::memset(out, 0, sizeof *out);
            return 1;
        }
        set_name(out, name);
        return 0;
    } catch (const std::exception &e) {
        candela_io::set_err(err, name, std::string("cannot build the grid: ") + e.what());
    }
    io_volume_grid_free(out);
    return 1;
}

extern "C" void io_volume_grid_free(IoVolumeGrid *grid) {
    std::free(grid->buffer);
    std::memset(grid, 0, sizeof *grid);
}
