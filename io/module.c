/* io/module.c: loads the heavy adapters (io_module.h) on first use, and the io.h functions
 * that go through them: the VDB ones here, image decoding in image.cpp. */
#include "io_module.h"

#include <dlfcn.h>
#include <limits.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

/* snprintf that may truncate (messages are one line of at most IO_ERR_LEN) */
static void fmt(char *buf, size_t len, const char *format, ...) __attribute__((format(printf, 3, 4)));
static void fmt(char *buf, size_t len, const char *format, ...) {
    va_list ap;
    va_start(ap, format);
    vsnprintf(buf, len, format, ap);
    va_end(ap);
}

static void set_err(char err[IO_ERR_LEN], const char *prefix, const char *problem) {
    if (err) fmt(err, IO_ERR_LEN, "%s: %s", prefix ? prefix : "(null)", problem);
}

#ifdef CANDELA_IO_STATIC_MODULES
/* libFuzzer builds: both adapters are linked in and call io/files.c directly */
void io_module_set_host(const IoModuleHost *host) { (void)host; }
#endif

static const IoModuleHost host = {
    .abi = IO_MODULE_ABI,
    .temp_begin = io_temp_begin,
    .temp_end = io_temp_end,
    .open_input = io_open_input,
};

#ifndef CANDELA_IO_STATIC_MODULES
/* The folders a module is looked for in, in order (io_module.h); returns how many. */
enum { MAX_DIRS = 5 };
static int module_dirs(char dirs[MAX_DIRS][PATH_MAX]) {
    int n = 0;
    const char *env = getenv("CANDELA_MODULE_DIR");
    if (env && *env) {
        fmt(dirs[n++], PATH_MAX, "%s", env);
        return n;
    }
    char exe[PATH_MAX];
    ssize_t len = readlink("/proc/self/exe", exe, sizeof exe - 1);
    if (len > 0) {
        exe[len] = 0;
        char *slash = strrchr(exe, '/');
        if (slash) {
            *slash = 0;
            fmt(dirs[n++], PATH_MAX, "%s", exe);
            fmt(dirs[n++], PATH_MAX, "%s/../io", exe);
#ifdef CANDELA_MODULE_REL_DIR
            fmt(dirs[n++], PATH_MAX, "%s/%s", exe, CANDELA_MODULE_REL_DIR);
#endif
        }
    }
#ifdef CANDELA_MODULE_INSTALL_DIR
    fmt(dirs[n++], PATH_MAX, "%s", CANDELA_MODULE_INSTALL_DIR);
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
        fmt(path, sizeof path, "%s/%s", dirs[i], file);
        struct stat st;
        if (stat(path, &st) != 0) {
            size_t used = strlen(looked);
            fmt(looked + used, sizeof looked - used, "%s%s", used ? ", " : "", dirs[i]);
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
            fmt(why, IO_ERR_LEN, "cannot load %s (%s): %s", path, needed_for, e ? e : "dlopen failed");
            return NULL;
        }
        void *sym = dlsym(handle, entry);
        if (!sym) {
            fmt(why, IO_ERR_LEN, "%s has no %s (%s): a module of another build?", path, entry, needed_for);
            return NULL;
        }
        return sym;
    }
    fmt(why, IO_ERR_LEN, "%s not found (%s; looked in %s%s)", file, needed_for, looked,
             getenv("CANDELA_MODULE_DIR") ? ", from CANDELA_MODULE_DIR" : "");
    return NULL;
}

#endif

static pthread_mutex_t lock = PTHREAD_MUTEX_INITIALIZER;

typedef int (*ImageEntry)(const IoModuleHost *, IoImageModule *);
typedef int (*VdbEntry)(const IoModuleHost *, IoVdbModule *);

const IoImageModule *io_image_module(const char *prefix, const char *needed_for, char err[IO_ERR_LEN]) {
    static IoImageModule module;
    static int state; /* 0 not tried, 1 loaded, -1 failed (why holds the reason) */
    static char why[IO_ERR_LEN];
    pthread_mutex_lock(&lock);
    if (state == 0) {
#ifdef CANDELA_IO_STATIC_MODULES
        ImageEntry fn = candela_io_image_module;
#else
        ImageEntry fn;
        void *sym = open_module(IO_IMAGE_MODULE_FILE, IO_IMAGE_MODULE_ENTRY, needed_for, why);
        memcpy(&fn, &sym, sizeof fn);
#endif
        if (fn && (fn(&host, &module) != 0 || module.abi != IO_MODULE_ABI)) {
            fmt(why, sizeof why, "%s is of another version (%s)", IO_IMAGE_MODULE_FILE, needed_for);
            fn = NULL;
        }
        state = fn ? 1 : -1;
    }
    pthread_mutex_unlock(&lock);
    if (state == 1) return &module;
    set_err(err, prefix, why);
    return NULL;
}

const IoVdbModule *io_vdb_module(const char *prefix, const char *needed_for, char err[IO_ERR_LEN]) {
    static IoVdbModule module;
    static int state;
    static char why[IO_ERR_LEN];
    pthread_mutex_lock(&lock);
    if (state == 0) {
#ifdef CANDELA_IO_STATIC_MODULES
        VdbEntry fn = candela_io_vdb_module;
#else
        VdbEntry fn;
        void *sym = open_module(IO_VDB_MODULE_FILE, IO_VDB_MODULE_ENTRY, needed_for, why);
        memcpy(&fn, &sym, sizeof fn);
#endif
        if (fn && (fn(&host, &module) != 0 || module.abi != IO_MODULE_ABI)) {
            fmt(why, sizeof why, "%s is of another version (%s)", IO_VDB_MODULE_FILE, needed_for);
            fn = NULL;
        }
        state = fn ? 1 : -1;
    }
    pthread_mutex_unlock(&lock);
    if (state == 1) return &module;
    set_err(err, prefix, why);
    return NULL;
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
        set_err(err, path, "cannot open: no such file");
        return 1;
    }
    if (!S_ISREG(st.st_mode)) {
        set_err(err, path, "not a regular file");
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
