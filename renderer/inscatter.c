/* renderer/inscatter.c: cache-point in-scattering sampling (the cache points paper §4.2; the
 * spec's §7.2-7.3).
 *
 * Along a camera ray's segment through media, null-collision tracking finds the first
 * scattering vertex with a density that follows the extinction: in a thin medium around a
 * bright light it rarely scatters where the light is. The cache points know where in-scattered
 * light is strong (their scattering weights, computed in the build), so a second technique
 * draws the vertex's distance from a piecewise-linear density through the weights of the
 * nearest cache points along the segment (stations one radius of influence apart, at most 64,
 * plus a defensive uniform part), ratio-tracks the transmittance to it and does NEE there.
 * Both techniques estimate the single-scattered direct light of the segment; each weighs its
 * sample by the balance heuristic over the pair with the density ratio of Eq. 10 (corrected in
 * the spec): p_null / p_cachepoint = [product over the null vertices of mean(sigma_n) / sigma_maj]
 * x mean(sigma_s(x_k)) / p_select(x_k), the same function of the vertices in both (the
 * trackers report the product). The phase-sampled continuation and everything after the first
 * scatter stay with the null-collision walk. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "integrator.h"
#include "rng.h"
#include "scatter.h"

#define INSCATTER_STATIONS 64
#define INSCATTER_DELTA 0.1f /* the defensive uniform share (spec §7.2) */

int inscatter_table(const Integrator *ig, SceneRay ray, float tmax, const MediaView *view, uint32_t *hint,
                    VolumeDistanceTable *tab) {
    const float o[3] = {ray.org.x, ray.org.y, ray.org.z}, d[3] = {ray.dir.x, ray.dir.y, ray.dir.z};
    float ta = INFINITY, tb = -INFINITY;
    for (int i = 0; i < view->count; ++i) {
        float t0, t1;
        if (!medium_clip_ray(view->media[i], o, d, 0.0f, tmax, &t0, &t1)) continue;
        ta = fminf(ta, t0);
        tb = fmaxf(tb, t1);
    }
    if (!(tb > ta) || !isfinite(ta) || !isfinite(tb)) return 0;
    float ts[INSCATTER_STATIONS + 1], ss[INSCATTER_STATIONS + 1];
    float step_min = (tb - ta) / INSCATTER_STATIONS;
    int n = 0;
    for (float t = ta; n < INSCATTER_STATIONS && t < tb;) {
        vec3 x = v3_madd(ray.org, ray.dir, t);
        const float xf[3] = {x.x, x.y, x.z};
        float r = 0.0f;
        ts[n] = t;
        ss[n] = light_sampler_inscatter_weight(ig->light_sampler, xf, hint, &r);
        ++n;
        t += fmaxf(r, step_min);
    }
    vec3 x = v3_madd(ray.org, ray.dir, tb);
    const float xf[3] = {x.x, x.y, x.z};
    float r;
    ts[n] = tb;
    ss[n] = light_sampler_inscatter_weight(ig->light_sampler, xf, hint, &r);
    ++n;
    return volume_distance_table_init(tab, ts, ss, n, INSCATTER_DELTA) == 0;
}

float inscatter_estimate(const Integrator *ig, Slice *s, uint32_t p, SceneRay ray, const MediaView *view,
                         const VolumeDistanceTable *tab, uint32_t *hint, float *scratch, float *cost) {
    const PathState *ps = &ig->ps;
    uint64_t key = ps->rng_key[p];
    uint32_t depth = ps->depth[p];
    RngStream stream = rng_stream(key, depth, RNG_STREAM_INSCATTER + (ps->crossings[p] << 8));
    float u0 = rng_stream_next(&stream), u1 = rng_stream_next(&stream), u_medium = rng_stream_next(&stream);
    float u_light[6];
    for (int k = 0; k < 6; ++k) u_light[k] = rng_stream_next(&stream);
    float pdf;
    float t = volume_distance_sample(tab, u0, u1, &pdf);
    *cost = 0.0f;
    if (!(pdf > 0.0f)) return 0.0f;
    vec3 x = v3_madd(ray.org, ray.dir, t);
    const float xf[3] = {x.x, x.y, x.z};

    /* the scattering coefficients at x_k; one medium's phase function, picked in proportion
     * to lum(sigma_s) as the null-collision walk picks it */
    vec3 sigma_s[VOLUME_MAX_OVERLAP], sum = v3s(0.0f);
    float lum[VOLUME_MAX_OVERLAP], lsum = 0.0f;
    for (int i = 0; i < view->count; ++i) {
        MediumCoefficients c;
        medium_eval(view->media[i], xf, &c);
        sigma_s[i] = v3(c.sigma_s[0], c.sigma_s[1], c.sigma_s[2]);
        lum[i] = fmaxf(v3_luminance(sigma_s[i]), 0.0f);
        sum = v3_add(sum, sigma_s[i]);
        lsum += lum[i];
    }
    if (!(lsum > 0.0f)) return 0.0f; /* nothing scatters at x_k: the integrand is 0 */
    int pick = -1;
    float target = u_medium * lsum;
    for (int i = 0; i < view->count; ++i) {
        if (!(lum[i] > 0.0f)) continue;
        pick = i;
        if (target < lum[i]) break;
        target -= lum[i];
    }

    /* ratio tracking to x_k: the transmittance and the null vertices' product of Eq. 10 */
    VolumeRng rng = {rng_stream_next_cb, &stream};
    const float o[3] = {ray.org.x, ray.org.y, ray.org.z}, d[3] = {ray.dir.x, ray.dir.y, ray.dir.z};
    float T[3], null_mis;
    uint64_t collisions0 = s->volume.collisions;
    media_ratio_track(view, o, d, 0.0f, t, &rng, T, &null_mis, &s->volume);
    *cost = 0.1f * (float)(s->volume.collisions - collisions0);
    if (T[0] == 0.0f && T[1] == 0.0f && T[2] == 0.0f) return 0.0f;
    float r = null_mis * (sum.x + sum.y + sum.z) * (1.0f / 3.0f);
    float w = pdf / (pdf + r); /* balance heuristic, Eq. 10 */
    vec3 beta = v3_mul(ps->throughput[p], v3_mul(v3(T[0], T[1], T[2]), sigma_s[pick]));
    beta = v3_scale(beta, w * (lsum / lum[pick]) / pdf);
    if (!v3_is_finite(beta) || v3_is_black(beta)) return 0.0f;

    /* NEE at x_k: the light sampler's fluence context, the phase function, a shadow ray */
    Scatter sc;
    scatter_init_phase(&sc, view->media[pick]->g, v3_neg(ray.dir));
    LightSampleContext lc = {x, v3s(0.0f), {0, 0.0f}, scratch};
    light_sampler_prepare(ig->light_sampler, &lc, hint);
    LightLiSample ls;
    vec3 contrib;
    uint32_t outcome;
    float visibility = 0.0f, added = 0.0f;
    if (direct_light_sample_u(ig, beta, &sc, &lc, u_light, &ls, &contrib, &outcome)) {
        float tfar = isinf(ls.distance) ? INFINITY : ls.distance * (1.0f - 1e-3f);
        s->shadow_rays++;
        *cost += 1.0f;
        if (scene_visible1(ig->scene, (SceneRay){x, 0.0f, ls.wi, tfar})) {
            RngStream sh = rng_stream(key, depth, RNG_STREAM_INSCATTER_SHADOW + (ps->crossings[p] << 8));
            VolumeRng shr = {rng_stream_next_cb, &sh};
            uint64_t c0 = s->volume.collisions;
            vec3 Ts = media_transmittance_segment(ig->media, ps->medium[p], x, ls.wi, tfar, &shr, &s->volume);
            *cost += 0.1f * (float)(s->volume.collisions - c0);
            visibility = clampf(v3_average(Ts), 0.0f, 1.0f);
            vec3 c = v3_mul(contrib, Ts);
            path_add_radiance(ps, p, c, RADIANCE_DIRECT);
            added = v3_luminance(c);
        }
    }
    light_sampler_record(ig->light_sampler, outcome, visibility);
    return added;
}

/* ---------------------------------------------------------------- auto (the paper's §5.2.3 wish) */

/* The paper's renderer leaves these features off by default because they raise the cost per
 * sample (§5.2.3) and names an automatic choice as wanted. auto measures, per medium, during
 * the first INSCATTER_PROBE_ITERATIONS iterations (2 spp) with the technique on everywhere:
 * over the paths whose camera ray crossed the medium, the variance of the path's radiance
 * (luminance), of the camera segment's NEE by tracking alone (unweighted: what it is without
 * the technique) and by both (MIS-weighted), the technique's cost per path and the cost of a
 * path (rays + collisions / 10: deterministic counts, not clocks, so the choice and the image
 * never depend on timing or threads). The rest of the pixel's variance is V_path - V_both, so
 * the technique stays on where
 *     (V_rest + V_both) C  <  (V_rest + V_tracking) (C - C_technique),
 * i.e. where it lowers the time-to-unit-variance estimate. Sums run in path order. */
#define INSCATTER_PROBE_ITERATIONS 3 /* 1 + 1 + 2 spp: the first sets the clamp, the others measure */
#define INSCATTER_PROBE_CLAMP 16.0   /* x the first iteration's mean path radiance */

/* Near a point light inside a thin medium both techniques' NEE has a 1/r^2 tail, and a few
 * paths of the probe decide its sample variances: the decision then is a coin toss. The
 * statistics are taken over values clamped at 16x the mean radiance of the medium's paths in
 * the first probe iteration, which measures what each technique does for the bulk of the
 * pixels (the clamp is only in the decision, never in the image). */
typedef struct InscatterProbe {
    double n, null_sum, null_sum2, mis_sum, mis_sum2, path_sum, path_sum2, cost;
    double first_n, first_sum, clamp;
} InscatterProbe;

int inscatter_segment_on(const Integrator *ig, const MediaView *view) {
    if (ig->inscatter_probe) return 1;
    for (int i = 0; i < view->count; ++i)
        if (ig->inscatter_on[media_id(ig->media, view->media[i])]) return 1;
    return 0;
}

static double variance(double n, double sum, double sum2) {
    return n > 1.0 ? fmax((sum2 - sum * sum / n) / (n - 1.0), 0.0) : 0.0;
}

static void inscatter_auto_barrier(void *user) {
    Integrator *ig = user;
    if (!ig->inscatter_probe) return;
    if (++ig->probe_iterations == 1) { /* the clamp from the first iteration */
        for (uint32_t m = 0; m < media_count(ig->media); ++m) {
            InscatterProbe *P = &ig->probe[m];
            P->clamp = P->first_n > 0.0 ? INSCATTER_PROBE_CLAMP * P->first_sum / P->first_n : 0.0;
        }
        return;
    }
    if (ig->probe_iterations < INSCATTER_PROBE_ITERATIONS) return;
    ig->inscatter_probe = 0;
    double C = ig->probe_paths > 0.0 ? ig->probe_cost / ig->probe_paths : 0.0;
    for (uint32_t m = 0; m < media_count(ig->media); ++m) {
        const InscatterProbe *P = &ig->probe[m];
        if (P->n < 2.0) { ig->inscatter_on[m] = 0; continue; } /* no camera ray crossed it */
        double v_path = variance(P->n, P->path_sum, P->path_sum2);
        double v_both = variance(P->n, P->mis_sum, P->mis_sum2);
        double v_track = variance(P->n, P->null_sum, P->null_sum2);
        double v_rest = fmax(v_path - v_both, 0.0), c_tech = P->cost / P->n;
        double ttuv_on = (v_rest + v_both) * C, ttuv_off = (v_rest + v_track) * fmax(C - c_tech, 1e-9);
        ig->inscatter_on[m] = ttuv_on < ttuv_off;
        if (!ig->opt->quiet)
            fprintf(stderr, "candela: --volume-cachepoint-scatter auto: medium %u %s (estimated time to unit variance x%.2f)\n",
                    m, ig->inscatter_on[m] ? "on" : "off", ttuv_off > 0.0 ? ttuv_on / ttuv_off : 1.0);
    }
}

void inscatter_probe_batch(Integrator *ig, const Slice *slices, uint32_t n) {
    if (!ig->inscatter_probe) return;
    const PathState *ps = &ig->ps;
    int first = ig->probe_iterations == 0;
    for (uint32_t k = 0; k < n; ++k)
        ig->probe_cost += (double)(slices[k].bounce_rays + slices[k].shadow_rays) + 0.1 * (double)slices[k].volume.collisions;
    ig->probe_cost += ig->batch_count; /* the camera rays */
    ig->probe_paths += ig->batch_count;
    for (uint32_t p = 0; p < ig->batch_count; ++p) {
        if (!ps->probe_medium[p]) continue;
        InscatterProbe *P = &ig->probe[ps->probe_medium[p] - 1];
        double L = v3_luminance(ps->radiance[p]), a = ps->probe_null[p], b = ps->probe_mis[p];
        if (!isfinite(L) || !isfinite(a) || !isfinite(b)) continue;
        if (first) {
            P->first_n += 1.0;
            P->first_sum += L;
            continue;
        }
        L = fmin(L, P->clamp);
        a = fmin(a, P->clamp);
        b = fmin(b, P->clamp);
        P->n += 1.0;
        P->path_sum += L; P->path_sum2 += L * L;
        P->null_sum += a; P->null_sum2 += a * a;
        P->mis_sum += b; P->mis_sum2 += b * b;
        P->cost += ps->probe_cost[p];
    }
}

int inscatter_init(Integrator *ig, int mode) {
    uint32_t n = media_count(ig->media);
    ig->inscatter_on = calloc(n + 1, 1);
    ig->probe = calloc(n + 1, sizeof *ig->probe);
    if (!ig->inscatter_on || !ig->probe) return -1;
    if (mode == 1) memset(ig->inscatter_on, 1, n);
    if (mode == 2) {
        ig->inscatter_probe = 1;
        integrator_add_barrier_hook(ig, inscatter_auto_barrier, ig);
    }
    return 0;
}

void inscatter_free(Integrator *ig) {
    free(ig->inscatter_on);
    free(ig->probe);
    ig->inscatter_on = NULL;
    ig->probe = NULL;
}
