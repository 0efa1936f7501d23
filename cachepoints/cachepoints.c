/* cachepoints/cachepoints.c: the cache point build (§3.1), online visibility learning (§3.2)
 * and render-time light selection (§3.3). Section and equation numbers are the paper's;
 * "spec" refers to ../shared/design/cache-points-spec.md. */
#include "cachepoints.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "kdtree.h"

#define MIN_POINTS 10
#define FAR_BINS 7
#define OMNI_BIN 6

typedef struct FarEntry {
    uint32_t light;
    float value[FAR_BINS]; /* irradiance on +X -X +Y -Y +Z -Z, fluence */
} FarEntry;

struct CachePoints {
    uint32_t n;
    float *pos;        /* 3n */
    float *radius;     /* n: r_p (§3.1.4) */
    uint32_t *near_off, *near_light;   /* near lists, sorted by light id */
    uint32_t *far_off;                 /* far lists after the blur, sorted by light id */
    FarEntry *far;
    /* visibility slots: union of near and far lights per point, sorted by light id */
    uint32_t *vis_off, *vis_light;
    uint32_t *h_total, *h_success;     /* atomics */
    float *w_vis, *w_blurred;          /* Eq. 6, then the §3.2.2 blur (used at render time) */
    float *blur_wsum;                  /* scratch of the visibility blur */
    /* render-time tables, rebuilt whenever W' changes: per far entry and bin the effective
     * weight E_i(e) W'(e) (0 for lights also in the near list: near wins) and its inclusive
     * running sum within the point; per point and bin the total T_i */
    float *far_eff;                    /* FAR_BINS per far entry (entry-major) */
    float *far_cdf;                    /* per point, bin-major: the binary search stays in one array */
    float *bin_total;                  /* FAR_BINS per point */
    float *near_vis;                   /* W' of each near entry */
    uint32_t *nbr;                     /* blur_neighbours per point (UINT32_MAX: none) */
    float *nbr_w;                      /* normalised Eq. 4 weights */
    float *self_w;
    uint32_t num_lights;
    CachePointParams params;
    KdTree kd;
};

void cachepoints_default_params(CachePointParams *p) {
    memset(p, 0, sizeof *p);
    p->knn = 20;
    p->near_factor = 4.0f;
    p->energy_fraction = 0.97f;
    p->min_per_bin = 4;
    p->max_per_bin = 256;
    p->max_near = 256;
    p->blur_neighbours = 16;
    p->r_min = 0.04f;
    p->epsilon = 0.03f;
    p->visibility = 1;
    p->vis_blur_renorm = 1;
}

static double now_seconds(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static void run_parallel(const CachePointParams *p, size_t n, size_t grain,
                         void (*fn)(void *, size_t, size_t, int), void *ctx) {
    if (p->parallel_for) p->parallel_for(p->pool, n, grain, fn, ctx);
    else if (n) fn(ctx, 0, n, 0);
}

static inline float dist2(const float *a, const float *b) {
    float dx = a[0] - b[0], dy = a[1] - b[1], dz = a[2] - b[2];
    return dx * dx + dy * dy + dz * dz;
}

/* world size of one pixel at x (r_px, spec §3.3) */
static float pixel_footprint(const CachePointCamera *c, const float *x) {
    if (c->pixel_angle > 0.0f) return sqrtf(dist2(x, c->position)) * c->pixel_angle;
    return c->pixel_size;
}

/* ---------------------------------------------------------------- spatial sort */

static uint64_t spread21(uint64_t x) {
    x &= 0x1fffff;
    x = (x | x << 32) & 0x1f00000000ffffull;
    x = (x | x << 16) & 0x1f0000ff0000ffull;
    x = (x | x << 8) & 0x100f00f00f00f00full;
    x = (x | x << 4) & 0x10c30c30c30c30c3ull;
    x = (x | x << 2) & 0x1249249249249249ull;
    return x;
}

typedef struct SortItem { uint64_t key; uint32_t index; } SortItem;

static int cmp_sort_item(const void *a, const void *b) {
    const SortItem *x = a, *y = b;
    if (x->key != y->key) return x->key < y->key ? -1 : 1;
    return x->index < y->index ? -1 : (x->index > y->index);
}

/* §3.1.1: sort by a 63-bit Morton code, ties by generation order; returns the new order. */
static float *spatial_sort(const float *pts, uint32_t n) {
    float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (uint32_t i = 0; i < n; ++i)
        for (int k = 0; k < 3; ++k) {
            lo[k] = fminf(lo[k], pts[3 * i + k]);
            hi[k] = fmaxf(hi[k], pts[3 * i + k]);
        }
    SortItem *items = malloc((size_t)n * sizeof *items);
    float *out = malloc((size_t)n * 3 * sizeof(float));
    if (!items || !out) { free(items); free(out); return NULL; }
    for (uint32_t i = 0; i < n; ++i) {
        uint64_t code = 0;
        for (int k = 0; k < 3; ++k) {
            float ext = hi[k] - lo[k];
            float t = ext > 0.0f ? (pts[3 * i + k] - lo[k]) / ext : 0.0f;
            uint64_t q = (uint64_t)(fminf(fmaxf(t, 0.0f), 1.0f) * 2097151.0f);
            code |= spread21(q) << k;
        }
        items[i].key = code;
        items[i].index = i;
    }
    qsort(items, n, sizeof *items, cmp_sort_item);
    for (uint32_t i = 0; i < n; ++i) memcpy(out + 3 * i, pts + 3 * (size_t)items[i].index, 3 * sizeof(float));
    free(items);
    return out;
}

/* Keeps the points whose deleted flag is 0, in order. */
static uint32_t compact(float *pts, float *extra, const uint8_t *deleted, uint32_t n) {
    uint32_t m = 0;
    for (uint32_t i = 0; i < n; ++i) {
        if (deleted[i]) continue;
        memmove(pts + 3 * (size_t)m, pts + 3 * (size_t)i, 3 * sizeof(float));
        if (extra) extra[m] = extra[i];
        ++m;
    }
    return m;
}

/* ---------------------------------------------------------------- merging (§3.1.2, §3.1.4) */

/* Both merge passes keep the lowest index of a neighbourhood and delete the rest. Applied to
 * every point at once (the paper's parallel loop read literally), overlapping neighbourhoods
 * cascade: in 1-D with spacing 1 and radius 1.5 every point but index 0 is deleted, and a
 * 6,000-candidate test scene kept a single point. The paper's radius of 1e-5 hides this
 * (neighbourhoods never overlap); with the spec's pixel-sized radii it does not. We use the
 * sequential reading instead: in index order, a point still alive deletes the neighbours
 * with a higher index inside its radius. Survivors are then radius-separated, the result is
 * the same where neighbourhoods do not overlap, and it is deterministic by construction.
 * The kNN queries (the expensive part) run in parallel into a neighbour table first. */
typedef struct NeighbourCtx {
    const float *pts;
    const KdTree *kd;
    uint32_t knn;
    const float *radius;               /* per point, or NULL: use camera footprint */
    const CachePointCamera *camera;
    uint32_t *nbr;                     /* knn per point, UINT32_MAX padded */
} NeighbourCtx;

static void neighbour_range(void *vctx, size_t b, size_t e, int thread) {
    (void)thread;
    NeighbourCtx *c = vctx;
    for (size_t i = b; i < e; ++i) {
        const float *x = c->pts + 3 * i;
        float r = c->radius ? c->radius[i] : pixel_footprint(c->camera, x);
        uint32_t *out = c->nbr + i * c->knn;
        uint32_t k = kdtree_knn(c->kd, x, c->knn, r * r, (uint32_t)i, out, NULL);
        for (uint32_t j = k; j < c->knn; ++j) out[j] = UINT32_MAX;
    }
}

static int greedy_merge(const CachePointParams *P, const float *pts, const KdTree *kd, uint32_t n,
                        const float *radius, const CachePointCamera *camera, uint8_t *deleted) {
    uint32_t *nbr = malloc((size_t)n * P->knn * sizeof *nbr);
    if (!nbr) return -1;
    NeighbourCtx c = {pts, kd, P->knn, radius, camera, nbr};
    run_parallel(P, n, 512, neighbour_range, &c);
    for (uint32_t i = 0; i < n; ++i) {
        if (deleted[i]) continue;
        for (uint32_t j = 0; j < P->knn; ++j) {
            uint32_t q = nbr[(size_t)i * P->knn + j];
            if (q != UINT32_MAX && q > i) deleted[q] = 1;
        }
    }
    free(nbr);
    return 0;
}

/* ---------------------------------------------------------------- light distributions (§3.1.3) */

typedef struct Dist {        /* per point, during the build */
    uint32_t near_count;
    uint32_t *near;          /* sorted by id */
    float *near_fluence;     /* fluence of each near light at x (for pass 2's similarity) */
    uint32_t far_count;
    FarEntry *far;           /* sorted by id; union of the 7 truncated bins */
} Dist;

typedef struct OmniDist { uint32_t count; uint32_t *light; float *p; } OmniDist;
static int omni_build(const Dist *d, OmniDist *o);
static void dist_free(Dist *d);

/* Two uses: with omni != NULL only the fluence bin is computed and each point's distribution is
 * reduced at once to its normalised omni distribution (all merge pass 2 needs); the full seven
 * bins are computed afterwards for the survivors only, which keeps the build's memory to the
 * final points rather than every pass-1 survivor. */
typedef struct DistCtx {
    const float *pts;
    const float *r0;
    const CachePointLights *lights;
    const CachePointParams *params;
    Dist *dist;
    int failed;
    OmniDist *omni;
} DistCtx;

typedef struct ValueIndex { float v; uint32_t light; } ValueIndex;


/* Total orders (ties by light id / position) keep every result deterministic. */
static inline int vi_before(const ValueIndex *a, const ValueIndex *b) { /* value desc, light asc */
    return a->v > b->v || (a->v == b->v && a->light < b->light);
}

static void sort_u64(uint64_t *a, size_t n) {
    for (size_t start = n / 2; start-- > 0;) {
        size_t root = start;
        for (;;) {
            size_t child = 2 * root + 1;
            if (child >= n) break;
            if (child + 1 < n && a[child] < a[child + 1]) ++child;
            if (!(a[root] < a[child])) break;
            uint64_t t = a[root]; a[root] = a[child]; a[child] = t;
            root = child;
        }
    }
    for (size_t end = n; end > 1; --end) {
        uint64_t t = a[0]; a[0] = a[end - 1]; a[end - 1] = t;
        size_t root = 0, m = end - 1;
        for (;;) {
            size_t child = 2 * root + 1;
            if (child >= m) break;
            if (child + 1 < m && a[child] < a[child + 1]) ++child;
            if (!(a[root] < a[child])) break;
            uint64_t u = a[root]; a[root] = a[child]; a[child] = u;
            root = child;
        }
    }
}

/* Quickselect-style partitions under the (value desc, light asc) order, O(n) expected: the
 * far-bin rule needs only the membership of a prefix of the sorted order, never its order. */
static void vi_insertion_sort(ValueIndex *a, uint32_t n) {
    for (uint32_t i = 1; i < n; ++i) {
        ValueIndex x = a[i];
        uint32_t j = i;
        while (j > 0 && vi_before(&x, &a[j - 1])) { a[j] = a[j - 1]; --j; }
        a[j] = x;
    }
}

/* Partitions a[lo, hi) around a median-of-three pivot; returns the pivot's final index. */
static uint32_t vi_partition(ValueIndex *a, uint32_t lo, uint32_t hi) {
    uint32_t mid = lo + (hi - lo) / 2, last = hi - 1;
    if (vi_before(&a[mid], &a[lo])) { ValueIndex t = a[mid]; a[mid] = a[lo]; a[lo] = t; }
    if (vi_before(&a[last], &a[lo])) { ValueIndex t = a[last]; a[last] = a[lo]; a[lo] = t; }
    if (vi_before(&a[mid], &a[last])) { ValueIndex t = a[mid]; a[mid] = a[last]; a[last] = t; }
    ValueIndex pivot = a[last]; /* the median */
    uint32_t store = lo;
    for (uint32_t i = lo; i < last; ++i)
        if (vi_before(&a[i], &pivot)) { ValueIndex t = a[i]; a[i] = a[store]; a[store] = t; ++store; }
    ValueIndex t = a[store]; a[store] = a[last]; a[last] = t;
    return store;
}

/* Moves the first m elements of the sorted order to the front, m the smallest count whose
 * sum reaches target (n if none does); returns m. */
static uint32_t select_energy_prefix(ValueIndex *a, uint32_t n, double target) {
    uint32_t lo = 0, hi = n;
    double acc = 0.0;
    while (hi - lo > 24) {
        uint32_t p = vi_partition(a, lo, hi);
        double before = 0.0;
        for (uint32_t i = lo; i < p; ++i) before += a[i].v;
        if (acc + before >= target) { hi = p; continue; }
        acc += before + a[p].v;
        if (acc >= target) return p + 1;
        lo = p + 1;
    }
    vi_insertion_sort(a + lo, hi - lo);
    for (uint32_t i = lo; i < hi; ++i) {
        acc += a[i].v;
        if (acc >= target) return i + 1;
    }
    return hi < n ? hi : n;
}

/* Moves the first k elements of the sorted order to the front. */
static void select_top(ValueIndex *a, uint32_t n, uint32_t k) {
    uint32_t lo = 0, hi = n;
    while (hi - lo > 24 && k > lo && k < hi) {
        uint32_t p = vi_partition(a, lo, hi);
        if (p == k || p + 1 == k) return;
        if (p > k) hi = p;
        else lo = p + 1;
    }
    vi_insertion_sort(a + lo, hi - lo);
}

static void dist_range(void *vctx, size_t b, size_t e, int thread) {
    (void)thread;
    DistCtx *c = vctx;
    const CachePointLights *L = c->lights;
    const CachePointParams *P = c->params;
    uint32_t N = L->count;
    float *values = malloc((size_t)N * FAR_BINS * sizeof(float));
    uint8_t *is_near = malloc(N ? N : 1);
    ValueIndex *vi = malloc((size_t)(N ? N : 1) * sizeof *vi);
    uint8_t *keep = malloc(N ? N : 1);
    if (!values || !is_near || !vi || !keep) {
        c->failed = 1;
        free(values); free(is_near); free(vi); free(keep);
        return;
    }
    for (size_t i = b; i < e; ++i) {
        const float *x = c->pts + 3 * i;
        float rn = P->near_factor * c->r0[i];
        Dist *d = &c->dist[i];
        /* Eq. 1: finite lights whose centroid lies within D r_p are near */
        uint32_t near_count = 0;
        for (uint32_t l = 0; l < N; ++l) {
            if (c->omni) values[(size_t)l * FAR_BINS + OMNI_BIN] = L->estimate(L->user, l, x, NULL);
            else L->estimate7(L->user, l, x, values + (size_t)l * FAR_BINS);
            is_near[l] = !L->infinite[l] && dist2(L->centroid + 3 * (size_t)l, x) <= rn * rn;
            near_count += is_near[l];
        }
        if (near_count > P->max_near) {
            /* cap (spec §3.4): keep the strongest by fluence; the rest become far */
            uint32_t m = 0;
            for (uint32_t l = 0; l < N; ++l)
                if (is_near[l]) { vi[m].v = values[(size_t)l * FAR_BINS + OMNI_BIN]; vi[m].light = l; ++m; }
            select_top(vi, m, P->max_near);
            for (uint32_t j = P->max_near; j < m; ++j) is_near[vi[j].light] = 0;
            near_count = P->max_near;
        }
        d->near_count = near_count;
        d->near = malloc((near_count ? near_count : 1) * sizeof(uint32_t));
        d->near_fluence = malloc((near_count ? near_count : 1) * sizeof(float));
        if (!d->near || !d->near_fluence) { c->failed = 1; break; }
        uint32_t m = 0;
        for (uint32_t l = 0; l < N; ++l)
            if (is_near[l]) { d->near[m] = l; d->near_fluence[m] = values[(size_t)l * FAR_BINS + OMNI_BIN]; ++m; }
        /* far bins: per bin the shortest prefix (by value, ties by id) holding 97% of the
         * bin's energy, length clamped to [min(4, nonzero), 256] (spec §3.4) */
        memset(keep, 0, N);
        for (int bin = c->omni ? OMNI_BIN : 0; bin < FAR_BINS; ++bin) {
            uint32_t nz = 0;
            double total = 0.0;
            for (uint32_t l = 0; l < N; ++l) {
                float v = values[(size_t)l * FAR_BINS + bin];
                if (is_near[l] || !(v > 0.0f) || !isfinite(v)) continue;
                vi[nz].v = v; vi[nz].light = l; ++nz;
                total += v;
            }
            if (nz == 0) continue;
            /* the shortest prefix of the (value desc, light asc) order holding 97% */
            uint32_t len = select_energy_prefix(vi, nz, P->energy_fraction * total);
            uint32_t lo = P->min_per_bin < nz ? P->min_per_bin : nz;
            if (len < lo) { select_top(vi, nz, lo); len = lo; }
            if (len > P->max_per_bin) { select_top(vi, len, P->max_per_bin); len = P->max_per_bin; }
            for (uint32_t j = 0; j < len; ++j) keep[vi[j].light] |= (uint8_t)(1u << bin);
        }
        uint32_t fc = 0;
        for (uint32_t l = 0; l < N; ++l) fc += keep[l] != 0;
        d->far_count = fc;
        d->far = malloc((fc ? fc : 1) * sizeof(FarEntry));
        if (!d->far) { c->failed = 1; break; }
        fc = 0;
        for (uint32_t l = 0; l < N; ++l) {
            if (!keep[l]) continue;
            d->far[fc].light = l;
            for (int bin = 0; bin < FAR_BINS; ++bin)
                d->far[fc].value[bin] = (keep[l] >> bin) & 1 ? values[(size_t)l * FAR_BINS + bin] : 0.0f;
            ++fc;
        }
        if (c->omni) {
            if (omni_build(d, &c->omni[i]) != 0) c->failed = 1;
            dist_free(d);
        }
    }
    free(values); free(is_near); free(vi); free(keep);
}

static void dist_free(Dist *d) {
    free(d->near); free(d->near_fluence); free(d->far);
    memset(d, 0, sizeof *d);
}

/* ---------------------------------------------------------------- merge pass 2 (§3.1.4) */

/* The omni distribution of a point: near fluence plus the far fluence bin, normalised,
 * as (light, probability) sorted by light id (spec §3.5 proposal). */

static int omni_build(const Dist *d, OmniDist *o) {
    uint32_t n = d->near_count + d->far_count;
    o->light = malloc((n ? n : 1) * sizeof(uint32_t));
    o->p = malloc((n ? n : 1) * sizeof(float));
    if (!o->light || !o->p) return -1;
    /* merge the two sorted lists */
    uint32_t a = 0, b = 0, m = 0;
    double total = 0.0;
    while (a < d->near_count || b < d->far_count) {
        uint32_t la = a < d->near_count ? d->near[a] : UINT32_MAX;
        uint32_t lb = b < d->far_count ? d->far[b].light : UINT32_MAX;
        float v;
        uint32_t l;
        if (la <= lb) { l = la; v = d->near_fluence[a++]; if (la == lb) ++b; }
        else { l = lb; v = d->far[b++].value[OMNI_BIN]; }
        if (!(v > 0.0f)) continue;
        o->light[m] = l; o->p[m] = v; total += v; ++m;
    }
    for (uint32_t i = 0; i < m; ++i) o->p[i] = (float)(o->p[i] / total);
    o->count = m;
    return 0;
}

/* Eqs. 2-3 */
static float similarity(const OmniDist *A, const OmniDist *B) {
    if (A->count + B->count == 0) return 1.0f;
    uint32_t a = 0, b = 0;
    double s = 0.0;
    while (a < A->count && b < B->count) {
        if (A->light[a] < B->light[b]) ++a;
        else if (A->light[a] > B->light[b]) ++b;
        else {
            double pa = A->p[a], pb = B->p[b];
            s += pa + pb > 0.0 ? 1.0 - fabs(pb - pa) / (pa + pb) : 1.0;
            ++a; ++b;
        }
    }
    return (float)(2.0 * s / (double)(A->count + B->count));
}

typedef struct Pass2Ctx {
    const float *pts;
    const KdTree *kd;
    const CachePointCamera *camera;
    const OmniDist *omni;
    uint32_t knn;
    float scene_scale;
    float *radius;
} Pass2Ctx;

static void pass2_radius_range(void *vctx, size_t b, size_t e, int thread) {
    (void)thread;
    Pass2Ctx *c = vctx;
    uint32_t nb[64];
    float d2[64];
    for (size_t i = b; i < e; ++i) {
        const float *x = c->pts + 3 * i;
        uint32_t k = kdtree_knn(c->kd, x, c->knn, INFINITY, (uint32_t)i, nb, d2);
        float r0 = 0.0f, msum = 0.0f;
        for (uint32_t j = 0; j < k; ++j) {
            r0 += sqrtf(d2[j]);
            msum += similarity(&c->omni[i], &c->omni[nb[j]]);
        }
        float mavg = k ? msum / (float)k : 1.0f;
        r0 = k ? r0 / (float)k : 0.01f * c->scene_scale;
        /* r_p = max(r0 M_avg, 0.25 r0, 3 r_px) (spec §3.5) */
        float r = fmaxf(fmaxf(r0 * mavg, 0.25f * r0), 3.0f * pixel_footprint(c->camera, x));
        c->radius[i] = r;
    }
}

/* ---------------------------------------------------------------- blur (§3.1.5, Eq. 4) */

typedef struct BlurCtx {
    CachePoints *cp;
    const Dist *dist;    /* final points' own distributions */
    Dist *blurred;       /* out of place */
    int failed;
} BlurCtx;


static void blur_weights(CachePoints *cp, size_t i) {
    uint32_t K = cp->params.blur_neighbours;
    uint32_t nb[64];
    float d2[64];
    uint32_t k = kdtree_knn(&cp->kd, cp->pos + 3 * i, K, INFINITY, (uint32_t)i, nb, d2);
    float dfar2 = k ? d2[k - 1] : 0.0f;
    float z = 1.0f;
    float w[64];
    for (uint32_t j = 0; j < k; ++j) {
        w[j] = dfar2 > 0.0f ? 1.0f - (15.0f / 16.0f) * d2[j] / dfar2 : 1.0f; /* Eq. 4 as printed */
        z += w[j];
    }
    cp->self_w[i] = 1.0f / z;
    for (uint32_t j = 0; j < K; ++j) {
        cp->nbr[i * K + j] = j < k ? nb[j] : UINT32_MAX;
        cp->nbr_w[i * K + j] = j < k ? w[j] / z : 0.0f;
    }
}

static void blur_range(void *vctx, size_t b, size_t e, int thread) {
    (void)thread;
    BlurCtx *c = vctx;
    CachePoints *cp = c->cp;
    uint32_t K = cp->params.blur_neighbours, N = cp->num_lights;
    /* dense per-light accumulators: contributions are added in source order (self, then the
     * neighbours by distance), so the float sums are deterministic */
    float *acc = calloc((size_t)N * FAR_BINS + 1, sizeof(float));
    uint8_t *touched = calloc((size_t)N + 1, 1);
    uint32_t *list = malloc(((size_t)N + 1) * sizeof(uint32_t));
    if (!acc || !touched || !list) { free(acc); free(touched); free(list); c->failed = 1; return; }
    for (size_t i = b; i < e; ++i) {
        blur_weights(cp, i);
        uint32_t count = 0;
        for (int j = -1; j < (int)K; ++j) {
            uint32_t src = j < 0 ? (uint32_t)i : cp->nbr[i * K + (uint32_t)j];
            if (src == UINT32_MAX) continue;
            float w = j < 0 ? cp->self_w[i] : cp->nbr_w[i * K + (uint32_t)j];
            const Dist *d = &c->dist[src];
            for (uint32_t q = 0; q < d->far_count; ++q) {
                uint32_t l = d->far[q].light;
                if (!touched[l]) { touched[l] = 1; list[count++] = l; }
                for (int bin = 0; bin < FAR_BINS; ++bin) acc[(size_t)l * FAR_BINS + bin] += w * d->far[q].value[bin];
            }
        }
        /* emit sorted by light id: a scan when dense, a sort of the touched ids when sparse */
        if ((uint64_t)count * 16 >= N) {
            count = 0;
            for (uint32_t l = 0; l < N; ++l) if (touched[l]) list[count++] = l;
        } else {
            uint64_t *tmp = (uint64_t *)malloc((size_t)count * sizeof(uint64_t) + 8);
            if (!tmp) { c->failed = 1; break; }
            for (uint32_t q = 0; q < count; ++q) tmp[q] = list[q];
            sort_u64(tmp, count);
            for (uint32_t q = 0; q < count; ++q) list[q] = (uint32_t)tmp[q];
            free(tmp);
        }
        Dist *out = &c->blurred[i];
        out->far = malloc((count ? count : 1) * sizeof(FarEntry));
        if (!out->far) { c->failed = 1; break; }
        for (uint32_t q = 0; q < count; ++q) {
            uint32_t l = list[q];
            out->far[q].light = l;
            for (int bin = 0; bin < FAR_BINS; ++bin) {
                out->far[q].value[bin] = acc[(size_t)l * FAR_BINS + bin];
                acc[(size_t)l * FAR_BINS + bin] = 0.0f;
            }
            touched[l] = 0;
        }
        out->far_count = count;
        if (cp->params.retruncate && count > 0) {
            /* optional (spec §3.6): re-apply the 97% / 4..256 rule per bin to the blurred
             * lists, which bounds memory at 7 x 256 lights per point */
            ValueIndex *vi = malloc(count * sizeof *vi);
            uint8_t *keep = calloc(count, 1);
            if (!vi || !keep) { free(vi); free(keep); c->failed = 1; break; }
            for (int bin = 0; bin < FAR_BINS; ++bin) {
                uint32_t nz = 0;
                double total = 0.0;
                for (uint32_t q = 0; q < count; ++q) {
                    float v = out->far[q].value[bin];
                    if (!(v > 0.0f)) continue;
                    vi[nz].v = v; vi[nz].light = q; ++nz; /* light = position in the list */
                    total += v;
                }
                if (nz == 0) continue;
                uint32_t len = select_energy_prefix(vi, nz, cp->params.energy_fraction * total);
                uint32_t lo = cp->params.min_per_bin < nz ? cp->params.min_per_bin : nz;
                if (len < lo) { select_top(vi, nz, lo); len = lo; }
                if (len > cp->params.max_per_bin) { select_top(vi, len, cp->params.max_per_bin); len = cp->params.max_per_bin; }
                for (uint32_t j = 0; j < len; ++j) keep[vi[j].light] |= (uint8_t)(1u << bin);
            }
            uint32_t m = 0;
            for (uint32_t q = 0; q < count; ++q) {
                if (!keep[q]) continue;
                FarEntry f = out->far[q];
                for (int bin = 0; bin < FAR_BINS; ++bin) if (!((keep[q] >> bin) & 1)) f.value[bin] = 0.0f;
                out->far[m++] = f;
            }
            out->far_count = m;
            free(vi); free(keep);
        }
    }
    free(acc); free(touched); free(list);
}

/* ---------------------------------------------------------------- visibility (§3.2) */

float cachepoints_visibility_weight(uint32_t successes, uint32_t attempts, float r_min) {
    float r = ((float)successes + 1.0f) / ((float)attempts + 1.0f); /* Eq. 5 */
    return r <= r_min ? (r / r_min) * (r / r_min) : 1.0f;           /* Eq. 6: never 0 */
}

static int find_u32(const uint32_t *a, uint32_t lo, uint32_t hi, uint32_t key, uint32_t *at) {
    while (lo < hi) {
        uint32_t mid = lo + (hi - lo) / 2;
        if (a[mid] < key) lo = mid + 1;
        else hi = mid;
    }
    *at = lo;
    return 0;
}

static int vis_slot(const CachePoints *cp, uint32_t point, uint32_t light, uint32_t *slot) {
    uint32_t at;
    find_u32(cp->vis_light, cp->vis_off[point], cp->vis_off[point + 1], light, &at);
    if (at < cp->vis_off[point + 1] && cp->vis_light[at] == light) { *slot = at; return 1; }
    return 0;
}

void cachepoints_record(CachePoints *cp, uint32_t point, uint32_t light, int success) {
    if (!cp || point >= cp->n) return;
    uint32_t slot;
    if (!vis_slot(cp, point, light, &slot)) return; /* only listed lights have counters (spec §4.1) */
    __atomic_fetch_add(&cp->h_total[slot], 1u, __ATOMIC_RELAXED);
    if (success) __atomic_fetch_add(&cp->h_success[slot], 1u, __ATOMIC_RELAXED);
}

typedef struct VisCtx { CachePoints *cp; } VisCtx;

static void vis_weight_range(void *vctx, size_t b, size_t e, int thread) {
    (void)thread;
    CachePoints *cp = ((VisCtx *)vctx)->cp;
    for (size_t i = cp->vis_off[b]; i < cp->vis_off[e]; ++i)
        cp->w_vis[i] = cachepoints_visibility_weight(cp->h_success[i], cp->h_total[i], cp->params.r_min);
}

/* §3.2.2: W'(p,e) = w_p W(p,e) + sum over neighbours n holding e of w_n W(n,e); with
 * vis_blur_renorm the sum is divided by the weights of the points that hold e, so a fully
 * visible light keeps W' = 1 however few neighbours list it. */
static void vis_blur_range(void *vctx, size_t b, size_t e, int thread) {
    (void)thread;
    CachePoints *cp = ((VisCtx *)vctx)->cp;
    uint32_t K = cp->params.blur_neighbours;
    for (size_t p = b; p < e; ++p) {
        uint32_t s0 = cp->vis_off[p], s1 = cp->vis_off[p + 1];
        /* accumulate in w_blurred (acc) and h_scratch (weight sums); each neighbour's sorted
         * slot list is merged against p's in one linear walk */
        for (uint32_t s = s0; s < s1; ++s) {
            cp->w_blurred[s] = cp->self_w[p] * cp->w_vis[s];
            cp->blur_wsum[s] = cp->self_w[p];
        }
        for (uint32_t j = 0; j < K; ++j) {
            uint32_t nb = cp->nbr[p * K + j];
            if (nb == UINT32_MAX) continue;
            float w = cp->nbr_w[p * K + j];
            uint32_t a = s0, q = cp->vis_off[nb], q1 = cp->vis_off[nb + 1];
            while (a < s1 && q < q1) {
                uint32_t la = cp->vis_light[a], lq = cp->vis_light[q];
                if (la < lq) ++a;
                else if (la > lq) ++q;
                else {
                    cp->w_blurred[a] += w * cp->w_vis[q];
                    cp->blur_wsum[a] += w;
                    ++a; ++q;
                }
            }
        }
        if (cp->params.vis_blur_renorm)
            for (uint32_t s = s0; s < s1; ++s) cp->w_blurred[s] /= cp->blur_wsum[s];
    }
}


float cachepoints_visibility(const CachePoints *cp, uint32_t point, uint32_t light) {
    uint32_t slot;
    if (!cp || point >= cp->n || !vis_slot(cp, point, light, &slot)) return 1.0f;
    return cp->w_blurred[slot];
}

/* ---------------------------------------------------------------- selection (§3.3) */

/* Far bins are blended by b_i(n) = max(0, n.a_i)^2, which sums to 1 for a unit normal
 * (spec §5.3); without a normal (volumes, transmissive surfaces) only the fluence bin. */
static int bin_blend(const float *n, float b[FAR_BINS]) {
    for (int i = 0; i < FAR_BINS; ++i) b[i] = 0.0f;
    if (!n) { b[OMNI_BIN] = 1.0f; return 1; }
    b[0] = n[0] > 0.0f ? n[0] * n[0] : 0.0f;
    b[1] = n[0] < 0.0f ? n[0] * n[0] : 0.0f;
    b[2] = n[1] > 0.0f ? n[1] * n[1] : 0.0f;
    b[3] = n[1] < 0.0f ? n[1] * n[1] : 0.0f;
    b[4] = n[2] > 0.0f ? n[2] * n[2] : 0.0f;
    b[5] = n[2] < 0.0f ? n[2] * n[2] : 0.0f;
    return 1;
}


static int far_index(const CachePoints *cp, uint32_t point, uint32_t light, uint32_t *at) {
    uint32_t lo = cp->far_off[point], hi = cp->far_off[point + 1];
    while (lo < hi) {
        uint32_t mid = lo + (hi - lo) / 2;
        if (cp->far[mid].light < light) lo = mid + 1;
        else hi = mid;
    }
    *at = lo;
    return lo < cp->far_off[point + 1] && cp->far[lo].light == light;
}

static int near_index(const CachePoints *cp, uint32_t point, uint32_t light, uint32_t *at) {
    find_u32(cp->near_light, cp->near_off[point], cp->near_off[point + 1], light, at);
    return *at < cp->near_off[point + 1] && cp->near_light[*at] == light;
}

/* far_cdf layout: point p's block starts at FAR_BINS * far_off[p]; inside it bin i's running
 * sums are contiguous (F = the point's far count). */
static inline size_t cdf_index(const CachePoints *cp, size_t p, int bin, uint32_t k) {
    uint32_t base = cp->far_off[p], count = cp->far_off[p + 1] - base;
    return (size_t)FAR_BINS * base + (size_t)bin * count + (k - base);
}

typedef struct TableCtx { CachePoints *cp; } TableCtx;

static void tables_range(void *vctx, size_t b, size_t e, int thread) {
    (void)thread;
    CachePoints *cp = ((TableCtx *)vctx)->cp;
    for (size_t p = b; p < e; ++p) {
        double run[FAR_BINS] = {0};
        /* far, near and visibility lists are all sorted by light id: one merge walk */
        uint32_t a = cp->near_off[p], a1 = cp->near_off[p + 1];
        uint32_t sl = cp->vis_off[p], s1 = cp->vis_off[p + 1];
        for (uint32_t k = cp->far_off[p]; k < cp->far_off[p + 1]; ++k) {
            const FarEntry *f = &cp->far[k];
            while (a < a1 && cp->near_light[a] < f->light) ++a;
            while (sl < s1 && cp->vis_light[sl] < f->light) ++sl;
            int dup = a < a1 && cp->near_light[a] == f->light;
            float w = dup ? 0.0f : (sl < s1 && cp->vis_light[sl] == f->light ? cp->w_blurred[sl] : 1.0f);
            for (int i = 0; i < FAR_BINS; ++i) {
                float v = f->value[i] > 0.0f && isfinite(f->value[i]) ? f->value[i] * w : 0.0f;
                cp->far_eff[(size_t)k * FAR_BINS + i] = v;
                run[i] += v;
                cp->far_cdf[cdf_index(cp, p, i, k)] = (float)run[i];
            }
        }
        for (int i = 0; i < FAR_BINS; ++i) cp->bin_total[p * FAR_BINS + i] = (float)run[i];
        /* each near light's visibility slot, so per-vertex weights need no search */
        sl = cp->vis_off[p];
        for (uint32_t k = cp->near_off[p]; k < a1; ++k) {
            while (sl < s1 && cp->vis_light[sl] < cp->near_light[k]) ++sl;
            cp->near_vis[k] = sl < s1 && cp->vis_light[sl] == cp->near_light[k] ? cp->w_blurred[sl] : 1.0f;
        }
    }
}

static void rebuild_tables(CachePoints *cp) {
    TableCtx c = {cp};
    run_parallel(&cp->params, cp->n, 256, tables_range, &c);
}

void cachepoints_update_visibility(CachePoints *cp) {
    if (!cp || !cp->params.visibility) return;
    VisCtx c = {cp};
    run_parallel(&cp->params, cp->n, 256, vis_weight_range, &c);
    run_parallel(&cp->params, cp->n, 256, vis_blur_range, &c);
    rebuild_tables(cp);
}

/* Exact weight of near light k at the vertex: its estimate times W' (§3.3). */
static float near_weight(const CachePoints *cp, const CachePointLights *L, uint32_t k,
                         const float x[3], const float *n) {
    uint32_t light = cp->near_light[k];
    float w = L->estimate(L->user, light, x, n);
    if (!(w > 0.0f) || !isfinite(w)) return 0.0f;
    return w * cp->near_vis[k];
}

/* The vertex's distribution is a mixture: near lights with their exact weights, and far bin i
 * with weight b_i(n) T_i, each bin sampled through its running sums. A far light's weight is
 * then sum_i b_i eff_i(e), so the PMF is one formula whichever branch picked the light. */
typedef struct VertexWeights {
    uint32_t point;
    float b[FAR_BINS];
    float near_total, far_total, total;
} VertexWeights;

static void vertex_weights(const CachePoints *cp, const CachePointLights *L, uint32_t point, const float x[3],
                           const float *n, VertexWeights *v) {
    v->point = point;
    bin_blend(n, v->b);
    float nt = 0.0f;
    for (uint32_t k = cp->near_off[point]; k < cp->near_off[point + 1]; ++k) nt += near_weight(cp, L, k, x, n);
    float ft = 0.0f;
    for (int i = 0; i < FAR_BINS; ++i) ft += v->b[i] * cp->bin_total[(size_t)point * FAR_BINS + i];
    v->near_total = nt;
    v->far_total = ft;
    v->total = nt + ft;
}

static float light_weight(const CachePoints *cp, const CachePointLights *L, const VertexWeights *v, uint32_t light,
                          const float x[3], const float *n) {
    uint32_t at;
    if (near_index(cp, v->point, light, &at)) return near_weight(cp, L, at, x, n);
    if (!far_index(cp, v->point, light, &at)) return 0.0f;
    float w = 0.0f;
    for (int i = 0; i < FAR_BINS; ++i) w += v->b[i] * cp->far_eff[(size_t)at * FAR_BINS + i];
    return w;
}

static inline float pmf_from(float w, float total, float eps, uint32_t count) {
    if (!(total > 0.0f)) return 1.0f / (float)count;
    return (1.0f - eps) * (w / total) + eps / (float)count;
}

uint32_t cachepoints_select(const CachePoints *cp, const CachePointLights *L, const float x[3], const float *n,
                            uint32_t point_hint, float u, float *pmf, uint32_t *point_out) {
    uint32_t N = L->count;
    float eps = cp->params.epsilon;
    uint32_t point = point_hint < cp->n ? point_hint : kdtree_nearest(&cp->kd, x, NULL);
    *point_out = point;
    VertexWeights v;
    vertex_weights(cp, L, point, x, n, &v);
    uint32_t pick = UINT32_MAX;
    if (!(v.total > 0.0f) || u < eps) {
        float uu = v.total > 0.0f ? u / eps : u;
        pick = (uint32_t)(uu * (float)N);
        if (pick >= N) pick = N - 1;
    } else {
        float target = (u - eps) / (1.0f - eps) * v.total;
        if (target < v.near_total) {
            float cum = 0.0f;
            for (uint32_t k = cp->near_off[point]; k < cp->near_off[point + 1]; ++k) {
                float w = near_weight(cp, L, k, x, n);
                if (!(w > 0.0f)) continue;
                cum += w;
                pick = cp->near_light[k];
                if (target < cum) break;
            }
        }
        if (pick == UINT32_MAX && v.far_total > 0.0f) {
            /* choose a bin, then a light inside it by binary search over the running sums */
            float t = target - v.near_total;
            if (t < 0.0f) t = 0.0f;
            int bin = -1;
            float cum = 0.0f;
            for (int i = 0; i < FAR_BINS; ++i) {
                float wi = v.b[i] * cp->bin_total[(size_t)point * FAR_BINS + i];
                if (!(wi > 0.0f)) continue;
                bin = i;
                if (t < cum + wi) break;
                cum += wi;
            }
            if (bin >= 0) {
                float tb = v.b[bin] > 0.0f ? (t - cum) / v.b[bin] : 0.0f;
                uint32_t lo = cp->far_off[point], hi = cp->far_off[point + 1];
                while (lo < hi) { /* first entry whose running sum exceeds tb */
                    uint32_t mid = lo + (hi - lo) / 2;
                    if (cp->far_cdf[cdf_index(cp, point, bin, mid)] <= tb) lo = mid + 1;
                    else hi = mid;
                }
                if (lo >= cp->far_off[point + 1]) lo = cp->far_off[point + 1] - 1;
                /* rounding may land on a zero-weight entry: step back to one with weight */
                while (lo > cp->far_off[point] && !(cp->far_eff[(size_t)lo * FAR_BINS + bin] > 0.0f)) --lo;
                pick = cp->far[lo].light;
            }
        }
        if (pick == UINT32_MAX) pick = (uint32_t)(u * (float)N) < N ? (uint32_t)(u * (float)N) : N - 1;
    }
    *pmf = pmf_from(light_weight(cp, L, &v, pick, x, n), v.total, eps, N);
    return pick;
}

uint32_t cachepoints_nearest(const CachePoints *cp, const float x[3]) {
    return kdtree_nearest(&cp->kd, x, NULL);
}

float cachepoints_pmf(const CachePoints *cp, const CachePointLights *L, const float x[3], const float *n,
                      uint32_t point_hint, uint32_t light) {
    if (light >= L->count) return 0.0f;
    VertexWeights v;
    vertex_weights(cp, L, point_hint < cp->n ? point_hint : kdtree_nearest(&cp->kd, x, NULL), x, n, &v);
    return pmf_from(light_weight(cp, L, &v, light, x, n), v.total, cp->params.epsilon, L->count);
}

/* ---------------------------------------------------------------- build */

uint32_t cachepoints_count(const CachePoints *cp) { return cp ? cp->n : 0; }

void cachepoints_point(const CachePoints *cp, uint32_t i, float pos[3], float *radius) {
    memcpy(pos, cp->pos + 3 * (size_t)i, 3 * sizeof(float));
    *radius = cp->radius[i];
}

void cachepoints_free(CachePoints *cp) {
    if (!cp) return;
    kdtree_free(&cp->kd);
    free(cp->pos); free(cp->radius);
    free(cp->near_off); free(cp->near_light);
    free(cp->far_off); free(cp->far);
    free(cp->vis_off); free(cp->vis_light);
    free(cp->h_total); free(cp->h_success); free(cp->w_vis); free(cp->w_blurred); free(cp->blur_wsum);
    free(cp->nbr); free(cp->nbr_w); free(cp->self_w);
    free(cp->far_eff); free(cp->far_cdf); free(cp->bin_total); free(cp->near_vis);
    free(cp);
}

typedef struct R0Ctx { const KdTree *kd; const float *pts; uint32_t knn; float *r0; float fallback; } R0Ctx;

static void r0_range(void *vctx, size_t b, size_t e, int thread) {
    (void)thread;
    R0Ctx *c = vctx;
    uint32_t nb[64];
    float d2[64];
    for (size_t i = b; i < e; ++i) {
        uint32_t k = kdtree_knn(c->kd, c->pts + 3 * i, c->knn, INFINITY, (uint32_t)i, nb, d2);
        float s = 0.0f;
        for (uint32_t j = 0; j < k; ++j) s += sqrtf(d2[j]);
        c->r0[i] = k ? s / (float)k : c->fallback;
    }
}

int cachepoints_build(CachePoints **out, const float *cand, uint32_t num_candidates, const CachePointLights *L,
                      const CachePointCamera *camera, const CachePointParams *P, CachePointStats *stats) {
    double t0 = now_seconds();
    *out = NULL;
    CachePointStats st = {0};
    st.candidates = num_candidates;
    if (P->knn > 64 || P->blur_neighbours > 64 || L->count == 0) return 1;
    /* drop non-finite candidates */
    float *in = malloc(((size_t)num_candidates + 1) * 3 * sizeof(float));
    if (!in) return -1;
    uint32_t nc = 0;
    for (uint32_t i = 0; i < num_candidates; ++i)
        if (isfinite(cand[3 * i]) && isfinite(cand[3 * i + 1]) && isfinite(cand[3 * i + 2]))
            memcpy(in + 3 * (size_t)nc++, cand + 3 * (size_t)i, 3 * sizeof(float));
    if (nc < MIN_POINTS) { free(in); if (stats) *stats = st; return 1; }
    float *pts = spatial_sort(in, nc);
    free(in);
    if (!pts) return -1;
    float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (uint32_t i = 0; i < nc; ++i)
        for (int k = 0; k < 3; ++k) { lo[k] = fminf(lo[k], pts[3 * i + k]); hi[k] = fmaxf(hi[k], pts[3 * i + k]); }
    float scene_scale = sqrtf((hi[0] - lo[0]) * (hi[0] - lo[0]) + (hi[1] - lo[1]) * (hi[1] - lo[1]) + (hi[2] - lo[2]) * (hi[2] - lo[2]));
    if (!(scene_scale > 0.0f)) scene_scale = 1.0f;

    /* merge pass 1 */
    KdTree kd;
    uint8_t *deleted = calloc(nc, 1);
    if (!deleted || kdtree_build(&kd, pts, nc) != 0) { free(deleted); free(pts); return -1; }
    if (greedy_merge(P, pts, &kd, nc, NULL, camera, deleted) != 0) { kdtree_free(&kd); free(deleted); free(pts); return -1; }
    kdtree_free(&kd);
    uint32_t n1 = compact(pts, NULL, deleted, nc);
    free(deleted);
    st.after_pass1 = n1;
    if (n1 < MIN_POINTS) { free(pts); if (stats) *stats = st; return 1; }

    /* r0 (the §3.1.4 initial guess, used by Eq. 1 before §3.1.4 defines r_p), then the omni
     * distributions that merge pass 2 compares */
    float *r0 = malloc(n1 * sizeof(float));
    OmniDist *omni = calloc(n1, sizeof *omni);
    Dist *dist = calloc(n1, sizeof *dist);
    if (!r0 || !omni || !dist || kdtree_build(&kd, pts, n1) != 0) { free(r0); free(omni); free(dist); free(pts); return -1; }
    R0Ctx rc = {&kd, pts, P->knn, r0, 0.01f * scene_scale};
    run_parallel(P, n1, 512, r0_range, &rc);
    DistCtx oc = {pts, r0, L, P, dist, 0, omni};
    run_parallel(P, n1, 16, dist_range, &oc);
    int failed = oc.failed;

    /* merge pass 2 */
    float *radius = malloc(n1 * sizeof(float));
    deleted = calloc(n1, 1);
    if (!radius || !deleted) failed = 1;
    if (!failed) {
        Pass2Ctx p2 = {pts, &kd, camera, omni, P->knn, scene_scale, radius};
        run_parallel(P, n1, 256, pass2_radius_range, &p2);
        failed = greedy_merge(P, pts, &kd, n1, radius, camera, deleted) != 0;
    }
    kdtree_free(&kd);
    for (uint32_t i = 0; i < n1; ++i) { free(omni[i].light); free(omni[i].p); }
    free(omni);
    uint32_t n = 0;
    if (!failed) {
        for (uint32_t i = 0; i < n1; ++i) if (!deleted[i]) r0[n++] = r0[i];
        n = compact(pts, radius, deleted, n1) == n ? n : 0;
    }
    free(deleted);
    /* the seven far bins for the survivors (§3.1.3) */
    if (!failed && n > 0) {
        DistCtx dc = {pts, r0, L, P, dist, 0, NULL};
        run_parallel(P, n, 16, dist_range, &dc);
        failed = dc.failed;
    }
    free(r0);
    CachePoints *cp = calloc(1, sizeof *cp);
    if (failed || !cp || n == 0) {
        for (uint32_t i = 0; i < n1; ++i) dist_free(&dist[i]);
        free(dist); free(pts); free(radius); free(cp);
        return failed ? -1 : 1;
    }
    cp->n = n;
    cp->pos = pts;
    cp->radius = radius;
    cp->params = *P;
    cp->num_lights = L->count;
    uint32_t K = P->blur_neighbours;
    cp->nbr = malloc((size_t)n * K * sizeof(uint32_t));
    cp->nbr_w = malloc((size_t)n * K * sizeof(float));
    cp->self_w = malloc(n * sizeof(float));
    Dist *blurred = calloc(n, sizeof *blurred);
    failed = !cp->nbr || !cp->nbr_w || !cp->self_w || !blurred || kdtree_build(&cp->kd, cp->pos, n) != 0;
    if (!failed) {
        /* blur the far bins out of place (§3.1.5) */
        BlurCtx bc = {cp, dist, blurred, 0};
        run_parallel(P, n, 64, blur_range, &bc);
        failed = bc.failed;
    }
    /* the points' own far lists are no longer needed once blurred: free them before the CSR
     * arrays exist, so the build never holds three copies of the far data at once */
    for (uint32_t i = 0; i < n; ++i) { free(dist[i].far); dist[i].far = NULL; dist[i].far_count = 0; }
    /* flatten into CSR arrays */
    size_t near_total = 0, far_total = 0;
    for (uint32_t i = 0; i < n && !failed; ++i) { near_total += dist[i].near_count; far_total += blurred[i].far_count; }
    if (!failed) {
        cp->near_off = malloc((n + 1) * sizeof(uint32_t));
        cp->near_light = malloc((near_total + 1) * sizeof(uint32_t));
        cp->far_off = malloc((n + 1) * sizeof(uint32_t));
        cp->far = malloc((far_total + 1) * sizeof(FarEntry));
        cp->vis_off = malloc((n + 1) * sizeof(uint32_t));
        cp->vis_light = malloc((near_total + far_total + 1) * sizeof(uint32_t));
        failed = !cp->near_off || !cp->near_light || !cp->far_off || !cp->far || !cp->vis_off || !cp->vis_light;
    }
    if (!failed) {
        size_t a = 0, f = 0, v = 0;
        for (uint32_t i = 0; i < n; ++i) {
            cp->near_off[i] = (uint32_t)a;
            cp->far_off[i] = (uint32_t)f;
            cp->vis_off[i] = (uint32_t)v;
            memcpy(cp->near_light + a, dist[i].near, dist[i].near_count * sizeof(uint32_t));
            memcpy(cp->far + f, blurred[i].far, blurred[i].far_count * sizeof(FarEntry));
            /* visibility slots: sorted union of near and far light ids */
            uint32_t x = 0, y = 0;
            while (x < dist[i].near_count || y < blurred[i].far_count) {
                uint32_t lx = x < dist[i].near_count ? dist[i].near[x] : UINT32_MAX;
                uint32_t ly = y < blurred[i].far_count ? blurred[i].far[y].light : UINT32_MAX;
                if (lx <= ly) { cp->vis_light[v++] = lx; ++x; if (lx == ly) ++y; }
                else { cp->vis_light[v++] = ly; ++y; }
            }
            a += dist[i].near_count;
            f += blurred[i].far_count;
            free(blurred[i].far); /* copied: release as we go */
            blurred[i].far = NULL;
            blurred[i].far_count = 0;
        }
        cp->near_off[n] = (uint32_t)a;
        cp->far_off[n] = (uint32_t)f;
        cp->vis_off[n] = (uint32_t)v;
        cp->h_total = calloc(v + 1, sizeof(uint32_t));
        cp->h_success = calloc(v + 1, sizeof(uint32_t));
        cp->w_vis = malloc((v + 1) * sizeof(float));
        cp->w_blurred = malloc((v + 1) * sizeof(float));
        cp->blur_wsum = malloc((v + 1) * sizeof(float));
        failed = !cp->h_total || !cp->h_success || !cp->w_vis || !cp->w_blurred || !cp->blur_wsum;
        cp->far_eff = malloc((f + 1) * FAR_BINS * sizeof(float));
        cp->far_cdf = malloc((f + 1) * FAR_BINS * sizeof(float));
        cp->bin_total = malloc(((size_t)n + 1) * FAR_BINS * sizeof(float));
        cp->near_vis = malloc((a + 1) * sizeof(float));
        failed = failed || !cp->far_eff || !cp->far_cdf || !cp->bin_total || !cp->near_vis;
        if (!failed) for (size_t s = 0; s < v; ++s) cp->w_vis[s] = cp->w_blurred[s] = 1.0f; /* first iteration: W = 1 */
        st.bytes = (size_t)n * (3 + 1 + 3 + 2 * K + 1) * sizeof(float) + a * 4 + f * sizeof(FarEntry) + v * 20;
    }
    for (uint32_t i = 0; i < n; ++i) { dist_free(&dist[i]); dist_free(&blurred[i]); }
    free(dist);
    free(blurred);
    if (failed) { cachepoints_free(cp); return -1; }
    rebuild_tables(cp);
    st.final_points = n;
    st.seconds = now_seconds() - t0;
    if (stats) *stats = st;
    *out = cp;
    return 0;
}
