/* cachepoints/kdtree.c: static 3-D kd-tree (see kdtree.h).
 *
 * Layout: an implicit median-split tree over an array of point copies {x, y, z, index}.
 * A range [lo, hi) with more than KD_LEAF points splits on the widest axis of its bounding
 * box at mid = lo + (hi - lo) / 2: the point at mid is the splitting point, [lo, mid) holds
 * the points with smaller (coordinate, index) keys and [mid + 1, hi) the larger ones. The
 * split axis is stored per mid position. Smaller ranges are leaves scanned linearly.
 *
 * Build: quickselect per level (O(n log n) overall) on a total-order key
 * (float bits mapped to an unsigned order, index) so equal coordinates are ordered by
 * index and NaNs cannot break the partition. The pivot is a median of three positions
 * drawn from a fixed-seed generator: deterministic and robust to sorted input.
 *
 * Queries: depth-first, nearer child first. The far child's lower bound is
 * off[0]^2 + off[1]^2 + off[2]^2, where off[a] is q's offset to the last splitting plane
 * on axis a that separates q from the cell (0 if none), computed with the same float
 * formula as point distances. It is exact as a bound: |fl(p - q)| is monotone in p, and
 * squaring and adding non-negative terms are monotone under rounding, so no point in the
 * cell can have a computed distance below it. A cell is skipped only when the bound is
 * strictly greater than the current limit (the radius, or the worst kept distance once
 * full), so equal-distance points with a lower index are never missed. */
#include "kdtree.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

enum { KD_LEAF = 8, KD_SMALL_K = 32, KD_SELECT_SMALL = 16 };

typedef struct KdNode {
    float p[3];
    uint32_t idx;
} KdNode;

/* ---------------------------------------------------------------- build */

static inline uint64_t kd_key(const KdNode *n, int axis) {
    uint32_t u;
    memcpy(&u, &n->p[axis], sizeof u);
    u ^= (uint32_t)((int32_t)u >> 31) | 0x80000000u; /* float order -> unsigned order */
    return ((uint64_t)u << 32) | n->idx;
}

static inline uint64_t kd_rand(uint64_t *s) { /* splitmix64 */
    uint64_t z = (*s += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

static inline void kd_swap(KdNode *a, size_t i, size_t j) {
    KdNode t = a[i];
    a[i] = a[j];
    a[j] = t;
}

/* Rearrange a[lo, hi) so a[nth] holds the element of that rank by key, smaller keys
 * before it and larger after (keys are unique thanks to the index). */
static void kd_select(KdNode *a, size_t lo, size_t hi, size_t nth, int axis, uint64_t *rng) {
    while (hi - lo > KD_SELECT_SMALL) {
        size_t n = hi - lo;
        uint64_t r = kd_rand(rng);
        size_t i0 = lo + (size_t)((r & 0xFFFFFFFFu) * n >> 32);
        size_t i1 = lo + (size_t)((r >> 32) * n >> 32);
        size_t i2 = lo + n / 2;
        uint64_t k0 = kd_key(&a[i0], axis), k1 = kd_key(&a[i1], axis), k2 = kd_key(&a[i2], axis);
        size_t pi; /* median of three */
        if (k0 < k1)
            pi = (k1 < k2) ? i1 : (k0 < k2 ? i2 : i0);
        else
            pi = (k0 < k2) ? i0 : (k1 < k2 ? i2 : i1);
        kd_swap(a, lo, pi);
        uint64_t pk = kd_key(&a[lo], axis);
        size_t i = lo, j = hi;
        for (;;) {
            do ++i; while (i < hi && kd_key(&a[i], axis) < pk);
            do --j; while (kd_key(&a[j], axis) > pk); /* stops at lo at the latest */
            if (i >= j) break;
            kd_swap(a, i, j);
        }
        kd_swap(a, lo, j); /* pivot now at its rank j */
        if (nth == j) return;
        if (nth < j)
            hi = j;
        else
            lo = j + 1;
    }
    for (size_t i = lo + 1; i < hi; ++i) { /* insertion sort the small remainder */
        KdNode t = a[i];
        uint64_t tk = kd_key(&t, axis);
        size_t j = i;
        while (j > lo && kd_key(&a[j - 1], axis) > tk) {
            a[j] = a[j - 1];
            --j;
        }
        a[j] = t;
    }
}

static void kd_build_rec(KdNode *a, uint8_t *axes, size_t lo, size_t hi, uint64_t *rng) {
    while (hi - lo > KD_LEAF) {
        float mn[3] = {INFINITY, INFINITY, INFINITY}, mx[3] = {-INFINITY, -INFINITY, -INFINITY};
        for (size_t i = lo; i < hi; ++i)
            for (int c = 0; c < 3; ++c) {
                float v = a[i].p[c];
                if (v < mn[c]) mn[c] = v;
                if (v > mx[c]) mx[c] = v;
            }
        int axis = 0;
        float ext = mx[0] - mn[0];
        for (int c = 1; c < 3; ++c)
            if (mx[c] - mn[c] > ext) {
                ext = mx[c] - mn[c];
                axis = c;
            }
        size_t mid = lo + (hi - lo) / 2;
        kd_select(a, lo, hi, mid, axis, rng);
        axes[mid] = (uint8_t)axis;
        kd_build_rec(a, axes, lo, mid, rng);
        lo = mid + 1;
    }
}

int kdtree_build(KdTree *tree, const float *points, uint32_t count) {
    memset(tree, 0, sizeof *tree);
    tree->points = points;
    if (count == 0) return 0;
    KdNode *nodes = malloc((size_t)count * sizeof *nodes);
    uint8_t *axes = calloc(count, 1);
    if (!nodes || !axes) {
        free(nodes);
        free(axes);
        tree->points = NULL;
        return -1;
    }
    for (uint32_t i = 0; i < count; ++i) {
        nodes[i].p[0] = points[3 * (size_t)i + 0];
        nodes[i].p[1] = points[3 * (size_t)i + 1];
        nodes[i].p[2] = points[3 * (size_t)i + 2];
        nodes[i].idx = i;
    }
    uint64_t rng = 0x6B64747265650001ull; /* fixed seed: deterministic layout */
    kd_build_rec(nodes, axes, 0, count, &rng);
    tree->count = count;
    tree->nodes = nodes;
    tree->axes = axes;
    tree->num_nodes = count;
    return 0;
}

void kdtree_free(KdTree *tree) {
    if (!tree) return;
    free(tree->nodes);
    free(tree->axes);
    free(tree->clear2);
    memset(tree, 0, sizeof *tree);
}

/* ---------------------------------------------------------------- queries */

static inline float kd_dist2(const float p[3], const float q[3]) {
    float dx = p[0] - q[0], dy = p[1] - q[1], dz = p[2] - q[2];
    return dx * dx + dy * dy + dz * dz;
}

typedef struct KdKnn {
    const KdNode *nodes;
    const uint8_t *axes;
    const float *points; /* caller's array, for distances when hd == NULL (heap mode) */
    float q[3];
    float off[3];        /* per-axis offset from q to the current cell (0: inside) */
    uint32_t k, n, exclude;
    float bound;         /* radius2 until k are kept, then the worst kept distance */
    float *hd;           /* kept distances (sorted mode: ascending; heap mode: max-heap) */
    uint32_t *hi;        /* kept indices */
    int heap;            /* 0: sorted mode, 1: heap mode */
} KdKnn;

/* ---- sorted mode (k <= KD_SMALL_K): arrays kept ascending by (d, index) */

static inline void kd_sorted_consider(KdKnn *r, const KdNode *nd) {
    float d = kd_dist2(nd->p, r->q);
    if (!(d <= r->bound)) return;
    uint32_t idx = nd->idx;
    if (idx == r->exclude) return;
    uint32_t j;
    if (r->n == r->k) {
        if (d == r->hd[r->k - 1] && idx > r->hi[r->k - 1]) return;
        j = r->k - 1;
    } else {
        j = r->n++;
    }
    while (j > 0 && (r->hd[j - 1] > d || (r->hd[j - 1] == d && r->hi[j - 1] > idx))) {
        r->hd[j] = r->hd[j - 1];
        r->hi[j] = r->hi[j - 1];
        --j;
    }
    r->hd[j] = d;
    r->hi[j] = idx;
    if (r->n == r->k) r->bound = r->hd[r->k - 1];
}


/* ---- heap mode (k > KD_SMALL_K): max-heap on (d, index) */

static inline float kd_hdist(const KdKnn *r, uint32_t j) {
    return r->hd ? r->hd[j] : kd_dist2(&r->points[3 * (size_t)r->hi[j]], r->q);
}

/* (da, ia) > (db, ib) */
static inline int kd_greater(float da, uint32_t ia, float db, uint32_t ib) {
    return da > db || (da == db && ia > ib);
}

static inline void kd_hset(KdKnn *r, uint32_t j, float d, uint32_t idx) {
    if (r->hd) r->hd[j] = d;
    r->hi[j] = idx;
}

static void kd_sift_down(KdKnn *r, uint32_t j, uint32_t n, float d, uint32_t idx) {
    for (;;) {
        uint32_t c = 2 * j + 1;
        if (c >= n) break;
        float dc = kd_hdist(r, c);
        if (c + 1 < n) {
            float d1 = kd_hdist(r, c + 1);
            if (kd_greater(d1, r->hi[c + 1], dc, r->hi[c])) {
                ++c;
                dc = d1;
            }
        }
        if (!kd_greater(dc, r->hi[c], d, idx)) break;
        kd_hset(r, j, dc, r->hi[c]);
        j = c;
    }
    kd_hset(r, j, d, idx);
}

static void kd_heap_consider(KdKnn *r, const KdNode *nd) {
    float d = kd_dist2(nd->p, r->q);
    if (!(d <= r->bound)) return;
    uint32_t idx = nd->idx;
    if (idx == r->exclude) return;
    if (r->n == r->k) {
        if (!kd_greater(r->bound, r->hi[0], d, idx)) return;
        kd_sift_down(r, 0, r->n, d, idx);
    } else {
        uint32_t j = r->n++;
        while (j > 0) {
            uint32_t p = (j - 1) / 2;
            float dp = kd_hdist(r, p);
            if (!kd_greater(d, idx, dp, r->hi[p])) break;
            kd_hset(r, j, dp, r->hi[p]);
            j = p;
        }
        kd_hset(r, j, d, idx);
    }
    if (r->n == r->k) r->bound = kd_hdist(r, 0);
}

/* The walk shared by every query, instantiated per query type (a macro rather than a
 * function taking the consider step, so that each instance is a direct recursive function
 * with its consider step inlined: the render-time 1-NN query pays for no indirection).
 * State is a struct with nodes, axes, q[3], off[3] and bound (the distance a cell must not
 * exceed to be visited); consider(r, node) offers one point and may lower r->bound.
 * Depth-first, near child first, then the splitting point, then the far child only if
 * q's offset to the far cell (off[], restored on the way out) does not exceed the bound. */
#define KD_DEFINE_WALK(name, State, consider)                                                        \
    static void name(State *r, size_t lo, size_t hi) {                                              \
        if (hi - lo > KD_LEAF) {                                                                    \
            size_t mid = lo + (hi - lo) / 2;                                                        \
            const KdNode *m = &r->nodes[mid];                                                       \
            int ax = r->axes[mid];                                                                  \
            float diff = r->q[ax] - m->p[ax];                                                       \
            size_t flo, fhi;                                                                        \
            if (diff < 0) {                                                                         \
                name(r, lo, mid);                                                                   \
                flo = mid + 1, fhi = hi;                                                            \
            } else {                                                                                \
                name(r, mid + 1, hi);                                                               \
                flo = lo, fhi = mid;                                                                \
            }                                                                                       \
            consider(r, m);                                                                         \
            float old = r->off[ax];                                                                 \
            r->off[ax] = diff;                                                                      \
            float rd = r->off[0] * r->off[0] + r->off[1] * r->off[1] + r->off[2] * r->off[2];       \
            if (!(rd > r->bound)) name(r, flo, fhi);                                                \
            r->off[ax] = old;                                                                       \
            return;                                                                                 \
        }                                                                                           \
        for (size_t i = lo; i < hi; ++i) consider(r, &r->nodes[i]);                                 \
    }

/* kNN: one instance for both modes (the mode test is one predictable branch per point). */
static inline void kd_consider(KdKnn *r, const KdNode *nd) {
    if (r->heap) kd_heap_consider(r, nd);
    else kd_sorted_consider(r, nd);
}

KD_DEFINE_WALK(kd_knn_rec, KdKnn, kd_consider)

uint32_t kdtree_knn(const KdTree *tree, const float q[3], uint32_t k, float radius2, uint32_t exclude,
                    uint32_t *indices, float *dist2) {
    if (!tree || tree->count == 0 || k == 0 || !(radius2 >= 0.0f)) return 0;
    uint32_t avail = tree->count - (exclude < tree->count ? 1u : 0u);
    if (k > avail) k = avail;
    if (k == 0) return 0;

    KdKnn r = {.nodes = tree->nodes, .axes = tree->axes, .points = tree->points,
               .q = {q[0], q[1], q[2]}, .k = k, .n = 0, .exclude = exclude, .bound = radius2};
    if (k <= KD_SMALL_K) {
        float d[KD_SMALL_K];
        uint32_t ix[KD_SMALL_K];
        r.hd = d;
        r.hi = ix;
        kd_knn_rec(&r, 0, tree->count);
        memcpy(indices, ix, r.n * sizeof *ix);
        if (dist2) memcpy(dist2, d, r.n * sizeof *d);
        return r.n;
    }

    float *owned = NULL;
    if (!dist2) owned = malloc((size_t)k * sizeof *owned); /* NULL: recompute distances */
    r.hd = dist2 ? dist2 : owned;
    r.hi = indices;
    r.heap = 1;
    kd_knn_rec(&r, 0, tree->count);
    for (uint32_t end = r.n; end > 1; --end) { /* heapsort into ascending order */
        float d = kd_hdist(&r, end - 1);
        uint32_t idx = r.hi[end - 1];
        kd_hset(&r, end - 1, kd_hdist(&r, 0), r.hi[0]);
        kd_sift_down(&r, 0, end - 1, d, idx);
    }
    free(owned);
    return r.n;
}

/* ---- 1-NN */

typedef struct KdNear {
    const KdNode *nodes;
    const uint8_t *axes;
    float q[3];
    float off[3];
    float bound;         /* the best distance so far */
    uint32_t best;       /* its index */
} KdNear;

static inline void kd_near_consider(KdNear *r, const KdNode *nd) {
    float d = kd_dist2(nd->p, r->q);
    if (d < r->bound || (d == r->bound && nd->idx < r->best)) {
        r->bound = d;
        r->best = nd->idx;
    }
}

KD_DEFINE_WALK(kd_near_rec, KdNear, kd_near_consider)

int kdtree_build_clearance(KdTree *tree) {
    if (!tree->count) return 0;
    float *c = malloc((size_t)tree->count * sizeof *c);
    if (!c) return -1;
    for (uint32_t i = 0; i < tree->count; ++i) {
        uint32_t nb;
        float d2 = 0.0f;
        const float *p = tree->points + 3 * (size_t)i;
        /* 0.2401 = 0.49^2: |q - p| < 0.49 nn gives |q - o| >= 0.51 nn for every other o */
        c[i] = p[0] == p[0] && p[1] == p[1] && p[2] == p[2] && kdtree_knn(tree, p, 1, INFINITY, i, &nb, &d2) == 1
                   ? 0.2401f * d2
                   : 0.0f;
    }
    tree->clear2 = c;
    return 0;
}

uint32_t kdtree_nearest(const KdTree *tree, const float q[3], float *dist2) {
    return kdtree_nearest_hint(tree, q, UINT32_MAX, dist2);
}

uint32_t kdtree_nearest_hint(const KdTree *tree, const float q[3], uint32_t hint, float *dist2) {
    KdNear r = {.nodes = tree ? tree->nodes : NULL, .axes = tree ? tree->axes : NULL,
                .q = {q[0], q[1], q[2]}, .bound = INFINITY, .best = UINT32_MAX};
    if (tree && hint < tree->count) { /* an upper bound that prunes; the answer is unchanged */
        float d = kd_dist2(tree->points + 3 * (size_t)hint, r.q);
        if (tree->clear2 && d < tree->clear2[hint]) { /* inside the hint's clearance: it is the nearest */
            if (dist2) *dist2 = d;
            return hint;
        }
        if (d <= INFINITY) { r.bound = d; r.best = hint; } /* (never a NaN point: those are never returned) */
    }
    if (tree && tree->count) kd_near_rec(&r, 0, tree->count);
    if (dist2) *dist2 = r.bound;
    return r.best;
}
