/* cachepoints/far_cut.c: light distributions from a cut through the scene's light tree
 * (beyond the paper: its answer to the §5.2.2 scaling failure, where the linear build of
 * §3.1.3 visits every light for every point).
 *
 * Near lights (Eq. 1) come from a range query on the tree. The far entries are a cut,
 * refined from the root by splitting the queued entry of largest estimate until cut_size
 * entries exist; nodes holding a near light are always split and near lights left out, so
 * near and far never overlap. A point's cost is O(cut_size log N) and every far light stays
 * reachable through some cluster. Keys are tree nodes (internal.h). */
#include <math.h>
#include <stdlib.h>

#include "build_internal.h"

/* Merge pass 2's omni distributions use cut_size / 4 entries (at least 32). */
#define CUT_PASS2_DIVISOR 4
#define CUT_PASS2_MIN 32

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

static void *scratch_new(const DistCtx *c) {
    (void)c;
    return calloc(1, sizeof(CutScratch)); /* the arrays grow on demand */
}

static void scratch_free(void *vs) {
    CutScratch *s = vs;
    if (!s) return;
    free(s->pool); free(s->heap); free(s->final); free(s->near_key);
    free(s);
}

static inline void sanitize7(float v[CP_FAR_BINS]) {
    for (int i = 0; i < CP_FAR_BINS; ++i) if (!(v[i] > 0.0f) || !isfinite(v[i])) v[i] = 0.0f;
}

static inline int any_positive7(const float v[CP_FAR_BINS]) {
    for (int i = 0; i < CP_FAR_BINS; ++i) if (v[i] > 0.0f) return 1;
    return 0;
}

static inline int heap_before(const CutScratch *s, HeapItem a, HeapItem b) {
    return a.priority > b.priority || (a.priority == b.priority && s->pool[a.entry].key < s->pool[b.entry].key);
}

static int heap_push(CutScratch *s, HeapItem it) {
    if (cp_grow((void **)&s->heap, &s->heap_cap, s->heap_count + 1, sizeof(HeapItem)) != 0) return -1;
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
    if (cp_grow((void **)&s->pool, &s->pool_cap, s->pool_count + 1, sizeof(FarEntry)) != 0) return -1;
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

static int cut_point(const DistCtx *c, void *vs, size_t i) {
    CutScratch *s = vs;
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
                if (L->infinite[light] || !(cp_dist2(L->centroid + 3 * (size_t)light, x) <= rn2)) continue;
                if (cp_grow((void **)&s->near_key, &s->near_cap, s->near_count + 1, sizeof(uint32_t)) != 0) return -1;
                s->near_key[s->near_count++] = node;
                continue;
            }
            if (top + 2 > sizeof stack / sizeof *stack) return -1; /* deeper than any tree we build */
            stack[top++] = T->second_child[node];
            stack[top++] = node + 1;
        }
    }
    uint32_t near_count = s->near_count;
    if (cp_dist_alloc_near(d, near_count < P->max_near ? near_count : P->max_near) != 0) return -1;
    if (near_count > P->max_near) {
        /* cap (CachePointParams.max_near): the strongest by fluence, ties by key; then back
         * in key order */
        ValueIndex *vi = malloc(near_count * sizeof *vi);
        uint64_t *keys = malloc(P->max_near * sizeof *keys);
        if (!vi || !keys) { free(vi); free(keys); return -1; }
        for (uint32_t k = 0; k < near_count; ++k) {
            vi[k].id = s->near_key[k];
            vi[k].v = L->estimate(L->user, K->key_light[vi[k].id], x, NULL);
        }
        cp_select_top(vi, near_count, P->max_near);
        for (uint32_t k = 0; k < P->max_near; ++k) keys[k] = vi[k].id;
        cp_sort_u64(keys, P->max_near);
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
            if (cp_grow((void **)&s->final, &s->final_cap, s->final_count + 1, sizeof(uint32_t)) != 0) return -1;
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
    cp_sort_by_key(order, order + m, m);
    for (uint32_t k = 0; k < m; ++k) sorted[k] = d->far[(uint32_t)order[k]];
    free(order);
    free(d->far);
    d->far = sorted;
    d->far_count = m;
    return 0;
}

const DistBuilder cp_far_cut = {scratch_new, scratch_free, cut_point};
