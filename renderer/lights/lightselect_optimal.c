/* renderer/lights/lightselect_optimal.c: the "locally optimal" light-selection strategy (the cache
 * points paper's reference, Table 1): every light's unoccluded estimate (light_estimates.c) at
 * every vertex, optionally times a binary visibility from one shadow ray per light
 * (--optimal-occlusion, as Table 1 measures "optimal selection"). The selection PMF mixes in a
 * uniform floor so no light ever has probability zero (eps = 0.03, as cache points use):
 *     p(e | x) = (1 - eps) w_e / W + eps / N,   W = sum_e w_e;   p = 1/N when W == 0.
 * Every estimate is a deterministic function of (light, p, n): select and pmf recompute the
 * same numbers in the same order, so the PMF select reports equals the pmf bit for bit.
 * Cost is O(N) per vertex, which is the point of the paper: this is the reference that cache
 * points compress. Without occlusion rays and with at most LIGHT_SAMPLER_SCRATCH lights,
 * prepare evaluates the N weights once per vertex into the caller's scratch and keeps their
 * sum W in the vertex token, so select reads them back and the MIS pdf at the next wave costs
 * one light's weight (the same numbers in the same order: the image does not change). That
 * makes it the `auto` sampler's choice for scenes with few lights (light_sampler.c). */
#include <stdlib.h>

#include "light_sampler.h"
#include "scene.h"

#define OPTIMAL_EPSILON 0.03f

typedef struct OptimalSampler {
    const Lights *lights;
    const Scene *scene;  /* for the occlusion rays */
    int occlusion;
    int per_vertex;      /* prepare evaluates the weights (no occlusion, N <= the scratch) */
    LightEstimateTable table;
} OptimalSampler;

/* One shadow ray from p towards the light's reference point (point/spot position, the
 * centroid of the first triangle of an area light, or the direction of a distant light). */
static int light_visible(const Scene *scene, const Light *l, vec3 p, vec3 n, uint32_t mask) {
    vec3 target;
    float tfar;
    vec3 dir;
    switch (l->type) {
    case LIGHT_POINT:
    case LIGHT_SPOT:
    case LIGHT_RECT:  /* a sphere's, rect's or disk's centre */
    case LIGHT_DISK:
    case LIGHT_VOLUME: /* its emission centroid */
        target = l->position;
        if ((l->type == LIGHT_POINT || l->type == LIGHT_SPOT) && l->radius > 0.0f) {
            /* a sphere: its point nearest p (a light a little inside an occluder shows there) */
            vec3 to = v3_sub(p, l->position);
            float len = v3_length(to);
            if (len > l->radius) target = v3_madd(l->position, to, l->radius / len);
        }
        break;
    case LIGHT_AREA: {
        const float *v = l->world_vertices;
        target = v3((v[0] + v[3] + v[6]) / 3.0f, (v[1] + v[4] + v[7]) / 3.0f, (v[2] + v[5] + v[8]) / 3.0f);
        break;
    }
    case LIGHT_DIRECTIONAL:
        dir = v3_neg(l->direction);
        tfar = INFINITY;
        goto trace;
    default:
        return 1; /* the environment: visibility varies over the sphere; treat as visible */
    }
    dir = v3_sub(target, p);
    tfar = v3_length(dir);
    if (!(tfar > 0.0f)) return 1;
    dir = v3_scale(dir, 1.0f / tfar);
    tfar *= 1.0f - 1e-3f;
trace:;
    vec3 o = v3_is_black(n) ? p : offset_ray_origin(p, v3_dot(dir, n) >= 0.0f ? n : v3_neg(n));
    return scene_visible1_masked(scene, (SceneRay){o, 0.0f, dir, tfar}, mask); /* shadow linking's mask */
}

/* Light i's unoccluded weight from its estimate w: zero for a light not linked to the vertex
 * and for a non-positive or non-finite estimate. */
static inline float optimal_weight_from(const OptimalSampler *s, uint32_t i, const LightSampleContext *ctx, float w) {
    if (ctx->link_class && !light_reaches(s->lights, ctx->link_class, i)) return 0.0f; /* light linking */
    return w > 0.0f && isfinite(w) ? w : 0.0f;
}

static inline float optimal_weight(const OptimalSampler *s, uint32_t i, const LightSampleContext *ctx) {
    if (ctx->link_class && !light_reaches(s->lights, ctx->link_class, i)) return 0.0f; /* no estimate needed */
    float w = optimal_weight_from(s, i, ctx, light_contribution_estimate_table(s->lights, &s->table, i, ctx->p, ctx->n));
    if (w > 0.0f && s->occlusion &&
        !light_visible(s->scene, &s->lights->lights[i], ctx->p, ctx->n, lights_shadow_mask(s->lights, i)))
        return 0.0f;
    return w;
}

static inline float optimal_pmf_from(float w, float total, uint32_t count) {
    if (!(total > 0.0f)) return 1.0f / (float)count;
    return (1.0f - OPTIMAL_EPSILON) * (w / total) + OPTIMAL_EPSILON / (float)count;
}

/* Light linking: the uniform floor spreads over the vertex's class's lights only (count and
 * the k-th of them); class 0 is every light. */
static inline uint32_t class_count(const OptimalSampler *s, const LightSampleContext *ctx) {
    const LightLinking *k = s->lights->link;
    return ctx->link_class ? k->enabled_off[ctx->link_class + 1] - k->enabled_off[ctx->link_class] : s->lights->count;
}
static inline uint32_t class_light(const OptimalSampler *s, const LightSampleContext *ctx, uint32_t i) {
    const LightLinking *k = s->lights->link;
    return ctx->link_class ? k->enabled_lights[k->enabled_off[ctx->link_class] + i] : i;
}

static float optimal_total(const OptimalSampler *s, const LightSampleContext *ctx) {
    if (ctx->vertex.word) return ctx->vertex.value; /* prepared: the sum below, kept in the token */
    float total = 0.0f;
    for (uint32_t i = 0; i < s->lights->count; ++i) total += optimal_weight(s, i, ctx);
    return total;
}

/* Every light's weight into the scratch and their sum (in light order, as optimal_total adds
 * them) into the token. */
static void optimal_prepare(const void *state, LightSampleContext *ctx, uint32_t *hint) {
    (void)hint;
    const OptimalSampler *s = state;
    if (!s->per_vertex) return; /* no occlusion rays, count <= LIGHT_SAMPLER_SCRATCH */
    float local[LIGHT_SAMPLER_SCRATCH];
    float *wv = ctx->scratch ? ctx->scratch : local;
    /* optimal_weight of every light (no occlusion here): the estimates all at once (point
     * lights four at a time), then the same rules */
    light_estimate_table_all(s->lights, &s->table, ctx->p, ctx->n, wv);
    float total = 0.0f;
    if (ctx->link_class) {
        for (uint32_t i = 0; i < s->lights->count; ++i) {
            wv[i] = optimal_weight_from(s, i, ctx, wv[i]);
            total += wv[i];
        }
    } else {
        /* optimal_weight_from without linking: w > 0 && isfinite(w) is w in (0, inf) */
        for (uint32_t i = 0; i < s->lights->count; ++i) {
            float w = wv[i];
            wv[i] = w > 0.0f && w < INFINITY ? w : 0.0f;
            total += wv[i];
        }
    }
    ctx->vertex = (LightVertex){1u, total};
}

static uint32_t optimal_select(const void *state, const LightSampleContext *ctx, float u, float u1, float *pmf,
                               uint32_t *outcome) {
    (void)u1;
    (void)outcome;
    const OptimalSampler *s = state;
    uint32_t count = class_count(s, ctx);
    if (!count) { *pmf = 0.0f; return 0; } /* light linking: no light reaches the vertex */
    /* the weights prepare left in the scratch (per light index), valid for the vertex it prepared */
    const float *wv = ctx->vertex.word && ctx->scratch ? ctx->scratch : NULL;
    float total = optimal_total(s, ctx);
    uint32_t pick;
    if (!(total > 0.0f) || u < OPTIMAL_EPSILON) {
        float uu = total > 0.0f ? u / OPTIMAL_EPSILON : u;
        pick = (uint32_t)(uu * (float)count);
        if (pick >= count) pick = count - 1;
        pick = class_light(s, ctx, pick);
        *pmf = optimal_pmf_from(wv ? wv[pick] : optimal_weight(s, pick, ctx), total, count);
        return pick;
    }
    float target = (u - OPTIMAL_EPSILON) / (1.0f - OPTIMAL_EPSILON) * total;
    float cum = 0.0f, w = 0.0f;
    pick = s->lights->count - 1;
    for (uint32_t i = 0; i < s->lights->count; ++i) {
        w = wv ? wv[i] : optimal_weight(s, i, ctx);
        cum += w;
        if (w > 0.0f && target < cum) { pick = i; break; }
    }
    /* rounding can leave target >= cum at the end: take the last light with weight */
    if (!(target < cum)) {
        while (pick > 0 && !((wv ? wv[pick] : optimal_weight(s, pick, ctx)) > 0.0f)) --pick;
    }
    *pmf = optimal_pmf_from(wv ? wv[pick] : optimal_weight(s, pick, ctx), total, count);
    return pick;
}

static float optimal_pmf(const void *state, const LightSampleContext *ctx, uint32_t light) {
    const OptimalSampler *s = state;
    if (ctx->link_class && !light_reaches(s->lights, ctx->link_class, light)) return 0.0f;
    float total = optimal_total(s, ctx);
    return optimal_pmf_from(optimal_weight(s, light, ctx), total, class_count(s, ctx));
}

static void optimal_destroy(void *state) {
    OptimalSampler *s = state;
    if (!s) return;
    light_estimate_table_free(&s->table);
    free(s);
}

static const LightSamplerOps OPTIMAL_OPS = {
    .name = "optimal", .prepare = optimal_prepare, .select = optimal_select, .pmf = optimal_pmf,
    .destroy = optimal_destroy};

int light_sampler_optimal_create(LightSampler *ls, const Lights *lights, const Scene *scene, int occlusion) {
    OptimalSampler *s = malloc(sizeof *s);
    if (!s) return -1;
    *s = (OptimalSampler){lights, scene, occlusion, !occlusion && lights->count <= LIGHT_SAMPLER_SCRATCH, {0}};
    if (light_estimate_table_build(&s->table, lights) != 0) { free(s); return -1; }
    *ls = (LightSampler){&OPTIMAL_OPS, s, lights->count};
    return 0;
}
