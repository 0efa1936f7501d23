/* cachepoints/checkpoint.c: the cache points' learned state for checkpoints (a resumed render
 * continues bit-identically).
 *
 * The build is a deterministic function of the scene and the options, so a resumed render
 * rebuilds the points and only what visibility learning changed is saved: the counters of every
 * slot (Eq. 5, accumulating within an iteration), W' after the last barrier with its per-point
 * flags, and the render tables built from it (near W', the far bins' running sums and totals).
 * The tables could be rebuilt from W', but copying them is exact by construction. Native byte
 * order; the sizes of the build are checked, so a checkpoint of another build is refused. */
#include <stdio.h>

#include "internal.h"

#define CP_CHECKPOINT_MAGIC 0x4b435043u /* "CPCK" */
#define CP_CHECKPOINT_VERSION 1u

static int put(FILE *out, const void *p, size_t n) { return fwrite(p, 1, n, out) == n ? 0 : -1; }
static int get(FILE *in, void *p, size_t n) { return fread(p, 1, n, in) == n ? 0 : -1; }

int cachepoints_save_learned(const CachePoints *cp, FILE *out) {
    uint32_t n = cp->n, a = cp->near_off[n], f = cp->far_off[n], v = cp->vis_off[n];
    uint32_t head[6] = {CP_CHECKPOINT_MAGIC, CP_CHECKPOINT_VERSION, n, a, f, v};
    return put(out, head, sizeof head) | put(out, cp->vis_count, (size_t)v * sizeof *cp->vis_count) |
           put(out, cp->w_blurred, (size_t)v * sizeof *cp->w_blurred) | put(out, cp->vis_low, n) |
           put(out, cp->vis_active, n) | put(out, cp->tables_dirty, n) |
           put(out, cp->near_vis, (size_t)a * sizeof *cp->near_vis) |
           put(out, cp->far_cdf, (size_t)f * CP_FAR_BINS * sizeof *cp->far_cdf) |
           put(out, cp->far_bin_total, (size_t)n * CP_BIN_STRIDE * sizeof *cp->far_bin_total);
}

int cachepoints_load_learned(CachePoints *cp, FILE *in) {
    uint32_t n = cp->n, a = cp->near_off[n], f = cp->far_off[n], v = cp->vis_off[n];
    uint32_t head[6];
    if (get(in, head, sizeof head) || head[0] != CP_CHECKPOINT_MAGIC || head[1] != CP_CHECKPOINT_VERSION) return -1;
    if (head[2] != n || head[3] != a || head[4] != f || head[5] != v) return -2;
    /* read in place: on failure the caller abandons the render, so a half-read state is never used */
    return get(in, cp->vis_count, (size_t)v * sizeof *cp->vis_count) |
           get(in, cp->w_blurred, (size_t)v * sizeof *cp->w_blurred) | get(in, cp->vis_low, n) |
           get(in, cp->vis_active, n) | get(in, cp->tables_dirty, n) |
           get(in, cp->near_vis, (size_t)a * sizeof *cp->near_vis) |
           get(in, cp->far_cdf, (size_t)f * CP_FAR_BINS * sizeof *cp->far_cdf) |
           get(in, cp->far_bin_total, (size_t)n * CP_BIN_STRIDE * sizeof *cp->far_bin_total);
}
