/* cachepoints/inspect.c: read-only views of the cache points for visualisation (the
 * renderer's `--aov cachepoint` and `--dump-cachepoints`): a per-point summary of the build
 * and of what visibility learning (§3.2) made of it, and the entry a vertex would most
 * likely select (§3.3). Nothing here changes the points or any sampling decision. */
#include <math.h>

#include "internal.h"

void cachepoints_summary(const CachePoints *cp, uint32_t point, CachePointSummary *s) {
    const float *p = cp->pos + 3 * (size_t)point;
    s->pos[0] = p[0]; s->pos[1] = p[1]; s->pos[2] = p[2];
    s->radius = cp->radius[point];
    s->near_count = cp->near_off[point + 1] - cp->near_off[point];
    s->far_count = cp->far_off[point + 1] - cp->far_off[point];
    s->far_clusters = 0;
    for (uint32_t k = cp->far_off[point]; k < cp->far_off[point + 1]; ++k)
        s->far_clusters += cp_key_light(cp, cp->far[k].key) == CP_NONE;
    uint32_t s0 = cp->vis_off[point], s1 = cp->vis_off[point + 1];
    s->slots = s1 - s0;
    s->attempts = 0;
    s->successes = 0.0;
    s->learned_slots = 0;
    s->sparse_slots = 0;
    double wsum = 0.0;
    float wmin = 1.0f;
    for (uint32_t k = s0; k < s1; ++k) {
        uint32_t t = cp->vis_count[k].total;
        s->attempts += t;
        s->successes += (double)cp->vis_count[k].success / (double)CP_VIS_ONE;
        /* Eq. 6 can only leave W = 1 once R = 1 / (t + 1) <= r_min, i.e. t >= 1 / r_min - 1 (24) */
        s->sparse_slots += (float)t * cp->params.r_min + cp->params.r_min < 0.999f;
        float w = cp->w_blurred[k];
        s->learned_slots += w != 1.0f;
        wsum += w;
        if (w < wmin) wmin = w;
    }
    s->mean_w = s->slots ? (float)(wsum / s->slots) : 1.0f;
    s->min_w = wmin;
}

uint32_t cachepoints_top_entry(const CachePoints *cp, const CachePointLights *L, const float x[3], const float *n,
                               const CachePointVertex *v, const float *near_w, int *cluster) {
    uint32_t p = v->point, best = CP_NONE;
    float best_w = 0.0f;
    *cluster = 0;
    uint32_t k0 = cp->near_off[p];
    for (uint32_t k = k0; k < cp->near_off[p + 1]; ++k) {
        float w;
        if (near_w) w = near_w[k - k0];
        else {
            w = L->estimate(L->user, cp->near_light[k], x, n);
            w = w > 0.0f && isfinite(w) ? w * cp->near_vis[k] : 0.0f;
        }
        if (w > best_w) { best_w = w; best = cp->near_light[k]; }
    }
    /* far entries weighted as selection weighs them: the blended steps of the running sums */
    float b[CP_FAR_BINS];
    cp_bin_blend(n, b);
    for (uint32_t k = cp->far_off[p]; k < cp->far_off[p + 1]; ++k) {
        float w = 0.0f;
        for (int i = 0; i < CP_FAR_BINS; ++i) {
            if (!(b[i] > 0.0f)) continue;
            const float *c = cp_cdf(cp, p, i, k);
            w += b[i] * (k > cp->far_off[p] ? c[0] - c[-1] : c[0]);
        }
        if (w > best_w) {
            best_w = w;
            uint32_t key = cp->far[k].key, light = cp_key_light(cp, key);
            *cluster = light == CP_NONE;
            best = light == CP_NONE ? key : light;
        }
    }
    return best;
}
