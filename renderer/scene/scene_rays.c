/* renderer/scene/scene_rays.c: the scene ray interface (scene.h) over Embree 3. Every ray the
 * renderer traces comes through here, so a change of ray tracing back-end, ray flags or
 * statistics is one file. */
#include "scene.h"

/* Geometry masks (scene.c): ordinary surfaces 1, invisible medium boundaries 2. Closest-hit
 * rays see both (a path crosses boundaries), occlusion rays only surfaces. Shadow linking:
 * surfaces also carry bits 2..31 and an instance lacks the bit of each blockers list naming
 * it, so a shadow ray with mask 1 << bit passes through exactly those instances. */
enum { MASK_SURFACES = 1u, MASK_BOUNDARIES = 2u, MASK_ALL = 0xffffffffu };

static inline void fill_ray(struct RTCRay *r, const SceneRay *s, unsigned id, unsigned mask) {
    r->org_x = s->org.x; r->org_y = s->org.y; r->org_z = s->org.z;
    r->tnear = s->tnear;
    r->dir_x = s->dir.x; r->dir_y = s->dir.y; r->dir_z = s->dir.z;
    r->time = 0.0f;
    r->tfar = s->tfar;
    r->mask = mask;
    r->id = id;
    r->flags = 0;
}

static inline void read_hit(const struct RTCRayHit *h, SceneHit *out) {
    if (h->hit.geomID == RTC_INVALID_GEOMETRY_ID) {
        out->t = INFINITY;
        return;
    }
    out->t = h->ray.tfar;
    out->u = h->hit.u;
    out->v = h->hit.v;
    out->instance = h->hit.instID[0];
    out->local_prim = h->hit.geomID;
    out->triangle = h->hit.primID;
}

void scene_intersect(const Scene *scene, const SceneRay *rays, const uint32_t *items, uint32_t n, SceneHit *hits,
                     int coherent) {
    struct RTCRayHit rh[SCENE_RAY_PACKET];
    struct RTCIntersectContext ictx;
    rtcInitIntersectContext(&ictx);
    ictx.flags = coherent ? RTC_INTERSECT_CONTEXT_FLAG_COHERENT : RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
    for (uint32_t s = 0; s < n; s += SCENE_RAY_PACKET) {
        unsigned m = n - s < SCENE_RAY_PACKET ? n - s : SCENE_RAY_PACKET;
        for (unsigned k = 0; k < m; ++k) {
            fill_ray(&rh[k].ray, &rays[items ? items[s + k] : s + k], k, MASK_ALL);
            rh[k].hit.geomID = RTC_INVALID_GEOMETRY_ID;
            rh[k].hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
        }
        rtcIntersect1M(scene->top, &ictx, rh, m, sizeof(struct RTCRayHit));
        for (unsigned k = 0; k < m; ++k) read_hit(&rh[k], &hits[s + k]);
    }
}

void scene_occluded(const Scene *scene, const SceneRay *rays, const uint32_t *items, uint32_t n, uint8_t *occluded) {
    scene_occluded_masked(scene, rays, items, n, NULL, occluded);
}

void scene_occluded_masked(const Scene *scene, const SceneRay *rays, const uint32_t *items, uint32_t n,
                           const uint32_t *masks, uint8_t *occluded) {
    struct RTCRay r[SCENE_RAY_PACKET];
    struct RTCIntersectContext ictx;
    rtcInitIntersectContext(&ictx);
    for (uint32_t s = 0; s < n; s += SCENE_RAY_PACKET) {
        unsigned m = n - s < SCENE_RAY_PACKET ? n - s : SCENE_RAY_PACKET;
        for (unsigned k = 0; k < m; ++k)
            fill_ray(&r[k], &rays[items ? items[s + k] : s + k], k, masks ? masks[s + k] : MASK_SURFACES);
        /* one call a ray: incoherent shadow rays gain nothing from the stream interface, whose
         * bookkeeping cost about 3 % of the shadow stage (bench.gltf, 1 thread, min of 5) */
        for (unsigned k = 0; k < m; ++k) rtcOccluded1(scene->top, &ictx, &r[k]);
        for (unsigned k = 0; k < m; ++k) occluded[s + k] = !(r[k].tfar >= 0.0f); /* tfar = -inf when occluded */
    }
}

static int intersect1(const Scene *scene, SceneRay ray, SceneHit *hit, unsigned mask) {
    struct RTCRayHit rh;
    struct RTCIntersectContext ictx;
    rtcInitIntersectContext(&ictx);
    fill_ray(&rh.ray, &ray, 0, mask);
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(scene->top, &ictx, &rh);
    read_hit(&rh, hit);
    return hit->t < INFINITY;
}

int scene_intersect1(const Scene *scene, SceneRay ray, SceneHit *hit) { return intersect1(scene, ray, hit, MASK_ALL); }

int scene_intersect_boundary1(const Scene *scene, SceneRay ray, SceneHit *hit) {
    return intersect1(scene, ray, hit, MASK_BOUNDARIES);
}

int scene_visible1(const Scene *scene, SceneRay ray) { return scene_visible1_masked(scene, ray, MASK_SURFACES); }

int scene_visible1_masked(const Scene *scene, SceneRay ray, uint32_t mask) {
    struct RTCRay r;
    struct RTCIntersectContext ictx;
    rtcInitIntersectContext(&ictx);
    fill_ray(&r, &ray, 0, mask);
    rtcOccluded1(scene->top, &ictx, &r);
    return r.tfar >= 0.0f;
}
