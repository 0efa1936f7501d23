/* renderer/integrator/volume_auto.c: the volume estimators' `auto` choices, one module: the probe
 * both share, in-scattering sampling's (--volume-cachepoint-scatter, the estimator is
 * inscatter.c) and emission sampling's (--volume-emission-sampling) feature-table entries (the
 * paper's §5.2.3 names an automatic choice as wanted).
 *
 * The probe. While probing (the first AUTO_PROBE_ITERATIONS iterations: 1 + 1 + 2 = 4 spp; 3 spp
 * with guiding, whose training iterations are of 1 spp) the feature is on everywhere and every
 * path records, for the one medium it is attributed to, the feature's share of its radiance as
 * rendered (`on`) and as it would be without the feature (`off`: the other technique alone,
 * unweighted), and the feature's cost. What decides is the variance of a pixel's estimate, not
 * the spread between pixels (a fire seen directly differs from the floor by 1000x in both
 * cases), so the variances are within-pixel ones: consecutive probe samples of one pixel form a
 * pair, and (x1 - x2)^2 / 2 is an unbiased estimate of the variance of one sample; a sample not
 * attributed to a medium has a zero share of it (most of the variance of a technique that rarely
 * finds a source is there). Per medium, with V_path (all paths) and V_on / V_off (the medium's
 * shares), C the mean counted cost of a path (rays + collisions / 10) and c the mean cost the
 * feature adds for the medium, the feature stays on where estimator_ttuv_ratio < 1. Sums run in
 * path order after each batch; costs are counts, never clocks: the choice, hence the image, does
 * not depend on timing or threads.
 *
 * In-scattering sampling (§4.2) adds a second technique on camera segments; the probe weighs it
 * per medium (below, inscatter_probe_batch).
 *
 * Emission sampling (§4.3: an emissive volume is also a light, NEE with line integration, MIS
 * with tracking) lowers the variance of what the volume lights, at the cost of NEE rays and line
 * integrals. With auto every emissive volume is a light, and for the first 4 spp every one is
 * sampled; the probe attributes a path to the first emissive medium it met and records that
 * medium's contributions as rendered (MIS-weighted NEE and tracking) and as tracking alone would
 * have given them (unweighted), with the NEE's cost (2 units per NEE of the volume: the shadow
 * ray and the line integral). At the barrier after the probe a medium keeps emission sampling
 * where the estimated time to unit variance is lower with it; for the others NEE skips the
 * volume (a selected volume light contributes nothing) and tracking's emission takes weight 1,
 * which is again a partition of unity, so the image stays unbiased.
 *
 * Both entries keep their place in the feature table (feature.c: in-scattering first) and their
 * checkpoint sections (one probe each, PROBE_TAG, in table order). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "ckpt_io.h"
#include "feature.h"
#include "volume_auto.h"

/* ---------------------------------------------------------------- the probe */

typedef struct ProbeMedium {
    double on_d2, off_d2; /* summed squared differences of pairs (the pair count is global) */
    double cost;          /* the feature's summed cost on this medium's paths */
} ProbeMedium;

static int auto_probe_init(AutoProbe *ap, const char *flag, uint32_t num_media, uint32_t npixels, int mode) {
    memset(ap, 0, sizeof *ap);
    ap->flag = flag;
    ap->num_media = num_media;
    ap->on = calloc((size_t)num_media + 1, 1);
    if (!ap->on) return -1;
    if (mode == 1) memset(ap->on, 1, num_media);
    if (mode == 2) {
        memset(ap->on, 1, num_media);
        ap->media = calloc((size_t)num_media + 1, sizeof *ap->media);
        ap->prev = calloc((size_t)npixels + 1, sizeof *ap->prev);
        if (!ap->media || !ap->prev) return -1;
        ap->active = 1;
    }
    return 0;
}

static void auto_probe_free(AutoProbe *ap) {
    free(ap->on);
    free(ap->media);
    free(ap->prev);
    memset(ap, 0, sizeof *ap);
}

/* One pair's contribution to a medium's sums: a sample not attributed to the medium has a
 * zero share of it (a technique that rarely finds a source has most of its variance there). */
static void pair_add(ProbeMedium *P, double on_a, double off_a, double on_b, double off_b) {
    P->on_d2 += 0.5 * (on_a - on_b) * (on_a - on_b);
    P->off_d2 += 0.5 * (off_a - off_b) * (off_a - off_b);
}

static void auto_probe_batch(AutoProbe *ap, const Integrator *ig, const Slice *slices, uint32_t n,
                             const uint32_t *medium, const float *on, const float *off, const float *cost) {
    if (!ap->active) return;
    const PathState *ps = &ig->ps;
    for (uint32_t k = 0; k < n; ++k)
        ap->cost += (double)(slices[k].bounce_rays + slices[k].shadow_rays) + 0.1 * (double)slices[k].volume.collisions;
    ap->cost += ig->batch_count; /* camera rays */
    ap->paths += ig->batch_count;
    for (uint32_t p = 0; p < ig->batch_count; ++p) {
        uint32_t m = medium[p];
        float L = v3_luminance(ps->radiance[p]);
        float a = m ? on[p] : 0.0f, b = m ? off[p] : 0.0f;
        float *prev = ap->prev[ps->pixel[p]];
        if (!isfinite(L) || !isfinite(a) || !isfinite(b) || m > ap->num_media) {
            prev[3] = 0.0f; /* unusable: the pixel's chain restarts */
            continue;
        }
        if (m) ap->media[m - 1].cost += cost[p];
        if (prev[3] > 0.0f) { /* a pair with the pixel's previous probe sample */
            uint32_t mp = (uint32_t)prev[3] - 1u;
            ap->pairs += 1.0;
            ap->path_d2 += 0.5 * ((double)L - prev[0]) * ((double)L - prev[0]);
            if (m && m == mp) {
                pair_add(&ap->media[m - 1], a, b, prev[1], prev[2]);
            } else {
                if (m) pair_add(&ap->media[m - 1], a, b, 0.0, 0.0);
                if (mp) pair_add(&ap->media[mp - 1], 0.0, 0.0, prev[1], prev[2]);
            }
        }
        prev[0] = L;
        prev[1] = a;
        prev[2] = b;
        prev[3] = (float)(m + 1u);
    }
}

static void auto_probe_barrier(AutoProbe *ap, int quiet) {
    if (!ap->active || ++ap->iterations < AUTO_PROBE_ITERATIONS) return;
    ap->active = 0;
    double C = ap->paths > 0.0 ? ap->cost / ap->paths : 0.0;
    for (uint32_t m = 0; m < ap->num_media; ++m) {
        const ProbeMedium *P = &ap->media[m];
        if (!ap->on[m] || ap->pairs < 2.0 || !(P->cost > 0.0 || P->on_d2 > 0.0 || P->off_d2 > 0.0))
            continue; /* never met: nothing to decide */
        double ratio = estimator_ttuv_ratio(ap->path_d2 / ap->pairs, P->on_d2 / ap->pairs, P->off_d2 / ap->pairs, C,
                                            P->cost / ap->paths);
        ap->on[m] = ratio < 1.0;
        if (!quiet)
            fprintf(stderr, "candela: %s auto: medium %u %s (estimated time to unit variance x%.2f with it)\n", ap->flag,
                    m, ap->on[m] ? "on" : "off", ratio);
    }
    free(ap->prev); /* the probe's per-pixel memory goes once it has decided */
    ap->prev = NULL;
}

/* ---------------------------------------------------------------- checkpoints */

#define PROBE_TAG CKPT_TAG('P', 'R', 'O', 'B')
#define PROBE_VERSION 1u

/* The choices per medium, and while probing the sums, the per-medium sums and every pixel's
 * last probe sample (the pairs continue across a resume). */
static int auto_probe_save(const AutoProbe *ap, uint32_t npixels, FILE *out) {
    int32_t head[4] = {(int32_t)ap->num_media, ap->active, ap->iterations, (ap->media != NULL) | (ap->prev != NULL) << 1};
    double sums[4] = {ap->cost, ap->paths, ap->pairs, ap->path_d2};
    return ckpt_put_tag(out, PROBE_TAG, PROBE_VERSION) | ckpt_put(out, head, sizeof head) |
           ckpt_put(out, sums, sizeof sums) | ckpt_put(out, ap->on, ap->num_media) |
           (ap->media ? ckpt_put(out, ap->media, ap->num_media * sizeof *ap->media) : 0) |
           (ap->prev ? ckpt_put(out, ap->prev, npixels * sizeof *ap->prev) : 0);
}

static int auto_probe_load(AutoProbe *ap, uint32_t npixels, FILE *in) {
    int32_t head[4];
    double sums[4];
    if (ckpt_get_tag(in, PROBE_TAG, PROBE_VERSION) || ckpt_get(in, head, sizeof head) || ckpt_get(in, sums, sizeof sums))
        return -1;
    int had_media = head[3] & 1, had_prev = (head[3] >> 1) & 1;
    /* a freshly built probe has both while it may still probe; the saved one may have let
     * `prev` go after deciding, never gained anything */
    if (head[0] != (int32_t)ap->num_media || had_media != (ap->media != NULL) || (had_prev && !ap->prev)) return -1;
    if (ckpt_get(in, ap->on, ap->num_media) || (had_media && ckpt_get(in, ap->media, ap->num_media * sizeof *ap->media)) ||
        (had_prev && ckpt_get(in, ap->prev, npixels * sizeof *ap->prev)))
        return -1;
    if (!had_prev) {
        free(ap->prev);
        ap->prev = NULL;
    }
    ap->active = head[1] != 0;
    ap->iterations = head[2];
    ap->cost = sums[0];
    ap->paths = sums[1];
    ap->pairs = sums[2];
    ap->path_d2 = sums[3];
    return 0;
}

/* ---------------------------------------------------------------- in-scattering sampling: on / auto */

/* A segment uses the technique while probing, or when one of its media chose it. */
int inscatter_segment_on(const Integrator *ig, const MediaView *view) {
    if (ig->inscatter_auto.active) return 1;
    for (int i = 0; i < view->count; ++i)
        if (ig->inscatter_auto.on[media_id(ig->media, view->media[i])]) return 1;
    return 0;
}

static void inscatter_auto_barrier(Integrator *ig) { auto_probe_barrier(&ig->inscatter_auto, ig->opt->quiet); }

/* The probe attributes a path to the medium of its first camera segment that ran the technique
 * (the view's first medium); `on` is that segment's NEE by both techniques (MIS-weighted),
 * `off` the walk's own NEE unweighted: what the pixel gets without the technique. */
static void inscatter_probe_batch(Integrator *ig, Slice *slices, uint32_t n) {
    const PathState *ps = &ig->ps;
    auto_probe_batch(&ig->inscatter_auto, ig, slices, n, ps->probe_medium, ps->probe_mis, ps->probe_null,
                     ps->probe_cost);
}

/* In-scattering sampling runs where there are media and lights and the light sampler gives
 * scattering weights; --volume-cachepoint-scatter on (1) or auto (2) there. */
static int inscatter_auto_init(Integrator *ig) {
    const CandelaOptions *o = ig->opt;
    ig->inscatter = o->volume_inscatter_sampling != 0 && media_any(ig->media) && ig->lights->count > 0 &&
                    light_sampler_has_inscatter(ig->light_sampler);
    return auto_probe_init(&ig->inscatter_auto, "--volume-cachepoint-scatter", media_count(ig->media), ig->npixels,
                           ig->inscatter ? o->volume_inscatter_sampling : 0);
}

static void inscatter_auto_free(Integrator *ig) { auto_probe_free(&ig->inscatter_auto); }
static int inscatter_auto_save(const Integrator *ig, FILE *out) { return auto_probe_save(&ig->inscatter_auto, ig->npixels, out); }
static int inscatter_auto_load(Integrator *ig, FILE *in) { return auto_probe_load(&ig->inscatter_auto, ig->npixels, in); }

const IntegratorFeature feature_inscatter_auto = {
    .name = "in-scattering auto choice",
    .init = inscatter_auto_init,
    .free = inscatter_auto_free,
    .batch_end = inscatter_probe_batch,
    .barrier = inscatter_auto_barrier,
    .save = inscatter_auto_save,
    .load = inscatter_auto_load,
};

/* ---------------------------------------------------------------- emission sampling: on / auto */

static void emission_auto_barrier(Integrator *ig) { auto_probe_barrier(&ig->emission_auto, ig->opt->quiet); }

static void emission_probe_batch(Integrator *ig, Slice *slices, uint32_t n) {
    const PathState *ps = &ig->ps;
    auto_probe_batch(&ig->emission_auto, ig, slices, n, ps->probe_em_medium, ps->probe_em_on, ps->probe_em_off,
                     ps->probe_em_cost);
}

/* --volume-emission-sampling on (1) or auto (2) where there are lights */
static int emission_auto_init(Integrator *ig) {
    int mode = ig->lights->count > 0 ? ig->opt->volume_emission_sampling : 0;
    AutoProbe *ap = &ig->emission_auto;
    if (auto_probe_init(ap, "--volume-emission-sampling", media_count(ig->media), ig->npixels, mode) != 0) return -1;
    /* only emissive volumes are lights: the others have nothing to sample */
    for (uint32_t m = 0; m < ap->num_media; ++m) ap->on[m] = ap->on[m] && m < ig->media->num_vdb && ig->media->vdb[m].emissive;
    return 0;
}

static void emission_auto_free(Integrator *ig) { auto_probe_free(&ig->emission_auto); }
static int emission_auto_save(const Integrator *ig, FILE *out) { return auto_probe_save(&ig->emission_auto, ig->npixels, out); }
static int emission_auto_load(Integrator *ig, FILE *in) { return auto_probe_load(&ig->emission_auto, ig->npixels, in); }

const IntegratorFeature feature_emission_auto = {
    .name = "emission sampling auto choice",
    .init = emission_auto_init,
    .free = emission_auto_free,
    .batch_end = emission_probe_batch,
    .barrier = emission_auto_barrier,
    .save = emission_auto_save,
    .load = emission_auto_load,
};
