/* guiding/recorder.c: the radiance recorder (path-guiding-in-production.txt ch. 2 §3.4).
 *
 * Vertices live in blocks of RECORDER_BLOCK_SIZE allocated on first need, up to a bound;
 * free indices circulate through one stack under a mutex, which threads reach through a
 * small per-thread cache so that most allocations and frees touch no lock. A vertex's fields
 * are only touched by the thread that owns its path (the caller's contract), so they need no
 * atomics; the mutex hand-over of indices orders the reuse of a slot by another thread. */
#include <math.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

#include "guiding.h"

/* 128 bytes, on cache-line boundaries: indices circulate between threads, and two threads'
 * vertices on one line made the recorder three times as expensive on two threads as on one
 * (false sharing). */
typedef struct RecorderVertex {
    _Alignas(64) float pos[3];
    float dir[3];
    float throughput[3];
    float emission[3];  /* §3.4.1: accumulated emission of the subtree (throughput-weighted) */
    float pdf, bsdf_pdf, guide_pdf, cosine;
    uint32_t parent;
    uint32_t refcount;  /* 0: free */
    uint32_t flags;
    uint32_t user;
    uint64_t path;
} RecorderVertex;
_Static_assert(sizeof(RecorderVertex) == 128, "a vertex is two cache lines");

struct Recorder {
    pthread_mutex_t lock;
    RecorderVertex **blocks;
    uint32_t num_blocks, max_blocks;
    uint32_t *queue;               /* ring of free indices, capacity max_blocks * BLOCK_SIZE */
    uint32_t queue_head, queue_count;
    uint64_t created, refused;     /* under the lock (flushed from the caches' counts) */
    int64_t live;                  /* vertices allocated and not freed, as of the last flushes */
    int64_t batch_peak;
    uint32_t peak_live;
    uint32_t filter;               /* RECORDER_KEEP_* (0: every sample) */
};

#define BLOCK RECORDER_BLOCK_SIZE

static RecorderVertex *vertex_at(const Recorder *r, uint32_t pv) { return &r->blocks[pv / BLOCK][pv % BLOCK]; }

Recorder *recorder_create(uint32_t max_vertices) {
    Recorder *r = calloc(1, sizeof *r);
    if (!r) return NULL;
    uint64_t blocks = ((uint64_t)max_vertices + BLOCK - 1) / BLOCK;
    if (blocks == 0) blocks = 1;
    if (blocks * BLOCK >= PV_SKIPPED) blocks = (PV_SKIPPED - 1) / BLOCK; /* indices stay below the sentinels */
    r->max_blocks = (uint32_t)blocks;
    r->blocks = calloc(r->max_blocks, sizeof *r->blocks);
    r->queue = malloc((size_t)r->max_blocks * BLOCK * sizeof *r->queue);
    if (!r->blocks || !r->queue || pthread_mutex_init(&r->lock, NULL) != 0) {
        free(r->blocks);
        free(r->queue);
        free(r);
        return NULL;
    }
    return r;
}

void recorder_free(Recorder *r) {
    if (!r) return;
    for (uint32_t b = 0; b < r->num_blocks; ++b) free(r->blocks[b]);
    free(r->blocks);
    free(r->queue);
    pthread_mutex_destroy(&r->lock);
    free(r);
}

/* Under the lock: a new block's indices join the queue. 0 ok, -1 at the bound or out of memory. */
static int grow_locked(Recorder *r) {
    if (r->num_blocks >= r->max_blocks) return -1;
    RecorderVertex *block = aligned_alloc(64, BLOCK * sizeof *block);
    if (!block) return -1;
    memset(block, 0, BLOCK * sizeof *block);
    uint32_t b = r->num_blocks++;
    r->blocks[b] = block;
    uint32_t capacity = r->max_blocks * BLOCK;
    for (uint32_t i = 0; i < BLOCK; ++i) {
        r->queue[(r->queue_head + r->queue_count) % capacity] = b * BLOCK + i;
        r->queue_count++;
    }
    return 0;
}

/* Refills half of a thread's cache from the queue (growing by a block if it is empty), taking
 * the indices spilled last: the free indices are used as a stack, so the slots in use stay the
 * few thousand of the peak (about 1 MiB) instead of cycling through every slot ever allocated
 * (a first-in first-out queue walked guiding_interior's 76,000 slots, 9.7 MiB, past the L2). */
static void cache_refill(Recorder *r, RecorderCache *c) {
    pthread_mutex_lock(&r->lock);
    if (r->queue_count == 0) grow_locked(r);
    uint32_t capacity = r->max_blocks * BLOCK;
    while (c->count < RECORDER_CACHE_SIZE / 2 && r->queue_count > 0) {
        r->queue_count--;
        c->free[c->count++] = r->queue[(r->queue_head + r->queue_count) % capacity];
    }
    pthread_mutex_unlock(&r->lock);
}

/* Returns the cache's indices beyond `keep` to the queue. */
static void cache_spill(Recorder *r, RecorderCache *c, uint32_t keep) {
    pthread_mutex_lock(&r->lock);
    uint32_t capacity = r->max_blocks * BLOCK;
    while (c->count > keep) {
        r->queue[(r->queue_head + r->queue_count) % capacity] = c->free[--c->count];
        r->queue_count++;
    }
    pthread_mutex_unlock(&r->lock);
}

void recorder_flush_cache(Recorder *r, RecorderCache *c) {
    if (c->count) cache_spill(r, c, 0);
    pthread_mutex_lock(&r->lock);
    r->created += c->created;
    r->refused += c->refused;
    r->batch_peak += c->peak;
    r->live += c->live;
    pthread_mutex_unlock(&r->lock);
    c->created = c->refused = 0;
    c->peak = c->live; /* what it still holds */
    c->live = 0;
}

void recorder_end_batch(Recorder *r) {
    pthread_mutex_lock(&r->lock);
    if (r->batch_peak > (int64_t)r->peak_live) r->peak_live = (uint32_t)(r->batch_peak < UINT32_MAX ? r->batch_peak : UINT32_MAX);
    r->batch_peak = 0;
    pthread_mutex_unlock(&r->lock);
}

void recorder_set_filter(Recorder *r, uint32_t keep) { r->filter = keep; }

void recorder_prefetch(const Recorder *r, uint32_t pv) {
    if (pv_is_vertex(pv)) {
        const char *v = (const char *)vertex_at(r, pv);
        __builtin_prefetch(v, 1);
        __builtin_prefetch(v + 64, 1);
    }
}

void recorder_prefetch_parent(const Recorder *r, uint32_t pv) {
    if (pv_is_vertex(pv)) recorder_prefetch(r, vertex_at(r, pv)->parent);
}

void recorder_continue(Recorder *r, uint32_t pv) {
    if (pv_is_vertex(pv)) vertex_at(r, pv)->refcount++;
}

uint32_t recorder_new_child(Recorder *r, RecorderCache *c, uint32_t parent, const RecorderVertexInit *init) {
    if (parent == PV_SKIPPED) return PV_SKIPPED;
    if (c->count == 0) cache_refill(r, c);
    if (c->count == 0) {
        /* §3.4.4: the recorder is full: the ray carries its parent on, so its emission still
         * reaches the ancestors (the parent's sample then spans one more bounce) */
        c->refused++;
        recorder_continue(r, parent);
        return parent;
    }
    uint32_t pv = c->free[--c->count];
    /* the thread's next new vertex, for writing: a slot freed a wave or more ago, out of the
     * cache by then (the stores into it were recorder_new_child's stall) */
    if (c->count) recorder_prefetch(r, c->free[c->count - 1]);
    RecorderVertex *v = vertex_at(r, pv);
    memcpy(v->pos, init->pos, sizeof v->pos);
    memcpy(v->dir, init->dir, sizeof v->dir);
    memcpy(v->throughput, init->throughput, sizeof v->throughput);
    v->emission[0] = v->emission[1] = v->emission[2] = 0.0f;
    v->pdf = init->pdf;
    v->bsdf_pdf = init->bsdf_pdf;
    v->guide_pdf = init->guide_pdf;
    v->cosine = init->cosine;
    v->parent = parent;
    v->refcount = 1;
    v->flags = init->flags;
    v->user = init->user;
    v->path = init->path;
    if (pv_is_vertex(parent)) {
        RecorderVertex *pa = vertex_at(r, parent);
        pa->refcount++;
        if (init->flags & PV_FLAG_DELTA) pa->flags |= PV_FLAG_DELTA_CHILD;
    }
    c->created++;
    if (++c->live > c->peak) c->peak = c->live;
    return pv;
}

uint32_t recorder_fold_child(Recorder *r, RecorderCache *c, uint32_t parent) {
    if (parent == PV_SKIPPED) return PV_SKIPPED;
    recorder_continue(r, parent);
    c->created++;
    return parent;
}

void recorder_add_emission(Recorder *r, uint32_t pv, const float e[3]) {
    if (!pv_is_vertex(pv)) return;
    RecorderVertex *v = vertex_at(r, pv);
    for (int k = 0; k < 3; ++k) v->emission[k] += e[k];
}

static void samples_append(RecorderSamples *s, const RecorderVertex *v) {
    if (s->count == s->capacity) {
        size_t cap = s->capacity ? 2 * s->capacity : 1024;
        RecorderSample *items = realloc(s->items, cap * sizeof *items);
        if (!items) { s->failed = 1; return; }
        s->items = items;
        s->capacity = cap;
    }
    RecorderSample *o = &s->items[s->count++];
    memcpy(o->pos, v->pos, sizeof o->pos);
    memcpy(o->dir, v->dir, sizeof o->dir);
    for (int k = 0; k < 3; ++k) {
        /* §3.1: P_rad = P_em / P_tp per channel; a zero throughput channel carries nothing */
        float tp = v->throughput[k];
        o->radiance[k] = tp != 0.0f ? v->emission[k] / tp : 0.0f;
        o->debug[k] = o->radiance[k] * tp;
    }
    o->pdf = v->pdf;
    o->bsdf_pdf = v->bsdf_pdf;
    o->guide_pdf = v->guide_pdf;
    o->cosine = v->cosine;
    o->flags = v->flags | (v->parent == PV_CAMERA ? RECORDER_SAMPLE_PRIMARY : 0u);
    o->user = v->user;
    o->path = v->path;
}

void recorder_done(Recorder *r, RecorderCache *c, uint32_t pv, RecorderSamples *out) {
    /* §3.4.3 backprop, iteratively: a vertex whose count reaches zero records its one sample,
     * hands its emission to its parent, is freed, and the parent loses a holder */
    while (pv_is_vertex(pv)) {
        RecorderVertex *v = vertex_at(r, pv);
        if (v->refcount == 0) return; /* a caller's double release: ignore (recorder_consistent reports leaks) */
        if (--v->refcount > 0) return;
        uint32_t keep = r->filter;
        if (!keep || ((keep & RECORDER_KEEP_PRIMARY) && v->parent == PV_CAMERA) ||
            ((keep & RECORDER_KEEP_TRAINABLE) && !(v->flags & (PV_FLAG_NEE | PV_FLAG_DELTA))))
            samples_append(out, v);
        uint32_t parent = v->parent;
        if (pv_is_vertex(parent)) {
            RecorderVertex *pa = vertex_at(r, parent);
            for (int k = 0; k < 3; ++k) pa->emission[k] += v->emission[k];
        }
        if (c->count == RECORDER_CACHE_SIZE) cache_spill(r, c, RECORDER_CACHE_SIZE / 2);
        c->free[c->count++] = pv;
        c->live--; /* below zero only for a vertex another thread made: the sum stays right */
        pv = parent;
    }
}

void recorder_stats(const Recorder *r, RecorderStats *st) {
    Recorder *m = (Recorder *)r; /* the lock only */
    pthread_mutex_lock(&m->lock);
    st->vertices_created = r->created;
    st->vertices_refused = r->refused;
    st->bytes = (size_t)r->num_blocks * BLOCK * sizeof(RecorderVertex) + (size_t)r->max_blocks * BLOCK * sizeof(uint32_t);
    st->peak_bytes = st->bytes; /* blocks are kept until recorder_free */
    st->bound_bytes = (size_t)r->max_blocks * BLOCK * (sizeof(RecorderVertex) + sizeof(uint32_t));
    st->peak_live = r->peak_live;
    pthread_mutex_unlock(&m->lock);
}

void recorder_reset_counts(Recorder *r) {
    pthread_mutex_lock(&r->lock);
    r->created = r->refused = 0;
    pthread_mutex_unlock(&r->lock);
}

void recorder_restore_counts(Recorder *r, uint64_t vertices_created, uint64_t vertices_refused) {
    pthread_mutex_lock(&r->lock);
    r->created = vertices_created;
    r->refused = vertices_refused;
    pthread_mutex_unlock(&r->lock);
}

int recorder_consistent(const Recorder *r) {
    uint32_t n = r->num_blocks * BLOCK;
    if (r->live != 0 || r->queue_count != n) return 0;
    uint8_t *seen = calloc(n ? n : 1, 1);
    if (!seen) return 0;
    uint32_t capacity = r->max_blocks * BLOCK;
    int ok = 1;
    for (uint32_t i = 0; i < r->queue_count && ok; ++i) {
        uint32_t pv = r->queue[(r->queue_head + i) % capacity];
        if (pv >= n || seen[pv] || vertex_at(r, pv)->refcount != 0) ok = 0;
        else seen[pv] = 1;
    }
    free(seen);
    return ok;
}

void recorder_samples_clear(RecorderSamples *s) {
    s->count = 0;
    s->failed = 0;
}

void recorder_samples_free(RecorderSamples *s) {
    free(s->items);
    s->items = NULL;
    s->count = s->capacity = 0;
}

/* The stable merge sort by path: the fallback when the keys do not fit the radix sort's. */
static int samples_merge_sort(RecorderSamples *s) {
    size_t n = s->count;
    RecorderSample *tmp = malloc(n * sizeof *tmp);
    if (!tmp) return -1;
    RecorderSample *src = s->items, *dst = tmp;
    for (size_t width = 1; width < n; width *= 2) {
        for (size_t lo = 0; lo < n; lo += 2 * width) {
            size_t mid = lo + width < n ? lo + width : n, hi = lo + 2 * width < n ? lo + 2 * width : n;
            size_t i = lo, j = mid, k = lo;
            while (i < mid && j < hi) dst[k++] = src[j].path < src[i].path ? src[j++] : src[i++];
            while (i < mid) dst[k++] = src[i++];
            while (j < hi) dst[k++] = src[j++];
        }
        RecorderSample *t = src;
        src = dst;
        dst = t;
    }
    if (src != s->items) memcpy(s->items, src, n * sizeof *tmp);
    free(tmp);
    return 0;
}

int recorder_samples_sort(RecorderSamples *s) {
    /* Stable by path index: a path's samples keep their (deterministic) order. A slice's paths
     * are a narrow range of indices, so the sort is an LSD radix sort of 64-bit keys (the path's
     * offset from the smallest above, the sample's position below: ties keep their order) over
     * the key bytes that vary, then one gather of the 80-byte samples; the merge sort moved
     * every sample log2(n) times (its passes were 9% of a guided render's instructions on the
     * interior at 320x240). */
    size_t n = s->count;
    if (n < 2) return 0;
    uint64_t lo = s->items[0].path, hi = lo;
    int sorted = 1;
    for (size_t i = 1; i < n; ++i) {
        uint64_t p = s->items[i].path;
        sorted &= p >= s->items[i - 1].path;
        lo = p < lo ? p : lo;
        hi = p > hi ? p : hi;
    }
    if (sorted) return 0;
    if (hi - lo >= (1ull << 32) || n >= (1ull << 32)) return samples_merge_sort(s);
    uint64_t *keys = malloc(2 * n * sizeof *keys);
    RecorderSample *out = malloc(n * sizeof *out);
    if (!keys || !out) {
        free(keys);
        free(out);
        return -1;
    }
    uint64_t *a = keys, *b = keys + n;
    for (size_t i = 0; i < n; ++i) a[i] = (s->items[i].path - lo) << 32 | (uint64_t)i;
    for (int shift = 32; shift < 64 && ((hi - lo) >> (shift - 32)) != 0; shift += 8) {
        size_t count[257] = {0};
        for (size_t i = 0; i < n; ++i) count[((a[i] >> shift) & 0xFF) + 1]++;
        for (int d = 0; d < 256; ++d) count[d + 1] += count[d];
        for (size_t i = 0; i < n; ++i) b[count[(a[i] >> shift) & 0xFF]++] = a[i];
        uint64_t *t = a;
        a = b;
        b = t;
    }
    for (size_t i = 0; i < n; ++i) out[i] = s->items[a[i] & 0xFFFFFFFFu];
    free(keys);
    free(s->items);
    s->items = out;
    s->capacity = n;
    return 0;
}
