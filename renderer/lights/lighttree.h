/* renderer/lights/lighttree.h (private): light BVH for context-aware light selection
 * (Conty Estevez & Kulla 2018, "Importance Sampling of Many Lights with Adaptive Tree
 * Splitting"; the single-path variant of pbrt-v4's BVHLightSampler).
 *
 * Every finite light with power > 0 is a leaf of a binary BVH whose nodes store a bounding
 * box, a bounding cone of emitter normals (axis w, spread theta_o, emission falloff theta_e;
 * two-sided emitters keep their cone and mirror it) and phi, the summed power of isotropic
 * emitters of the members' peak intensities (a spot counts 4 pi I, not its flux: its cone is
 * in the orientation bound). The build is pbrt-v4's SAOH (12 buckets per axis, cost
 * phi x M_Omega x surface area x Kr). Selection walks one path from the root, choosing a child
 * with probability proportional to its importance for the shading point (p, n):
 * phi cos(theta') / d^2 x cos(theta_i') (Conty Estevez & Kulla 2018, §4.1), with d^2 the
 * squared distance to the box's centre clamped to LIGHT_TREE_D2_CLAMP x the squared radius
 * of its bounding sphere, and a one-sided receiver cosine (n faces the side light is
 * gathered from; zero n: a medium point or a transmissive surface, no cosine), so a cluster
 * wholly below the horizon gets 0. The light's probability is the product of the branch
 * probabilities. light_tree_pmf() recomputes the same branch probabilities along the light's
 * stored bit trail, with the same float operations in the same order, so it returns exactly
 * what light_tree_select() reported.
 *
 * Infinite lights (directional, environment) are not in the BVH: as in pbrt-v4, each of them
 * and the BVH get one equal share, except that a directional light below the receiver's
 * horizon, and the BVH when its root has importance 0, get none at that context (they cannot
 * contribute); with nothing left the context-free shares apply. Lights with zero (or
 * non-finite) power are left out: probability 0 everywhere.
 *
 * When both children of a node have zero importance (the bounds say the point sees nothing
 * in either), the node splits in proportion to the children's power instead of giving up, so
 * the probabilities over all lights always sum to 1 (when any light is selectable) and a
 * light whose bounds are wrong by rounding is still never starved. Such samples cost one
 * light_sample_li() call that contributes nothing.
 *
 * The same structure serves as the inner tree of an emissive mesh (light_tree_build_triangles,
 * the cache points paper, §2 and §5.2.2: an emissive mesh is one light whose triangles a light
 * hierarchy picks): its "lights" are the mesh's triangles (power = area x luminance,
 * x2 when two-sided; bounds = the triangle's box; normal cone = the triangle's normal,
 * mirrored when two-sided; theta_e = pi/2), with no infinite entries, so
 * light_tree_select / light_tree_pmf pick a triangle index and give its probability. */
#ifndef CANDELA_LIGHTTREE_H
#define CANDELA_LIGHTTREE_H

#include <stdint.h>

#include "vecmath.h"

typedef struct Light Light;                           /* lights.h */
typedef struct LightSampleContext LightSampleContext; /* lights.h */

#define LIGHT_TREE_INTERIOR UINT32_MAX
/* Tree depth limit: SAOH splits up to LIGHT_TREE_SAH_DEPTH, then median splits (<= 32 more
 * levels for any uint32 light count), so every bit trail fits in 64 bits. */
#define LIGHT_TREE_SAH_DEPTH 32

enum { LIGHT_TREE_NONE = 0, LIGHT_TREE_BVH = 1, LIGHT_TREE_INFINITE = 2 };

typedef struct LightTreeNode {
    vec3 bmin, bmax;     /* bounds of the emitting geometry */
    vec3 w;              /* unit axis of the normal cone */
    float cos_o;         /* cos theta_o: spread of the normals around w (-1: every direction) */
    float cos_e;         /* cos theta_e: emission beyond the normals (point 0, spot cos_outer) */
    float phi;           /* summed power of isotropic emitters of the peak intensities (4 pi I) */
    uint32_t two_sided;  /* 1: some member emits from both faces (the cone is mirrored: |cos|) */
    uint32_t child;      /* interior: index of the second child (the first is this + 1) */
    uint32_t light;      /* leaf: light index; interior: LIGHT_TREE_INTERIOR */
} LightTreeNode;

typedef struct LightTree {
    LightTreeNode *nodes;  /* depth-first; node 0 is the root */
    uint32_t node_count;
    uint32_t light_count;  /* size of the per-light arrays */
    uint64_t *trail;       /* per light: bit d = 1 -> second child at depth d */
    uint8_t *kind;         /* per light: LIGHT_TREE_NONE / _BVH / _INFINITE */
    uint32_t *infinite;    /* light indices of the infinite lights */
    vec3 *inf_dir;         /* per infinite light: a directional light's travel direction (0: environment) */
    float *inf_sin;        /* per infinite light: sin of a sun's cone half-angle (0: a delta direction) */
    uint32_t num_infinite;
    float p_inf;           /* context-free probability of choosing among the infinite lights */
    float p_bvh;           /* 1 - p_inf: context-free factor every BVH light's pmf starts from */
    float pmf_inf;         /* p_inf / num_infinite */
    uint8_t *depth;        /* per node: its depth (the root is 0) */
    float *intensity;      /* per node, optional: summed peak radiant intensity (light_tree_set_intensities) */
} LightTree;

/* Build over lights[0..count). 0 ok, -1 out of memory (t is then empty). */
int light_tree_build(LightTree *t, const Light *lights, uint32_t count);
/* The same over the lights with enabled[i] != 0 only (NULL: all): light linking's per-class
 * trees. Light indices stay those of lights[]; the others get probability 0. */
int light_tree_build_enabled(LightTree *t, const Light *lights, uint32_t count, const uint8_t *enabled);
/* Inner tree over `count` triangles (world_vertices: 9 floats each) of one emitter with the
 * given emission luminance. Zero-area triangles are left out (probability 0). 0 ok, -1 out
 * of memory (t is then empty). */
int light_tree_build_triangles(LightTree *t, const float *world_vertices, uint32_t count, float luminance,
                               int two_sided);
/* The same tree over another placement of the same triangles (another instance of an emissive
 * mesh): `topology`'s splits, with every node's bounds, cone and power recomputed from
 * world_vertices bottom-up (no split search: the cache points paper's street instances one
 * emissive mesh thousands of times). Selection stays exact for any tree; only how well the
 * splits fit a sheared or non-uniformly scaled copy can differ. 0 ok, 1 the topology does not
 * fit (another count, or other triangles emit nothing: build instead), -1 out of memory (t is
 * then empty). */
int light_tree_refit_triangles(LightTree *t, const LightTree *topology, const float *world_vertices, uint32_t count,
                               float luminance, int two_sided);
void light_tree_free(LightTree *t);
/* Picks a light for ctx with u in [0,1); *pmf is its probability. Always returns an index
 * < count (0 when nothing is selectable, with *pmf = 0). */
uint32_t light_tree_select(const LightTree *t, const LightSampleContext *ctx, float u, float *pmf);
/* The probability light_tree_select gives `light` for ctx (bit-identical). */
float light_tree_pmf(const LightTree *t, const LightSampleContext *ctx, uint32_t light);
/* The single-path descent below `node` (cache point clusters): picks a light of that subtree
 * for ctx with u, *pmf its probability given the node. light_tree_pmf_from returns bit for
 * bit the probability light_tree_select_from gives `light` (0 if it is not below node). */
uint32_t light_tree_select_from(const LightTree *t, uint32_t node, const LightSampleContext *ctx, float u, float *pmf);
float light_tree_pmf_from(const LightTree *t, uint32_t node, const LightSampleContext *ctx, uint32_t light);
/* Per-node sums of the lights' peak radiant intensities (luminance, W/sr), for
 * light_tree_node_estimate7. 0 ok, -1 out of memory. */
int light_tree_set_intensities(LightTree *t, const float *light_intensity);
/* A node's approximate unoccluded fluence at p (out[6]) and irradiance on the planes facing
 * +X -X +Y -Y +Z -Z (out[0..5]), from its bounds, cone and summed intensity. */
void light_tree_node_estimate7(const LightTree *t, uint32_t node, vec3 p, float out[7]);
/* Importance of one node for a shading point (n zero: a point in a medium). Exposed for
 * tests. */
float light_tree_node_importance(const LightTreeNode *node, vec3 p, vec3 n);

#endif
