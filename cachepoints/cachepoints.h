/* cachepoints/cachepoints.h: cache points for occlusion-aware many-light selection (Li et
 * al., "Cache Points for Production-Scale Occlusion-Aware Many-Lights Sampling and
 * Volumetric Scattering", DigiPro 2024, §3). Section (§) and equation numbers in this
 * module's comments are the paper's.
 *
 * A sparse set of world-space points, each holding a compressed light distribution: a near
 * list (lights evaluated exactly at the shading vertex) and seven far bins (irradiance on the
 * six cardinal planes and an omnidirectional fluence, unoccluded, blurred over neighbours),
 * multiplied at render time by a learned visibility weight per (point, light).
 *
 * The module knows nothing about the renderer: lights are seen through CachePointLights
 * (a centroid per light and an estimate callback), parallel loops through a parallel-for
 * callback. Everything is deterministic for a given input whatever the thread count. */
#ifndef CANDELA_CACHEPOINTS_H
#define CANDELA_CACHEPOINTS_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

/* Optional view of the scene's light BVH. With it the build works on clusters of lights (a
 * cut through the tree) and never visits every light for every point (the paper's scaling
 * failure, §5.2.2). The tree is binary and depth-first: node 0 is the root and an interior
 * node's first child is node + 1, so a subtree is a contiguous range of node indices. */
typedef struct CachePointTree {
    uint32_t node_count;
    const uint32_t *second_child; /* per node: interior: index of the second child; leaf: 0 */
    const uint32_t *leaf_light;   /* per node: leaf: its light; interior: UINT32_MAX */
    const uint32_t *light_leaf;   /* per light: its leaf, or UINT32_MAX (infinite, or no power) */
    /* bounding box of the emitters below a node */
    void (*node_bounds)(const void *user, uint32_t node, float lo[3], float hi[3]);
    /* Approximate summed unoccluded contribution of the lights below an interior node at x, in
     * the seven bins of estimate7 (from the node's bounds; only ever a sampling weight). */
    void (*node_estimate7)(const void *user, uint32_t node, const float x[3], float out[7]);
    /* Picks a light below `node` for a vertex (x, n; n == NULL: omnidirectional) with u in
     * [0,1) and reports its probability given the node; descend_pmf returns bit for bit the
     * probability descend gives `light` (a light below node). */
    uint32_t (*descend)(const void *user, uint32_t node, const float x[3], const float *n, float u, float *pmf);
    float (*descend_pmf)(const void *user, uint32_t node, const float x[3], const float *n, uint32_t light);
} CachePointTree;

/* The scene's lights as the cache points see them. */
typedef struct CachePointLights {
    uint32_t count;
    const float *centroid;   /* 3 per light */
    const uint8_t *infinite; /* 1: directional / environment (always far, §3.1.3) */
    /* Unoccluded estimate of light `light` at x for the seven sensors of §3.1.3: out[0..5]
     * irradiance on the planes facing +X, -X, +Y, -Y, +Z, -Z; out[6] fluence. Deterministic. */
    void (*estimate7)(const void *user, uint32_t light, const float x[3], float out[7]);
    /* The same irradiance on the plane with unit normal n (n == NULL: fluence), used for the
     * exact near-light weights at a vertex (§3.3). */
    float (*estimate)(const void *user, uint32_t light, const float x[3], const float *n);
    const void *user;
    const CachePointTree *tree; /* NULL: only the linear build is possible */
    /* Optional, for BSDF-aware selection (cachepoints_vertex_lobe): 4 floats per light, a
     * bounding sphere (centre, radius; 0 for a point); for an infinite light the unit direction
     * toward it and its angular radius in radians (>= pi: all around, an environment). NULL: the
     * lobe is never used. */
    const float *bound;
} CachePointLights;

/* Camera footprint for the pixel-sized radii of the merge passes (r_px): pass 1 merges
 * within one pixel (merge.c says why not the paper's 1e-5), §3.1.4 keeps r_p >= 3 pixels. */
typedef struct CachePointCamera {
    float position[3];
    float pixel_angle;   /* perspective: 2 tan(fov_y/2) / height; 0 for orthographic */
    float pixel_size;    /* orthographic: world size of a pixel */
} CachePointCamera;

typedef void (*CachePointParallelFor)(void *pool, size_t n, size_t grain,
                                      void (*fn)(void *ctx, size_t begin, size_t end, int thread), void *ctx);

typedef struct CachePointParams {
    uint32_t knn;             /* 20: merge passes (§3.1.2, §3.1.4) */
    float near_factor;        /* D = 4 (Eq. 1) */
    float energy_fraction;    /* 0.97 per far bin (§3.1.3) */
    uint32_t min_per_bin, max_per_bin; /* 4, 256 */
    uint32_t max_near;        /* 256, at most CACHEPOINTS_MAX_NEAR (the paper sets no cap: this bounds the
                               * work per vertex; the strongest by fluence stay near, the rest go far) */
    uint32_t blur_neighbours; /* 16 (§3.1.5) */
    float r_min;              /* 0.04 (Eq. 6) */
    float epsilon;            /* 0.03: probability of a uniform pick among all lights (§3.3, which gives
                               * no value; bins keep 97% of their energy) */
    int visibility;           /* learn visibility (§3.2); 0 = --no-visibility */
    int pool_visibility;      /* 1: a slot with too few attempts for Eq. 6 pools its neighbours' counters;
                               * 2: and then, cut build, those of its point's slots below an ancestor of
                               * its key in the light tree (pool.c, beyond the paper); 0: the paper's */
    int retruncate;           /* linear: re-apply 97% / 4..256 per bin after the blur (bounds memory; off = paper) */
    int build_cut;            /* 1: far entries are a cut through lights->tree (needs the tree); 0: linear */
    uint32_t cut_size;        /* cut build: far entries per point (clusters or single lights) */
    /* progressive insertion (cachepoints_progress, progressive.c; beyond the paper, §5.2.1):
     * at barriers progressive_first .. progressive_first + progressive_rounds - 1 (1: the
     * first barrier), up to progressive_budget x the build's points in all; 0 rounds: off */
    uint32_t progressive_rounds, progressive_first;
    float progressive_budget;
    CachePointParallelFor parallel_for;
    void *pool;
} CachePointParams;

void cachepoints_default_params(CachePointParams *p);

typedef struct CachePoints CachePoints;

/* Statistics of the build, for the comparison table (the caller times the build). */
typedef struct CachePointStats {
    uint32_t candidates, after_pass1, final_points;
    size_t bytes;                 /* the cache points' arrays */
    double mean_near, mean_far;   /* entries per point (far: after the blur) */
    double mean_far_clusters;     /* cut build: far entries per point that are clusters */
} CachePointStats;

/* Builds from candidate positions (3 floats each; non-finite ones are dropped) in the order
 * given, which should be spatially coherent (§3.1.1 sorts them along a space-filling curve;
 * the renderer uses a 63-bit Morton code): the merge passes keep the lowest index of a
 * neighbourhood, so the order decides which of two close candidates survives, and any
 * deterministic order gives a deterministic build. Returns
 *    0  ok, *out is the cache points;
 *    1  fewer than 10 points (§3.1.1: the caller falls back to per-vertex optimal
 *       selection), or no lights at all (nothing to select: no points are needed);
 *   -1  out of memory;
 *   -2  invalid parameters: knn or blur_neighbours above 64, epsilon outside [0, 1], or
 *       build_cut without a complete tree (every callback, cut_size >= 1, the documented
 *       layout).
 * Whenever it does not return 0, *out is NULL. */
int cachepoints_build(CachePoints **out, const float *candidates, uint32_t num_candidates,
                      const CachePointLights *lights, const CachePointCamera *camera,
                      const CachePointParams *params, CachePointStats *stats);
void cachepoints_free(CachePoints *cp);
uint32_t cachepoints_count(const CachePoints *cp);
/* Position and radius of point i (tests, debugging). */
void cachepoints_point(const CachePoints *cp, uint32_t i, float pos[3], float *radius);

/* A path vertex as the cache points see it (§3.3): its cache point and the summed exact
 * weight of that point's near lights at the vertex. Computed once per vertex and kept (the
 * wavefront stores it in the path state), so that NEE and the MIS PDF of the next bounce
 * hitting a light use one nearest-point query and one near-light pass, and the PDF is
 * exactly that of the distribution NEE sampled from. */
typedef struct CachePointVertex {
    uint32_t point;
    float near_total;
    /* BSDF-aware selection (cachepoints_vertex_lobe; all 0: the paper's normal-only selection):
     * the glossy lobe's axis and sharpness lambda, its share of the distribution and
     * the sum of the lobe-weighted weights */
    float lobe_axis[3], lobe_sharpness, lobe_mix, lobe_total;
} CachePointVertex;

/* Near lists hold at most this many lights (CachePointParams.max_near is clamped to it), so
 * a caller can keep a vertex's near weights in a stack array. */
#define CACHEPOINTS_MAX_NEAR 256

/* The vertex at x with shading normal n (n == NULL: volumes and transmissive surfaces use
 * the fluence bin); its point is the nearest cache point (ties: lowest index). hint: a guess
 * that speeds up the search without changing its result (the previous vertex's point in a
 * coherent stream), or UINT32_MAX.
 * near_w (may be NULL; CACHEPOINTS_MAX_NEAR floats) receives each near light's weight, which
 * cachepoints_select then reuses instead of evaluating the near lights again. */
void cachepoints_vertex(const CachePoints *cp, const CachePointLights *lights, const float x[3], const float *n,
                        uint32_t hint, CachePointVertex *v, float *near_w);
/* The vertex at x using cache point `point` if x lies within its radius of influence (§3.3:
 * a medium walk keeps its previous point while it stays inside it; no search), else as
 * cachepoints_vertex. */
void cachepoints_vertex_reuse(const CachePoints *cp, const CachePointLights *lights, const float x[3], const float *n,
                              uint32_t point, CachePointVertex *v, float *near_w);
/* Render-time selection (§3.3): near lights exact, far bins blended by n, visibility
 * weights, uniform floor epsilon; a cluster entry descends the light tree with u_descend.
 * *slot receives the visibility slot cachepoints_record counts the outcome in
 * (UINT32_MAX: none). */
uint32_t cachepoints_select(const CachePoints *cp, const CachePointLights *lights, const float x[3],
                            const float *n, const CachePointVertex *v, const float *near_w, float u, float u_descend,
                            float *pmf, uint32_t *slot);
/* Exactly the probability cachepoints_select gives `light` at the vertex. */
float cachepoints_pmf(const CachePoints *cp, const CachePointLights *lights, const float x[3], const float *n,
                      const CachePointVertex *v, uint32_t light);
/* BSDF-aware selection at glossy vertices (beyond the paper: §6 names joint BSDF and light
 * selection as future work). The paper weighs a vertex's entries by irradiance on its normal,
 * w_e (near lights exact, far bins blended by n, x W'), which follows a diffuse BSDF. For a
 * glossy lobe whose density toward wi is about D(wi) = (1 + 2 lambda) / (4 pi) / (1 + lambda
 * (1 - cos(wi, axis)))^2 (GGX's profile around the mirror direction `axis`, unit; lookup.c),
 * an entry's lobe-weighted weight is w_e x D_e, with D_e the lobe's mean density over the
 * entry's bounding cone (the lobe widened by the cone; clusters: their tree node's box; needs
 * lights->bound). The distribution becomes the
 * defensive mixture
 *     p(e) = (1 - eps) [(1 - g) w_e / W + g w_e D_e / W_D] + eps / N,
 * W and W_D the two sums, g = kappa W_D / (W + kappa W_D) (kappa: the lobe's weight against
 * the diffuse part, INFINITY for a metal) clamped to CACHEPOINTS_LOBE_MAX_MIX, so that p never
 * falls below (1 - g_max) of the paper's. This sets v's lobe fields (lobe_mix g, lobe_total
 * W_D) for a vertex cachepoints_vertex (or _reuse) prepared with the same x, n (near_w: its
 * near weights, or NULL); g below CACHEPOINTS_LOBE_MIN_MIX, no normal, no lights->bound or a
 * zero total leave lobe_mix 0, and select / pmf then are exactly the paper's. Select and pmf
 * follow the lobe for such a vertex; keep its lobe fields with it (the renderer's token). Not
 * for light-linked vertices (the _linked functions ignore the lobe). */
/* The key spheres the lobe needs (call once after the build, with lights->bound set): 0 ok, -1
 * out of memory or no bounds. */
int cachepoints_prepare_lobes(CachePoints *cp, const CachePointLights *lights);
#define CACHEPOINTS_LOBE_MAX_MIX 0.9f
#define CACHEPOINTS_LOBE_MIN_MIX 0.02f
void cachepoints_vertex_lobe(const CachePoints *cp, const CachePointLights *lights, const float x[3], const float *n,
                             const float *near_w, const float axis[3], float sharpness, float kappa,
                             CachePointVertex *v);
/* Light linking (§3.3: "we then remove any lights that are disabled for the current path
 * vertex through light linking"): the lights that may illuminate a vertex. The *_linked
 * functions are the ones above for such a vertex: disabled near lights weigh 0, disabled far
 * entries that are single lights leave the far distribution (their weights are subtracted
 * per bin and the search skips them), and the uniform floor epsilon spreads over the enabled
 * lights only, so p(e | x) = (1 - eps) w_e / W' + eps / N_link for enabled lights and 0 for
 * the others. A far *cluster* (cut build) holding disabled lights is kept whole: its descent
 * may land on a disabled light, and then select reports pmf 0 and no slot (the caller takes
 * no sample); the probabilities of enabled lights stay exact (pmf agrees with select). The
 * vertex's near_total is the linked one: use the linked functions throughout for the vertex.
 * "... and add back in any lights that are marked as exclusive to the current path vertex":
 * an exclusive light (one whose include list names the vertex's object) that no entry of the
 * point holds is weighed exactly at the vertex as a near light is (without a visibility
 * slot), so an object lit only by its own lights does not depend on the floor for them (the
 * first CACHEPOINTS_MAX_EXCLUSIVE of them; more rely on the entries and the floor). */
#define CACHEPOINTS_MAX_EXCLUSIVE 64
typedef struct CachePointLink {
    const uint8_t *enabled;   /* per light: 1 when it may illuminate the vertex */
    const uint32_t *lights;   /* the enabled lights, ascending (the uniform floor's choices) */
    uint32_t count;
    const uint32_t *exclusive; /* the exclusive lights, ascending */
    uint32_t num_exclusive;
    const uint32_t *disabled;  /* the disabled lights, ascending (far clusters' cuts) */
    uint32_t num_disabled;
} CachePointLink;
void cachepoints_vertex_linked(const CachePoints *cp, const CachePointLights *lights, const float x[3],
                               const float *n, uint32_t hint, const CachePointLink *link, CachePointVertex *v,
                               float *near_w);
void cachepoints_vertex_reuse_linked(const CachePoints *cp, const CachePointLights *lights, const float x[3],
                                     const float *n, uint32_t point, const CachePointLink *link, CachePointVertex *v,
                                     float *near_w);
uint32_t cachepoints_select_linked(const CachePoints *cp, const CachePointLights *lights, const float x[3],
                                   const float *n, const CachePointVertex *v, const float *near_w,
                                   const CachePointLink *link, float u, float u_descend, float *pmf, uint32_t *slot);
float cachepoints_pmf_linked(const CachePoints *cp, const CachePointLights *lights, const float x[3], const float *n,
                             const CachePointVertex *v, const CachePointLink *link, uint32_t light);

/* The cache point a vertex at x uses (the nearest; ties: lowest index). */
uint32_t cachepoints_nearest(const CachePoints *cp, const float x[3]);

/* The cache point of x (as cachepoints_nearest; hint as for cachepoints_vertex) and its
 * radius of influence r_p in *radius (may be NULL). */
uint32_t cachepoints_nearest_hint(const CachePoints *cp, const float x[3], uint32_t hint, float *radius);

/* Cache-point in-scattering sampling (§4.2): the scattering sample weight s(p, e) per (point,
 * light), computed after the build (scatter.c). The caller supplies the medium and one light
 * sample as callbacks (the module knows neither media nor cameras). */
typedef struct CachePointScatter {
    /* The scattering coefficient at y as a weight (luminance of mu_s, 1/m; 0 outside media)
     * and in *g the Henyey-Greenstein anisotropy of the medium that scatters there. */
    float (*medium)(const void *user, const float y[3], float *g);
    /* One sample of light `light` seen from y (u: 4 uniforms in [0, 1)): the phase function
     * rho_g(toward the camera, toward the light point) x the emitted radiance x the geometry
     * term / the sample's pdf, unoccluded, luminance (0 when the sample fails). */
    float (*light_sample)(const void *user, uint32_t light, const float y[3], float g, const float u[4]);
    const void *user;
    uint64_t seed;
} CachePointScatter;
/* Fills the weights: per near entry s(p, e) = the mean over 4 points y uniform in the ball of
 * radius r_p of mu_s(y) x light_sample(e, y) (the spec's §7.2 proposal); per point the far
 * lists' summed s, estimated with 8 draws of far entries from the fluence bin. Deterministic
 * whatever the thread count (the build's parallel-for). 0 ok, -1 out of memory, -2 a missing
 * callback. */
int cachepoints_build_scatter(CachePoints *cp, const CachePointLights *lights, const CachePointScatter *sc);
/* S_p = sum over lights of s(p, e): the near entries' plus the far estimate (0 before
 * cachepoints_build_scatter). */
float cachepoints_scatter_total(const CachePoints *cp, uint32_t point);
/* s(p, e) of a near light of the point; -1 when e is not in its near list (tests). */
float cachepoints_scatter_weight(const CachePoints *cp, uint32_t point, uint32_t light);
/* The far lists' part of S_p (tests). */
float cachepoints_scatter_far(const CachePoints *cp, uint32_t point);

/* Visibility learning (§3.2.1), atomic: one call per selection, once its outcome is known,
 * in the slot cachepoints_select reported. It counts an attempt (H_total) and adds
 * `visibility` to H_success: the fraction of the shadow ray that got through with a useful
 * contribution, in [0, 1] (clamped; NaN counts 0): 0 or 1 for surfaces, a transmittance
 * through participating media. Fractions are kept in steps of 1/256 (round to nearest), so
 * results do not depend on the order of the calls. Counting both at the outcome touches
 * the counters once. UINT32_MAX is ignored (the light is in none of the point's lists). */
void cachepoints_record(CachePoints *cp, uint32_t slot, float visibility);
/* A hint to fetch a slot's counters ahead of cachepoints_record (e.g. before tracing the
 * shadow rays whose outcome it will record); no effect on results. */
void cachepoints_prefetch_counters(const CachePoints *cp, uint32_t slot);
/* The slot of (point, light) (tests): UINT32_MAX when no entry of the point holds it. */
uint32_t cachepoints_slot(const CachePoints *cp, uint32_t point, uint32_t light);
/* At the iteration barrier: Eqs. 5-6 then the visibility blur (§3.2.2), out of place. A
 * slot past 2^23 attempts has both counters halved here (a deterministic rescale that
 * keeps R), so the counters never overflow while a slot gets fewer than 2^23 records per
 * iteration. */
void cachepoints_update_visibility(CachePoints *cp);
/* Progressive insertion (progressive.c; beyond the paper: §5.2.1's "add new cache points at
 * later iterations", the cache placement paper's discontinuity-guided sampling as its digest's
 * section C.3 adapts it). Call at every iteration barrier *before*
 * cachepoints_update_visibility. It counts the barrier; at the rounds the params name it
 * scores the probes (the candidates merge pass 2 deleted) by the jump in visibility rate
 * between the point a probe uses and the next nearest point, inserts the best (a budget per
 * round, minimum separation), rebuilds distributions, kd-tree and blur over old and new
 * points, and moves every old point's counters to its new slots. Old points keep their
 * indices; new ones come after them. Deterministic (counters, build and probe order only).
 * *inserted receives the count. 0 ok (also when nothing is inserted), -1 out of memory (cp
 * is unchanged). The caller rebuilds anything derived from the points (scattering weights). */
int cachepoints_progress(CachePoints *cp, const CachePointLights *lights, uint32_t *inserted);
/* Points inserted so far (cachepoints_count minus the one-shot build's). */
uint32_t cachepoints_inserted(const CachePoints *cp);
/* Checkpoints of progressive insertion: the inserted points and the barrier count. load runs
 * on a fresh build of the same scene and options, re-inserts the points (the same rebuild),
 * and must precede cachepoints_load_learned: 0 ok, -1 a short or damaged record, -2 a record
 * of another build, -3 out of memory. */
int cachepoints_save_inserted(const CachePoints *cp, FILE *out);
int cachepoints_load_inserted(CachePoints *cp, const CachePointLights *lights, FILE *in);

/* Checkpoints (checkpoint.c): what visibility learning changed (the counters, W' and the tables
 * built from it), in native byte order with a magic and format version. load expects the same
 * build (a deterministic function of the scene and options): 0 ok, -1 a short or damaged record,
 * -2 a record of another build (its sizes differ). */
int cachepoints_save_learned(const CachePoints *cp, FILE *out);
int cachepoints_load_learned(CachePoints *cp, FILE *in);
/* The visibility weight W' currently used for (point, light): that of the entry holding the
 * light (a cluster's with the cut build); 1 when no entry holds it. */
float cachepoints_visibility(const CachePoints *cp, uint32_t point, uint32_t light);
/* Eqs. 5-6: W for `successes` (the summed visibility of the attempts) out of `attempts`
 * (exposed for the anchor-value tests). */
float cachepoints_visibility_weight(float successes, uint32_t attempts, float r_min);

/* Read-only views for visualisation (inspect.c): a point's build and learning summary. */
typedef struct CachePointSummary {
    float pos[3], radius;
    uint32_t near_count, far_count; /* entries; far_count includes the clusters */
    uint32_t far_clusters;          /* far entries that are light-tree clusters (cut build) */
    uint32_t slots;                 /* visibility slots (one per near and far entry) */
    uint64_t attempts;              /* H_total summed over the slots (§3.2.1) */
    double successes;               /* H_success summed over the slots (visibility units) */
    uint32_t sparse_slots;          /* slots with too few attempts for Eq. 6 to leave W = 1 */
    uint32_t learned_slots;         /* slots whose W' (after the §3.2.2 blur) is not 1 */
    float mean_w, min_w;            /* W' over the slots (1 without slots) */
} CachePointSummary;
void cachepoints_summary(const CachePoints *cp, uint32_t point, CachePointSummary *s);
/* The entry the vertex weighs most (§3.3: near lights exact, far entries blended by n, with
 * W'): its light, or with *cluster = 1 the light-tree node of a cluster entry. UINT32_MAX
 * when every weight is 0 (only the uniform floor selects there). */
uint32_t cachepoints_top_entry(const CachePoints *cp, const CachePointLights *lights, const float x[3], const float *n,
                               const CachePointVertex *v, const float *near_w, int *cluster);

#endif
