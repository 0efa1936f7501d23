/* cachepoints/scatter.c: the scattering sample weights of cache-point in-scattering sampling
 * (§4.2). While the build has each point's light lists, s(p, e) approximates the radiance
 * the medium around p scatters toward the camera from light e,
 *     s(p, e) ~ integral of mu_s(y) L_e(y, w') rho(y, w_camera, w') dw',
 * y a random point in p's radius of influence, w' toward a random point of e, w_camera toward
 * the camera (the spec's §7.2 proposal: 4 points y uniform in the ball of radius r_p, one light
 * sample each, unoccluded, luminance). It is kept per near light; the far lists' part is one
 * number per point, estimated by drawing far entries from the fluence bin (clusters descend
 * the light tree) so no point ever visits every light. The render sums them per point
 * (cachepoints_scatter_total) into the stations of a distance distribution along camera rays. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "internal.h"

#define SCATTER_POINTS 4      /* y samples per point (spec §7.2) */
#define SCATTER_FAR_SAMPLES 8 /* far-entry draws per point */

/* A counter-based uniform in [0, 1) keyed by (seed, point, index): the weights do not depend
 * on the thread count. */
static float scatter_uniform(uint64_t seed, uint32_t point, uint32_t index) {
    uint64_t z = seed ^ ((uint64_t)point << 20 | index) * 0x9e3779b97f4a7c15ull;
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    z ^= z >> 31;
    return (float)(z >> 40) * 0x1.0p-24f;
}

typedef struct ScatterCtx {
    CachePoints *cp;
    const CachePointLights *lights;
    const CachePointScatter *sc;
} ScatterCtx;

/* y uniform in the ball of radius r around c (cube root of u for the radius). */
static void ball_point(const float c[3], float r, float u0, float u1, float u2, float y[3]) {
    float z = 1.0f - 2.0f * u0, s = sqrtf(fmaxf(0.0f, 1.0f - z * z)), phi = 6.2831853f * u1;
    float rr = r * cbrtf(u2);
    y[0] = c[0] + rr * s * cosf(phi);
    y[1] = c[1] + rr * s * sinf(phi);
    y[2] = c[2] + rr * z;
}

static void scatter_range(void *vctx, size_t b, size_t e, int thread) {
    (void)thread;
    const ScatterCtx *ctx = vctx;
    CachePoints *cp = ctx->cp;
    const CachePointLights *L = ctx->lights;
    const CachePointScatter *sc = ctx->sc;
    for (size_t pi = b; pi < e; ++pi) {
        uint32_t p = (uint32_t)pi;
        float y[SCATTER_POINTS][3], mu[SCATTER_POINTS], g[SCATTER_POINTS];
        int any = 0;
        for (int j = 0; j < SCATTER_POINTS; ++j) {
            ball_point(cp->pos + 3 * (size_t)p, cp->radius[p], scatter_uniform(sc->seed, p, 3 * j),
                       scatter_uniform(sc->seed, p, 3 * j + 1), scatter_uniform(sc->seed, p, 3 * j + 2), y[j]);
            g[j] = 0.0f;
            mu[j] = sc->medium(sc->user, y[j], &g[j]);
            if (!(mu[j] > 0.0f) || !isfinite(mu[j])) mu[j] = 0.0f;
            any |= mu[j] > 0.0f;
        }
        float total = 0.0f;
        /* near lights: s(p, e) each */
        for (uint32_t k = cp->near_off[p]; k < cp->near_off[p + 1]; ++k) {
            float s = 0.0f;
            for (int j = 0; j < SCATTER_POINTS && any; ++j) {
                if (mu[j] == 0.0f) continue;
                float u[4];
                for (int q = 0; q < 4; ++q) u[q] = scatter_uniform(sc->seed, p, 16 + 4 * (uint32_t)j + (uint32_t)q);
                float v = sc->light_sample(sc->user, cp->near_light[k], y[j], g[j], u);
                if (v > 0.0f && isfinite(v)) s += mu[j] * v;
            }
            cp->scatter_near[k] = s / SCATTER_POINTS;
            total += cp->scatter_near[k];
        }
        /* far entries: sum over their lights of s, estimated by drawing entries from the
         * fluence bin's running sums (and a light below a cluster from the tree) */
        float far = 0.0f;
        uint32_t f0 = cp->far_off[p], nf = cp->far_off[p + 1] - f0;
        float ft = cp->far_bin_total[(size_t)p * CP_BIN_STRIDE + CP_OMNI_BIN];
        if (any && nf > 0 && ft > 0.0f) {
            const float *cum = cp_cdf(cp, p, CP_OMNI_BIN, f0);
            for (int j = 0; j < SCATTER_FAR_SAMPLES; ++j) {
                int yj = j % SCATTER_POINTS;
                if (mu[yj] == 0.0f) continue;
                float target = scatter_uniform(sc->seed, p, 64 + 8 * (uint32_t)j) * ft;
                uint32_t lo = 0, hi = nf - 1;
                while (lo < hi) {
                    uint32_t mid = lo + (hi - lo) / 2;
                    if (cum[mid] > target) hi = mid;
                    else lo = mid + 1;
                }
                float w = lo > 0 ? cum[lo] - cum[lo - 1] : cum[0];
                if (!(w > 0.0f)) continue;
                float pmf = w / ft;
                uint32_t key = cp->far[f0 + lo].key, light = cp_key_light(cp, key);
                if (light == CP_NONE) {
                    float dp = 0.0f;
                    light = L->tree->descend(L->user, key, y[yj], NULL, scatter_uniform(sc->seed, p, 65 + 8 * (uint32_t)j), &dp);
                    if (!(dp > 0.0f)) continue;
                    pmf *= dp;
                }
                float u[4];
                for (int q = 0; q < 4; ++q) u[q] = scatter_uniform(sc->seed, p, 66 + 8 * (uint32_t)j + (uint32_t)q);
                float v = sc->light_sample(sc->user, light, y[yj], g[yj], u);
                if (v > 0.0f && isfinite(v)) far += mu[yj] * v / pmf;
            }
            far /= SCATTER_FAR_SAMPLES;
        }
        cp->scatter_far[p] = far;
        cp->scatter_total[p] = total + far;
    }
}

int cachepoints_build_scatter(CachePoints *cp, const CachePointLights *lights, const CachePointScatter *sc) {
    if (!cp || !lights || !sc || !sc->medium || !sc->light_sample) return -2;
    size_t nn = cp->near_off[cp->n];
    free(cp->scatter_near); free(cp->scatter_far); free(cp->scatter_total);
    cp->scatter_near = calloc(nn + 1, sizeof(float));
    cp->scatter_far = calloc((size_t)cp->n + 1, sizeof(float));
    cp->scatter_total = calloc((size_t)cp->n + 1, sizeof(float));
    if (!cp->scatter_near || !cp->scatter_far || !cp->scatter_total) {
        free(cp->scatter_near); free(cp->scatter_far); free(cp->scatter_total);
        cp->scatter_near = cp->scatter_far = cp->scatter_total = NULL;
        return -1;
    }
    ScatterCtx ctx = {cp, lights, sc};
    cp_run_parallel(&cp->params, cp->n, 64, scatter_range, &ctx);
    cp->stats.bytes += (nn + 2 * (size_t)cp->n) * sizeof(float);
    return 0;
}

float cachepoints_scatter_total(const CachePoints *cp, uint32_t point) {
    return cp->scatter_total && point < cp->n ? cp->scatter_total[point] : 0.0f;
}

float cachepoints_scatter_weight(const CachePoints *cp, uint32_t point, uint32_t light) {
    if (!cp->scatter_near || point >= cp->n) return 0.0f;
    for (uint32_t k = cp->near_off[point]; k < cp->near_off[point + 1]; ++k)
        if (cp->near_light[k] == light) return cp->scatter_near[k];
    return -1.0f;
}

float cachepoints_scatter_far(const CachePoints *cp, uint32_t point) {
    return cp->scatter_far && point < cp->n ? cp->scatter_far[point] : 0.0f;
}

uint32_t cachepoints_nearest_hint(const CachePoints *cp, const float x[3], uint32_t hint, float *radius) {
    uint32_t p = cp_nearest_point(cp, x, hint);
    if (radius) *radius = cp->radius[p];
    return p;
}
