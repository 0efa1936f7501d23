/* renderer/media.h (private): the scene's participating media, built beside the scene from
 * the loaded glTF (the volumes/ module holds the media and their estimators).
 *
 * VDB volumes (node extras candela_volume) are bounded media anywhere in the scene: a ray
 * segment is in every VDB medium whose bounds it crosses. The media view of a segment lists
 * them (the first VOLUME_MAX_OVERLAP in scene order: more overlapping volumes than that are
 * not supported); the volume walk (stage_medium.c) and the shadow rays'
 * transmittance use it. */
#ifndef CANDELA_MEDIA_H
#define CANDELA_MEDIA_H

#include <stdint.h>

#include "candela.h"
#include "scene.h"
#include "volumes.h"

typedef struct SceneMedia {
    Medium *vdb;              /* one per IoScene volume */
    uint32_t num_vdb;
} SceneMedia;

/* 0 ok; -1 with a one-line message naming the scene file. */
int media_build(SceneMedia *media, const Scene *scene, const char *scene_path, char err[CANDELA_ERR_LEN]);
void media_free(SceneMedia *media);
static inline int media_any(const SceneMedia *media) { return media->num_vdb > 0; }

/* The media of the segment o + t d, t in [0, tmax] (VDB media whose bounds it crosses). */
void media_view(const SceneMedia *media, vec3 o, vec3 d, float tmax, MediaView *view);

#endif
