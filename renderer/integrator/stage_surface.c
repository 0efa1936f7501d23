/* renderer/integrator/stage_surface.c: sorted deferred shading of the hit queue.
 *
 * Per hit, in three steps (each a function below): the emission the path found (MIS against
 * the light sampler with the previous vertex's context), next-event estimation (the light
 * sampler picks a light, the light is sampled, the scattering function evaluated; a shadow
 * ray with its pending contribution goes to the shadow queue), and the continuation (the
 * scattering function samples a direction, Russian roulette, the next wave's ray). The hit
 * queue is in (primitive, Morton) order, so consecutive hits share materials, textures and
 * the light sampler's per-vertex lookups, and the path state is visited in random slot order: it is prefetched ahead. */
#include "vertex.h"
#include "guide.h"
#include "record.h"
#include "volume_auto.h"

/* how many hits ahead the path state is prefetched; the hit's index triple at half that,
 * its vertices at a quarter (bench.gltf, 2 threads: 16 against 8, alternating runs, ratio
 * 0.590 / 0.603 / 0.605 against 0.591 / 0.597 / 0.592) */
#define SHADE_PREFETCH 16

/* Emission of the emitter the path hit, MIS-weighted against NEE's probability of sampling the
 * same point from the previous vertex. */
static void surface_emission(const Integrator *ig, uint32_t p, const SurfaceHit *h, vec3 wo) {
    const PathState *ps = &ig->ps;
    int32_t light = lights_of_primitive(ig->lights, h->instance, h->local_prim);
    if (light < 0) return;
    /* light linking: an emitter that does not illuminate the previous vertex's object adds
     * nothing there, whichever technique found it (its NEE pmf there is 0) */
    uint32_t link_class = ps->prev_link_class[p];
    if (link_class && !light_reaches(ig->lights, link_class, (uint32_t)light)) return;
    vec3 le = scene_emitted_radiance(ig->scene, h, wo);
    if (v3_is_black(le)) return;
    float w = 1.0f;
    LightSampleContext lc;
    if (vertex_previous_context(ps, p, &lc))
        w = vertex_emitter_weight(ig, &lc, p, (uint32_t)light,
                                  light_area_pdf_li(&ig->lights->lights[light], &lc, h->triangle, h->p, h->ng));
    path_add_radiance(ig, p, v3_scale(v3_mul(ps->throughput[p], le), w), RADIANCE_EMISSION, ps->depth[p]);
}

/* The mesh medium on the side of the surface a ray in direction d leaves into: the surface's
 * own medium when it is a transmissive medium boundary and d points inside, outside of it when
 * d points out, else the medium the path is in. */
static uint32_t side_medium(const Integrator *ig, uint32_t p, const SurfaceHit *h, vec3 d) {
    uint32_t m = ig->media->num_homogeneous ? media_of_primitive(ig->media, h->instance, h->local_prim) : 0;
    if (!m) return ig->ps.medium[p];
    return v3_dot(d, h->ng) < 0.0f ? m : 0;
}

/* A hit on an invisible medium boundary: the path crosses it, into the mesh's medium or out
 * of it, and goes on in the same direction at the same depth (no vertex). Returns 0 when the
 * path has crossed too many boundaries (degenerate geometry) and ends. */
#define MAX_CROSSINGS 256
static int cross_boundary(const Integrator *ig, Slice *s, uint32_t p, const SceneHit *hit) {
    const PathState *ps = &ig->ps;
    if (++ps->crossings[p] > MAX_CROSSINGS) return 0;
    SurfaceHit h;
    scene_surface_hit(ig->scene, hit->instance, hit->local_prim, hit->triangle, hit->u, hit->v, &h);
    vec3 d = ps->ray[p].dir;
    int entering = v3_dot(d, h.ng) < 0.0f;
    ps->medium[p] = entering ? media_of_primitive(ig->media, hit->instance, hit->local_prim) : 0;
    ps->ray[p] = (SceneRay){offset_ray_origin(h.p, entering ? v3_neg(h.ng) : h.ng), 0.0f, d, INFINITY};
    s->keys[s->num_rays] = sort_key_ray(ig, &ps->ray[p]);
    s->rays[s->num_rays++] = p;
    return 1;
}

/* Next-event estimation from the vertex: the MIS-weighted contribution pending on a shadow ray
 * (queued when non-zero). The selection's outcome goes back to the sampler: from the shadow
 * stage when a ray is queued, from here (nothing got through) when not. */
static void surface_direct_light(const Integrator *ig, Slice *s, uint32_t p, const SurfaceHit *h,
                                 const Scatter *sc, const LightSampleContext *lc) {
    const PathState *ps = &ig->ps;
    uint32_t depth = ps->depth[p];
    LightLiSample ls;
    vec3 contrib;
    uint32_t outcome;
    int sampled = vertex_direct_light(ig, p, sc, lc, &ls, &contrib, &outcome);
    emission_probe_nee(ig, p, ls.light, 0.0f, ls.cost + (sampled ? 1.0f : 0.0f)); /* the shadow ray's part comes later */
    if (sampled) {
        vec3 o = offset_ray_origin(h->p, scatter_side_normal(sc, ls.wi));
        vec3 dir = ls.wi;
        float tfar = INFINITY;
        if (!isinf(ls.distance)) {
            /* aim from the offset origin at the sampled point itself: keeping the unoffset
             * direction and length made the ray end behind nearby emitters and darkened small
             * scenes */
            vec3 to = v3_sub(v3_madd(h->p, ls.wi, ls.distance), o);
            float len = v3_length(to);
            if (len > 0.0f) { dir = v3_scale(to, 1.0f / len); tfar = len * (1.0f - 1e-3f); }
            else tfar = 0.0f;
        }
        ps->shadow_ray[p] = (SceneRay){o, 0.0f, dir, tfar};
        ps->shadow_contrib[p] = contrib;
        ps->shadow_outcome[p] = outcome;
        ps->shadow_depth[p] = depth;
        ps->shadow_medium[p] = side_medium(ig, p, h, ls.wi);
        ps->shadow_light[p] = ls.light; /* also its shadow-linking ray mask (stage_shadow.c) */
        record_nee_vertex(ig, s, p, &h->p, &ls.wi, &contrib, 1.0f, &ls.radiance, ls.pdf, PV_FLAG_NEE, ps->hit[p].t);
        s->shadows[s->num_shadows++] = p;
        return;
    }
    light_sampler_record(ig->light_sampler, outcome, 0.0f); /* no shadow ray: nothing reached the light */
}

/* The continuation (vertex_continue) with the direction the scattering function sampled (ss;
 * NULL: none), then the next wave's ray, on the side of the surface it leaves into. Returns 1 when
 * the path goes on. */
static int surface_continuation(const Integrator *ig, Slice *s, uint32_t p, const SurfaceHit *h,
                                 const Scatter *sc, const LightSampleContext *lc, DimsGroup *g, const ScatterSample *ss) {
    const PathState *ps = &ig->ps;
    if (!ss) return 0;
    uint32_t flags = record_surface_flags(ig, ss->delta, &sc->ng);
    if (!vertex_continue(ig, s, p, h->p, ss, sc->guide, g, lc, fabsf(v3_dot(ss->wi, sc->frame.n)), flags, ps->hit[p].t)) return 0;
    if (ss->transmitted) ps->medium[p] = side_medium(ig, p, h, ss->wi);
    ps->ray[p] = (SceneRay){offset_ray_origin(h->p, scatter_side_normal(sc, ss->wi)), 0.0f, ss->wi, INFINITY};
    s->keys[s->num_rays] = sort_key_ray(ig, &ps->ray[p]);
    s->rays[s->num_rays++] = p;
    return 1;
}

/* A hit between its two halves (stage_surface): what shade_front computed for shade_back. The
 * Scatter points into the material sample and the group into the dims, so a slot is filled in
 * place and never copied. */
typedef struct ShadeSlot {
    uint32_t p;
    int boundary;              /* an invisible medium boundary: shade_back crosses it */
    vec3 wo;
    SurfaceHit h;
    MaterialSample m;
    Scatter sc;
    PathDims dims;
    DimsGroup g;               /* the continuation's numbers: the direction's u, v, the lobe, the roulette */
    float u[6];
} ShadeSlot;

/* The first half of a hit: the surface point, its material and scattering function, the guide's
 * distribution and the continuation's numbers. It changes nothing another path reads (only the
 * path's own regularised roughness), so it may run a hit ahead of the second half: it ends with a
 * prefetch of the guide table entry the second half will read (a cache miss per guided vertex at
 * high resolution), which the other hit's work then hides. */
static void shade_front(const Integrator *ig, uint32_t p, ShadeSlot *x) {
    const PathState *ps = &ig->ps;
    const Scene *scene = ig->scene;
    const SceneHit *hit = &ps->hit[p];
    x->p = p;
    x->boundary = scene_hit_primitive(scene, hit)->medium_boundary;
    if (x->boundary) return;
    x->wo = v3_neg(ps->ray[p].dir);
    scene_surface_hit(scene, hit->instance, hit->local_prim, hit->triangle, hit->u, hit->v, &x->h);
    const BsdfPrepared *prepared = scene_material_prepared(scene, &x->h, &x->m);
    float gamma = ig->opt->path_regularization;
    if (gamma > 0.0f) {
        prepared = NULL; /* the roughness changes below */
        /* path-space regularisation (ch. 1 §7, Eq. 25, OPSR with k = 1): a vertex after a rough
         * one is roughened, alpha' = 1 - (1 - alpha)(1 - gamma alpha'_prev), so guiding can
         * learn caustics (a biased, consistent-in-gamma trade: off unless asked) */
        float r = fminf(fmaxf(x->m.bsdf.roughness, 0.0f), 1.0f);
        x->m.bsdf.roughness = 1.0f - (1.0f - r) * (1.0f - gamma * ps->reg_roughness[p]);
        ps->reg_roughness[p] = x->m.bsdf.roughness;
    }
    scatter_init_surface_prepared(&x->sc, &x->h, &x->m.bsdf, prepared, x->wo);
    if (ig->guide.active && scatter_guidable(&x->sc))
        scatter_set_guide(&x->sc, guide_lookup(ig, x->h.p, x->sc.ng), (ScatterGuideMode)ig->guide.mode,
                          record_training(ig));
    x->dims = path_dims(ig, p);
    x->g = dims_group(&x->dims, ps->depth[p], DIMS_SCATTER);
    scatter_numbers(&x->sc, &x->g, x->u);
    scatter_prefetch_guided(&x->sc, x->u);
}

/* The second half: every effect of the hit, in the order of one pass (emission, AOVs, the depth
 * limit, light selection, NEE, the continuation). */
static void shade_back(const Integrator *ig, Slice *s, ShadeSlot *x, uint32_t *hint, float *scratch) {
    const PathState *ps = &ig->ps;
    uint32_t p = x->p;
    const SceneHit *hit = &ps->hit[p];
    vertex_shape_emission(ig, s, p, hit->t, 0);
    if (x->boundary) {
        if (!cross_boundary(ig, s, p, hit)) path_end(ig, s, p);
        return;
    }
    const SurfaceHit *h = &x->h;
    Scatter *sc = &x->sc;
    uint32_t depth = ps->depth[p];
    if (depth == 0) path_write_aovs(ps, p, x->m.bsdf.base_color, sc->frame.n, hit->t);

    surface_emission(ig, p, h, x->wo);
    if ((int)(depth - ps->volume_bounces[p]) >= ig->opt->max_depth) { /* surface vertices */
        path_end(ig, s, p);
        return;
    }
    uint32_t incoming = ps->pv[p]; /* the recorder vertex of the ray that found this hit */

    /* light-selection context: transmissive surfaces receive light from both sides, so they
     * use the omnidirectional (fluence) estimates, as a point in a medium does */
    LightSampleContext lc = light_sample_context(h->p, scatter_light_normal(sc), scratch, &s->volume,
                                                 lights_instance_class(ig->lights, hit->instance));
    int delta = scatter_is_delta(sc);
    if (!delta && light_sampler_uses_lobe(ig->light_sampler)) scatter_light_lobe(sc, &lc.lobe); /* a strategy that weighs lights by the BSDF */
    /* the continuation's direction before the light selection and NEE (it changes no state):
     * a guided vertex's table accesses, cache misses at high resolution, then overlap that
     * independent work */
    ScatterSample ss;
    int sampled = scatter_sample_guided(sc, x->u, &ss);
    if (!delta) light_sampler_prepare(ig->light_sampler, &lc, hint); /* once per vertex */
    if (depth == 0 && ig->film.sel_aov) /* the light sampler's AOV: what the first hit's selection uses */
        light_sampler_aov(ig->light_sampler, &lc, &ps->aov_sel_point[p], &ps->aov_sel_light[p]);
    if (!delta && ig->lights->count > 0) surface_direct_light(ig, s, p, h, sc, &lc);
    int continued = surface_continuation(ig, s, p, h, sc, &lc, &x->g, sampled ? &ss : NULL);
    record_scatter_done(ig, s, p, incoming, continued); /* the scattering event is done with the incoming vertex */
}

void stage_surface(const Integrator *ig, Slice *s) {
    const PathState *ps = &ig->ps;
    const Scene *scene = ig->scene;
    uint32_t hint = UINT32_MAX; /* hits are sorted spatially: the last vertex's answer is near */
    float scratch[LIGHT_SAMPLER_SCRATCH];
    ShadeSlot slots[2]; /* hit i's second half runs after hit i + 1's first */
    s->num_shadows = 0;
    s->num_rays = 0; /* the ray queue was consumed by stage_intersect: it now collects the next wave */
    for (uint32_t i = 0; i <= s->num_hits; ++i) {
        if (i < s->num_hits) {
            if (i + SHADE_PREFETCH < s->num_hits) path_state_prefetch_shade(ps, s->hits[i + SHADE_PREFETCH]);
            /* the hit's mesh data in two steps behind the path state: its indices, then its vertices */
            if (i + SHADE_PREFETCH / 2 < s->num_hits) scene_prefetch_hit_indices(scene, &ps->hit[s->hits[i + SHADE_PREFETCH / 2]]);
            if (i + SHADE_PREFETCH / 4 < s->num_hits) scene_prefetch_hit_vertices(scene, &ps->hit[s->hits[i + SHADE_PREFETCH / 4]]);
            /* the recorder vertex the hit's ray carries (its pv was fetched a few hits earlier) */
            record_prefetch_ray(ig, s->hits, s->num_hits, i + SHADE_PREFETCH / 2);
            record_prefetch_ray_parent(ig, s->hits, s->num_hits, i + SHADE_PREFETCH / 4);
            shade_front(ig, s->hits[i], &slots[i & 1]);
        }
        if (i > 0) shade_back(ig, s, &slots[(i - 1) & 1], &hint, scratch);
    }
}
