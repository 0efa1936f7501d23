/* cachepoints/far_linear.c: the paper's light distributions (§3.1.3). Every light is
 * estimated at every point: finite lights within D r_p are near (Eq. 1), the others fill
 * seven far bins (irradiance on the six cardinal planes, fluence), each keeping the lights
 * that hold 97% of its energy, 4 to 256 of them. The cost is O(lights) per point: the
 * scaling failure of §5.2.2, which far_cut.c avoids. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "build_internal.h"

uint32_t cp_bin_keep(const CachePointParams *P, ValueIndex *vi, uint32_t n, double total) {
    uint32_t len = cp_select_energy_prefix(vi, n, P->energy_fraction * total);
    uint32_t lo = P->min_per_bin < n ? P->min_per_bin : n;
    if (len < lo) { cp_select_top(vi, n, lo); len = lo; }
    if (len > P->max_per_bin) { cp_select_top(vi, len, P->max_per_bin); len = P->max_per_bin; }
    return len;
}

typedef struct LinearScratch {
    float *values;      /* CP_FAR_BINS per light */
    uint8_t *is_near;   /* per light */
    uint8_t *keep;      /* per light: bit b set when far bin b keeps it */
    ValueIndex *vi;     /* per light */
} LinearScratch;

static void scratch_free(void *vs) {
    LinearScratch *s = vs;
    if (!s) return;
    free(s->values); free(s->is_near); free(s->keep); free(s->vi);
    free(s);
}

static void *scratch_new(const DistCtx *c) {
    uint32_t N = c->lights->count;
    LinearScratch *s = calloc(1, sizeof *s);
    if (!s) return NULL;
    s->values = malloc((size_t)(N ? N : 1) * CP_FAR_BINS * sizeof(float));
    s->is_near = malloc(N ? N : 1);
    s->keep = malloc(N ? N : 1);
    s->vi = malloc((size_t)(N ? N : 1) * sizeof *s->vi);
    if (!s->values || !s->is_near || !s->keep || !s->vi) { scratch_free(s); return NULL; }
    return s;
}

static int linear_point(const DistCtx *c, void *vs, size_t i) {
    LinearScratch *s = vs;
    const CachePointLights *L = c->lights;
    const CachePointParams *P = c->params;
    uint32_t N = L->count;
    const float *x = c->pts + 3 * i;
    float rn = P->near_factor * c->near_radius[i];
    Dist *d = &c->dist[i];
    float *values = s->values;
    /* Eq. 1: finite lights whose centroid lies within D r_p are near; infinite lights are
     * always far (§3.1.3) */
    uint32_t near_count = 0;
    for (uint32_t l = 0; l < N; ++l) {
        if (c->omni) values[(size_t)l * CP_FAR_BINS + CP_OMNI_BIN] = L->estimate(L->user, l, x, NULL);
        else L->estimate7(L->user, l, x, values + (size_t)l * CP_FAR_BINS);
        s->is_near[l] = !L->infinite[l] && cp_dist2(L->centroid + 3 * (size_t)l, x) <= rn * rn;
        near_count += s->is_near[l];
    }
    if (near_count > P->max_near) {
        /* cap (the paper sets none; CachePointParams.max_near): keep the strongest by
         * fluence; the rest become far */
        uint32_t m = 0;
        for (uint32_t l = 0; l < N; ++l)
            if (s->is_near[l]) { s->vi[m].v = values[(size_t)l * CP_FAR_BINS + CP_OMNI_BIN]; s->vi[m].id = l; ++m; }
        cp_select_top(s->vi, m, P->max_near);
        for (uint32_t j = P->max_near; j < m; ++j) s->is_near[s->vi[j].id] = 0;
        near_count = P->max_near;
    }
    if (cp_dist_alloc_near(d, near_count) != 0) return -1;
    uint32_t m = 0;
    for (uint32_t l = 0; l < N; ++l)
        if (s->is_near[l]) {
            d->near_key[m] = d->near_light[m] = l;
            d->near_fluence[m] = values[(size_t)l * CP_FAR_BINS + CP_OMNI_BIN];
            ++m;
        }
    /* far bins (§3.1.3): the rule of cp_bin_keep over each bin's nonzero far lights */
    memset(s->keep, 0, N);
    for (int bin = c->omni ? CP_OMNI_BIN : 0; bin < CP_FAR_BINS; ++bin) {
        uint32_t nz = 0;
        double total = 0.0;
        for (uint32_t l = 0; l < N; ++l) {
            float v = values[(size_t)l * CP_FAR_BINS + bin];
            if (s->is_near[l] || !(v > 0.0f) || !isfinite(v)) continue;
            s->vi[nz].v = v; s->vi[nz].id = l; ++nz;
            total += v;
        }
        if (nz == 0) continue;
        uint32_t len = cp_bin_keep(P, s->vi, nz, total);
        for (uint32_t j = 0; j < len; ++j) s->keep[s->vi[j].id] |= (uint8_t)(1u << bin);
    }
    uint32_t fc = 0;
    for (uint32_t l = 0; l < N; ++l) fc += s->keep[l] != 0;
    d->far_count = fc;
    d->far = malloc((fc ? fc : 1) * sizeof(FarEntry));
    if (!d->far) return -1;
    fc = 0;
    for (uint32_t l = 0; l < N; ++l) {
        if (!s->keep[l]) continue;
        d->far[fc].key = l;
        for (int bin = 0; bin < CP_FAR_BINS; ++bin)
            d->far[fc].value[bin] = (s->keep[l] >> bin) & 1 ? values[(size_t)l * CP_FAR_BINS + bin] : 0.0f;
        ++fc;
    }
    return 0;
}

const DistBuilder cp_far_linear = {scratch_new, scratch_free, linear_point};
