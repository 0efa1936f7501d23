/* renderer/media.c: the scene's media from its VDB volumes (media.h). */
#include "media.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

int media_build(SceneMedia *media, const Scene *scene, const char *scene_path, char err[CANDELA_ERR_LEN]) {
    memset(media, 0, sizeof *media);
    const IoScene *io = &scene->io;
    for (uint32_t i = 0; i < io->num_materials; ++i)
        if (io->materials[i].has_medium)
            fprintf(stderr, "%s: warning: material '%s': media inside meshes are not rendered yet; the mesh renders "
                            "as a surface\n", scene_path, io->materials[i].name);
    if (io->num_volumes == 0) return 0;
    media->vdb = calloc(io->num_volumes, sizeof *media->vdb);
    if (!media->vdb) { snprintf(err, CANDELA_ERR_LEN, "candela: out of memory building the media"); return -1; }
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
        char verr[IO_ERR_LEN];
        if (medium_init_vdb(&media->vdb[i], &desc, verr) != 0) {
            snprintf(err, CANDELA_ERR_LEN, "%.200s: volume '%.60s': %.200s", scene_path, v->name, verr);
            media_free(media);
            return -1;
        }
        media->num_vdb = i + 1;
    }
    return 0;
}

void media_free(SceneMedia *media) {
    for (uint32_t i = 0; i < media->num_vdb; ++i) medium_free(&media->vdb[i]);
    free(media->vdb);
    memset(media, 0, sizeof *media);
}

void media_view(const SceneMedia *media, vec3 o, vec3 d, float tmax, MediaView *view) {
    view->count = 0;
    const float of[3] = {o.x, o.y, o.z}, df[3] = {d.x, d.y, d.z};
    for (uint32_t i = 0; i < media->num_vdb && view->count < VOLUME_MAX_OVERLAP; ++i) {
        float t0, t1;
        if (medium_clip_ray(&media->vdb[i], of, df, 0.0f, tmax, &t0, &t1)) view->media[view->count++] = &media->vdb[i];
    }
}
