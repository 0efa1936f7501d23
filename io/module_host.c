/* io/module_host.c: linked into each module (io_module.h), never into the program: the io.h
 * functions a module calls back, forwarded to the program's own (io/files.c), so that e.g. the
 * temporary file a module writes is the one the program's signal handler removes. */
#include "io_module.h"

static const IoModuleHost *host;

void io_module_set_host(const IoModuleHost *h) { host = h; }

void io_temp_begin(const char *tmp_path) { host->temp_begin(tmp_path); }

void io_temp_end(void) { host->temp_end(); }

int io_open_input(const char *path, uint64_t max_bytes, const char *what, int *fd, uint64_t *size,
                  char err[IO_ERR_LEN]) {
    return host->open_input(path, max_bytes, what, fd, size, err);
}
