/* renderer/integrator/path_state.h (private): the integrator's per-path state, declared once.
 *
 * PathState is a structure of arrays indexed by a path's slot in the batch. PATH_STATE_FIELDS
 * is the one list of its members; the struct, allocation, release and the shading prefetch
 * all expand from it, so adding a member is one line here. Each entry is
 *     F(type, name, prefetch)
 * where prefetch says whether surface shading, which visits slots in a random order (hits are
 * sorted by primitive), fetches the member ahead: R (read), W (written), N (not).
 *
 * The volume walk, which draws an unbounded number of random numbers per bounce, uses a
 * sub-stream keyed by (rng_key, depth) (rng.h: rng_stream), so it needs no member at all. */
#ifndef CANDELA_PATH_STATE_H
#define CANDELA_PATH_STATE_H

#include <stdint.h>

#include "lights.h"
#include "scene.h"
#include "vecmath.h"

#define PATH_STATE_FIELDS(F)                                                                        \
    /* -- path: identity and accumulation */                                                     \
    F(uint64_t, rng_key, R)         /* counter-based RNG key: (seed, pixel, sample) */           \
    F(uint32_t, pixel, N)           /* the film pixel the path belongs to */                     \
    F(uint32_t, sample_rindex, R)   /* its sample's index within the pixel, bit-reversed (sequence.h) */ \
    F(uint32_t, scramble, R)        /* the pixel's Sobol' seed (sequence.h) */                  \
    F(uint32_t, depth, W)           /* the vertex the path shades next: 0 = the camera ray's hit */ \
    F(uint32_t, volume_bounces, W)  /* how many of its vertices so far were in media */          \
    F(uint32_t, medium, W)          /* the mesh medium its ray travels in (media.h; 0: none) */  \
    F(uint32_t, crossings, N)       /* invisible medium boundaries crossed (bounded) */          \
    F(vec3, radiance, W)            /* accumulated L; written only through path_add_radiance */  \
    F(vec3, throughput, W)          /* beta: the path's weight so far */                         \
    F(float, pixel_estimate, N)     /* its pixel's estimate for the adjoint-driven roulette (0: none) */ \
    F(double, rr_scale, W)          /* throughput factor for the Russian roulette decision only \
                                     * (removes refraction's eta^2 radiance scaling and guided   \
                                     * sampling's max(1, p / p_bsdf): double, ch. 1 §4.1.1) */   \
    F(uint32_t, pv, W)              /* the radiance recorder's vertex of the ray (PVIndex) */    \
    F(uint8_t, record_skip, N)      /* the recorder skips this path (path skipping) */          \
    F(float, reg_roughness, N)      /* path-space regularisation: the last vertex's roughness   \
                                     * alpha' (ch. 1 §7 Eq. 25; 0 at the camera) */               \
    /* -- ray: what this wave traces */                                                          \
    F(SceneRay, ray, R)                                                                          \
    /* -- hit: the closest hit of the ray (t = INFINITY: escaped) */                             \
    F(SceneHit, hit, R)                                                                          \
    /* -- MIS context of the previous vertex, for when this wave's ray finds a light */          \
    F(vec3, prev_pos, W)            /* its position, */                                          \
    F(vec3, prev_normal, W)         /* its light-selection normal (zero: omnidirectional), */    \
    F(LightVertex, prev_light_vertex, N) /* the light sampler's token for it, */                 \
    F(float, prev_scatter_pdf, W)   /* the pdf of the direction it sampled, */                   \
    F(uint8_t, prev_delta, W)       /* and 1 if that was a delta lobe (or the camera): no MIS */ \
    F(uint16_t, prev_link_class, W) /* and its light-linking class (0: every light; the camera) */ \
    /* -- shadow ray of this wave's vertex */                                                    \
    F(SceneRay, shadow_ray, N)                                                                   \
    F(vec3, shadow_contrib, N)      /* the NEE contribution if the shadow ray gets through */    \
    F(uint32_t, shadow_outcome, N)  /* the light sampler's outcome token for the selection */    \
    F(uint32_t, shadow_depth, N)    /* the depth of the vertex that cast it (its RNG sub-stream) */ \
    F(uint32_t, shadow_medium, N)   /* the mesh medium it starts in */                          \
    F(uint32_t, shadow_light, N)    /* the light it aims at */                                   \
    F(uint32_t, shadow_pv, N)       /* the recorder's vertex of the shadow ray (PVIndex) */      \
    /* -- the probe of in-scattering sampling auto (volume_auto.c), first iterations only */   \
    F(uint32_t, probe_medium, N)    /* the medium (media_id + 1) of its first camera segment   \
                                     * that ran in-scattering sampling; 0: none */              \
    F(float, probe_null, N)         /* that NEE by tracking alone, unweighted (luminance) */     \
    F(float, probe_mis, N)          /* the same NEE by both techniques, MIS-weighted */          \
    F(float, probe_cost, N)         /* in-scattering sampling's cost (rays + collisions / 10) */ \
    /* -- the probe of emission sampling auto (volume_auto.c) */                                \
    F(uint32_t, probe_em_medium, N) /* the first emissive medium (media_id + 1) it met; 0: none */ \
    F(float, probe_em_on, N)        /* that medium's emission: NEE and tracking, MIS-weighted */ \
    F(float, probe_em_off, N)       /* the same by tracking alone (unweighted) */                \
    F(float, probe_em_cost, N)      /* emission sampling's cost (2 per NEE of the volume) */     \
    /* -- the probe of --guiding auto (guide.c), first 4 spp only */                             \
    F(float, probe_indirect, N)     /* luminance of its contributions through 2+ scattering vertices */ \
    /* -- first-hit AOVs */                                                                      \
    F(vec3, aov_albedo, N)                                                                       \
    F(vec3, aov_normal, N)                                                                       \
    F(float, aov_depth, N)          /* first-hit distance; INFINITY: the camera ray escaped */   \
    F(vec3, aov_recorder, N)        /* --aov recorder-debug: this path's splat */                \
    F(vec3, aov_sel_point, N)       /* the light sampler's AOV at the first hit (two colours) */ \
    F(vec3, aov_sel_light, N)

typedef struct PathState {
    uint32_t capacity;
#define PATH_STATE_MEMBER(type, name, prefetch) type *name;
    PATH_STATE_FIELDS(PATH_STATE_MEMBER)
#undef PATH_STATE_MEMBER
} PathState;

/* Allocates every member for n paths (zeroed). 0 ok, -1 out of memory (nothing is left). */
int path_state_alloc(PathState *ps, uint32_t n);
void path_state_free(PathState *ps);

#define PATH_PREFETCH_R(addr) __builtin_prefetch(addr)
#define PATH_PREFETCH_W(addr) __builtin_prefetch(addr, 1)
#define PATH_PREFETCH_N(addr)

/* Fetches the members shading reads or writes for slot p (a hint; no effect on results). */
static inline void path_state_prefetch_shade(const PathState *ps, uint32_t p) {
#define PATH_STATE_PREFETCH(type, name, prefetch) PATH_PREFETCH_##prefetch(&ps->name[p]);
    PATH_STATE_FIELDS(PATH_STATE_PREFETCH)
#undef PATH_STATE_PREFETCH
}

#endif
