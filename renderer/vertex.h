/* renderer/vertex.h: what every stage does at a path vertex (vertex.c), so that the stages call
 * this, never each other:
 *   - the MIS weight of light a path found against next-event estimation from its previous
 *     vertex (an emitter hit, a light shape crossed, the environment, an emissive volume's line),
 *   - direct light sampling's sampling half at a surface or medium vertex (the stage traces or
 *     queues the shadow ray), and the transmittance of a shadow ray through the media,
 *   - the light shapes a ray crosses,
 *   - the continuation: the scattering function's (or the guide's) sample applied to the
 *     throughput, the Russian roulette, the recorder's child vertex and the MIS context handed on.
 * A stage owns its queues and what is particular to it (a surface's boundary crossings and
 * shadow-ray offsets, the medium's free flights and its depth-first tracing). */
#ifndef CANDELA_VERTEX_H
#define CANDELA_VERTEX_H

#include "integrator.h"
#include "scatter.h"

/* The previous vertex's light-selection context (what its NEE used, kept in the path state),
 * for weighing light the path found against NEE from there. Returns 0 when the previous vertex
 * sampled a delta lobe (or is the camera): NEE could not have found that light, the weight is 1. */
static inline int vertex_previous_context(const PathState *ps, uint32_t p, LightSampleContext *lc) {
    if (ps->prev_delta[p]) return 0;
    *lc = (LightSampleContext){ps->prev_pos[p], ps->prev_normal[p], ps->prev_light_vertex[p]};
    lc->link_class = ps->prev_link_class[p];
    return 1;
}

/* The power-heuristic weight of light from `light` that the previous vertex's scattering
 * sample found, against NEE's probability of the same: the light sampler's pmf there times the
 * light's own pdf_li of the point (solid angle; the caller computes it with lc, for its kind of
 * emitter). MIS against NEE uses the scattering function's own pdf (scatter.h). */
static inline float vertex_emitter_weight(const Integrator *ig, const LightSampleContext *lc, uint32_t p,
                                          uint32_t light, float pdf_li) {
    float pl = light_sampler_pmf(ig->light_sampler, lc, light) * pdf_li;
    return power_heuristic(ig->ps.prev_scatter_pdf[p], pl);
}

/* The light shapes (spheres, rects, disks; suns when the ray escapes, tmax INFINITY) that path
 * p's ray crosses between its tnear and tmax add their radiance, MIS-weighted against NEE from
 * the previous vertex (README "Light shapes"; lights are transparent to rays and invisible to
 * camera rays, as Blender 3.4's lights are in Cycles). in_medium: the medium walk gathers a
 * segment's lights before its free flight, each times the transmittance up to it, and then
 * moves the ray's tnear past the segment. */
void vertex_shape_emission(const Integrator *ig, Slice *s, uint32_t p, float tmax, int in_medium);

/* Next-event estimation's sampling half, shared by surface and medium vertices: the light
 * sampler picks a light (its outcome token in *outcome either way), the light is sampled and
 * the scattering function evaluated, MIS-weighted with the power heuristic. Returns 1 with the
 * pending contribution (before visibility) in *contrib when it is finite and non-zero. The
 * vertex's bounce dimensions supply every random number. */
int vertex_direct_light(const Integrator *ig, uint32_t p, const Scatter *sc, const LightSampleContext *lc,
                        LightLiSample *ls, vec3 *contrib, uint32_t *outcome);
/* The same with the throughput and the six uniforms (select, descend, the light's four) given
 * (a technique with its own random numbers: in-scattering sampling). */
int vertex_direct_light_u(const Integrator *ig, vec3 beta, const Scatter *sc, const LightSampleContext *lc,
                          const float u[6], LightLiSample *ls, vec3 *contrib, uint32_t *outcome);

/* Transmittance (RGB) of a shadow segment starting in mesh medium `medium` through the scene's
 * media, with the path's shadow sub-stream of this depth (1 without media). */
vec3 vertex_shadow_transmittance(const Integrator *ig, Slice *s, uint64_t key, uint32_t depth, uint32_t medium,
                                 vec3 o, vec3 d, float tmax);

/* The continuation at vertex x: the sample ss (the scattering function's or the guide's)
 * multiplies the throughput, Russian roulette decides from depth RR_START_DEPTH - 1 on (with
 * the roulette's number, lane 3 of the vertex's scatter group g), the recorder gets the child
 * vertex of the ray that leaves (cos_term, flags and segment for its sample), and the vertex
 * hands on its MIS context lc; the path moves to the next depth. Returns 0 when the path ends
 * (a zero or non-finite throughput, or the roulette) and changes nothing then but the
 * roulette's scale. The stage then sets the ray that leaves. */
#define RR_START_DEPTH 3 /* the first depth whose continuation is subject to the roulette, plus one */
int vertex_continue(const Integrator *ig, Slice *s, uint32_t p, vec3 x, const ScatterSample *ss, DimsGroup *g,
                    const LightSampleContext *lc, float cos_term, uint32_t flags, float segment);

#endif
