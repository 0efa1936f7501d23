/* renderer/scene/scene.h (private): the render-time scene.
 *
 * Owns the IoScene from io/, the Embree device and scenes (one Embree scene per glTF mesh,
 * instanced once per node that references it), the camera and the environment image. The
 * lights are built beside it from the loaded scene (lights.h), so the scene knows nothing of
 * lights or of how they are selected. Everything here is read-only once scene_load()
 * returns (and between scene_pose calls, which frame batches make between renders), so every
 * stage may read it from any thread.
 *
 * Every ray the renderer traces goes through the scene ray interface below (closest hit and
 * occlusion, one ray or a batch): the wavefront stages, the cache point pilot paths, the
 * optimal sampler's occlusion rays and the benchmark's bare-Embree replay. */
#ifndef CANDELA_SCENE_H
#define CANDELA_SCENE_H

#include <embree3/rtcore.h>

#include "bsdf.h"
#include "candela.h"
#include "io.h"
#include "vecmath.h"

#define SCENE_MAX_INSTANCE_PRIMITIVES 2147483647u /* the light table's int32 indices */

typedef struct Camera {
    int type;              /* IO_CAMERA_* */
    float xform[16];       /* camera-to-world */
    float tan_half_fov_y;  /* perspective */
    float xmag, ymag;      /* orthographic half extents (ymag; xmag follows the image aspect) */
    int width, height;     /* the full image */
    /* --crop: the pixels rendered, [crop_x, crop_x + crop_width) x [crop_y, crop_y + crop_height) of
     * the full image (the whole image without a crop); rays are always the full image's */
    int crop_x, crop_y, crop_width, crop_height;
} Camera;

/* One glTF primitive as the renderer needs it. Embree's geometry user pointer points here
 * (the alpha-mask filter reads it). */
/* The material at a hit: BSDF parameters (emission is scene_emitted_radiance's). */
typedef struct MaterialSample {
    BsdfParams bsdf;
    int double_sided;
} MaterialSample;

/* A material no texture varies: scene_material_at's answer at every hit on it, and its BSDF
 * prepared (bsdf_prepare), both made once at load. */
typedef struct MaterialFixed {
    MaterialSample sample;
    BsdfPrepared prepared;
} MaterialFixed;

typedef struct ScenePrimitive {
    const IoPrimitive *io;
    const IoMaterial *material;  /* never NULL (the default material stands in) */
    const MaterialFixed *material_fixed; /* NULL when a texture varies the material */
    const struct Scene *scene;
    int alpha_masked;
    /* the surface of a medium inside a closed mesh whose material does not transmit: invisible
     * (rays cross it into or out of the medium; shadow rays ignore it) */
    int medium_boundary;
} ScenePrimitive;

typedef struct SceneInstance {
    float xform[16];          /* object to world */
    float normal_xform[9];    /* inverse transpose of the 3x3 part, row-major */
    int linear_identity;      /* the 3x3 part is the identity (a translation at most): hit
                               * attributes skip the matrix products */
    uint32_t mesh;
    uint32_t primitive_base;  /* index of (this instance, local primitive 0) among all instance
                               * primitives: per-instance-primitive tables (the area light of
                               * a hit) are indexed by primitive_base + local primitive */
    int hidden;               /* a zero scale now (IoInstance.hidden): disabled in Embree, no
                               * area lights, no cache point candidates */
} SceneInstance;

typedef struct Scene {
    IoScene io;
    IoMaterial default_material;
    RTCDevice device;
    RTCScene top;
    RTCScene *mesh_scenes;     /* io.num_meshes */
    ScenePrimitive *prims;     /* io.num_primitives */
    SceneInstance *instances;  /* io.num_instances */
    uint32_t num_instance_primitives; /* sum over instances of their mesh's primitives
                                       * (at most SCENE_MAX_INSTANCE_PRIMITIVES) */
    uint32_t num_triangles_total;
    vec3 bounds_min, bounds_max;
    vec3 center;
    float radius;              /* bounding sphere of the geometry (>= a small minimum) */
    Camera camera;
    IoImage env;               /* linear float RGBA lat-long (rgba, never rgba8); width 0 when there is none */
    float env_strength;
    float env_rotation_turns;  /* the environment's rotation about +Y in turns, in [0, 1) (scene_env_dir_to_uv) */
    CandelaLightModel light_model; /* how lights_build shapes punctual lights (--light-model) */
    CandelaMaterialModel material_model; /* which BSDF scene_material_at sets up (--material-model) */
    /* shadow linking (io.light_links' blockers): per IoLightLink, the Embree ray mask of the
     * shadow rays of its lights (SCENE_MASK_SURFACES when it has no blockers); NULL when no
     * link has blockers. Each distinct blockers list is one mask bit (2..31) that the
     * instances it lists lack, so their shadow rays pass through them (scene_rays.c). */
    uint32_t *link_shadow_mask;
    MaterialFixed *material_fixed; /* io.num_materials + 1 (the default material last) */
} Scene;

/* Loads the glTF, applies options (camera choice, resolution, environment) and builds the
 * Embree scene. */
int scene_load(Scene *scene, const CandelaOptions *o, char err[CANDELA_ERR_LEN]);
/* The phase clock of a render (candela.h, CANDELA_PHASE_*): phase_mark ends `phase` now, adding
 * the seconds since the previous mark, with the render's peak memory so far and the resident
 * memory now (render.c). */
typedef struct ScenePhases {
    double t;
    double seconds[CANDELA_PHASES];
    size_t peak[CANDELA_PHASES], rss[CANDELA_PHASES];
} ScenePhases;
void phase_mark(ScenePhases *p, int phase);
/* scene_load, marking the parse, flatten and embree phases on `phases` (NULL: none). */
int scene_load_phased(Scene *scene, const CandelaOptions *o, ScenePhases *phases, char err[CANDELA_ERR_LEN]);
void scene_free(Scene *scene);
/* Re-places the loaded scene at animation time `seconds` (io_scene_pose): the instances that
 * moved get their new transforms (Embree's top-level scene is rebuilt when any did; meshes and
 * textures stay), then bounds and camera follow. Between renders only (no ray in flight).
 * *changed_instances: how many moved. Fails (one line) on a transform the scene cannot take at
 * that time. */
int scene_pose(Scene *scene, const CandelaOptions *o, double seconds, uint32_t *changed_instances,
               char err[CANDELA_ERR_LEN]);

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

void scene_material_at(const Scene *scene, const SurfaceHit *hit, MaterialSample *m);
/* scene_material_at, and the BSDF already prepared when the material is fixed (else NULL). */
const BsdfPrepared *scene_material_prepared(const Scene *scene, const SurfaceHit *hit, MaterialSample *m);

/* Emitted radiance of the area light at hit towards direction w (pointing away from the
 * surface): zero on the back of single-sided emitters. */
vec3 scene_emitted_radiance(const Scene *scene, const SurfaceHit *hit, vec3 w);

/* Environment radiance for a world direction d (zero without an environment). */
vec3 scene_env_radiance(const Scene *scene, vec3 d);
/* Lat-long mapping (Cycles' equirectangular convention in glTF's Y-up axes, turned by the
 * scene's environment rotation): uv in [0, 1)^2, v = 0 the image's top row. */
vec2 scene_env_dir_to_uv(const Scene *scene, vec3 d);
vec3 scene_env_uv_to_dir(const Scene *scene, vec2 uv);

/* Camera ray through film position (fx, fy) in pixels (0..width, 0..height, y down). */
void camera_generate_ray(const Camera *c, float fx, float fy, vec3 *org, vec3 *dir);

/* Bilinear lookup with glTF wrap modes and KHR_texture_transform applied, of either form of
 * image (float or 8-bit: the same texels give the same result to the bit). */
void texture_lookup(const IoImage *image, const IoTextureRef *ref, vec2 uv, float out[4]);

/* ---------------------------------------------------------------- the scene ray interface */

/* A ray segment [tnear, tfar] from org along dir (unit for the renderer's own rays). */
typedef struct SceneRay {
    vec3 org;
    float tnear;
    vec3 dir;
    float tfar;
} SceneRay;

/* The closest hit of a ray: t = INFINITY when it escaped (the rest is then undefined). */
typedef struct SceneHit {
    float t, u, v;       /* distance and barycentrics (b1, b2) of the hit */
    uint32_t instance, local_prim, triangle;
} SceneHit;

/* Closest hits of n rays: ray i is rays[items[i]] (items NULL: rays[i]); its hit goes to
 * hits[i]. Any n (traced in packets of SCENE_RAY_PACKET). coherent: a hint that the rays share
 * an origin and similar directions (camera rays). */
#define SCENE_RAY_PACKET 256
void scene_intersect(const Scene *scene, const SceneRay *rays, const uint32_t *items, uint32_t n, SceneHit *hits,
                     int coherent);
/* Occlusion of n rays (indexed as above): occluded[i] = 1 if anything but an invisible medium
 * boundary lies on ray i within [tnear, tfar]. */
void scene_occluded(const Scene *scene, const SceneRay *rays, const uint32_t *items, uint32_t n, uint8_t *occluded);
/* The ray mask of ordinary occlusion rays; a light with shadow linking has its own
 * (Scene.link_shadow_mask). */
#define SCENE_MASK_SURFACES 1u
/* scene_occluded with a ray mask per ray (masks[i] for ray i): shadow linking. */
void scene_occluded_masked(const Scene *scene, const SceneRay *rays, const uint32_t *items, uint32_t n,
                           const uint32_t *masks, uint8_t *occluded);
/* One ray: 1 if it hit (and *hit holds the hit), 0 if it escaped. */
int scene_intersect1(const Scene *scene, SceneRay ray, SceneHit *hit);
/* One ray against the invisible medium boundaries only (for the media a segment crosses). */
int scene_intersect_boundary1(const Scene *scene, SceneRay ray, SceneHit *hit);
/* One ray: 1 if nothing but invisible medium boundaries lies on it. */
int scene_visible1(const Scene *scene, SceneRay ray);
/* The same with a ray mask (SCENE_MASK_SURFACES: scene_visible1; a shadow-linked light's mask). */
int scene_visible1_masked(const Scene *scene, SceneRay ray, uint32_t mask);

/* The glTF primitive a hit lies on (its material, mesh data, medium boundary flag). */
static inline const ScenePrimitive *scene_hit_primitive(const Scene *scene, const SceneHit *hit) {
    const SceneInstance *inst = &scene->instances[hit->instance];
    return &scene->prims[scene->io.meshes[inst->mesh].first_primitive + hit->local_prim];
}

/* Cache hints for shading a hit a few hits ahead (no effect on results). Embree's traversal
 * reads its own copy of the triangles, so the renderer's mesh buffers are cold when a hit is
 * shaded: the index triple first, then (once it has arrived) the vertices' attributes. */
static inline void scene_prefetch_hit_indices(const Scene *scene, const SceneHit *hit) {
    __builtin_prefetch(scene_hit_primitive(scene, hit)->io->indices + 3 * (size_t)hit->triangle);
}
static inline void scene_prefetch_hit_vertices(const Scene *scene, const SceneHit *hit) {
    const IoPrimitive *p = scene_hit_primitive(scene, hit)->io;
    const uint32_t *idx = p->indices + 3 * (size_t)hit->triangle;
    for (int k = 0; k < 3; ++k) {
        __builtin_prefetch(p->positions + 3 * (size_t)idx[k]);
        if (p->normals) __builtin_prefetch(p->normals + 3 * (size_t)idx[k]);
        if (p->uvs) __builtin_prefetch(p->uvs + 2 * (size_t)idx[k]);
    }
}

/* Offset a ray origin off the surface along n, scaled to the position's magnitude. */
static inline vec3 offset_ray_origin(vec3 p, vec3 n) {
    /* maxf (compares), not fmaxf (a libm call): equal for every finite p */
    float scale = 1e-4f * (1.0f + maxf(fabsf(p.x), maxf(fabsf(p.y), fabsf(p.z))));
    return v3_madd(p, n, scale);
}

#endif
