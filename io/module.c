/* io/module.c: loads the heavy adapters (io_module.h) on first use, and the io.h functions
 * that go through them: the VDB ones here, image decoding in image.cpp. */
#include "io_module.h"
#include "io_err.h"

#include <dlfcn.h>
#include <limits.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#ifdef CANDELA_IO_STATIC_MODULES
/* libFuzzer builds: both adapters are linked in and call io/files.c directly */
void io_module_set_host(const IoModuleHost *host) { (void)host; }
#endif

static const IoModuleHost host = {
    .abi = IO_MODULE_ABI,
    .atomic_begin = io_atomic_begin,
    .atomic_commit = io_atomic_commit,
    .atomic_abort = io_atomic_abort,
    .open_input = io_open_input,
};

#ifndef CANDELA_IO_STATIC_MODULES
/* The folders a module is looked for in, in order (io_module.h); returns how many. */
enum { MAX_DIRS = 5 };
static int module_dirs(char dirs[MAX_DIRS][PATH_MAX]) {
    int n = 0;
    const char *env = getenv("CANDELA_MODULE_DIR");
    if (env && *env) {
        io_fmt(dirs[n++], PATH_MAX, "%s", env);
        return n;
    }
    char exe[PATH_MAX];
    ssize_t len = readlink("/proc/self/exe", exe, sizeof exe - 1);
    if (len > 0) {
        exe[len] = 0;
        char *slash = strrchr(exe, '/');
        if (slash) {
            *slash = 0;
            io_fmt(dirs[n++], PATH_MAX, "%s", exe);
            io_fmt(dirs[n++], PATH_MAX, "%s/../io", exe);
#ifdef CANDELA_MODULE_REL_DIR
            io_fmt(dirs[n++], PATH_MAX, "%s/%s", exe, CANDELA_MODULE_REL_DIR);
#endif
        }
    }
#ifdef CANDELA_MODULE_INSTALL_DIR
    io_fmt(dirs[n++], PATH_MAX, "%s", CANDELA_MODULE_INSTALL_DIR);
#endif
    return n;
}

/* dlopen's the module `file` and returns its entry point `entry`; NULL with the problem (one
 * line naming the file and what needs it) in why. */
static void *open_module(const char *file, const char *entry, const char *needed_for, char why[IO_ERR_LEN]) {
    char dirs[MAX_DIRS][PATH_MAX];
    const int n = module_dirs(dirs);
    char looked[IO_ERR_LEN] = "";
    for (int i = 0; i < n; ++i) {
        char path[PATH_MAX + 64];
        io_fmt(path, sizeof path, "%s/%s", dirs[i], file);
        struct stat st;
        if (stat(path, &st) != 0) {
            size_t used = strlen(looked);
            io_fmt(looked + used, sizeof looked - used, "%s%s", used ? ", " : "", dirs[i]);
            continue;
        }
        /* RTLD_LOCAL: the library's symbols stay out of the program's scope. RTLD_LAZY: its
         * calls bind on first use, as they did when the program linked it (RTLD_NOW binds all
         * of OpenImageIO's ~250 libraries up front: +78M instructions for a textured scene).
         * Not RTLD_DEEPBIND (~100M fewer lookups): the module's malloc would then be libc's
         * even under valgrind or a preloaded allocator, while the program frees its buffers. */
        void *handle = dlopen(path, RTLD_LAZY | RTLD_LOCAL);
        if (!handle) {
            const char *e = dlerror();
            io_fmt(why, IO_ERR_LEN, "cannot load %s (%s): %s", path, needed_for, e ? e : "dlopen failed");
            return NULL;
        }
        void *sym = dlsym(handle, entry);
        if (!sym) {
            io_fmt(why, IO_ERR_LEN, "%s has no %s (%s): a module of another build?", path, entry, needed_for);
            return NULL;
        }
        return sym;
    }
    io_fmt(why, IO_ERR_LEN, "%s not found (%s; looked in %s%s)", file, needed_for, looked,
           getenv("CANDELA_MODULE_DIR") ? ", from CANDELA_MODULE_DIR" : "");
    return NULL;
}

#endif

static pthread_mutex_t lock = PTHREAD_MUTEX_INITIALIZER;

/* One module: where it is, and its state, tried once (under the lock) and kept. */
typedef struct Module {
    const char *file, *entry;
    IoModuleEntry linked; /* CANDELA_IO_STATIC_MODULES: the entry point linked in */
    void *table;          /* the module's table (IoImageModule, IoVdbModule), filled by its entry */
    size_t table_size;
    int state;            /* 0 not tried, 1 loaded, -1 failed (why holds the reason) */
    char why[IO_ERR_LEN];
} Module;

/* The module's table, loading it on first use; NULL with "PREFIX: why" in err. */
static const void *module_table(Module *m, const char *prefix, const char *needed_for, char err[IO_ERR_LEN]) {
    pthread_mutex_lock(&lock);
    if (m->state == 0) {
        IoModuleEntry fn = m->linked;
#ifndef CANDELA_IO_STATIC_MODULES
        void *sym = open_module(m->file, m->entry, needed_for, m->why);
        memcpy(&fn, &sym, sizeof fn); /* dlsym's object pointer as the function it names (POSIX) */
#endif
        if (fn && (fn(&host, m->table, m->table_size) != 0 || *(const int *)m->table != IO_MODULE_ABI)) {
            io_fmt(m->why, sizeof m->why, "%s is of another version (%s)", m->file, needed_for);
            fn = NULL;
        }
        m->state = fn ? 1 : -1;
    }
    const int state = m->state;
    pthread_mutex_unlock(&lock);
    if (state == 1) return m->table;
    io_err(err, prefix, "%s", m->why);
    return NULL;
}

#ifdef CANDELA_IO_STATIC_MODULES
#define LINKED(entry) entry
#else
#define LINKED(entry) NULL
#endif

const IoImageModule *io_image_module(const char *prefix, const char *needed_for, char err[IO_ERR_LEN]) {
    static IoImageModule table;
    static Module m = {IO_IMAGE_MODULE_FILE, IO_IMAGE_MODULE_ENTRY, LINKED(candela_io_image_module), &table, sizeof table, 0, ""};
    return module_table(&m, prefix, needed_for, err);
}

const IoVdbModule *io_vdb_module(const char *prefix, const char *needed_for, char err[IO_ERR_LEN]) {
    static IoVdbModule table;
    static Module m = {IO_VDB_MODULE_FILE, IO_VDB_MODULE_ENTRY, LINKED(candela_io_vdb_module), &table, sizeof table, 0, ""};
    return module_table(&m, prefix, needed_for, err);
}

/* ---------------------------------------------------------------- VDB (io.h) */
#define VDB_NEEDED "OpenVDB, needed to read VDB volumes"
#define VDB_BUILD_NEEDED "OpenVDB, needed to build volume grids"
#define VDB_WRITE_NEEDED "OpenVDB, needed to write VDB files"

int io_load_vdb_grid(const char *path, const char *grid_name, IoVolumeGrid *grid, char err[IO_ERR_LEN]) {
    memset(grid, 0, sizeof *grid);
    /* the checks that need no OpenVDB first: a missing file says so, module or not */
    struct stat st;
    if (stat(path, &st) != 0) {
        io_err(err, path, "cannot open: no such file");
        return 1;
    }
    if (!S_ISREG(st.st_mode)) {
        io_err(err, path, "not a regular file");
        return 1;
    }
    const IoVdbModule *m = io_vdb_module(path, VDB_NEEDED, err);
    return m ? m->load_grid(path, grid_name, grid, err) : 1;
}

int io_volume_grid_from_dense(const float *values, int nx, int ny, int nz, const float index_to_world[16],
                              const char *name, IoVolumeGrid *grid, char err[IO_ERR_LEN]) {
    memset(grid, 0, sizeof *grid);
    const IoVdbModule *m = io_vdb_module(name, VDB_BUILD_NEEDED, err);
    return m ? m->from_dense(values, nx, ny, nz, index_to_world, name, grid, err) : 1;
}

int io_volume_grid_from_voxels(const int32_t *ijk, const float *values, size_t count, const int32_t *boxes,
                               const float *box_values, size_t num_boxes, const float index_to_world[16],
                               const char *name, IoVolumeGrid *grid, char err[IO_ERR_LEN]) {
    memset(grid, 0, sizeof *grid);
    const IoVdbModule *m = io_vdb_module(name, VDB_BUILD_NEEDED, err);
    return m ? m->from_voxels(ijk, values, count, boxes, box_values, num_boxes, index_to_world, name, grid, err) : 1;
}

int io_write_vdb_dense(const char *path, const char *const *names, const float *const *values, int num_grids,
                       int nx, int ny, int nz, const float index_to_world[16], char err[IO_ERR_LEN]) {
    const IoVdbModule *m = io_vdb_module(path, VDB_WRITE_NEEDED, err);
    return m ? m->write_dense(path, names, values, num_grids, nx, ny, nz, index_to_world, err) : 1;
}
