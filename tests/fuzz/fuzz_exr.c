/* tests/fuzz/fuzz_exr.c: libFuzzer over the OpenEXR C API reader (io_read_exr_channel: the
 * reference images of `candela compare`). */
#include "fuzz_common.h"
#include "io.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    const char *path = fuzz_write_input("in.exr", data, size);
    int w = 0, h = 0;
    float *px = NULL;
    char err[IO_ERR_LEN];
    if (io_read_exr_channel(path, "R", &w, &h, &px, err) == 0) free(px);
    return 0;
}
