/* renderer/integrator/guide.c: path guiding in the wavefront (--guiding off|mis|ris).
 *
 * Guiding fields (guiding/guiding.h: Practical Path Guiding's SD-tree) over the scene bounds:
 * one for medium vertices (PPG knows no media; the digest's §2 asks for separate statistics)
 * and six for surface vertices, one per orientation class of the shading normal (its largest
 * component and sign). A spatial leaf of a room's corner holds floor, wall and ceiling points
 * whose incident light comes from different hemispheres: one shared distribution sent a quarter
 * of the guide's samples below the surface and spread the rest over every orientation's lobes
 * (scenes/guiding_interior.gltf). After every batch the recorder's samples
 * (record.c; sorted by path, so the order never depends on the thread count) train the
 * building trees: continuation vertices only, not NEE vertices, and not directions from delta
 * lobes (ch. 1 §5: the guide learns indirect plus MIS-weighted direct light, as the emission a
 * continuation's subtree found is already MIS-weighted), zero-radiance samples included
 * (ch. 1 §8.1). At each iteration barrier the fields update (PPG's spatial split at
 * c sqrt(spp of the iteration), quadtree refinement); guided sampling starts once 8 spp have
 * trained them (ch. 2 §5.2, §5.3.3), on the guided schedule of render.c. */
#include <math.h>
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "clock.h"
#include "io.h"
#include "ckpt_io.h"
#include "feature.h"
#include "record.h"
#include "scatter.h"
#include "guide.h"

#define GUIDE_TRAINING_SPP 8 /* samples per pixel of training before guided sampling starts */
/* The bootstrap's samples are dropped from the image when guided samples follow, in a render of
 * at least this many spp (guide_drop_bootstrap). */
#define GUIDE_DROP_MIN_SPP (4 * GUIDE_TRAINING_SPP)
/* Whether this render drops them (long enough, no adaptive sampling): the drop and auto's
 * prediction both ask. */
static int render_drops_bootstrap(const Integrator *ig) {
    return ig->opt->spp >= GUIDE_DROP_MIN_SPP && !ig->film.stopped;
}

/* --guiding auto. Its probe renders the first GUIDE_AUTO_PROBE_SPP as `mis` does (unguided
 * iterations of 1 spp with the recorder training the fields: guided sampling starts only after
 * GUIDE_TRAINING_SPP), measuring per pixel the variance of the paths' radiance and of its part
 * through two or more scattering vertices, none of them in a medium (what guiding can improve:
 * direct light is NEE's, with MIS; in media, guided phase sampling removed only 1.07-1.22x of
 * the relative variance of make_volumes.py's cornell_cloud, fig9_thick and camera_in_fog, where
 * the probe's spread promised 2-3x), from consecutive samples' squared differences. f is that
 * indirect share of the variance, each pixel weighted by 1 / (mean^2 + 0.01) as relMSE weighs
 * it. How badly the function's own sampling finds the indirect light is its spread S, the
 * indirect samples' variance over their mean squared over the image, and the gain G that guiding
 * brings on the indirect part is S^2 (at most GUIDE_AUTO_MAX_GAIN). That fits what guided MIS
 * removed since its roulette and caustic defense (96af807; scenes/RESULTS.md, "The
 * adjoint-driven roulette and `auto`'s gain"): scenes/default.gltf S 1.55, indirect variance
 * 2.3x lower; the box lit through the ceiling S 3.5, 8x; guiding_interior S 3.8, 5x. The cap is
 * 3: a spread above 1.7 came as often from light guiding learns (the box, guiding_interior) as
 * from light it does not (blender_interior S 3.9, lit through a lamp shade and a glass sphere:
 * 2.0x; make_manylights.py's windows S 3.3: 2.9x), and with a cap of 8 auto guided
 * blender_interior, where guiding's relMSE x time is 1.10-1.35x off's. With G = S, as before,
 * auto left guiding off on default.gltf, where it takes the time to unit variance to 0.80x. For a
 * render of n spp, s of them probed, T trained
 * (U = GUIDE_TRAINING_SPP of them unguided), the prediction is
 *     variance ratio = (U + (n - U) (1 - f + f / G)) / n, or n (1 - f + f / G) / (n - U) when the
 *                      image drops the U unguided samples (render_drops_bootstrap)
 *     time ratio     = (T COST_TRAIN + (n - T) COST_GUIDED) / (s COST_TRAIN + n - s)
 * (the probe's spp were recorded either way; the costs are the guiding benchmark's,
 * scenes/RESULTS.md); guiding goes on when the product is below GUIDE_AUTO_THRESHOLD and the
 * render goes on exactly as `mis` (bit for bit: the probe only reads), else the recorder stops
 * and the render is the unguided one, bit for bit, having paid for the probe's recording only.
 * Deterministic: counts and film sums, no clock. */
#define GUIDE_AUTO_PROBE_SPP 4
#define GUIDE_AUTO_MAX_GAIN 3.0
#define GUIDE_AUTO_COST_TRAIN 1.9
#define GUIDE_AUTO_COST_GUIDED 1.5
#define GUIDE_AUTO_THRESHOLD 0.85

static void guide_free(Integrator *ig);

static int guide_init(Integrator *ig) {
    GuideState *gs = &ig->guide;
    memset(gs, 0, sizeof *gs);
    gs->guided_from = -1;
    if (ig->opt->guiding == CANDELA_GUIDING_OFF) return 0;
    if (ig->opt->guiding == CANDELA_GUIDING_AUTO) {
        gs->auto_state = GUIDE_AUTO_PROBING;
        gs->probe_prev = calloc(ig->npixels, sizeof *gs->probe_prev);
        gs->probe_d2 = calloc(ig->npixels, sizeof *gs->probe_d2);
        gs->probe_samples = calloc(ig->npixels, sizeof *gs->probe_samples);
        gs->probe_sum = calloc(ig->npixels, sizeof *gs->probe_sum);
        if (!gs->probe_prev || !gs->probe_d2 || !gs->probe_samples || !gs->probe_sum) {
            guide_free(ig);
            return -1;
        }
    }
    gs->guided_from = 0; /* auto probes with mis's schedule (guide_schedule_start) */
    if (ig->opt->guide_roulette == CANDELA_GUIDE_ROULETTE_ADJOINT) {
        gs->pixel_estimate = calloc(ig->npixels, sizeof *gs->pixel_estimate);
        if (!gs->pixel_estimate) {
            guide_free(ig);
            return -1;
        }
    }
    GuideFieldParams params;
    guide_field_params_default(&params);
    if (ig->opt->guide_spatial_threshold > 0.0f) params.spatial_threshold = ig->opt->guide_spatial_threshold;
    params.spatial_filter = ig->opt->guide_spatial_filter;
    params.directional_filter = ig->opt->guide_directional_filter;
    params.min_bsdf_share = ig->opt->guide_min_bsdf_share;
    params.learn_bsdf_share = !(ig->opt->guide_bsdf_share > 0.0f);
    params.caustic_threshold = ig->opt->guide_caustic_threshold;
    params.caustic_share = ig->opt->guide_caustic_share;
    params.caustic_defense = ig->opt->guide_caustic_defense;
    if (!params.learn_bsdf_share) params.bsdf_share = ig->opt->guide_bsdf_share;
    const float lo[3] = {ig->scene->bounds_min.x, ig->scene->bounds_min.y, ig->scene->bounds_min.z};
    const float hi[3] = {ig->scene->bounds_max.x, ig->scene->bounds_max.y, ig->scene->bounds_max.z};
    gs->on = 1;
    for (int k = 0; k < GUIDE_FIELDS; ++k) {
        if (k == GUIDE_SURFACE_CLASSES && !media_any(ig->media)) break;
        gs->fields[k] = guide_field_create(lo, hi, &params);
        if (!gs->fields[k]) {
            guide_free(ig);
            return -1;
        }
    }
    gs->keep_last = ig->opt->guide_dump_prefix != NULL;
    gs->mode = ig->opt->guiding == CANDELA_GUIDING_RIS ? SCATTER_GUIDE_RIS : SCATTER_GUIDE_MIS;
    gs->learn_share = gs->mode == SCATTER_GUIDE_MIS && params.learn_bsdf_share;
    gs->share_stats = gs->mode == SCATTER_GUIDE_MIS && (params.learn_bsdf_share || params.caustic_threshold > 0.0f);
    return 0;
}

static void probe_free(GuideState *gs) {
    free(gs->probe_prev);
    free(gs->probe_d2);
    free(gs->probe_samples);
    free(gs->probe_sum);
    gs->probe_sum = NULL;
    gs->probe_prev = NULL;
    gs->probe_d2 = NULL;
    gs->probe_samples = NULL;
}

static void guide_free(Integrator *ig) {
    GuideState *gs = &ig->guide;
    probe_free(gs);
    free(gs->pixel_estimate);
    gs->pixel_estimate = NULL;
    for (int k = 0; k < GUIDE_FIELDS; ++k) guide_field_free(gs->fields[k]);
    for (int k = 0; k < MAX_SLICES; ++k) free(gs->train[k]);
    free(gs->last);
    free(gs->last_class);
    memset(gs, 0, sizeof *gs);
}


#define GUIDE_CLASS_SHIFT 16 /* bits of the recorder flags above PV_FLAG_* and RECORDER_SAMPLE_PRIMARY */

uint32_t guide_surface_flags(vec3 n) { return (uint32_t)(guide_field_of_normal(n) + 1) << GUIDE_CLASS_SHIFT; }

static int field_of_flags(uint32_t flags) {
    if (flags & PV_FLAG_VOLUME) return GUIDE_SURFACE_CLASSES;
    uint32_t c = (flags >> GUIDE_CLASS_SHIFT) & 7u;
    return c >= 1 && c <= GUIDE_SURFACE_CLASSES ? (int)c - 1 : -1;
}

uint32_t guide_leaf_hint(const Integrator *ig, uint32_t flags, const GuideDistribution *d) {
    int k = d ? field_of_flags(flags) : -1;
    return k >= 0 ? guide_field_leaf_of(ig->guide.fields[k], d) : GUIDE_NO_LEAF;
}

const GuideDistribution *guide_lookup(const Integrator *ig, vec3 p, vec3 n) {
    const GuideState *gs = &ig->guide;
    if (!gs->active) return NULL;
    int k = guide_field_of_normal(n);
    const GuideField *f = gs->fields[k];
    if (!f) return NULL;
    const float x[3] = {p.x, p.y, p.z};
    return guide_field_lookup(f, x);
}

/* The field a recorder sample trains (-1: none: an NEE or delta sample, or no such field). */
static int training_field(const GuideState *gs, uint32_t flags) {
    int f = flags & (PV_FLAG_NEE | PV_FLAG_DELTA) ? -1 : field_of_flags(flags);
    return f >= 0 && gs->fields[f] ? f : -1;
}

/* Slice k's samples of the batch as training samples, grouped by field (a stable counting sort:
 * each field's in path order), into the slice's scratch (the slices convert on the threads). */
static void convert_slice(GuideState *gs, int k, const RecorderSamples *batch) {
    size_t *start = gs->train_split[k];
    memset(start, 0, (GUIDE_FIELDS + 1) * sizeof *start);
    gs->slice_failed[k] = 0;
    for (size_t i = 0; i < batch->count; ++i) {
        int f = training_field(gs, batch->items[i].flags);
        if (f >= 0) start[f + 1]++;
    }
    for (int f = 0; f < GUIDE_FIELDS; ++f) start[f + 1] += start[f];
    size_t n = start[GUIDE_FIELDS];
    if (n > gs->train_capacity[k]) {
        GuideTrainingSample *t = realloc(gs->train[k], n * sizeof *t);
        if (!t) { /* training loses the slice's samples of this batch; the image is not affected */
            gs->slice_failed[k] = 1;
            memset(start, 0, (GUIDE_FIELDS + 1) * sizeof *start);
            return;
        }
        gs->train[k] = t;
        gs->train_capacity[k] = n;
    }
    size_t next[GUIDE_FIELDS];
    memcpy(next, start, sizeof next);
    for (size_t i = 0; i < batch->count; ++i) {
        const RecorderSample *s = &batch->items[i];
        int f = training_field(gs, s->flags);
        if (f < 0) continue;
        GuideTrainingSample *t = &gs->train[k][next[f]++];
        memcpy(t->pos, s->pos, sizeof t->pos);
        memcpy(t->dir, s->dir, sizeof t->dir);
        /* surfaces learn L |cos theta| (the product the function's f |cos| multiplies, exact for a
         * diffuse surface; the fields are per orientation class, so a leaf's vertices share
         * nearly one normal); media learn L (cosine 1) */
        t->radiance = (0.2126f * s->radiance[0] + 0.7152f * s->radiance[1] + 0.0722f * s->radiance[2]) * s->cosine;
        t->pdf = s->pdf;
        t->leaf = s->user; /* the rendering lookup's leaf (record_child): training needs no descent */
        /* the statistics of the leaf's BSDF share (the learned one, ch. 1 §3.2.1, and the caustic
         * guard's), from a guided MIS vertex (it had a leaf): F = luminance(L) p_f stands for
         * f |cos| L (exact for a function sampled in proportion to f |cos|, up to its albedo,
         * which a leaf's vertices share nearly) */
        t->share_value = 0.0f;
        t->bsdf_pdf = 0.0f; /* none */
        t->guide_pdf = 0.0f;
        t->delta_child = (s->flags & PV_FLAG_DELTA_CHILD) != 0;
        t->defense = t->delta_child && s->pdf > 0.0f && s->bsdf_pdf > 0.0f ? s->bsdf_pdf / s->pdf : 0.0f;
        if (gs->share_stats && s->user != GUIDE_NO_LEAF && s->bsdf_pdf > 0.0f) {
            double F = (0.2126 * s->radiance[0] + 0.7152 * s->radiance[1] + 0.0722 * s->radiance[2]) * s->bsdf_pdf;
            t->share_value = (float)(F * F / s->pdf);
            t->bsdf_pdf = s->bsdf_pdf;
            t->guide_pdf = s->guide_pdf;
        }
    }
}

typedef struct FieldCtx {
    GuideState *gs;
    const RecordState *rs;
    float iteration_spp;
} FieldCtx;

static void convert_slices(void *ctx, size_t begin, size_t end, int thread_index) {
    (void)thread_index;
    FieldCtx *c = ctx;
    for (size_t k = begin; k < end; ++k) convert_slice(c->gs, (int)k, &c->rs->samples[k].s);
}

/* Field k trains on its samples of every slice in slice order: the batch's in path order (the
 * field's sums are the same as from one call over them all: guide_field_record adds in order). */
static void train_fields(void *ctx, size_t begin, size_t end, int thread_index) {
    (void)thread_index;
    FieldCtx *c = ctx;
    GuideState *gs = c->gs;
    for (size_t k = begin; k < end; ++k) {
        gs->train_count[k] = 0;
        if (!gs->fields[k]) continue;
        for (uint32_t j = 0; j < c->rs->batch_slices; ++j) {
            size_t b = gs->train_split[j][k], e = gs->train_split[j][k + 1];
            guide_field_record(gs->fields[k], gs->train[j] + b, e - b);
            gs->train_count[k] += e - b;
        }
    }
}

static void update_fields(void *ctx, size_t begin, size_t end, int thread_index) {
    (void)thread_index;
    FieldCtx *c = ctx;
    for (size_t k = begin; k < end; ++k)
        c->gs->field_failed[k] = c->gs->fields[k] && guide_field_update(c->gs->fields[k], c->iteration_spp) != 0;
}

/* guide-dump's histogram: the surface fields' samples of the batch, appended in field order. */
static void keep_last_samples(GuideState *gs, int k, uint32_t slices) {
    size_t n = gs->train_count[k];
    if (k < GUIDE_SURFACE_CLASSES && gs->keep_last && n > 0) {
        if (gs->last_count + n > gs->last_capacity) {
            size_t cap = 2 * (gs->last_count + n);
            GuideTrainingSample *l = realloc(gs->last, cap * sizeof *l);
            uint8_t *c = l ? realloc(gs->last_class, cap) : NULL;
            if (l) gs->last = l;
            if (c) gs->last_class = c;
            if (!l || !c) { gs->dropped = 1; return; }
            gs->last_capacity = cap;
        }
        for (uint32_t j = 0; j < slices; ++j) {
            size_t b = gs->train_split[j][k], e = gs->train_split[j][k + 1];
            if (e > b) memcpy(gs->last + gs->last_count, gs->train[j] + b, (e - b) * sizeof *gs->train[j]);
            memset(gs->last_class + gs->last_count, k, e - b);
            gs->last_count += e - b;
        }
    }
}

static void guide_train_batch(Integrator *ig) {
    GuideState *gs = &ig->guide;
    const RecordState *rs = &ig->record;
    uint32_t slices = rs->batch_slices;
    size_t total = 0;
    for (uint32_t j = 0; j < slices; ++j) total += rs->samples[j].s.count;
    if (!gs->on || !rs->active || total == 0) return;
    gs->pending = 1;
    double t0 = clock_seconds();
    /* the slices' samples to training samples by field on the threads, then the fields train on
     * the threads, each over the slices in order (no copy of the whole batch in between) */
    FieldCtx c = {gs, rs, 0.0f};
    if (ig->pool && slices > 1) threadpool_parallel_for(ig->pool, slices, 1, convert_slices, &c);
    else convert_slices(&c, 0, slices, 0);
    for (uint32_t j = 0; j < slices; ++j)
        if (gs->slice_failed[j]) gs->dropped = 1;
    if (ig->pool) threadpool_parallel_for(ig->pool, GUIDE_FIELDS, 1, train_fields, &c);
    else train_fields(&c, 0, GUIDE_FIELDS, 0);
    for (int k = 0; k < GUIDE_FIELDS; ++k) {
        if (!gs->fields[k]) continue;
        gs->samples_trained += gs->train_count[k];
        keep_last_samples(gs, k, slices);
    }
    gs->train_seconds += clock_seconds() - t0;
}

static void guide_probe_batch(Integrator *ig) {
    GuideState *gs = &ig->guide;
    if (gs->auto_state != GUIDE_AUTO_PROBING) return;
    const PathState *ps = &ig->ps;
    for (uint32_t p = 0; p < ig->batch_count; ++p) { /* path order: each pixel's samples in sample order */
        uint32_t px = ps->pixel[p];
        float L = v3_luminance(ps->radiance[p]), I = ps->probe_indirect[p];
        if (!isfinite(L) || !isfinite(I)) L = I = 0.0f;
        if (gs->probe_samples[px]++ > 0) {
            double dl = (double)L - gs->probe_prev[px][0], di = (double)I - gs->probe_prev[px][1];
            gs->probe_d2[px][0] += dl * dl;
            gs->probe_d2[px][1] += di * di;
        }
        gs->probe_prev[px][0] = L;
        gs->probe_prev[px][1] = I;
        gs->probe_sum[px] += I;
    }
}

/* The probe's decision (above): guiding on from the next iteration, or off. */
static void auto_decide(Integrator *ig) {
    GuideState *gs = &ig->guide;
    const Film *film = &ig->film;
    double v_total = 0.0, v_indirect = 0.0;
    for (uint32_t i = 0; i < ig->npixels; ++i) {
        uint32_t n = gs->probe_samples[i];
        if (n < 2 || film->count[i] == 0) continue;
        double c = film->count[i];
        double mean = (0.2126 * film->sum[3 * i] + 0.7152 * film->sum[3 * i + 1] + 0.0722 * film->sum[3 * i + 2]) / c;
        double w = 1.0 / (mean * mean + 0.01) / (2.0 * (n - 1)); /* E[(x_k - x_k-1)^2] = 2 var */
        v_total += w * gs->probe_d2[i][0];
        v_indirect += w * gs->probe_d2[i][1];
    }
    double f = v_total > 0.0 ? fmin(v_indirect / v_total, 1.0) : 0.0;
    /* how badly the function's own sampling finds the indirect light: its samples' variance
     * over their mean squared, over the image (a smooth indirect field, as in a Cornell box lit
     * from above, about 1.6; light through a window or off a bright patch, 3.6 or more) */
    double ind_var = 0.0, ind_mean2 = 0.0;
    for (uint32_t i = 0; i < ig->npixels; ++i) {
        uint32_t n = gs->probe_samples[i];
        if (n < 2) continue;
        double mi = gs->probe_sum[i] / n;
        ind_var += gs->probe_d2[i][1] / (2.0 * (n - 1));
        ind_mean2 += mi * mi;
    }
    double spread = ind_mean2 > 0.0 ? fmax(ind_var / ind_mean2, 1.0) : 1.0;
    double gain = fmin(spread * spread, GUIDE_AUTO_MAX_GAIN);
    double n = ig->opt->spp, probed = ig->spp_done;
    double unguided = fmin(GUIDE_TRAINING_SPP, n), trained = fmax(fmin((double)ig->record.training_spp, n), probed);
    /* the unguided bootstrap stays in the image of a short render, else it is dropped
     * (guide_drop_bootstrap): the image holds n - unguided guided samples */
    double guided = 1.0 - f + f / gain;
    double var = render_drops_bootstrap(ig) ? n * guided / (n - unguided) : (unguided + (n - unguided) * guided) / n;
    double time = (trained * GUIDE_AUTO_COST_TRAIN + (n - trained) * GUIDE_AUTO_COST_GUIDED) /
                  (probed * GUIDE_AUTO_COST_TRAIN + n - probed);
    gs->auto_ratio = (float)(var * time);
    gs->auto_indirect = (float)f;
    gs->auto_gain = (float)gain;
    int on = v_total > 0.0 && var * time < GUIDE_AUTO_THRESHOLD;
    gs->auto_state = on ? GUIDE_AUTO_ON : GUIDE_AUTO_OFF;
    probe_free(gs);
    if (!on) { /* the unguided schedule from here on; nothing more is recorded */
        gs->guided_from = -1;
        ig->record.active = ig->record.debug_aov;
        if (!ig->record.active) record_drop_batch(ig);
    }
    if (!ig->opt->quiet)
        fprintf(stderr, "candela: --guiding auto: %s (indirect light %.0f%% of the relative variance, predicted gain on it "
                        "%.2f; estimated time to unit variance x%.2f with guiding)\n", on ? "on" : "off", 100.0 * f, gain,
                var * time);
}

static int guide_schedule_start(const Integrator *ig) { return ig->guide.guided_from; }

/* The adjoint-driven roulette's estimate of each pixel (vertex.h adjoint_survival): the luminance
 * of the film's mean at this barrier, fixed for the iteration that follows (so it does not depend
 * on batches or threads) and kept in checkpoints (one taken within an iteration cannot rebuild
 * it from its film). A pixel without samples (the bootstrap just dropped) estimates 0: the
 * throughput's roulette there. */
static void update_pixel_estimate(Integrator *ig) {
    float *est = ig->guide.pixel_estimate;
    if (!est) return;
    const Film *film = &ig->film;
    for (uint32_t i = 0; i < ig->npixels; ++i) {
        const double *s = &film->sum[3 * (size_t)i];
        double mean = film->count[i] ? (0.2126 * s[0] + 0.7152 * s[1] + 0.0722 * s[2]) / film->count[i] : 0.0;
        est[i] = mean > 0.0 && mean < 1e30 ? (float)mean : 0.0f;
    }
}

static void guide_barrier(Integrator *ig) {
    GuideState *gs = &ig->guide;
    if (!gs->on) return;
    if (gs->auto_state == GUIDE_AUTO_PROBING && ig->spp_done >= GUIDE_AUTO_PROBE_SPP) auto_decide(ig);
    if (gs->auto_state == GUIDE_AUTO_OFF) return;
    update_pixel_estimate(ig);
    /* ch. 2 §5.3.3: guided sampling only after the first 8 spp trained the fields */
    gs->active = ig->spp_done >= gs->train_start + GUIDE_TRAINING_SPP;
    if (!gs->pending) return; /* nothing new was recorded: the fields stay as they are */
    gs->pending = 0;
    double t0 = clock_seconds();
    FieldCtx c = {gs, NULL, (float)ig->iteration_spp};
    if (ig->pool) threadpool_parallel_for(ig->pool, GUIDE_FIELDS, 1, update_fields, &c);
    else update_fields(&c, 0, GUIDE_FIELDS, 0);
    for (int k = 0; k < GUIDE_FIELDS; ++k)
        if (gs->field_failed[k]) gs->dropped = 1;
    gs->updates++;
    gs->train_seconds += clock_seconds() - t0;
    if (ig->record.active && ig->spp_done < ig->opt->spp) gs->last_count = 0; /* guide-dump keeps the last trained iteration's */
}

static void guide_report(const Integrator *ig, CandelaStats *st) {
    const GuideState *gs = &ig->guide;
    st->guide_auto = gs->auto_state == GUIDE_AUTO_ON ? 1 : gs->auto_state == GUIDE_AUTO_OFF ? 0 : -1;
    st->guide_auto_ratio = gs->auto_ratio;
    st->guide_auto_indirect = gs->auto_indirect;
    if (!gs->on) return;
    st->guide_updates = gs->updates;
    st->guide_train_seconds = gs->train_seconds;
    st->guide_samples = gs->samples_trained;
    st->guide_leaves = 0;
    st->guide_bytes = 0;
    st->guide_share_per_leaf = gs->share_stats;
    _Static_assert(CANDELA_GUIDE_SHARES == GUIDE_SHARE_CANDIDATES, "the stats' share bins are the field's candidates");
    for (int j = 0; j < CANDELA_GUIDE_SHARES; ++j) {
        st->guide_share_value[j] = guide_share_candidates[j];
        st->guide_share_leaves[j] = 0;
    }
    for (int k = 0; k < GUIDE_FIELDS; ++k)
        if (gs->fields[k]) {
            st->guide_leaves += guide_field_num_leaves(gs->fields[k]);
            st->guide_bytes += guide_field_bytes(gs->fields[k]);
            uint32_t counts[GUIDE_SHARE_CANDIDATES];
            guide_field_share_leaves(gs->fields[k], counts);
            for (int j = 0; j < CANDELA_GUIDE_SHARES; ++j) st->guide_share_leaves[j] += counts[j];
        }
    st->guide_dropped = gs->dropped;
}

/* Writes an image as EXR (R = G = B = v) and a PNG preview scaled to its maximum, both with the
 * attributes of prov (NULL: none) and candela:guideDumpPlane = what. */
static int write_plane(const char *prefix, const char *what, int w, int h, const float *v, CandelaProvenance *prov,
                       char err[CANDELA_ERR_LEN]) {
    char path[4096], ioerr[IO_ERR_LEN];
    size_t n = (size_t)w * (size_t)h;
    float *rgb = malloc(3 * n * sizeof *rgb);
    if (!rgb) { snprintf(err, CANDELA_ERR_LEN, "%s: out of memory", prefix); return -1; }
    float vmax = 0.0f;
    for (size_t i = 0; i < n; ++i) vmax = fmaxf(vmax, v[i]);
    const IoExrChannel ch[3] = {{"R", v}, {"G", v}, {"B", v}};
    snprintf(path, sizeof path, "%s.%s.exr", prefix, what);
    IoExrAttribute attrs[CANDELA_PROVENANCE_MAX];
    int nattrs = 0;
    if (prov) {
        if (candela_provenance_set(prov, "candela:guideDumpPlane", what) != 0) {
            free(rgb);
            snprintf(err, CANDELA_ERR_LEN, "%s: out of memory", prefix);
            return -1;
        }
        nattrs = prov->count;
        for (int k = 0; k < nattrs; ++k) attrs[k] = (IoExrAttribute){prov->attrs[k].name, prov->attrs[k].value};
    }
    int rc = io_write_exr(path, w, h, ch, 3, nattrs ? attrs : NULL, nattrs, ioerr);
    if (rc == 0) {
        for (size_t i = 0; i < n; ++i) rgb[3 * i] = rgb[3 * i + 1] = rgb[3 * i + 2] = vmax > 0.0f ? sqrtf(v[i] / vmax) : 0.0f;
        snprintf(path, sizeof path, "%s.%s.png", prefix, what);
        rc = io_write_png(path, w, h, rgb, nattrs ? attrs : NULL, nattrs, ioerr);
    }
    free(rgb);
    if (rc != 0) snprintf(err, CANDELA_ERR_LEN, "%s", ioerr);
    return rc;
}

static int guide_dump(const Integrator *ig, const float at[3], const char *prefix, char err[CANDELA_ERR_LEN]) {
    const GuideState *gs = &ig->guide;
    if (!gs->on) { snprintf(err, CANDELA_ERR_LEN, "guide-dump: guiding is off"); return -1; }
    /* the surface orientation whose leaf at the point learned from the most samples */
    int best = 0;
    double most = -1.0;
    for (int k = 0; k < GUIDE_SURFACE_CLASSES; ++k) {
        double learned = guide_distribution_samples(guide_field_lookup(gs->fields[k], at));
        if (learned > most) { most = learned; best = k; }
    }
    static const char *const class_names[GUIDE_SURFACE_CLASSES] = {"+x", "-x", "+y", "-y", "+z", "-z"};
    enum { W = 128, H = 128 }; /* the octahedral (u, v) square (guiding.h): u across, v down */
    float *img = calloc((size_t)W * H, sizeof *img);
    if (!img) { snprintf(err, CANDELA_ERR_LEN, "%s: out of memory", prefix); return -1; }
    const GuideDistribution *d = guide_field_lookup(gs->fields[best], at);
    float lo[3], hi[3];
    guide_distribution_bounds(d, lo, hi);
    /* the leaf must hold the point (render.c refused a point outside the field before
     * rendering; this keeps a dump from ever describing another place) */
    if (!(at[0] >= lo[0] && at[0] <= hi[0] && at[1] >= lo[1] && at[1] <= hi[1] && at[2] >= lo[2] && at[2] <= hi[2])) {
        snprintf(err, CANDELA_ERR_LEN, "%s: guide-dump --at %g,%g,%g is in no leaf of the guiding field", prefix, (double)at[0],
                 (double)at[1], (double)at[2]);
        free(img);
        return -1;
    }
    guide_distribution_image(d, W, H, img);
    /* how the files were made (issue 27): the run's provenance, the scene and its hash, the
     * options, the samples done, the position and the leaf's surface orientation */
    CandelaProvenance prov = {0};
    const CandelaOptions *o = ig->opt;
    if (o->guide_dump_provenance) {
        char num[32], pos[96];
        snprintf(num, sizeof num, "%d", ig->spp_done);
        snprintf(pos, sizeof pos, "%.9g,%.9g,%.9g", (double)at[0], (double)at[1], (double)at[2]);
        char *options = candela_options_json(o);
        int prc = candela_provenance_copy(&prov, o->guide_dump_provenance);
        if (prc == 0 && candela_provenance_scene(&prov, o->scene_path, err) != 0) {
            candela_provenance_free(&prov);
            free(options);
            free(img);
            return -1;
        }
        if (prc == 0)
            prc = (options == NULL) | candela_provenance_set(&prov, "candela:options", options) |
                  candela_provenance_set(&prov, "candela:sppDone", num) |
                  candela_provenance_set(&prov, "candela:guideDumpAt", pos) |
                  candela_provenance_set(&prov, "candela:guideDumpClass", class_names[best]);
        free(options);
        if (prc != 0) {
            candela_provenance_free(&prov);
            free(img);
            snprintf(err, CANDELA_ERR_LEN, "%s: out of memory", prefix);
            return -1;
        }
    }
    CandelaProvenance *pp = o->guide_dump_provenance ? &prov : NULL;
    int rc = write_plane(prefix, "guide", W, H, img, pp, err);
    size_t in_leaf = 0;
    if (rc == 0) {
        /* the training directions of the final iteration inside the leaf's box (blurrier than
         * the model: they marginalise over the box; the seed's ch. 2 §4.4) */
        memset(img, 0, (size_t)W * H * sizeof *img);
        for (size_t i = 0; i < gs->last_count; ++i) {
            const GuideTrainingSample *t = &gs->last[i];
            if (gs->last_class[i] != best) continue;
            if (t->pos[0] < lo[0] || t->pos[0] > hi[0] || t->pos[1] < lo[1] || t->pos[1] > hi[1] || t->pos[2] < lo[2] ||
                t->pos[2] > hi[2])
                continue;
            float u, v;
            if (!guide_direction_uv(t->dir, &u, &v)) continue;
            int x = (int)(u * W), y = (int)(v * H);
            x = x < 0 ? 0 : x >= W ? W - 1 : x;
            y = y < 0 ? 0 : y >= H ? H - 1 : y;
            img[(size_t)y * W + x] += 1.0f;
            ++in_leaf;
        }
        rc = write_plane(prefix, "hist", W, H, img, pp, err);
    }
    candela_provenance_free(&prov);
    free(img);
    if (rc == 0) {
        char path[4096];
        snprintf(path, sizeof path, "%s.leaves.ply", prefix);
        /* through io's atomic writer, as the planes (io.h) */
        IoAtomicFile af;
        char ioerr[IO_ERR_LEN];
        int prc = io_atomic_begin(&af, path, "w", ioerr);
        if (prc == 0 && guide_field_write_ply(gs->fields[best], af.f) != 0 && !af.error) {
            snprintf(ioerr, sizeof ioerr, "%.400s: cannot write: %s", af.path, strerror(errno));
            io_atomic_abort(&af);
            prc = -1;
        } else if (prc == 0) {
            prc = io_atomic_commit(&af, ioerr); /* a failed write was kept with its reason (af.error) */
        }
        if (prc != 0) {
            snprintf(err, CANDELA_ERR_LEN, "%s", ioerr);
            return -1;
        }
        if (!ig->opt->quiet)
            fprintf(stderr,
                    "candela: guide-dump at (%g, %g, %g), surfaces facing %s: leaf [%g %g %g] - [%g %g %g], learned from "
                    "%.0f samples, %zu training directions of the last trained iteration; wrote %s.guide.exr/.png, "
                    "%s.hist.exr/.png, %s\n",
                    at[0], at[1], at[2], class_names[best], lo[0], lo[1], lo[2], hi[0], hi[1], hi[2], guide_distribution_samples(d), in_leaf,
                    prefix, prefix, path);
    }
    return rc;
}

/* ---------------------------------------------------------------- checkpoints */

#define GUIDE_TAG CKPT_TAG('G', 'U', 'I', 'D')
#define GUIDE_VERSION 3u

/* The fields (guiding/sdtree.c saves each whole: sampling and building trees), whether guided
 * sampling is on, whether samples wait for the next update, the statistics' counts, and --guiding
 * auto's state (while probing, its per-pixel sums), the adjoint-driven roulette's pixel estimates.
 * guide-dump's `last` samples are not kept: a
 * dump is a render of its own. */
static int guide_save(const Integrator *ig, FILE *out) {
    const GuideState *gs = &ig->guide;
    int32_t flags[7] = {gs->on, gs->active, gs->pending, gs->updates, gs->auto_state, gs->train_start, gs->guided_from};
    float prediction[3] = {gs->auto_ratio, gs->auto_indirect, gs->auto_gain};
    uint32_t present = 0;
    for (int k = 0; k < GUIDE_FIELDS; ++k) present |= (uint32_t)(gs->fields[k] != NULL) << k;
    int rc = ckpt_put_tag(out, GUIDE_TAG, GUIDE_VERSION) | ckpt_put(out, flags, sizeof flags) |
             ckpt_put(out, prediction, sizeof prediction) |
             ckpt_put(out, &present, sizeof present) | ckpt_put(out, &gs->samples_trained, sizeof gs->samples_trained);
    if (rc == 0 && gs->auto_state == GUIDE_AUTO_PROBING)
        rc = ckpt_put(out, gs->probe_prev, ig->npixels * sizeof *gs->probe_prev) |
             ckpt_put(out, gs->probe_d2, ig->npixels * sizeof *gs->probe_d2) |
             ckpt_put(out, gs->probe_samples, ig->npixels * sizeof *gs->probe_samples) |
             ckpt_put(out, gs->probe_sum, ig->npixels * sizeof *gs->probe_sum);
    if (rc == 0 && gs->pixel_estimate) rc = ckpt_put(out, gs->pixel_estimate, ig->npixels * sizeof *gs->pixel_estimate);
    for (int k = 0; k < GUIDE_FIELDS && rc == 0; ++k)
        if (gs->fields[k]) rc = guide_field_save(gs->fields[k], out);
    return rc;
}

static int guide_load(Integrator *ig, FILE *in) {
    GuideState *gs = &ig->guide;
    int32_t flags[7];
    float prediction[3];
    uint32_t present = 0, expected = 0;
    uint64_t trained;
    for (int k = 0; k < GUIDE_FIELDS; ++k) expected |= (uint32_t)(gs->fields[k] != NULL) << k;
    if (ckpt_get_tag(in, GUIDE_TAG, GUIDE_VERSION) || ckpt_get(in, flags, sizeof flags) ||
        ckpt_get(in, prediction, sizeof prediction) ||
        ckpt_get(in, &present, sizeof present) || ckpt_get(in, &trained, sizeof trained))
        return -1;
    if (flags[0] != gs->on || present != expected) return -1;
    /* a fixed mode stays itself; auto may have moved on from probing */
    int fixed = gs->auto_state == GUIDE_AUTO_NONE;
    if (fixed ? flags[4] != GUIDE_AUTO_NONE : (flags[4] < GUIDE_AUTO_PROBING || flags[4] > GUIDE_AUTO_OFF)) return -1;
    if (flags[5] < 0 || flags[6] < -1) return -1;
    if (flags[4] == GUIDE_AUTO_PROBING &&
        (ckpt_get(in, gs->probe_prev, ig->npixels * sizeof *gs->probe_prev) ||
         ckpt_get(in, gs->probe_d2, ig->npixels * sizeof *gs->probe_d2) ||
         ckpt_get(in, gs->probe_samples, ig->npixels * sizeof *gs->probe_samples) ||
         ckpt_get(in, gs->probe_sum, ig->npixels * sizeof *gs->probe_sum)))
        return -1;
    if (gs->pixel_estimate && ckpt_get(in, gs->pixel_estimate, ig->npixels * sizeof *gs->pixel_estimate)) return -1;
    for (uint32_t i = 0; gs->pixel_estimate && i < ig->npixels; ++i)
        if (!(gs->pixel_estimate[i] >= 0.0f && gs->pixel_estimate[i] < 1e30f)) return -1;
    gs->auto_state = flags[4];
    gs->train_start = flags[5];
    gs->guided_from = flags[6];
    gs->auto_ratio = prediction[0];
    gs->auto_indirect = prediction[1];
    gs->auto_gain = prediction[2];
    if (gs->auto_state == GUIDE_AUTO_ON || gs->auto_state == GUIDE_AUTO_OFF) probe_free(gs);
    for (int k = 0; k < GUIDE_FIELDS; ++k)
        if (gs->fields[k] && guide_field_load(gs->fields[k], in) != 0) return -1;
    gs->active = flags[1] != 0;
    gs->pending = flags[2] != 0;
    gs->updates = flags[3];
    gs->samples_trained = trained;
    return 0;
}

/* The first batch of guided samples (called before it reaches the film): the film drops the
 * unguided bootstrap it holds, GUIDE_TRAINING_SPP samples per pixel that trained the guide. Their
 * variance is that of the unguided render (4x the guided one on the indirect-lit box, 5x on
 * guiding_interior), so although they are 8 of 256 spp they carried 12-14% of the image's
 * variance: dropping them lowered relMSE 8% on the box at 192x192 (scenes/RESULTS.md). Müller et
 * al. 2017 likewise keep only the guided iterations; the image stays unbiased, every sample in it
 * being an unbiased estimate. Not in a render of fewer than GUIDE_DROP_MIN_SPP, where the
 * bootstrap is too large a share to throw away, nor with adaptive sampling, whose pilot the
 * bootstrap is part of. Deterministic: a function of the schedule, so a checkpoint resumed at
 * any batch drops exactly when the uninterrupted render did (a checkpoint's film says what it
 * dropped). */
static void guide_drop_bootstrap(Integrator *ig) {
    const GuideState *gs = &ig->guide;
    if (!gs->on || !gs->active || !render_drops_bootstrap(ig)) return;
    if (ig->spp_done != gs->train_start + GUIDE_TRAINING_SPP || ig->batch_first != 0 || ig->film.dropped) return;
    (void)film_drop(&ig->film); /* every pixel holds the bootstrap's count: it cannot refuse */
}

/* After a batch: the fields learn from its samples, and auto's probe takes its sums. */
static void guide_batch_end(Integrator *ig, Slice *slices, uint32_t n) {
    (void)slices;
    (void)n;
    guide_train_batch(ig);
    guide_probe_batch(ig);
    guide_drop_bootstrap(ig);
}

/* guide-dump reads the guiding field's leaf at --at: the fields span the scene's bounds, and a
 * point outside them has no leaf of its own (the nearest one's box would not hold it). Said
 * before the render, not after it. */
static int guide_validate(const CandelaOptions *o, const Scene *scene, char err[CANDELA_ERR_LEN]) {
    if (!o->guide_dump_prefix) return 0;
    const float *at = o->guide_dump_at;
    const vec3 lo = scene->bounds_min, hi = scene->bounds_max;
    if (at[0] >= lo.x && at[0] <= hi.x && at[1] >= lo.y && at[1] <= hi.y && at[2] >= lo.z && at[2] <= hi.z) return 0;
    snprintf(err, CANDELA_ERR_LEN,
             "%s: guide-dump --at %g,%g,%g is outside the scene's bounds [%g %g %g] - [%g %g %g], which the guiding "
             "field covers",
             o->scene_path, (double)at[0], (double)at[1], (double)at[2], (double)lo.x, (double)lo.y, (double)lo.z,
             (double)hi.x, (double)hi.y, (double)hi.z);
    return -1;
}

static int guide_finish(Integrator *ig, char err[CANDELA_ERR_LEN]) {
    const CandelaOptions *o = ig->opt;
    return o->guide_dump_prefix ? guide_dump(ig, o->guide_dump_at, o->guide_dump_prefix, err) : 0;
}

const IntegratorFeature feature_guiding = {
    .name = "guiding",
    .validate = guide_validate,
    .init = guide_init,
    .free = guide_free,
    .batch_end = guide_batch_end,
    .barrier = guide_barrier,
    .schedule_start = guide_schedule_start,
    .report = guide_report,
    .finish = guide_finish,
    .save = guide_save,
    .load = guide_load,
};
