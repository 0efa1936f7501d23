/* io/module_host.c: linked into each module (io_module.h), never into the program: the io.h
 * functions a module calls back, forwarded to the program's own (io/atomic_file.c, io/files.c),
 * so that e.g. the temporary file a module writes is one the program's signal handler removes. */
#include "io_module.h"

static const IoModuleHost *host;

void io_module_set_host(const IoModuleHost *h) { host = h; }

int io_atomic_begin(IoAtomicFile *af, const char *path, const char *mode, char err[IO_ERR_LEN]) {
    return host->atomic_begin(af, path, mode, err);
}

int io_atomic_commit(IoAtomicFile *af, char err[IO_ERR_LEN]) { return host->atomic_commit(af, err); }

void io_atomic_abort(IoAtomicFile *af) { host->atomic_abort(af); }

int io_open_input(const char *path, uint64_t max_bytes, const char *what, int *fd, uint64_t *size,
                  char err[IO_ERR_LEN]) {
    return host->open_input(path, max_bytes, what, fd, size, err);
}
