/* renderer/integrator/scatter.h (private): the scattering interface of a path vertex.
 *
 * Whatever scatters light at a vertex is a Scatter: sample a direction, evaluate the
 * function and its pdf for a given direction. Directions are world-space unit vectors
 * pointing away from the vertex. A Scatter is a surface BSDF (bsdf.h) in its shading frame or
 * a medium's Henyey-Greenstein phase function (volumes.h); a guided mixture (path guiding,
 * one-sample MIS or RIS over BSDF and guide) is a further kind behind the same three calls,
 * so the stages that sample directions, do NEE and weigh MIS never change when one is added.
 *
 * Surfaces keep the BSDF-light geometry guard: a direction whose geometric and shading
 * hemispheres disagree is neither sampled nor evaluated (no light leaks through shading
 * normals). */
#ifndef CANDELA_SCATTER_H
#define CANDELA_SCATTER_H

#include "bsdf.h"
#include "guiding.h"
#include "lights.h"
#include "scene.h"
#include "sequence.h"
#include "vecmath.h"

typedef enum { SCATTER_BSDF = 0, SCATTER_PHASE = 1 } ScatterKind;

/* How a guided Scatter combines its function with the guide (path-guiding-in-production.txt
 * ch. 1 §3.2-3.3): one-sample MIS of the two, or RIS over a candidate of each. The MIS weights
 * between these directions and the light sampler's use the scattering function's own pdf on both
 * sides (scatter_eval for NEE, ScatterSample.scatter_pdf for an emitter a direction finds): any
 * pair of weights that sums to 1 keeps the combination unbiased, and the guided sample's own
 * pdf stays in its estimator's denominator. Against the mixture's pdf this saves a guide pdf
 * per NEE sample, and had higher variance (cornell_indirect 192x192, 256 spp, MIS: relative
 * variance 3.16e-3 against 2.99e-3; time 1.62x against 1.55x unguided's). */
typedef enum { SCATTER_GUIDE_NONE = 0, SCATTER_GUIDE_MIS = 1, SCATTER_GUIDE_RIS = 2 } ScatterGuideMode;
/* RIS's target t = f|cos| (beta / 4 pi + (1 - beta) g) (§3.3, Eq. 10, where beta = 1/2): the
 * uniform share keeps the target positive where the guide learned nothing. A guide learned from
 * few samples misses real light, and a candidate picked there carries the weight (1/N) sum w / t:
 * with beta = 1/2 those rare heavy weights made RIS noisier than one-sample MIS on
 * scenes/guiding_interior.gltf (160x120, 256 spp, 3 seeds: MSE 2.14, 1.97, 1.56 e-5 against
 * 1.50, 1.40, 1.40 e-5 with 3/4; 0.9 gave 1.59) */
#define SCATTER_RIS_UNIFORM_SHARE 0.75f
#define SCATTER_PHASE_GUIDE_MAX_G 0.95f /* |g| above this: the phase function alone (§3.1) */

typedef struct Scatter {
    ScatterKind kind;
    float g;           /* phase: Henyey-Greenstein anisotropy */
    vec3 wo_world;     /* phase: the outgoing direction (world) */
    Frame frame;       /* shading frame (n: the shading normal, turned towards wo unless the
                        * surface transmits) */
    vec3 ng;           /* geometric normal, turned like frame.n */
    vec3 wo;           /* outgoing direction in the local frame */
    /* the caller's BSDF parameters and their derived constants (the material's, prepared at
     * load, or prep_own, computed here once per vertex): pointed to, not copied (the copy
     * had stalled on the parameters just written field by field); both outlive the Scatter,
     * which is never copied */
    const BsdfParams *bsdf;
    const BsdfPrepared *prep;
    BsdfPrepared prep_own;
    int transmissive;  /* has a transmission lobe: receives light from both sides */
    int wo_outside;    /* wo is on the geometric normal's side (refraction enters the surface) */
    const GuideDistribution *guide; /* the learned incident radiance here (NULL: not guided) */
    ScatterGuideMode guide_mode;
    float guide_share;  /* MIS: the scattering function's share, the guide leaf's learned one
                         * (ch. 1 §3.2.1; 1: the function alone); RIS: unused */
    int guide_pdf_wanted; /* where the share is 1, still evaluate the guide's pdf of the direction
                           * (training: the share's statistics need it) */
} Scatter;

typedef struct ScatterSample {
    vec3 wi;          /* sampled direction (world) */
    vec3 weight;      /* f |cos| / pdf: what the path throughput is multiplied by */
    float pdf;        /* pdf of the sampling technique (solid angle; a lobe pmf for deltas) */
    int delta;        /* the direction came from a delta lobe: no MIS, pdf is not a density */
    int transmitted;  /* it crossed the surface (refraction) */
    float rr_factor;  /* factor for the Russian roulette throughput: 1/eta^2 refraction
                       * scaling removed, and a guided sample's weight brought back to what
                       * sampling the function alone gives where that is larger (max(1, p /
                       * p_bsdf), ch. 1 §4.1.1; scatter.c guided_rr_factor) */
    float scatter_pdf; /* the scattering function's own pdf of wi (= pdf unguided) */
    float guide_pdf;   /* the guide's pdf of wi (0: unguided) */
} ScatterSample;

/* The BSDF of a surface hit seen from direction wo_world (unit, pointing away from the hit),
 * prepared from bsdf (scene_material_prepared), or NULL: prepared here. */
void scatter_init_surface_prepared(Scatter *s, const SurfaceHit *h, const BsdfParams *bsdf,
                                   const BsdfPrepared *prepared, vec3 wo_world);
/* Whether sampling reads its lobe-choice number: a BSDF with more than one lobe (a Lambert-only
 * one and the phase function ignore it, so a caller may pass 0 instead of drawing it). */
static inline int scatter_uses_lobe_u(const Scatter *s) { return s->kind == SCATTER_BSDF && !s->prep->lambert; }
/* A medium's Henyey-Greenstein phase function at a scattering point seen from wo_world. */
void scatter_init_phase(Scatter *s, float g, vec3 wo_world);
/* 1 if a direction was sampled (u_lobe picks a lobe, u1 and u2 the direction in it). Never
 * guided. */
int scatter_sample(const Scatter *s, float u_lobe, float u1, float u2, ScatterSample *out);
/* The same with the guide when there is one: u[0..2] as above; with MIS, u[0] also chooses
 * between the function and the guide (rescaled for the lobe) and the chosen one takes u[1],
 * u[2]; with RIS, u[3], u[4] are the guide candidate's direction and u[5] the choice between
 * the candidates. */
int scatter_sample_guided(const Scatter *s, const float u[6], ScatterSample *out);
/* A hint ahead of scatter_sample_guided with the same numbers: fetches the guide's table entry
 * it will read (its alias slot when u chooses the guide, the root of its pdf tree when it
 * chooses the function; RIS reads both). Changes nothing. */
void scatter_prefetch_guided(const Scatter *s, const float u[6]);
/* The six numbers of scatter_sample_guided from the vertex's scatter group (DIMS_SCATTER: u, v,
 * lobe, roulette) and, for RIS, its guide group (the guide candidate's u, v and the choice); the
 * lobe number only where there is a lobe to choose or a guided MIS choice (the others ignore
 * it). One-sample MIS takes its choice from the lobe lane, so the (u, v) of either technique is
 * the scatter group's stratified pair and a guided vertex draws no more numbers than an
 * unguided one (the guide group's three lanes were 20% of a guided render's instructions). */
static inline void scatter_numbers(const Scatter *s, DimsGroup *scatter, float u[6]);
static inline void scatter_numbers(const Scatter *s, DimsGroup *scatter, float u[6]) {
    u[0] = scatter_uses_lobe_u(s) || s->guide ? dims_lane(scatter, 2) : 0.0f;
    u[1] = dims_lane(scatter, 0);
    u[2] = dims_lane(scatter, 1);
    u[3] = u[4] = u[5] = 0.0f;
    if (s->guide && s->guide_mode == SCATTER_GUIDE_RIS) {
        DimsGroup guide = dims_group(scatter->dims, scatter->depth, DIMS_GUIDE);
        for (uint32_t l = 0; l < 3; ++l) u[3 + l] = dims_lane(&guide, l);
    }
}
/* 1 where guiding may help (ch. 1 §3.1): surfaces with a lobe rougher than 0.05 and no delta
 * lobe, media with |g| < 0.95. Ask before looking the guide up: the lookup is a tree descent. */
int scatter_guidable(const Scatter *s);
/* Guides the scatter with d (NULL: not guided). Only for a scatter scatter_guidable accepted
 * (the callers ask first, to skip the lookup; asking again here was 1.5% of a guided render). */
void scatter_set_guide(Scatter *s, const GuideDistribution *d, ScatterGuideMode mode, int training);
/* f |cos| for direction wi (world), and the pdf the scattering function's own sampling has for it
 * (a guided Scatter's too: the MIS weight against NEE, above); zero when the direction is not
 * reachable (delta lobes, the geometry guard). pdf may be NULL. */
vec3 scatter_eval(const Scatter *s, vec3 wi, float *pdf);
/* 1 if every lobe is a delta: no direction can be evaluated, so NEE is useless. */
static inline int scatter_is_delta(const Scatter *s) { return s->kind == SCATTER_BSDF && bsdf_prepared_is_delta(s->prep); }
/* The normal of the light-selection context: the shading normal, or zero (an omnidirectional
 * receiver, as in a medium) for a surface that transmits light from both sides. */
static inline vec3 scatter_light_normal(const Scatter *s) {
    return s->kind == SCATTER_PHASE || s->transmissive ? v3s(0.0f) : s->frame.n;
}
/* The glossy lobe light selection may weigh lights by (scatter_lobe.c; light_sampler_uses_lobe):
 * zero weight for diffuse and rough surfaces, transmissive ones and phase functions. */
void scatter_light_lobe(const Scatter *s, LightLobe *lobe);
/* The side of the surface a ray in direction d leaves from, for offsetting its origin. */
static inline vec3 scatter_side_normal(const Scatter *s, vec3 d) {
    return v3_dot(d, s->ng) > 0.0f ? s->ng : v3_neg(s->ng);
}

#endif
