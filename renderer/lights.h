/* renderer/lights.h (private): lights and light selection.
 *
 * Lights: punctual (point, spot, directional; delta), area (one light per emissive glTF
 * primitive per instance) and the environment map (importance-sampled lat-long).
 *
 * An area light's triangle is picked by its inner light tree (lighttree.h, cache-points spec
 * §5.5: importance from the shading point and normal) when it has more than
 * LIGHT_AREA_TREE_MAX_CDF triangles, else in proportion to area (l->triangles). The tree
 * also falls back to the area CDF for a context from which the tree's root has zero
 * importance (the bounds say the point sees no emitting side); sampling and
 * light_area_pdf_li make that decision with the same function, so the pdf stays exact.
 *
 * Light selection goes through one interface so that MIS stays correct whatever the
 * strategy: light_select() picks a light for a shading context and returns its probability;
 * light_select_pmf() returns the probability the same context gives a named light. The two
 * must agree exactly (tests/test_lights.c). Strategies: uniform, power, the light BVH
 * (lighttree.h: importance from the shading point and normal), per-vertex optimal, and cache
 * points (cachepoints/, set up in cachepoint_setup.c), whose context carries the vertex's
 * cache point and near-light sum (lights_prepare_context). */
#ifndef CANDELA_LIGHTS_H
#define CANDELA_LIGHTS_H

#include <stdint.h>

#include "cachepoints.h"
#include "candela.h"
#include "lighttree.h"
#include "sampling.h"
#include "vecmath.h"

struct Scene;

typedef enum { LIGHT_POINT, LIGHT_SPOT, LIGHT_DIRECTIONAL, LIGHT_AREA, LIGHT_ENVIRONMENT } LightType;

typedef struct Light {
    LightType type;
    vec3 position;        /* point, spot */
    vec3 direction;       /* spot, directional: the direction light travels */
    vec3 intensity;       /* point/spot: W/sr; directional: irradiance W/m^2 */
    float cos_inner, cos_outer; /* spot */
    /* area */
    uint32_t instance, local_prim, global_prim;
    float area;               /* world-space area of the primitive */
    vec3 emission;            /* emissiveFactor x strength (times the texture, if any) */
    Distribution1D triangles; /* world triangle areas */
    float *world_vertices;    /* 9 floats per triangle, world space */
    int two_sided;            /* the material is double-sided: emits from both faces */
    float power;              /* estimate for the power sampler (luminance, W) */
    LightTree tri_tree;       /* inner tree over the triangles (node_count 0: area CDF only) */
} Light;

/* Area lights with at most this many triangles pick them by area alone (no inner tree). */
#define LIGHT_AREA_TREE_MAX_CDF 8

typedef struct LightSampleContext {
    vec3 p;
    vec3 n;     /* shading normal, or zero for a point in a medium */
    /* cache point of this vertex + 1 and the summed weight of its near lights at the vertex,
     * when the caller already has them from lights_prepare_context (0: look them up). The
     * wavefront stores both per path, so NEE, counting and the MIS PDF at the next wave use
     * one nearest-point query and one near-light pass (spec §5.1, §5.6). */
    uint32_t cache_point1;
    float cp_near_total;
    /* scratch for the near lights' weights at this vertex (CACHEPOINTS_MAX_NEAR floats), filled
     * by lights_prepare_context and reused by light_select; NULL: evaluate them again. Never
     * stored: the MIS PDF at the next wave needs only one light's weight. */
    float *cp_near_w;
} LightSampleContext;

typedef struct Lights {
    Light *lights;
    uint32_t count;
    int32_t environment;        /* index of the environment light or -1 */
    Distribution2D env_distribution;
    CandelaLightSampler strategy;
    Distribution1D power_distribution;
    LightTree tree;             /* CANDELA_LIGHT_SAMPLER_TREE only */
    const struct Scene *scene;  /* for --optimal-occlusion's shadow rays */
    int optimal_occlusion;
    float env_estimate[7];      /* environment irradiance on the 6 axis planes + fluence */
    /* CANDELA_LIGHT_SAMPLER_CACHEPOINTS (built by lights_build_cachepoints once the thread
     * pool exists; NULL otherwise, or when fewer than 10 points fell back to optimal) */
    CachePoints *cachepoints;
    CachePointLights cp_view;
    float *cp_centroid;
    uint8_t *cp_infinite;
    CachePointStats cp_stats;
    /* --cachepoint-build cut: the light tree (ls->tree) seen by the cache points */
    CachePointTree cp_tree;
    uint32_t *cp_second, *cp_leaf_light, *cp_light_leaf;
} Lights;

/* Build from the scene's punctual lights, emissive primitives and environment. */
int lights_build(struct Scene *scene, CandelaLightUnits units, CandelaLightSampler strategy,
                 char *err, size_t err_len);
void lights_free(Lights *lights);

/* §Light selection interface. u picks the light; u_descend is a second uniform that cache
 * point clusters use to descend the light tree. *cp_slot (may be NULL) receives the cache
 * point visibility slot to count the attempt in (UINT32_MAX: none). */
uint32_t light_select(const Lights *lights, const LightSampleContext *ctx, float u, float u_descend, float *pmf,
                      uint32_t *cp_slot);
float light_select_pmf(const Lights *lights, const LightSampleContext *ctx, uint32_t light);

/* lightselect_optimal.c: unoccluded contribution estimates (cache points spec §3.4) and
 * the locally optimal strategy (§5.8). */
float light_contribution_estimate(const Lights *ls, const Light *l, vec3 p, vec3 n);
uint32_t optimal_select(const Lights *ls, const LightSampleContext *ctx, float u, float *pmf);
float optimal_pmf(const Lights *ls, const LightSampleContext *ctx, uint32_t light);
void lights_env_estimates(const struct Scene *scene, float out[7]);
void light_contribution_estimate7(const Lights *ls, const Light *l, vec3 p, float out[7]);

/* cachepoint_setup.c: candidates (§3.1.1), estimate callbacks and the build; pool is the
 * renderer's ThreadPool. */
int lights_build_cachepoints(struct Scene *scene, void *pool, const CandelaOptions *o, char err[CANDELA_ERR_LEN]);
/* Fills ctx->cache_point1 and ctx->cp_near_total (and ctx->cp_near_w) when cache points
 * select lights (else leaves them 0): once per vertex, before light_select and before
 * storing the context for the MIS PDF at the next wave. *hint (may be NULL) is the previous
 * vertex's cache point of a coherent stream, updated: it speeds up the nearest-point search
 * and never changes its result. */
void lights_prepare_context(const Lights *ls, LightSampleContext *ctx, uint32_t *hint);

/* A sampled point on a light as seen from a shading point. */
typedef struct LightLiSample {
    vec3 wi;          /* unit, from the shading point to the light */
    float distance;   /* INFINITY for directional and environment */
    vec3 radiance;    /* arriving radiance (delta lights: intensity / r^2 or irradiance) */
    float pdf;        /* solid-angle pdf given the light (1 for delta lights) */
    int is_delta;
    uint32_t triangle; /* area lights: the sampled triangle (for light_area_pdf_li) */
} LightLiSample;

/* Samples a point on `light` as seen from ctx (ctx->n steers an area light's inner tree; use
 * the same context for light_area_pdf_li). */
int light_sample_li(const struct Scene *scene, const Light *light, const LightSampleContext *ctx, float u0,
                    float u1, float u2, LightLiSample *s);
/* Solid-angle pdf (given the light) of sampling the point y with normal ny on triangle
 * `triangle` of an area light from ctx: p_tri(triangle | ctx) / area(triangle) * d^2 / |cos|. */
float light_area_pdf_li(const Light *light, const LightSampleContext *ctx, uint32_t triangle, vec3 y, vec3 ny);
/* Probability that light_sample_li picks `triangle` of an area light from ctx. */
float light_area_triangle_pmf(const Light *light, const LightSampleContext *ctx, uint32_t triangle);
/* Builds l->tri_tree from world_vertices, emission and two_sided when the light has more than
 * LIGHT_AREA_TREE_MAX_CDF triangles (else leaves it empty). 0 ok, -1 out of memory. */
int light_area_tree_build(Light *l);
/* Frees an area light's arrays and tree. */
void light_area_free(Light *l);
/* Solid-angle pdf of the environment light for direction d. */
float light_env_pdf_li(const struct Scene *scene, vec3 d);

#endif
