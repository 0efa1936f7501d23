/* cachepoints/blur.c: blurring the far bins across cache points (§3.1.5, Eq. 4), out of
 * place, for both builds: the linear build unions the neighbours' lists (the paper), the
 * cut build maps them onto the point's own cut. Near lists are not blurred (§3.1.5: they
 * change at a higher frequency). The neighbours and weights are kept for the visibility
 * blur (§3.2.2, lookup.c). */
#include <math.h>
#include <stdlib.h>

#include "build_internal.h"

typedef struct BlurCtx {
    CachePoints *cp;
    const Dist *dist;    /* final points' own distributions */
    Dist *blurred;       /* out of place */
    int failed;
} BlurCtx;

/* The blur_neighbours (16) nearest points and their Eq. 4 weights, normalised together
 * with the point's own weight 1. */
static void blur_weights(CachePoints *cp, size_t i) {
    uint32_t K = cp->params.blur_neighbours;
    uint32_t nb[64];
    float d2[64];
    uint32_t k = kdtree_knn(&cp->kd, cp->pos + 3 * i, K, INFINITY, (uint32_t)i, nb, d2);
    float dfar2 = k ? d2[k - 1] : 0.0f;
    float z = 1.0f;
    float w[64];
    for (uint32_t j = 0; j < k; ++j) {
        /* Eq. 4 as printed: mix(1, 1/16, d^2 / d_far^2), so the nearest neighbour gets 1 only
         * at distance 0 (the prose says the nearest gets 1) */
        w[j] = dfar2 > 0.0f ? 1.0f - (15.0f / 16.0f) * d2[j] / dfar2 : 1.0f;
        z += w[j];
    }
    cp->self_w[i] = 1.0f / z;
    /* render-time 1-NN shortcut (lookup.c, nearest_point): a query closer to point i than
     * 0.49 of its K-th neighbour's distance has its nearest point among i and the K (any
     * nearer point q has |q - i| <= 2 |x - i| < 0.98 d_K, so q is one of them); with fewer
     * than K other points every point is one of them */
    cp->nbr_clear2[i] = k < K ? INFINITY : 0.2401f * dfar2;
    for (uint32_t j = 0; j < K; ++j) {
        cp->nbr[i * K + j] = j < k ? nb[j] : CP_NONE;
        cp->nbr_w[i * K + j] = j < k ? w[j] / z : 0.0f;
    }
}

/* Optional (CachePointParams.retruncate, beyond the paper): re-applies the §3.1.3 bin rule
 * to a blurred list, which bounds memory at 7 x 256 lights per point (a union over 17
 * points can hold up to 17 x 256 per bin). */
static int retruncate(const CachePointParams *P, Dist *out) {
    uint32_t count = out->far_count;
    ValueIndex *vi = malloc((count ? count : 1) * sizeof *vi);
    uint8_t *keep = calloc(count ? count : 1, 1);
    if (!vi || !keep) { free(vi); free(keep); return -1; }
    for (int bin = 0; bin < CP_FAR_BINS; ++bin) {
        uint32_t nz = 0;
        double total = 0.0;
        for (uint32_t q = 0; q < count; ++q) {
            float v = out->far[q].value[bin];
            if (!(v > 0.0f)) continue;
            vi[nz].v = v; vi[nz].id = q; ++nz; /* id = position in the list */
            total += v;
        }
        if (nz == 0) continue;
        uint32_t len = cp_bin_keep(P, vi, nz, total);
        for (uint32_t j = 0; j < len; ++j) keep[vi[j].id] |= (uint8_t)(1u << bin);
    }
    uint32_t m = 0;
    for (uint32_t q = 0; q < count; ++q) {
        if (!keep[q]) continue;
        FarEntry f = out->far[q];
        for (int bin = 0; bin < CP_FAR_BINS; ++bin) if (!((keep[q] >> bin) & 1)) f.value[bin] = 0.0f;
        out->far[m++] = f;
    }
    out->far_count = m;
    free(vi); free(keep);
    return 0;
}

/* Linear build (the paper): p's blurred list is the union of its own and its neighbours'
 * lists, each scaled by its weight. Dense per-light accumulators; contributions are added in
 * source order (self, then neighbours by distance), so the float sums are deterministic. */
static void blur_linear_range(void *vctx, size_t b, size_t e, int thread) {
    (void)thread;
    BlurCtx *c = vctx;
    CachePoints *cp = c->cp;
    uint32_t K = cp->params.blur_neighbours, N = cp->num_lights;
    float *acc = calloc((size_t)N * CP_FAR_BINS + 1, sizeof(float));
    uint8_t *touched = calloc((size_t)N + 1, 1);
    uint32_t *list = malloc(((size_t)N + 1) * sizeof(uint32_t));
    uint64_t *tmp = malloc(((size_t)N + 1) * sizeof(uint64_t));
    if (!acc || !touched || !list || !tmp) { free(acc); free(touched); free(list); free(tmp); c->failed = 1; return; }
    for (size_t i = b; i < e; ++i) {
        blur_weights(cp, i);
        uint32_t count = 0;
        for (int j = -1; j < (int)K; ++j) {
            uint32_t src = j < 0 ? (uint32_t)i : cp->nbr[i * K + (uint32_t)j];
            if (src == CP_NONE) continue;
            float w = j < 0 ? cp->self_w[i] : cp->nbr_w[i * K + (uint32_t)j];
            const Dist *d = &c->dist[src];
            for (uint32_t q = 0; q < d->far_count; ++q) {
                uint32_t l = d->far[q].key;
                if (!touched[l]) { touched[l] = 1; list[count++] = l; }
                for (int bin = 0; bin < CP_FAR_BINS; ++bin) acc[(size_t)l * CP_FAR_BINS + bin] += w * d->far[q].value[bin];
            }
        }
        /* emit sorted by light id: a scan when dense, a sort of the touched ids when sparse */
        if ((uint64_t)count * 16 >= N) {
            count = 0;
            for (uint32_t l = 0; l < N; ++l) if (touched[l]) list[count++] = l;
        } else {
            for (uint32_t q = 0; q < count; ++q) tmp[q] = list[q];
            cp_sort_u64(tmp, count);
            for (uint32_t q = 0; q < count; ++q) list[q] = (uint32_t)tmp[q];
        }
        Dist *out = &c->blurred[i];
        out->far = malloc((count ? count : 1) * sizeof(FarEntry));
        if (!out->far) { c->failed = 1; break; }
        for (uint32_t q = 0; q < count; ++q) {
            uint32_t l = list[q];
            out->far[q].key = l;
            for (int bin = 0; bin < CP_FAR_BINS; ++bin) {
                out->far[q].value[bin] = acc[(size_t)l * CP_FAR_BINS + bin];
                acc[(size_t)l * CP_FAR_BINS + bin] = 0.0f;
            }
            touched[l] = 0;
        }
        out->far_count = count;
        if (cp->params.retruncate && count > 0 && retruncate(&cp->params, out) != 0) { c->failed = 1; break; }
    }
    free(acc); free(touched); free(list); free(tmp);
}

/* Cut build: p keeps its own cut; each neighbour's entry B is mapped onto it. If an entry of
 * p holds B (same node or an ancestor), B's values go to that entry; if B is coarser, its
 * values are shared among p's entries inside B in proportion to p's own values, bin by bin.
 * If B falls in a hole of p's cut (p estimated nothing there: typically a narrow spot light
 * whose cone misses p but not the neighbour, the paper's §5.2.1 case), B becomes an entry of
 * p, holes nested in one another merging into the outermost; a B holding one of p's near
 * lights is dropped instead, so near and far stay disjoint. Eq. 4 weights, self first, then
 * neighbours by distance, holes summed in (key, arrival) order: deterministic. */
static void blur_cut_range(void *vctx, size_t b, size_t e, int thread) {
    (void)thread;
    BlurCtx *c = vctx;
    CachePoints *cp = c->cp;
    uint32_t K = cp->params.blur_neighbours;
    uint32_t *keys = NULL, cap = 0, hole_cap = 0;
    FarEntry *holes = NULL;
    uint64_t *order = NULL;
    uint32_t order_cap = 0;
    for (size_t i = b; i < e && !c->failed; ++i) {
        blur_weights(cp, i);
        const Dist *own = &c->dist[i];
        uint32_t m = own->far_count, nholes = 0;
        Dist *out = &c->blurred[i];
        out->far = malloc((m ? m : 1) * sizeof(FarEntry));
        if (!out->far || cp_grow((void **)&keys, &cap, m + 1, sizeof(uint32_t)) != 0) { c->failed = 1; break; }
        out->far_count = m;
        for (uint32_t q = 0; q < m; ++q) {
            keys[q] = own->far[q].key;
            out->far[q].key = own->far[q].key;
            for (int bin = 0; bin < CP_FAR_BINS; ++bin) out->far[q].value[bin] = cp->self_w[i] * own->far[q].value[bin];
        }
        for (uint32_t j = 0; j < K && !c->failed; ++j) {
            uint32_t src = cp->nbr[i * K + j];
            if (src == CP_NONE) continue;
            float w = cp->nbr_w[i * K + j];
            const Dist *d = &c->dist[src];
            /* both lists ascend and a cut's entries are disjoint key ranges, so one forward
             * walk finds every entry's place: at = the first of p's keys above B's key */
            uint32_t at = 0;
            for (uint32_t q = 0; q < d->far_count; ++q) {
                const FarEntry *B = &d->far[q];
                while (at < m && keys[at] <= B->key) ++at;
                if (at > 0 && B->key < cp_key_end(cp, keys[at - 1])) { /* held by entry at - 1 */
                    for (int bin = 0; bin < CP_FAR_BINS; ++bin) out->far[at - 1].value[bin] += w * B->value[bin];
                    continue;
                }
                uint32_t lo = at, hi = at, end = cp_key_end(cp, B->key);
                while (hi < m && keys[hi] < end) ++hi;
                if (lo == hi) { /* a hole of p's cut */
                    uint32_t nk = cp_lower_bound(own->near_key, 0, own->near_count, B->key);
                    if (nk < own->near_count && own->near_key[nk] < end) continue; /* near wins */
                    if (cp_grow((void **)&holes, &hole_cap, nholes + 1, sizeof(FarEntry)) != 0) { c->failed = 1; break; }
                    holes[nholes].key = B->key;
                    for (int bin = 0; bin < CP_FAR_BINS; ++bin) holes[nholes].value[bin] = w * B->value[bin];
                    ++nholes;
                    continue;
                }
                for (int bin = 0; bin < CP_FAR_BINS; ++bin) {
                    if (!(B->value[bin] > 0.0f)) continue;
                    double sum = 0.0;
                    for (uint32_t k = lo; k < hi; ++k) sum += own->far[k].value[bin];
                    if (!(sum > 0.0)) continue;
                    for (uint32_t k = lo; k < hi; ++k)
                        out->far[k].value[bin] += (float)((double)w * B->value[bin] * own->far[k].value[bin] / sum);
                }
            }
        }
        if (c->failed || nholes == 0) continue;
        /* holes in key order (ties: arrival order), nested ones merged into the outermost,
         * then merged with p's entries (disjoint from them by construction) */
        if (cp_grow((void **)&order, &order_cap, 2 * nholes, sizeof(uint64_t)) != 0) { c->failed = 1; break; }
        for (uint32_t h = 0; h < nholes; ++h) order[h] = (uint64_t)holes[h].key << 32 | h;
        cp_sort_by_key(order, order + nholes, nholes);
        FarEntry *merged = malloc(((size_t)m + nholes) * sizeof(FarEntry));
        if (!merged) { c->failed = 1; break; }
        uint32_t a = 0, n = 0, h = 0;
        while (a < m || h < nholes) {
            if (h == nholes || (a < m && out->far[a].key < holes[(uint32_t)order[h]].key)) {
                merged[n++] = out->far[a++];
                continue;
            }
            FarEntry outer = holes[(uint32_t)order[h++]];
            uint32_t end = cp_key_end(cp, outer.key);
            while (h < nholes && holes[(uint32_t)order[h]].key < end) {
                const FarEntry *inner = &holes[(uint32_t)order[h++]];
                for (int bin = 0; bin < CP_FAR_BINS; ++bin) outer.value[bin] += inner->value[bin];
            }
            merged[n++] = outer;
        }
        free(out->far);
        out->far = merged;
        out->far_count = n;
    }
    free(keys); free(holes); free(order);
}

int cp_blur_far(CachePoints *cp, const Dist *dist, Dist *blurred) {
    size_t n = cp->n, K = cp->params.blur_neighbours;
    cp->nbr = malloc(n * K * sizeof(uint32_t) + 1);
    cp->nbr_w = malloc(n * K * sizeof(float) + 1);
    cp->self_w = malloc(n * sizeof(float));
    cp->nbr_clear2 = malloc(n * sizeof(float) + 1);
    if (!cp->nbr || !cp->nbr_w || !cp->self_w || !cp->nbr_clear2) return -1;
    BlurCtx bc = {cp, dist, blurred, 0};
    cp_run_parallel(&cp->params, n, 64, cp->params.build_cut ? blur_cut_range : blur_linear_range, &bc);
    return bc.failed ? -1 : 0;
}
