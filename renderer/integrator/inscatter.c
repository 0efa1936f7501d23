/* renderer/integrator/inscatter.c: cache-point in-scattering sampling (the cache points paper §4.2; the
 * spec's §7.2-7.3).
 *
 * Along a camera ray's segment through media, null-collision tracking finds the first
 * scattering vertex with a density that follows the extinction: in a thin medium around a
 * bright light it rarely scatters where the light is. The cache points know where in-scattered
 * light is strong (their scattering weights, computed in the build), so a second technique
 * draws the vertex's distance from a piecewise-linear density through the weights of the
 * nearest cache points along the segment (stations one radius of influence apart, at most INSCATTER_STATIONS,
 * plus a defensive uniform part), ratio-tracks the transmittance to it and does NEE there.
 * Both techniques estimate the single-scattered direct light of the segment; each weighs its
 * sample by the balance heuristic over the pair with the density ratio of Eq. 10 (corrected in
 * the spec): p_null / p_cachepoint = [product over the null vertices of mean(sigma_n) / sigma_maj]
 * x mean(sigma_s(x_k)) / p_select(x_k), the same function of the vertices in both (the
 * trackers report the product). The phase-sampled continuation and everything after the first
 * scatter stay with the null-collision walk. Whether a segment uses the technique (on, off, or
 * auto's choice per medium) is volume_auto.c's. */
#include "integrator.h"
#include "rng.h"
#include "vertex.h"
#include "inscatter.h"
#include "volume_auto.h"

#define INSCATTER_STATIONS 16 /* torch_mist, 160x90: 64 cost 0.07 G instructions per spp more (+14%) at the same variance */
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
    LightSampleContext lc = {x, v3s(0.0f), {0, 0.0f}, scratch, &s->volume};
    lc.link_class = lights_media_class(ig->lights); /* a medium vertex belongs to no object */
    light_sampler_prepare(ig->light_sampler, &lc, hint);
    LightLiSample ls;
    vec3 contrib;
    uint32_t outcome;
    float visibility = 0.0f, added = 0.0f;
    int sampled = vertex_direct_light_u(ig, beta, &sc, &lc, u_light, &ls, &contrib, &outcome);
    if (sampled) {
        float tfar = isinf(ls.distance) ? INFINITY : ls.distance * (1.0f - 1e-3f);
        s->shadow_rays++;
        *cost += 1.0f;
        if (scene_visible1_masked(ig->scene, (SceneRay){x, 0.0f, ls.wi, tfar}, lights_shadow_mask(ig->lights, ls.light))) {
            RngStream sh = rng_stream(key, depth, RNG_STREAM_INSCATTER_SHADOW + (ps->crossings[p] << 8));
            VolumeRng shr = {rng_stream_next_cb, &sh};
            uint64_t c0 = s->volume.collisions;
            vec3 Ts = media_transmittance_segment(ig->media, ps->medium[p], x, ls.wi, tfar, &shr, &s->volume);
            *cost += 0.1f * (float)(s->volume.collisions - c0);
            visibility = clampf(v3_average(Ts), 0.0f, 1.0f);
            vec3 c = v3_mul(contrib, Ts);
            path_add_radiance(ig, p, c, RADIANCE_DIRECT, depth);
            added = v3_luminance(c);
        }
    }
    emission_probe_nee(ig, p, ls.light, added, ls.cost + (sampled ? 1.0f : 0.0f));
    light_sampler_record(ig->light_sampler, outcome, visibility);
    return added;
}
