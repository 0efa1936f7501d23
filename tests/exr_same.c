/* tests/exr_same.c: exit 0 when two of Candela's EXRs hold the same pixels bit for bit (every
 * channel Candela writes, present in both or in neither), 1 when they differ, 2 on an error.
 * The header's provenance (command line, host, times: README "Output") is not compared, so the
 * determinism tests compare images, not files. usage: exr_same A.exr B.exr */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "io.h"

static const char *const CHANNELS[] = {
    "R", "G", "B", "A", "albedo.R", "albedo.G", "albedo.B", "N.X", "N.Y", "N.Z", "Z",
    "variance.R", "variance.G", "variance.B", "recorder_debug.R", "recorder_debug.G", "recorder_debug.B",
    "cachepoint.R", "cachepoint.G", "cachepoint.B", "cachepoint_light.R", "cachepoint_light.G",
    "cachepoint_light.B", "spp", NULL};

int main(int argc, char **argv) {
    if (argc != 3) {
        fprintf(stderr, "usage: exr_same A.exr B.exr\n");
        return 2;
    }
    for (int c = 0; CHANNELS[c]; ++c) {
        int w[2] = {0, 0}, h[2] = {0, 0};
        float *data[2] = {NULL, NULL};
        char err[2][IO_ERR_LEN];
        int rc[2];
        for (int k = 0; k < 2; ++k) rc[k] = io_read_exr_channel(argv[1 + k], CHANNELS[c], &w[k], &h[k], &data[k], err[k]);
        int result = -1;
        if (rc[0] != 0 && rc[1] != 0) {
            if (c == 0) { /* every image has R: neither file is readable */
                fprintf(stderr, "exr_same: %s\n", err[0]);
                result = 2;
            }
        } else if (rc[0] != 0 || rc[1] != 0) {
            fprintf(stderr, "exr_same: channel %s only in %s\n", CHANNELS[c], argv[rc[0] == 0 ? 1 : 2]);
            result = 1;
        } else if (w[0] != w[1] || h[0] != h[1]) {
            fprintf(stderr, "exr_same: sizes differ (%dx%d, %dx%d)\n", w[0], h[0], w[1], h[1]);
            result = 1;
        } else if (memcmp(data[0], data[1], (size_t)w[0] * (size_t)h[0] * sizeof(float)) != 0) {
            fprintf(stderr, "exr_same: channel %s differs\n", CHANNELS[c]);
            result = 1;
        }
        free(data[0]);
        free(data[1]);
        if (result >= 0) return result;
    }
    return 0;
}
