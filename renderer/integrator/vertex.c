/* renderer/integrator/vertex.c: what every stage does at a path vertex (vertex.h says what and why). */
#include "vertex.h"

#include "rng.h"

/* One crossed shape light: its radiance with its MIS weight against NEE from the previous vertex
 * (in a medium walk, times the transmittance up to it: ratio tracking with a sub-stream of its
 * own per light). */
typedef struct ShapeEmission { const Integrator *ig; Slice *s; uint32_t p; int in_medium; } ShapeEmission;
static void shape_emission_add(void *user, uint32_t light, float t, vec3 le) {
    const ShapeEmission *se = user;
    const Integrator *ig = se->ig;
    const PathState *ps = &ig->ps;
    uint32_t p = se->p, link_class = ps->prev_link_class[p];
    /* light linking: a light that does not reach the previous vertex adds nothing there */
    if (link_class && !light_reaches(ig->lights, link_class, light)) return;
    const SceneRay *ray = &ps->ray[p];
    float w = 1.0f;
    LightSampleContext lc;
    if (vertex_previous_context(ps, p, &lc)) {
        vec3 prev = lc.p;
        /* the pdf from the previous vertex (a crossed medium boundary started this ray later) */
        float tp = isinf(t) ? INFINITY : v3_length(v3_sub(v3_madd(ray->org, ray->dir, t), prev));
        w = vertex_emitter_weight(ig, &lc, p, light, light_shape_pdf_li(&ig->lights->lights[light], prev, ray->dir, tp));
    }
    vec3 c = v3_scale(v3_mul(ps->throughput[p], le), w);
    if (se->in_medium && !v3_is_black(c)) {
        RngStream stream = rng_stream(ps->rng_key[p], ps->depth[p],
                                      RNG_STREAM_SHADOW + ((light + 1u) << 8) + ((uint32_t)ps->crossings[p] << 24));
        VolumeRng rng = {rng_stream_next_cb, &stream};
        vec3 T = media_transmittance_segment(ig->media, ps->medium[p], ray->org, ray->dir, t, &rng, &se->s->volume);
        c = v3_mul(c, T);
    }
    path_add_radiance(ig, p, c, RADIANCE_EMISSION, ps->depth[p]);
}

void vertex_shape_emission(const Integrator *ig, Slice *s, uint32_t p, float tmax, int in_medium) {
    const Lights *lights = ig->lights;
    if (!lights->num_shapes) return;
    const PathState *ps = &ig->ps;
    /* camera rays do not see them: Blender 3.4's lights have visible_camera off (Cycles then
     * skips them for camera rays), and they are Blender's lights */
    if (ps->depth[p] == 0) return;
    const SceneRay ray = ps->ray[p];
    ShapeEmission se = {ig, s, p, in_medium};
    lights_shape_crossings(lights, ray.org, ray.dir, ray.tnear, tmax, ps->prev_pos[p], shape_emission_add, &se);
}

/* Whether light_sample_li draws random numbers for the light (a point, spot or distant light
 * without a shape is one point, one direction). */
static int light_sample_uses_u(const Light *l) {
    return light_is_shape(l) || !(l->type == LIGHT_POINT || l->type == LIGHT_SPOT || l->type == LIGHT_DIRECTIONAL);
}

/* vertex_direct_light_u with the light's four numbers given (u_light) or, with the vertex's light
 * group, drawn from the path's dimensions only if the selected light uses them: the same
 * numbers either way, so the same estimate. */
static int direct_light_sample_core(const Integrator *ig, vec3 beta, const Scatter *sc, const LightSampleContext *lc,
                                    float u_select, float u_descend, const float *u_light, DimsGroup *group,
                                    LightLiSample *ls, vec3 *contrib, uint32_t *outcome) {
    float pmf;
    uint32_t li = light_sampler_select(ig->light_sampler, lc, u_select, u_descend, &pmf, outcome);
    ls->light = pmf > 0.0f ? li : UINT32_MAX;
    ls->cost = 0.0f;
    if (!(pmf > 0.0f)) return 0;
    const Light *light = &ig->lights->lights[li];
    /* light linking: every strategy gives unlinked lights probability 0 (a strategy that
     * could still land on one reports pmf 0 there): a guard, no sample */
    if (lc->link_class && !light_reaches(ig->lights, lc->link_class, li)) return 0;
    /* an emissive volume whose emission sampling is off (auto): found by tracking alone */
    if (light->type == LIGHT_VOLUME && !ig->emission_auto.on[light->medium]) return 0;
    float u[4] = {0.0f, 0.0f, 0.0f, 0.0f};
    if (!group) {
        for (int k = 0; k < 4; ++k) u[k] = u_light[k];
    } else if (light_sample_uses_u(light)) {
        /* the group's stratified pair (lanes 0, 1) goes to the light's 2D point: u0, u1 for shapes,
         * u1, u2 for an emissive mesh, whose u0 picks the triangle (with independent numbers the
         * order of the dimensions is kept: the images of the versions before Sobol') */
        int mesh = light->type == LIGHT_AREA && group->dims->sobol;
        u[mesh ? 1 : 0] = dims_lane(group, 0);
        u[mesh ? 2 : 1] = dims_lane(group, 1);
        u[mesh ? 0 : 2] = dims_lane(group, 3);
        if (light->type == LIGHT_VOLUME) u[3] = dims_bounce(group->dims, group->depth, RNG_BOUNCE_LIGHT_X); /* only they read it */
    }
    uint64_t collisions = lc->stats ? lc->stats->collisions : 0;
    int ok = light_sample_li(ig->lights, light, lc, u[0], u[1], u[2], u[3], ls);
    /* a volume light: the line's end (a ray), the pdf's DDA (about a ray), its collisions */
    if (light->type == LIGHT_VOLUME)
        ls->cost = 2.0f + (lc->stats ? 0.1f * (float)(lc->stats->collisions - collisions) : 0.0f);
    if (!ok) return 0;
    float scatter_pdf = 0.0f;
    vec3 f = scatter_eval(sc, ls->wi, ls->is_delta ? NULL : &scatter_pdf);
    if (v3_is_black(f)) return 0;
    float light_pdf = pmf * ls->pdf;
    float w = ls->is_delta ? 1.0f : power_heuristic(light_pdf, scatter_pdf);
    *contrib = v3_scale(v3_mul(v3_mul(beta, f), ls->radiance), w / light_pdf);
    return v3_is_finite(*contrib) && !v3_is_black(*contrib);
}

int vertex_direct_light_u(const Integrator *ig, vec3 beta, const Scatter *sc, const LightSampleContext *lc,
                          const float u[6], LightLiSample *ls, vec3 *contrib, uint32_t *outcome) {
    return direct_light_sample_core(ig, beta, sc, lc, u[0], u[1], u + 2, NULL, ls, contrib, outcome);
}

int vertex_direct_light(const Integrator *ig, uint32_t p, const Scatter *sc, const LightSampleContext *lc,
                        LightLiSample *ls, vec3 *contrib, uint32_t *outcome) {
    const PathState *ps = &ig->ps;
    PathDims dims = path_dims(ig, p);
    uint32_t depth = ps->depth[p];
    DimsGroup light = dims_group(&dims, depth, DIMS_LIGHT); /* the light's u, v, the selection, the light's w */
    /* the descent number only for a sampler that reads it (the others ignore it) */
    float u_descend = light_sampler_uses_descend(ig->light_sampler) ? dims_bounce(&dims, depth, RNG_BOUNCE_LIGHT_DESCEND)
                                                                     : 0.0f;
    float u_select = depth == 0 ? dims_bounce(&dims, depth, RNG_BOUNCE_LIGHT_SELECT) /* in the camera group */
                                : dims_lane(&light, 2);
    return direct_light_sample_core(ig, ps->throughput[p], sc, lc, u_select, u_descend, NULL, &light, ls,
                                    contrib, outcome);
}

vec3 vertex_shadow_transmittance(const Integrator *ig, Slice *s, uint64_t key, uint32_t depth, uint32_t medium, vec3 o,
                                 vec3 d, float tmax) {
    RngStream stream = rng_stream(key, depth, RNG_STREAM_SHADOW);
    VolumeRng rng = {rng_stream_next_cb, &stream};
    return media_transmittance_segment(ig->media, medium, o, d, tmax, &rng, &s->volume);
}
