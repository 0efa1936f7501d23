/* renderer/lights/lights.h (private): the light list and light sampling.
 *
 * Lights: punctual (point, spot, directional; delta), area (one light per emissive glTF
 * primitive per instance) and the environment map (importance-sampled lat-long). They are
 * built beside the scene from the loaded Scene (lights_build), which knows nothing of them.
 * How NEE picks one of them is the light-selection protocol's business (light_sampler.h).
 *
 * An area light's triangle is picked by its inner light tree (lighttree.h; importance from
 * the shading point and normal, as for whole lights) when it has more than
 * LIGHT_AREA_TREE_MAX_CDF triangles, else in proportion to area (l->triangles). The tree
 * also falls back to the area CDF for a context from which the tree's root has zero
 * importance (the bounds say the point sees no emitting side, or the whole mesh lies below
 * the receiver's horizon); sampling and
 * light_area_pdf_li make that decision with the same function, so the pdf stays exact. */
#ifndef CANDELA_LIGHTS_H
#define CANDELA_LIGHTS_H

#include <stdint.h>

#include "candela.h"
#include "lighttree.h"
#include "sampling.h"
#include "vecmath.h"

struct Scene;

typedef enum { LIGHT_POINT, LIGHT_SPOT, LIGHT_DIRECTIONAL, LIGHT_AREA, LIGHT_ENVIRONMENT, LIGHT_VOLUME,
               LIGHT_RECT, LIGHT_DISK } LightType;

/* An inner tree shared by the instances of an emissive primitive (lights_build): built once
 * over the primitive's object-space triangles and read, for an instance placed by
 * x -> M x + origin with M a rotation times a scale (orthogonal columns, det M > 0), with the
 * shading point taken into object space by M^-1 and the receiver's normal by M^T
 * (normalised). Both sidedness tests that make an importance zero (in front of an emitter,
 * above the receiver's horizon) are then the world-space ones, so no triangle that can
 * contribute loses its probability: selection stays exact and unbiased. Under a uniform scale
 * distances scale and angles stay, so the branch probabilities are those of a world-space tree
 * over the same splits but with the object-space boxes (turned with the instance; for a mesh
 * modelled along its axes these are the tighter ones: test_arealight (h)); a stretch (the
 * street's buildings scale their facades 0.9-1.6x in height) also tilts the angles, so only
 * stretches up to LIGHT_SHARED_TREE_MAX_STRETCH share. The production street
 * places each window mesh about six times: one tree instead of six keeps the descents' nodes
 * in cache. Other placements (mirrors, shears, larger stretches) refit a tree of their own
 * (Light.tri_tree). */
#define LIGHT_SHARED_TREE_MAX_STRETCH 2.0f
typedef struct LightSharedTree {
    const LightTree *tree; /* the primitive's object-space tree (Lights.object_trees) */
    vec3 origin;           /* the instance's translation */
    vec3 row[3];           /* the rows of M^-1: object point = row . (p - origin) */
    vec3 col[3];           /* the columns of M: object normal ~ (col . n) */
} LightSharedTree;

typedef struct Light {
    LightType type;
    vec3 position;        /* point, spot */
    vec3 direction;       /* spot, directional: the direction light travels */
    vec3 intensity;       /* point/spot: W/sr; directional: irradiance W/m^2 */
    float cos_inner, cos_outer; /* spot */
    float spot_smooth;          /* spot, --light-model blender3: Cycles' smoothstep width in cos (0: none) */
    int spot_cycles;            /* spot: 1 = Cycles 3.4's falloff (light_spot_falloff) */
    /* area */
    uint32_t instance, local_prim, global_prim;
    float area;               /* world-space area of the primitive */
    vec3 emission;            /* emissiveFactor x strength (times the texture, if any) */
    Distribution1D triangles; /* world triangle areas */
    float *world_vertices;    /* 9 floats per triangle, world space */
    int two_sided;            /* the material is double-sided: emits from both faces */
    float power;              /* estimate for the power sampler (luminance, W) */
    LightTree tri_tree;       /* inner tree over the triangles (node_count 0: area CDF only) */
    const LightSharedTree *shared_tree; /* instead of tri_tree: the primitive's object-space
                                         * tree, in this instance's frame (NULL: tri_tree) */
    /* volume (an emissive VDB medium, the cache points paper's §4.3 emission sampling):
     * position = its emission centroid, intensity = its integral of sigma_a L_e (W/sr) */
    uint32_t medium;          /* index into SceneMedia.vdb */
    uint32_t medium_mesh;     /* the mesh medium around it (media.h; 0: none) */
    vec3 bounds_min, bounds_max; /* its world bounds */
    int32_t link;             /* its IoScene.light_links entry (light linking), or -1 */
    /* light shapes (README "Light shapes"; light_is_shape): a point or spot light with radius > 0
     * is a sphere of uniform radiance `emission` (I / (pi r^2); a spot's is scaled by its falloff
     * towards the receiver, evaluated from the centre); a directional light with sun_omc > 0 a
     * sun, a cone of half-angle h around -direction (sun_omc = 1 - cos h) of radiance `emission`
     * (E / (pi sin^2 h): the glTF irradiance E on a perpendicular plane is kept); LIGHT_RECT /
     * LIGHT_DISK a one-sided parallelogram / ellipse centred at position with half-extent vectors
     * axis_u, axis_v, emitting `emission` along `direction` (its plane normal), area `area`. Rect
     * and disk also fill triangles / world_vertices (2 triangles; a 16-triangle inscribed fan for
     * the disk): only the estimates' fixed points use them, sampling and hits are exact. */
    float radius;             /* point, spot: sphere radius (0: a delta point) */
    int sphere_disk;          /* --light-model blender3: the radius is Cycles 3.4's disk of that radius
                               * facing the receiver, not a sphere (same radiance) */
    float sun_omc;            /* directional: 1 - cos(half-angle) (0: a delta direction) */
    vec3 axis_u, axis_v;      /* rect, disk: world half-extent vectors */
    vec3 dual_u, dual_v;      /* rect, disk: (y - position) . dual = the point's local coordinates */
    int rect_ortho;           /* rect: its sides are perpendicular (spherical-rectangle sampling applies) */
} Light;

/* Whether a light has an extent that rays can hit (a sphere, a sun, a rect or a disk): NEE
 * samples it by solid angle or area (not delta) and BSDF rays find it (lights_shape_hit), MIS. */
static inline int light_is_shape(const Light *l) {
    return ((l->type == LIGHT_POINT || l->type == LIGHT_SPOT) && l->radius > 0.0f) ||
           (l->type == LIGHT_DIRECTIONAL && l->sun_omc > 0.0f) || l->type == LIGHT_RECT || l->type == LIGHT_DISK;
}
/* Whether a light's estimates sum fixed points on triangles (world_vertices): emissive meshes,
 * rects and disks. */
static inline int light_is_areal(const Light *l) {
    return l->type == LIGHT_AREA || l->type == LIGHT_RECT || l->type == LIGHT_DISK;
}

/* Area lights with at most this many triangles pick them by area alone (no inner tree). */
#define LIGHT_AREA_TREE_MAX_CDF 8

/* A light-selection strategy's per-vertex state, opaque to everyone else: the strategy fills
 * it in light_sampler_prepare and reads it back in select / pmf. The wavefront keeps it in the
 * path state, so the MIS pdf of a light found by the next wave's BSDF sample is evaluated with
 * the very context NEE used at this vertex. All zero: not prepared (the strategy then works
 * it out again, with the same result). */
typedef struct LightVertex {
    uint32_t word;
    float value;
    /* BSDF-aware selection (cache points with --cachepoint-bsdf): the glossy lobe the vertex's
     * distribution followed, as prepare quantised it (the axis octahedral in 2 x 16 bits), its
     * share of the distribution and the lobe-weighted total; lobe_mix 0: the normal alone */
    uint32_t lobe_axis;
    float lobe_sharpness, lobe_mix, lobe_total;
} LightVertex;

/* A surface vertex's glossy BSDF lobe as light selection sees it (scatter_light_lobe): f cos
 * toward wi is about rho_d / pi (cos wi) + rho_s D(wi), D a normalised lobe density of
 * sharpness `sharpness` around `axis` (wo mirrored about the shading normal); `weight` is
 * kappa = pi rho_s / (rho_d cos wo), the lobe's weight against the normal-only (irradiance)
 * weights (INFINITY for a pure metal). weight 0: no lobe worth following (diffuse or rough
 * surfaces, transmissive ones, media); a strategy may ignore the lobe. */
typedef struct LightLobe {
    vec3 axis;
    float sharpness;
    float weight;
} LightLobe;

/* Where light arrives: a point with a shading normal, or (n = 0) an omnidirectional receiver
 * (a point in a medium, a transmissive surface), for which strategies use fluence. */
typedef struct LightSampleContext {
    vec3 p;
    vec3 n;
    LightVertex vertex;  /* from light_sampler_prepare; zero: not prepared */
    /* LIGHT_SAMPLER_SCRATCH floats the strategy may fill in prepare and reuse in select for
     * this vertex only (e.g. cache points' near-light weights); NULL: none */
    float *scratch;
    /* where a volume light's line integral counts its collisions (NULL: nowhere) */
    struct VolumeStats *stats;
    /* the same path's previous vertex's token when that vertex was in the same medium walk
     * (zero: none): a strategy may reuse its state while the vertex stays close (cache points
     * reuse the previous point inside its radius, §3.3) */
    LightVertex previous;
    /* light linking: the vertex's link class (Lights.link), the set of lights that may
     * illuminate it; 0 = every light (no linking, the camera, objects no link names) */
    uint32_t link_class;
    /* the vertex's glossy lobe (zero: none), set by the caller like link_class; strategies
     * that follow it keep what they need of it in the vertex token */
    LightLobe lobe;
} LightSampleContext;

/* A context with every member set one by one: a per-vertex aggregate initialiser was compiled
 * to a string store over the whole struct (rep stos, dear for its size) */
static inline LightSampleContext light_sample_context(vec3 p, vec3 n, float *scratch, struct VolumeStats *stats,
                                                      uint32_t link_class) {
    LightSampleContext c;
    c.p = p;
    c.n = n;
    c.vertex = (LightVertex){0u, 0.0f};
    c.scratch = scratch;
    c.stats = stats;
    c.previous = (LightVertex){0u, 0.0f};
    c.link_class = link_class;
    c.lobe = (LightLobe){{0.0f, 0.0f, 0.0f}, 0.0f, 0.0f};
    return c;
}

/* Light linking (extras.candela_light_linking, README "Light linking"): receiving objects are
 * grouped into link classes, the distinct sets of lights that reach them (usually few), so
 * that every strategy can build its distributions per class and a vertex carries one small
 * number (LightSampleContext.link_class, kept in the path state for the next wave's MIS pdf).
 * Class 0 is every light. A vertex in a medium belongs to no object: it is reached by every
 * light that has no receivers list or an exclude list (media_class). Shadow linking is the
 * lights' Embree ray masks (scene.h). */
typedef struct LightLinking {
    uint32_t num_classes;
    uint16_t *class_of_instance;  /* per scene instance */
    uint16_t media_class;         /* medium vertices (no object) */
    uint8_t *enabled;             /* num_classes x count: 1 when the light reaches the class */
    uint32_t *enabled_off, *enabled_lights;   /* per class (num_classes + 1 offsets): its lights, ascending */
    uint32_t *disabled_off, *disabled_lights; /* per class: the lights that do not reach it, ascending */
    uint32_t *exclusive_off, *exclusive_lights; /* per class: its lights that have an include list
                                                 * naming it ("exclusive" to it, §3.3), ascending */
    uint32_t *shadow_mask;        /* per light: its shadow rays' ray mask (NULL: no shadow linking) */
} LightLinking;

typedef struct Lights {
    Light *lights;
    uint32_t count;
    int32_t environment;        /* index of the environment light or -1 */
    Distribution2D env_distribution;
    float env_estimate[7];      /* environment irradiance on the 6 axis planes + fluence */
    /* per instance primitive (SceneInstance.primitive_base + local primitive): the area light
     * it is, or -1: how a hit on an emitter finds its light for MIS */
    int32_t *of_primitive;
    int32_t *of_medium;         /* per SceneMedia.vdb: the volume light it is, or -1 */
    const struct Scene *scene;  /* built from (environment image, emissive materials) */
    const struct SceneMedia *media; /* emissive volumes (NULL: none are lights) */
    LightLinking *link;         /* NULL: the scene has no light linking */
    /* the shape lights (light_is_shape), ascending: what a camera or BSDF ray may cross
     * (lights_shape_hit); suns only on rays that escape */
    uint32_t *shapes;
    uint32_t num_shapes;
    uint32_t *suns;             /* the suns among them (found by escaping rays only) */
    uint32_t num_suns;
    void *shape_bvh;            /* lights.c ShapeBvh: an Embree BVH over the finite shapes, or NULL
                                 * (few shapes: the list is tested linearly) */
    /* inner trees shared in object space (LightSharedTree): per scene primitive, the tree its
     * instances read when their placement allows (node_count 0: none); per instance primitive,
     * the frame its area light reads it in */
    LightTree *object_trees;
    LightSharedTree *shared_trees;
} Lights;

/* Whether `light` may illuminate a vertex of link class cls (LightLinking). */
static inline int light_reaches(const Lights *ls, uint32_t cls, uint32_t light) {
    return cls == 0 || ls->link->enabled[(size_t)cls * ls->count + light];
}
/* The link class of a surface vertex on `instance`, and of a vertex in a medium. */
static inline uint32_t lights_instance_class(const Lights *ls, uint32_t instance) {
    return ls->link ? ls->link->class_of_instance[instance] : 0u;
}
static inline uint32_t lights_media_class(const Lights *ls) { return ls->link ? ls->link->media_class : 0u; }
/* The ray mask of a shadow ray towards `light` (1 = SCENE_MASK_SURFACES: no shadow linking). */
static inline uint32_t lights_shadow_mask(const Lights *ls, uint32_t light) {
    return ls->link && ls->link->shadow_mask && light < ls->count ? ls->link->shadow_mask[light] : 1u;
}
/* light_linking.c: builds ls->link from the scene's links (Light.link set); nothing without
 * any. 0 ok, -1 out of memory or too many classes (message in err). */
int lights_build_linking(Lights *ls, const struct Scene *scene, char *err, size_t err_len);
void lights_free_linking(Lights *ls);

/* Builds the lights of a loaded scene: punctual lights, emissive primitives, environment, and
 * with media != NULL every emissive VDB volume (emission sampling, §4.3). The scene and the
 * media must outlive the lights. 0 ok; -1 with a message in err. */
struct SceneMedia;
int lights_build(Lights *lights, const struct Scene *scene, const struct SceneMedia *media, CandelaLightUnits units,
                 char *err, size_t err_len);
void lights_free(Lights *lights);

/* The area light a hit on (instance, local primitive) belongs to, or -1. */
int32_t lights_of_primitive(const Lights *lights, uint32_t instance, uint32_t local_prim);

/* A spot light's intensity factor in direction w (unit, from the light): glTF's recommended
 * smooth falloff between the cones (a squared linear ramp in cos), or with --light-model
 * blender3 Cycles 3.4's: cos x smoothstep((cos - cos_outer) / spot_smooth). */
float light_spot_falloff(const Light *l, vec3 w);

/* light_estimates.c: unoccluded contribution estimates (the cache points paper's Table 1
 * "optimal" selection weights; the estimators are described there). Irradiance at p on the
 * plane with normal n (fluence when n = 0); estimate7 gives the irradiance on the six planes
 * facing +X -X +Y -Y +Z -Z and the fluence at once. Deterministic functions of (light, p, n). */
float light_contribution_estimate(const Lights *ls, const Light *l, vec3 p, vec3 n);
void light_contribution_estimate7(const Lights *ls, const Light *l, vec3 p, float out[7]);
/* The same estimates with their position-independent part computed once (an area light's 16
 * points and normals, the luminances): light_contribution_estimate_table returns bit for bit
 * light_contribution_estimate, at a fraction of the cost for area lights (per-vertex users:
 * the optimal strategy, cache points' near lists). 0 ok, -1 out of memory. */
/* an area light's 16 estimate points and their triangles' normals, SoA (one vector loop) */
typedef struct LightEstimatePoints { float y[3][16], ng[3][16]; } LightEstimatePoints;
typedef struct LightEstimateTable {
    uint32_t *slot;             /* per light: its entry in points (UINT32_MAX: not an area light) */
    float *lum;                 /* per light: luminance of the emission (area) or intensity */
    LightEstimatePoints *points;
    /* the point lights (LIGHT_POINT, no radius), SoA padded to a multiple of 4: their light
     * index and position / luminance, for light_estimate_table_all's vector loop */
    uint32_t num_point_lights;
    uint32_t *point_light;
    uint32_t num_other_lights;  /* every other light, in light order */
    uint32_t *other_light;
    float *point_x, *point_y, *point_z, *point_lum;
    int avx; /* the CPU runs AVX: an area light's 16 points go eight to a register */
} LightEstimateTable;
int light_estimate_table_build(LightEstimateTable *t, const Lights *ls);
void light_estimate_table_free(LightEstimateTable *t);
float light_contribution_estimate_table(const Lights *ls, const LightEstimateTable *t, uint32_t light, vec3 p, vec3 n);
/* Every light's light_contribution_estimate_table (bit for bit) into out[0 .. count), the point
 * lights four at a time. */
void light_estimate_table_all(const Lights *ls, const LightEstimateTable *t, vec3 p, vec3 n, float *out);
/* The environment's estimates (position-independent), computed once by lights_build. */
void light_env_estimates(const struct Scene *scene, float out[7]);
/* Peak radiant intensity of a light (luminance, W/sr): what a light-tree cluster estimate sums. */
float light_peak_intensity(const Light *l);

/* A sampled point on a light as seen from a shading point. */
typedef struct LightLiSample {
    vec3 wi;          /* unit, from the shading point to the light */
    float distance;   /* INFINITY for directional and environment */
    vec3 radiance;    /* arriving radiance (delta lights: intensity / r^2 or irradiance) */
    float pdf;        /* solid-angle pdf given the light (1 for delta lights) */
    int is_delta;
    uint32_t triangle; /* area lights: the sampled triangle (for light_area_pdf_li) */
    uint32_t light;    /* the light's index (set by next-event estimation's selection) */
    float cost;        /* NEE's counted cost beyond a shadow ray: a volume light's line integral and
                        * pdf (the auto choices' cost model; set by vertex_direct_light_u) */
} LightLiSample;

/* Samples a point on `light` as seen from ctx (ctx->n steers an area light's inner tree; use
 * the same context for light_area_pdf_li). A volume light samples a point in proportion to
 * the emission energy and returns the emission integrated along the whole line through the
 * volume up to the first surface (Algorithm 1 line integration), with the solid-angle pdf of
 * Eq. 11; its distance is where the line enters the volume (the shadow ray tests occlusion
 * and other media up to there). */
int light_sample_li(const Lights *ls, const Light *light, const LightSampleContext *ctx, float u0, float u1,
                    float u2, float u3, LightLiSample *s);
/* Solid-angle pdf (given the light) of a volume light's direction d from p (Eq. 11). */
float light_volume_pdf_li(const Lights *ls, const Light *light, vec3 p, vec3 d);
/* Solid-angle pdf (given the light) of sampling the point y with normal ny on triangle
 * `triangle` of an area light from ctx: p_tri(triangle | ctx) / area(triangle) * d^2 / |cos|. */
float light_area_pdf_li(const Light *light, const LightSampleContext *ctx, uint32_t triangle, vec3 y, vec3 ny);
/* Probability that light_sample_li picks `triangle` of an area light from ctx. */
float light_area_triangle_pmf(const Light *light, const LightSampleContext *ctx, uint32_t triangle);
/* The inner tree that picks an area light's triangle for ctx, with ctx's point and normal in
 * that tree's frame in *local (its other members zero), or NULL when the area CDF picks it (no
 * tree, or the tree's root has importance 0 there). Sampling and the pdfs decide through it. */
const LightTree *light_area_tree(const Light *light, const LightSampleContext *ctx, LightSampleContext *local);
/* Whether an instance transform (column-major 4x4, xform_point's) may read a shared tree
 * (LightSharedTree: a rotation times a scale of stretch <= LIGHT_SHARED_TREE_MAX_STRETCH, to
 * within rounding); if so fills *f's frame (f->tree is left NULL). */
int light_shared_tree_frame(const float xform[16], LightSharedTree *f);
/* Builds l->tri_tree from world_vertices, emission and two_sided when the light has more than
 * LIGHT_AREA_TREE_MAX_CDF triangles (else leaves it empty). 0 ok, -1 out of memory. */
int light_area_tree_build(Light *l);
/* Frees an area light's arrays and tree. */
void light_area_free(Light *l);
/* A ray o + t d (d unit) crossing shape light `light` (light_is_shape) at t in (tmin, tmax), tmax
 * INFINITY for a ray that escapes (only then a sun is crossed, at t = INFINITY): 1 with the
 * crossing's t and the radiance arriving along -d at `receiver` (the vertex that will weigh it
 * by MIS: a spot sphere's falloff is evaluated towards it). Lights are transparent to rays
 * (Cycles continues a ray through the lights it hits), so every crossing counts. A sphere is
 * crossed once: where the ray enters it, or leaves it for an origin inside. Rects and disks are
 * one-sided: only a ray against `direction` sees them. */
int light_shape_hit(const Light *l, vec3 o, vec3 d, float tmin, float tmax, vec3 receiver, float *t, vec3 *radiance);
/* Every shape light the ray o + t d crosses in (tmin, tmax) (light_shape_hit; suns only when tmax
 * is INFINITY), passed to fn in ascending light order whatever the traversal (so sums are the
 * same bit for bit with or without the BVH). Above LIGHT_SHAPE_BVH_MIN finite shapes the
 * candidates come from an Embree BVH over their bounds (user geometry whose intersection
 * callback runs light_shape_hit and never reports a hit, so traversal visits every crossing). */
#define LIGHT_SHAPE_BVH_MIN 8
void lights_shape_crossings(const Lights *ls, vec3 o, vec3 d, float tmin, float tmax, vec3 receiver,
                            void (*fn)(void *user, uint32_t light, float t, vec3 radiance), void *user);
/* Solid-angle pdf (given the light) that light_sample_li samples the direction d (unit) from p,
 * for a shape light that d reaches (light_shape_hit true at distance t). */
float light_shape_pdf_li(const Light *l, vec3 p, vec3 d, float t);
/* Solid-angle pdf of the environment light for direction d. */
float light_env_pdf_li(const Lights *ls, vec3 d);

#endif
