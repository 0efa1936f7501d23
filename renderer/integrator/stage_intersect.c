/* renderer/integrator/stage_intersect.c: closest hits of the ray queue (sorted by sort_rays), split into
 * the hit queue and the escaped queue in ray-queue order; the hit queue's sort keys with it
 * (the ray keys, read by the sort, are dead by now). */
#include "integrator.h"

void stage_intersect(const Integrator *ig, Slice *s) {
    const PathState *ps = &ig->ps;
    SceneHit hits[SCENE_RAY_PACKET];
    s->num_hits = s->num_escaped = 0;
    for (uint32_t b = 0; b < s->num_rays; b += SCENE_RAY_PACKET) {
        uint32_t m = s->num_rays - b < SCENE_RAY_PACKET ? s->num_rays - b : SCENE_RAY_PACKET;
        scene_intersect(ig->scene, ps->ray, s->rays + b, m, hits, s->wave == 0);
        for (uint32_t k = 0; k < m; ++k) {
            uint32_t p = s->rays[b + k];
            ps->hit[p] = hits[k];
            if (isinf(hits[k].t)) s->escaped[s->num_escaped++] = p;
            else {
                s->keys[s->num_hits] = sort_key_hit(ig, &ps->ray[p], &hits[k]);
                s->hits[s->num_hits++] = p;
            }
        }
    }
}
