/* renderer/lights/light_sampler.c: the light-selection protocol's dispatch (light_sampler.h) and its
 * two context-free strategies, uniform and power. */
#include "light_sampler.h"
#include "cachepoint_viz.h"
#include "media.h"
#include "scene.h"

#include <stdio.h>
#include <stdlib.h>

/* ---------------------------------------------------------------- uniform */

/* Light linking: a vertex of link class c > 0 picks among the class's lights only
 * (LightLinking.enabled_lights), so no sample goes to a light that cannot reach it; class 0 is
 * the unlinked path, unchanged. */
typedef struct UniformSampler {
    uint32_t count;
    const LightLinking *link; /* NULL: no linking */
} UniformSampler;

static uint32_t uniform_select(const void *state, const LightSampleContext *ctx, float u, float u1, float *pmf,
                               uint32_t *outcome) {
    (void)u1; (void)outcome;
    const UniformSampler *us = state;
    uint32_t count = us->count;
    const uint32_t *list = NULL;
    if (ctx->link_class) {
        const LightLinking *k = us->link;
        count = k->enabled_off[ctx->link_class + 1] - k->enabled_off[ctx->link_class];
        list = k->enabled_lights + k->enabled_off[ctx->link_class];
        if (!count) { *pmf = 0.0f; return 0; }
    }
    uint32_t i = (uint32_t)(u * (float)count);
    if (i >= count) i = count - 1;
    *pmf = 1.0f / (float)count;
    return list ? list[i] : i;
}

static float uniform_pmf(const void *state, const LightSampleContext *ctx, uint32_t light) {
    const UniformSampler *us = state;
    if (ctx->link_class) {
        const LightLinking *k = us->link;
        if (!k->enabled[(size_t)ctx->link_class * us->count + light]) return 0.0f;
        return 1.0f / (float)(k->enabled_off[ctx->link_class + 1] - k->enabled_off[ctx->link_class]);
    }
    return 1.0f / (float)us->count;
}

static const LightSamplerOps UNIFORM_OPS = {
    .name = "uniform", .select = uniform_select, .pmf = uniform_pmf, .destroy = free};

int light_sampler_uniform_create(LightSampler *s, const Lights *lights) {
    UniformSampler *us = malloc(sizeof *us);
    if (!us) return -1;
    *us = (UniformSampler){lights->count, lights->link};
    *s = (LightSampler){&UNIFORM_OPS, us, lights->count};
    return 0;
}

/* ---------------------------------------------------------------- power */

/* In proportion to each light's power estimate (Light.power), whatever the shading point; with
 * light linking, one distribution per link class over the class's lights. */
typedef struct PowerSampler {
    Distribution1D all;
    const LightLinking *link; /* NULL: no linking */
    Distribution1D *per_class; /* [num_classes]: entry c > 0 over the class's lights */
    const Lights *lights;
} PowerSampler;

/* The position of `light` in class c's ascending list, or UINT32_MAX. */
static uint32_t class_position(const LightLinking *k, uint32_t c, uint32_t light) {
    const uint32_t *a = k->enabled_lights + k->enabled_off[c];
    uint32_t lo = 0, hi = k->enabled_off[c + 1] - k->enabled_off[c];
    while (lo < hi) {
        uint32_t mid = lo + (hi - lo) / 2;
        if (a[mid] < light) lo = mid + 1;
        else hi = mid;
    }
    return lo < k->enabled_off[c + 1] - k->enabled_off[c] && a[lo] == light ? lo : UINT32_MAX;
}

static uint32_t power_select(const void *state, const LightSampleContext *ctx, float u, float u1, float *pmf,
                             uint32_t *outcome) {
    (void)u1; (void)outcome;
    const PowerSampler *ps = state;
    if (ctx->link_class) {
        const Distribution1D *d = &ps->per_class[ctx->link_class];
        if (!d->n) { *pmf = 0.0f; return 0; }
        uint32_t i = dist1d_sample_discrete(d, u, pmf, NULL);
        return ps->link->enabled_lights[ps->link->enabled_off[ctx->link_class] + i];
    }
    return dist1d_sample_discrete(&ps->all, u, pmf, NULL);
}

static float power_pmf(const void *state, const LightSampleContext *ctx, uint32_t light) {
    const PowerSampler *ps = state;
    if (ctx->link_class) {
        uint32_t i = class_position(ps->link, ctx->link_class, light);
        return i == UINT32_MAX ? 0.0f : dist1d_pmf(&ps->per_class[ctx->link_class], i);
    }
    return dist1d_pmf(&ps->all, light);
}

static void power_destroy(void *state) {
    PowerSampler *ps = state;
    dist1d_free(&ps->all);
    if (ps->per_class)
        for (uint32_t c = 1; c < ps->link->num_classes; ++c) dist1d_free(&ps->per_class[c]);
    free(ps->per_class);
    free(ps);
}

static const LightSamplerOps POWER_OPS = {
    .name = "power", .select = power_select, .pmf = power_pmf, .destroy = power_destroy};

/* In-scattering sampling's importance with one light (auto picks power for one light, also with
 * media): the light's own unoccluded fluence estimate at x (light_estimates.c), so the distance
 * density along a camera segment follows the light as equiangular sampling would, without a
 * cache point build. No radius: the stations are spread evenly over the segment. */
static float power_inscatter_weight(const void *state, const float x[3], uint32_t *hint, float *radius) {
    (void)hint;
    const PowerSampler *ps = state;
    *radius = 0.0f;
    float w = light_contribution_estimate(ps->lights, &ps->lights->lights[0], v3(x[0], x[1], x[2]), v3s(0.0f));
    return isfinite(w) && w > 0.0f ? w : 0.0f;
}

static const LightSamplerOps POWER_ONE_LIGHT_INSCATTER_OPS = {
    .name = "power", .select = power_select, .pmf = power_pmf, .inscatter_weight = power_inscatter_weight,
    .destroy = power_destroy};

int light_sampler_power_create(LightSampler *s, const Lights *lights) {
    PowerSampler *ps = calloc(1, sizeof *ps);
    if (ps && lights->count == 0) { /* nothing to select (the protocol never asks) */
        *s = (LightSampler){&POWER_OPS, ps, 0};
        return 0;
    }
    float *powers = malloc(((size_t)lights->count + 1) * sizeof(float));
    if (!ps || !powers) { free(ps); free(powers); return -1; }
    for (uint32_t i = 0; i < lights->count; ++i) powers[i] = lights->lights[i].power;
    int rc = dist1d_init(&ps->all, powers, lights->count);
    const LightLinking *k = lights->link;
    if (rc == 0 && k && k->num_classes > 1) {
        ps->link = k;
        ps->per_class = calloc(k->num_classes, sizeof *ps->per_class);
        if (!ps->per_class) rc = -1;
        for (uint32_t c = 1; c < k->num_classes && rc == 0; ++c) {
            uint32_t m = 0;
            for (uint32_t j = k->enabled_off[c]; j < k->enabled_off[c + 1]; ++j) powers[m++] = lights->lights[k->enabled_lights[j]].power;
            if (m) rc = dist1d_init(&ps->per_class[c], powers, m);
        }
    }
    free(powers);
    if (rc != 0) { power_destroy(ps); return -1; }
    ps->lights = lights;
    *s = (LightSampler){lights->count == 1 ? &POWER_ONE_LIGHT_INSCATTER_OPS : &POWER_OPS, ps, lights->count};
    return 0;
}

/* ---------------------------------------------------------------- auto (the default) */

CandelaLightSampler light_sampler_auto_choice(const Lights *lights, const struct SceneMedia *media,
                                              const CandelaOptions *o) {
    /* one light (or none): every strategy picks it with probability 1; power does no work, and
     * gives in-scattering sampling the light's own estimate (no cache point build) */
    if (lights->count <= 1) return CANDELA_LIGHT_SAMPLER_POWER;
    /* in-scattering sampling along camera rays (§4.2) with more lights needs cache points */
    if (o->volume_inscatter_sampling == 1 || (o->volume_inscatter_sampling != 0 && media && media_any(media)))
        return CANDELA_LIGHT_SAMPLER_CACHEPOINTS;
    /* few lights: every light's exact estimate per vertex (the distribution cache points
     * approximate, narrow spot cones included; the paper itself falls back to it below 10
     * points, §3.1.1), without a build, while that costs less per vertex than about
     * LIGHT_SAMPLER_AUTO_EXACT_COST point lights (an area light's estimate sums 16 points:
     * it counts LIGHT_SAMPLER_AUTO_AREA_COST) */
    if (lights->count > LIGHT_SAMPLER_SCRATCH) return CANDELA_LIGHT_SAMPLER_CACHEPOINTS;
    uint32_t cost = 0;
    for (uint32_t i = 0; i < lights->count; ++i)
        cost += light_is_areal(&lights->lights[i]) ? LIGHT_SAMPLER_AUTO_AREA_COST : 1u;
    return cost <= LIGHT_SAMPLER_AUTO_EXACT_COST ? CANDELA_LIGHT_SAMPLER_OPTIMAL : CANDELA_LIGHT_SAMPLER_CACHEPOINTS;
}

/* The within-pixel variance of what the camera sees directly (emitters and the environment):
 * at AUTO_SEEN_GRID^2 pixels spread over the image (the crop, with --crop: what is rendered),
 * 2x2 stratified positions per pixel, the unbiased sample variance of the seen radiance's
 * luminance, averaged over the pixels. */
enum { AUTO_SEEN_GRID = 64 };
static double seen_emission_variance(const Scene *scene) {
    const Camera *cam = &scene->camera;
    double acc = 0.0;
    for (int j = 0; j < AUTO_SEEN_GRID; ++j)
        for (int i = 0; i < AUTO_SEEN_GRID; ++i) {
            float px = (float)cam->crop_x + floorf(((float)i + 0.5f) / AUTO_SEEN_GRID * (float)cam->crop_width);
            float py = (float)cam->crop_y + floorf(((float)j + 0.5f) / AUTO_SEEN_GRID * (float)cam->crop_height);
            double x[4], mean = 0.0;
            for (int k = 0; k < 4; ++k) {
                vec3 o, d;
                camera_generate_ray(cam, px + 0.25f + 0.5f * (float)(k & 1), py + 0.25f + 0.5f * (float)(k >> 1), &o, &d);
                SceneHit sh;
                vec3 le;
                if (scene_intersect1(scene, (SceneRay){o, 0.0f, d, INFINITY}, &sh)) {
                    SurfaceHit h;
                    scene_surface_hit(scene, sh.instance, sh.local_prim, sh.triangle, sh.u, sh.v, &h);
                    le = scene_emitted_radiance(scene, &h, v3_neg(d));
                } else {
                    le = scene_env_radiance(scene, d);
                }
                float l = v3_luminance(le);
                x[k] = isfinite(l) ? (double)l : 0.0;
                mean += 0.25 * x[k];
            }
            double v = 0.0;
            for (int k = 0; k < 4; ++k) v += (x[k] - mean) * (x[k] - mean);
            acc += v / 3.0;
        }
    return acc / ((double)AUTO_SEEN_GRID * AUTO_SEEN_GRID);
}

float light_sampler_power_moment_ratio(const Lights *lights, const struct Scene *scene) {
    uint32_t n = lights->count;
    if (n == 0 || n > LIGHT_SAMPLER_AUTO_PROBE_MAX || !scene) return INFINITY;
    double power_sum = 0.0;
    for (uint32_t i = 0; i < n; ++i) power_sum += lights->lights[i].power > 0.0f ? lights->lights[i].power : 0.0f;
    if (!(power_sum > 0.0)) return INFINITY;
    float *q = malloc(sizeof(float) * n);
    if (!q) return INFINITY;
    /* the estimates through the table: the same bits as light_contribution_estimate, with an
     * area light's points precomputed (1,024 area lights at 256 points: 0.1 s without it) */
    LightEstimateTable table;
    if (light_estimate_table_build(&table, lights) != 0) { free(q); return INFINITY; }
    enum { GRID = 16 };
    const Camera *cam = &scene->camera;
    double num = 0.0, den = 0.0;
    for (int j = 0; j < GRID; ++j)
        for (int i = 0; i < GRID; ++i) {
            vec3 o, d;
            /* over the crop with --crop (the whole image without): where the render looks */
            camera_generate_ray(cam, (float)cam->crop_x + ((float)i + 0.5f) / GRID * (float)cam->crop_width,
                                (float)cam->crop_y + ((float)j + 0.5f) / GRID * (float)cam->crop_height, &o, &d);
            SceneHit sh;
            if (!scene_intersect1(scene, (SceneRay){o, 0.0f, d, INFINITY}, &sh)) continue;
            SurfaceHit h;
            scene_surface_hit(scene, sh.instance, sh.local_prim, sh.triangle, sh.u, sh.v, &h);
            vec3 nrm = v3_dot(h.ns, d) < 0.0f ? h.ns : v3_neg(h.ns);
            /* the estimates are irradiance: a diffuse reflectance turns them into the radiance
             * the pixel sees, the unit of the seen emission's variance below */
            MaterialSample ms;
            scene_material_at(scene, &h, &ms);
            double rho = (double)v3_luminance(ms.bsdf.base_color) * (1.0 - (double)ms.bsdf.metallic) / PI_F;
            double total = 0.0;
            for (uint32_t e = 0; e < n; ++e) {
                float w = light_contribution_estimate_table(lights, &table, e, h.p, nrm);
                q[e] = w > 0.0f && isfinite(w) ? w : 0.0f;
                total += q[e];
            }
            if (!(total > 0.0)) continue;
            double m = 0.0;
            for (uint32_t e = 0; e < n; ++e) {
                if (!(q[e] > 0.0f)) continue;
                double pe = (lights->lights[e].power > 0.0f ? lights->lights[e].power : 0.0f) / power_sum;
                if (!(pe > 0.0)) { /* power never picks a light that matters */
                    free(q);
                    light_estimate_table_free(&table);
                    return INFINITY;
                }
                double qe = q[e] / total;
                m += qe * qe / pe;
            }
            double t2 = rho * rho * total * total;
            num += t2 * m;
            den += t2;
        }
    free(q);
    light_estimate_table_free(&table);
    if (!(den > 0.0)) return INFINITY;
    /* per pixel: the NEE estimates' second moments plus what the camera sees directly, which
     * no light sampler changes (the emitters' edges can hold most of an image's variance:
     * cornell_many_lights, 94 % in the panel rows) */
    double seen = seen_emission_variance(scene);
    double ratio = (num / (GRID * GRID) + seen) / (den / (GRID * GRID) + seen);
    return (float)ratio;
}

/* ---------------------------------------------------------------- dispatch */

int light_sampler_create(LightSampler *s, const Lights *lights, const struct Scene *scene,
                         const struct SceneMedia *media, struct ThreadPool *pool, const CandelaOptions *o,
                         char err[CANDELA_ERR_LEN]) {
    int rc;
    CandelaLightSampler which = o->light_sampler;
    if (which == CANDELA_LIGHT_SAMPLER_AUTO) {
        which = light_sampler_auto_choice(lights, media, o);
        if ((which == CANDELA_LIGHT_SAMPLER_OPTIMAL || which == CANDELA_LIGHT_SAMPLER_CACHEPOINTS) &&
            !(media && media_any(media)) && !lights->link &&
            light_sampler_power_moment_ratio(lights, scene) <=
                (which == CANDELA_LIGHT_SAMPLER_OPTIMAL ? LIGHT_SAMPLER_AUTO_POWER_RATIO
                                                        : LIGHT_SAMPLER_AUTO_POWER_RATIO_CACHEPOINTS))
            which = CANDELA_LIGHT_SAMPLER_POWER;
    }
    if ((o->aov_selection || o->cachepoint_dump_path) && which != CANDELA_LIGHT_SAMPLER_CACHEPOINTS && !o->no_warnings)
        fprintf(stderr, "%s: warning: --light-sampler auto chose %s for this scene: %s (give --light-sampler "
                "cachepoints to see cache points)\n", o->scene_path, candela_light_sampler_name(which),
                o->aov_selection ? "the cachepoint AOV stays black" : "the cache point dump is empty");
    switch (which) {
    case CANDELA_LIGHT_SAMPLER_POWER: rc = light_sampler_power_create(s, lights); break;
    case CANDELA_LIGHT_SAMPLER_TREE: rc = light_sampler_tree_create(s, lights); break;
    case CANDELA_LIGHT_SAMPLER_OPTIMAL:
        /* auto never adds occlusion rays (a shadow ray per light per vertex) */
        rc = light_sampler_optimal_create(s, lights, scene, o->light_sampler == which && o->optimal_occlusion);
        break;
    case CANDELA_LIGHT_SAMPLER_CACHEPOINTS:
        return light_sampler_cachepoints_create(s, lights, scene, media, pool, o, err); /* its own messages */
    default: rc = light_sampler_uniform_create(s, lights); break;
    }
    if (rc != 0) {
        snprintf(err, CANDELA_ERR_LEN, "%s: out of memory building the light sampler", o->scene_path);
        return rc;
    }
    /* auto chose another sampler: the dump is still written, as an empty PLY (0 vertices), so a
     * script reading it finds a valid file saying "no cache points" (README) */
    if (o->cachepoint_dump_path && cachepoint_write_ply(NULL, o->cachepoint_dump_path, err) != 0) {
        light_sampler_free(s);
        return -1;
    }
    return 0;
}

void light_sampler_free(LightSampler *s) {
    if (s->ops && s->ops->destroy) s->ops->destroy(s->state);
    *s = (LightSampler){0};
}
