/* cachepoints/build.c: the cache point build (§3.1). Section and equation numbers are the
 * paper's; "spec" is ../shared/design/cache-points-spec.md.
 *
 * candidates -> spatial sort -> merge pass 1 -> per point the near list and the fluence bin
 * -> merge pass 2 (Eqs. 2-3) -> the seven far bins for the survivors -> far-bin blur (Eq. 4)
 * -> flat arrays. Two ways to build a point's far distribution:
 *   linear (the paper): every light is estimated at every point; each bin keeps the lights
 *     holding 97% of its energy (4..256 of them); the blur unions the neighbours' lists.
 *   cut (beyond the paper, its §5.2.2 scaling failure): a cut through the scene's light tree,
 *     refined from the root by splitting the entry of largest estimated fluence until
 *     cut_size entries exist; nodes holding a near light are always split and near lights
 *     left out, so near and far never overlap. A point never visits every light: its cost is
 *     O(cut_size log N). The blur maps the neighbours' entries onto the point's own cut, so
 *     lists never grow. Every far light stays reachable through some cluster. */
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "internal.h"

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
    p->build_cut = 0;
    p->cut_size = 128;
}

static double now_seconds(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

void cp_run_parallel(const CachePointParams *p, size_t n, size_t grain, void (*fn)(void *, size_t, size_t, int),
                     void *ctx) {
    if (p->parallel_for) p->parallel_for(p->pool, n, grain, fn, ctx);
    else if (n) fn(ctx, 0, n, 0);
}
#define run_parallel cp_run_parallel

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


typedef struct ValueIndex { float v; uint32_t id; } ValueIndex;


/* Total orders (ties by light id / position) keep every result deterministic. */
static inline int vi_before(const ValueIndex *a, const ValueIndex *b) { /* value desc, id asc */
    return a->v > b->v || (a->v == b->v && a->id < b->id);
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

/* ---------------------------------------------------------------- light distributions (§3.1.3) */

typedef struct Dist {        /* per point, during the build */
    uint32_t near_count;
    uint32_t *near_key;      /* sorted */
    uint32_t *near_light;
    float *near_fluence;     /* fluence of each near light at x (for pass 2's similarity) */
    uint32_t far_count;
    FarEntry *far;           /* sorted by key */
} Dist;

static void dist_free(Dist *d) {
    free(d->near_key); free(d->near_light); free(d->near_fluence); free(d->far);
    memset(d, 0, sizeof *d);
}

static int dist_alloc_near(Dist *d, uint32_t count) {
    d->near_count = count;
    d->near_key = malloc((count ? count : 1) * sizeof(uint32_t));
    d->near_light = malloc((count ? count : 1) * sizeof(uint32_t));
    d->near_fluence = malloc((count ? count : 1) * sizeof(float));
    return d->near_key && d->near_light && d->near_fluence ? 0 : -1;
}

/* The omni distribution of a point: near fluence plus the far fluence bin, normalised, as
 * (key, probability) sorted by key (spec §3.5 proposal): what merge pass 2 compares. */
typedef struct OmniDist { uint32_t count; uint32_t *key; float *p; } OmniDist;

static int omni_build(const Dist *d, OmniDist *o) {
    uint32_t n = d->near_count + d->far_count;
    o->key = malloc((n ? n : 1) * sizeof(uint32_t));
    o->p = malloc((n ? n : 1) * sizeof(float));
    if (!o->key || !o->p) return -1;
    uint32_t a = 0, b = 0, m = 0;
    double total = 0.0;
    while (a < d->near_count || b < d->far_count) {
        uint32_t ka = a < d->near_count ? d->near_key[a] : CP_NONE;
        uint32_t kb = b < d->far_count ? d->far[b].key : CP_NONE;
        float v;
        uint32_t k;
        if (ka <= kb) { k = ka; v = d->near_fluence[a++]; if (ka == kb) ++b; }
        else { k = kb; v = d->far[b++].value[CP_OMNI_BIN]; }
        if (!(v > 0.0f)) continue;
        o->key[m] = k; o->p[m] = v; total += v; ++m;
    }
    for (uint32_t i = 0; i < m; ++i) o->p[i] = (float)(o->p[i] / total);
    o->count = m;
    return 0;
}

/* Two uses: with omni != NULL each point's distribution is reduced at once to its normalised
 * omni distribution (all merge pass 2 needs), so the build's memory stays proportional to
 * the final points; the full seven bins are computed afterwards for the survivors only. */
typedef struct DistCtx {
    const float *pts;
    /* the r_p of Eq. 1: the final radius for the survivors; in the pass-1 phase, before
     * §3.1.4 defines it, its initial guess r0 (the mean 20-NN distance) */
    const float *near_radius;
    const CachePointLights *lights;
    const CachePointParams *params;
    const CachePoints *keys;   /* key space (cut build) */
    Dist *dist;
    OmniDist *omni;
    int failed;
} DistCtx;

static inline void sanitize7(float v[CP_FAR_BINS]) {
    for (int i = 0; i < CP_FAR_BINS; ++i) if (!(v[i] > 0.0f) || !isfinite(v[i])) v[i] = 0.0f;
}

static inline int any_positive7(const float v[CP_FAR_BINS]) {
    for (int i = 0; i < CP_FAR_BINS; ++i) if (v[i] > 0.0f) return 1;
    return 0;
}

/* --- linear: every light at every point (the paper) */

typedef struct LinearScratch { float *values; uint8_t *is_near, *keep; ValueIndex *vi; } LinearScratch;

static int linear_point(const DistCtx *c, LinearScratch *s, size_t i) {
    const CachePointLights *L = c->lights;
    const CachePointParams *P = c->params;
    uint32_t N = L->count;
    const float *x = c->pts + 3 * i;
    float rn = P->near_factor * c->near_radius[i];
    Dist *d = &c->dist[i];
    float *values = s->values;
    /* Eq. 1: finite lights whose centroid lies within D r_p are near */
    uint32_t near_count = 0;
    for (uint32_t l = 0; l < N; ++l) {
        if (c->omni) values[(size_t)l * CP_FAR_BINS + CP_OMNI_BIN] = L->estimate(L->user, l, x, NULL);
        else L->estimate7(L->user, l, x, values + (size_t)l * CP_FAR_BINS);
        s->is_near[l] = !L->infinite[l] && dist2(L->centroid + 3 * (size_t)l, x) <= rn * rn;
        near_count += s->is_near[l];
    }
    if (near_count > P->max_near) {
        /* cap (spec §3.4): keep the strongest by fluence; the rest become far */
        uint32_t m = 0;
        for (uint32_t l = 0; l < N; ++l)
            if (s->is_near[l]) { s->vi[m].v = values[(size_t)l * CP_FAR_BINS + CP_OMNI_BIN]; s->vi[m].id = l; ++m; }
        select_top(s->vi, m, P->max_near);
        for (uint32_t j = P->max_near; j < m; ++j) s->is_near[s->vi[j].id] = 0;
        near_count = P->max_near;
    }
    if (dist_alloc_near(d, near_count) != 0) return -1;
    uint32_t m = 0;
    for (uint32_t l = 0; l < N; ++l)
        if (s->is_near[l]) {
            d->near_key[m] = d->near_light[m] = l;
            d->near_fluence[m] = values[(size_t)l * CP_FAR_BINS + CP_OMNI_BIN];
            ++m;
        }
    /* far bins: per bin the shortest prefix (by value, ties by id) holding 97% of the bin's
     * energy, length clamped to [min(4, nonzero), 256] (spec §3.4) */
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
        uint32_t len = select_energy_prefix(s->vi, nz, P->energy_fraction * total);
        uint32_t lo = P->min_per_bin < nz ? P->min_per_bin : nz;
        if (len < lo) { select_top(s->vi, nz, lo); len = lo; }
        if (len > P->max_per_bin) { select_top(s->vi, len, P->max_per_bin); len = P->max_per_bin; }
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

/* --- cut: a cut through the light tree */

/* Merge pass 2's omni distributions use cut_size / 4 entries (at least 32). */
#define CUT_PASS2_DIVISOR 4
#define CUT_PASS2_MIN 32

/* Sorts (key << 32 | index) pairs by key: LSD radix over the key's bytes, skipping bytes
 * every key shares. O(n) for the few hundred entries of a cut. */
static void sort_by_key(uint64_t *a, uint64_t *tmp, uint32_t n) {
    for (int byte = 4; byte < 8; ++byte) {
        uint32_t count[256] = {0};
        int shift = 8 * byte;
        for (uint32_t i = 0; i < n; ++i) count[(a[i] >> shift) & 0xff]++;
        if (n == 0 || count[(a[0] >> shift) & 0xff] == n) continue;
        uint32_t sum = 0;
        for (int d = 0; d < 256; ++d) { uint32_t c = count[d]; count[d] = sum; sum += c; }
        for (uint32_t i = 0; i < n; ++i) tmp[count[(a[i] >> shift) & 0xff]++] = a[i];
        memcpy(a, tmp, n * sizeof *a);
    }
}

typedef struct HeapItem { float priority; uint32_t entry; } HeapItem; /* entry: index into the pool */

typedef struct CutScratch {
    FarEntry *pool;           /* estimates of the nodes considered so far */
    uint32_t pool_count, pool_cap;
    HeapItem *heap;           /* max-heap over pool entries by (priority desc, key asc) */
    uint32_t heap_count, heap_cap;
    uint32_t *final;          /* pool indices of the entries kept */
    uint32_t final_count, final_cap;
    uint32_t *near_key;       /* near candidates (traversal order = ascending keys) */
    uint32_t near_count, near_cap;
} CutScratch;

static int grow(void **a, uint32_t *cap, uint32_t need, size_t elem) {
    if (need <= *cap) return 0;
    uint32_t nc = *cap ? *cap : 64;
    while (nc < need) nc *= 2;
    void *n = realloc(*a, (size_t)nc * elem);
    if (!n) return -1;
    *a = n;
    *cap = nc;
    return 0;
}

static void cut_scratch_free(CutScratch *s) {
    free(s->pool); free(s->heap); free(s->final); free(s->near_key);
    memset(s, 0, sizeof *s);
}

static inline int heap_before(const CutScratch *s, HeapItem a, HeapItem b) {
    return a.priority > b.priority || (a.priority == b.priority && s->pool[a.entry].key < s->pool[b.entry].key);
}

static int heap_push(CutScratch *s, HeapItem it) {
    if (grow((void **)&s->heap, &s->heap_cap, s->heap_count + 1, sizeof(HeapItem)) != 0) return -1;
    uint32_t i = s->heap_count++;
    while (i > 0) {
        uint32_t parent = (i - 1) / 2;
        if (!heap_before(s, it, s->heap[parent])) break;
        s->heap[i] = s->heap[parent];
        i = parent;
    }
    s->heap[i] = it;
    return 0;
}

static HeapItem heap_pop(CutScratch *s) {
    HeapItem top = s->heap[0], last = s->heap[--s->heap_count];
    uint32_t i = 0, n = s->heap_count;
    for (;;) {
        uint32_t c = 2 * i + 1;
        if (c >= n) break;
        if (c + 1 < n && heap_before(s, s->heap[c + 1], s->heap[c])) ++c;
        if (!heap_before(s, s->heap[c], last)) break;
        s->heap[i] = s->heap[c];
        i = c;
    }
    if (n) s->heap[i] = last;
    return top;
}

static float box_dist2(const float lo[3], const float hi[3], const float x[3]) {
    float d2 = 0.0f;
    for (int k = 0; k < 3; ++k) {
        float d = x[k] < lo[k] ? lo[k] - x[k] : (x[k] > hi[k] ? x[k] - hi[k] : 0.0f);
        d2 += d * d;
    }
    return d2;
}

/* 1 if a near key lies in [key, end) */
static int holds_near(const CutScratch *s, uint32_t key, uint32_t end) {
    uint32_t at = cp_lower_bound(s->near_key, 0, s->near_count, key);
    return at < s->near_count && s->near_key[at] < end;
}

/* Estimates node `key` at x and queues it, or, when it holds a near light, splits it right
 * away (near lights are evaluated exactly and must not also sit in a far cluster). */
static int cut_consider(const DistCtx *c, CutScratch *s, uint32_t key, const float *x) {
    const CachePointLights *L = c->lights;
    const CachePointTree *T = L->tree;
    const CachePoints *K = c->keys;
    uint32_t light = K->key_light[key];
    if (holds_near(s, key, K->key_end[key])) {
        if (light != CP_NONE) return 0; /* the near light itself */
        if (cut_consider(c, s, key + 1, x) != 0) return -1;
        return cut_consider(c, s, T->second_child[key], x);
    }
    if (grow((void **)&s->pool, &s->pool_cap, s->pool_count + 1, sizeof(FarEntry)) != 0) return -1;
    FarEntry *e = &s->pool[s->pool_count];
    e->key = key;
    if (light != CP_NONE) L->estimate7(L->user, light, x, e->value);
    else T->node_estimate7(L->user, key, x, e->value);
    sanitize7(e->value);
    if (!any_positive7(e->value)) return 0; /* reachable through the uniform floor only */
    float pri = 0.0f;
    for (int i = 0; i < CP_FAR_BINS; ++i) pri = e->value[i] > pri ? e->value[i] : pri; /* (fmaxf is a libm call) */
    return heap_push(s, (HeapItem){pri, s->pool_count++});
}

static int cut_point(const DistCtx *c, CutScratch *s, size_t i) {
    const CachePointLights *L = c->lights;
    const CachePointTree *T = L->tree;
    const CachePointParams *P = c->params;
    const CachePoints *K = c->keys;
    const float *x = c->pts + 3 * i;
    float rn = P->near_factor * c->near_radius[i], rn2 = rn * rn;
    Dist *d = &c->dist[i];
    /* Eq. 1 near lights by a range query on the tree: subtrees whose box is farther than D r_p
     * hold none; leaves test the light's centroid as the linear build does. Depth-first,
     * first child first: the keys come out sorted. Merge pass 2 compares pure fluence cuts
     * (no near list: a strong nearby light is resolved to a leaf by the refinement anyway),
     * which spares the range query and the forced splits for every pass-1 point. */
    s->near_count = 0;
    if (T->node_count && !c->omni) {
        uint32_t stack[160];
        uint32_t top = 0;
        stack[top++] = 0;
        while (top) {
            uint32_t node = stack[--top];
            float lo[3], hi[3];
            T->node_bounds(L->user, node, lo, hi);
            if (!(box_dist2(lo, hi, x) <= rn2)) continue;
            uint32_t light = T->leaf_light[node];
            if (light != CP_NONE) {
                if (L->infinite[light] || !(dist2(L->centroid + 3 * (size_t)light, x) <= rn2)) continue;
                if (grow((void **)&s->near_key, &s->near_cap, s->near_count + 1, sizeof(uint32_t)) != 0) return -1;
                s->near_key[s->near_count++] = node;
                continue;
            }
            if (top + 2 > sizeof stack / sizeof *stack) return -1; /* deeper than any tree we build */
            stack[top++] = T->second_child[node];
            stack[top++] = node + 1;
        }
    }
    uint32_t near_count = s->near_count;
    if (dist_alloc_near(d, near_count < P->max_near ? near_count : P->max_near) != 0) return -1;
    if (near_count > P->max_near) {
        /* cap (spec §3.4): the strongest by fluence, ties by key; then back in key order */
        ValueIndex *vi = malloc(near_count * sizeof *vi);
        uint64_t *keys = malloc(P->max_near * sizeof *keys);
        if (!vi || !keys) { free(vi); free(keys); return -1; }
        for (uint32_t k = 0; k < near_count; ++k) {
            vi[k].id = s->near_key[k];
            vi[k].v = L->estimate(L->user, K->key_light[vi[k].id], x, NULL);
        }
        select_top(vi, near_count, P->max_near);
        for (uint32_t k = 0; k < P->max_near; ++k) keys[k] = vi[k].id;
        sort_u64(keys, P->max_near);
        for (uint32_t k = 0; k < P->max_near; ++k) s->near_key[k] = (uint32_t)keys[k];
        s->near_count = near_count = P->max_near;
        free(vi); free(keys);
    }
    for (uint32_t k = 0; k < near_count; ++k) {
        d->near_key[k] = s->near_key[k];
        d->near_light[k] = K->key_light[s->near_key[k]];
        float v = L->estimate(L->user, d->near_light[k], x, NULL);
        d->near_fluence[k] = v > 0.0f && isfinite(v) ? v : 0.0f;
    }
    /* the cut: split the queued entry of largest estimate while the budget allows. Merge
     * pass 2 only compares omni distributions, which a coarser cut describes well enough. */
    uint32_t budget = c->omni ? (P->cut_size / CUT_PASS2_DIVISOR > CUT_PASS2_MIN ? P->cut_size / CUT_PASS2_DIVISOR : CUT_PASS2_MIN)
                              : P->cut_size;
    s->pool_count = s->heap_count = s->final_count = 0;
    if (T->node_count && cut_consider(c, s, 0, x) != 0) return -1;
    while (s->heap_count && s->final_count + s->heap_count + 1 <= budget) {
        HeapItem it = heap_pop(s);
        uint32_t key = s->pool[it.entry].key;
        if (K->key_light[key] != CP_NONE) { /* a single light: final */
            if (grow((void **)&s->final, &s->final_cap, s->final_count + 1, sizeof(uint32_t)) != 0) return -1;
            s->final[s->final_count++] = it.entry;
            continue;
        }
        if (cut_consider(c, s, key + 1, x) != 0 || cut_consider(c, s, T->second_child[key], x) != 0) return -1;
    }
    uint32_t count = s->final_count + s->heap_count;
    /* infinite lights are not in the tree: each is its own entry (always far, §3.1.3) */
    uint32_t num_inf = K->num_keys - T->node_count;
    d->far = malloc((count + num_inf + 1) * sizeof(FarEntry));
    if (!d->far) return -1;
    uint32_t m = 0;
    for (uint32_t k = 0; k < s->final_count; ++k) d->far[m++] = s->pool[s->final[k]];
    for (uint32_t k = 0; k < s->heap_count; ++k) d->far[m++] = s->pool[s->heap[k].entry];
    for (uint32_t j = 0; j < num_inf; ++j) {
        FarEntry *e = &d->far[m];
        e->key = T->node_count + j;
        L->estimate7(L->user, K->key_light[e->key], x, e->value);
        sanitize7(e->value);
        if (any_positive7(e->value)) ++m;
    }
    /* sort by key (keys are unique) */
    uint64_t *order = malloc(2 * (size_t)(m ? m : 1) * sizeof *order);
    FarEntry *sorted = malloc((m ? m : 1) * sizeof *sorted);
    if (!order || !sorted) { free(order); free(sorted); return -1; }
    for (uint32_t k = 0; k < m; ++k) order[k] = (uint64_t)d->far[k].key << 32 | k;
    sort_by_key(order, order + m, m);
    for (uint32_t k = 0; k < m; ++k) sorted[k] = d->far[(uint32_t)order[k]];
    free(order);
    free(d->far);
    d->far = sorted;
    d->far_count = m;
    return 0;
}

static void dist_range(void *vctx, size_t b, size_t e, int thread) {
    (void)thread;
    DistCtx *c = vctx;
    uint32_t N = c->lights->count;
    LinearScratch ls = {0};
    CutScratch cs = {0};
    if (!c->params->build_cut) {
        ls.values = malloc((size_t)(N ? N : 1) * CP_FAR_BINS * sizeof(float));
        ls.is_near = malloc(N ? N : 1);
        ls.keep = malloc(N ? N : 1);
        ls.vi = malloc((size_t)(N ? N : 1) * sizeof *ls.vi);
        if (!ls.values || !ls.is_near || !ls.keep || !ls.vi) c->failed = 1;
    }
    for (size_t i = b; i < e && !c->failed; ++i) {
        int rc = c->params->build_cut ? cut_point(c, &cs, i) : linear_point(c, &ls, i);
        if (rc == 0 && c->omni) {
            rc = omni_build(&c->dist[i], &c->omni[i]);
            dist_free(&c->dist[i]);
        }
        if (rc != 0) c->failed = 1;
    }
    free(ls.values); free(ls.is_near); free(ls.keep); free(ls.vi);
    cut_scratch_free(&cs);
}

/* ---------------------------------------------------------------- merge pass 2 (§3.1.4) */


/* Eqs. 2-3 */
static float similarity(const OmniDist *A, const OmniDist *B) {
    if (A->count + B->count == 0) return 1.0f;
    uint32_t a = 0, b = 0;
    double s = 0.0;
    while (a < A->count && b < B->count) {
        if (A->key[a] < B->key[b]) ++a;
        else if (A->key[a] > B->key[b]) ++b;
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
/* ---------------------------------------------------------------- blur (§3.1.5, Eq. 4) */

typedef struct BlurCtx {
    CachePoints *cp;
    const Dist *dist;    /* final points' own distributions */
    Dist *blurred;       /* out of place */
    int failed;
} BlurCtx;

/* The 16 nearest points and their normalised Eq. 4 weights (kept: the visibility blur of
 * §3.2.2 reuses them at every barrier). */
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
        cp->nbr[i * K + j] = j < k ? nb[j] : CP_NONE;
        cp->nbr_w[i * K + j] = j < k ? w[j] / z : 0.0f;
    }
}

/* Optional (spec §3.6): re-apply the 97% / 4..256 rule per bin to a blurred list, which
 * bounds memory at 7 x 256 lights per point. */
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
        uint32_t len = select_energy_prefix(vi, nz, P->energy_fraction * total);
        uint32_t lo = P->min_per_bin < nz ? P->min_per_bin : nz;
        if (len < lo) { select_top(vi, nz, lo); len = lo; }
        if (len > P->max_per_bin) { select_top(vi, len, P->max_per_bin); len = P->max_per_bin; }
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
            sort_u64(tmp, count);
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
        if (!out->far || grow((void **)&keys, &cap, m + 1, sizeof(uint32_t)) != 0) { c->failed = 1; break; }
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
                    if (grow((void **)&holes, &hole_cap, nholes + 1, sizeof(FarEntry)) != 0) { c->failed = 1; break; }
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
        if (grow((void **)&order, &order_cap, 2 * nholes, sizeof(uint64_t)) != 0) { c->failed = 1; break; }
        for (uint32_t h = 0; h < nholes; ++h) order[h] = (uint64_t)holes[h].key << 32 | h;
        sort_by_key(order, order + nholes, nholes);
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

/* ---------------------------------------------------------------- key space */

/* Cut build: keys are the tree's nodes, then one per infinite light (spec'd in internal.h). */
static int key_space_init(CachePoints *cp, const CachePointLights *L) {
    cp->num_lights = L->count;
    cp->num_keys = L->count;
    if (!cp->params.build_cut) return 0;
    const CachePointTree *T = L->tree;
    uint32_t nn = T->node_count, ninf = 0;
    for (uint32_t l = 0; l < L->count; ++l) ninf += L->infinite[l] && T->light_leaf[l] == CP_NONE;
    cp->num_keys = nn + ninf;
    cp->light_key = malloc(((size_t)L->count + 1) * sizeof(uint32_t));
    cp->key_end = malloc(((size_t)cp->num_keys + 1) * sizeof(uint32_t));
    cp->key_light = malloc(((size_t)cp->num_keys + 1) * sizeof(uint32_t));
    if (!cp->light_key || !cp->key_end || !cp->key_light) return -1;
    /* depth-first layout: node k's subtree is k, its first child's subtree, its second's */
    for (uint32_t k = nn; k-- > 0;) {
        uint32_t light = T->leaf_light[k];
        int leaf = light != CP_NONE;
        if (!leaf && !(T->second_child[k] > k && T->second_child[k] < nn)) return -2; /* malformed tree */
        if (leaf && light >= L->count) return -2;
        cp->key_light[k] = light;
        cp->key_end[k] = leaf ? k + 1 : cp->key_end[T->second_child[k]];
    }
    uint32_t j = nn;
    for (uint32_t l = 0; l < L->count; ++l) {
        cp->light_key[l] = T->light_leaf[l];
        if (L->infinite[l] && T->light_leaf[l] == CP_NONE) {
            cp->light_key[l] = j;
            cp->key_light[j] = l;
            cp->key_end[j] = j + 1;
            ++j;
        }
    }
    return 0;
}

/* ---------------------------------------------------------------- the build */

uint32_t cachepoints_count(const CachePoints *cp) { return cp ? cp->n : 0; }

void cachepoints_point(const CachePoints *cp, uint32_t i, float pos[3], float *radius) {
    memcpy(pos, cp->pos + 3 * (size_t)i, 3 * sizeof(float));
    *radius = cp->radius[i];
}

void cachepoints_free(CachePoints *cp) {
    if (!cp) return;
    kdtree_free(&cp->kd);
    free(cp->pos); free(cp->radius);
    free(cp->light_key); free(cp->key_end); free(cp->key_light);
    free(cp->near_off); free(cp->near_key); free(cp->near_light); free(cp->near_slot); free(cp->near_vis);
    free(cp->far_off); free(cp->far); free(cp->far_slot); free(cp->far_cdf);
    free(cp->vis_off); free(cp->vis_key); free(cp->vis_count); free(cp->far_bin_total); free(cp->w_blurred);
    free(cp->vis_low); free(cp->vis_active); free(cp->tables_dirty);
    free(cp->nbr); free(cp->nbr_w); free(cp->self_w);
    free(cp);
}

/* Flattens the final points' near lists and blurred far lists into CSR arrays (far entries a
 * near list also holds are dropped: near lights are evaluated exactly, spec §5.3), with one
 * visibility slot per key: a parallel count, prefix sums, then a parallel fill that frees
 * the per-point lists as it goes. */
typedef struct FlattenCtx { CachePoints *cp; Dist *dist, *blurred; int fill; size_t clusters[64]; } FlattenCtx;

static void flatten_range(void *vctx, size_t b, size_t e, int thread) {
    FlattenCtx *c = vctx;
    CachePoints *cp = c->cp;
    size_t clusters = 0;
    for (size_t i = b; i < e; ++i) {
        Dist *d = &c->dist[i], *bl = &c->blurred[i];
        uint32_t a = 0, f = 0, v = 0, x = 0, y = 0;
        if (c->fill) { a = cp->near_off[i]; f = cp->far_off[i]; v = cp->vis_off[i]; }
        /* one merge walk over the two sorted lists */
        while (x < d->near_count || y < bl->far_count) {
            uint32_t kx = x < d->near_count ? d->near_key[x] : CP_NONE;
            uint32_t ky = y < bl->far_count ? bl->far[y].key : CP_NONE;
            if (kx <= ky) {
                if (c->fill) {
                    cp->near_key[a] = kx;
                    cp->near_light[a] = d->near_light[x];
                    cp->near_slot[a] = v;
                    cp->vis_key[v] = kx;
                }
                ++a; ++v; ++x;
                if (kx == ky) ++y; /* near wins */
            } else {
                if (c->fill) {
                    cp->far[f] = bl->far[y];
                    cp->far_slot[f] = v;
                    cp->vis_key[v] = ky;
                    clusters += cp_key_light(cp, ky) == CP_NONE;
                }
                ++f; ++v; ++y;
            }
        }
        if (c->fill) {
            dist_free(d);
            dist_free(bl);
        } else { /* counts, turned into offsets by the caller */
            cp->near_off[i + 1] = a;
            cp->far_off[i + 1] = f;
            cp->vis_off[i + 1] = v;
        }
    }
    __atomic_fetch_add(&c->clusters[thread & 63], clusters, __ATOMIC_RELAXED);
}

static int flatten(CachePoints *cp, Dist *dist, Dist *blurred) {
    uint32_t n = cp->n;
    cp->near_off = malloc((n + 1) * sizeof(uint32_t));
    cp->far_off = malloc((n + 1) * sizeof(uint32_t));
    cp->vis_off = malloc((n + 1) * sizeof(uint32_t));
    cp->vis_low = calloc(n + 1, 1);
    cp->vis_active = calloc(n + 1, 1);
    cp->tables_dirty = calloc(n + 1, 1);
    if (!cp->near_off || !cp->far_off || !cp->vis_off || !cp->vis_low || !cp->vis_active || !cp->tables_dirty) return -1;
    FlattenCtx c = {cp, dist, blurred, 0, {0}};
    run_parallel(&cp->params, n, 64, flatten_range, &c);
    size_t a = 0, f = 0, v = 0;
    cp->near_off[0] = cp->far_off[0] = cp->vis_off[0] = 0;
    for (uint32_t i = 0; i < n; ++i) {
        a += cp->near_off[i + 1];
        f += cp->far_off[i + 1];
        v += cp->vis_off[i + 1];
        if (v >= UINT32_MAX) return -1; /* offsets are 32-bit */
        cp->near_off[i + 1] = (uint32_t)a;
        cp->far_off[i + 1] = (uint32_t)f;
        cp->vis_off[i + 1] = (uint32_t)v;
    }
    cp->near_key = malloc((a + 1) * sizeof(uint32_t));
    cp->near_light = malloc((a + 1) * sizeof(uint32_t));
    cp->near_slot = malloc((a + 1) * sizeof(uint32_t));
    cp->near_vis = malloc((a + 1) * sizeof(float));
    cp->far = malloc((f + 1) * sizeof(FarEntry));
    cp->far_slot = malloc((f + 1) * sizeof(uint32_t));
    cp->vis_key = malloc((v + 1) * sizeof(uint32_t));
    cp->vis_count = calloc(v + 1, sizeof(VisCounter));
    size_t bt_bytes = ((size_t)n * CP_BIN_STRIDE * sizeof(float) + 63) / 64 * 64 + 64;
    cp->far_bin_total = aligned_alloc(64, bt_bytes); /* a point's 32-byte block never straddles a line */
    if (cp->far_bin_total) memset(cp->far_bin_total, 0, bt_bytes);
    cp->w_blurred = malloc((v + 1) * sizeof(float));
    cp->far_cdf = malloc((f + 1) * CP_FAR_BINS * sizeof(float));
    if (!cp->near_key || !cp->near_light || !cp->near_slot || !cp->near_vis || !cp->far || !cp->far_slot ||
        !cp->vis_key || !cp->vis_count || !cp->far_bin_total || !cp->w_blurred || !cp->far_cdf)
        return -1;
    c.fill = 1;
    run_parallel(&cp->params, n, 64, flatten_range, &c);
    size_t clusters = 0;
    for (int t = 0; t < 64; ++t) clusters += c.clusters[t];
    for (size_t s = 0; s < v; ++s) cp->w_blurred[s] = 1.0f; /* first iteration: W = 1 */
    uint32_t K = cp->params.blur_neighbours;
    cp->stats.bytes = (size_t)n * (3 + 1 + 3 + 2 * K + 1 + CP_BIN_STRIDE) * sizeof(float) + a * 16 + f * (sizeof(FarEntry) + 4 + 4 * CP_FAR_BINS) +
                      v * 16 + (size_t)cp->num_keys * 8 + (cp->light_key ? (size_t)cp->num_lights * 4 : 0) +
                      (size_t)n * 19 /* kd-tree, flags */;
    cp->stats.mean_near = n ? (double)a / n : 0.0;
    cp->stats.mean_far = n ? (double)f / n : 0.0;
    cp->stats.mean_far_clusters = n ? (double)clusters / n : 0.0;
    return 0;
}

int cachepoints_build(CachePoints **out, const float *cand, uint32_t num_candidates, const CachePointLights *L,
                      const CachePointCamera *camera, const CachePointParams *P, CachePointStats *stats) {
    double t0 = now_seconds();
    *out = NULL;
    CachePointStats st = {0};
    st.candidates = num_candidates;
    if (stats) *stats = st;
    if (P->knn > 64 || P->blur_neighbours > 64 || L->count == 0) return 1;
    if (P->build_cut && (!L->tree || !L->tree->node_bounds || !L->tree->node_estimate7 || P->cut_size < 1)) return -1;
    CachePoints *cp = calloc(1, sizeof *cp);
    if (!cp) return -1;
    cp->params = *P;
    if (cp->params.max_near > CACHEPOINTS_MAX_NEAR) cp->params.max_near = CACHEPOINTS_MAX_NEAR;
    P = &cp->params;
    if (key_space_init(cp, L) != 0) { cachepoints_free(cp); return -1; }
    /* drop non-finite candidates */
    float *in = malloc(((size_t)num_candidates + 1) * 3 * sizeof(float));
    if (!in) { cachepoints_free(cp); return -1; }
    uint32_t nc = 0;
    for (uint32_t i = 0; i < num_candidates; ++i)
        if (isfinite(cand[3 * i]) && isfinite(cand[3 * i + 1]) && isfinite(cand[3 * i + 2]))
            memcpy(in + 3 * (size_t)nc++, cand + 3 * (size_t)i, 3 * sizeof(float));
    if (nc < CP_MIN_POINTS) { free(in); cachepoints_free(cp); return 1; }
    float *pts = spatial_sort(in, nc);
    free(in);
    if (!pts) { cachepoints_free(cp); return -1; }
    float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (uint32_t i = 0; i < nc; ++i)
        for (int k = 0; k < 3; ++k) { lo[k] = fminf(lo[k], pts[3 * i + k]); hi[k] = fmaxf(hi[k], pts[3 * i + k]); }
    float scene_scale = sqrtf((hi[0] - lo[0]) * (hi[0] - lo[0]) + (hi[1] - lo[1]) * (hi[1] - lo[1]) + (hi[2] - lo[2]) * (hi[2] - lo[2]));
    if (!(scene_scale > 0.0f)) scene_scale = 1.0f;

    /* merge pass 1 (§3.1.2) */
    KdTree kd;
    uint8_t *deleted = calloc(nc, 1);
    if (!deleted || kdtree_build(&kd, pts, nc) != 0) { free(deleted); free(pts); cachepoints_free(cp); return -1; }
    int failed = greedy_merge(P, pts, &kd, nc, NULL, camera, deleted) != 0;
    kdtree_free(&kd);
    uint32_t n1 = failed ? 0 : compact(pts, NULL, deleted, nc);
    free(deleted);
    st.after_pass1 = n1;
    if (failed || n1 < CP_MIN_POINTS) { free(pts); cachepoints_free(cp); if (stats) *stats = st; return failed ? -1 : 1; }

    /* r0 (the §3.1.4 initial guess, used by Eq. 1 before §3.1.4 defines r_p), then the omni
     * distributions that merge pass 2 compares */
    float *r0 = malloc(n1 * sizeof(float));
    OmniDist *omni = calloc(n1, sizeof *omni);
    Dist *dist = calloc(n1, sizeof *dist);
    float *radius = malloc(n1 * sizeof(float));
    deleted = calloc(n1, 1);
    failed = !r0 || !omni || !dist || !radius || !deleted || kdtree_build(&kd, pts, n1) != 0;
    if (!failed) {
        R0Ctx rc = {&kd, pts, P->knn, r0, 0.01f * scene_scale};
        run_parallel(P, n1, 512, r0_range, &rc);
        DistCtx oc = {pts, r0, L, P, cp, dist, omni, 0};
        run_parallel(P, n1, 16, dist_range, &oc);
        failed = oc.failed;
        /* merge pass 2 (§3.1.4) */
        if (!failed) {
            Pass2Ctx p2 = {pts, &kd, camera, omni, P->knn, scene_scale, radius};
            run_parallel(P, n1, 256, pass2_radius_range, &p2);
            failed = greedy_merge(P, pts, &kd, n1, radius, camera, deleted) != 0;
        }
        kdtree_free(&kd);
    }
    for (uint32_t i = 0; omni && i < n1; ++i) { free(omni[i].key); free(omni[i].p); }
    free(omni);
    uint32_t n = 0;
    if (!failed) {
        for (uint32_t i = 0; i < n1; ++i) if (!deleted[i]) r0[n++] = r0[i];
        compact(pts, radius, deleted, n1);
    }
    free(deleted);
    /* the seven far bins for the survivors (§3.1.3) */
    if (!failed && n > 0) {
        DistCtx dc = {pts, radius, L, P, cp, dist, NULL, 0};
        run_parallel(P, n, 16, dist_range, &dc);
        failed = dc.failed;
    }
    free(r0);
    cp->n = n;
    cp->pos = pts;
    cp->radius = radius;
    uint32_t K = P->blur_neighbours;
    Dist *blurred = NULL;
    if (!failed && n > 0) {
        cp->nbr = malloc((size_t)n * K * sizeof(uint32_t) + 1);
        cp->nbr_w = malloc((size_t)n * K * sizeof(float) + 1);
        cp->self_w = malloc(n * sizeof(float));
        blurred = calloc(n, sizeof *blurred);
        failed = !cp->nbr || !cp->nbr_w || !cp->self_w || !blurred || kdtree_build(&cp->kd, cp->pos, n) != 0 ||
                 kdtree_build_clearance(&cp->kd) != 0; /* render-time 1-NN shortcut */
    }
    if (!failed && n > 0) {
        /* blur the far bins out of place (§3.1.5); then the points' own lists are freed
         * before the flat arrays exist, so the build never holds three copies */
        BlurCtx bc = {cp, dist, blurred, 0};
        run_parallel(P, n, 64, P->build_cut ? blur_cut_range : blur_linear_range, &bc);
        failed = bc.failed;
        for (uint32_t i = 0; i < n; ++i) { free(dist[i].far); dist[i].far = NULL; dist[i].far_count = 0; }
    }
    if (!failed && n > 0) failed = flatten(cp, dist, blurred) != 0;
    for (uint32_t i = 0; i < n1 && dist; ++i) dist_free(&dist[i]);
    for (uint32_t i = 0; i < n && blurred; ++i) dist_free(&blurred[i]);
    free(dist);
    free(blurred);
    if (failed || n == 0) { cachepoints_free(cp); return failed ? -1 : 1; }
    cp_rebuild_tables(cp, 1);
    st.final_points = n;
    st.bytes = cp->stats.bytes;
    st.mean_near = cp->stats.mean_near;
    st.mean_far = cp->stats.mean_far;
    st.mean_far_clusters = cp->stats.mean_far_clusters;
    st.seconds = now_seconds() - t0;
    cp->stats = st;
    if (stats) *stats = st;
    *out = cp;
    return 0;
}
