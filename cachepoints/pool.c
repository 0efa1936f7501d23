/* cachepoints/pool.c: pooled visibility learning (beyond the paper; CachePointParams.
 * pool_visibility, the renderer's --cachepoint-pooling).
 *
 * Eq. 6 leaves W = 1 until R = (H_success + 1) / (H_total + 1) drops to R_min, which takes at
 * least 1 / R_min - 1 = 24 attempts. A slot sees an attempt only when its point's vertices
 * select its entry, so with many points and many entries (the city: 40k points x ~130 slots)
 * most slots stay below that for the whole render and the learned visibility never acts,
 * even where every attempt failed. The §3.2.2 blur cannot help: it averages W, and the
 * neighbours' W are 1 for the same reason.
 *
 * Pooling averages the evidence instead of the weights: for a slot with fewer attempts than
 * Eq. 6 needs, H_total and H_success become the weighted sums over the point and its 16 blur
 * neighbours that hold the same key (the Eq. 4 weights of the far-bin blur, relative to the
 * point's own weight 1), and Eqs. 5-6 run on those. A slot with enough attempts of its own
 * keeps them (its own estimate is the unbiased local one). The §3.2.2 blur then runs on the
 * pooled W as on the plain one. Only sampling weights change, so the image stays unbiased.
 * Deterministic: each slot's sums are taken in neighbour order from the counters as they
 * stand at the barrier (before the rescale), written out of place. */
#include <stdlib.h>

#include "internal.h"

typedef struct PoolCtx { CachePoints *cp; uint32_t max_slots; int failed; } PoolCtx;

static void pool_range(void *vctx, size_t b, size_t e, int thread) {
    (void)thread;
    PoolCtx *c = vctx;
    CachePoints *cp = c->cp;
    const float r_min = cp->params.r_min;
    const uint32_t K = cp->params.blur_neighbours;
    double *tot = malloc(((size_t)c->max_slots + 1) * 2 * sizeof(double));
    if (!tot) { c->failed = 1; return; }
    double *suc = tot + c->max_slots + 1;
    for (size_t p = b; p < e; ++p) {
        uint32_t s0 = cp->vis_off[p], s1 = cp->vis_off[p + 1];
        int sparse = 0;
        for (uint32_t s = s0; s < s1; ++s) {
            uint32_t t = cp->vis_count[s].total;
            tot[s - s0] = t;
            suc[s - s0] = (double)cp->vis_count[s].success / (double)CP_VIS_ONE;
            sparse |= (float)t * r_min + r_min < 0.999f; /* Eq. 6 cannot act on this slot alone */
        }
        if (sparse) {
            float self = cp->self_w[p];
            for (uint32_t j = 0; j < K; ++j) {
                uint32_t nb = cp->nbr[p * K + j];
                if (nb == CP_NONE || !(self > 0.0f)) continue;
                double w = (double)cp->nbr_w[p * K + j] / self;
                uint32_t a = s0, q = cp->vis_off[nb], q1 = cp->vis_off[nb + 1];
                while (a < s1 && q < q1) { /* both slot lists are sorted by key */
                    uint32_t ka = cp->vis_key[a], kq = cp->vis_key[q];
                    if (ka < kq) ++a;
                    else if (ka > kq) ++q;
                    else {
                        tot[a - s0] += w * cp->vis_count[q].total;
                        suc[a - s0] += w * (double)cp->vis_count[q].success / (double)CP_VIS_ONE;
                        ++a; ++q;
                    }
                }
            }
        }
        for (uint32_t s = s0; s < s1; ++s) {
            uint32_t t = cp->vis_count[s].total;
            int own = !((float)t * r_min + r_min < 0.999f);
            double T = own ? (double)t : tot[s - s0];
            double S = own ? (double)cp->vis_count[s].success / (double)CP_VIS_ONE : suc[s - s0];
            float R = (float)((S + 1.0) / (T + 1.0)); /* Eq. 5 on the pooled counts */
            cp->w_pool[s] = R <= r_min ? (R / r_min) * (R / r_min) : 1.0f; /* Eq. 6 */
        }
    }
    free(tot);
}

int cp_pool_visibility(CachePoints *cp) {
    if (!cp->w_pool) {
        cp->w_pool = malloc(((size_t)cp->vis_off[cp->n] + 1) * sizeof(float));
        if (!cp->w_pool) return -1;
    }
    PoolCtx c = {cp, 0, 0};
    for (uint32_t p = 0; p < cp->n; ++p) {
        uint32_t s = cp->vis_off[p + 1] - cp->vis_off[p];
        if (s > c.max_slots) c.max_slots = s;
    }
    cp_run_parallel(&cp->params, cp->n, 256, pool_range, &c);
    return c.failed ? -1 : 0;
}
