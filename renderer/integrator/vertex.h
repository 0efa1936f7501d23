/* renderer/integrator/vertex.h: what every stage does at a path vertex (vertex.c), so that the stages call
 * this, never each other:
 *   - the MIS weight of light a path found against next-event estimation from its previous
 *     vertex (an emitter hit, a light shape crossed, the environment, an emissive volume's line),
 *   - direct light sampling's sampling half at a surface or medium vertex (the stage traces or
 *     queues the shadow ray), and the transmittance of a shadow ray through the media,
 *   - the light shapes a ray crosses,
 *   - the continuation: the scattering function's (or the guide's) sample applied to the
 *     throughput, the Russian roulette, the recorder's child vertex and the MIS context handed on,
 *   - the radiance funnel every contribution goes through (path_add_radiance), and a path's end.
 * A stage owns its queues and what is particular to it (a surface's boundary crossings and
 * shadow-ray offsets, the medium's free flights and its depth-first tracing). */
#ifndef CANDELA_VERTEX_H
#define CANDELA_VERTEX_H

#include "integrator.h"
#include "record.h"
#include "scatter.h"

/* Every addition to a path's radiance goes through here (throughput and MIS weight already
 * applied): the one place the radiance recorder observes the contributions of a path, and
 * where --clamp-direct / --clamp-indirect apply. An emitter or the environment found by the
 * path's ray goes to that ray's vertex, a shadow ray's contribution to the NEE vertex. depth:
 * that of the ray that found the emitter (emission, environment) or of the vertex that sampled
 * the light (direct), so the light reaches the camera through depth (depth + 1) scattering
 * vertices; at most one is "direct" (Cycles' clamps: the camera's emitters, NEE at the first
 * hit, and the first hit's BSDF samples that find a light), the rest indirect. */
static inline void path_add_radiance(const Integrator *ig, uint32_t p, vec3 contribution, RadianceSource source,
                                     uint32_t depth) {
    uint32_t vertices = source == RADIANCE_DIRECT ? depth + 1 : depth;
    float limit = vertices <= 1 ? ig->opt->clamp_direct : ig->opt->clamp_indirect;
    if (limit > 0.0f) { /* the largest channel to the limit, hue kept (biased: off by default) */
        float m = v3_max_component(contribution);
        if (m > limit) contribution = v3_scale(contribution, limit / m);
    }
    ig->ps.radiance[p] = v3_add(ig->ps.radiance[p], contribution);
    /* --guiding auto's probe: the light guiding could help with (two or more bounces, none of
     * them in a medium: there guiding removed only 1.07-1.22x of the variance, guide.c) */
    if (ig->guide.auto_state == GUIDE_AUTO_PROBING && vertices >= 2 && ig->ps.volume_bounces[p] == 0)
        ig->ps.probe_indirect[p] += v3_luminance(contribution);
    record_vertex_radiance(ig, p, &contribution, source);
}

/* The path ends: its ray's vertex is released. */
static inline void path_end(const Integrator *ig, Slice *s, uint32_t p) {
    record_path_end(ig, s, p);
}

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
 * roulette's scale. The stage then sets the ray that leaves. (Inline: the surface stage's hot
 * loop; a call cost 0.5% of bench.gltf's instructions.) */
#define RR_START_DEPTH 3 /* the first depth whose continuation is subject to the roulette, plus one */
/* Russian roulette on the throughput with refraction's radiance scaling removed: the path
 * survives with probability 1 - q, q = 1 - max(beta) rr_scale clamped to [0, 0.95], and its
 * throughput is divided by that. Returns 0 when the path is terminated. */
static inline int russian_roulette(vec3 *beta, double rr_scale, float u) {
    /* compares, not libm calls; NaN -> 0 as fmaxf(0, NaN) */
    float q = maxf(1.0f - v3_max_component(*beta) * (float)rr_scale, 0.0f);
    q = minf(q, 0.95f);
    if (u < q) return 0;
    *beta = v3_scale(*beta, 1.0f / (1.0f - q));
    return 1;
}

/* Adjoint-driven Russian roulette (ch. 1 §4.2.1; Vorba and Krivanek 2016), at a guided vertex
 * from the camera's hit on: the guide's estimate of the radiance arriving from the sampled
 * direction wi is L = flux p_guide(wi) / |cos| (a surface's guide learns L |cos|, a medium's L:
 * cos_term 1), so the path's expected contribution from here is lum(beta) L, beta the throughput
 * with this vertex's weight. Against its pixel's estimate I (the film at the last barrier) a path
 * expected to bring at least I / ADJOINT_RR_KEEP continues outright; below that it survives with
 * probability ADJOINT_RR_KEEP lum(beta) L / I (at least ADJOINT_RR_MIN_SURVIVAL, so an estimate
 * the guide got wrong boosts a survivor 20x at most), its throughput divided by that. Returns
 * that probability, or -1 where there is no estimate (an unguided or delta vertex, a leaf that
 * learned nothing, a black pixel so far): the throughput's roulette decides there. Measured
 * (scenes/RESULTS.md, "The adjoint-driven roulette and `auto`'s gain"): against the corrected
 * throughput roulette, paths the guide expects to matter live longer and the rest die sooner;
 * KEEP 10 had the lowest relMSE x time of 1, 3, 5, 10 and 30 on the indirect-lit box. */
#define ADJOINT_RR_KEEP 10.0f
#define ADJOINT_RR_MIN_SURVIVAL 0.05f
static inline float adjoint_survival(float pixel_estimate, vec3 beta, const ScatterSample *ss,
                                     const GuideDistribution *guide, float cos_term) {
    if (!(pixel_estimate > 0.0f) || !(ss->guide_pdf > 0.0f)) return -1.0f;
    float L = ss->guide_pdf * guide_distribution_flux(guide) / maxf(cos_term, 0.05f);
    if (!(L > 0.0f)) return -1.0f;
    float ratio = ADJOINT_RR_KEEP * v3_luminance(beta) * L / pixel_estimate;
    return ratio >= 1.0f ? 1.0f : maxf(ratio, ADJOINT_RR_MIN_SURVIVAL); /* NaN -> the minimum */
}

/* A scattering vertex hands on its MIS context (what a light found by the next ray is weighed
 * with) and the path moves to the next depth. */
static inline void path_scattered(const PathState *ps, uint32_t p, vec3 pos, const LightSampleContext *lc, float pdf,
                                  int delta) {
    ps->prev_pos[p] = pos;
    ps->prev_normal[p] = lc->n;
    ps->prev_light_vertex[p] = lc->vertex;
    ps->prev_scatter_pdf[p] = pdf;
    ps->prev_delta[p] = (uint8_t)delta;
    ps->prev_link_class[p] = (uint16_t)lc->link_class;
    ps->depth[p] = ps->depth[p] + 1;
}

static inline int vertex_continue(const Integrator *ig, Slice *s, uint32_t p, vec3 x, const ScatterSample *ss,
                                  const GuideDistribution *guide, DimsGroup *g, const LightSampleContext *lc,
                                  float cos_term, uint32_t flags, float segment) {
    const PathState *ps = &ig->ps;
    vec3 beta = v3_mul(ps->throughput[p], ss->weight);
    ps->rr_scale[p] *= ss->rr_factor;
    if (!v3_is_finite(beta) || v3_is_black(beta)) return 0;
    float survival = ig->guide.pixel_estimate ? adjoint_survival(ps->pixel_estimate[p], beta, ss, guide, cos_term) : -1.0f;
    if (survival >= 0.0f) { /* ch. 1 §4.2.1 */
        if (survival < 1.0f) {
            if (dims_lane(g, 3) >= survival) return 0;
            beta = v3_scale(beta, 1.0f / survival);
        }
    } else if (ps->depth[p] + 1 >= RR_START_DEPTH && !russian_roulette(&beta, ps->rr_scale[p], dims_lane(g, 3))) return 0;
    ps->throughput[p] = beta;
    record_vertex_child(ig, s, p, &x, &ss->wi, &beta, ss->pdf, ss->scatter_pdf, ss->guide_pdf, cos_term, flags, segment, guide);
    path_scattered(ps, p, x, lc, ss->scatter_pdf, ss->delta); /* MIS against NEE: the function's pdf (scatter.h) */
    return 1;
}

#endif
