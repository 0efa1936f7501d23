/* tests/exr_stats.c: what a test needs to know of a rendered image without a reference: the
 * count of non-finite values in R, G and B, their means, the fraction of pixels with any
 * light, and how many tiles of an 8 x 8 grid are black (every pixel 0 in R, G and B: a tile
 * the renderer never wrote or lit). One line of JSON on stdout; exit 2 on an error.
 * usage: exr_stats IMAGE.exr */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "io.h"

int main(int argc, char **argv) {
    if (argc != 2) {
        fprintf(stderr, "usage: exr_stats IMAGE.exr\n");
        return 2;
    }
    static const char *const CH[3] = {"R", "G", "B"};
    float *data[3] = {NULL, NULL, NULL};
    int w = 0, h = 0;
    for (int c = 0; c < 3; ++c) {
        char err[IO_ERR_LEN];
        int cw = 0, chh = 0;
        if (io_read_exr_channel(argv[1], CH[c], &cw, &chh, &data[c], err) != 0) {
            fprintf(stderr, "exr_stats: %s\n", err);
            return 2;
        }
        if (c > 0 && (cw != w || chh != h)) {
            fprintf(stderr, "exr_stats: %s: channels of different sizes\n", argv[1]);
            return 2;
        }
        w = cw;
        h = chh;
    }
    enum { GRID = 8 };
    int lit_tile[GRID][GRID] = {{0}};
    long long nonfinite = 0, lit = 0;
    double sum[3] = {0.0, 0.0, 0.0};
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            size_t i = (size_t)y * (size_t)w + (size_t)x;
            int any = 0;
            for (int c = 0; c < 3; ++c) {
                float v = data[c][i];
                if (!isfinite(v)) {
                    ++nonfinite;
                    continue;
                }
                sum[c] += v;
                if (v != 0.0f) any = 1;
            }
            if (any) {
                ++lit;
                lit_tile[(long)y * GRID / h][(long)x * GRID / w] = 1;
            }
        }
    int black_tiles = 0;
    for (int ty = 0; ty < GRID; ++ty)
        for (int tx = 0; tx < GRID; ++tx) black_tiles += !lit_tile[ty][tx];
    double n = (double)w * (double)h;
    printf("{\"width\": %d, \"height\": %d, \"nonfinite\": %lld, \"mean\": [%.9g, %.9g, %.9g], "
           "\"lit_fraction\": %.6f, \"black_tiles\": %d}\n",
           w, h, nonfinite, sum[0] / n, sum[1] / n, sum[2] / n, (double)lit / n, black_tiles);
    for (int c = 0; c < 3; ++c) free(data[c]);
    return 0;
}
