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
 * stages' continuations; its samples train the guiding fields after every batch, and the
 * fields update at the iteration barrier (both entries of the feature table, feature.h).
 *
 * This header declares the state once (as Cycles' integrator state): the film (film.h), each
 * feature's state (AutoProbe, RecordState, GuideState), the Integrator, the slices and their
 * queues, the stages. What a feature does at a vertex is in its own header, which includes
 * this one: record.h (the recorder's hooks), guide.h (guiding's lookups), inscatter.h
 * (in-scattering sampling), volume_auto.h (the volume auto choices' probe records); what every
 * stage does at a vertex, the radiance funnel among it, is vertex.h; the features' lifecycle
 * is feature.h. */
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
#include "film.h"

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
    int debug_aov;          /* off: NEE rays carry their parent's vertex, not their own (record_child) */
    uint32_t budget;        /* vertices per path before skipping; 0: no skipping */
    float path_skip;        /* this iteration's probability that a camera ray is not recorded */
    float min_distance;     /* a child closer than this to its parent continues the parent */
    struct { _Alignas(64) RecorderSamples s; } samples[MAX_SLICES]; /* per slice, during a batch (one cache line each) */
    uint32_t batch_slices;  /* the batch's samples: samples[0 .. batch_slices), each sorted by path
                             * (in slice order they are the batch's in path order) */
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
    int learn_share;              /* MIS with --guide-bsdf-share 0: leaves learn their BSDF share */
    int share_stats;              /* training samples carry the statistics of the leaves' BSDF
                                   * shares (learned, or the caustic guard's) */
    int active;                   /* guided sampling in this iteration (after the training spp) */
    int updates;
    double train_seconds;         /* recording into and updating the fields */
    uint64_t samples_trained;
    GuideTrainingSample *train[MAX_SLICES];   /* scratch: each slice's samples of the batch, by field */
    size_t train_capacity[MAX_SLICES];
    size_t train_split[MAX_SLICES][GUIDE_FIELDS + 1]; /* field k's in train[slice][split[k] .. split[k + 1]) */
    size_t train_count[GUIDE_FIELDS];         /* each field's samples of the batch */
    int slice_failed[MAX_SLICES];
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
    /* the adjoint-driven roulette's per-pixel estimate (luminance of the film's mean at the last
     * barrier; NULL: --guide-roulette corrected or no guiding) */
    float *pixel_estimate;
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

/* MIS weight of a technique with pdf a against one with pdf b (power heuristic, beta = 2). */
static inline float power_heuristic(float a, float b) {
    if (isinf(a)) return 1.0f;
    float a2 = a * a, b2 = b * b;
    return a2 + b2 > 0.0f ? a2 / (a2 + b2) : 0.0f;
}

#endif
