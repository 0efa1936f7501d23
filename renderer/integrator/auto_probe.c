/* renderer/integrator/auto_probe.c: the measurement behind the volume estimators' `auto` choices
 * (--volume-cachepoint-scatter auto in inscatter.c, --volume-emission-sampling auto in
 * emission_auto.c; the paper's §5.2.3 names an automatic choice as wanted).
 *
 * While probing (the first AUTO_PROBE_ITERATIONS iterations: 1 + 1 + 2 = 4 spp; 3 spp with guiding,
 * whose training iterations are of 1 spp) the feature is
 * on everywhere and every path records, for the one medium it is attributed to, the feature's
 * share of its radiance as rendered (`on`) and as it would be without the feature (`off`: the
 * other technique alone, unweighted), and the feature's cost. What decides is the variance of a
 * pixel's estimate, not the spread between pixels (a fire seen directly differs from the floor
 * by 1000x in both cases), so the variances are within-pixel ones: consecutive probe samples of
 * one pixel form a pair, and (x1 - x2)^2 / 2 is an unbiased estimate of the variance of one
 * sample; a sample not attributed to a medium has a zero share of it (most of the variance of a
 * technique that rarely finds a source is there). Per medium, with V_path (all paths) and V_on /
 * V_off (the medium's shares), C the mean counted cost of a path (rays + collisions / 10) and c
 * the mean cost the feature adds for the medium, the feature stays on where
 * estimator_ttuv_ratio < 1. Sums run in
 * path order after each batch; costs are counts, never clocks: the choice, hence the image,
 * does not depend on timing or threads. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "ckpt_io.h"
#include "integrator.h"

typedef struct ProbeMedium {
    double on_d2, off_d2; /* summed squared differences of pairs (the pair count is global) */
    double cost;          /* the feature's summed cost on this medium's paths */
} ProbeMedium;

int auto_probe_init(AutoProbe *ap, const char *flag, uint32_t num_media, uint32_t npixels, int mode) {
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

void auto_probe_free(AutoProbe *ap) {
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

void auto_probe_batch(AutoProbe *ap, const Integrator *ig, const Slice *slices, uint32_t n, const uint32_t *medium,
                      const float *on, const float *off, const float *cost) {
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

void auto_probe_barrier(AutoProbe *ap, int quiet) {
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
int auto_probe_save(const AutoProbe *ap, uint32_t npixels, FILE *out) {
    int32_t head[4] = {(int32_t)ap->num_media, ap->active, ap->iterations, (ap->media != NULL) | (ap->prev != NULL) << 1};
    double sums[4] = {ap->cost, ap->paths, ap->pairs, ap->path_d2};
    return ckpt_put_tag(out, PROBE_TAG, PROBE_VERSION) | ckpt_put(out, head, sizeof head) |
           ckpt_put(out, sums, sizeof sums) | ckpt_put(out, ap->on, ap->num_media) |
           (ap->media ? ckpt_put(out, ap->media, ap->num_media * sizeof *ap->media) : 0) |
           (ap->prev ? ckpt_put(out, ap->prev, npixels * sizeof *ap->prev) : 0);
}

int auto_probe_load(AutoProbe *ap, uint32_t npixels, FILE *in) {
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
