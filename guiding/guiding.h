/* guiding/guiding.h: the radiance recorder and the path-guiding field (C17, no renderer types).
 *
 * Two parts, used by the renderer's integrator:
 *
 * 1. The radiance recorder (path-guiding-in-production.txt ch. 2 §3; digest §1.2): path
 *    vertices in blocks of RECORDER_BLOCK_SIZE, addressed by a 32-bit PVIndex = block *
 *    RECORDER_BLOCK_SIZE + slot that a ray carries. A vertex is created for each ray leaving a
 *    scattering point (continuation and NEE), collects the emission its subtree finds, and when
 *    its reference count reaches zero records one training sample L = emission / throughput,
 *    hands its emission to its parent and is freed (cascading iteratively to the camera).
 *    The operations on one path's vertices must come from one thread in a deterministic order
 *    (the wavefront gives every path to one slice); allocation is shared and thread-safe through
 *    a per-thread RecorderCache. Training samples go to the caller's per-thread buffer.
 *
 * 2. The guiding field: Practical Path Guiding (Müller et al. 2017) written here: a spatial
 *    binary tree over the scene bounds whose leaves hold a directional quadtree pair (sampling:
 *    learned up to the previous update; building: accumulating now) over the octahedral map of
 *    directions to the (u, v) square (sdtree.c: dir_to_uv; no transcendental functions, the
 *    density's factor applied). Training and updates are
 *    single-threaded and deterministic in the order of the samples given; lookups, sampling and
 *    pdfs only read the sampling trees (any number of threads, between updates). */
#ifndef CANDELA_GUIDING_H
#define CANDELA_GUIDING_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

/* ------------------------------------------------------------------ radiance recorder */

#define RECORDER_BLOCK_SIZE 4096u
#define PV_CAMERA 0xFFFFFFFFu  /* no vertex: the camera (as a parent), or a ray with no vertex */
#define PV_SKIPPED 0xFFFFFFFEu /* a skipped path: never allocates, its children are skipped */
static inline int pv_is_vertex(uint32_t pv) { return pv < PV_SKIPPED; }

enum {
    PV_FLAG_NEE = 1,         /* the vertex's ray is a next-event (shadow) ray */
    PV_FLAG_VOLUME = 2,      /* its origin is a scattering point in a medium */
    PV_FLAG_DELTA = 4,       /* its direction came from a delta lobe (not trainable) */
    PV_FLAG_DELTA_CHILD = 8  /* set by the recorder: the vertex's ray reached a delta scatterer (a
                              * child of it took a delta direction; its sample carries the flag) */
};                           /* bits 16 and up are the caller's (the renderer: a normal class) */

/* What a new vertex knows: its ray and the throughput of that ray (camera to the vertex, times
 * the sampling weight of its direction), the pdfs of its direction. */
typedef struct RecorderVertexInit {
    float pos[3], dir[3];
    float throughput[3];
    float pdf;        /* the technique that sampled the direction (solid angle) */
    float bsdf_pdf;   /* the scattering function's own pdf of it */
    float guide_pdf;  /* the guide's pdf of it (0: not guided) */
    float cosine;     /* |cos| between the direction and the surface's normal (1 in media): the
                       * factor guiding learns the radiance times (product guiding, renderer/integrator/guide.c) */
    uint32_t flags;   /* PV_FLAG_* */
    uint32_t user;    /* the caller's word, handed back in the vertex's sample (the renderer: the
                       * guide leaf its lookup found, guide_field_leaf_of) */
    uint64_t path;    /* the path's index in the render: the sort key of its samples */
} RecorderVertexInit;

/* One training sample: the incident radiance estimate at pos from dir. */
typedef struct RecorderSample {
    float pos[3], dir[3];
    float radiance[3];   /* L = emission / throughput (0 where the throughput is 0) */
    float debug[3];      /* L x throughput, for the recorder-debug AOV (primary vertices) */
    float pdf, bsdf_pdf, guide_pdf;
    float cosine;        /* RecorderVertexInit.cosine */
    uint32_t flags;      /* PV_FLAG_*, plus RECORDER_SAMPLE_PRIMARY */
    uint32_t user;       /* RecorderVertexInit.user */
    uint64_t path;
} RecorderSample;
#define RECORDER_SAMPLE_PRIMARY 0x100u /* the vertex's parent is the camera */

/* A growable per-thread buffer of samples (the caller owns it; recorder_samples_free). */
typedef struct RecorderSamples {
    RecorderSample *items;
    size_t count, capacity;
    int failed; /* an append ran out of memory (the sample was dropped) */
} RecorderSamples;
void recorder_samples_clear(RecorderSamples *s);
void recorder_samples_free(RecorderSamples *s);
/* Stable sort by path index: the order of samples a thread count never changes. */
int recorder_samples_sort(RecorderSamples *s);

#define RECORDER_CACHE_SIZE 64
typedef struct RecorderCache {
    uint32_t free[RECORDER_CACHE_SIZE];
    uint32_t count;
    uint64_t created, refused; /* counts, added to the recorder's at recorder_flush_cache */
    int64_t live, peak;        /* this thread's live vertices (its paths' vertices are its own) */
} RecorderCache;

typedef struct Recorder Recorder;

/* A recorder holding at most max_vertices live vertices (rounded up to whole blocks; blocks
 * are allocated when first needed). NULL: out of memory. */
Recorder *recorder_create(uint32_t max_vertices);
void recorder_free(Recorder *r);
/* A child of `parent` (PV_CAMERA for a ray leaving the camera's first hit) with reference
 * count 1; the parent's count goes up by one. PV_SKIPPED when the parent is skipped. When the
 * recorder is full (counted in recorder_stats) the parent is continued and returned instead,
 * so the new ray's emission still reaches the ancestors. */
uint32_t recorder_new_child(Recorder *r, RecorderCache *cache, uint32_t parent, const RecorderVertexInit *init);
/* A ray whose vertex would record a sample nobody reads (an NEE ray under RECORDER_KEEP_TRAINABLE)
 * folds into its parent instead: the parent is continued (+1, as recorder_continue) and the ray's
 * emission is added to it directly, which is what the child would have handed up. Returned: the
 * parent. The child counts as created (recorder_stats, the path-skipping budget: the same
 * decisions, hence the same samples, as when it was a vertex). */
uint32_t recorder_fold_child(Recorder *r, RecorderCache *cache, uint32_t parent);
/* Emission (throughput-weighted, as added to the image) reaching the vertex's ray. */
void recorder_add_emission(Recorder *r, uint32_t pv, const float e[3]);
/* Another ray carries the same vertex on (e.g. a child too close to its parent): +1. */
void recorder_continue(Recorder *r, uint32_t pv);
/* One holder is done with the vertex: -1; at zero, records, backpropagates, frees (and
 * cascades up the parents). Samples are appended to `out`. */
void recorder_done(Recorder *r, RecorderCache *cache, uint32_t pv, RecorderSamples *out);
/* A hint: fetch the vertex into the cache ahead of its use (the wavefront touches a vertex
 * once per wave, long after the last time). */
void recorder_prefetch(const Recorder *r, uint32_t pv);
/* The same for the vertex's parent (read from the vertex: prefetch that first). */
void recorder_prefetch_parent(const Recorder *r, uint32_t pv);
/* Returns a thread's cached free indices to the shared stack (call at the end of a batch, for
 * every thread's cache, then recorder_end_batch). */
void recorder_flush_cache(Recorder *r, RecorderCache *cache);
/* The batch's peak of live vertices (the sum of the threads' peaks: a bound) joins the stats. */
void recorder_end_batch(Recorder *r);
/* Which samples recorder_done appends (the others are backpropagated all the same): all
 * (0, the default), or those of primary vertices (parent: the camera) and/or trainable ones
 * (neither NEE nor delta). Writing samples nobody reads was a third of the recorder's cost. */
enum { RECORDER_KEEP_PRIMARY = 1, RECORDER_KEEP_TRAINABLE = 2 };
void recorder_set_filter(Recorder *r, uint32_t keep);

typedef struct RecorderStats {
    uint64_t vertices_created;  /* since the last recorder_reset_counts */
    uint64_t vertices_refused;  /* children refused because the recorder was full */
    uint32_t peak_live;         /* the most ever allocated at once (the sum of the threads' peaks
                                 * over a batch, so a bound) */
    size_t bytes;               /* memory of the blocks allocated now */
    size_t peak_bytes;          /* the most ever (blocks are never returned before recorder_free) */
    size_t bound_bytes;         /* the most it can ever hold */
} RecorderStats;
void recorder_stats(const Recorder *r, RecorderStats *st);
void recorder_reset_counts(Recorder *r);
/* A resumed render (checkpoints): the counts since the last recorder_reset_counts as saved
 * (they decide the next iteration's path skipping). */
void recorder_restore_counts(Recorder *r, uint64_t vertices_created, uint64_t vertices_refused);
/* Every vertex freed and every index back in the free stack exactly once (a test's check). */
int recorder_consistent(const Recorder *r);

/* ------------------------------------------------------------------ guiding field (PPG) */

typedef struct GuideFieldParams {
    float spatial_threshold;   /* c: a leaf splits when its samples exceed c sqrt(2^k) (3000; PPG's
                                * 12000 is for fresh data each iteration, and the building trees
                                * here accumulate: cornell_indirect 192x192, 256 spp, 450 leaves and
                                * 1.3x lower relative variance than with 12000's 103) */
    float flux_threshold;      /* rho: a quadtree node subdivides above this share of flux (0.01) */
    int max_quadtree_depth;    /* 20 */
    size_t max_bytes;          /* memory cap of the spatial tree and its quadtrees (0: 256 MiB) */
    int spatial_filter;        /* 1: a sample trains the leaf at a point jittered within a box of
                                * its own leaf's size (Müller 2019's stochastic box filter,
                                * deterministic: the jitter hashes the sample's index); 0
                                * (default): no measurable gain on scenes/guiding_interior.gltf or
                                * scenes/default.gltf (MSE 1.13x and 1.03x of unfiltered, one run) */
    int directional_filter;    /* 1 (default): a sample trains a box of its building cell's size
                                * around its direction, each quadtree node the share it overlaps
                                * (Müller 2019's directional box filter): cornell_indirect 256x256,
                                * 256 spp, relMSE 1.38e-4 against 1.57e-4 unfiltered, 2.5% more time */
    int accumulate;            /* 1 (default): the building trees keep their statistics across
                                * updates (re-binned into the rebuilt structure, halved per
                                * split); 0: PPG 2017's fresh start each iteration */
    int learn_bsdf_share;      /* 1: each leaf learns the scattering function's share of guided
                                * one-sample MIS (ch. 1 §3.2.1) from its guided training samples'
                                * second moments; 0 (default): bsdf_share everywhere (no gain
                                * measured on the benchmark scenes: guiding/README.md) */
    float min_bsdf_share;      /* the smallest share a leaf may learn (GUIDE_DEFAULT_MIN_BSDF_SHARE) */
    float bsdf_share;          /* every leaf's share before it learns one, and always without
                                * learning (GUIDE_DEFAULT_BSDF_SHARE); in (0, 1] */
    float caustic_threshold;   /* the caustic guard (0: off; GUIDE_DEFAULT_CAUSTIC_THRESHOLD): a leaf
                                * whose guided samples show the function's sampling reaching delta
                                * scatterers with a probability above it, and the light beyond them
                                * dimmer than the leaf's average, samples the function more (share
                                * caustic_share): caustics the guide has not learned get 1 / share
                                * of their unguided weight instead of 2 */
    float caustic_share;       /* the share such a leaf takes (GUIDE_DEFAULT_CAUSTIC_SHARE), at least
                                * what it would take otherwise */
    float caustic_defense;     /* the guide's defensive density toward delta scatterers (0: none;
                                * GUIDE_DEFAULT_CAUSTIC_DEFENSE): a training sample whose ray reached
                                * one also trains its direction with this times the leaf's mean
                                * flux per sample times p_f / p, so the guide learns to send about
                                * this times the function's own density there and a caustic it has
                                * not learned keeps about its unguided weight */
} GuideFieldParams;
#define GUIDE_DEFAULT_BSDF_SHARE 0.5f
#define GUIDE_DEFAULT_MIN_BSDF_SHARE 0.5f
#define GUIDE_DEFAULT_CAUSTIC_THRESHOLD 0.0f /* off: the caustic defense does its work for less */
#define GUIDE_CAUSTIC_GUARD_THRESHOLD 0.002f  /* the threshold the guard was measured at */
#define GUIDE_DEFAULT_CAUSTIC_SHARE 0.75f
#define GUIDE_DEFAULT_CAUSTIC_DEFENSE 1.0f
void guide_field_params_default(GuideFieldParams *p);

/* A training sample of the field: incident radiance (a scalar: luminance) at pos from the unit
 * direction dir, sampled with solid-angle pdf `pdf` by the technique used (zero radiance
 * samples count: they carry weight). */
typedef struct GuideTrainingSample {
    float pos[3], dir[3];
    float radiance;
    float pdf;
    uint32_t leaf; /* a hint: the leaf guide_field_leaf_of named for a lookup at pos since the last
                    * update (GUIDE_NO_LEAF: none). Taken when pos lies in that leaf's box, where
                    * the descent would end too; else the sample's leaf is looked up. */
    /* What the leaf's BSDF share (learned, and the caustic guard) needs of a sample drawn by guided
     * one-sample MIS (bsdf_pdf 0, as zero-initialised: the sample says nothing of it): share_value
     * = F^2 / pdf >= 0 with F the estimator's numerator (a scalar, up to a factor constant over
     * the leaf), and the function's (> 0) and the guide's pdfs of dir. */
    float share_value, bsdf_pdf, guide_pdf;
    int delta_child; /* the sample's ray reached a delta scatterer (PV_FLAG_DELTA_CHILD): light
                      * beyond it is what guides rarely learn (caustics) */
    float defense;   /* a delta_child sample's p_f / pdf, the function's pdf of dir over the
                      * sample's (caustic_defense; 0: none) */
} GuideTrainingSample;
#define GUIDE_NO_LEAF 0xFFFFFFFFu

typedef struct GuideField GuideField;
/* The spatial tree spans the cube around [lo, hi] (enlarged slightly). NULL: out of memory. */
GuideField *guide_field_create(const float lo[3], const float hi[3], const GuideFieldParams *p);
void guide_field_free(GuideField *f);
/* Adds samples to the building quadtrees in the given order (deterministic). */
void guide_field_record(GuideField *f, const GuideTrainingSample *s, size_t n);
/* End of a training iteration of `iteration_spp` samples per pixel (PPG's 2^k): splits leaves
 * past the sample threshold c sqrt(iteration_spp), rebuilds every building quadtree from its
 * flux (subdivide above rho, prune below), makes them the sampling trees, and starts empty
 * building trees. 0 ok, -1 out of memory (the field keeps its previous state). */
int guide_field_update(GuideField *f, float iteration_spp);
/* Updates done so far (0: nothing learned; sampling is uniform over the sphere). */
int guide_field_iterations(const GuideField *f);
size_t guide_field_bytes(const GuideField *f);
uint32_t guide_field_num_leaves(const GuideField *f);

/* The sampling distribution of the leaf containing pos (never NULL for a live field; a point
 * outside the bounds gets the nearest leaf). Valid until the next guide_field_update. The
 * descent starts at the tree's depth-12 node, found per axis from cached midpoints (a few
 * independent compares and one load of a 16 KiB grid), then walks 8-byte nodes. */
typedef struct GuideDistribution GuideDistribution;
const GuideDistribution *guide_field_lookup(const GuideField *f, const float pos[3]);
/* The index of d, a lookup's answer since the last update, among f's leaves (GUIDE_NO_LEAF: d
 * is NULL or not f's): what a training sample of that lookup's point carries to spare the
 * descent (GuideTrainingSample.leaf). */
uint32_t guide_field_leaf_of(const GuideField *f, const GuideDistribution *d);
/* A direction from the distribution with two uniforms; its solid-angle pdf in *pdf. */
void guide_distribution_sample(const GuideDistribution *d, float u1, float u2, float dir[3], float *pdf);
float guide_distribution_pdf(const GuideDistribution *d, const float dir[3]);
/* Hints ahead of a sample with first uniform u1, and of a pdf: fetch what they will read first
 * (the alias slot; the pdf tree's root). They change nothing. */
void guide_distribution_prefetch_sample(const GuideDistribution *d, float u1);
void guide_distribution_prefetch_pdf(const GuideDistribution *d);
/* The leaf's box (the spatial node's extent), and the samples its sampling tree learned from. */
void guide_distribution_bounds(const GuideDistribution *d, float lo[3], float hi[3]);
double guide_distribution_samples(const GuideDistribution *d);
/* The leaf's estimate of the integral over the sphere of what it learned (the training samples'
 * mean radiance / pdf: the incident radiance times |cos| on surfaces, the radiance in media), so
 * that flux x guide_distribution_pdf(d, w) estimates what arrives from w; 0 before the leaf learned
 * from any sample, or for NULL. */
float guide_distribution_flux(const GuideDistribution *d);
/* The scattering function's share of guided one-sample MIS the leaf learned (in (0, 1]; 1: the
 * function alone; GUIDE_DEFAULT_BSDF_SHARE before it learned one, or for NULL). */
float guide_distribution_bsdf_share(const GuideDistribution *d);
/* The shares a leaf can learn, ascending, and how many of f's leaves hold each now. */
#define GUIDE_SHARE_CANDIDATES 7
extern const float guide_share_candidates[GUIDE_SHARE_CANDIDATES];
void guide_field_share_leaves(const GuideField *f, uint32_t counts[GUIDE_SHARE_CANDIDATES]);
/* A direction's point of the (u, v) octahedral square (the map the distributions live on); 0
 * for a zero or non-finite direction. */
int guide_direction_uv(const float dir[3], float *u, float *v);
/* The pdf over the (u, v) octahedral square on a w x h grid (row-major, v down the rows),
 * in units of solid-angle pdf, for inspection. */
void guide_distribution_image(const GuideDistribution *d, int w, int h, float *out);
/* Writes the spatial tree's leaves as an ASCII PLY of boxes (8 vertices, 6 faces each) to out
 * (the caller names the file and writes it atomically: renderer/integrator/guide.c through io's writer),
 * flushed. 0 ok; -1 with errno on failure. */
int guide_field_write_ply(const GuideField *f, FILE *out);
/* Checkpoints: the field's whole learned state (trees, counts, update count) in native byte
 * order, with its own magic and format version. load replaces the state of a field created
 * with the same parameters; on failure (-1: a short, damaged or foreign record, or out of
 * memory) the field is left as it was. */
int guide_field_save(const GuideField *f, FILE *out);
int guide_field_load(GuideField *f, FILE *in);

#endif
