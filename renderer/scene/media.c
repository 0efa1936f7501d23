/* renderer/scene/media.c: the scene's media (media.h). */
#include "media.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define MAX_BOUNDARY_CROSSINGS 64 /* per shadow segment: a bound, never reached by sane scenes */

int media_build(SceneMedia *media, const Scene *scene, const char *scene_path, uint64_t volume_budget,
                char err[CANDELA_ERR_LEN]) {
    memset(media, 0, sizeof *media);
    media->scene = scene;
    const IoScene *io = &scene->io;
    char verr[IO_ERR_LEN];
    media->of_material = malloc(((size_t)io->num_materials + 1) * sizeof *media->of_material);
    media->homogeneous = calloc((size_t)io->num_materials + 1, sizeof *media->homogeneous);
    media->vdb = calloc((size_t)io->num_volumes + 1, sizeof *media->vdb);
    if (!media->of_material || !media->homogeneous || !media->vdb) goto oom;
    for (uint32_t i = 0; i < io->num_materials; ++i) {
        const IoMaterial *m = &io->materials[i];
        media->of_material[i] = -1;
        if (!m->has_medium) continue;
        if (medium_init_homogeneous(&media->homogeneous[media->num_homogeneous], m->medium_sigma_a, m->medium_sigma_s,
                                    m->medium_anisotropy, verr) != 0) {
            snprintf(err, CANDELA_ERR_LEN, "%.200s: material '%.60s': %.200s", scene_path, m->name, verr);
            media_free(media);
            return -1;
        }
        media->of_material[i] = (int32_t)media->num_homogeneous++;
    }
    /* the scene's volume budget: the grids first (loaded), then each medium's own structures
     * within what is left, checked before they are allocated */
    uint64_t used = 0;
    for (uint32_t i = 0; i < io->num_volumes; ++i)
        used += io->volumes[i].density.size + io->volumes[i].emission.size + io->volumes[i].temperature.size;
    for (uint32_t i = 0; i < io->num_volumes; ++i) {
        const IoVolume *v = &io->volumes[i];
        VolumeDesc desc = {&v->density, v->emission.buffer ? &v->emission : NULL,
                           v->temperature.buffer ? &v->temperature : NULL};
        memcpy(desc.node_to_world, v->xform, sizeof desc.node_to_world);
        desc.density_scale = v->density_scale;
        memcpy(desc.albedo, v->albedo, sizeof desc.albedo);
        desc.anisotropy = v->anisotropy;
        desc.emission_scale = v->emission_scale;
        memcpy(desc.emission_color, v->emission_color, sizeof desc.emission_color);
        desc.memory_budget = !volume_budget ? 0 : used < volume_budget ? volume_budget - used : 1;
        if (medium_init_vdb(&media->vdb[i], &desc, verr) != 0) {
            snprintf(err, CANDELA_ERR_LEN, "%.200s: volume '%.60s': %.200s%s", scene_path, v->name, verr,
                     strstr(verr, "volume memory") ? " (--volume-budget-mb)" : "");
            media_free(media);
            return -1;
        }
        used += media->vdb[i].memory_bytes;
        media->num_vdb = i + 1;
    }
    media->bytes = used;
    return 0;
oom:
    snprintf(err, CANDELA_ERR_LEN, "%s: out of memory building the media", scene_path);
    media_free(media);
    return -1;
}

void media_free(SceneMedia *media) {
    for (uint32_t i = 0; i < media->num_vdb; ++i) medium_free(&media->vdb[i]);
    for (uint32_t i = 0; i < media->num_homogeneous; ++i) medium_free(&media->homogeneous[i]);
    free(media->vdb);
    free(media->homogeneous);
    free(media->of_material);
    memset(media, 0, sizeof *media);
}

uint32_t media_of_primitive(const SceneMedia *media, uint32_t instance, uint32_t local_prim) {
    const Scene *scene = media->scene;
    uint32_t global = scene->io.meshes[scene->instances[instance].mesh].first_primitive + local_prim;
    int32_t mi = scene->io.primitives[global].material;
    if (mi < 0 || (uint32_t)mi >= scene->io.num_materials) return 0;
    return media->of_material[mi] >= 0 ? (uint32_t)media->of_material[mi] + 1u : 0u;
}

/* The outward (winding) normal of a hit primitive. */
static vec3 hit_normal(const Scene *scene, const SceneHit *h) {
    SurfaceHit sh;
    scene_surface_hit(scene, h->instance, h->local_prim, h->triangle, h->u, h->v, &sh);
    return sh.ng;
}

uint32_t media_at_point(const SceneMedia *media, vec3 p) {
    if (media->num_homogeneous == 0) return 0;
    /* an arbitrary, non-axis-aligned direction: the first boundary it meets says inside or out */
    vec3 d = v3_normalize(v3(0.1234f, 0.9871f, 0.0987f));
    SceneHit h;
    if (!scene_intersect_boundary1(media->scene, (SceneRay){p, 0.0f, d, INFINITY}, &h)) return 0;
    uint32_t m = media_of_primitive(media, h.instance, h.local_prim);
    return m && v3_dot(d, hit_normal(media->scene, &h)) > 0.0f ? m : 0; /* leaving it: inside */
}

void media_view(const SceneMedia *media, uint32_t mesh_medium, vec3 o, vec3 d, float tmax, MediaView *view) {
    view->count = 0;
    view->decomposition = 1;
    if (mesh_medium) view->media[view->count++] = &media->homogeneous[mesh_medium - 1];
    const float of[3] = {o.x, o.y, o.z}, df[3] = {d.x, d.y, d.z};
    for (uint32_t i = 0; i < media->num_vdb && view->count < VOLUME_MAX_OVERLAP; ++i) {
        float t0, t1;
        if (medium_clip_ray(&media->vdb[i], of, df, 0.0f, tmax, &t0, &t1)) view->media[view->count++] = &media->vdb[i];
    }
}

vec3 media_transmittance_segment(const SceneMedia *media, uint32_t mesh_medium, vec3 o, vec3 d, float tmax,
                                 VolumeRng *rng, VolumeStats *stats) {
    vec3 T = v3s(1.0f);
    /* mesh media: exact, piece by piece between the boundaries the segment crosses */
    if (media->num_homogeneous > 0) {
        uint32_t m = mesh_medium;
        float t = 0.0f;
        for (int crossing = 0; crossing <= MAX_BOUNDARY_CROSSINGS; ++crossing) {
            SceneHit h;
            int hit = crossing < MAX_BOUNDARY_CROSSINGS &&
                      scene_intersect_boundary1(media->scene, (SceneRay){o, t, d, tmax}, &h);
            float t1 = hit ? h.t : tmax;
            if (m && isfinite(t1)) {
                const Medium *hm = &media->homogeneous[m - 1];
                float len = t1 - t;
                T = v3_mul(T, v3(expf(-(hm->sigma_a[0] + hm->sigma_s[0]) * len), expf(-(hm->sigma_a[1] + hm->sigma_s[1]) * len),
                                 expf(-(hm->sigma_a[2] + hm->sigma_s[2]) * len)));
            } else if (m) {
                return v3s(0.0f); /* an unbounded path through a medium: nothing gets through */
            }
            if (!hit) break;
            uint32_t mh = media_of_primitive(media, h.instance, h.local_prim);
            m = v3_dot(d, hit_normal(media->scene, &h)) < 0.0f ? mh : 0; /* entering or leaving */
            t = t1 + 1e-5f * (1.0f + t1);
        }
    }
    /* VDB media: ratio tracking */
    MediaView view;
    media_view(media, 0, o, d, tmax, &view);
    if (view.count > 0) {
        const float of[3] = {o.x, o.y, o.z}, df[3] = {d.x, d.y, d.z};
        float tv[3];
        media_transmittance(&view, of, df, 0.0f, tmax, rng, tv, stats);
        T = v3_mul(T, v3(tv[0], tv[1], tv[2]));
    }
    return T;
}
