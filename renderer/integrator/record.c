/* renderer/integrator/record.c: the radiance recorder in the wavefront (guiding/guiding.h; the seed's
 * ch. 2 §3.4, the digest's §1.2-1.3).
 *
 * Every ray of a path carries a PVIndex in the path state: `pv` for the ray the path traces
 * (its vertex collects what that ray finds: emission, the environment, volume emission along
 * it), `shadow_pv` for the NEE shadow ray pending in the same slot. A scattering event (a
 * surface or medium vertex) creates children for its NEE and continuation rays and then
 * releases the incoming ray's vertex (record_done); a path that ends releases its ray's vertex
 * where it ends. The camera ray's vertex is PV_CAMERA: what it finds directly (emission seen
 * by the camera, in-scattering along the camera segment) belongs to no vertex.
 *
 * Memory control (§3.4.4, §5.1): path skipping decided per camera ray from the previous
 * iteration's mean vertices per recorded path against a budget (4: skip = 1 - budget x
 * paths / vertices), a vertex past the budget recorded with probability 1/4 (else the ray
 * continues its parent, so the emission still reaches the ancestors), a child closer than a
 * minimum distance to its parent continues the parent, and the recorder's bound
 * (--recorder-mb). All decisions hash the path's RNG key: the recorded samples, hence what
 * guiding learns, never depend on the thread count. Samples go to per-slice buffers, are sorted
 * by path after the batch (recorder_samples_sort: stable, so a path keeps its order), and
 * handed on in that order. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "ckpt_io.h"
#include "feature.h"
#include "rng.h"
#include "record.h"

#define RECORD_BUDGET_DEFAULT 4         /* vertices per path (the seed's soft budget) */
#define RECORD_DEEP_PROBABILITY 0.25f   /* a vertex past the budget is recorded with this (§5.1.3) */
#define RECORD_MIN_DISTANCE_REL 1e-4f   /* of the scene's diagonal: closer children continue the parent */

static float hash_uniform(uint64_t key, uint64_t salt) {
    return (float)(rng_mix64(key ^ rng_mix64(salt + 0x5265636f72646572ull)) >> 40) * 0x1.0p-24f;
}

static int record_init(Integrator *ig) {
    const CandelaOptions *o = ig->opt;
    RecordState *rs = &ig->record;
    memset(rs, 0, sizeof *rs);
    int need = o->aov_recorder_debug || o->guiding != CANDELA_GUIDING_OFF;
    if (!need) return 0;
    size_t mb = o->recorder_mb ? o->recorder_mb : 256;
    uint64_t vertices = (uint64_t)mb * 1024u * 1024u / 132u; /* 128 bytes per vertex and its queue entry */
    if (vertices > 0xF0000000ull) vertices = 0xF0000000ull;
    rs->recorder = recorder_create((uint32_t)vertices);
    if (!rs->recorder) return -1;
    rs->debug_aov = o->aov_recorder_debug;
    rs->active = 1; /* auto records during its probe too: if it chooses guiding, its fields trained from the first sample, as mis's (guide.c) */
    /* guiding trains on the first samples (at least its 8 + 2 + 4 + 8 spp), then renders with
     * the fields as learned: the recorder's cost is not paid on the rest. How many: about 2^21
     * training paths, but no less than an eighth of the samples and no more than a fifth. The
     * guide's quality follows the paths it learned from, its cost the spp it records: at 256
     * spp, training to the 54-spp barrier instead of 38 took relMSE x time 4% lower on the box at
     * 192x192 (relMSE 0.93x, time 1.04x alternated) and better at 128x128, but 5% higher on
     * guiding_interior at 640x480 (relMSE 0.97x, time 1.08x), whose 38 spp are 12M paths
     * already (scenes/RESULTS.md, "Guided time and the bootstrap") */
    rs->training_spp = o->guide_training_spp;
    if (rs->training_spp <= 0) {
        uint64_t lo = (uint64_t)o->spp / 8, hi = (uint64_t)o->spp / 5;
        uint64_t want = ig->npixels ? ((1ull << 21) + ig->npixels - 1) / ig->npixels : hi;
        uint64_t t = want < lo ? lo : want > hi ? hi : want;
        rs->training_spp = t > 22 ? (int)t : 22;
    }
    /* only the samples something reads: the AOV's primary ones, guiding's trainable ones */
    recorder_set_filter(rs->recorder, (rs->debug_aov ? RECORDER_KEEP_PRIMARY : 0u) |
                                          (o->guiding != CANDELA_GUIDING_OFF ? RECORDER_KEEP_TRAINABLE : 0u));
    rs->budget = o->recorder_budget >= 0 ? (uint32_t)o->recorder_budget : RECORD_BUDGET_DEFAULT;
    rs->path_skip = 0.0f;
    vec3 ext = v3_sub(ig->scene->bounds_max, ig->scene->bounds_min);
    float diag = v3_length(ext);
    rs->min_distance = isfinite(diag) ? RECORD_MIN_DISTANCE_REL * diag : 0.0f;
    if (rs->debug_aov) { /* the film's recorder-debug AOV */
        ig->film.recorder = calloc(3 * (size_t)ig->npixels, sizeof(double));
        if (!ig->film.recorder) return -1;
    }
    return 0;
}

static void record_free(Integrator *ig) {
    RecordState *rs = &ig->record;
    for (int k = 0; k < MAX_SLICES; ++k) recorder_samples_free(&rs->samples[k].s);
    recorder_free(rs->recorder);
    rs->recorder = NULL;
}

void record_camera(const Integrator *ig, uint32_t p, uint64_t path) {
    const PathState *ps = &ig->ps;
    ps->pv[p] = PV_CAMERA;
    ps->shadow_pv[p] = PV_CAMERA;
    ps->aov_recorder[p] = v3s(0.0f);
    const RecordState *rs = &ig->record;
    ps->record_skip[p] = rs->active && rs->path_skip > 0.0f && hash_uniform(ps->rng_key[p], 1) < rs->path_skip;
    (void)path;
}

uint32_t record_child(const Integrator *ig, Slice *s, uint32_t p, uint32_t parent, vec3 pos, vec3 dir, vec3 tp,
                      float pdf, float scatter_pdf, float guide_pdf, float cosine, uint32_t flags, float segment,
                      const GuideDistribution *guide) {
    const RecordState *rs = &ig->record;
    const PathState *ps = &ig->ps;
    if (parent == PV_SKIPPED || (parent == PV_CAMERA && ps->record_skip[p])) return PV_SKIPPED;
    uint32_t depth = ps->depth[p];
    /* §3.4.4: a child too close to its parent (dense media), or past the budget and not drawn
     * for recording (§5.1.3), continues its parent; the camera's children always start a vertex */
    if (parent != PV_CAMERA) {
        int keep = segment >= rs->min_distance;
        if (keep && rs->budget > 0 && depth >= rs->budget)
            keep = hash_uniform(ps->rng_key[p], 2 + 2 * (uint64_t)depth + ((flags & PV_FLAG_NEE) ? 1 : 0)) <
                   RECORD_DEEP_PROBABILITY;
        if (!keep) {
            recorder_continue(rs->recorder, parent);
            return parent;
        }
    }
    /* an NEE vertex's own sample is read only by the debug AOV (a primary one); without it, its
     * ray carries its parent's vertex and adds its light there (recorder_fold_child): the same
     * sums in the same order (the child's one addition, 0 + c, was handed up unchanged), one
     * vertex allocation and release fewer per shadow ray (a third of a training spp's vertices
     * on cornell_indirect) */
    if (!rs->debug_aov && (flags & PV_FLAG_NEE)) return recorder_fold_child(rs->recorder, &s->record_cache, parent);
    RecorderVertexInit init = {{pos.x, pos.y, pos.z}, {dir.x, dir.y, dir.z}, {tp.x, tp.y, tp.z}, pdf, scatter_pdf, guide_pdf,
                               cosine, flags, guide_leaf_hint(ig, flags, guide),
                               (ig->sample_base + (ig->batch_first + p) / ig->iteration_pixels) * ig->npixels + ps->pixel[p]};
    return recorder_new_child(rs->recorder, &s->record_cache, parent, &init);
}

void record_done(const Integrator *ig, Slice *s, uint32_t p, uint32_t pv) {
    if (!pv_is_vertex(pv)) return;
    const RecordState *rs = &ig->record;
    RecorderSamples *out = s->record_samples;
    size_t before = out->count;
    recorder_done(rs->recorder, &s->record_cache, pv, out);
    if (!rs->debug_aov) return;
    /* §4.1: the primary vertices' samples times their throughput rebuild the image (divided by
     * the probability the path was recorded) */
    const PathState *ps = &ig->ps;
    float inv = 1.0f / (1.0f - rs->path_skip);
    for (size_t i = before; i < out->count; ++i) {
        const RecorderSample *smp = &out->items[i];
        if (!(smp->flags & RECORDER_SAMPLE_PRIMARY)) continue;
        ps->aov_recorder[p] = v3_add(ps->aov_recorder[p], v3_scale(v3(smp->debug[0], smp->debug[1], smp->debug[2]), inv));
    }
}

void record_radiance(const Integrator *ig, uint32_t p, vec3 c, RadianceSource source) {
    const PathState *ps = &ig->ps;
    uint32_t target = source == RADIANCE_DIRECT ? ps->shadow_pv[p] : ps->pv[p];
    if (target == PV_CAMERA) {
        /* found by the camera ray itself, or by no recorded vertex: exact in the debug AOV */
        ps->aov_recorder[p] = v3_add(ps->aov_recorder[p], c);
        return;
    }
    const float e[3] = {c.x, c.y, c.z};
    recorder_add_emission(ig->record.recorder, target, e);
}

typedef struct SortCtx {
    RecordState *rs;
    int failed[MAX_SLICES];
} SortCtx;

static void sort_slices(void *ctx, size_t begin, size_t end, int thread_index) {
    (void)thread_index;
    SortCtx *c = ctx;
    for (size_t k = begin; k < end; ++k)
        if (recorder_samples_sort(&c->rs->samples[k].s) != 0) c->failed[k] = 1;
}

static void record_batch_end(Integrator *ig, Slice *slices, uint32_t n) {
    RecordState *rs = &ig->record;
    if (!rs->active) return;
    for (uint32_t k = 0; k < n; ++k) recorder_flush_cache(rs->recorder, &slices[k].record_cache);
    recorder_end_batch(rs->recorder);
    /* Slice k holds the paths [begin_k, end_k), contiguous and in slice order: every slice's
     * samples sorted by path (stable, on the threads) are, in slice order, the stable sort of
     * the batch's; guiding reads them so (guide.c), with no serial sort or copy of them all. */
    SortCtx sc = {rs, {0}};
    if (ig->pool && n > 1) threadpool_parallel_for(ig->pool, n, 1, sort_slices, &sc);
    else sort_slices(&sc, 0, n, 0);
    size_t total = 0;
    for (uint32_t k = 0; k < n; ++k) {
        /* a slice whose buffer or sort ran out of memory: its samples are dropped, not trained out of order */
        if (sc.failed[k] || rs->samples[k].s.failed) {
            rs->dropped = 1;
            recorder_samples_clear(&rs->samples[k].s);
        }
        total += rs->samples[k].s.count;
    }
    rs->batch_slices = n;
    /* recorded paths of the batch, for the next iteration's path skipping */
    uint32_t recorded = 0;
    for (uint32_t p = 0; p < ig->batch_count; ++p) recorded += !ig->ps.record_skip[p];
    rs->iteration_paths += recorded;
    rs->iteration_samples += total;
}

void record_drop_batch(Integrator *ig) {
    RecordState *rs = &ig->record;
    for (uint32_t k = 0; k < rs->batch_slices; ++k) recorder_samples_clear(&rs->samples[k].s);
    rs->batch_slices = 0;
}

static void record_barrier(Integrator *ig) {
    RecordState *rs = &ig->record;
    if (!rs->recorder) return;
    RecorderStats st;
    recorder_stats(rs->recorder, &st);
    /* §3.4.4: skip = 1 - budget x paths / vertices of the iteration just done */
    if (rs->budget > 0 && st.vertices_created > 0) {
        double skip = 1.0 - (double)rs->budget * (double)rs->iteration_paths / (double)st.vertices_created;
        rs->path_skip = skip > 0.0 ? (float)fmin(skip, 0.9) : 0.0f;
    }
    rs->total_vertices += st.vertices_created;
    rs->total_paths += rs->iteration_paths;
    rs->total_samples += rs->iteration_samples;
    rs->refused += st.vertices_refused;
    recorder_reset_counts(rs->recorder);
    rs->iteration_paths = rs->iteration_samples = 0;
    if (rs->active && !rs->debug_aov && ig->spp_done >= ig->guide.train_start + rs->training_spp) {
        rs->active = 0; /* no ray carries a vertex from here on */
        record_drop_batch(ig);
    }
}

static void record_report(const Integrator *ig, CandelaStats *st) {
    const RecordState *rs = &ig->record;
    if (!rs->recorder) return;
    RecorderStats rst;
    recorder_stats(rs->recorder, &rst);
    st->recorder_peak_bytes = rst.peak_bytes;
    st->recorder_bound_bytes = rst.bound_bytes;
    st->recorder_peak_vertices = rst.peak_live;
    st->recorder_vertices = rs->total_vertices;
    st->recorder_samples = rs->total_samples;
    st->recorder_refused = rs->refused;
    st->recorder_paths = rs->total_paths;
    st->recorder_path_skip = rs->path_skip;
}

/* ---------------------------------------------------------------- checkpoints */

#define RECORD_TAG CKPT_TAG('R', 'E', 'C', 'D')
#define RECORD_VERSION 1u

/* What the next barrier's path skipping and the training switch read: this iteration's
 * counts so far (the recorder's own and the paths'), the skip probability in force, whether
 * rays still carry vertices, and the totals of the statistics. No vertex is live at a batch
 * boundary, so nothing else of the recorder is needed. */
static int record_save(const Integrator *ig, FILE *out) {
    const RecordState *rs = &ig->record;
    RecorderStats st = {0};
    if (rs->recorder) recorder_stats(rs->recorder, &st);
    int32_t flags[2] = {rs->recorder != NULL, rs->active};
    uint64_t counts[8] = {rs->iteration_paths, rs->iteration_samples, rs->total_vertices, rs->total_paths,
                          rs->total_samples, rs->refused, st.vertices_created, st.vertices_refused};
    return ckpt_put_tag(out, RECORD_TAG, RECORD_VERSION) | ckpt_put(out, flags, sizeof flags) |
           ckpt_put(out, &rs->path_skip, sizeof rs->path_skip) | ckpt_put(out, counts, sizeof counts);
}

static int record_load(Integrator *ig, FILE *in) {
    RecordState *rs = &ig->record;
    int32_t flags[2];
    uint64_t counts[8];
    float skip;
    if (ckpt_get_tag(in, RECORD_TAG, RECORD_VERSION) || ckpt_get(in, flags, sizeof flags) ||
        ckpt_get(in, &skip, sizeof skip) || ckpt_get(in, counts, sizeof counts))
        return -1;
    if (flags[0] != (rs->recorder != NULL) || !(skip >= 0.0f && skip <= 1.0f)) return -1;
    if (!rs->recorder) return 0;
    rs->active = flags[1] != 0;
    rs->path_skip = skip;
    rs->iteration_paths = counts[0];
    rs->iteration_samples = counts[1];
    rs->total_vertices = counts[2];
    rs->total_paths = counts[3];
    rs->total_samples = counts[4];
    rs->refused = counts[5];
    recorder_restore_counts(rs->recorder, counts[6], counts[7]);
    return 0;
}

static void record_slice_begin(Integrator *ig, Slice *s, uint32_t k) {
    RecordState *rs = &ig->record;
    recorder_samples_clear(&rs->samples[k].s); /* the last batch's were trained on */
    s->record_samples = &rs->samples[k].s;
}

const IntegratorFeature feature_recorder = {
    .name = "radiance recorder",
    .init = record_init,
    .free = record_free,
    .slice_begin = record_slice_begin,
    .batch_end = record_batch_end,
    .barrier = record_barrier,
    .report = record_report,
    .save = record_save,
    .load = record_load,
};
