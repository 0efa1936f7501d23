/* io/io_module.h: the two heavy adapters as modules loaded on first use (private to io/).
 *
 * OpenImageIO (image reading) and OpenVDB (volumes) pull in ~250 shared libraries between them
 * (boost, TBB, every image codec...), whose loading and symbol binding cost more start-up time
 * than a small render takes. They live in shared modules beside the program, opened with
 * dlopen(RTLD_LAZY | RTLD_LOCAL) the first time a run needs one:
 *   candela_io_image.so  image_module.cpp: decoding textures, environment maps and any image
 *                         io_load_image reads (OpenImageIO)
 *   candela_io_vdb.so    vdb.cpp: reading, building and writing VDB grids (OpenVDB)
 * Everything else in io/ (glTF, EXR through the OpenEXR C API, PNG through libpng, files) is in
 * the program. Each module exports one C entry point, which receives the host's functions the
 * module calls back (so that a file a module writes goes through the program's own atomic
 * writer, whose registry the signal handler reads) and fills a table of the module's functions. No C++ type crosses it.
 *
 * Where a module is looked for (module.c): $CANDELA_MODULE_DIR when set (only there), else the
 * program's own folder, ../io beside it (the build tree: build/renderer/candela and
 * build/tests/test_* find build/io/), the install folder relative to the program
 * (bindir/../libdir/candela) and the install folder itself. A missing module is a one-line
 * error naming the file and what needs it.
 *
 * With -Dfuzz=true (libFuzzer builds) both adapters are linked into the program instead
 * (CANDELA_IO_STATIC_MODULES): the harnesses then cover them without loading anything. */
#ifndef CANDELA_IO_MODULE_H
#define CANDELA_IO_MODULE_H

#include "io.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Bumped whenever a table below changes: a module of another version is refused. */
#define IO_MODULE_ABI 2

/* What a module calls back in the program (io/atomic_file.c, io/files.c). */
typedef struct IoModuleHost {
    int abi;
    int (*atomic_begin)(IoAtomicFile *af, const char *path, const char *mode, char err[IO_ERR_LEN]);
    int (*atomic_commit)(IoAtomicFile *af, char err[IO_ERR_LEN]);
    void (*atomic_abort)(IoAtomicFile *af);
    int (*open_input)(const char *path, uint64_t max_bytes, const char *what, int *fd, uint64_t *size,
                      char err[IO_ERR_LEN]);
} IoModuleHost;

/* A module's entry point: checks the host's version, keeps it (io_module_set_host) and fills
 * its table (table_size bytes: a table of another size is refused), whose first member is the
 * abi. One signature for every module, so that module.c loads them all by one function. */
typedef int (*IoModuleEntry)(const IoModuleHost *host, void *table, size_t table_size);

/* candela_io_image.so. decode: io_internal.hpp's decode_image with a C signature (problem:
 * the one-line reason without a file-name prefix). */
typedef struct IoImageModule {
    int abi;
    int (*decode)(const char *path, const void *mem, size_t mem_size, int srgb, int keep_8bit,
                  uint64_t max_bytes, IoImage *out, char problem[IO_ERR_LEN]);
} IoImageModule;
#define IO_IMAGE_MODULE_FILE "candela_io_image.so"
#define IO_IMAGE_MODULE_ENTRY "candela_io_image_module"
int candela_io_image_module(const IoModuleHost *host, void *table, size_t table_size);

/* candela_io_vdb.so: io.h's VDB functions that need OpenVDB. */
typedef struct IoVdbModule {
    int abi;
    int (*load_grid)(const char *path, const char *grid_name, IoVolumeGrid *grid, char err[IO_ERR_LEN]);
    int (*from_dense)(const float *values, int nx, int ny, int nz, const float index_to_world[16],
                      const char *name, IoVolumeGrid *grid, char err[IO_ERR_LEN]);
    int (*from_voxels)(const int32_t *ijk, const float *values, size_t count, const int32_t *boxes,
                       const float *box_values, size_t num_boxes, const float index_to_world[16],
                       const char *name, IoVolumeGrid *grid, char err[IO_ERR_LEN]);
    int (*write_dense)(const char *path, const char *const *names, const float *const *values, int num_grids,
                       int nx, int ny, int nz, const float index_to_world[16], char err[IO_ERR_LEN]);
} IoVdbModule;
#define IO_VDB_MODULE_FILE "candela_io_vdb.so"
#define IO_VDB_MODULE_ENTRY "candela_io_vdb_module"
int candela_io_vdb_module(const IoModuleHost *host, void *table, size_t table_size);

/* The module's table, loading it on first use (thread-safe); NULL with "PREFIX: problem" in
 * err when it cannot be loaded (the problem names the module file and `needed_for`). */
const IoImageModule *io_image_module(const char *prefix, const char *needed_for, char err[IO_ERR_LEN]);
const IoVdbModule *io_vdb_module(const char *prefix, const char *needed_for, char err[IO_ERR_LEN]);

/* Inside a module: the host the entry point was given (module_host.c forwards io_atomic_begin,
 * io_atomic_commit, io_atomic_abort and io_open_input to it). */
void io_module_set_host(const IoModuleHost *host);

#ifdef __cplusplus
}
#endif

#endif
