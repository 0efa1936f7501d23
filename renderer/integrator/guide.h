/* renderer/integrator/guide.h (private): path guiding's side of the wavefront (guide.c): the lookups a
 * vertex makes (its state, GuideState, is declared with the integrator's). */
#ifndef CANDELA_GUIDE_H
#define CANDELA_GUIDE_H

#include <math.h>

#include "integrator.h"

/* guide.c: path guiding (see there; its lifecycle, training, auto's probe, guide-dump and
 * checkpoints are its entry in the feature table, feature.h). */
#define GUIDE_MAX_VOLUME_VERTICES 8 /* medium vertices of a path that are guided (stage_medium.c) */
/* The learned distribution at p: a surface's with normal n (its orientation class), or the
 * medium field's (n zero); NULL while guiding is not active. */
const GuideDistribution *guide_lookup(const Integrator *ig, vec3 p, vec3 n);
/* The field guide_lookup reads for normal n: surfaces by the orientation class of n (2 x the axis
 * of its largest component + (that component < 0)), media (n zero) the last. */
static inline int guide_field_of_normal(vec3 n) {
    if (n.x == 0.0f && n.y == 0.0f && n.z == 0.0f) return GUIDE_SURFACE_CLASSES;
    float ax = fabsf(n.x), ay = fabsf(n.y), az = fabsf(n.z);
    if (ax >= ay && ax >= az) return n.x < 0.0f;
    if (ay >= az) return 2 + (n.y < 0.0f);
    return 4 + (n.z < 0.0f);
}
/* The recorder flags that carry a surface vertex's orientation class. */
uint32_t guide_surface_flags(vec3 n);
/* The leaf index in the field of a vertex's flags (guide_surface_flags, PV_FLAG_VOLUME) of d, the
 * guide_lookup answer at its point (GUIDE_NO_LEAF: d NULL): its training sample's hint. */
uint32_t guide_leaf_hint(const Integrator *ig, uint32_t flags, const GuideDistribution *d);

#endif
