/* renderer/lights.h (private): lights and light selection.
 *
 * Lights: punctual (point, spot, directional; delta), area (one light per emissive glTF
 * primitive per instance; triangles chosen in proportion to area) and the environment map
 * (importance-sampled lat-long).
 *
 * Light selection goes through one interface so that MIS stays correct whatever the
 * strategy: light_select() picks a light for a shading context and returns its probability;
 * light_select_pmf() returns the probability the same context gives a named light. The two
 * must agree exactly (tests/test_lights.c). Strategies: uniform, power, and the light BVH
 * (lighttree.h: importance from the shading point and normal). Cache points (issue 3) plug
 * in as another LightSelectStrategy whose context carries the cache point index. */
#ifndef CANDELA_LIGHTS_H
#define CANDELA_LIGHTS_H

#include <stdint.h>

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
} Light;

typedef struct LightSampleContext {
    vec3 p;
    vec3 n;     /* shading normal, or zero for a point in a medium */
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
} Lights;

/* Build from the scene's punctual lights, emissive primitives and environment. */
int lights_build(struct Scene *scene, CandelaLightUnits units, CandelaLightSampler strategy,
                 char *err, size_t err_len);
void lights_free(Lights *lights);

/* §Light selection interface. */
uint32_t light_select(const Lights *lights, const LightSampleContext *ctx, float u, float *pmf);
float light_select_pmf(const Lights *lights, const LightSampleContext *ctx, uint32_t light);

/* lightselect_optimal.c: unoccluded contribution estimates (cache points spec §3.4) and
 * the locally optimal strategy (§5.8). */
float light_contribution_estimate(const Lights *ls, const Light *l, vec3 p, vec3 n);
uint32_t optimal_select(const Lights *ls, const LightSampleContext *ctx, float u, float *pmf);
float optimal_pmf(const Lights *ls, const LightSampleContext *ctx, uint32_t light);
void lights_env_estimates(const struct Scene *scene, float out[7]);

/* A sampled point on a light as seen from a shading point. */
typedef struct LightLiSample {
    vec3 wi;          /* unit, from the shading point to the light */
    float distance;   /* INFINITY for directional and environment */
    vec3 radiance;    /* arriving radiance (delta lights: intensity / r^2 or irradiance) */
    float pdf;        /* solid-angle pdf given the light (1 for delta lights) */
    int is_delta;
} LightLiSample;

int light_sample_li(const struct Scene *scene, const Light *light, vec3 p, float u0, float u1,
                    float u2, LightLiSample *s);
/* Solid-angle pdf (given the light) of sampling the point y with normal ny on an area light
 * from p. */
float light_area_pdf_li(const Light *light, vec3 p, vec3 y, vec3 ny);
/* Solid-angle pdf of the environment light for direction d. */
float light_env_pdf_li(const struct Scene *scene, vec3 d);

#endif
