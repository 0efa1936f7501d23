/* renderer/scene.h (private): the render-time scene.
 *
 * Owns the IoScene from io/, the Embree device and scenes (one Embree scene per glTF mesh,
 * instanced once per node that references it), the camera, the environment and the lights.
 * Everything here is read-only once scene_build() returns, so every stage may read it from
 * any thread. */
#ifndef CANDELA_SCENE_H
#define CANDELA_SCENE_H

#include <embree3/rtcore.h>

#include "bsdf.h"
#include "candela.h"
#include "io.h"
#include "lights.h"
#include "vecmath.h"

typedef struct Camera {
    int type;              /* IO_CAMERA_* */
    float xform[16];       /* camera-to-world */
    float tan_half_fov_y;  /* perspective */
    float xmag, ymag;      /* orthographic half extents (ymag; xmag follows the image aspect) */
    int width, height;
} Camera;

/* One glTF primitive as the renderer needs it. Embree's geometry user pointer points here
 * (the alpha-mask filter reads it). */
typedef struct ScenePrimitive {
    const IoPrimitive *io;
    const IoMaterial *material;  /* never NULL (the default material stands in) */
    const struct Scene *scene;
    int alpha_masked;
} ScenePrimitive;

typedef struct SceneInstance {
    float xform[16];          /* object to world */
    float normal_xform[9];    /* inverse transpose of the 3x3 part, row-major */
    uint32_t mesh;
    uint32_t light_table_base; /* light_of_primitive[base + local primitive] */
} SceneInstance;

typedef struct Scene {
    IoScene io;
    IoMaterial default_material;
    RTCDevice device;
    RTCScene top;
    RTCScene *mesh_scenes;     /* io.num_meshes */
    ScenePrimitive *prims;     /* io.num_primitives */
    SceneInstance *instances;  /* io.num_instances */
    int32_t *light_of_primitive; /* per (instance, local primitive): area light index or -1 */
    uint32_t num_triangles_total;
    vec3 bounds_min, bounds_max;
    vec3 center;
    float radius;              /* bounding sphere of the geometry (>= a small minimum) */
    Camera camera;
    IoImage env;               /* linear RGBA lat-long; width 0 when there is none */
    float env_strength;
    Lights lights;
} Scene;

/* Loads the glTF, applies options (camera choice, resolution, environment, light units),
 * builds the Embree scene and the light list. */
int scene_load(Scene *scene, const CandelaOptions *o, char err[CANDELA_ERR_LEN]);
void scene_free(Scene *scene);

/* Everything shading needs about a hit point, in world space. */
typedef struct SurfaceHit {
    vec3 p;
    vec3 ng;          /* geometric normal from the winding (unit) */
    vec3 ns;          /* interpolated (and normal-mapped) shading normal, same side as ng */
    vec3 dpdu;        /* tangent for normal mapping (unit, orthogonal to ns) */
    vec2 uv;
    const IoMaterial *material;
    uint32_t instance, local_prim, global_prim, triangle;
} SurfaceHit;

void scene_surface_hit(const Scene *scene, uint32_t instance, uint32_t local_prim,
                       uint32_t triangle, float b1, float b2, SurfaceHit *hit);

/* The material at a hit: BSDF parameters, emitted radiance (factor x strength x texture, 0
 * when not emissive) and opacity. */
typedef struct MaterialSample {
    BsdfParams bsdf;
    vec3 emission;
    int double_sided;
} MaterialSample;

void scene_material_at(const Scene *scene, const SurfaceHit *hit, MaterialSample *m);

/* Emitted radiance of the area light at hit towards direction w (pointing away from the
 * surface): zero on the back of single-sided emitters. */
vec3 scene_emitted_radiance(const Scene *scene, const SurfaceHit *hit, vec3 w);

/* Environment radiance for a world direction d (zero without an environment). */
vec3 scene_env_radiance(const Scene *scene, vec3 d);
/* Lat-long mapping (Blender's equirectangular convention in glTF's Y-up axes). */
vec2 scene_env_dir_to_uv(vec3 d);
vec3 scene_env_uv_to_dir(vec2 uv);

/* Camera ray through film position (fx, fy) in pixels (0..width, 0..height, y down). */
void camera_generate_ray(const Camera *c, float fx, float fy, vec3 *org, vec3 *dir);

/* Bilinear lookup with glTF wrap modes and KHR_texture_transform applied. */
void texture_lookup(const IoImage *image, const IoTextureRef *ref, vec2 uv, float out[4]);

/* Offset a ray origin off the surface along n, scaled to the position's magnitude. */
static inline vec3 offset_ray_origin(vec3 p, vec3 n) {
    float scale = 1e-4f * (1.0f + fmaxf(fabsf(p.x), fmaxf(fabsf(p.y), fabsf(p.z))));
    return v3_madd(p, n, scale);
}

#endif
