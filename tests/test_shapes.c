/* tests/test_shapes.c: light shapes (README "Light shapes"): spheres (point and spot lights with
 * extras.candela_light.radius), suns (angle), rect and disk area lights (candela_area_light).
 *
 * Usage: test_shapes SCENES_DIR   (the scenes come from scenes/make_scenes.py light_shapes())
 *
 * 1. Light level, on shapes_mix.gltf (RAW units), per shape light and receiver (outside, near,
 *    inside a sphere, behind a one-sided light):
 *    - every NEE sample (light_sample_li) is found again by a ray along its direction
 *      (light_shape_hit: same distance, same radiance) with the same pdf (light_shape_pdf_li,
 *      the MIS pdf of BSDF hits), relative 1e-3;
 *    - the pdf integrates to 1 over the directions that reach the light (Monte Carlo over a cone
 *      that bounds the light, 5 standard errors);
 *    - irradiance three ways: NEE alone, BSDF (cosine) sampling with light_shape_hit alone, and
 *      their power-heuristic MIS (which is unbiased only if the pdf of a BSDF hit is the density
 *      NEE really has), each against the closed form: a sphere with its normal towards it and
 *      wholly above the horizon E = I cos(beta) / d^2 (a spot's falloff from the centre), a sun
 *      E_perp cos(tilt), a circular disk parallel to the receiver (coaxial or offset:
 *      F = (1 - (r^2 + h^2 - a^2) / sqrt((r^2 + h^2 + a^2)^2 - 4 r^2 a^2)) / 2, E = pi L F), rects
 *      and the ellipse by Lambert's polygon formula (the ellipse as a 4096-gon); 5 sigma + 1e-4.
 * 2. Every light sampler (uniform, power, tree, optimal, cache points): pmfs sum to 1 and a light
 *    that contributes at a receiver (an NEE sample with a non-zero contribution) has pmf > 0 there
 *    (the tree's bounds must be conservative for spheres, rects and disks).
 * 3. Renders against closed forms (test_analytic's method: pixel footprints integrated 16x16, 6
 *    sigma per pixel for 99% of them, the image mean within 5 standard errors): sphere_plane,
 *    sun_plane (and with --light-model blender3: Cycles 3.4's 2 cos h / (1 + cos h) of it),
 *    rect_plane (with a back-facing rect), disk_plane; the light samplers agree on
 *    shapes_mix (glossy plane, every shape: z statistics against uniform); lamp_slab: a sphere
 *    light inside a thin slab lights the plane below (lamp_slab_point, radius 0: black);
 *    shapes_mix bit-identical for 1 and 2 threads (tree and cache points).
 * 4. Above LIGHT_SHAPE_BVH_MIN shapes (shapes_many: 40 and a sun), the BVH finds exactly the
 *    crossings the list does (same lights, t and radiance, bit for bit, 200000 random rays); the
 *    tree and cache points agree with uniform there, and it renders the same on 1 and 2 threads. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "candela.h"
#include "check.h"
#include "light_sampler.h"
#include "rng.h"
#include "sampling.h"
#include "scene.h"
#include "threads.h"

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

static const char *g_dir = ".";

/* ------------------------------------------------------------------ closed forms */

/* Lambert's polygon formula: irradiance at p (normal n) from a polygon of radiance L, vertices
 * in order (either winding; the light's one-sidedness is the caller's business). */
static double polygon_irradiance(const double (*v)[3], int nv, const double p[3], const double n[3], double L) {
    double sum = 0.0;
    for (int i = 0; i < nv; ++i) {
        const double *a0 = v[i], *b0 = v[(i + 1) % nv];
        double a[3], b[3], la = 0, lb = 0;
        for (int k = 0; k < 3; ++k) { a[k] = a0[k] - p[k]; b[k] = b0[k] - p[k]; la += a[k] * a[k]; lb += b[k] * b[k]; }
        la = sqrt(la); lb = sqrt(lb);
        for (int k = 0; k < 3; ++k) { a[k] /= la; b[k] /= lb; }
        double cr[3] = {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
        double cl = sqrt(cr[0] * cr[0] + cr[1] * cr[1] + cr[2] * cr[2]);
        if (!(cl > 0)) continue;
        double ang = atan2(cl, a[0] * b[0] + a[1] * b[1] + a[2] * b[2]);
        sum += ang * (cr[0] * n[0] + cr[1] * n[1] + cr[2] * n[2]) / cl;
    }
    return 0.5 * L * fabs(sum);
}

/* A planar light (rect or ellipse) as a polygon, in double. */
static int light_polygon(const Light *l, double (*v)[3], int max) {
    double c[3] = {l->position.x, l->position.y, l->position.z};
    double u[3] = {l->axis_u.x, l->axis_u.y, l->axis_u.z}, w[3] = {l->axis_v.x, l->axis_v.y, l->axis_v.z};
    int n = l->type == LIGHT_RECT ? 4 : max;
    for (int i = 0; i < n; ++i) {
        double a, b;
        if (l->type == LIGHT_RECT) {
            static const double s[4][2] = {{-1, -1}, {1, -1}, {1, 1}, {-1, 1}};
            a = s[i][0]; b = s[i][1];
        } else {
            double t = 2 * M_PI * i / n;
            a = cos(t); b = sin(t);
        }
        for (int k = 0; k < 3; ++k) v[i][k] = c[k] + a * u[k] + b * w[k];
    }
    return n;
}

/* ------------------------------------------------------------------ light level */

typedef struct Receiver { vec3 p, n; const char *what; int closed; } Receiver;

/* The exact irradiance (red channel) at r from light l, or NAN when no closed form applies. */
static double exact_irradiance(const Light *l, const Receiver *r) {
    vec3 to = v3_sub(l->position, r->p);
    double d = v3_length(to);
    switch (l->type) {
    case LIGHT_POINT:
    case LIGHT_SPOT: {
        double sin_max = l->radius / d, cb = v3_dot(v3_scale(to, (float)(1.0 / d)), r->n);
        double half = l->sphere_disk ? atan(l->radius / d) : asin(fmin(sin_max, 1.0));
        if ((!l->sphere_disk && !(sin_max < 1.0)) || acos(fmin(cb, 1.0)) + half >= 0.5 * M_PI) return NAN;
        double I = l->intensity.x;
        if (l->type == LIGHT_SPOT) I *= light_spot_falloff(l, v3_scale(to, (float)(-1.0 / d)));
        /* Cycles 3.4's disk facing p: a cone of tan = r / d, E = pi L sin^2 cos = I cos / (r^2 + d^2) */
        return l->sphere_disk ? I * cb / (l->radius * l->radius + d * d) : I * cb / (d * d);
    }
    case LIGHT_DIRECTIONAL: {
        double h = acos(1.0 - l->sun_omc), ct = -v3_dot(l->direction, r->n);
        if (acos(fmin(ct, 1.0)) + h >= 0.5 * M_PI) return NAN;
        return l->intensity.x * ct;
    }
    case LIGHT_RECT:
    case LIGHT_DISK: {
        /* one-sided: nothing behind; the polygon must lie above the receiver's horizon */
        if (v3_dot(v3_sub(r->p, l->position), l->direction) <= 0.0f) return 0.0;
        static double v[4096][3];
        int nv = light_polygon(l, v, 4096);
        double p[3] = {r->p.x, r->p.y, r->p.z}, n[3] = {r->n.x, r->n.y, r->n.z};
        for (int i = 0; i < nv; ++i)
            if ((v[i][0] - p[0]) * n[0] + (v[i][1] - p[1]) * n[1] + (v[i][2] - p[2]) * n[2] <= 0.0) return NAN;
        double E = polygon_irradiance(v, nv, p, n, l->emission.x);
        /* a circle parallel to the receiver: the differential-element form factor as well */
        double au = v3_length(l->axis_u), av = v3_length(l->axis_v);
        if (l->type == LIGHT_DISK && fabs(au - av) < 1e-6 * au && fabs(v3_dot(l->direction, r->n) + 1.0f) < 1e-6f) {
            double h = v3_dot(v3_sub(r->p, l->position), l->direction);
            vec3 off = v3_sub(v3_sub(r->p, l->position), v3_scale(l->direction, (float)h));
            double rr = v3_dot(off, off), a2 = au * au, h2 = h * h;
            double F = 0.5 * (1.0 - (rr + h2 - a2) / sqrt((rr + h2 + a2) * (rr + h2 + a2) - 4.0 * rr * a2));
            double Ed = M_PI * l->emission.x * F;
            CHECK(fabs(Ed - E) <= 1e-4 * Ed, "disk: the form factor %.8g and the 4096-gon %.8g disagree", Ed, E);
            return Ed;
        }
        return E;
    }
    default:
        return NAN;
    }
}

typedef struct Acc { double sum, sum2; long n; } Acc;
static void acc_add(Acc *a, double x) { a->sum += x; a->sum2 += x * x; ++a->n; }
static double acc_mean(const Acc *a) { return a->sum / (double)a->n; }
static double acc_se(const Acc *a) {
    double m = acc_mean(a), var = a->sum2 / (double)a->n - m * m;
    return sqrt(fmax(var, 0.0) / (double)a->n);
}

static void check_light_receiver(const Lights *ls, uint32_t li, const Receiver *r, uint64_t seed) {
    const Light *l = &ls->lights[li];
    const int N = 200000;
    char name[128];
    snprintf(name, sizeof name, "light %u (type %d) at %s", li, (int)l->type, r->what);
    LightSampleContext ctx = {r->p, r->n};
    Acc nee = {0}, hit = {0}, mis = {0}, norm = {0};
    int mismatched = 0, unfound = 0, samples = 0;
    Frame f = frame_from_normal(r->n);
    /* the cone that bounds the light from p (for the pdf's integral) */
    vec3 axis;
    float cos_bound;
    if (l->type == LIGHT_DIRECTIONAL) {
        axis = v3_neg(l->direction);
        cos_bound = 1.0f - 2.5f * l->sun_omc;
    } else {
        float R = l->type == LIGHT_RECT ? v3_length(v3_add(v3_scale(l->axis_u, 1.0f), l->axis_v)) * 1.01f
                  : l->type == LIGHT_DISK ? fmaxf(v3_length(l->axis_u), v3_length(l->axis_v)) * 1.01f
                                          : l->radius * 1.01f;
        vec3 to = v3_sub(l->position, r->p);
        float d = v3_length(to);
        axis = v3_scale(to, 1.0f / d);
        cos_bound = R < d ? sqrtf(1.0f - (R / d) * (R / d)) : -1.0f;
    }
    Frame fa = frame_from_normal(axis);
    for (int s = 0; s < N; ++s) {
        uint64_t key = rng_path_key(seed, li, (uint64_t)s);
        float u[6];
        for (int k = 0; k < 6; ++k) u[k] = rng_uniform(key, (uint32_t)k);
        /* NEE */
        LightLiSample ss;
        double e_nee = 0.0, e_mis_nee = 0.0;
        if (light_sample_li(ls, l, &ctx, u[0], u[1], u[2], u[3], &ss)) {
            ++samples;
            float t;
            vec3 le;
            float tmax = isinf(ss.distance) ? INFINITY : ss.distance * 1.01f;
            if (!light_shape_hit(l, r->p, ss.wi, 0.0f, tmax, r->p, &t, &le)) {
                ++unfound;
            } else {
                float pdf = light_shape_pdf_li(l, r->p, ss.wi, t);
                int same_t = isinf(ss.distance) ? isinf(t) : fabsf(t - ss.distance) <= 1e-3f * ss.distance;
                if (!same_t || !(fabsf(pdf - ss.pdf) <= 1e-3f * ss.pdf) || !(fabsf(le.x - ss.radiance.x) <= 1e-4f * ss.radiance.x))
                    ++mismatched;
            }
            double c = fmax(0.0, v3_dot(ss.wi, r->n));
            e_nee = ss.radiance.x * c / ss.pdf;
            double pb = c / M_PI;
            e_mis_nee = e_nee * ss.pdf * ss.pdf / (ss.pdf * ss.pdf + pb * pb);
        }
        acc_add(&nee, e_nee);
        /* BSDF-like: cosine sampling, E = pi E_cos[L] */
        vec3 d = frame_to_world(&f, sample_cosine_hemisphere(u[4], u[5]));
        double e_hit = 0.0, e_mis_hit = 0.0;
        float t;
        vec3 le;
        if (light_shape_hit(l, r->p, d, 0.0f, INFINITY, r->p, &t, &le)) {
            double pb = fmax(0.0, v3_dot(d, r->n)) / M_PI;
            double pl = light_shape_pdf_li(l, r->p, d, t);
            e_hit = le.x * M_PI;
            e_mis_hit = e_hit * pb * pb / (pb * pb + pl * pl);
        }
        acc_add(&hit, e_hit);
        acc_add(&mis, e_mis_nee + e_mis_hit);
        /* the pdf's integral over a bounding cone */
        vec3 dc = frame_to_world(&fa, sample_uniform_cone(u[2], u[3], cos_bound));
        double val = 0.0;
        if (light_shape_hit(l, r->p, dc, 0.0f, INFINITY, r->p, &t, &le))
            val = light_shape_pdf_li(l, r->p, dc, t) * 2.0 * M_PI * (1.0 - (double)cos_bound);
        acc_add(&norm, val);
    }
    /* a sample on the very rim may round to just outside it (1e-4 of them at most) */
    CHECK(unfound <= samples / 10000 && mismatched == 0, "%s: of %d NEE samples %d not found by a ray, %d with another t/pdf/radiance",
          name, samples, unfound, mismatched);
    double ex = exact_irradiance(l, r);
    fprintf(stderr, "  %-34s E exact %-10.6g NEE %.6g (+-%.2g) hit %.6g (+-%.2g) MIS %.6g (+-%.2g); pdf integral %.4f (+-%.4f)\n",
            name, ex, acc_mean(&nee), acc_se(&nee), acc_mean(&hit), acc_se(&hit), acc_mean(&mis), acc_se(&mis),
            acc_mean(&norm), acc_se(&norm));
    if (samples > 0)
        CHECK(fabs(acc_mean(&norm) - 1.0) <= 5.0 * acc_se(&norm) + 1e-4, "%s: the pdf integrates to %.5f (+-%.5f)", name,
              acc_mean(&norm), acc_se(&norm));
    const Acc *est[3] = {&nee, &hit, &mis};
    const char *est_name[3] = {"NEE", "BSDF hits", "MIS"};
    for (int k = 0; k < 3; ++k) {
        double ref = isnan(ex) ? acc_mean(&nee) : ex;
        double se = isnan(ex) ? sqrt(acc_se(&nee) * acc_se(&nee) + acc_se(est[k]) * acc_se(est[k])) : acc_se(est[k]);
        if (isnan(ex) && k == 0) continue;
        CHECK(fabs(acc_mean(est[k]) - ref) <= 5.0 * se + 1e-4 * fabs(ref) + 1e-9,
              "%s: %s irradiance %.6g (+-%.2g), expected %.6g%s", name, est_name[k], acc_mean(est[k]), acc_se(est[k]),
              ref, isnan(ex) ? " (NEE)" : "");
    }
    if (r->closed) CHECK(!isnan(ex), "%s: no closed form applies (the test's receiver is misplaced)", name);
}

static int load_lights(const char *file, Scene *scene, Lights *lights, CandelaOptions *o, CandelaLightModel model) {
    static char path[4096];
    snprintf(path, sizeof path, "%s/%s", g_dir, file);
    candela_options_default(o);
    o->light_model = model;
    o->scene_path = path;
    o->light_units = CANDELA_LIGHT_UNITS_RAW;
    o->width = o->height = 16;
    char err[CANDELA_ERR_LEN];
    int rc = scene_load(scene, o, err);
    CHECK(rc == 0, "%s", err);
    if (rc != 0) return -1;
    rc = lights_build(lights, scene, NULL, o->light_units, err, sizeof err);
    CHECK(rc == 0, "%s", err);
    if (rc != 0) { scene_free(scene); return -1; }
    return 0;
}

static uint32_t find_light(const Lights *ls, LightType type, int spot_or_ellipse) {
    for (uint32_t i = 0; i < ls->count; ++i) {
        const Light *l = &ls->lights[i];
        if (l->type != type) continue;
        if (type == LIGHT_DISK &&
            (fabsf(v3_length(l->axis_u) - v3_length(l->axis_v)) > 1e-4f) != (spot_or_ellipse != 0))
            continue;
        return i;
    }
    return UINT32_MAX;
}

static void test_light_level(void) {
    Scene scene;
    Lights ls;
    CandelaOptions o;
    if (load_lights("shapes_mix.gltf", &scene, &ls, &o, CANDELA_LIGHT_MODEL_GLTF) != 0) return;
    CHECK(ls.count == 6 && ls.num_shapes == 6, "shapes_mix: %u lights, %u shapes (want 6, 6)", ls.count, ls.num_shapes);
    uint32_t sphere = find_light(&ls, LIGHT_POINT, 0), spot = find_light(&ls, LIGHT_SPOT, 0),
             sun = find_light(&ls, LIGHT_DIRECTIONAL, 0), rect = find_light(&ls, LIGHT_RECT, 0),
             disk = find_light(&ls, LIGHT_DISK, 0), ellipse = find_light(&ls, LIGHT_DISK, 1);
    CHECK(sphere != UINT32_MAX && spot != UINT32_MAX && sun != UINT32_MAX && rect != UINT32_MAX && disk != UINT32_MAX &&
              ellipse != UINT32_MAX, "shapes_mix: a shape is missing");
    if (ls.count != 6 || sphere == UINT32_MAX || spot == UINT32_MAX || sun == UINT32_MAX || rect == UINT32_MAX ||
        disk == UINT32_MAX || ellipse == UINT32_MAX) {
        lights_free(&ls);
        scene_free(&scene);
        return;
    }
    /* sphere: facing it (closed form), tilted 30 deg, near (inside the cone's large-angle
     * branch), inside, and grazing (part of it below the horizon: NEE vs hits only) */
    const Light *ps = &ls.lights[sphere];
    vec3 c = ps->position;
    Receiver rs[] = {
        {v3_add(c, v3(0.0f, -1.0f, 0.0f)), v3(0, 1, 0), "below, facing it", 1},
        {v3_add(c, v3(0.8f, -0.6f, 0.0f)), v3_normalize(v3(-0.8f * 0.866f + 0.6f * 0.5f, 0.6f * 0.866f + 0.8f * 0.5f, 0)), "tilted 30 deg", 1},
        {v3_add(c, v3(0.0f, -0.2f, 0.0f)), v3(0, 1, 0), "0.05 from its surface", 1},
        {v3_add(c, v3(0.05f, -0.05f, 0.02f)), v3(0, 1, 0), "inside", 0},
        {v3_add(c, v3(0.0f, -0.1f, 0.4f)), v3(0, 0, -1), "grazing", 0},
    };
    for (size_t k = 0; k < sizeof rs / sizeof rs[0]; ++k) check_light_receiver(&ls, sphere, &rs[k], 100 + k);
    /* the spot sphere: inside its cone, in the blend, outside (black) */
    const Light *pp = &ls.lights[spot];
    Receiver rp[] = {
        {v3_madd(pp->position, pp->direction, 1.0f), v3_neg(pp->direction), "on the spot's axis", 1},
        {v3_add(v3_madd(pp->position, pp->direction, 1.0f), v3(0.45f, 0.0f, 0.2f)), v3_neg(pp->direction), "in the blend", 0},
        {v3_madd(pp->position, pp->direction, -1.0f), pp->direction, "behind the spot", 1},
    };
    for (size_t k = 0; k < sizeof rp / sizeof rp[0]; ++k) check_light_receiver(&ls, spot, &rp[k], 200 + k);
    /* the sun: facing it, tilted 40 deg (its cone above the horizon), at grazing tilt */
    const Light *pn = &ls.lights[sun];
    vec3 axis = v3_neg(pn->direction);
    vec3 t0, b0;
    onb_from_normal(axis, &t0, &b0);
    Receiver rn[] = {
        {v3(0, 0, 0), axis, "facing the sun", 1},
        {v3(0, 0, 0), v3_normalize(v3_add(v3_scale(axis, cosf(0.698f)), v3_scale(t0, sinf(0.698f)))), "40 deg to the sun", 1},
        {v3(0, 0, 0), v3_normalize(v3_add(v3_scale(axis, cosf(1.54f)), v3_scale(t0, sinf(1.54f)))), "sun at the horizon", 0},
    };
    for (size_t k = 0; k < sizeof rn / sizeof rn[0]; ++k) check_light_receiver(&ls, sun, &rn[k], 300 + k);
    /* rect, disk, ellipse: in front (closed forms), off to the side, behind (black) */
    uint32_t planar[3] = {rect, disk, ellipse};
    for (int q = 0; q < 3; ++q) {
        const Light *pl = &ls.lights[planar[q]];
        vec3 front = v3_madd(pl->position, pl->direction, 0.7f);
        Receiver rq[] = {
            {front, v3_neg(pl->direction), "0.7 in front, facing it", 1},
            {v3_add(front, v3_scale(v3_normalize(pl->axis_u), 0.3f)), v3_neg(pl->direction), "in front, off-axis", 1},
            {v3_madd(pl->position, pl->direction, 0.05f), v3_neg(pl->direction), "0.05 in front", 1},
            {v3_add(v3_madd(pl->position, pl->direction, 0.3f), v3_scale(pl->axis_u, 2.5f)),
             v3_normalize(v3_sub(pl->position, v3_add(v3_madd(pl->position, pl->direction, 0.3f), v3_scale(pl->axis_u, 2.5f)))),
             "to the side", 0},
            {v3_madd(pl->position, pl->direction, -0.5f), pl->direction, "behind (one-sided)", 1},
        };
        for (size_t k = 0; k < sizeof rq / sizeof rq[0]; ++k) check_light_receiver(&ls, planar[q], &rq[k], 400 + 10 * q + k);
    }

    /* every strategy: pmfs sum to 1; a light that contributes has pmf > 0 */
    ThreadPool *pool = threadpool_create(2);
    const CandelaLightSampler strategies[] = {CANDELA_LIGHT_SAMPLER_UNIFORM, CANDELA_LIGHT_SAMPLER_POWER,
                                              CANDELA_LIGHT_SAMPLER_TREE, CANDELA_LIGHT_SAMPLER_OPTIMAL,
                                              CANDELA_LIGHT_SAMPLER_CACHEPOINTS};
    for (size_t k = 0; k < sizeof strategies / sizeof strategies[0]; ++k) {
        o.light_sampler = strategies[k];
        LightSampler sampler;
        char err[CANDELA_ERR_LEN];
        int rc = light_sampler_create(&sampler, &ls, &scene, NULL, pool, &o, err);
        CHECK(rc == 0, "light sampler %s: %s", candela_light_sampler_name(strategies[k]), err);
        if (rc != 0) continue;
        int bad_sum = 0, zero_pmf = 0, points = 0;
        uint64_t key = rng_path_key(7, k, 0);
        for (int q = 0; q < 400; ++q) {
            /* points near the plane and the lights, normals anywhere in the upper hemisphere */
            vec3 p = v3(2.4f * rng_uniform(key, 6 * q) - 1.2f, 1.0f * rng_uniform(key, 6 * q + 1),
                        2.4f * rng_uniform(key, 6 * q + 2) - 1.2f);
            vec3 n = sample_cosine_hemisphere(rng_uniform(key, 6 * q + 3), rng_uniform(key, 6 * q + 4));
            n = v3(n.x, n.z, n.y);
            float scratch[LIGHT_SAMPLER_SCRATCH];
            LightSampleContext ctx = {p, n, {0, 0.0f}, scratch};
            uint32_t hint = UINT32_MAX;
            light_sampler_prepare(&sampler, &ctx, &hint);
            double sum = 0.0;
            for (uint32_t i = 0; i < ls.count; ++i) sum += light_sampler_pmf(&sampler, &ctx, i);
            bad_sum += !(fabs(sum - 1.0) < 1e-4);
            for (uint32_t i = 0; i < ls.count; ++i) {
                int contributes = 0;
                for (int s = 0; s < 64 && !contributes; ++s) {
                    LightLiSample ss;
                    uint64_t k2 = rng_path_key(8, (uint64_t)q, (uint64_t)s);
                    if (light_sample_li(&ls, &ls.lights[i], &ctx, rng_uniform(k2, 0), rng_uniform(k2, 1), 0.5f, 0.5f, &ss))
                        contributes = v3_dot(ss.wi, n) > 0.0f;
                }
                if (!contributes) continue;
                ++points;
                int zero = !(light_sampler_pmf(&sampler, &ctx, i) > 0.0f);
                zero_pmf += zero;
                if (zero && getenv("SHAPES_VERBOSE"))
                    fprintf(stderr, "    pmf 0: light %u (type %d) at (%g %g %g) n (%g %g %g)\n", i, (int)ls.lights[i].type,
                            p.x, p.y, p.z, n.x, n.y, n.z);
            }
        }
        fprintf(stderr, "  %-12s pmf sums off at %d of 400 points; %d of %d contributing (point, light) pairs with pmf 0\n",
                candela_light_sampler_name(strategies[k]), bad_sum, zero_pmf, points);
        CHECK(bad_sum == 0, "%s: the pmf does not sum to 1 at %d points", candela_light_sampler_name(strategies[k]), bad_sum);
        CHECK(zero_pmf == 0 && points > 0, "%s: %d contributing lights have pmf 0 (of %d)",
              candela_light_sampler_name(strategies[k]), zero_pmf, points);
        light_sampler_free(&sampler);
    }
    threadpool_destroy(pool);
    lights_free(&ls);
    scene_free(&scene);

    /* --light-model blender3: the point radius is Cycles 3.4's disk facing the receiver */
    if (load_lights("shapes_mix.gltf", &scene, &ls, &o, CANDELA_LIGHT_MODEL_BLENDER3) != 0) return;
    for (uint32_t li = 0; li < 2 && li < ls.count; ++li) {
        const Light *l = &ls.lights[li];
        CHECK(l->sphere_disk && l->radius > 0.0f, "blender3: light %u is not a facing disk", li);
        vec3 below = v3_add(l->position, v3(0.1f, -0.9f, 0.05f));
        Receiver rb[] = {
            {below, v3_normalize(v3_sub(l->position, below)), "blender3 disk, facing it", 1},
            {v3_add(l->position, v3(0.0f, -0.2f, 0.0f)), v3(0, 1, 0), "blender3 disk, near", 0},
            {v3_add(l->position, v3(0.02f, -0.03f, 0.0f)), v3(0, 1, 0), "blender3 disk, inside r", 0},
        };
        for (size_t k = 0; k < sizeof rb / sizeof rb[0]; ++k) check_light_receiver(&ls, li, &rb[k], 600 + 10 * li + k);
    }
    lights_free(&ls);
    scene_free(&scene);
}

/* Above LIGHT_SHAPE_BVH_MIN finite shapes, rays find them through the BVH: the crossings it
 * reports (in light order) are exactly the list's, for random rays from the plane, from inside
 * the light cluster, short and escaping. */
typedef struct Crossings { uint32_t n, light[256]; float t[256]; vec3 le[256]; } Crossings;
static void collect(void *user, uint32_t light, float t, vec3 le) {
    Crossings *c = user;
    if (c->n < 256) { c->light[c->n] = light; c->t[c->n] = t; c->le[c->n] = le; }
    ++c->n;
}

static void test_shape_bvh(void) {
    Scene scene;
    Lights ls;
    CandelaOptions o;
    if (load_lights("shapes_many.gltf", &scene, &ls, &o, CANDELA_LIGHT_MODEL_GLTF) != 0) return;
    CHECK(ls.shape_bvh != NULL && ls.num_shapes == 41 && ls.num_suns == 1, "shapes_many: %u shapes, %u suns, bvh %p",
          ls.num_shapes, ls.num_suns, ls.shape_bvh);
    uint64_t key = rng_path_key(77, 0, 0);
    int differ = 0;
    long crossings = 0;
    for (int q = 0; q < 200000; ++q) {
        float u[8];
        for (int k = 0; k < 8; ++k) u[k] = rng_uniform(key, 8 * (uint32_t)q + (uint32_t)k);
        vec3 o = q % 2 ? v3(4.0f * u[0] - 2.0f, 0.01f, 4.0f * u[1] - 2.0f) : v3(4.0f * u[0] - 2.0f, 1.5f * u[2], 4.0f * u[1] - 2.0f);
        vec3 d = sample_uniform_sphere(u[3], u[4]);
        if (q % 2) d.y = fabsf(d.y);
        float tmax = u[5] < 0.5f ? INFINITY : 3.0f * u[6];
        vec3 recv = v3_sub(o, v3_scale(d, 0.1f * u[7]));
        Crossings a = {0}, b = {0};
        lights_shape_crossings(&ls, o, d, 0.0f, tmax, recv, collect, &a);
        for (uint32_t k = 0; k < ls.num_shapes; ++k) { /* the list by hand */
            float t;
            vec3 le;
            if (light_shape_hit(&ls.lights[ls.shapes[k]], o, d, 0.0f, tmax, recv, &t, &le)) collect(&b, ls.shapes[k], t, le);
        }
        crossings += a.n;
        int same = a.n == b.n;
        for (uint32_t k = 0; same && k < a.n && k < 256; ++k)
            same = a.light[k] == b.light[k] && memcmp(&a.t[k], &b.t[k], sizeof(float)) == 0 &&
                   memcmp(&a.le[k], &b.le[k], sizeof(vec3)) == 0;
        differ += !same;
    }
    fprintf(stderr, "  shape BVH: 200000 rays, %ld crossings, %d rays differ from the list\n", crossings, differ);
    CHECK(differ == 0 && crossings > 1000, "shape BVH: %d of 200000 rays cross other lights than the list (%ld crossings)",
          differ, crossings);
    lights_free(&ls);
    scene_free(&scene);
}

/* ------------------------------------------------------------------ renders */

typedef struct RenderSpec {
    const char *file;
    int width, height, spp;
    CandelaLightSampler sampler;
    uint64_t seed;
    int threads;
    CandelaLightModel light_model;
} RenderSpec;

static int render(const RenderSpec *s, CandelaImage *img) {
    CandelaOptions o;
    candela_options_default(&o);
    char path[4096];
    snprintf(path, sizeof path, "%s/%s", g_dir, s->file);
    o.scene_path = path;
    o.width = s->width;
    o.height = s->height;
    o.spp = s->spp;
    o.light_sampler = s->sampler;
    o.light_units = CANDELA_LIGHT_UNITS_RAW;
    o.seed = s->seed;
    o.threads = s->threads ? s->threads : 2;
    o.light_model = s->light_model;
    o.quiet = 1;
    memset(img, 0, sizeof *img);
    CandelaStats st;
    memset(&st, 0, sizeof st);
    char err[CANDELA_ERR_LEN];
    err[0] = 0;
    double t0 = test_seconds();
    int rc = candela_render(&o, img, &st, NULL, err);
    CHECK(rc == 0, "%s: candela_render failed: %s", s->file, err);
    if (rc != 0) return rc;
    fprintf(stderr, "  render %-20s %dx%d %4d spp %-11s %d threads: %.2f s\n", s->file, s->width, s->height, s->spp,
            candela_light_sampler_name(s->sampler), o.threads, test_seconds() - t0);
    return img->rgb && img->variance ? 0 : 1;
}

static int all_finite(const char *name, const CandelaImage *img) {
    size_t n = (size_t)img->width * (size_t)img->height * 3, bad = 0;
    for (size_t i = 0; i < n; ++i)
        if (!isfinite(img->rgb[i]) || !isfinite(img->variance[i]) || img->variance[i] < 0.0f) ++bad;
    CHECK(bad == 0, "%s: %zu non-finite values or negative variances", name, bad);
    return bad == 0;
}

/* test_analytic's comparison: 6 sigma per pixel for 99% of them, the mean within 5 standard errors */
static void compare(const char *name, const CandelaImage *img, const double *exact) {
    if (!all_finite(name, img)) return;
    int n = img->width * img->height, ok_pixels = 0;
    for (int p = 0; p < n; ++p) {
        int ok = 1;
        for (int c = 0; c < 3; ++c) {
            double v = img->rgb[3 * p + c], e = exact[3 * p + c];
            double tol = 6.0 * sqrt((double)img->variance[3 * p + c]) + 1e-4 * fabs(e) + 1e-6;
            if (fabs(v - e) > tol) ok = 0;
        }
        ok_pixels += ok;
    }
    CHECK(ok_pixels >= (int)ceil(0.99 * n), "%s: only %d of %d pixels within 6 sigma", name, ok_pixels, n);
    for (int c = 0; c < 3; ++c) {
        double sd = 0, sv = 0, se = 0, sr = 0;
        for (int p = 0; p < n; ++p) {
            sd += img->rgb[3 * p + c] - exact[3 * p + c];
            sv += img->variance[3 * p + c];
            se += fabs(exact[3 * p + c]);
            sr += img->rgb[3 * p + c];
        }
        double tol = 5.0 * sqrt(sv) / n + 1e-4 * se / n + 1e-6;
        CHECK(fabs(sd / n) <= tol, "%s: channel %d mean %.7g, exact %.7g: bias %.3g > tol %.3g", name, c, sr / n, se / n,
              sd / n, tol);
        if (c == 0)
            fprintf(stderr, "  %-26s mean %.6f exact %.6f (diff %+.2e, stderr %.2e), %d/%d pixels within 6 sigma\n", name,
                    sr / n, se / n, sd / n, sqrt(sv) / n, ok_pixels, n);
    }
}

typedef double (*PlaneFn)(double x, double z);
/* the top orthographic camera (make_scenes.py top_ortho, mag 1) over the plane y = 0: footprint
 * averages of rho/pi E(x, z), 16x16 midpoint rule */
static double *plane_exact(int w, int h, PlaneFn f) {
    double *e = malloc(sizeof(double) * 3 * (size_t)w * (size_t)h);
    const int sub = 16;
    for (int py = 0; py < h; ++py)
        for (int px = 0; px < w; ++px) {
            double sum = 0;
            for (int j = 0; j < sub; ++j)
                for (int i = 0; i < sub; ++i) {
                    double x = 2 * (px + (i + 0.5) / sub) / w - 1, z = 2 * (py + (j + 0.5) / sub) / h - 1;
                    sum += f(x, z);
                }
            for (int c = 0; c < 3; ++c) e[3 * (py * w + px) + c] = 0.5 / M_PI * sum / (sub * sub);
        }
    return e;
}

/* sphere_plane: I = 32 pi, 4 m up: the point light's E (the whole sphere above every horizon) */
static double sphere_E(double x, double z) {
    double h = 4.0, r2 = h * h + x * x + z * z;
    return 32 * M_PI * h / (r2 * sqrt(r2));
}
static double sun_E(double x, double z) { (void)x; (void)z; return 2 * M_PI * cos(M_PI / 6); }
/* sphere_plane under --light-model blender3: Cycles 3.4's disk of radius a = 0.5 facing each point,
 * E = I cos(beta) / (a^2 + d^2) */
static double sphere_cycles_E(double x, double z) {
    double h = 4.0, r2 = h * h + x * x + z * z;
    return 32 * M_PI * (h / sqrt(r2)) / (0.25 + r2);
}
/* the same sun under --light-model blender3: Cycles 3.4's 2 cos h / (1 + cos h) of it (h = 10 deg) */
static double sun_cycles_E(double x, double z) {
    double ch = cos(10.0 * M_PI / 180.0);
    return sun_E(x, z) * 2.0 * ch / (1.0 + ch);
}
static double rect_E(double x, double z) {
    const double v[4][3] = {{-0.5, 1, -0.5}, {0.5, 1, -0.5}, {0.5, 1, 0.5}, {-0.5, 1, 0.5}};
    double p[3] = {x, 0, z}, n[3] = {0, 1, 0};
    return polygon_irradiance(v, 4, p, n, 2.0);
}
static double disk_E(double x, double z) {
    double rr = x * x + z * z, h2 = 1.0, a2 = 0.25;
    return M_PI * 2.0 * 0.5 * (1.0 - (rr + h2 - a2) / sqrt((rr + h2 + a2) * (rr + h2 + a2) - 4.0 * rr * a2));
}

static void test_planes(void) {
    struct { const char *file; PlaneFn f; } cases[] = {
        {"sphere_plane.gltf", sphere_E}, {"sun_plane.gltf", sun_E}, {"rect_plane.gltf", rect_E}, {"disk_plane.gltf", disk_E}};
    for (size_t k = 0; k < sizeof cases / sizeof cases[0]; ++k) {
        RenderSpec s = {cases[k].file, 32, 32, 64, CANDELA_LIGHT_SAMPLER_POWER, 5 + k, 2};
        CandelaImage img;
        if (render(&s, &img) == 0) {
            double *e = plane_exact(32, 32, cases[k].f);
            compare(cases[k].file, &img, e);
            free(e);
        }
        candela_image_free(&img);
    }
    struct { const char *file; PlaneFn f; const char *name; } cycles[] = {
        {"sun_plane.gltf", sun_cycles_E, "sun_plane (blender3)"}, {"sphere_plane.gltf", sphere_cycles_E, "sphere_plane (blender3)"}};
    for (size_t k = 0; k < 2; ++k) {
        RenderSpec s = {cycles[k].file, 32, 32, 64, CANDELA_LIGHT_SAMPLER_POWER, 9 + k, 2, CANDELA_LIGHT_MODEL_BLENDER3};
        CandelaImage img;
        if (render(&s, &img) == 0) {
            double *e = plane_exact(32, 32, cycles[k].f);
            compare(cycles[k].name, &img, e);
            free(e);
        }
        candela_image_free(&img);
    }
}

/* Two independent renders agree: per pixel z = (a - b) / sqrt(va + vb), mean z^2 within
 * 1 +- 5 sqrt(2/N) (allowing for the variance estimates' own noise: 1 + 0.5 slack above),
 * and each channel's mean difference within 5 standard errors. */
static void compare_renders(const char *what, const CandelaImage *a, const CandelaImage *b) {
    int n = a->width * a->height;
    double z2 = 0;
    int used = 0;
    for (int c = 0; c < 3; ++c) {
        double sd = 0, sv = 0;
        for (int p = 0; p < n; ++p) {
            double d = (double)a->rgb[3 * p + c] - b->rgb[3 * p + c];
            double v = (double)a->variance[3 * p + c] + b->variance[3 * p + c];
            sd += d;
            sv += v;
            if (v > 0) { z2 += d * d / v; ++used; }
        }
        CHECK(fabs(sd / n) <= 5.0 * sqrt(sv) / n + 1e-6, "%s: channel %d mean difference %.3g > 5 se %.3g", what, c, sd / n,
              5.0 * sqrt(sv) / n);
    }
    double mz2 = used ? z2 / used : 0;
    fprintf(stderr, "  %-30s mean z^2 %.3f over %d pixel channels\n", what, mz2, used);
    CHECK(used > 0 && mz2 < 1.0 + 5.0 * sqrt(2.0 / used) + 0.5, "%s: mean z^2 %.3f (the images differ beyond noise)", what,
          mz2);
}

static void test_samplers(void) {
    RenderSpec su = {"shapes_mix.gltf", 24, 24, 256, CANDELA_LIGHT_SAMPLER_UNIFORM, 31, 2};
    CandelaImage ref;
    if (render(&su, &ref) != 0 || !all_finite("shapes_mix uniform", &ref)) { candela_image_free(&ref); return; }
    const CandelaLightSampler others[] = {CANDELA_LIGHT_SAMPLER_POWER, CANDELA_LIGHT_SAMPLER_TREE,
                                          CANDELA_LIGHT_SAMPLER_OPTIMAL, CANDELA_LIGHT_SAMPLER_CACHEPOINTS};
    for (size_t k = 0; k < sizeof others / sizeof others[0]; ++k) {
        RenderSpec s = su;
        s.sampler = others[k];
        s.seed = 32 + k;
        CandelaImage img;
        if (render(&s, &img) == 0 && all_finite("shapes_mix", &img)) {
            char what[64];
            snprintf(what, sizeof what, "shapes_mix %s vs uniform", candela_light_sampler_name(others[k]));
            compare_renders(what, &ref, &img);
        }
        candela_image_free(&img);
    }
    candela_image_free(&ref);
    /* 41 shapes through the BVH: the tree and cache points against uniform */
    RenderSpec mu = {"shapes_many.gltf", 24, 24, 256, CANDELA_LIGHT_SAMPLER_UNIFORM, 41, 2};
    CandelaImage mref;
    if (render(&mu, &mref) == 0 && all_finite("shapes_many uniform", &mref)) {
        const CandelaLightSampler many[] = {CANDELA_LIGHT_SAMPLER_TREE, CANDELA_LIGHT_SAMPLER_CACHEPOINTS};
        for (size_t k = 0; k < 2; ++k) {
            RenderSpec s = mu;
            s.sampler = many[k];
            s.seed = 42 + k;
            CandelaImage img;
            if (render(&s, &img) == 0 && all_finite("shapes_many", &img)) {
                char what[64];
                snprintf(what, sizeof what, "shapes_many %s vs uniform", candela_light_sampler_name(many[k]));
                compare_renders(what, &mref, &img);
            }
            candela_image_free(&img);
        }
    }
    candela_image_free(&mref);
    /* 1 vs 2 threads, bit for bit */
    const CandelaLightSampler det[] = {CANDELA_LIGHT_SAMPLER_TREE, CANDELA_LIGHT_SAMPLER_CACHEPOINTS,
                                       CANDELA_LIGHT_SAMPLER_CACHEPOINTS};
    for (size_t k = 0; k < 3; ++k) {
        RenderSpec s1 = {k == 2 ? "shapes_many.gltf" : "shapes_mix.gltf", 24, 24, 16, det[k], 9, 1}, s2 = s1;
        s2.threads = 2;
        CandelaImage a, b;
        if (render(&s1, &a) == 0 && render(&s2, &b) == 0)
            CHECK(memcmp(a.rgb, b.rgb, sizeof(float) * 3 * 24 * 24) == 0, "%s %s: 1 and 2 threads differ", s1.file,
                  candela_light_sampler_name(det[k]));
        candela_image_free(&a);
        candela_image_free(&b);
    }
}

/* A point light 1 cm inside a 4 cm slab lights nothing; with a 0.1 m radius the part of the
 * sphere below the slab lights the plane (the lamp post). The plane right below sees
 * the cap under the slab (y in [0.9, 0.98]): between the cap's and the whole lower half's
 * point-light bounds. */
/* rect_fog: rect_plane inside a purely absorbing medium (sigma_a = 0.5; the camera 0.5 above the
 * plane inside it too): pixel = e^(-0.5 sigma) rho/pi int L cos cos' e^(-sigma r) / r^2 dA, the
 * integral by a 24x24 midpoint rule over the rect and 4x4 points per pixel (errors ~1e-4, in
 * the tolerance's floor). The BSDF rays that find the rect cross the medium: the medium walk
 * weighs it by the transmittance up to it. */
static double fog_pixel(double x, double z) {
    const double sigma = 0.5, L = 2.0;
    double E = 0.0;
    const int q = 24;
    for (int j = 0; j < q; ++j)
        for (int i = 0; i < q; ++i) {
            double lx = -0.5 + (i + 0.5) / q - x, lz = -0.5 + (j + 0.5) / q - z, ly = 1.0;
            double r2 = lx * lx + ly * ly + lz * lz, r = sqrt(r2);
            E += L * (ly / r) * (ly / r) * exp(-sigma * r) / r2 / (q * q);
        }
    return exp(-sigma * 0.5) * 0.5 / M_PI * E;
}

static void test_fog(void) {
    const int w = 16, h = 16, sub = 4;
    RenderSpec s = {"rect_fog.gltf", w, h, 1024, CANDELA_LIGHT_SAMPLER_POWER, 12, 2};
    CandelaImage img;
    if (render(&s, &img) == 0) {
        double *e = malloc(sizeof(double) * 3 * w * h);
        for (int py = 0; py < h; ++py)
            for (int px = 0; px < w; ++px) {
                double sum = 0;
                for (int j = 0; j < sub; ++j)
                    for (int i = 0; i < sub; ++i)
                        sum += fog_pixel(2 * (px + (i + 0.5) / sub) / w - 1, 2 * (py + (j + 0.5) / sub) / h - 1);
                for (int c = 0; c < 3; ++c) e[3 * (py * w + px) + c] = sum / (sub * sub);
            }
        compare("rect_fog.gltf", &img, e);
        free(e);
    }
    candela_image_free(&img);
}

/* Light linking reaches shapes: rect_plane's rect with the plane excluded from its receivers
 * leaves the plane black (NEE and BSDF hits alike), for every sampler. */
static void test_linking(void) {
    const CandelaLightSampler all[] = {CANDELA_LIGHT_SAMPLER_UNIFORM, CANDELA_LIGHT_SAMPLER_TREE,
                                       CANDELA_LIGHT_SAMPLER_OPTIMAL, CANDELA_LIGHT_SAMPLER_CACHEPOINTS};
    for (size_t k = 0; k < sizeof all / sizeof all[0]; ++k) {
        RenderSpec s = {"rect_plane_unlinked.gltf", 16, 16, 16, all[k], 4, 2};
        CandelaImage img;
        if (render(&s, &img) == 0) {
            double mx = 0;
            for (int i = 0; i < 3 * 16 * 16; ++i) mx = fmax(mx, img.rgb[i]);
            CHECK(mx == 0.0, "rect_plane_unlinked %s: the unlinked rect lights the plane (max %g)",
                  candela_light_sampler_name(all[k]), mx);
        }
        candela_image_free(&img);
    }
}

static void test_lamp_slab(void) {
    RenderSpec s = {"lamp_slab.gltf", 32, 32, 64, CANDELA_LIGHT_SAMPLER_POWER, 3, 2};
    CandelaImage lit, dark;
    int r1 = render(&s, &lit);
    s.file = "lamp_slab_point.gltf";
    int r2 = render(&s, &dark);
    if (r1 == 0 && r2 == 0 && all_finite("lamp_slab", &lit) && all_finite("lamp_slab_point", &dark)) {
        double max_dark = 0, plane_sum = 0;
        int plane_px = 0, plane_zero = 0;
        for (int p = 0; p < 32 * 32; ++p) {
            max_dark = fmax(max_dark, dark.rgb[3 * p]);
            int px = p % 32, py = p / 32;
            /* the plane outside the slab's footprint ([-0.5, 0.5]^2 of the 4 m view) */
            double x = 4.0 * (px + 0.5) / 32 - 2.0, z = 4.0 * (py + 0.5) / 32 - 2.0;
            if (fabs(x) < 0.6 && fabs(z) < 0.6) continue;
            ++plane_px;
            plane_sum += lit.rgb[3 * p];
            plane_zero += lit.rgb[3 * p] == 0.0f;
        }
        fprintf(stderr, "  lamp_slab: plane mean %.4g outside the slab (%d pixels black); radius 0: max %g\n",
                plane_sum / plane_px, plane_zero, max_dark);
        CHECK(max_dark == 0.0, "lamp_slab_point: a point light inside the slab leaks light (%g)", max_dark);
        CHECK(plane_zero == 0 && plane_sum / plane_px > 1e-3, "lamp_slab: the sphere light does not light the plane");
    }
    candela_image_free(&lit);
    candela_image_free(&dark);
}

int main(int argc, char **argv) {
    if (argc > 1) g_dir = argv[1];
    test_light_level();
    test_shape_bvh();
    test_planes();
    test_samplers();
    test_lamp_slab();
    test_linking();
    test_fog();
    return test_exit();
}
