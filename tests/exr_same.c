/* tests/exr_same.c: exit 0 when two of Candela's EXRs hold the same pixels bit for bit (every
 * channel Candela writes, present in both or in neither), 1 when they differ, 2 on an error.
 * The header's provenance (command line, host, times: README "Output") is not compared, so the
 * determinism tests compare images, not files. usage: exr_same A.exr B.exr
 *
 * exr_same --at X,Y A.exr B.exr: B is a part of A (a --crop render against the full render):
 * every channel of B equals A's pixels from (X, Y) on, bit for bit (B's size, inside A). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "io.h"

static const char *const CHANNELS[] = {
    "R", "G", "B", "A", "albedo.R", "albedo.G", "albedo.B", "N.X", "N.Y", "N.Z", "Z",
    "variance.R", "variance.G", "variance.B", "recorder_debug.R", "recorder_debug.G", "recorder_debug.B",
    "cachepoint.R", "cachepoint.G", "cachepoint.B", "cachepoint_light.R", "cachepoint_light.G",
    "cachepoint_light.B", "spp", NULL};

/* B (wb x hb) against A's (wa x ha) region at (x0, y0): 0 equal, 1 not (the first pixel said) */
static int region_differs(const char *channel, const float *a, int wa, int ha, const float *b, int wb, int hb, int x0,
                          int y0) {
    if (x0 + wb > wa || y0 + hb > ha) {
        fprintf(stderr, "exr_same: %dx%d at (%d, %d) is not inside %dx%d\n", wb, hb, x0, y0, wa, ha);
        return 1;
    }
    for (int y = 0; y < hb; ++y)
        if (memcmp(b + (size_t)y * wb, a + (size_t)(y0 + y) * wa + x0, (size_t)wb * sizeof(float)) != 0) {
            for (int x = 0; x < wb; ++x)
                if (memcmp(&b[(size_t)y * wb + x], &a[(size_t)(y0 + y) * wa + x0 + x], sizeof(float)) != 0) {
                    fprintf(stderr, "exr_same: channel %s differs at (%d, %d) of the part: %.9g, not %.9g\n", channel, x, y,
                            (double)b[(size_t)y * wb + x], (double)a[(size_t)(y0 + y) * wa + x0 + x]);
                    break;
                }
            return 1;
        }
    return 0;
}

int main(int argc, char **argv) {
    int at = 0, x0 = 0, y0 = 0;
    if (argc == 5 && strcmp(argv[1], "--at") == 0) {
        char tail = 0;
        if (sscanf(argv[2], "%d,%d%c", &x0, &y0, &tail) != 2 || x0 < 0 || y0 < 0) {
            fprintf(stderr, "exr_same: --at wants X,Y (two integers >= 0), not '%s'\n", argv[2]);
            return 2;
        }
        at = 1;
        argv += 2;
        argc -= 2;
    }
    if (argc != 3) {
        fprintf(stderr, "usage: exr_same [--at X,Y] A.exr B.exr\n");
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
        } else if (at) {
            result = region_differs(CHANNELS[c], data[0], w[0], h[0], data[1], w[1], h[1], x0, y0) ? 1 : -1;
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
