/* renderer/integrator/inscatter.h (private): in-scattering sampling along camera rays (inscatter.c). */
#ifndef CANDELA_INSCATTER_H
#define CANDELA_INSCATTER_H

#include "integrator.h"

/* inscatter.c: in-scattering sampling along camera rays (the paper's §4.2, spec §7.2-7.3), for
 * light samplers that provide scattering weights (light_sampler_inscatter_weight). A camera
 * segment through media gets a distance table (stations at the sampler's weights along it);
 * 1 when built, 0 when the segment has no finite medium interval. */
int inscatter_table(const Integrator *ig, SceneRay ray, float tmax, const MediaView *view, uint32_t *hint,
                    VolumeDistanceTable *tab);
/* The technique's estimate: a distance from the table, ratio tracking to it, and NEE there
 * (light selection through the protocol, a shadow ray with its transmittance), weighted by the
 * balance heuristic against null-collision tracking (Eq. 10), added through the funnel. */
float inscatter_estimate(const Integrator *ig, Slice *s, uint32_t p, SceneRay ray, const MediaView *view,
                         const VolumeDistanceTable *tab, uint32_t *hint, float *scratch, float *cost);

/* The balance-heuristic weight of the null-collision technique's first scatter at t (its
 * VolumeEvent's null_mis and sigma_s_mean) against the table's distance sampling. */
static inline float inscatter_null_weight(const VolumeDistanceTable *tab, float t, float null_mis,
                                          float sigma_s_mean) {
    float r = null_mis * sigma_s_mean, pd = volume_distance_pdf(tab, t);
    return r + pd > 0.0f ? r / (r + pd) : 1.0f;
}

#endif
