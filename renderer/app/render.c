/* renderer/app/render.c: candela_render(), a render from file to film.
 *
 *   scene_load -> media_build -> lights_build -> light_sampler_create (on the thread pool) -> for each
 *   iteration (spp schedule 1, 1, 2, 4, 8, ... capped, summing to --spp): for each batch of
 *   paths, integrator_run_batch (waves, film) -> the iteration barrier (no ray in flight:
 *   the barrier hooks run, then progress is reported) -> film_resolve.
 * Path j of an iteration is pixel j % npixels, sample base + j / npixels, so batches are
 * contiguous runs of j and the film receives every pixel's samples in sample order whatever
 * the batch size or thread count: the image is bit-identical across both. */
#include <stdio.h>
#include <stdlib.h>
#ifdef __GLIBC__
#include <malloc.h>
#endif
#include <string.h>
#include <sys/resource.h>
#include <unistd.h>

#include "checkpoint.h"
#include "clock.h"
#include "feature.h"

/* The default batch gives each thread a slice of this many paths. Shading visits the slice's
 * path state in hit order, i.e. in random slot order: at ~150 bytes of state read or written
 * per path, 2,048 paths stay in a 1 MiB L2 cache with room for the scene data (8,192 did not:
 * scenes/bench.gltf, 2 threads, shade stage 2.7 s at 2,048 per thread against 3.5 s at 8,192) */
#define DEFAULT_PATHS_PER_THREAD 2048u
#define MAX_BATCH_SIZE (1u << 22)
#define DEFAULT_MAX_ITERATION_SPP 64
#define TRAIN_MAX_ITERATION_SPP 16


/* ---------------------------------------------------------------- progress */

typedef struct Progress {
    int quiet, is_tty;
    double start, last;
} Progress;

static void report_progress(Progress *pr, uint64_t done, uint64_t total, int final) {
    if (pr->quiet) return;
    double t = clock_seconds();
    double elapsed = t - pr->start;
    double frac = total ? (double)done / (double)total : 1.0;
    double eta = frac > 0.0 ? elapsed * (1.0 - frac) / frac : 0.0;
    if (pr->is_tty) {
        if (!final && t - pr->last < 0.2) return;
        pr->last = t;
        int width = 40, filled = (int)(frac * width);
        char bar[64];
        for (int i = 0; i < width; ++i) bar[i] = i < filled ? '#' : '-';
        bar[width] = 0;
        fprintf(stderr, "\r[%s] %5.1f%%  %6.1fs elapsed  ETA %6.1fs", bar, 100.0 * frac, elapsed, eta);
        if (final) fputc('\n', stderr);
        fflush(stderr);
    } else {
        if (!final && t - pr->last < 10.0) return;
        pr->last = t;
        fprintf(stderr, "candela: %5.1f%% done, %.1fs elapsed, ETA %.1fs\n", 100.0 * frac, elapsed, eta);
    }
}

/* ---------------------------------------------------------------- peak memory */

/* Peak resident memory of this render. Linux lets a process reset its high-water mark
 * (write "5" to /proc/self/clear_refs), so renders run one after another in one process
 * (candela compare, the tests) each report their own peak; elsewhere getrusage's lifetime
 * maximum is the fallback. */
static void peak_rss_reset(void) {
#ifdef __GLIBC__
    malloc_trim(0); /* hand the previous render's freed heap back first, or it counts here */
#endif
    FILE *f = fopen("/proc/self/clear_refs", "w");
    if (f) { fputs("5", f); fclose(f); }
}

static size_t peak_rss_bytes(void) {
    FILE *f = fopen("/proc/self/status", "r");
    if (f) {
        char line[256];
        size_t kb = 0;
        while (fgets(line, sizeof line, f))
            if (sscanf(line, "VmHWM: %zu kB", &kb) == 1) break;
        fclose(f);
        if (kb > 0) return kb * 1024u;
    }
    struct rusage ru;
    if (getrusage(RUSAGE_SELF, &ru) != 0) return 0;
    return (size_t)ru.ru_maxrss * 1024u;
}

/* Resident memory now (VmRSS), 0 where /proc is not there. */
static size_t rss_bytes(void) {
    FILE *f = fopen("/proc/self/status", "r");
    size_t kb = 0;
    if (f) {
        char line[256];
        while (fgets(line, sizeof line, f))
            if (sscanf(line, "VmRSS: %zu kB", &kb) == 1) break;
        fclose(f);
    }
    return kb * 1024u;
}

/* Phases (candela.h, CANDELA_PHASE_*): the high-water mark is read, never reset, between
 * phases: a reset would also lower what the kernel reports as the process's maximum resident
 * size at exit (/usr/bin/time, getrusage of a child), which the acceptance is measured
 * with. So a phase's peak is the render's peak so far, and the phase that raised it is the one
 * where it grows; the resident size at its end is beside it. */
void phase_mark(ScenePhases *p, int phase) {
    double now = clock_seconds();
    p->seconds[phase] += now - p->t;
    p->rss[phase] = rss_bytes(); /* first: the high-water mark read after it is at least it */
    p->peak[phase] = peak_rss_bytes();
    p->t = now;
}

const char *candela_phase_name(int phase) {
    static const char *const names[CANDELA_PHASES] = {"parse", "flatten", "embree", "lights", "sampler",
                                                      "first_iteration"};
    return phase >= 0 && phase < CANDELA_PHASES ? names[phase] : "?";
}

/* ---------------------------------------------------------------- render */

static void light_sampler_barrier_hook(void *sampler) { light_sampler_barrier(sampler); }

/* Adaptive sampling: the next iteration's pixels, those the film has not stopped (in pixel
 * order, so every pixel still gets its samples in sample order). */
static void update_pixel_list(Integrator *ig) {
    if (!ig->pixel_list) return;
    uint32_t n = 0;
    for (uint32_t i = 0; i < ig->npixels; ++i)
        if (!ig->film.stopped[i]) ig->pixel_list[n++] = i;
    ig->iteration_pixels = n;
}

/* The samples per pixel the film holds: smallest, mean, power-of-two histogram. */
static void spp_statistics(const Film *f, CandelaStats *st) {
    size_t n = (size_t)f->width * (size_t)f->height;
    uint64_t total = 0;
    uint32_t lo = UINT32_MAX;
    memset(st->spp_histogram, 0, sizeof st->spp_histogram);
    for (size_t i = 0; i < n; ++i) {
        uint32_t c = f->count[i];
        total += c;
        if (c < lo) lo = c;
        int k = 0;
        while (k < 20 && (c >> (k + 1)) != 0) ++k;
        if (c) st->spp_histogram[k]++;
    }
    st->spp_min = n ? (int)lo : 0;
    st->spp_mean = n ? (double)total / (double)n : 0.0;
    st->spp_dropped = (int)f->dropped;
}

/* Samples per pixel of iteration i: 1, 1, 2, 4, 8, ... capped, and never past the total. (The
 * shift is bounded: at iteration 32 an unbounded 1 << 31 overflowed and the schedule ran
 * backwards.) A feature's training schedule (features_schedule_start; path guiding's, ch. 2
 * §5.2), from iteration train_from on (-1: none): 8 x 1 spp while it trains, then 2, 4, 8, ...
 * capped at its own maximum. */
static int iteration_spp(int iteration, int max_iteration_spp, int max_train_spp, int remaining, int train_from) {
    int training = train_from >= 0 && iteration >= train_from;
    int first = training ? train_from + 8 : 2; /* the iterations of 1 spp end here */
    int cap = training ? max_train_spp : max_iteration_spp;
    int k = iteration - first + 1;
    int spp = iteration < first ? 1 : (k >= 30 ? cap : 1 << k);
    if (spp > cap) spp = cap;
    return spp < remaining ? spp : remaining;
}

typedef struct Render {
    Scene scene;
    Lights lights;
    SceneMedia media;
    LightSampler sampler;
    ThreadPool *pool;
    Integrator ig;
    int have_scene, have_lights, have_media, have_sampler, have_integrator;
    int warned_unlit; /* "no lights and no environment" said once per session */
    ScenePhases phases; /* this render's (or frame's) phase clock (candela.h, CANDELA_PHASE_*) */
} Render;

/* What one frame builds from the (posed) scene: media, lights, light sampler, integrator. The
 * scene, its Embree device and the thread pool outlive it (a frame batch renders many). */
static void render_free_frame(Render *r) {
    if (r->have_integrator) integrator_free(&r->ig);
    if (r->have_sampler) light_sampler_free(&r->sampler);
    if (r->have_media) media_free(&r->media);
    if (r->have_lights) lights_free(&r->lights);
    r->have_integrator = r->have_sampler = r->have_media = r->have_lights = 0;
}

static void render_free(Render *r) {
    render_free_frame(r);
    if (r->pool) threadpool_destroy(r->pool);
    if (r->have_scene) scene_free(&r->scene);
    free(r);
}

static int render_options_valid(const CandelaOptions *o, char err[CANDELA_ERR_LEN]) {
    if (o->spp < 1 || o->max_depth < 0 || o->max_volume_bounces < 0 || o->width < 0 || o->height < 0 || o->width > 16384 || o->height > 16384) {
        snprintf(err, CANDELA_ERR_LEN, "%s: invalid render options (spp >= 1, 0 <= max depth and volume bounces, resolution <= 16384)",
                 o->scene_path ? o->scene_path : "candela");
        return 0;
    }
    return 1;
}

/* One render of the loaded scene as it is placed now: media -> lights -> light sampler ->
 * integrator -> iterations -> film. Frees what it built (render_free_frame) before it returns;
 * t_start is when the caller started (load or pose), for time_load and time_total. */
static int render_frame(Render *r, const CandelaOptions *o, CandelaImage *image, CandelaStats *stats,
                        CandelaRayLog *ray_log, double t_start, char err[CANDELA_ERR_LEN]) {
    /* --sample-shard I/N: this render is samples [sample_begin, sample_begin + spp) of every pixel
     * of the full render (with its RNG streams), and learns from those alone: a render of that
     * many spp whose sample indices start at sample_begin (`ro` is what the integrator sees). */
    CandelaOptions ro = *o;
    uint64_t sample_begin = 0;
    if (o->shard_count) {
        uint64_t b = (uint64_t)o->spp * o->shard_index / o->shard_count;
        uint64_t e = (uint64_t)o->spp * (o->shard_index + 1) / o->shard_count;
        if (o->shard_index >= o->shard_count || e == b) {
            snprintf(err, CANDELA_ERR_LEN, "%s: sample shard %u/%u of %d spp is empty (shards need at least one sample each)",
                     o->scene_path, o->shard_index, o->shard_count, o->spp);
            render_free_frame(r);
            return -1;
        }
        sample_begin = b;
        ro.spp = (int)(e - b);
    }
    const CandelaOptions *given = o; /* the identity names the full render */
    o = &ro;
    /* the render's identity, and a checkpoint to resume checked against it before anything is built */
    CheckpointIdentity identity;
    int use_identity = o->checkpoint_path || o->resume_from || o->film_path;
    if (use_identity) {
        if (checkpoint_identity(given, r->scene.camera.width, r->scene.camera.height, sample_begin, (uint64_t)o->spp,
                                &identity, err) != 0 ||
            (o->resume_from && checkpoint_check(o->resume_from, &identity, err) != 0)) {
            render_free_frame(r);
            return -1;
        }
    }
    /* what a feature cannot do with this scene, said before anything is built */
    if (features_validate(o, &r->scene, err) != 0) {
        render_free_frame(r);
        return -1;
    }
    if (media_build(&r->media, &r->scene, o->scene_path, (uint64_t)o->volume_budget_mb << 20, err) != 0) {
        render_free_frame(r);
        return -1;
    }
    r->have_media = 1;
    if (lights_build(&r->lights, &r->scene, o->volume_emission_sampling ? &r->media : NULL, o->light_units, err,
                     CANDELA_ERR_LEN) != 0) {
        render_free_frame(r);
        return -1;
    }
    r->have_lights = 1;
    phase_mark(&r->phases, CANDELA_PHASE_LIGHTS);
    if (r->lights.count == 0 && !o->no_warnings && !r->warned_unlit) {
        fprintf(stderr, "%s: warning: the scene has no lights and no environment (no punctual light, no emissive "
                        "material, no --env or candela_environment): the image is black\n", o->scene_path);
        r->warned_unlit = 1;
    }
    double t_loaded = clock_seconds();
    stats->time_load = t_loaded - t_start;
    stats->num_triangles = r->scene.num_triangles_total;
    stats->num_lights = r->lights.count;
    stats->num_instances = r->scene.io.num_instances;
    stats->num_textures = r->scene.io.num_images;
    for (uint32_t i = 0; i < r->scene.io.num_images; ++i) {
        stats->texture_bytes += io_image_bytes(&r->scene.io.images[i]);
        if (r->scene.io.images[i].rgba8) ++stats->num_textures_8bit;
    }
    stats->num_volumes = r->media.num_vdb;
    stats->volume_bytes = r->media.bytes;

    const Camera *cam = &r->scene.camera;
    uint32_t npixels = (uint32_t)cam->crop_width * (uint32_t)cam->crop_height; /* the film's: the crop's with --crop */
    stats->image_width = cam->width;
    stats->image_height = cam->height;
    if (!r->pool) r->pool = threadpool_create(o->threads);
    if (!r->pool) { snprintf(err, CANDELA_ERR_LEN, "candela: out of memory"); render_free_frame(r); return -1; }
    uint64_t batch64 = o->batch_size ? o->batch_size : (uint64_t)DEFAULT_PATHS_PER_THREAD * (uint64_t)threadpool_size(r->pool);
    uint32_t batch = batch64 > MAX_BATCH_SIZE ? MAX_BATCH_SIZE : (uint32_t)batch64;
    uint64_t max_paths_per_iteration = (uint64_t)npixels * (uint64_t)o->spp;
    if (batch > max_paths_per_iteration) batch = (uint32_t)max_paths_per_iteration;
    if (light_sampler_create(&r->sampler, &r->lights, &r->scene, &r->media, r->pool, o, err) != 0) {
        render_free_frame(r);
        return -1;
    }
    r->have_sampler = 1;
    light_sampler_report(&r->sampler, stats);
    if (integrator_init(&r->ig, o, &r->scene, &r->lights, &r->media, &r->sampler, batch) != 0) {
        snprintf(err, CANDELA_ERR_LEN, "%s: out of memory allocating the %dx%d film and %u paths in flight",
                 o->scene_path, cam->crop_width, cam->crop_height, batch);
        render_free_frame(r);
        return -1;
    }
    r->have_integrator = 1;
    Integrator *ig = &r->ig;
    ig->ray_log = ray_log;
    ig->pool = r->pool;
    if (light_sampler_has_barrier(&r->sampler) && integrator_add_barrier_hook(ig, light_sampler_barrier_hook, &r->sampler) != 0) {
        snprintf(err, CANDELA_ERR_LEN, "%s: internal error: too many barrier hooks", o->scene_path);
        render_free_frame(r);
        return -1;
    }
    update_pixel_list(ig); /* adaptive sampling: every pixel to begin with */
    stats->time_build = clock_seconds() - t_loaded;
    phase_mark(&r->phases, CANDELA_PHASE_SAMPLER);

    Progress progress = {o->quiet, isatty(2), clock_seconds(), 0.0}; /* the first report comes at once */
    int max_iter_spp = o->max_iteration_spp > 0 ? o->max_iteration_spp : DEFAULT_MAX_ITERATION_SPP;
    /* a feature's schedule: smaller iterations, so what it learns updates often (ch. 2 §5.2) */
    int max_train_spp = o->max_iteration_spp > 0 ? o->max_iteration_spp : TRAIN_MAX_ITERATION_SPP;
    uint64_t total_paths = (uint64_t)npixels * (uint64_t)o->spp, done_paths = 0;
    CheckpointProgress at = {0, 0, 0}; /* where the render stands (a resumed one: where the checkpoint stood) */
    if (o->resume_from) {
        if (checkpoint_load(o->resume_from, &identity, &at, ig, &r->sampler, err) != 0) {
            render_free_frame(r);
            return -1;
        }
        /* the progress must be a point of this render's schedule (the checksum guards the bytes;
         * this guards a file written by a build with another schedule) */
        update_pixel_list(ig); /* adaptive sampling: the pixels the checkpoint's film still samples */
        int cumulative = 0, k = 0;
        for (; k < at.iteration && cumulative < o->spp; ++k)
            cumulative += iteration_spp(k, max_iter_spp, max_train_spp, o->spp - cumulative, features_schedule_start(ig));
        uint64_t iteration_total =
            (uint64_t)ig->iteration_pixels * (uint64_t)iteration_spp(k, max_iter_spp, max_train_spp, o->spp - cumulative, features_schedule_start(ig));
        if (k != at.iteration || cumulative != at.spp_done || at.spp_done >= o->spp ||
            (at.iteration_paths >= iteration_total && at.iteration_paths > 0)) {
            snprintf(err, CANDELA_ERR_LEN, "%s: its progress (iteration %d, %d spp) is not a point of this render's schedule",
                     o->resume_from, at.iteration, at.spp_done);
            render_free_frame(r);
            return -1;
        }
        done_paths = (uint64_t)npixels * (uint64_t)at.spp_done + at.iteration_paths;
    }
    int spp_done = at.spp_done, iteration = at.iteration, stopped = 0, limited = 0;
    const int first_iteration = at.iteration; /* this run's first (a resumed render's too) */
    uint64_t resume_paths = at.iteration_paths;
    int min_spp = o->min_spp > 0 ? o->min_spp : CANDELA_DEFAULT_MIN_SPP;
    ig->spp_done = spp_done;
    for (; spp_done < o->spp && ig->iteration_pixels > 0; ++iteration) {
        int spp_i = iteration_spp(iteration, max_iter_spp, max_train_spp, o->spp - spp_done, features_schedule_start(ig));
        ig->iteration_spp = spp_i;
        ig->iteration_index = iteration;
        ig->sample_base = sample_begin + (uint64_t)spp_done;
        uint64_t iter_paths = (uint64_t)ig->iteration_pixels * (uint64_t)spp_i;
        uint64_t first = resume_paths < iter_paths ? resume_paths : 0;
        resume_paths = 0;
        while (first < iter_paths) {
            ig->batch_first = first;
            ig->batch_count = (uint32_t)((iter_paths - first) < batch ? (iter_paths - first) : batch);
            integrator_run_batch(ig, r->pool, stats);
            done_paths += ig->batch_count;
            first += ig->batch_count;
            report_progress(&progress, done_paths, total_paths, 0);
            /* an interruption abandons the rest of the iteration: the state at this batch
             * boundary is a checkpoint like any other (the iteration continues from here) */
            if (o->stop && *o->stop && first < iter_paths) {
                at = (CheckpointProgress){iteration, spp_done, first};
                stopped = 1;
                break;
            }
        }
        if (stopped) break;
        spp_done += spp_i;
        ig->spp_done = spp_done;
        double t_barrier = clock_seconds();
        integrator_barrier(ig); /* no ray in flight: learned state changes here */
        stats->iterations = iteration + 1;
        stats->spp_done = spp_done;
        /* adaptive sampling decides from the film at the barrier (no clock): deterministic, and
         * a checkpoint written below holds the decision */
        if (ig->pixel_list && spp_done >= min_spp && spp_done < o->spp) {
            film_adaptive_update(&ig->film, o->noise_threshold);
            update_pixel_list(ig);
            total_paths = done_paths + (uint64_t)ig->iteration_pixels * (uint64_t)(o->spp - spp_done);
        }
        stats->time_barrier += clock_seconds() - t_barrier; /* statistics only: no decision reads it */
        if (iteration == first_iteration) phase_mark(&r->phases, CANDELA_PHASE_FIRST_ITERATION);
        report_progress(&progress, done_paths, total_paths, done_paths == total_paths);
        at = (CheckpointProgress){iteration + 1, spp_done, 0};
        if (o->on_iteration) {
            CandelaIterationInfo info = {iteration, spp_done, clock_seconds() - t_start, ig->film.width, ig->film.height,
                                         &ig->film};
            if (o->on_iteration(o->on_iteration_user, &info) != 0 && spp_done < o->spp) {
                stopped = 1;
                break;
            }
        }
        if (o->stop && *o->stop && spp_done < o->spp) {
            stopped = 1;
            break;
        }
        /* the one clock that decides anything: where a time-limited render stops */
        if (o->time_limit > 0.0 && spp_done < o->spp && ig->iteration_pixels > 0 &&
            clock_seconds() - t_start >= o->time_limit) {
            limited = 1;
            break;
        }
        int next = spp_done + iteration_spp(iteration + 1, max_iter_spp, max_train_spp, o->spp - spp_done, features_schedule_start(ig));
        if (o->checkpoint_path && checkpoint_due(spp_done, next, o->spp)) {
            if (checkpoint_write(o->checkpoint_path, &identity, &at, ig, &r->sampler, 0, err) != 0) {
                fprintf(stderr, "candela: warning: %s (the render goes on)\n", err); /* a later one may succeed */
            } else if (!o->quiet && !progress.is_tty) {
                fprintf(stderr, "candela: checkpoint at %d spp: %s\n", spp_done, o->checkpoint_path);
            }
        }
    }
    stats->spp_done = spp_done;
    stats->time_limited = limited;
    stats->adaptive_active_pixels = ig->pixel_list ? ig->iteration_pixels : 0;
    spp_statistics(&ig->film, stats);
    light_sampler_report(&r->sampler, stats); /* again: what the barriers changed in the strategy */
    if (limited && o->checkpoint_path) {
        /* a finished image, and a checkpoint to go on from with more time */
        if (checkpoint_write(o->checkpoint_path, &identity, &at, ig, &r->sampler, 0, err) != 0) {
            fprintf(stderr, "candela: warning: %s\n", err);
            stats->checkpoint_failed = 1;
        }
    }
    if (stopped) {
        /* the image of the samples done is returned (per-pixel counts differ after an abandoned
         * iteration; each pixel's mean is its own samples'), and the state is kept to resume */
        stats->interrupted = 1;
        if (o->checkpoint_path && checkpoint_write(o->checkpoint_path, &identity, &at, ig, &r->sampler, 0, err) != 0) {
            fprintf(stderr, "candela: warning: %s\n", err); /* the image so far may still be wanted */
            stats->checkpoint_failed = 1;
        }
    } else if (o->film_path && checkpoint_write(o->film_path, &identity, &at, ig, &r->sampler, 1, err) != 0) {
        render_free_frame(r);
        return -1;
    }
    stats->time_total = clock_seconds() - t_start;
    features_report(ig, stats);
    if (features_finish(ig, err) != 0) {
        render_free_frame(r);
        return -1;
    }
    /* the light sampler's own outputs of the finished render (a dump of what it learned) */
    if (light_sampler_finish(&r->sampler, err) != 0) {
        render_free_frame(r);
        return -1;
    }
    int rc = film_resolve(&ig->film, image);
    if (rc != 0) snprintf(err, CANDELA_ERR_LEN, "%s: out of memory resolving the film", o->scene_path);
    if (rc == 0) { /* where the film lies in the full image (--crop) */
        image->crop_x = cam->crop_x;
        image->crop_y = cam->crop_y;
        image->full_width = cam->width;
        image->full_height = cam->height;
    }
    stats->peak_memory_bytes = peak_rss_bytes();
    for (int k = 0; k < CANDELA_PHASES; ++k) {
        stats->phase_seconds[k] = r->phases.seconds[k];
        stats->phase_peak_bytes[k] = r->phases.peak[k];
        stats->phase_rss_bytes[k] = r->phases.rss[k];
    }
    render_free_frame(r);
    return rc;
}

int candela_render(const CandelaOptions *o, CandelaImage *image, CandelaStats *stats, CandelaRayLog *ray_log,
                   char err[CANDELA_ERR_LEN]) {
    CandelaStats local_stats;
    if (!stats) stats = &local_stats;
    memset(stats, 0, sizeof *stats);
    memset(image, 0, sizeof *image);
    if (!render_options_valid(o, err)) return -1;
    Render *r = calloc(1, sizeof *r);
    if (!r) { snprintf(err, CANDELA_ERR_LEN, "candela: out of memory"); return -1; }
    peak_rss_reset();
    double t_start = clock_seconds();
    r->phases.t = t_start;
    if (scene_load_phased(&r->scene, o, &r->phases, err) != 0) { render_free(r); return -1; }
    r->have_scene = 1;
    /* a single render is unposed (a frame batch, candela_session_*, renders animation times) */
    if (r->scene.io.num_channels > 0 && !o->no_warnings)
        fprintf(stderr, "%s: warning: %u animation channel%s not rendered: a single render shows the rest pose "
                        "(render animation times with --frames)\n", o->scene_path, r->scene.io.num_channels,
                r->scene.io.num_channels == 1 ? " is" : "s are");
    int rc = render_frame(r, o, image, stats, ray_log, t_start, err);
    render_free(r);
    return rc;
}

/* ---------------------------------------------------------------- sessions (frame batches) */

/* A loaded scene rendered at many animation times: meshes, textures, volumes' grids, the
 * Embree device and mesh scenes and the thread pool load once; each frame poses the scene
 * (instance transforms, top-level rebuild), then render_frame builds media, lights and the
 * light sampler for that pose and renders. candela_render is exactly a session
 * of one unposed frame. */
struct CandelaSession {
    Render *r;
};

int candela_session_open(const CandelaOptions *o, CandelaSession **out, CandelaSessionInfo *info,
                         char err[CANDELA_ERR_LEN]) {
    *out = NULL;
    memset(info, 0, sizeof *info);
    if (!render_options_valid(o, err)) return -1;
    CandelaSession *s = calloc(1, sizeof *s);
    Render *r = calloc(1, sizeof *r);
    if (!s || !r) {
        free(s);
        free(r);
        snprintf(err, CANDELA_ERR_LEN, "candela: out of memory");
        return -1;
    }
    double t_start = clock_seconds();
    if (scene_load(&r->scene, o, err) != 0) {
        free(s);
        render_free(r);
        return -1;
    }
    r->have_scene = 1;
    s->r = r;
    info->time_load = clock_seconds() - t_start;
    info->num_channels = r->scene.io.num_channels;
    info->anim_start = r->scene.io.anim_start;
    info->anim_end = r->scene.io.anim_end;
    info->width = r->scene.camera.width;
    info->height = r->scene.camera.height;
    info->image_width = r->scene.camera.crop_width;
    info->image_height = r->scene.camera.crop_height;
    *out = s;
    return 0;
}

int candela_session_render(CandelaSession *s, const CandelaOptions *o, double seconds, CandelaImage *image,
                           CandelaStats *stats, CandelaFrameInfo *frame, char err[CANDELA_ERR_LEN]) {
    memset(stats, 0, sizeof *stats);
    memset(image, 0, sizeof *image);
    memset(frame, 0, sizeof *frame);
    if (!render_options_valid(o, err)) return -1;
    peak_rss_reset();
    double t_start = clock_seconds();
    if (scene_pose(&s->r->scene, o, seconds, &frame->instances_moved, err) != 0) return -1;
    frame->time_pose = clock_seconds() - t_start;
    memset(&s->r->phases, 0, sizeof s->r->phases); /* a frame's own phases: no load (peaks since the frame's start) */
    s->r->phases.t = clock_seconds();
    return render_frame(s->r, o, image, stats, NULL, t_start, err);
}

void candela_session_close(CandelaSession *s) {
    if (!s) return;
    render_free(s->r);
    free(s);
}
