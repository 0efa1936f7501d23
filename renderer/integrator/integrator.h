/* renderer/integrator/integrator.h (private): the wavefront integrator's state and its stages.
 *
 * The integrator renders iterations of batches of paths. A batch's paths live in the
 * PathState (path_state.h), indexed by slot; the batch is cut into one contiguous slice of
 * slots per worker thread, and each thread runs every wave of its slice on its own queues
 * (arrays of slots). One wave advances every live path of the slice by one bounce:
 *
 *   stage_generate ─> rays ─sort_rays─> stage_intersect ─> stage_medium ─┬─> escaped ─> stage_escaped
 *        (once)        ^                                                 └─> hits ─sort_hits─> stage_surface ─┐
 *                      │                                                   │                    │
 *                      └───────── continuation rays (the next wave) <──────┘    shadows <──────┘
 *                                                                                  │
 *                                                                            stage_shadow
 *
 * Stages are functions of (integrator, slice) in one file each (stage_*.c); the sequencing,
 * timing and ray logging are in wavefront.c. Every path carries its own depth, so a queue may
 * hold paths of different depths. Queues are filled in queue order by one thread, so their
 * contents are a function of the input only, never of thread timing.
 *
 * Two seams: the medium stage (the volume walk: free-flight sampling between the ray origin
 * and its hit, scattering and NEE in the medium through the light-selection protocol and the
 * scattering interface, then back into the hit or escaped queue) sits between
 * stage_intersect and the hit/escaped stages; the radiance recorder sees every
 * contribution through path_add_radiance and every scattering event in the surface and medium
 * stages' continuations; its samples train the guiding fields after every batch
 * (guide_train_batch), and the fields update at the iteration barrier (guide_barrier). */
#ifndef CANDELA_INTEGRATOR_H
#define CANDELA_INTEGRATOR_H

#include <pthread.h>
#include <stdio.h>
#include <stdint.h>

#include "candela.h"
#include "guiding.h"
#include "light_sampler.h"
#include "lights.h"
#include "media.h"
#include "path_state.h"
#include "scene.h"
#include "sequence.h"
#include "threads.h"

/* Per-pixel sums over the render (double: thousands of samples per pixel). */
typedef struct Film {
    int width, height;
    double *sum, *sum2;      /* 3 per pixel: sums of L and L^2 */
    double *albedo, *normal; /* 3 per pixel: sums over the paths whose camera ray hit */
    double *depth;           /* per pixel: sum of first-hit distances */
    uint32_t *hits, *count;  /* per pixel: camera rays that hit; samples */
    double *recorder;        /* 3 per pixel (--aov recorder-debug; else NULL): sums of the recorder's splats */
    double *sel_aov;         /* 6 per pixel (the light sampler's AOV, CandelaOptions.aov_selection; else NULL):
                              * sums over the hits of its two false colours (light_sampler_aov) */
    uint8_t *stopped;        /* per pixel with adaptive sampling (else NULL): 1 once it stopped sampling */
    uint32_t *target;        /* per pixel with adaptive sampling (else NULL): the samples it takes, fixed
                              * at the pilot barrier from its neighbours' pilots (0 before) */
    int aov_spp;             /* film_resolve writes CandelaImage.spp */
} Film;

int film_alloc(Film *f, int width, int height);
void film_free(Film *f);
/* Adds paths [0, count) of the batch, in path order, so every pixel sums its samples in
 * sample order whatever the batch size or thread count. */
void film_add_paths(Film *f, const PathState *ps, uint32_t count);
/* Mean, variance of the mean (sample variance / n) and AOVs. 0 ok, -1 out of memory. */
int film_resolve(const Film *f, CandelaImage *img);
/* The film's checkpoint section (ckpt_io.h). film_load checks the size (and the recorder AOV's presence); -3: an
 * adaptive film of the rule before the pilot rule (not resumable). */
int film_save(const Film *f, FILE *out);
int film_load(Film *f, FILE *in);
/* A loaded shard film fit to merge: every pixel's count equal to the shard's samples, sums
 * finite (film.c). -1 with the first bad pixel in what. */
int film_check(const Film *f, uint64_t samples, char *what, size_t len);
/* The same for a checkpoint's film: a pixel still sampling counts [done, most], one adaptive
 * sampling stopped [1, done]. */
int film_check_counts(const Film *f, uint64_t done, uint64_t most, const char *declares, char *what, size_t len);
/* Adaptive sampling (film.c has the rule and why it is unbiased). At an iteration barrier past
 * --min-spp: the first call takes the film as it stands as the pilot (every pixel the same
 * count) and fixes each pixel's target count from its neighbours' pilot statistics, never its
 * own; every call stops the pixels whose count reached their target. Needs f->stopped and
 * f->target. Returns the number of pixels still sampling. A function of the film alone. */
uint32_t film_adaptive_update(Film *f, float threshold);
/* 1 once the pilot has fixed the targets (f->target set), else 0. */
int film_adaptive_pilot_done(const Film *f);

/* Work at an iteration barrier, when no ray is in flight: learned state (a light sampler's
 * visibility, the guiding fields' update, the volume estimators' auto choices) changes only here. */
typedef struct BarrierHook {
    void (*run)(void *user);
    void *user;
} BarrierHook;
#define MAX_BARRIER_HOOKS 8

/* volume_auto.c: the probe behind the `auto` choices of the volume estimators (one per choice). */
#define AUTO_PROBE_ITERATIONS 3 /* 1 + 1 + 2 spp */
typedef struct AutoProbe {
    const char *flag;      /* the CLI flag, for the message */
    uint32_t num_media;
    uint8_t *on;           /* per medium (media_id): the feature is used */
    int active, iterations;
    double cost, paths;    /* all probe paths: counted cost */
    double pairs, path_d2; /* consecutive sample pairs of a pixel; their summed squared differences */
    struct ProbeMedium *media;
    float (*prev)[4];      /* per pixel: its last probe sample (L, on, off, medium + 1) */
} AutoProbe;

#define MAX_SLICES 256

/* record.c: the radiance recorder's state in the integrator (off: recorder NULL). */
typedef struct RecordState {
    Recorder *recorder;
    int active;             /* rays carry vertices in this iteration (guiding trains, or the AOV) */
    int training_spp;       /* guiding alone: recording stops once this many spp trained */
    int debug_aov;
    uint32_t budget;        /* vertices per path before skipping; 0: no skipping */
    float path_skip;        /* this iteration's probability that a camera ray is not recorded */
    float min_distance;     /* a child closer than this to its parent continues the parent */
    struct { _Alignas(64) RecorderSamples s; } samples[MAX_SLICES]; /* per slice, during a batch (one cache line each) */
    RecorderSamples batch;  /* the batch's samples, sorted by path */
    uint64_t iteration_paths, iteration_samples;
    uint64_t total_vertices, total_paths, total_samples, refused;
    int dropped;            /* a sample buffer ran out of memory (samples lost; the image is not affected) */
} RecordState;

/* guide.c: path guiding's state (off: surface NULL). */
/* surface fields per orientation class of the normal (+x, -x, +y, -y, +z, -z), then the medium's */
#define GUIDE_SURFACE_CLASSES 6
#define GUIDE_FIELDS (GUIDE_SURFACE_CLASSES + 1)
typedef struct GuideState {
    GuideField *fields[GUIDE_FIELDS]; /* [class]: surfaces; [GUIDE_SURFACE_CLASSES]: media (NULL without) */
    int on;                       /* guiding is on (the fields exist) */
    int mode;                     /* ScatterGuideMode (scatter.h) */
    int active;                   /* guided sampling in this iteration (after the training spp) */
    int updates;
    double train_seconds;         /* recording into and updating the fields */
    uint64_t samples_trained;
    GuideTrainingSample *train[GUIDE_FIELDS]; /* scratch: each field's samples of the batch */
    size_t train_capacity[GUIDE_FIELDS], train_count[GUIDE_FIELDS];
    int field_failed[GUIDE_FIELDS];           /* per field (the fields train on the threads) */
    GuideTrainingSample *last;    /* guide-dump: the surface samples of the iteration being trained */
    uint8_t *last_class;          /* their normal classes */
    size_t last_count, last_capacity;
    int dropped;                  /* a batch's training or an update ran out of memory */
    int keep_last;                /* guide-dump asked: keep `last` */
    int pending;                  /* samples were recorded since the last update */
    /* --guiding auto (guide.c): probing during the first GUIDE_AUTO_PROBE_SPP, then on or off */
    int auto_state;               /* GUIDE_AUTO_NONE (a fixed mode), _PROBING, _ON, _OFF */
    int train_start;              /* spp done when training began (0: auto probes with the recorder on) */
    int guided_from;              /* the first iteration of the guided schedule (render.c); -1: none */
    float auto_ratio, auto_indirect, auto_gain; /* the decision's prediction, indirect share and gain */
    float (*probe_prev)[2];       /* per pixel while probing: its last sample's L and indirect L */
    double (*probe_d2)[2];        /* and the sums of their squared differences to the one before */
    uint32_t *probe_samples;      /* and its probe samples */
    double *probe_sum;            /* and the sum of their indirect L */
} GuideState;
enum { GUIDE_AUTO_NONE = 0, GUIDE_AUTO_PROBING, GUIDE_AUTO_ON, GUIDE_AUTO_OFF };

typedef struct Integrator {
    const CandelaOptions *opt;
    const Scene *scene;
    const Lights *lights;
    const LightSampler *light_sampler;
    const SceneMedia *media;
    uint32_t camera_medium;   /* the mesh medium the camera is in (media.h) */
    int inscatter;            /* in-scattering sampling on camera segments (inscatter.c) may run */
    /* per medium (media_id): whether its camera segments use in-scattering sampling, and whether
     * NEE samples its emission (on: all; auto: decided after a probe, volume_auto.c) */
    AutoProbe inscatter_auto, emission_auto;
    PathState ps;
    SobolTables sobol_tables;
    const SobolTables *sobol; /* --sampler sobol: &sobol_tables; NULL: independent numbers */
    /* queue storage for the whole batch; a slice uses its own [begin, end) part of each */
    uint32_t *queue_rays, *queue_hits, *queue_escaped, *queue_shadows;
    uint64_t *sort_keys, *sort_keys_tmp;
    uint32_t *sort_items_tmp;
    vec3 sort_origin, sort_scale; /* the Morton grid of the queue sort keys (queue_sort.c) */
    /* the batch being rendered: paths j = batch_first .. batch_first + batch_count - 1 of the
     * iteration (pixel j mod npixels, sample sample_base + j / npixels) */
    uint64_t batch_first, sample_base;
    uint32_t batch_count, npixels;
    /* adaptive sampling: the pixels of this iteration, in pixel order (path j is pixel
     * pixel_list[j mod iteration_pixels], sample sample_base + j / iteration_pixels); without
     * it pixel_list is NULL and iteration_pixels npixels */
    uint32_t *pixel_list;
    uint32_t iteration_pixels;
    Film film;
    RecordState record;
    GuideState guide;
    int iteration_spp, spp_done;  /* the iteration being rendered (render.c), for the barrier hooks */
    int iteration_index;          /* its index in the render's schedule */
    BarrierHook hooks[MAX_BARRIER_HOOKS];
    int num_hooks;
    CandelaRayLog *ray_log;   /* bench: every traced ray (NULL: not recorded) */
    ThreadPool *pool;         /* the render's threads, for the batch-end and barrier work (NULL: serial) */
    pthread_mutex_t ray_log_mutex;
} Integrator;

/* wavefront.c: allocation for batches of up to `batch` paths (0 ok, -1 out of memory), one
 * batch (the paths the caller set in batch_first / batch_count / sample_base) on the pool,
 * added to the film and the statistics, and the barrier hooks. */
int integrator_init(Integrator *ig, const CandelaOptions *o, const Scene *scene, const Lights *lights,
                    const SceneMedia *media, const LightSampler *sampler, uint32_t batch);
void integrator_free(Integrator *ig);
void integrator_run_batch(Integrator *ig, ThreadPool *pool, CandelaStats *stats);
/* a barrier hook of the caller's (the light sampler's learning): -1 when MAX_BARRIER_HOOKS are taken */
int integrator_add_barrier_hook(Integrator *ig, void (*run)(void *user), void *user);
void integrator_barrier(Integrator *ig);

/* bench.c: appends rays[items[i]] (i < n) to the benchmark's ray log (bounce rays with an
 * infinite tfar, shadow rays with theirs). */
void ray_log_append(CandelaRayLog *log, const SceneRay *rays, const uint32_t *items, uint32_t n, int shadow);

enum { STAGE_GENERATE, STAGE_SORT, STAGE_TRACE, STAGE_MEDIUM, STAGE_SHADE, STAGE_SHADOW, STAGE_COUNT };

/* One thread's part of a batch: slots [begin, end) and its queues. */
typedef struct Slice {
    _Alignas(64) uint32_t begin, end; /* slices of different threads never share a cache line */
    uint32_t wave;                                 /* 0: the camera rays */
    uint32_t *rays, *hits, *escaped, *shadows;    /* queues (slot indices) */
    uint32_t num_rays, num_hits, num_escaped, num_shadows;
    uint64_t *keys, *keys_tmp;                   /* keys[i]: the sort key of the queue being built (rays or hits); scratch */
    uint32_t *items_tmp;
    double seconds[STAGE_COUNT];
    uint64_t bounce_rays, shadow_rays;
    VolumeStats volume;                          /* the media trackers' counts */
    RecorderCache record_cache;                  /* the recorder's free indices of this thread */
    RecorderSamples *record_samples;             /* where this slice's training samples go */
} Slice;

/* ---------------------------------------------------------------- stages (stage_*.c) */

/* Stages take the integrator const: during a batch the threads share it read-only, and each
 * writes only the path state of its own slots (the PathState's arrays are not const) and its
 * own slice. */

/* Camera rays for every slot of the slice: the path's pixel and sample, its RNG key, an empty
 * radiance, unit throughput; fills the ray queue. */
void stage_generate(const Integrator *ig, Slice *s);
/* Closest hits of the ray queue; splits it into the hit and escaped queues (queue order). */
void stage_intersect(const Integrator *ig, Slice *s);
/* Paths whose ray segment crosses media walk it depth-first (free flights, scattering with
 * NEE and phase sampling, emission) with their own RNG sub-streams, and rejoin the hit or the
 * escaped queue where the walk leaves the media, or end. */
void stage_medium(const Integrator *ig, Slice *s);
/* Escaped rays: the environment's radiance, MIS-weighted against the light sampler. */
void stage_escaped(const Integrator *ig, Slice *s);
/* Hits, in the sorted hit queue: emission found (MIS), next-event estimation (a shadow ray
 * into the shadow queue), and the continuation (scatter, roulette; into the ray queue). */
void stage_surface(const Integrator *ig, Slice *s);
/* Shadow rays: the NEE contribution of the ones that get through; their outcome goes back to
 * the light sampler. */
void stage_shadow(const Integrator *ig, Slice *s);

/* queue_sort.c: the ray queue by (direction octant, Morton code of the origin), the hit queue by
 * (glTF primitive, Morton code of the hit point); stable radix sorts. */
void sort_rays(const Integrator *ig, Slice *s);
void sort_hits(const Integrator *ig, Slice *s);
/* The queues' keys are written where a path joins the queue (its ray or hit is in cache
 * there, not when the sort gathers it in queue order): whoever appends slot p at position i
 * of the ray (hit) queue sets s->keys[i] = sort_key_ray (sort_key_hit) of p. The camera rays
 * (wave 0) are not sorted: stage_generate queues them in pixel order, coherent already. */
void sort_init(Integrator *ig);
uint64_t sort_key_ray(const Integrator *ig, const SceneRay *r);
uint64_t sort_key_hit(const Integrator *ig, const SceneRay *r, const SceneHit *h);

/* ---------------------------------------------------------------- the radiance funnel */

typedef enum {
    RADIANCE_EMISSION,    /* an emitter hit by the path (camera or BSDF sample), MIS-weighted */
    RADIANCE_ENVIRONMENT, /* the environment seen by an escaped ray, MIS-weighted */
    RADIANCE_DIRECT       /* next-event estimation through an unoccluded shadow ray */
} RadianceSource;

/* record.c: the radiance recorder's side of the wavefront (see there; its lifecycle is its
 * entry in the feature table, feature.h). */
/* A camera ray: its vertex is the camera; path skipping is decided here. */
void record_camera(const Integrator *ig, uint32_t p, uint64_t path);
/* A child vertex of `parent` for a ray leaving pos in dir with throughput tp, or the parent
 * continued (too close: `segment` is the distance from the parent's origin; past the budget).
 * cosine: |cos| of dir to the surface's shading normal (1 in media, and for NEE rays, which
 * guiding does not learn from). */
uint32_t record_child(const Integrator *ig, Slice *s, uint32_t p, uint32_t parent, vec3 pos, vec3 dir, vec3 tp,
                      float pdf, float scatter_pdf, float guide_pdf, float cosine, uint32_t flags, float segment);
/* The holder of vertex pv in path p lets go (records and backpropagates at zero). */
void record_done(const Integrator *ig, Slice *s, uint32_t p, uint32_t pv);
void record_radiance(const Integrator *ig, uint32_t p, vec3 c, RadianceSource source);

/* The recorder's hooks as the stages call them, unconditionally: each tests whether the recorder
 * is on (record.active, set by guiding at the barrier) itself, so no stage does (as Cycles'
 * guiding_record_* hooks do). Inline, so a stage compiles to the branch it had when it tested the
 * flag at the call site; vectors are passed by pointer because a vec3 passed by value is copied
 * before the test (measured with callgrind: +1.3% in stage_surface with the recorder off). */
/* Radiance added to path p (path_add_radiance). */
static inline void record_vertex_radiance(const Integrator *ig, uint32_t p, const vec3 *c, RadianceSource source) {
    if (ig->record.active) record_radiance(ig, p, *c, source);
}
/* The path's ray continues from a scattering vertex: its vertex becomes the child of the one it
 * carried (vertex_continue). */
static inline void record_vertex_child(const Integrator *ig, Slice *s, uint32_t p, const vec3 *pos, const vec3 *dir,
                                       const vec3 *tp, float pdf, float scatter_pdf, float guide_pdf, float cosine,
                                       uint32_t flags, float segment) {
    if (ig->record.active)
        ig->ps.pv[p] =
            record_child(ig, s, p, ig->ps.pv[p], *pos, *dir, *tp, pdf, scatter_pdf, guide_pdf, cosine, flags, segment);
}
/* The throughput of an NEE ray, for its recorder vertex: the contribution per unit of the
 * light's radiance (so its sample is the radiance that arrived). */
static inline vec3 nee_throughput(vec3 contrib, vec3 radiance) {
    return v3(radiance.x > 0.0f ? contrib.x / radiance.x : 0.0f, radiance.y > 0.0f ? contrib.y / radiance.y : 0.0f,
              radiance.z > 0.0f ? contrib.z / radiance.z : 0.0f);
}

/* An NEE ray leaves pos toward a light sampled with pdf: its vertex (shadow_pv), a child of the
 * path's, with nee_throughput of its contribution times weight (the medium's MIS weight; 1 at a
 * surface) and the light's radiance. */
static inline void record_nee_vertex(const Integrator *ig, Slice *s, uint32_t p, const vec3 *pos, const vec3 *dir,
                                     const vec3 *contrib, float weight, const vec3 *radiance, float pdf, uint32_t flags,
                                     float segment) {
    if (ig->record.active)
        ig->ps.shadow_pv[p] = record_child(ig, s, p, ig->ps.pv[p], *pos, *dir, nee_throughput(v3_scale(*contrib, weight), *radiance),
                                           pdf, pdf, 0.0f, 1.0f, flags, segment);
}
/* The NEE ray of path p is done (its contribution added): its vertex is released. */
static inline void record_nee_done(const Integrator *ig, Slice *s, uint32_t p) {
    if (ig->record.active) {
        record_done(ig, s, p, ig->ps.shadow_pv[p]);
        ig->ps.shadow_pv[p] = PV_CAMERA;
    }
}
/* A scattering event is done with the vertex of the ray that arrived (`incoming`); continued: 0
 * when the path ends there (its ray then carries no vertex). */
static inline void record_scatter_done(const Integrator *ig, Slice *s, uint32_t p, uint32_t incoming, int continued) {
    if (ig->record.active) {
        if (!continued) ig->ps.pv[p] = PV_CAMERA;
        record_done(ig, s, p, incoming);
    }
}
/* The path ends (path_end): its ray's vertex is released. */
static inline void record_path_end(const Integrator *ig, Slice *s, uint32_t p) {
    if (ig->record.active) {
        record_done(ig, s, p, ig->ps.pv[p]);
        ig->ps.pv[p] = PV_CAMERA;
    }
}
/* The recorder vertex the ray of hit j of the slice carries (when there is such a hit),
 * prefetched a few hits before its shading. */
static inline void record_prefetch_hit(const Integrator *ig, const Slice *s, uint32_t j) {
    if (ig->record.active && j < s->num_hits) recorder_prefetch(ig->record.recorder, ig->ps.pv[s->hits[j]]);
}
/* The NEE vertices of the shadow rays items[0..m), and then their parents (read from the
 * vertices: prefetched after them), while the rays are traced. */
static inline void record_prefetch_shadows(const Integrator *ig, const uint32_t *items, uint32_t m) {
    if (ig->record.active)
        for (uint32_t k = 0; k < m; ++k) recorder_prefetch(ig->record.recorder, ig->ps.shadow_pv[items[k]]);
}
static inline void record_prefetch_shadow_parents(const Integrator *ig, const uint32_t *items, uint32_t m) {
    if (ig->record.active)
        for (uint32_t k = 0; k < m; ++k) recorder_prefetch_parent(ig->record.recorder, ig->ps.shadow_pv[items[k]]);
}

/* guide.c: path guiding (see there; its lifecycle, training, auto's probe, guide-dump and
 * checkpoints are its entry in the feature table, feature.h). */
#define GUIDE_MAX_VOLUME_VERTICES 8 /* medium vertices of a path that are guided (stage_medium.c) */
/* The learned distribution at p: a surface's with normal n (its orientation class), or the
 * medium field's (n zero); NULL while guiding is not active. cursors: one per field, zeroed at
 * the start of a stage (guiding.h: a spatially sorted sequence of lookups stays cheap). */
const GuideDistribution *guide_lookup(const Integrator *ig, vec3 p, vec3 n, GuideCursor cursors[GUIDE_FIELDS]);
/* The field guide_lookup reads for normal n: surfaces by the orientation class of n (2 x the axis
 * of its largest component + (that component < 0)), media (n zero) the last. */
static inline int guide_field_of_normal(vec3 n) {
    if (n.x == 0.0f && n.y == 0.0f && n.z == 0.0f) return GUIDE_SURFACE_CLASSES;
    float ax = fabsf(n.x), ay = fabsf(n.y), az = fabsf(n.z);
    if (ax >= ay && ax >= az) return n.x < 0.0f;
    if (ay >= az) return 2 + (n.y < 0.0f);
    return 4 + (n.z < 0.0f);
}
/* The recorder flags that carry a surface vertex's orientation class. */
uint32_t guide_surface_flags(vec3 n);
/* The recorder's flags of a surface vertex a path continues from (a recorder hook, above: 0,
 * nothing computed, while the recorder is off): delta, and the orientation class guiding
 * learns it in. */
static inline uint32_t record_surface_flags(const Integrator *ig, int delta, const vec3 *ng) {
    return ig->record.active ? (delta ? PV_FLAG_DELTA : 0u) | guide_surface_flags(*ng) : 0u;
}

/* Every addition to a path's radiance goes through here (throughput and MIS weight already
 * applied): the one place the radiance recorder observes the contributions of a path, and
 * where --clamp-direct / --clamp-indirect apply. An emitter or the environment found by the
 * path's ray goes to that ray's vertex, a shadow ray's contribution to the NEE vertex. depth:
 * that of the ray that found the emitter (emission, environment) or of the vertex that sampled
 * the light (direct), so the light reaches the camera through depth (depth + 1) scattering
 * vertices; at most one is "direct" (Cycles' clamps: the camera's emitters, NEE at the first
 * hit, and the first hit's BSDF samples that find a light), the rest indirect. */
static inline void path_add_radiance(const Integrator *ig, uint32_t p, vec3 contribution, RadianceSource source,
                                     uint32_t depth) {
    uint32_t vertices = source == RADIANCE_DIRECT ? depth + 1 : depth;
    float limit = vertices <= 1 ? ig->opt->clamp_direct : ig->opt->clamp_indirect;
    if (limit > 0.0f) { /* the largest channel to the limit, hue kept (biased: off by default) */
        float m = v3_max_component(contribution);
        if (m > limit) contribution = v3_scale(contribution, limit / m);
    }
    ig->ps.radiance[p] = v3_add(ig->ps.radiance[p], contribution);
    /* --guiding auto's probe: the light guiding could help with (two or more bounces) */
    if (ig->guide.auto_state == GUIDE_AUTO_PROBING && vertices >= 2) ig->ps.probe_indirect[p] += v3_luminance(contribution);
    record_vertex_radiance(ig, p, &contribution, source);
}

/* The path ends: its ray's vertex is released. */
static inline void path_end(const Integrator *ig, Slice *s, uint32_t p) {
    record_path_end(ig, s, p);
}

/* What path p draws its fixed dimensions with (sequence.h: dims_camera, dims_bounce). */
static inline PathDims path_dims(const Integrator *ig, uint32_t p) {
    PathDims d = {ig->ps.rng_key[p], ig->sobol, ig->ps.scramble[p], ig->ps.sample_rindex[p]};
    return d;
}

/* The first-hit AOVs of a path (written once, at depth 0). */
static inline void path_write_aovs(const PathState *ps, uint32_t p, vec3 albedo, vec3 normal, float depth) {
    ps->aov_albedo[p] = albedo;
    ps->aov_normal[p] = normal;
    ps->aov_depth[p] = depth;
}

/* inscatter.c: in-scattering sampling along camera rays (the paper's §4.2, spec §7.2-7.3), for
 * light samplers that provide scattering weights (light_sampler_inscatter_weight). A camera
 * segment through media gets a distance table (stations at the sampler's weights along it);
 * 1 when built, 0 when the segment has no finite medium interval. */
int inscatter_table(const Integrator *ig, SceneRay ray, float tmax, const MediaView *view, uint32_t *hint,
                    VolumeDistanceTable *tab);
/* The technique's estimate: a distance from the table, ratio tracking to it, and NEE there
 * (light selection through the protocol, a shadow ray with its transmittance), weighted by the
 * balance heuristic against null-collision tracking (Eq. 10), added through the funnel. */
float inscatter_estimate(const Integrator *ig, Slice *s, uint32_t p, SceneRay ray, const MediaView *view,
                         const VolumeDistanceTable *tab, uint32_t *hint, float *scratch, float *cost);

/* volume_auto.c: the volume estimators' `auto` choices, in-scattering sampling's and emission
 * sampling's: each a per-medium state (off, on, auto) and a probe (AutoProbe) whose accounting
 * after each batch and decision at a barrier are its entry in the feature table (feature.h);
 * the probes' records, path by path, are the inline functions below. */
/* Whether a camera segment through these media uses in-scattering sampling (a function of the
 * media and of the iteration's state only, so both techniques agree on it). */
int inscatter_segment_on(const Integrator *ig, const MediaView *view);

/* The auto choices' rule (both probes): with V_path the variance of the paths' radiance
 * measured with the feature on, V_on / V_off that of the feature's share of it with and
 * without the feature, C the mean cost of a path and c_feature what the feature adds to it,
 * keep the feature when (V_path - V_on + V_on) C < (V_path - V_on + V_off) (C - c_feature):
 * when it lowers the estimated time to unit variance. Returns that TTUV ratio (on / off). */
static inline double estimator_ttuv_ratio(double v_path, double v_on, double v_off, double C, double c_feature) {
    double v_rest = fmax(v_path - v_on, 0.0);
    double on = (v_rest + v_on) * C, off = (v_rest + v_off) * fmax(C - c_feature, 1e-9);
    return off > 0.0 ? on / off : (on > 0.0 ? INFINITY : 1.0);
}
static inline double sample_variance(double n, double sum, double sum2) {
    return n > 1.0 ? fmax((sum2 - sum * sum / n) / (n - 1.0), 0.0) : 0.0;
}

/* --volume-emission-sampling on / auto (volume_auto.c), as in-scattering sampling above: all
 * emissive volumes sample their emission by NEE during the probe (4 spp), then only those where
 * the estimated time to unit variance is lower with it (its entry in the feature table,
 * feature.h). */
/* The probe's record of a contribution of an emissive medium's emission to path p: `on` what
 * the path added (MIS-weighted NEE or tracking), `off` what tracking alone would add, cost. */
static inline void emission_probe_add(const Integrator *ig, uint32_t p, uint32_t medium_id, float on, float off,
                                      float cost) {
    const PathState *ps = &ig->ps;
    if (!ig->emission_auto.active) return;
    if (!ps->probe_em_medium[p]) ps->probe_em_medium[p] = medium_id + 1;
    if (ps->probe_em_medium[p] != medium_id + 1) return; /* one medium per path */
    ps->probe_em_on[p] += on;
    ps->probe_em_off[p] += off;
    ps->probe_em_cost[p] += cost;
}

/* ... of an NEE toward `light` (counted when it is an emissive volume): its contribution c
 * (luminance, 0 when blocked) and cost. */
static inline void emission_probe_nee(const Integrator *ig, uint32_t p, uint32_t light, float c, float cost) {
    if (!ig->emission_auto.active || light >= ig->lights->count) return;
    const Light *l = &ig->lights->lights[light];
    if (l->type == LIGHT_VOLUME) emission_probe_add(ig, p, l->medium, c, 0.0f, cost);
}

/* The probe's record of a camera segment's null-collision NEE (unweighted luminance c, and the
 * weight it got). */
static inline void inscatter_probe_null(const Integrator *ig, uint32_t p, float c, float w) {
    if (!ig->inscatter_auto.active) return;
    ig->ps.probe_null[p] += c;
    ig->ps.probe_mis[p] += w * c;
}
/* The balance-heuristic weight of the null-collision technique's first scatter at t (its
 * VolumeEvent's null_mis and sigma_s_mean) against the table's distance sampling. */
static inline float inscatter_null_weight(const VolumeDistanceTable *tab, float t, float null_mis,
                                          float sigma_s_mean) {
    float r = null_mis * sigma_s_mean, pd = volume_distance_pdf(tab, t);
    return r + pd > 0.0f ? r / (r + pd) : 1.0f;
}

/* MIS weight of a technique with pdf a against one with pdf b (power heuristic, beta = 2). */
static inline float power_heuristic(float a, float b) {
    if (isinf(a)) return 1.0f;
    float a2 = a * a, b2 = b * b;
    return a2 + b2 > 0.0f ? a2 / (a2 + b2) : 0.0f;
}

#endif
