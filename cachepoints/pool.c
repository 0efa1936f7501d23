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
 *
 * Mode 2 (cut build only) also pools over lights: a slot still short of attempts after the
 * spatial pooling takes the spatially pooled counts of every slot of its point whose key lies
 * below an ancestor of its key in the light tree (the tree is built spatially, so these are
 * the lights next to it: windows of one facade behind the same wall), climbing one level at a
 * time until the sums reach Eq. 6's threshold or POOL_TREE_LEVELS levels.
 *
 * Deterministic: each slot's sums are taken in a fixed order from the counters as they stand
 * at the barrier (before the rescale), written out of place. */
#include <stdlib.h>

#include "internal.h"

#define POOL_TREE_LEVELS 4 /* mode 2: at most this many light-tree levels up (16 lights' subtree) */

typedef struct PoolCtx { CachePoints *cp; uint32_t max_slots; int failed; } PoolCtx;

/* Eq. 6 cannot leave W = 1 with fewer attempts than this: R >= 1 / (T + 1) > r_min */
static inline int too_few(double attempts, float r_min) { return (float)attempts * r_min + r_min < 0.999f; }

static inline float pooled_weight(double T, double S, float r_min) {
    float R = (float)((S + 1.0) / (T + 1.0)); /* Eq. 5 on the pooled counts */
    return R <= r_min ? (R / r_min) * (R / r_min) : 1.0f; /* Eq. 6 */
}

static void pool_range(void *vctx, size_t b, size_t e, int thread) {
    (void)thread;
    PoolCtx *c = vctx;
    CachePoints *cp = c->cp;
    const float r_min = cp->params.r_min;
    const uint32_t K = cp->params.blur_neighbours;
    double *tot = malloc(((size_t)c->max_slots + 1) * 4 * sizeof(double));
    if (!tot) { c->failed = 1; return; }
    double *suc = tot + c->max_slots + 1;
    double *cum_t = suc + c->max_slots + 1, *cum_s = cum_t + c->max_slots + 1; /* mode 2: prefix sums */
    for (size_t p = b; p < e; ++p) {
        uint32_t s0 = cp->vis_off[p], s1 = cp->vis_off[p + 1];
        int sparse = 0;
        for (uint32_t s = s0; s < s1; ++s) {
            uint32_t t = cp->vis_count[s].total;
            tot[s - s0] = t;
            suc[s - s0] = (double)cp->vis_count[s].success / (double)CP_VIS_ONE;
            sparse |= too_few(t, r_min);
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
        int tree = sparse && cp->key_parent;
        if (tree) { /* prefix sums of the spatially pooled counts, in key order */
            double t = 0.0, u = 0.0;
            for (uint32_t s = s0; s < s1; ++s) {
                cum_t[s - s0] = t; cum_s[s - s0] = u;
                t += tot[s - s0]; u += suc[s - s0];
            }
            cum_t[s1 - s0] = t; cum_s[s1 - s0] = u;
        }
        for (uint32_t s = s0; s < s1; ++s) {
            uint32_t t = cp->vis_count[s].total;
            if (!too_few(t, r_min)) {
                cp->w_pool[s] = pooled_weight(t, (double)cp->vis_count[s].success / (double)CP_VIS_ONE, r_min);
                continue;
            }
            double T = tot[s - s0], S = suc[s - s0];
            uint32_t key = cp->vis_key[s];
            for (int level = 0; tree && too_few(T, r_min) && level < POOL_TREE_LEVELS; ++level) {
                key = cp->key_parent[key];
                if (key == CP_NONE) break;
                /* the point's slots whose keys lie below the ancestor: one contiguous run */
                uint32_t lo = cp_lower_bound(cp->vis_key, s0, s1, key);
                uint32_t hi = cp_lower_bound(cp->vis_key, lo, s1, cp->key_end[key]);
                T = cum_t[hi - s0] - cum_t[lo - s0];
                S = cum_s[hi - s0] - cum_s[lo - s0];
            }
            cp->w_pool[s] = pooled_weight(T, S, r_min);
        }
    }
    free(tot);
}

/* Mode 2: the parent of every key of the light tree (depth-first: node k's first child is
 * k + 1 and its second the node after the first child's subtree, key_end[k + 1]); CP_NONE for
 * the root and the keys of infinite lights. */
static int key_parents(CachePoints *cp) {
    cp->key_parent = malloc(((size_t)cp->num_keys + 1) * sizeof(uint32_t));
    if (!cp->key_parent) return -1;
    for (uint32_t k = 0; k < cp->num_keys; ++k) cp->key_parent[k] = CP_NONE;
    uint32_t nodes = cp->num_keys ? cp->key_end[0] : 0; /* the root's subtree: every tree node */
    for (uint32_t k = 0; k < nodes; ++k) {
        if (cp->key_end[k] <= k + 1) continue; /* a leaf */
        cp->key_parent[k + 1] = k;
        if (cp->key_end[k + 1] < cp->key_end[k]) cp->key_parent[cp->key_end[k + 1]] = k;
    }
    return 0;
}

int cp_pool_visibility(CachePoints *cp) {
    if (!cp->w_pool) {
        cp->w_pool = malloc(((size_t)cp->vis_off[cp->n] + 1) * sizeof(float));
        if (!cp->w_pool) return -1;
    }
    if (cp->params.pool_visibility >= 2 && cp->key_end && !cp->key_parent && key_parents(cp) != 0) return -1;
    PoolCtx c = {cp, 0, 0};
    for (uint32_t p = 0; p < cp->n; ++p) {
        uint32_t s = cp->vis_off[p + 1] - cp->vis_off[p];
        if (s > c.max_slots) c.max_slots = s;
    }
    cp_run_parallel(&cp->params, cp->n, 256, pool_range, &c);
    return c.failed ? -1 : 0;
}
