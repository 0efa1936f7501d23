/* tests/test_recorder.c: the radiance recorder (guiding/guiding.h).
 *
 * (a) The worked example of path-guiding-in-production.txt ch. 2 §3.2 (Figs. 3-4): exact
 *     recorded values and order (the seed's depth-first listing has `P3_em += e2`, a typo for e4;
 *     the digest §1.2 and §5 item 17); (b) the sentinels: a skipped path never allocates, a full
 *     recorder continues the parent; (c) random path trees on 1 and 2 threads record the same
 *     sorted samples, and every index is back in the free queue after each round. */
#include <math.h>
#include <pthread.h>
#include <string.h>

#include "check.h"
#include "guiding.h"

static RecorderVertexInit vinit(float tp, uint32_t flags, uint64_t path) {
    RecorderVertexInit v = {{0, 0, 0}, {0, 0, 1}, {tp, 2.0f * tp, 0.5f * tp}, 1.0f, 1.0f, 0.0f, 1.0f, flags, 0, path};
    return v;
}

static uint32_t child(Recorder *r, RecorderCache *c, uint32_t parent, float tp, uint32_t flags, uint64_t path) {
    RecorderVertexInit init = vinit(tp, flags, path);
    return recorder_new_child(r, c, parent, &init);
}

static void emit(Recorder *r, uint32_t pv, float e) {
    const float c[3] = {e, 2.0f * e, 0.5f * e};
    recorder_add_emission(r, pv, c);
}

/* The sample of a vertex: channel 0 of L, and L x tp (the recorder-debug splat). */
static void check_sample(const RecorderSample *s, float em, float tp, uint32_t nee, int primary, const char *name) {
    CHECK(fabsf(s->radiance[0] - em / tp) <= 1e-6f * (em / tp), "%s: L %g, expected %g", name, s->radiance[0], em / tp);
    /* channel 1 has twice the emission over twice the throughput: the same L */
    CHECK(fabsf(s->radiance[1] - em / tp) <= 1e-6f * (em / tp), "%s: L.g %g", name, s->radiance[1]);
    CHECK(fabsf(s->debug[0] - em) <= 1e-6f * em, "%s: debug %g, expected %g", name, s->debug[0], em);
    CHECK((s->flags & PV_FLAG_NEE) == nee, "%s: NEE flag %u", name, s->flags);
    CHECK(!!(s->flags & RECORDER_SAMPLE_PRIMARY) == primary, "%s: primary flag %u", name, s->flags);
}

static void test_worked_example(void) {
    Recorder *r = recorder_create(RECORDER_BLOCK_SIZE);
    RecorderCache c = {0};
    RecorderSamples out = {0};
    const RecorderVertexInit zero = {0};
    const float e[9] = {0, 1.0f, 2.0f, 4.0f, 8.0f, 16.0f, 32.0f, 64.0f, 128.0f}; /* e1..e8: distinct bits */
    const float tp[6] = {0.5f, 0.25f, 0.125f, 0.0625f, 0.03125f, 0.015625f};     /* P0..P5 */
    /* wave 0: the camera ray hits x1, which spawns P0 (continuation) and P1 (NEE) */
    uint32_t P0 = recorder_new_child(r, &c, PV_CAMERA, &zero);
    recorder_done(r, &c, P0, &out); /* a vertex released at once records (zero) and frees */
    CHECK(out.count == 1 && out.items[0].radiance[0] == 0.0f, "a lone vertex records one zero sample");
    recorder_samples_clear(&out);
    P0 = child(r, &c, PV_CAMERA, tp[0], 0, 7);
    uint32_t P1 = child(r, &c, PV_CAMERA, tp[1], PV_FLAG_NEE, 7);
    /* wave 1: P0 hits x2: children P2 (continuation), P3 (NEE); P0 done. P1 passes the virtual
     * light Q1: e1, continue, done. */
    uint32_t P2 = child(r, &c, P0, tp[2], 0, 7);
    uint32_t P3 = child(r, &c, P0, tp[3], PV_FLAG_NEE, 7);
    recorder_done(r, &c, P0, &out);
    emit(r, P1, e[1]);
    recorder_continue(r, P1);
    recorder_done(r, &c, P1, &out);
    CHECK(out.count == 0, "nothing recorded after wave 1 (%zu)", out.count);
    /* wave 2: P1 passes Q2: e2, done -> records (e1 + e2) / P1_tp. P2 hits x3: P4, P5; P2 done.
     * P3 passes Q3: e3, continue, done. */
    emit(r, P1, e[2]);
    recorder_done(r, &c, P1, &out);
    CHECK(out.count == 1, "wave 2 records P1 (%zu)", out.count);
    if (out.count == 1) check_sample(&out.items[0], e[1] + e[2], tp[1], PV_FLAG_NEE, 1, "P1");
    uint32_t P4 = child(r, &c, P2, tp[4], 0, 7);
    uint32_t P5 = child(r, &c, P2, tp[5], PV_FLAG_NEE, 7);
    recorder_done(r, &c, P2, &out);
    emit(r, P3, e[3]);
    recorder_continue(r, P3);
    recorder_done(r, &c, P3, &out);
    /* wave 3: P3 reaches its light: e4, done -> (e3 + e4) / P3_tp (the seed's listing says e2:
     * a typo). P4 escapes to an emitter: e5, done -> e5 / P4_tp. P5 passes Q6, Q7. */
    emit(r, P3, e[4]);
    recorder_done(r, &c, P3, &out);
    emit(r, P4, e[5]);
    recorder_done(r, &c, P4, &out);
    emit(r, P5, e[6]);
    recorder_continue(r, P5);
    recorder_done(r, &c, P5, &out);
    emit(r, P5, e[7]);
    recorder_continue(r, P5);
    recorder_done(r, &c, P5, &out);
    CHECK(out.count == 3, "waves 3-4 record P3 and P4 (%zu)", out.count);
    /* wave 5: P5 ends with e8 -> P5, then P2 (cascade), then P0 */
    emit(r, P5, e[8]);
    recorder_done(r, &c, P5, &out);
    CHECK(out.count == 6, "six samples in all (%zu)", out.count);
    if (out.count == 6) {
        check_sample(&out.items[1], e[3] + e[4], tp[3], PV_FLAG_NEE, 0, "P3");
        check_sample(&out.items[2], e[5], tp[4], 0, 0, "P4");
        check_sample(&out.items[3], e[6] + e[7] + e[8], tp[5], PV_FLAG_NEE, 0, "P5");
        check_sample(&out.items[4], e[5] + e[6] + e[7] + e[8], tp[2], 0, 0, "P2");
        check_sample(&out.items[5], e[3] + e[4] + e[5] + e[6] + e[7] + e[8], tp[0], 0, 1, "P0");
    }
    recorder_flush_cache(r, &c);
    recorder_end_batch(r);
    CHECK(recorder_consistent(r), "every index back in the free queue after the example");
    RecorderStats st;
    recorder_stats(r, &st);
    CHECK(st.vertices_created == 7 && st.peak_live == 5, "created %llu peak %u", (unsigned long long)st.vertices_created,
          st.peak_live);
    recorder_samples_free(&out);
    recorder_free(r);
}

static void test_sentinels(void) {
    Recorder *r = recorder_create(1); /* one block */
    RecorderCache c = {0};
    RecorderSamples out = {0};
    RecorderVertexInit init = vinit(1.0f, 0, 1);
    RecorderStats st;
    recorder_stats(r, &st);
    size_t empty_bytes = st.bytes;
    uint32_t s = recorder_new_child(r, &c, PV_SKIPPED, &init);
    CHECK(s == PV_SKIPPED, "a skipped path's child is skipped");
    emit(r, s, 1.0f);
    recorder_done(r, &c, s, &out);
    recorder_stats(r, &st);
    CHECK(st.vertices_created == 0 && st.bytes == empty_bytes && out.count == 0, "a skipped path never allocates");
    /* fill the block with a chain, then one more child continues its parent */
    uint32_t chain[RECORDER_BLOCK_SIZE], parent = PV_CAMERA;
    for (uint32_t i = 0; i < RECORDER_BLOCK_SIZE; ++i) parent = chain[i] = recorder_new_child(r, &c, parent, &init);
    uint32_t extra = recorder_new_child(r, &c, parent, &init);
    CHECK(extra == parent, "a full recorder continues the parent (%u vs %u)", extra, parent);
    emit(r, extra, 3.0f);
    recorder_done(r, &c, extra, &out);
    CHECK(out.count == 0, "the continued parent still has a holder");
    for (uint32_t i = RECORDER_BLOCK_SIZE; i-- > 0;) recorder_done(r, &c, chain[i], &out);
    CHECK(out.count == RECORDER_BLOCK_SIZE, "the chain records every vertex once (%zu)", out.count);
    CHECK(out.count && out.items[out.count - 1].debug[0] == 3.0f, "the emission reached the root");
    recorder_flush_cache(r, &c);
    recorder_stats(r, &st);
    CHECK(st.vertices_refused == 1 && st.bound_bytes >= st.bytes, "refused %llu",
          (unsigned long long)st.vertices_refused);
    CHECK(recorder_consistent(r), "consistent after the chain");
    recorder_samples_free(&out);
    recorder_free(r);
}

/* ---- random path trees on threads: the sorted samples never depend on the thread count */

static uint64_t splitmix(uint64_t *x) {
    uint64_t z = (*x += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

typedef struct Job {
    Recorder *r;
    uint64_t first, count;
    RecorderSamples out;
} Job;

/* A path in the wavefront's shape: each bounce may add emission, spawns an NEE child (which
 * gets emission and ends at once) and a continuation, then releases the incoming vertex. */
static void run_path(Recorder *r, RecorderCache *c, uint64_t path, RecorderSamples *out) {
    uint64_t rng = path * 7919u + 1;
    uint32_t pv = PV_CAMERA;
    int depth = 1 + (int)(splitmix(&rng) % 12);
    for (int d = 0; d < depth; ++d) {
        if (splitmix(&rng) % 3 == 0) emit(r, pv, (float)(splitmix(&rng) % 100) * 0.01f);
        RecorderVertexInit nee = vinit(0.5f + (float)(splitmix(&rng) % 100) * 0.01f, PV_FLAG_NEE, path);
        uint32_t n = recorder_new_child(r, c, pv, &nee);
        emit(r, n, (float)(splitmix(&rng) % 100) * 0.01f);
        recorder_done(r, c, n, out);
        RecorderVertexInit cont = vinit(0.25f + (float)(splitmix(&rng) % 100) * 0.01f, 0, path);
        uint32_t next = recorder_new_child(r, c, pv, &cont);
        if (pv != PV_CAMERA) recorder_done(r, c, pv, out);
        pv = next;
    }
    emit(r, pv, 1.0f);
    recorder_done(r, c, pv, out);
}

static void *run_job(void *arg) {
    Job *j = arg;
    RecorderCache c = {0};
    /* the paths of a job advance together, bounce by bounce, like a slice's waves: here simply
     * interleaved in pairs to mix their vertices in the blocks */
    for (uint64_t p = j->first; p < j->first + j->count; ++p) run_path(j->r, &c, p, &j->out);
    recorder_flush_cache(j->r, &c);
    return NULL;
}

static int run_threads(Recorder *r, int threads, uint64_t paths, RecorderSamples *all) {
    Job jobs[4];
    pthread_t tid[4];
    for (int t = 0; t < threads; ++t) {
        jobs[t] = (Job){r, paths * (uint64_t)t / (uint64_t)threads,
                        paths * (uint64_t)(t + 1) / (uint64_t)threads - paths * (uint64_t)t / (uint64_t)threads, {0}};
        pthread_create(&tid[t], NULL, run_job, &jobs[t]);
    }
    all->count = 0;
    for (int t = 0; t < threads; ++t) pthread_join(tid[t], NULL);
    recorder_end_batch(r);
    for (int t = 0; t < threads; ++t) { /* concatenated in reverse order: the sort must fix it */
        Job *j = &jobs[threads - 1 - t];
        for (size_t i = 0; i < j->out.count; ++i) {
            if (all->count == all->capacity) {
                all->capacity = all->capacity ? 2 * all->capacity : 4096;
                all->items = realloc(all->items, all->capacity * sizeof *all->items);
            }
            all->items[all->count++] = j->out.items[i];
        }
        recorder_samples_free(&j->out);
    }
    return recorder_samples_sort(all);
}

static void test_threads(void) {
    Recorder *r = recorder_create(1u << 16);
    RecorderSamples one = {0}, two = {0};
    CHECK(run_threads(r, 1, 20000, &one) == 0, "sort");
    CHECK(recorder_consistent(r), "consistent after the 1-thread round");
    CHECK(run_threads(r, 2, 20000, &two) == 0, "sort");
    CHECK(recorder_consistent(r), "consistent after the 2-thread round");
    CHECK(one.count == two.count && one.count > 20000, "sample counts %zu vs %zu", one.count, two.count);
    int same = one.count == two.count;
    for (size_t i = 0; same && i < one.count; ++i)
        same = one.items[i].path == two.items[i].path && memcmp(one.items[i].radiance, two.items[i].radiance, 12) == 0 &&
               one.items[i].flags == two.items[i].flags;
    CHECK(same, "1 and 2 threads record the same sorted samples");
    for (size_t i = 1; i < one.count; ++i)
        if (one.items[i].path < one.items[i - 1].path) { CHECK(0, "not sorted at %zu", i); break; }
    /* the filter: only the samples asked for, the same ones */
    RecorderSamples kept = {0};
    recorder_set_filter(r, RECORDER_KEEP_PRIMARY);
    CHECK(run_threads(r, 2, 20000, &kept) == 0, "sort");
    size_t primary = 0;
    for (size_t i = 0; i < one.count; ++i) primary += !!(one.items[i].flags & RECORDER_SAMPLE_PRIMARY);
    int all_primary = kept.count == primary;
    for (size_t i = 0; all_primary && i < kept.count; ++i) all_primary = !!(kept.items[i].flags & RECORDER_SAMPLE_PRIMARY);
    CHECK(all_primary && primary > 0, "the primary filter keeps the %zu primary samples (%zu)", primary, kept.count);
    CHECK(recorder_consistent(r), "consistent after the filtered round");
    recorder_samples_free(&kept);
    recorder_samples_free(&one);
    recorder_samples_free(&two);
    recorder_free(r);
}

/* ---- the sort by path is stable, for narrow (radix) and wide (merge) ranges of path indices */
static void check_stable_sort(uint64_t stride) {
    RecorderSamples s = {0};
    size_t n = 5000;
    s.items = calloc(n, sizeof *s.items);
    s.capacity = n;
    CHECK(s.items != NULL, "allocation");
    if (!s.items) return;
    uint64_t x = 12345;
    for (size_t i = 0; i < n; ++i) {
        x = x * 6364136223846793005ull + 1442695040888963407ull;
        s.items[i].path = 1000 + ((x >> 33) % 300) * stride; /* many samples per path, out of order */
        s.items[i].user = (uint32_t)i;                       /* the original position */
    }
    s.count = n;
    CHECK(recorder_samples_sort(&s) == 0, "sort");
    int ok = s.count == n;
    for (size_t i = 1; i < s.count && ok; ++i) {
        const RecorderSample *a = &s.items[i - 1], *b = &s.items[i];
        ok = a->path < b->path || (a->path == b->path && a->user < b->user);
    }
    CHECK(ok, "sorted by path, a path's samples in their order (stride %llu)", (unsigned long long)stride);
    recorder_samples_free(&s);
}

int main(void) {
    check_stable_sort(1);
    check_stable_sort(1000003);
    check_stable_sort(1ull << 40); /* beyond the radix keys: the merge sort */
    test_worked_example();
    test_sentinels();
    test_threads();
    return test_exit();
}
