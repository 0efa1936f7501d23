/* tests/fuzz/fuzz_vdb.c: libFuzzer over the OpenVDB adapter (io_load_vdb_grid: Candela's walk
 * of the file, OpenVDB's reader of the grid "density", then the conversion to a NanoVDB
 * buffer). */
#include "fuzz_common.h"
#include "io.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    const char *path = fuzz_write_input("in.vdb", data, size);
    IoVolumeGrid grid;
    char err[IO_ERR_LEN];
    if (io_load_vdb_grid(path, "density", &grid, err) == 0) io_volume_grid_free(&grid);
    return 0;
}
