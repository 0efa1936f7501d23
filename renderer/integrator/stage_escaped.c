/* renderer/integrator/stage_escaped.c: rays that left the scene see the environment. Its radiance is
 * MIS-weighted against the light sampler, evaluated with the context the previous vertex used
 * for NEE (kept in the path state). */
#include "record.h"
#include "vertex.h"

#define ESCAPED_PREFETCH 8 /* escaped rays ahead whose recorder vertices are fetched (then their parents) */

void stage_escaped(const Integrator *ig, Slice *s) {
    const PathState *ps = &ig->ps;
    const Lights *lights = ig->lights;
    for (uint32_t i = 0; i < s->num_escaped; ++i) {
        uint32_t p = s->escaped[i];
        record_prefetch_ray(ig, s->escaped, s->num_escaped, i + ESCAPED_PREFETCH);
        record_prefetch_ray_parent(ig, s->escaped, s->num_escaped, i + ESCAPED_PREFETCH / 2);
        vertex_shape_emission(ig, s, p, INFINITY, 0);
        if (lights->environment < 0) { path_end(ig, s, p); continue; }
        vec3 d = ps->ray[p].dir;
        vec3 le = scene_env_radiance(ig->scene, d);
        if (v3_is_black(le)) { path_end(ig, s, p); continue; }
        float w = 1.0f;
        LightSampleContext lc; /* (the environment is never linked) */
        if (vertex_previous_context(ps, p, &lc))
            w = vertex_emitter_weight(ig, &lc, p, (uint32_t)lights->environment, light_env_pdf_li(lights, d));
        path_add_radiance(ig, p, v3_scale(v3_mul(ps->throughput[p], le), w), RADIANCE_ENVIRONMENT, ps->depth[p]);
        path_end(ig, s, p);
    }
}
