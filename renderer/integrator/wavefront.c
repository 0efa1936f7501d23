/* renderer/integrator/wavefront.c: the wave sequencing of the integrator (integrator.h): waves of a
 * slice, slices of a batch, the film and the iteration barrier.
 *
 * Per-thread wavefronts: the batch's slots are cut into one contiguous slice per thread and
 * each thread runs every wave of its slice on its own queues, which live in its part of the
 * shared queue arrays. Paths never interact, so this is the same computation as one
 * batch-wide wavefront, with no synchronisation inside a batch (a pool call per stage,
 * thousands per render, had cost a third of the 2-thread speed-up). */
#include <stdlib.h>
#include <string.h>

#include "clock.h"
#include "feature.h"



/* Stage timing and ray logging wrap the stages; neither changes what a stage computes. */
#define TIMED(slice, stage, call)                                     \
    do {                                                              \
        double t0_ = clock_seconds();                                 \
        call;                                                         \
        (slice)->seconds[stage] += clock_seconds() - t0_;             \
    } while (0)

static void log_queue(const Integrator *ig, const SceneRay *rays, const uint32_t *items, uint32_t n) {
    if (!ig->ray_log) return;
    pthread_mutex_t *m = (pthread_mutex_t *)&ig->ray_log_mutex;
    pthread_mutex_lock(m);
    ray_log_append(ig->ray_log, rays, items, n, rays == ig->ps.shadow_ray);
    pthread_mutex_unlock(m);
}

_Static_assert(STAGE_COUNT == sizeof ((CandelaStats *)0)->stage_thread_seconds / sizeof(double),
               "CandelaStats.stage_thread_seconds holds one time per stage");

/* One wave: every live path of the slice advances by one bounce. */
static void run_wave(const Integrator *ig, Slice *s) {
    TIMED(s, STAGE_SORT, sort_rays(ig, s));
    log_queue(ig, ig->ps.ray, s->rays, s->num_rays);
    TIMED(s, STAGE_TRACE, stage_intersect(ig, s));
    TIMED(s, STAGE_MEDIUM, stage_medium(ig, s));
    TIMED(s, STAGE_SHADE, stage_escaped(ig, s));
    TIMED(s, STAGE_SORT, sort_hits(ig, s));
    TIMED(s, STAGE_SHADE, stage_surface(ig, s)); /* refills the ray queue for the next wave */
    s->shadow_rays += s->num_shadows;
    log_queue(ig, ig->ps.shadow_ray, s->shadows, s->num_shadows);
    TIMED(s, STAGE_SHADOW, stage_shadow(ig, s));
}

static void run_slice(const Integrator *ig, Slice *s) {
    TIMED(s, STAGE_GENERATE, stage_generate(ig, s));
    for (s->wave = 0; s->num_rays > 0; ++s->wave) {
        if (s->wave > 0) s->bounce_rays += s->num_rays;
        run_wave(ig, s);
    }
}

typedef struct SliceCtx { const Integrator *ig; Slice *slices; } SliceCtx;

static void slice_range(void *vctx, size_t b, size_t e, int thread) {
    (void)thread;
    SliceCtx *c = vctx;
    for (size_t k = b; k < e; ++k) run_slice(c->ig, &c->slices[k]);
}

void integrator_run_batch(Integrator *ig, ThreadPool *pool, CandelaStats *st) {
    uint32_t n = (uint32_t)threadpool_size(pool);
    if (n > MAX_SLICES) n = MAX_SLICES;
    if (n > ig->batch_count) n = ig->batch_count;
    Slice slices[MAX_SLICES];
    for (uint32_t k = 0; k < n; ++k) {
        uint32_t b = (uint32_t)((uint64_t)ig->batch_count * k / n), e = (uint32_t)((uint64_t)ig->batch_count * (k + 1) / n);
        slices[k] = (Slice){.begin = b, .end = e, .rays = ig->queue_rays + b, .hits = ig->queue_hits + b,
                            .escaped = ig->queue_escaped + b, .shadows = ig->queue_shadows + b,
                            .keys = ig->sort_keys + b, .keys_tmp = ig->sort_keys_tmp + b,
                            .items_tmp = ig->sort_items_tmp + b};
        features_slice_begin(ig, &slices[k], k);
    }
    SliceCtx c = {ig, slices};
    double t_region = clock_seconds();
    threadpool_parallel_for(pool, n, 1, slice_range, &c);
    double region = clock_seconds() - t_region;
    /* stage wall times: the region's wall time (measured here, on the calling thread) shared
     * among the stages in proportion to the threads' time in each, so they add up to it; the
     * threads' own times, averaged over the slices, are the per-thread detail */
    double *wall[STAGE_COUNT] = {&st->time_generate, &st->time_sort, &st->time_trace, &st->time_medium,
                                 &st->time_shade, &st->time_shadow};
    double per_stage[STAGE_COUNT] = {0}, busy = 0.0;
    for (uint32_t k = 0; k < n; ++k)
        for (int s = 0; s < STAGE_COUNT; ++s) {
            per_stage[s] += slices[k].seconds[s];
            busy += slices[k].seconds[s];
        }
    for (int s = 0; s < STAGE_COUNT; ++s) {
        *wall[s] += busy > 0.0 ? region * (per_stage[s] / busy) : (s == STAGE_GENERATE ? region : 0.0);
        st->stage_thread_seconds[s] += per_stage[s] / n;
    }
    if ((int)n > st->stage_threads) st->stage_threads = (int)n;
    for (uint32_t k = 0; k < n; ++k) {
        st->rays_bounce += slices[k].bounce_rays;
        st->rays_shadow += slices[k].shadow_rays;
        st->volume_collisions += slices[k].volume.collisions;
        st->volume_capped_walks += slices[k].volume.capped_walks;
    }
    st->paths += ig->batch_count;
    st->rays_camera += ig->batch_count;
    double t_learn = clock_seconds(); /* learning from the batch: serial phases */
    features_batch_end(ig, slices, n);
    st->time_learn += clock_seconds() - t_learn;
    /* film: serial, in path order, so every pixel sums its samples in sample order */
    double t = clock_seconds();
    film_add_paths(&ig->film, &ig->ps, ig->batch_count);
    st->time_film += clock_seconds() - t;
}

int integrator_add_barrier_hook(Integrator *ig, void (*run)(void *user), void *user) {
    if (ig->num_hooks >= MAX_BARRIER_HOOKS) return -1;
    ig->hooks[ig->num_hooks++] = (BarrierHook){run, user};
    return 0;
}

void integrator_barrier(Integrator *ig) {
    features_barrier(ig);
    for (int i = 0; i < ig->num_hooks; ++i) ig->hooks[i].run(ig->hooks[i].user);
}

int integrator_init(Integrator *ig, const CandelaOptions *o, const Scene *scene, const Lights *lights,
                    const SceneMedia *media, const LightSampler *sampler, uint32_t batch) {
    memset(ig, 0, sizeof *ig);
    ig->opt = o;
    ig->scene = scene;
    ig->lights = lights;
    ig->media = media;
    ig->camera_medium = media_at_point(media, xform_point(scene->camera.xform, v3s(0.0f)));
    ig->light_sampler = sampler;
    /* the film is the crop's (--crop; the whole image without one) */
    ig->npixels = (uint32_t)scene->camera.crop_width * (uint32_t)scene->camera.crop_height;
    ig->iteration_pixels = ig->npixels;
    if (o->sampler == CANDELA_SAMPLER_SOBOL) {
        sequence_tables_init(&ig->sobol_tables);
        ig->sobol = &ig->sobol_tables;
    }
    sort_init(ig);
    pthread_mutex_init(&ig->ray_log_mutex, NULL);
    size_t n = batch ? batch : 1;
    ig->queue_rays = malloc(n * sizeof(uint32_t));
    ig->queue_hits = malloc(n * sizeof(uint32_t));
    ig->queue_escaped = malloc(n * sizeof(uint32_t));
    ig->queue_shadows = malloc(n * sizeof(uint32_t));
    ig->sort_keys = malloc(n * sizeof(uint64_t));
    ig->sort_keys_tmp = malloc(n * sizeof(uint64_t));
    ig->sort_items_tmp = malloc(n * sizeof(uint32_t));
    int fail = !ig->queue_rays || !ig->queue_hits || !ig->queue_escaped || !ig->queue_shadows || !ig->sort_keys ||
               !ig->sort_keys_tmp || !ig->sort_items_tmp;
    fail = fail || path_state_alloc(&ig->ps, batch) != 0 || film_alloc(&ig->film, scene->camera.crop_width, scene->camera.crop_height) != 0;
    fail = fail || features_init(ig) != 0;
    ig->film.aov_spp = o->aov_spp;
    /* adaptive sampling's window is scaled to the full image, so a crop pools over the same
     * neighbourhoods as the full render would (film.c) */
    ig->film.window_side = scene->camera.width < scene->camera.height ? scene->camera.width : scene->camera.height;
    if (!fail && o->noise_threshold > 0.0f) {
        ig->film.stopped = calloc(ig->npixels, 1);
        ig->film.target = calloc(ig->npixels, sizeof(uint32_t));
        ig->pixel_list = malloc((size_t)ig->npixels * sizeof(uint32_t));
        fail = !ig->film.stopped || !ig->film.target || !ig->pixel_list;
    }
    if (!fail && o->aov_selection) {
        ig->film.sel_aov = calloc(6 * (size_t)ig->npixels, sizeof(double));
        fail = !ig->film.sel_aov;
    }
    if (fail) { integrator_free(ig); return -1; }
    return 0;
}

void integrator_free(Integrator *ig) {
    path_state_free(&ig->ps);
    free(ig->queue_rays); free(ig->queue_hits); free(ig->queue_escaped); free(ig->queue_shadows);
    free(ig->sort_keys); free(ig->sort_keys_tmp); free(ig->sort_items_tmp);
    film_free(&ig->film);
    free(ig->pixel_list);
    features_free(ig);
    pthread_mutex_destroy(&ig->ray_log_mutex);
    memset(ig, 0, sizeof *ig);
}
