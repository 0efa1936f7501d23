/* renderer/candela.h: the renderer's public API (the CLI in main.c and the tests use it).
 *
 * candela_render() loads a glTF scene, builds the Embree scene, runs the wavefront
 * iterations and returns the film; candela_write_outputs() writes EXR (+AOVs) and PNG. */
#ifndef CANDELA_H
#define CANDELA_H

#include <stddef.h>
#include <signal.h>
#include <stdint.h>
#include <stdio.h>

#define CANDELA_ERR_LEN 512

typedef enum {
    CANDELA_LIGHT_SAMPLER_UNIFORM = 0,
    CANDELA_LIGHT_SAMPLER_POWER = 1,
    CANDELA_LIGHT_SAMPLER_TREE = 2,  /* light BVH (Conty Estevez & Kulla 2018), renderer/lights/lighttree.h */
    CANDELA_LIGHT_SAMPLER_OPTIMAL = 3, /* every light's estimate per vertex: the paper's reference */
    CANDELA_LIGHT_SAMPLER_CACHEPOINTS = 4, /* cache points (Li et al. 2024), cachepoints/ */
    CANDELA_LIGHT_SAMPLER_AUTO = 5 /* the default: one of the above chosen per scene (light_sampler.c) */
} CandelaLightSampler;

/* --guiding: directional sampling at surfaces (and media) from the learned guiding field */
typedef enum {
    CANDELA_GUIDING_OFF = 0,
    CANDELA_GUIDING_MIS = 1, /* one-sample MIS of the BSDF and the guide, alpha = 0.5 (ch. 1 §3.2) */
    CANDELA_GUIDING_RIS = 2, /* RIS with one BSDF and one guide candidate (ch. 1 §3.3) */
    CANDELA_GUIDING_AUTO = 3 /* MIS where a probe over the first 4 spp predicts a lower time to unit
                              * variance, else off (renderer/integrator/guide.c) */
} CandelaGuiding;
const char *candela_guiding_name(CandelaGuiding g); /* "off", "mis", "ris", "auto" */

/* --guide-roulette: Russian roulette at guided vertices (renderer/integrator/vertex.h) */
typedef enum CandelaGuideRoulette {
    CANDELA_GUIDE_ROULETTE_CORRECTED = 0, /* the throughput's, corrected by max(1, p / p_bsdf) (ch. 1 §4.1.1), the default */
    CANDELA_GUIDE_ROULETTE_ADJOINT = 1    /* adjoint-driven from the guide's radiance estimate (ch. 1 §4.2.1) */
} CandelaGuideRoulette;

/* --sampler: where the numbers of a path's fixed dimensions come from (renderer/util/sequence.h). */
typedef enum CandelaSampler {
    CANDELA_SAMPLER_SOBOL = 0,       /* Owen-scrambled Sobol' (Burley 2020), the default */
    CANDELA_SAMPLER_INDEPENDENT = 1  /* independent hashed uniforms (the renders before Sobol') */
} CandelaSampler;

typedef enum {
    CANDELA_LIGHT_UNITS_BLENDER = 0, /* point/spot W/sr = cd/683, sun W/m^2 = lux/683 */
    CANDELA_LIGHT_UNITS_RAW = 1      /* intensities are already radiometric */
} CandelaLightUnits;

/* How punctual lights are shaped (issue 14): glTF's KHR_lights_punctual, or Blender 3.4's
 * Cycles for a scene Blender's glTF exporter wrote (spot cones: renderer/lights/lights.c). */
typedef enum {
    CANDELA_LIGHT_MODEL_GLTF = 0,     /* spot: glTF's squared linear ramp in cos between the cones */
    CANDELA_LIGHT_MODEL_BLENDER3 = 1  /* spot: Cycles 3.4's cos x smoothstep over spot_blend */
} CandelaLightModel;

/* Which BSDF materials get (issue 14; renderer/materials/bsdf.h has the formulas). */
typedef enum {
    CANDELA_MATERIAL_MODEL_GLTF = 0,     /* glTF 2.0 Appendix B + KHR_materials_* as specified */
    CANDELA_MATERIAL_MODEL_BLENDER3 = 1  /* Blender 3.4's Principled v1 as its glTF importer sets it up */
} CandelaMaterialModel;

struct CandelaIterationInfo;

#define CANDELA_DEFAULT_MIN_SPP 16

typedef struct CandelaOptions {
    const char *scene_path;
    const char *camera_name;   /* NULL: first camera, or a default view framing the scene */
    int width, height;         /* 0: from the camera's aspect (width 640) */
    /* --crop X0,Y0,X1,Y1 (crop[2] == 0: none, the whole image): render only the pixels
     * [X0, X1) x [Y0, Y1) of the width x height image. The camera and every pixel's rays and random
     * numbers are the full image's (a pixel's numbers are a function of the seed, its full-image
     * position and the sample: renderer/util/sequence.h); the image is the crop's size. */
    int crop[4];
    int spp;                   /* samples per pixel in total */
    uint64_t seed;
    int threads;               /* 0: all cores */
    int max_depth;             /* surface vertices of a path; 1 = direct light only */
    int max_volume_bounces;    /* scattering events in media per path (0: default) */
    int volume_emission_sampling; /* 1: emissive volumes are lights too (NEE, §4.3); 0: found by tracking only;
                                   * 2: auto (per volume, after a probe: volume_auto.c) */
    int volume_inscatter_sampling; /* --volume-cachepoint-scatter: in-scattering sampling along camera rays (§4.2): 0 off, 1 on,
                                    * 2 auto
                                    * (needs the cachepoints light sampler) */
    CandelaLightSampler light_sampler;
    CandelaLightUnits light_units;
    CandelaLightModel light_model; /* --light-model */
    CandelaMaterialModel material_model; /* --material-model */
    const char *env_path;      /* overrides the scene's extras; NULL: none */
    float env_strength;
    float env_rotation_deg;    /* --env-rotation: degrees about the vertical, Blender's sign; NaN: the scene's extras (else 0) */
    uint32_t batch_size;       /* paths in flight per batch; 0: default. Never changes the image. */
    int max_iteration_spp;     /* cap of the 1,1,2,4,... schedule; 0: default */
    int quiet;                 /* no progress output */
    int no_warnings;           /* --no-warnings: no "warning:" lines about the scene (what is read but not rendered) */
    int optimal_occlusion;     /* optimal sampler: one shadow ray per light per vertex */
    int cachepoint_no_visibility; /* cache points without visibility learning */
    int cachepoint_retruncate;    /* re-truncate blurred far bins (memory bound) */
    int cachepoint_build_linear;  /* 1: the paper's build (every light at every point); 0: a cut
                                   * through the light tree (the default) */
    uint32_t cachepoint_cut_size; /* cut build: far entries per point; 0: default */
    uint32_t cachepoint_max_near; /* near lights per point at most (CACHEPOINTS_MAX_NEAR); 0: default */
    int cachepoint_pooling;       /* 1: slots with too few attempts pool their neighbours' visibility counters;
                                   * 2: and then (cut build) their point's counters of nearby lights */
    uint32_t cachepoint_candidates; /* candidates in object boxes (§3.1.1); 0: scaled with the image */
    uint32_t cachepoint_pilots;     /* pilot paths (§3.1.1); 0: scaled with the image */
    int cachepoint_progressive;     /* --cachepoint-progressive: 0 the default, 1 on, 2 off (cachepoints/progressive.c) */
    float cachepoint_progressive_budget; /* --cachepoint-progressive-budget: inserted points / built points; 0: default */
    int cachepoint_bsdf;            /* --cachepoint-bsdf: 1 weigh entries by the glossy BSDF lobe at glossy vertices
                                     * (beyond the paper, §6), 0 the normal only */
    /* set non-zero (e.g. from a signal handler) to stop after the current batch (the rest of the
     * iteration is abandoned; with checkpoint_path its state is written): the image of the
     * samples done is returned and CandelaStats.interrupted set. NULL: never. */
    const volatile sig_atomic_t *stop;
    /* every file the scene references, and the scene, must lie inside this folder (NULL: the
     * default policy, files anywhere relative to the scene) */
    const char *confine_dir;
    uint32_t texture_budget_mb; /* decoded textures in total (8-bit files 4 B/texel, others 16); 0: no limit */
    uint32_t volume_budget_mb;  /* volume grids and the media built from them, in total; 0: no limit */
    CandelaGuiding guiding;
    CandelaSampler sampler;     /* --sampler */
    /* adaptive sampling (--noise-threshold; 0: off): at the first iteration barrier past min_spp
     * (the pilot) every pixel's sample count is fixed from its neighbours' pilot statistics, never
     * its own (film.c: unbiased); a pixel stops at the first barrier reaching it; spp stays the
     * upper bound */
    float noise_threshold;
    int min_spp;                /* --min-spp: the pilot, no pixel stops before it (0: CANDELA_DEFAULT_MIN_SPP) */
    double time_limit;          /* --time-limit S: stop at the first iteration barrier past S seconds of
                                 * the render's wall time, load included (0: none; the one option whose
                                 * image depends on the machine's speed) */
    /* --clamp-direct / --clamp-indirect (0: off): every contribution to a path's radiance is
     * scaled so that its largest channel is at most the limit (hue kept); direct: light that
     * reaches the camera through at most one scattering vertex, indirect: the rest (biased) */
    float clamp_direct, clamp_indirect;
    int aov_spp;                /* --aov spp: the samples each pixel got, as the EXR channel "spp" */
    const char *guide_dump_prefix; /* candela guide-dump: write the learned field at guide_dump_at */
    float guide_dump_at[3];
    /* guide-dump's files' provenance (software, command line, host, date; NULL: none): the
     * scene and its hash, the options, the position are added (renderer/integrator/guide.c) */
    const struct CandelaProvenance *guide_dump_provenance;
    float guide_spatial_threshold; /* PPG's c: a leaf splits past c sqrt(spp of the iteration); 0: default */
    float path_regularization;  /* gamma of path-space regularisation (ch. 1 §7; 0: off, 0.01: the course's) */
    int guide_spatial_filter;   /* Müller 2019's stochastic spatial box filter for training (0: off) */
    int guide_directional_filter; /* Müller 2019's directional box filter for training (1: on, the default) */
    float guide_bsdf_share;     /* the BSDF's share of guided MIS (default 0.5); 0: learned per leaf */
    float guide_min_bsdf_share; /* the smallest share a leaf learns (default 0.5) */
    float guide_caustic_threshold; /* the caustic guard's threshold (default 0: off; guiding/README.md) */
    float guide_caustic_share;  /* the BSDF share of a leaf the guard acts on (default 0.75) */
    float guide_caustic_defense; /* the guide's density toward delta scatterers over the BSDF's (default 1; 0: off) */
    CandelaGuideRoulette guide_roulette; /* --guide-roulette: the corrected throughput's (the default) or adjoint-driven */
    int guide_training_spp;     /* guiding trains on this many spp, then only renders; 0: default (spp / 8, at least 22) */
    int aov_recorder_debug;     /* --aov recorder-debug: the recorder's primary samples rebuild the image */
    int aov_selection;          /* --aov cachepoint: false colours of each first hit's cache point and its top entry */
    const char *cachepoint_dump_path; /* --dump-cachepoints FILE.ply: the points after the render (NULL: none) */
    uint32_t recorder_mb;       /* the radiance recorder's vertex storage bound; 0: default (256) */
    int recorder_budget;        /* vertices per path before skipping (path and vertex); 0: none; -1: default (4) */
    /* checkpoints (renderer/app/checkpoint.c): write the film and learned state to this file at the
     * barriers of the checkpoint-skipping schedule and when stopped (NULL: never) */
    const char *checkpoint_path;
    const char *resume_from;    /* continue the checkpoint in this file (NULL: start afresh) */
    /* --sample-shard I/N (shard_count 0: off): render only samples [spp I / N, spp (I + 1) / N)
     * of every pixel, with the full render's RNG streams, and write the film sums to film_path */
    uint32_t shard_index, shard_count;
    const char *film_path;
    /* called at every iteration barrier, after the barrier hooks (no ray in flight; candela
     * compare's convergence snapshots and equal-time stop); a non-zero return stops the render
     * there like `stop` (CandelaStats.interrupted). NULL: none. */
    int (*on_iteration)(void *user, const struct CandelaIterationInfo *info);
    void *on_iteration_user;
    /* what a checkpoint records beside the identity, for `--resume-from FILE` alone: the CLI's
     * `scene="..." output="..." png="..."|-` (absolute paths, renderer/app/options_table.h's string
     * form); NULL: nothing */
    const char *checkpoint_record;
} CandelaOptions;

/* What CandelaOptions.on_iteration is told at a barrier. */
typedef struct CandelaIterationInfo {
    int iteration;          /* 0-based index of the iteration just finished */
    int spp_done;           /* samples per pixel in the film so far */
    double seconds;         /* since candela_render started (scene load and build included) */
    int width, height;
    const void *film;       /* the film (opaque): read it with candela_iteration_mean */
} CandelaIterationInfo;

/* The film's mean radiance so far, 3 floats per pixel, top row first: exactly the values the
 * finished image would hold if the render stopped here. */
void candela_iteration_mean(const CandelaIterationInfo *info, float *rgb);

/* The render flags of the command line (renderer/app/flags.c): argv[*i] and, if it takes one, its
 * value. Returns 1 when it was a render flag (o set, *i on its last word), 0 when argv[*i] is
 * not a render flag (nothing changed), -1 on a missing or bad value (err: one line, no
 * program-name prefix). candela render and candela compare's variants share it. */
int candela_parse_render_flag(CandelaOptions *o, int argc, char *const *argv, int *i, char err[CANDELA_ERR_LEN]);
/* Combinations of render options that cannot work together: 0 ok, -1 with err. */
int candela_options_check(const CandelaOptions *o, char err[CANDELA_ERR_LEN]);

void candela_options_default(CandelaOptions *o);
/* "uniform", "power", "tree", "optimal", "cachepoints", "auto" */
const char *candela_light_sampler_name(CandelaLightSampler s);
const char *candela_sampler_name(CandelaSampler s); /* "sobol", "independent" */
int candela_light_sampler_parse(const char *name, CandelaLightSampler *s); /* 0 ok */

/* Times are wall-clock seconds measured on the calling thread, so that load + build + the
 * render's stages + other = total (other: what no stage covers, e.g. progress and checkpoint
 * writes; candela_stats_other_seconds). The wavefront stages (generate ... shadow) run
 * interleaved in one parallel region per batch: each gets the region's wall time in proportion
 * to the threads' time in it (so they add up to the region); learn (the recorder, guide
 * training and the auto probes after each batch), film and barrier (iteration barriers and
 * adaptive sampling's decisions) are serial phases. The threads' own per-stage times are in
 * stage_thread_seconds. */
/* The phases of a render from file to first image (issue 28), each with its wall seconds, the
 * render's peak resident memory by its end (so the phase that raised the peak is where it
 * grows; not reset between phases, render.c) and the resident memory at its end: parse (the glTF's
 * JSON and buffers read: tinygltf, and the loader's bulk pass over light nodes), flatten (the
 * rest of the loader: meshes, materials and textures, the node walk, lights), embree (the
 * render-time scene: Embree's mesh and top-level builds, camera, environment), lights (media
 * and the light list), sampler (the light sampler's build: the light tree, cache points) and
 * first_iteration (the first iteration's samples). A frame of a session (--frames) has no load
 * phases of its own. */
enum {
    CANDELA_PHASE_PARSE, CANDELA_PHASE_FLATTEN, CANDELA_PHASE_EMBREE, CANDELA_PHASE_LIGHTS, CANDELA_PHASE_SAMPLER,
    CANDELA_PHASE_FIRST_ITERATION, CANDELA_PHASES
};
const char *candela_phase_name(int phase);

typedef struct CandelaStats {
    double time_load, time_build, time_total;
    double phase_seconds[CANDELA_PHASES];
    size_t phase_peak_bytes[CANDELA_PHASES], phase_rss_bytes[CANDELA_PHASES];
    double time_generate, time_sort, time_trace, time_medium, time_shade, time_shadow, time_film;
    double time_learn, time_barrier;
    /* per-thread detail: seconds per stage (generate, sort, trace, medium, shade, shadow) each
     * batch's threads spent, averaged over the batch's threads and summed over batches (what
     * the summary showed before issue 27); stage_threads: the most threads a batch used */
    double stage_thread_seconds[6];
    int stage_threads;
    uint64_t rays_camera, rays_bounce, rays_shadow;
    uint64_t paths;
    int iterations;
    int spp_done;                 /* samples per pixel rendered (less than spp when interrupted) */
    int interrupted;              /* stopped after a batch by CandelaOptions.stop */
    int checkpoint_failed;        /* stopped, and the checkpoint of the stop could not be written */
    size_t peak_memory_bytes;
    uint32_t num_triangles, num_lights, num_instances;
    /* the scene's decoded textures (not the environment) as held, what --texture-budget-mb
     * counts: 8-bit files at 4 bytes per texel, the others at 16 */
    uint32_t num_textures, num_textures_8bit;
    uint64_t texture_bytes;
    CandelaLightSampler light_sampler_used; /* the strategy that ran (what `auto` chose; optimal
                                             * when cache points fell back, §3.1.1) */
    double time_cachepoints;       /* cache point build (inside time_build) */
    double cpu_cachepoints;        /* its CPU seconds, all threads (steadier on a busy machine) */
    uint32_t num_cachepoints, cachepoint_candidates;
    size_t cachepoint_bytes;
    double cachepoint_mean_near, cachepoint_mean_far, cachepoint_mean_clusters; /* entries per point */
    uint32_t cachepoints_inserted;   /* of num_cachepoints, inserted between iterations (progressive) */
    double time_cachepoint_insertion, cpu_cachepoint_insertion; /* their scoring and rebuilds, at the barriers */
    uint32_t num_volumes;
    uint64_t volume_bytes;        /* the volume grids and their media's majorant and emission grids (--volume-budget-mb) */
    uint64_t volume_collisions;   /* majorant collisions the media trackers evaluated */
    uint64_t volume_capped_walks; /* tracker calls stopped at their collision cap (a bad medium) */
    /* the radiance recorder (when guiding or its debug AOV is on) */
    size_t recorder_peak_bytes, recorder_bound_bytes;
    uint32_t recorder_peak_vertices;
    uint64_t recorder_vertices, recorder_samples, recorder_refused, recorder_paths;
    float recorder_path_skip;     /* the last iteration's path skipping probability */
    /* path guiding */
    int guide_updates, guide_dropped;
    double guide_train_seconds;   /* recording samples into the fields and updating them */
    uint64_t guide_samples;
    uint32_t guide_leaves;
    size_t guide_bytes;
#define CANDELA_GUIDE_SHARES 7
    float guide_share_value[CANDELA_GUIDE_SHARES]; /* the BSDF shares a guiding leaf can hold, and */
    uint32_t guide_share_leaves[CANDELA_GUIDE_SHARES]; /* how many hold each at the end (--guide-bsdf-share) */
    int guide_share_per_leaf;     /* 1: guided MIS chose shares per leaf (learned, or the caustic guard) */
    int guide_auto;              /* --guiding auto: 1 chose guiding, 0 chose off, -1 not auto or undecided */
    float guide_auto_ratio;      /* its predicted time-to-unit-variance ratio, guided / unguided */
    float guide_auto_indirect;   /* the probe's share of the relative variance in light of two or more bounces */
    /* samples per pixel over the image (they differ with adaptive sampling, and after an
     * interruption within an iteration): the smallest, the mean, and how many pixels got
     * [2^k, 2^(k+1)) samples (k = 0..20) */
    int spp_min;
    double spp_mean;
    uint32_t spp_histogram[21];
    int spp_dropped;                 /* samples per pixel rendered but not in the image: path guiding's
                                      * unguided bootstrap, dropped once guided samples followed */
    uint32_t adaptive_active_pixels; /* adaptive sampling: pixels still sampling at the end (0: all stopped) */
    int image_width, image_height;   /* the resolved resolution (the full image's with --crop) */
    int time_limited;                /* --time-limit stopped the render before --spp */
} CandelaStats;

/* Wall seconds of the render's stages (the wavefront stages, learn, film and barrier). */
static inline double candela_stats_render_seconds(const CandelaStats *s) {
    return s->time_generate + s->time_sort + s->time_trace + s->time_medium + s->time_shade + s->time_shadow +
           s->time_learn + s->time_film + s->time_barrier;
}
/* The rest of the total: total - load - build - the render's stages (never negative). */
static inline double candela_stats_other_seconds(const CandelaStats *s) {
    double o = s->time_total - s->time_load - s->time_build - candela_stats_render_seconds(s);
    return o > 0.0 ? o : 0.0;
}

/* The film after the render: per-pixel mean and AOVs, top row first. */
typedef struct CandelaImage {
    int width, height;
    /* where the image lies in the full image (--crop): its top-left pixel and the full image's
     * size (crop_x = crop_y = 0 and full_* = width, height without a crop; full_width 0: not
     * known, e.g. a merged image) */
    int crop_x, crop_y, full_width, full_height;
    float *rgb;       /* 3 per pixel, mean radiance */
    float *variance;  /* 3 per pixel, variance of the pixel mean (sample variance / n) */
    float *albedo;    /* 3 per pixel, first-hit albedo */
    float *normal;    /* 3 per pixel, first-hit shading normal (world) */
    float *depth;     /* 1 per pixel, first-hit distance along the camera ray (inf: miss) */
    float *recorder_debug; /* 3 per pixel with --aov recorder-debug (else NULL): the recorder's
                            * primary training samples times their throughput, plus what the
                            * camera ray found itself; converges to rgb */
    float *selection_point;  /* 3 per pixel with --aov cachepoint (else NULL): the mean false colour of
                              * the cache point each first hit used (black: none, e.g. a miss) */
    float *selection_light;  /* 3 per pixel with --aov cachepoint: that of the entry it weighed most */
    float *spp;              /* 1 per pixel with --aov spp (else NULL): the samples the pixel got */
} CandelaImage;

/* Every ray a render traced, for the bare-Embree replay of `candela bench`: at most
 * CANDELA_RAY_LOG_MAX rays (29 bytes each, 58 GiB; past it, or when memory runs out, `failed`). */
#define CANDELA_RAY_LOG_MAX ((size_t)1 << 31)
typedef struct CandelaRayLog {
    size_t count, capacity;
    float *org_dir_tfar;   /* 7 floats per ray: ox oy oz dx dy dz tfar */
    uint8_t *is_shadow;
    int failed;            /* out of memory: the log is incomplete and must not be used */
} CandelaRayLog;

/* ray_log (may be NULL): receives every traced ray (the benchmark). */
int candela_render(const CandelaOptions *o, CandelaImage *image, CandelaStats *stats,
                   CandelaRayLog *ray_log, char err[CANDELA_ERR_LEN]);
void candela_image_free(CandelaImage *image);
void candela_ray_log_free(CandelaRayLog *log);

/* Writes the EXR (RGBA + albedo, N, Z, variance layers) and, if png_path != NULL, an sRGB
 * preview. Both go to a temporary name first and are renamed when complete. */
int candela_write_outputs(const CandelaImage *image, const char *exr_path, const char *png_path,
                          char err[CANDELA_ERR_LEN]);
/* Linear radiance -> the preview's display value in [0, 1]: clipped and sRGB-encoded (Blender's
 * "Standard"). The one sRGB encoder: the PNG preview and candela compare's report use it. */
float candela_srgb_encode(float linear);

/* ---------------------------------------------------------------- identity
 * What an image is a function of (issue 27): "scene=HASH" (FNV-1a 64 of the scene file's
 * bytes, hex), every option the options table marks as changing the image (NAME=VALUE, the
 * table's canonical form, --res the resolved resolution) and "max-iteration-spp=N", separated
 * by spaces. Checkpoints and shard films carry it, --frames --resume compares a frame's
 * candela:identity EXR attribute with it, candela compare keys its cached reference on it. */
#define CANDELA_IDENTITY_LEN 8192
/* FNV-1a 64 of a scene file's bytes. -1 with a message when it cannot be read. */
int candela_scene_hash(const char *scene_path, uint64_t *hash, char err[CANDELA_ERR_LEN]);
/* o's identity for a scene of hash scene_hash rendered at width x height into buf. -1 when it
 * does not fit size (a very long camera or --env name). */
int candela_image_identity(const CandelaOptions *o, uint64_t scene_hash, int width, int height, char *buf, size_t size);
/* A checkpoint's or shard film's header (verified: checksum, format version). */
typedef struct CandelaCheckpointInfo {
    int kind;                 /* 1 checkpoint, 2 finished shard film */
    int width, height;
    int spp_done;
    unsigned shard_index, shard_count; /* --sample-shard (0/1: none) */
    char identity[CANDELA_IDENTITY_LEN];
    char record[16384];       /* CandelaOptions.checkpoint_record as written ("" when none) */
} CandelaCheckpointInfo;
int candela_checkpoint_info(const char *path, CandelaCheckpointInfo *info, char err[CANDELA_ERR_LEN]);

/* ---------------------------------------------------------------- provenance
 * How an image was made (renderer/app/provenance.c; README "Output"): string attributes written
 * into the EXR's header (and the statistics JSON's "provenance" object). The CLI fills one per
 * run: candela_provenance_begin (software, candela:commandLine, candela:host, capDate),
 * candela_provenance_scene (candela:scene, candela:sceneHash), candela_provenance_render after
 * each render (candela:options and the render's results). Setting a name again replaces it. */
typedef struct CandelaAttribute {
    const char *name;
    const char *value;
} CandelaAttribute;
#define CANDELA_PROVENANCE_MAX 24
typedef struct CandelaProvenance {
    int count;
    CandelaAttribute attrs[CANDELA_PROVENANCE_MAX]; /* names are literals, values owned */
} CandelaProvenance;
/* software: the --version line ("candela 0.1.0 (git REV)"); argv joined, shell-quoted where
 * needed. 0 ok, -1 out of memory. */
int candela_provenance_begin(CandelaProvenance *p, const char *software, int argc, char *const *argv);
/* the scene path as given and the FNV-1a 64 of its bytes (16 hex digits); -1 with err */
int candela_provenance_scene(CandelaProvenance *p, const char *scene_path, char err[CANDELA_ERR_LEN]);
/* candela:options (every render option of the options table, as one JSON object, defaults
 * included), candela:lightSamplerUsed, :sppDone, :seed, :sampler, :renderSeconds,
 * :peakMemoryBytes. 0 ok, -1 out of memory. */
int candela_provenance_render(CandelaProvenance *p, const CandelaOptions *o, const CandelaStats *s);
int candela_provenance_set(CandelaProvenance *p, const char *name, const char *value);
/* candela:identity: o's image identity at width x height (candela_image_identity) with the
 * scene hash candela_provenance_scene recorded (none without it); -1 out of memory. */
int candela_provenance_identity(CandelaProvenance *p, const CandelaOptions *o, int width, int height);
/* dst (uninitialised) = a copy of src; 0 ok, -1 out of memory (dst then empty) */
int candela_provenance_copy(CandelaProvenance *dst, const CandelaProvenance *src);
void candela_provenance_free(CandelaProvenance *p);
/* The render options as one JSON object {"spp": 16, "light-sampler": "auto", ...}: every render
 * option row of renderer/app/options_table.c by its flag name (malloc'd; NULL out of memory). */
char *candela_options_json(const CandelaOptions *o);
/* A JSON string literal of s, escaped by io_json_quote (nlohmann/json: quotes, backslashes and
 * control characters escaped, invalid UTF-8 replaced); "null" when out of memory. */
void candela_json_string(FILE *f, const char *s);
/* candela_write_outputs with the EXR header's provenance (NULL: none). */
int candela_write_outputs_provenance(const CandelaImage *image, const char *exr_path, const char *png_path,
                                     const CandelaProvenance *provenance, char err[CANDELA_ERR_LEN]);
/* With --aov cachepoint, the PNGs beside the preview: png_path NAME.png -> NAME.cachepoint.png
 * and NAME.cachepoint_light.png (out: IO_PATH_MAX bytes each). */
void candela_cachepoint_png_paths(const char *png_path, char *point_png, char *light_png, size_t len);

/* Replays a ray log through bare Embree on the scene (closest hit for bounce rays,
 * occlusion for shadow rays); returns the seconds spent tracing. */
int candela_replay_rays(const CandelaOptions *o, const CandelaRayLog *log, int threads,
                        double *seconds, char err[CANDELA_ERR_LEN]);

/* ---------------------------------------------------------------- a run's files
 * One rule for every output of a run (renderer/app/runfiles.c; README "Inputs and outputs"): it may
 * not be an input of the same run (the scene, any file the scene references, --env,
 * --resume-from, the films being merged, --variants, --reference, a variant's --env) nor another
 * output of it, and every output's lock file (OUTPUT.lock, emptied and removed by the run) counts
 * as an output too. Paths are compared by the file they name (device and inode, or the real folder
 * and name of a file not there yet). The commands record every input and output before any
 * work; the first clash is one line in err ("PATH: the PNG preview (--png) would replace the
 * scene, an input of this run"). role names the file in that message. */
typedef struct CandelaRunFile CandelaRunFile;
typedef struct CandelaRunFiles {
    CandelaRunFile *files;
    int count, capacity;
} CandelaRunFiles;
int candela_run_input(CandelaRunFiles *r, const char *path, const char *role, char err[CANDELA_ERR_LEN]);
/* the scene and every file it references (io_gltf_references) */
int candela_run_scene(CandelaRunFiles *r, const char *scene_path, char err[CANDELA_ERR_LEN]);
int candela_run_output(CandelaRunFiles *r, const char *path, const char *role, char err[CANDELA_ERR_LEN]);
/* candela_run_output for an output that continues an input and may replace it (--checkpoint
 * over the --resume-from checkpoint it continues: written atomically, after it was read) */
int candela_run_output_continuing(CandelaRunFiles *r, const char *path, const char *role, const char *continued,
                                  char err[CANDELA_ERR_LEN]);
/* the check of candela_run_output without recording the output (a frame's names) */
int candela_run_check_output(const CandelaRunFiles *r, const char *path, const char *role, char err[CANDELA_ERR_LEN]);
void candela_run_files_free(CandelaRunFiles *r);

/* candela compare: every variant at equal spp (or equal time) against a reference, and a
 * report folder (renderer/app/compare.c, renderer/app/report.c). */
typedef struct CandelaCompareOptions {
    const char *strategies;      /* comma-separated, e.g. "uniform,power,tree,optimal"; NULL: the default list */
    int reference_spp;           /* 0: 16 x spp */
    const char *reference_path;  /* reuse this EXR instead of rendering a reference */
    const char *out_dir;
    int optimal_max_lights;      /* skip `optimal` above this many lights (0: never skip) */
    int timing_runs;             /* renders per strategy for the median time (1..15; 0 = 1) */
    /* "NAME: FLAGS; NAME: FLAGS" or a FILE.toml / FILE.json (io_read_variants): any render
     * flags per variant; NULL: `strategies` (each NAME stands for --light-sampler NAME) */
    const char *variants;
    double time_budget;          /* > 0: equal time, every variant renders until this many seconds */
    /* the run's inputs and outputs so far (the scene's, --reference's, --variants'): the report's
     * files and the variants' own inputs are added and checked before anything renders; NULL: none */
    CandelaRunFiles *run;
    /* the build, for the cached reference's key: the CLI's "candela VERSION (git REV)" (NULL:
     * the version alone); the running binary's size and time are added to it */
    const char *build;
    /* the run's provenance (candela_provenance_begin: software, command line, host, date): each
     * rendered image (EXR, PNG, error PNG) gets it with the scene and its hash, its own render's
     * options and statistics and candela:compareVariant (its name; "reference"); NULL: none */
    const CandelaProvenance *provenance;
} CandelaCompareOptions;

int candela_compare(const CandelaOptions *base, const CandelaCompareOptions *c, char err[CANDELA_ERR_LEN]);
/* 1 when --variants SPEC names a file: it ends in .toml or .json and either has no ':' or a file
 * of that name exists (so an inline "a: --env sky.json" stays inline) */
int candela_variants_is_file(const char *spec);

/* candela merge: the finished films of the N sample shards of one render (any order) into the
 * EXR (and PNG preview unless NULL): sums of L and L^2, counts and AOV sums added in shard order,
 * then the mean and variance of the mean per pixel. Refuses films of different renders, a
 * shard twice or missing, ranges that do not tile the samples. 0 ok, -1 with a one-line message. */
int candela_merge(const char *out_exr, const char *png, const char *const *files, int num_files,
                  char err[CANDELA_ERR_LEN]);
/* candela_merge with the merged EXR's provenance (NULL: none) */
int candela_merge_provenance(const char *out_exr, const char *png, const char *const *files, int num_files,
                             const CandelaProvenance *provenance, char err[CANDELA_ERR_LEN]);

/* provenance (NULL: none): its attributes as the object "provenance" (candela:options as an
 * object, the others as strings) */
int candela_write_stats_json(const char *path, const CandelaOptions *o, const CandelaStats *s,
                             const CandelaProvenance *provenance, char err[CANDELA_ERR_LEN]);
/* The same statistics as one line of JSON (no newline), malloc'd into *json; 0 ok. */
int candela_stats_json_line(const CandelaOptions *o, const CandelaStats *s, char **json);

/* ---------------------------------------------------------------- animation frames
 * A session loads a scene once and renders it at many animation times (renderer/app/render.c):
 * meshes, textures and volume grids load once; per frame the scene is posed (instance
 * transforms, Embree's top-level scene), and media, lights and the light sampler (cache
 * points) are rebuilt for that pose. A session frame at time t renders exactly what a fresh
 * session's first frame at t renders. */
typedef struct CandelaSession CandelaSession;
typedef struct CandelaSessionInfo {
    double time_load;             /* seconds to load the scene */
    uint32_t num_channels;        /* animation channels (0: a still scene) */
    double anim_start, anim_end;  /* the animation's first and last key time, seconds */
    int width, height;            /* the frames' resolution (the full image's, with --crop) */
    int image_width, image_height; /* the frames' images' size: the crop's with --crop, else width x height */
} CandelaSessionInfo;
typedef struct CandelaFrameInfo {
    double time_pose;             /* posing the scene and updating Embree (inside stats time_load) */
    uint32_t instances_moved;     /* instances whose transform changed since the previous frame */
} CandelaFrameInfo;
int candela_session_open(const CandelaOptions *o, CandelaSession **session, CandelaSessionInfo *info,
                         char err[CANDELA_ERR_LEN]);
/* Renders the session's scene posed at `seconds`. o must name the session's scene (its seed,
 * spp, ... may differ per frame). A failure (a transform the scene cannot take at that time,
 * out of memory) leaves the session usable for other frames. */
int candela_session_render(CandelaSession *session, const CandelaOptions *o, double seconds, CandelaImage *image,
                           CandelaStats *stats, CandelaFrameInfo *frame, char err[CANDELA_ERR_LEN]);
void candela_session_close(CandelaSession *session);

/* The seed of frame f: splitmix64's output for the state seed + (f + 1) * 0x9E3779B97F4A7C15,
 * i.e. the (f + 1)-th number of the splitmix64 stream seeded with --seed (README "Animation"). */
uint64_t candela_frame_seed(uint64_t seed, int64_t frame);

/* candela render --frames (renderer/app/batch.c). */
typedef struct CandelaBatchOptions {
    const char *frames;       /* "A-B[:step]" or a comma list of frames and ranges */
    double fps;               /* frame f is time f / fps (default 24) */
    const char *shard;        /* "I/N" (I in 0..N-1, round-robin); NULL: SLURM_ARRAY_* or the whole list */
    const char *exr_pattern;  /* output name with a run of '#' replaced by the zero-padded frame number */
    const char *png_pattern;  /* the same for the PNG preview; NULL: none */
    const char *stats_jsonl;  /* one JSON line per frame appended here; NULL: none */
    int resume;               /* skip frames whose EXR (and PNG, when asked) exist */
    int save_partial;         /* an interrupted frame is written under a .partial name */
    int dry_run;              /* check the request, print "shard I/N" and "frame F EXR" per frame of
                               * this task to stdout, load and render nothing (returns 0) */
    /* the run's inputs and outputs (scene, --env, --frame-stats): every frame's names are checked
     * against them before the first frame renders; NULL: none */
    const CandelaRunFiles *run;
    /* every frame's EXR header: this, with each frame's render attributes (NULL: none) */
    const CandelaProvenance *provenance;
} CandelaBatchOptions;
/* Renders the frames. Returns -1 on an error before any frame was rendered (bad frame list,
 * shard, pattern, scene, a frame outside the animation: err says what; nothing written), else
 * the number of frames that failed (each reported on stderr with its number; the batch goes
 * on), with *interrupted set when a signal (o->stop) stopped it. */
int candela_batch_render(const CandelaOptions *o, const CandelaBatchOptions *b, int *interrupted,
                         char err[CANDELA_ERR_LEN]);

#endif
