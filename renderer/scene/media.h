/* renderer/scene/media.h (private): the scene's participating media, built beside the scene from
 * the loaded glTF (the volumes/ module holds the media and their estimators).
 *
 * Two kinds. VDB volumes (node extras candela_volume) are bounded media anywhere in the
 * scene: a ray segment is in every VDB medium whose bounds it crosses. Homogeneous media
 * fill closed meshes whose material has candela_medium (or KHR_materials_volume); a path
 * carries the one it is in (PathState.medium: 0 none, else index + 1), crossing into it and
 * out of it at the mesh's surface (an invisible boundary, or a dielectric one when the
 * material transmits). Media inside meshes do not nest: leaving one puts the path outside
 * every mesh medium. The media view of a segment lists the path's mesh medium and the VDB
 * media it crosses (the first VOLUME_MAX_OVERLAP in scene order: more than that overlapping
 * at once are not supported). */
#ifndef CANDELA_MEDIA_H
#define CANDELA_MEDIA_H

#include <stdint.h>

#include "candela.h"
#include "scene.h"
#include "volumes.h"

typedef struct SceneMedia {
    Medium *vdb;              /* one per IoScene volume */
    uint32_t num_vdb;
    Medium *homogeneous;      /* one per material with a medium */
    uint32_t num_homogeneous;
    int32_t *of_material;     /* per material: its homogeneous medium, or -1 */
    const Scene *scene;
    uint64_t bytes;           /* the volume grids and the media's majorant and emission grids */
} SceneMedia;

/* 0 ok; -1 with a one-line message naming the scene file. */
/* volume_budget: bytes for the volume grids (already loaded) and every medium's majorant and
 * emission grids together (--volume-budget-mb; 0: no limit). media->bytes: what they take. */
int media_build(SceneMedia *media, const Scene *scene, const char *scene_path, uint64_t volume_budget,
                char err[CANDELA_ERR_LEN]);
void media_free(SceneMedia *media);
static inline int media_any(const SceneMedia *media) { return media->num_vdb + media->num_homogeneous > 0; }

/* A medium's index among all of the scene's: VDB volumes first, then the mesh media. */
static inline uint32_t media_count(const SceneMedia *media) { return media->num_vdb + media->num_homogeneous; }
static inline uint32_t media_id(const SceneMedia *media, const Medium *m) {
    return m >= media->vdb && m < media->vdb + media->num_vdb ? (uint32_t)(m - media->vdb)
                                                              : media->num_vdb + (uint32_t)(m - media->homogeneous);
}

/* The mesh medium (index + 1, 0: none) inside the surface of a hit primitive. */
uint32_t media_of_primitive(const SceneMedia *media, uint32_t instance, uint32_t local_prim);
/* The mesh medium a point lies in, found by one ray against the invisible medium boundaries
 * (the camera's medium at the start; a camera inside glass is not detected). */
uint32_t media_at_point(const SceneMedia *media, vec3 p);

/* The media of the segment o + t d, t in [0, tmax]: the path's mesh medium (0: none) and the
 * VDB media whose bounds it crosses. */
void media_view(const SceneMedia *media, uint32_t mesh_medium, vec3 o, vec3 d, float tmax, MediaView *view);

/* Transmittance (RGB) of a shadow segment starting in mesh medium `mesh_medium`: exact
 * through the mesh media it crosses (boundaries found by rays against them), ratio tracking
 * through the VDB media (rng: the path's shadow sub-stream). */
vec3 media_transmittance_segment(const SceneMedia *media, uint32_t mesh_medium, vec3 o, vec3 d, float tmax,
                                 VolumeRng *rng, VolumeStats *stats);

#endif
