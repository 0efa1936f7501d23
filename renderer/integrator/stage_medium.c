/* renderer/integrator/stage_medium.c: the volume walk.
 *
 * A path whose ray segment [0, hit.t] crosses media walks it depth-first, as production
 * renderers do (hundreds of bounces in a cloud are cheap there; Hyperion bypasses its
 * wavefront the same way): a free flight by spectral tracking through
 * the segment's media (volumes.h) gathers emission through the radiance funnel and ends in
 * one of three ways. It passes (the path goes on to its surface hit, or escapes), it is
 * absorbed (the path ends), or it scatters: the vertex of this depth is in the medium, with
 * next-event estimation through the light-selection protocol (fluence context: zero normal)
 * and a shadow ray traced at once (occlusion, then the media's transmittance, which is also
 * the visibility the light sampler records), then the phase function samples the next
 * direction, the roulette applies, and the new ray's closest hit is traced at once; the walk
 * repeats until the path leaves the media. Every free flight draws from the path's medium
 * sub-stream of its depth, every NEE shadow ray from the shadow sub-stream, and everything a
 * vertex decides (light, phase direction, roulette) from the bounce dimensions of its depth,
 * exactly as a surface vertex does: the walk is deterministic whatever thread runs it. */
#include <string.h>

#include "rng.h"
#include "vertex.h"
#include "guide.h"
#include "inscatter.h"
#include "record.h"
#include "volume_auto.h"

typedef enum { WALK_SURFACE, WALK_ESCAPED, WALK_ENDED } WalkEnd;

#define CAMERA_EMISSION_LINES 8

/* NEE from a medium vertex: as at a surface (vertex_direct_light), with the phase function and
 * the shadow ray traced now (the walk is depth-first). */
static float medium_direct_light(const Integrator *ig, Slice *s, uint32_t p, vec3 x, const Scatter *sc,
                                 const LightSampleContext *lc, float weight, float segment) {
    const PathState *ps = &ig->ps;
    LightLiSample ls;
    vec3 contrib;
    uint32_t outcome;
    float visibility = 0.0f, unweighted = 0.0f;
    int sampled = vertex_direct_light(ig, p, sc, lc, &ls, &contrib, &outcome);
    if (sampled) {
        float tfar = isinf(ls.distance) ? INFINITY : ls.distance * (1.0f - 1e-3f);
        s->shadow_rays++;
        /* the NEE vertex, released below once its ray is traced */
        record_nee_vertex(ig, s, p, &x, &ls.wi, &contrib, weight, &ls.radiance, ls.pdf, PV_FLAG_NEE | PV_FLAG_VOLUME, segment);
        if (scene_visible1_masked(ig->scene, (SceneRay){x, 0.0f, ls.wi, tfar}, lights_shadow_mask(ig->lights, ls.light))) {
            vec3 T = vertex_shadow_transmittance(ig, s, ps->rng_key[p], ps->depth[p], ps->medium[p], x, ls.wi, tfar);
            visibility = clampf(v3_average(T), 0.0f, 1.0f);
            vec3 c = v3_mul(contrib, T);
            path_add_radiance(ig, p, v3_scale(c, weight), RADIANCE_DIRECT, ps->depth[p]);
            unweighted = v3_luminance(c);
        }
        record_nee_done(ig, s, p);
    }
    emission_probe_nee(ig, p, ls.light, unweighted * weight, ls.cost + (sampled ? 1.0f : 0.0f));
    light_sampler_record(ig->light_sampler, outcome, visibility);
    return unweighted;
}

/* The emission arriving along the segment from each emissive medium of the view, MIS-weighted
 * against NEE's probability of the same direction from the previous vertex when that medium
 * is a light (emission sampling: the line integral NEE estimates is this one). The segment's
 * emission is the line integral over [0, tmax] whatever the path does after it, so it is
 * estimated by emission-optimised tracking along the whole segment (the paper's §4.3,
 * Algorithm 1; the spec's §7.5: "a BSDF-sampled ray through the volume uses the same Alg. 1
 * for radiance") with its own sub-stream, not by the collisions of the free flight (which
 * stop at the first real event and were many times noisier on a fire seen directly). */
static void add_volume_emission(const Integrator *ig, Slice *s, uint32_t p, const MediaView *view, SceneRay ray,
                                float tmax, vec3 beta) {
    const PathState *ps = &ig->ps;
    const Lights *lights = ig->lights;
    const SceneMedia *media = ig->media;
    RngStream stream = rng_stream(ps->rng_key[p], ps->depth[p], RNG_STREAM_EMISSION_LINE + (ps->crossings[p] << 8));
    VolumeRng rng = {rng_stream_next_cb, &stream};
    const float o[3] = {ray.org.x, ray.org.y, ray.org.z}, d[3] = {ray.dir.x, ray.dir.y, ray.dir.z};
    /* a line the pixel sees directly (from the camera, or through delta lobes only) is the
     * pixel's value: the mean of CAMERA_EMISSION_LINES independent ones; a line found from a
     * scattering vertex, one. torch_mist, 160x90, where the fire's pixels hold 86% of the
     * image's variance: 4 lines cut the image variance 1.3x for 4% more collisions (one walk
     * with a 4x majorant only 1.15x: its transmittance through the mist is still one estimate),
     * 16 lines 1.46x for 5% more instructions than 4 */
    int lines = ps->prev_delta[p] ? CAMERA_EMISSION_LINES : 1;
    for (int k = 0; k < view->count; ++k) {
        const Medium *m = view->media[k];
        if (!m->emissive) continue;
        float L[3] = {0.0f, 0.0f, 0.0f};
        for (int i = 0; i < lines; ++i) {
            float Li[3];
            media_emission_line(view, k, o, d, 0.0f, tmax, &rng, Li, &s->volume);
            for (int c = 0; c < 3; ++c) L[c] += Li[c] * (1.0f / (float)lines);
        }
        vec3 e = v3(L[0], L[1], L[2]);
        if (v3_is_black(e)) continue;
        float w = 1.0f;
        uint32_t id = media_id(media, m);
        LightSampleContext lc; /* (volume lights are never linked) */
        if (lights->of_medium && m >= media->vdb && m < media->vdb + media->num_vdb && ig->emission_auto.on[id] &&
            vertex_previous_context(ps, p, &lc)) {
            int32_t light = lights->of_medium[m - media->vdb];
            if (light >= 0)
                w = vertex_emitter_weight(ig, &lc, p, (uint32_t)light,
                                          light_volume_pdf_li(lights, &lights->lights[light], lc.p, ray.dir));
        }
        vec3 c = v3_scale(v3_mul(beta, e), w);
        if (!v3_is_black(c) && v3_is_finite(c)) {
            path_add_radiance(ig, p, c, RADIANCE_EMISSION, ps->depth[p]);
            emission_probe_add(ig, p, id, v3_luminance(c), v3_luminance(v3_mul(beta, e)), w != 1.0f ? 1.0f : 0.0f);
        }
    }
}

static WalkEnd medium_walk(const Integrator *ig, Slice *s, uint32_t p, uint32_t *hint, float *scratch) {
    const PathState *ps = &ig->ps;
    LightVertex walk_previous = {0, 0.0f}; /* the light sampler's token of this walk's last vertex */
    for (;;) {
        SceneRay ray = ps->ray[p];
        float tmax = ps->hit[p].t;
        MediaView view;
        media_view(ig->media, ps->medium[p], ray.org, ray.dir, tmax, &view);
        if (view.count == 0) return isinf(tmax) ? WALK_ESCAPED : WALK_SURFACE;
        uint32_t depth = ps->depth[p];
        /* the camera ray's segments (the same depth until the first scatter, one per medium
         * boundary crossed) also get cache-point in-scattering sampling when it is on */
        VolumeDistanceTable table;
        int inscatter = ig->inscatter && depth == 0 && ps->volume_bounces[p] == 0 && ig->opt->max_volume_bounces > 0 &&
                        inscatter_segment_on(ig, &view) && inscatter_table(ig, ray, tmax, &view, hint, &table);
        if (inscatter) {
            float cost, added = inscatter_estimate(ig, s, p, ray, &view, &table, hint, scratch, &cost);
            if (ig->inscatter_auto.active) {
                if (!ps->probe_medium[p]) ps->probe_medium[p] = media_id(ig->media, view.media[0]) + 1;
                ps->probe_mis[p] += added;
                ps->probe_cost[p] += cost;
            }
        }
        /* decomposition tracking where it applies, except on a segment whose first scatter is
         * MIS-weighted against in-scattering sampling (Eq. 10 weighs the null vertices of one
         * undivided majorant in both techniques) */
        view.decomposition = !inscatter;
        /* a sub-stream per segment: a boundary crossing keeps the depth, so it is keyed too */
        RngStream stream = rng_stream(ps->rng_key[p], depth, RNG_STREAM_MEDIUM + (ps->crossings[p] << 8));
        VolumeRng rng = {rng_stream_next_cb, &stream};
        vec3 beta = ps->throughput[p];
        const float o[3] = {ray.org.x, ray.org.y, ray.org.z}, d[3] = {ray.dir.x, ray.dir.y, ray.dir.z};
        const float b[3] = {beta.x, beta.y, beta.z};
        VolumeEvent ev;
        add_volume_emission(ig, s, p, &view, ray, tmax, beta);
        /* the light shapes along the segment, each times the transmittance up to it, whatever
         * the free flight does next (as the emission above); the surface or escape stage then
         * starts past the segment (README "Light shapes") */
        vertex_shape_emission(ig, s, p, tmax, 1);
        media_sample_event(&view, o, d, 0.0f, tmax, b, &rng, &ev, &s->volume);
        if (ev.type == VOLUME_EVENT_ABSORBED) return WALK_ENDED;
        beta = v3_mul(beta, v3(ev.weight[0], ev.weight[1], ev.weight[2]));
        ps->throughput[p] = beta;
        if (!v3_is_finite(beta) || v3_is_black(beta)) return WALK_ENDED;
        if (ev.type == VOLUME_EVENT_PASSED) {
            if (ig->lights->num_shapes) ps->ray[p].tnear = tmax; /* its light shapes are counted */
            return isinf(tmax) ? WALK_ESCAPED : WALK_SURFACE;
        }

        /* a real scattering event: this depth's vertex is in the medium */
        if ((int)ps->volume_bounces[p] >= ig->opt->max_volume_bounces) return WALK_ENDED;
        ps->volume_bounces[p]++;
        ps->reg_roughness[p] = 1.0f; /* a phase function counts as fully rough (regularisation) */
        vec3 x = v3_madd(ray.org, ray.dir, ev.t);
        Scatter sc;
        scatter_init_phase(&sc, view.media[ev.medium]->g, v3_neg(ray.dir));
        /* guided phase sampling for the first few scattering events of a path only: each guided
         * weight f / (alpha p + (1 - alpha) g) lies in (0, 2], and hundreds of them in a dense
         * medium multiplied into a heavy-tailed throughput (a furnace of optical thickness 300
         * came out 9% dark at 64 spp, 21 paths overflowing to inf); deep in such media the
         * incident light is diffuse, and guiding has nothing to find there */
        if (ig->guide.active && ps->volume_bounces[p] <= GUIDE_MAX_VOLUME_VERTICES && scatter_guidable(&sc))
            scatter_set_guide(&sc, guide_lookup(ig, x, v3s(0.0f)), (ScatterGuideMode)ig->guide.mode, record_training(ig));
        LightSampleContext lc = {x, v3s(0.0f), {0, 0.0f}, scratch, &s->volume, walk_previous};
        lc.link_class = lights_media_class(ig->lights); /* a medium vertex belongs to no object */
        light_sampler_prepare(ig->light_sampler, &lc, hint);
        walk_previous = lc.vertex;
        /* the null-collision technique's NEE, weighed against in-scattering sampling (Eq. 10) */
        float w = inscatter ? inscatter_null_weight(&table, ev.t, ev.null_mis, ev.sigma_s_mean) : 1.0f;
        if (ig->lights->count > 0) {
            float c = medium_direct_light(ig, s, p, x, &sc, &lc, w, ev.t);
            if (inscatter) inscatter_probe_null(ig, p, c, w);
        }
        PathDims dims = path_dims(ig, p);
        ScatterSample ss;
        DimsGroup g = dims_group(&dims, depth, DIMS_SCATTER); /* the direction's u, v, the lobe, the roulette */
        float u[6];
        scatter_numbers(&sc, &g, u);
        if (!scatter_sample_guided(&sc, u, &ss)) return WALK_ENDED;
        uint32_t incoming = ps->pv[p];
        if (!vertex_continue(ig, s, p, x, &ss, sc.guide, &g, &lc, 1.0f, PV_FLAG_VOLUME, ev.t)) return WALK_ENDED;
        record_scatter_done(ig, s, p, incoming, 1); /* the scattering event is done with the incoming vertex */
        /* the next segment: its closest hit now (depth-first), then walk it */
        SceneRay next = {x, 0.0f, ss.wi, INFINITY};
        ps->ray[p] = next;
        SceneHit hit;
        if (!scene_intersect1(ig->scene, next, &hit)) hit.t = INFINITY;
        ps->hit[p] = hit;
        s->bounce_rays++;
    }
}

void stage_medium(const Integrator *ig, Slice *s) {
    if (!media_any(ig->media)) return;
    /* the walk may move a path between the hit and escaped queues: rebuild both, in a fixed
     * order (the hits, then the escaped), into scratch that is free at this point of the wave */
    uint32_t *hits = s->items_tmp, *escaped = s->shadows;
    uint32_t num_hits = 0, num_escaped = 0;
    uint32_t hint = UINT32_MAX;
    float scratch[LIGHT_SAMPLER_SCRATCH];
    for (int q = 0; q < 2; ++q) {
        const uint32_t *queue = q == 0 ? s->hits : s->escaped;
        uint32_t n = q == 0 ? s->num_hits : s->num_escaped;
        for (uint32_t i = 0; i < n; ++i) {
            uint32_t p = queue[i];
            switch (medium_walk(ig, s, p, &hint, scratch)) {
            case WALK_SURFACE: hits[num_hits++] = p; break;
            case WALK_ESCAPED: escaped[num_escaped++] = p; break;
            default: path_end(ig, s, p); break;
            }
        }
    }
    memcpy(s->hits, hits, num_hits * sizeof *hits);
    memcpy(s->escaped, escaped, num_escaped * sizeof *escaped);
    /* a walk may have moved the path's ray and hit: the hit queue's keys afresh */
    for (uint32_t i = 0; i < num_hits; ++i) s->keys[i] = sort_key_hit(ig, &ig->ps.ray[hits[i]], &ig->ps.hit[hits[i]]);
    s->num_hits = num_hits;
    s->num_escaped = num_escaped;
}
