/* renderer/stage_escaped.c: rays that left the scene see the environment. Its radiance is
 * MIS-weighted against the light sampler, evaluated with the context the previous vertex used
 * for NEE (kept in the path state). */
#include "integrator.h"

void stage_escaped(const Integrator *ig, Slice *s) {
    const PathState *ps = &ig->ps;
    const Lights *lights = ig->lights;
    for (uint32_t i = 0; i < s->num_escaped; ++i) {
        uint32_t p = s->escaped[i];
        path_shape_emission(ig, s, p, INFINITY, 0);
        if (lights->environment < 0) { path_end(ig, s, p); continue; }
        vec3 d = ps->ray[p].dir;
        vec3 le = scene_env_radiance(ig->scene, d);
        if (v3_is_black(le)) { path_end(ig, s, p); continue; }
        float w = 1.0f;
        if (!ps->prev_delta[p]) {
            LightSampleContext lc = {ps->prev_pos[p], ps->prev_normal[p], ps->prev_light_vertex[p]};
            lc.link_class = ps->prev_link_class[p]; /* (the environment is never linked) */
            float pl = light_sampler_pmf(ig->light_sampler, &lc, (uint32_t)lights->environment) *
                       light_env_pdf_li(lights, d);
            w = power_heuristic(ps->prev_scatter_pdf[p], pl);
        }
        path_add_radiance(ig, p, v3_scale(v3_mul(ps->throughput[p], le), w), RADIANCE_ENVIRONMENT, ps->depth[p]);
        path_end(ig, s, p);
    }
}
