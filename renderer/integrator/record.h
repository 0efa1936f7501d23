/* renderer/integrator/record.h (private): the radiance recorder's side of the wavefront (record.c): its
 * calls and the hooks the stages call (its state, RecordState, is declared with the integrator's). */
#ifndef CANDELA_RECORD_H
#define CANDELA_RECORD_H

#include "guide.h"
#include "integrator.h"

/* record.c: the radiance recorder's side of the wavefront (see there; its lifecycle is its
 * entry in the feature table, feature.h). */
/* A camera ray: its vertex is the camera; path skipping is decided here. */
void record_camera(const Integrator *ig, uint32_t p, uint64_t path);
/* A child vertex of `parent` for a ray leaving pos in dir with throughput tp, or the parent
 * continued (too close: `segment` is the distance from the parent's origin; past the budget).
 * cosine: |cos| of dir to the surface's shading normal (1 in media, and for NEE rays, which
 * guiding does not learn from). guide: the guide's answer at pos (NULL: none), whose leaf the
 * vertex's sample carries to training (guide_field_leaf_of). */
uint32_t record_child(const Integrator *ig, Slice *s, uint32_t p, uint32_t parent, vec3 pos, vec3 dir, vec3 tp,
                      float pdf, float scatter_pdf, float guide_pdf, float cosine, uint32_t flags, float segment,
                      const GuideDistribution *guide);
/* The holder of vertex pv in path p lets go (records and backpropagates at zero). */
void record_done(const Integrator *ig, Slice *s, uint32_t p, uint32_t pv);
void record_radiance(const Integrator *ig, uint32_t p, vec3 c, RadianceSource source);
/* The batch's samples are no longer needed (recording stopped): the slices' buffers emptied. */
void record_drop_batch(Integrator *ig);

/* The recorder's hooks as the stages call them, unconditionally: each tests whether the recorder
 * is on (record.active, set by guiding at the barrier) itself, so no stage does (as Cycles'
 * guiding_record_* hooks do). Inline, so a stage compiles to the branch it had when it tested the
 * flag at the call site; vectors are passed by pointer because a vec3 passed by value is copied
 * before the test (measured with callgrind: +1.3% in stage_surface with the recorder off). */
/* Whether the recorder is on (training): a guided vertex then reads the guide's pdf even where its
 * leaf's BSDF share is 1, for the share's statistics (scatter_set_guide). */
static inline int record_training(const Integrator *ig) { return ig->record.active; }
/* Radiance added to path p (path_add_radiance). */
static inline void record_vertex_radiance(const Integrator *ig, uint32_t p, const vec3 *c, RadianceSource source) {
    if (ig->record.active) record_radiance(ig, p, *c, source);
}
/* The path's ray continues from a scattering vertex: its vertex becomes the child of the one it
 * carried (vertex_continue). */
static inline void record_vertex_child(const Integrator *ig, Slice *s, uint32_t p, const vec3 *pos, const vec3 *dir,
                                       const vec3 *tp, float pdf, float scatter_pdf, float guide_pdf, float cosine,
                                       uint32_t flags, float segment, const GuideDistribution *guide) {
    if (ig->record.active)
        ig->ps.pv[p] = record_child(ig, s, p, ig->ps.pv[p], *pos, *dir, *tp, pdf, scatter_pdf, guide_pdf, cosine, flags,
                                    segment, guide);
}
/* The throughput of an NEE ray, for its recorder vertex: the contribution per unit of the
 * light's radiance (so its sample is the radiance that arrived). */
static inline vec3 nee_throughput(vec3 contrib, vec3 radiance) {
    return v3(radiance.x > 0.0f ? contrib.x / radiance.x : 0.0f, radiance.y > 0.0f ? contrib.y / radiance.y : 0.0f,
              radiance.z > 0.0f ? contrib.z / radiance.z : 0.0f);
}

/* An NEE ray leaves pos toward a light sampled with pdf: its vertex (shadow_pv), a child of the
 * path's, with nee_throughput of its contribution times weight (the medium's MIS weight; 1 at a
 * surface) and the light's radiance. */
static inline void record_nee_vertex(const Integrator *ig, Slice *s, uint32_t p, const vec3 *pos, const vec3 *dir,
                                     const vec3 *contrib, float weight, const vec3 *radiance, float pdf, uint32_t flags,
                                     float segment) {
    if (ig->record.active)
        ig->ps.shadow_pv[p] = record_child(ig, s, p, ig->ps.pv[p], *pos, *dir, nee_throughput(v3_scale(*contrib, weight), *radiance),
                                           pdf, pdf, 0.0f, 1.0f, flags, segment, NULL);
}
/* The NEE ray of path p is done (its contribution added): its vertex is released. */
static inline void record_nee_done(const Integrator *ig, Slice *s, uint32_t p) {
    if (ig->record.active) {
        record_done(ig, s, p, ig->ps.shadow_pv[p]);
        ig->ps.shadow_pv[p] = PV_CAMERA;
    }
}
/* A scattering event is done with the vertex of the ray that arrived (`incoming`); continued: 0
 * when the path ends there (its ray then carries no vertex). */
static inline void record_scatter_done(const Integrator *ig, Slice *s, uint32_t p, uint32_t incoming, int continued) {
    if (ig->record.active) {
        if (!continued) ig->ps.pv[p] = PV_CAMERA;
        record_done(ig, s, p, incoming);
    }
}
/* The path ends (path_end): its ray's vertex is released. */
static inline void record_path_end(const Integrator *ig, Slice *s, uint32_t p) {
    if (ig->record.active) {
        record_done(ig, s, p, ig->ps.pv[p]);
        ig->ps.pv[p] = PV_CAMERA;
    }
}
/* The recorder vertex of the ray of path items[j] of a list of n (when j < n), prefetched a few
 * paths before its use: the hits before their shading, escaped rays before their path ends. */
static inline void record_prefetch_ray(const Integrator *ig, const uint32_t *items, uint32_t n, uint32_t j) {
    if (ig->record.active && j < n) recorder_prefetch(ig->record.recorder, ig->ps.pv[items[j]]);
}
/* Its parent, read from the vertex once that has arrived (a path that ends there releases its
 * chain, the parent first, and it was last touched a wave ago). */
static inline void record_prefetch_ray_parent(const Integrator *ig, const uint32_t *items, uint32_t n, uint32_t j) {
    if (ig->record.active && j < n) recorder_prefetch_parent(ig->record.recorder, ig->ps.pv[items[j]]);
}
/* The NEE vertices of the shadow rays items[0..m) (folded: their parents'), and then their
 * parents (read from the vertices: prefetched after them), while the rays are traced. */
static inline void record_prefetch_shadows(const Integrator *ig, const uint32_t *items, uint32_t m) {
    if (ig->record.active)
        for (uint32_t k = 0; k < m; ++k) recorder_prefetch(ig->record.recorder, ig->ps.shadow_pv[items[k]]);
}
static inline void record_prefetch_shadow_parents(const Integrator *ig, const uint32_t *items, uint32_t m) {
    if (ig->record.active && ig->record.debug_aov) /* folded: shadow_pv is the parent already */
        for (uint32_t k = 0; k < m; ++k) recorder_prefetch_parent(ig->record.recorder, ig->ps.shadow_pv[items[k]]);
}

/* The recorder's flags of a surface vertex a path continues from (a recorder hook, above: 0,
 * nothing computed, while the recorder is off): delta, and the orientation class guiding
 * learns it in. */
static inline uint32_t record_surface_flags(const Integrator *ig, int delta, const vec3 *ng) {
    return ig->record.active ? (delta ? PV_FLAG_DELTA : 0u) | guide_surface_flags(*ng) : 0u;
}

#endif
